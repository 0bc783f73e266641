"""Leg-camera renderer and the camera_strides pipeline: known motion, the simulator's walk, bad input."""

from __future__ import annotations

import tomllib

import cv2
import numpy as np
import pandas as pd
import pytest

from pdr.errors import InputError
from pdr.flow import CorrelationOpticalFlow
from pdr.io.recording import Recording
from pdr.io.tomlio import dumps_toml
from pdr.pipelines.leg_camera import camera_strides
from pdr.sim.camera import CameraModel, LegCameraRenderer, load_texture, render_leg_camera, write_video
from pdr.sim.gait import WalkKinematics
from tests.conftest import make_imu
from conftest import warns

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


@pytest.mark.parametrize("texture", ["gravel", "brick", "grass"])
def test_renderer_flow_matches_projective_geometry(texture):
    frames, table = render_leg_camera(Slide(1.0, 0.6), CAM, 0.0, 1.0, load_texture(texture))
    assert frames.shape == (101, 120, 160) and frames.dtype == np.uint8 and frames.std() > 10
    flow = CorrelationOpticalFlow(patch_px=24, grid_step_px=24, max_shift_px=10, predict=True).estimate(frames, table.t_s).flow_
    expected = -CAM.focal_px * 1.0 / (0.6 - 0.25)  # -f v / D: the floor slides backwards through the image
    assert abs(np.median(flow.flow_x_pxps) / expected - 1) < 0.01
    assert abs(np.median(flow.flow_y_pxps)) < 3.0


def test_renderer_on_the_simulator_walk_sees_the_floor():
    kin = WalkKinematics.steady(speed_mps=1.3, duration_s=3.0, seed=2)
    frames, table = render_leg_camera(kin, CAM, 1.5, 3.5, load_texture("gravel"))
    assert np.all(np.diff(table.t_s) > 0) and len(frames) == 201
    assert np.median(frames.std(axis=(1, 2))) > 10  # textured floor in view, not the flat background


def _recording(tmp_path, kin, texture="gravel", t_end=7.9) -> Recording:
    frames, table = render_leg_camera(kin, CAM, 0.5, t_end, load_texture(texture), seed=1)
    write_video(tmp_path / "video.avi", frames, CAM.fps)
    return Recording(meta={"recording": {"id": "cam", "placement": "waist"}, "subject": kin.body.subject(70.0)},
                     imu=make_imu(8.0), camera=CAM.to_toml(), video_path=tmp_path / "video.avi", frames=table)


def _matched_errors(strides, kin):
    true = kin.true_strides()
    true = true[true.foot == "left"]
    k = np.abs(true.t_start_s.to_numpy()[None, :] - strides.t_start_s.to_numpy()[:, None]).argmin(axis=1)
    np.testing.assert_allclose(strides.t_start_s, true.t_start_s.to_numpy()[k], atol=0.06)  # heel strikes from the flow
    return strides.length_m.to_numpy() / true.length_m.to_numpy()[k] - 1


def test_camera_strides_on_a_rendered_walk(tmp_path):
    kin = WalkKinematics.steady(speed_mps=1.3, duration_s=7.0, seed=3)
    rec = _recording(tmp_path, kin)
    strides = camera_strides(rec, {})  # the floor odometry: mid-stance to mid-stance, the last stride has no end
    assert list(strides.columns) == ["t_start_s", "t_end_s", "foot", "length_m", "length_std_m", "source"]
    assert len(strides) >= 3 and (strides.source == "leg_camera").all() and (strides.foot == "left").all()
    assert np.mean(np.abs(_matched_errors(strides, kin))) < 0.05 and np.all(strides.length_std_m > 0)
    slip = camera_strides(rec, {"leg_camera": {"method": "slip_of"}})
    assert len(slip) >= 4 and np.mean(np.abs(_matched_errors(slip, kin))) < 0.15 and np.all(slip.length_std_m > 0)
    # the SLIP's toe lever is Winter's foot for the height: a measured foot, here far from it, moves no stride
    footed = {**rec.meta, "subject": {**rec.meta["subject"], "foot_length_m": 0.2}}
    again = camera_strides(Recording(meta=footed, imu=rec.imu, camera=rec.camera, video_path=rec.video_path,
                                     frames=rec.frames), {"leg_camera": {"method": "slip_of"}})
    pd.testing.assert_frame_equal(again, slip)
    assert camera_strides(Recording(meta=rec.meta, imu=rec.imu), {}) is None  # no video: no strides
    with pytest.raises(InputError, match=r"\[leg_camera\]"):
        camera_strides(rec, {"leg_camera": {"method": "visual"}})


def test_blank_floor_gives_no_confident_stride(tmp_path):
    kin = WalkKinematics.steady(speed_mps=1.3, duration_s=4.0, seed=3)
    blank = tmp_path / "blank.png"
    cv2.imwrite(str(blank), np.full((64, 64), 120, np.uint8))
    rec = _recording(tmp_path, kin, texture=str(blank), t_end=5.0)
    with warns():
        strides = camera_strides(rec, {})
    assert strides.empty


def test_bad_camera_inputs(tmp_path):
    kin = WalkKinematics.steady(speed_mps=1.3, duration_s=3.0, seed=3)
    rec = _recording(tmp_path, kin, t_end=1.5)
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
    with pytest.raises(InputError, match="above the ground"):
        LegCameraRenderer(CAM, load_texture("gravel")).render(Slide(1.0, 0.1), np.array([0.0]))
    with pytest.raises(InputError, match="expected an image"):
        load_texture(tmp_path / "missing.png")
    assert CameraModel.from_toml(tomllib.loads(dumps_toml(CAM.to_toml()))) == CAM
