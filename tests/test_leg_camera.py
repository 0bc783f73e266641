"""Leg-camera renderer and the camera_strides pipeline: known motion, true strides, bad input."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from pdr.errors import InputError
from pdr.flow import CorrelationOpticalFlow
from pdr.io.recording import Recording
from pdr.io.tomlio import dumps_toml, read_toml
from pdr.pipelines.leg_camera import camera_strides
from pdr.sim.camera import (
    CameraModel, FourierLegWalk, LegCameraRenderer, camera_from_section, load_texture, render_leg_camera, write_leg_camera,
)
from tests.conftest import make_imu

CAM = CameraModel(fps=100.0, focal_px=120.0, cx_px=79.5, cy_px=59.5, width_px=160, height_px=120,
                  segment="shank_left", distance_from_knee_m=0.25)


class Slide:
    """Test double: a vertical shank gliding forward at constant speed and height."""

    def __init__(self, v_mps: float, knee_z_m: float):
        self.v, self.z = v_mps, knee_z_m

    def joint_positions_m(self, t):
        t = np.asarray(t, float)
        return {"knee_left": np.column_stack([self.v * t, 0 * t, self.z + 0 * t])}

    def segment_rotation(self, t, segment):
        r = np.array([[1.0, 0, 0], [0, -1.0, 0], [0, 0, -1.0]])  # x forward, z down the shank
        return np.broadcast_to(r, (len(np.asarray(t)), 3, 3)).copy()


@pytest.mark.parametrize("texture", ["gravel", "brick"])
def test_renderer_flow_matches_projective_geometry(texture):
    frames, table = render_leg_camera(Slide(1.0, 0.6), CAM, 0.0, 1.0, load_texture(texture))
    assert frames.shape == (101, 120, 160) and frames.dtype == np.uint8 and frames.std() > 10
    flow = CorrelationOpticalFlow(patch_px=24, grid_step_px=24, max_shift_px=10, predict=True).estimate(frames, table.t_s).flow_
    expected = -CAM.focal_px * 1.0 / (0.6 - 0.25)  # -f v / D: the floor slides backwards through the image
    assert abs(np.median(flow.flow_x_pxps) / expected - 1) < 0.01
    assert abs(np.median(flow.flow_y_pxps)) < 3.0


def test_fourier_walk_strides_and_no_slip():
    walk = FourierLegWalk(stride_time_s=1.1, amplitude=0.85, duration_s=6.0)
    true = walk.true_strides("left")
    assert len(true) == 5 and np.ptp(true.length_m) < 1e-3 and 1.0 < true.length_m.iloc[0] < 1.5
    t = np.arange(0.3, 5.5, 0.01)
    pos = walk.joint_positions_m(t)
    low = np.minimum(pos["heel_left"][:, 2], pos["toe_left"][:, 2])
    assert low.min() > -1e-3  # the feet never go through the floor
    flat = pos["heel_left"][:, 2] < 1e-4
    speed = np.abs(np.gradient(pos["heel_left"][:, 0], t))[flat]
    assert np.median(speed) < 0.05  # a heel on the floor does not slide
    rot = walk.segment_rotation(t[:5], "shank_left")
    np.testing.assert_allclose(np.linalg.det(rot), 1.0)
    shank = pos["ankle_left"][:5] - pos["knee_left"][:5]
    np.testing.assert_allclose(rot[:, :, 2], shank / np.linalg.norm(shank, axis=1)[:, None], atol=1e-9)


def _recording(tmp_path, walk, texture="gravel", t_end=7.9) -> Recording:
    cam = write_leg_camera(tmp_path, walk, {"texture": texture}, 0.05, t_end, seed=1)
    frames = pd.read_csv(tmp_path / "frames.csv")
    return Recording(meta={"recording": {"id": "cam", "placement": "shank_left"},
                           "subject": {"thigh_length_m": 0.45, "shank_length_m": 0.45, "foot_length_m": 0.2}},
                     imu=make_imu(8.0), camera=read_toml(tmp_path / "camera.toml"), video_path=tmp_path / "video.avi",
                     frames=frames), cam


def test_camera_strides_on_a_rendered_walk(tmp_path):
    walk = FourierLegWalk(stride_time_s=1.1, amplitude=0.85, duration_s=8.0)
    rec, cam = _recording(tmp_path, walk)
    assert cam.segment == "shank_left"
    strides = camera_strides(rec, {})
    assert list(strides.columns) == ["t_start_s", "t_end_s", "foot", "length_m", "length_std_m", "source"]
    assert len(strides) >= 4 and (strides.source == "leg_camera").all() and (strides.foot == "left").all()
    true = walk.true_strides("left").length_m.iloc[0]
    assert np.all(np.abs(strides.length_m / true - 1) < 0.2)
    assert np.all(strides.length_std_m > 0)
    assert camera_strides(Recording(meta=rec.meta, imu=rec.imu), {}) is None  # no video: no strides


def test_blank_floor_gives_no_confident_stride(tmp_path):
    walk = FourierLegWalk(stride_time_s=1.1, amplitude=0.85, duration_s=5.0)
    blank = tmp_path / "blank.png"
    import cv2

    cv2.imwrite(str(blank), np.full((64, 64), 120, np.uint8))
    rec, _ = _recording(tmp_path, walk, texture=str(blank), t_end=4.9)
    with pytest.warns(UserWarning):
        strides = camera_strides(rec, {})
    assert strides.empty


def test_bad_camera_inputs(tmp_path):
    walk = FourierLegWalk(stride_time_s=1.1, amplitude=0.85, duration_s=2.0)
    rec, _ = _recording(tmp_path, walk, t_end=1.5)
    broken = {"camera": {k: v for k, v in rec.camera["camera"].items() if k != "focal_px"}, "mount": rec.camera["mount"]}
    with pytest.raises(InputError, match="camera.focal_px"):
        camera_strides(Recording(meta=rec.meta, imu=rec.imu, camera=broken, video_path=rec.video_path), {})
    with pytest.raises(InputError, match="camera.focal_px"):
        CameraModel.from_toml(broken)
    more = pd.DataFrame({"t_s": np.arange(len(rec.frames) + 3) / 100.0})
    with pytest.raises(InputError, match="frames.csv"):
        camera_strides(Recording(meta=rec.meta, imu=rec.imu, camera=rec.camera, video_path=rec.video_path, frames=more), {})
    data = rec.video_path.read_bytes()
    cut = tmp_path / "cut.avi"
    cut.write_bytes(data[: len(data) // 3])
    with pytest.raises(InputError):
        camera_strides(Recording(meta=rec.meta, imu=rec.imu, camera=rec.camera, video_path=cut, frames=rec.frames), {})
    with pytest.raises(InputError, match="unknown key"):
        camera_from_section({"focal": 100})
    with pytest.raises(InputError, match="above the ground"):
        LegCameraRenderer(CAM, load_texture("gravel")).render(Slide(1.0, 0.1), np.array([0.0]))
    assert "mount" in read_toml(tmp_path / "camera.toml") and "[camera]" in dumps_toml(CAM.to_toml())
