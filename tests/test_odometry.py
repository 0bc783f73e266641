"""Floor odometry of a leg camera: the plane homography's motion (known poses) and the strides scaled by the leg."""

from __future__ import annotations

import dataclasses
import math

import cv2
import numpy as np
import pandas as pd
import pytest

from pdr.errors import InputError
from pdr.flow import HomographyCameraMotion
from pdr.sim.camera import CameraModel, load_texture, render_leg_camera
from pdr.slip import FloorOdometryStride
from conftest import warns

CAM = CameraModel(fps=100.0, focal_px=120.0, cx_px=79.5, cy_px=59.5, width_px=160, height_px=120,
                  segment="shank_left", distance_from_knee_m=0.25)


class Pose:
    """Test double: a shank camera at knee height ``z(t)``, moving forward at ``v`` and tilted ``tilt(t)`` forward
    about the lateral axis (the optical axis down the shank)."""

    def __init__(self, v_mps, z, tilt):
        self.v, self.z, self.tilt = v_mps, z, tilt

    def joint_positions_m(self, t):
        t = np.asarray(t, float)
        return {"knee_left": np.column_stack([self.v * t, 0 * t, self.z(t)])}

    def segment_rotation(self, t, segment):
        a = self.tilt(np.asarray(t, float))
        c, s = np.cos(a), np.sin(a)
        z, o = np.zeros_like(a), np.ones_like(a)
        # columns: camera x (forward, tilted), camera y (lateral), camera z (down the shank, tilted back at the foot)
        return np.stack([np.stack([c, z, s], -1), np.stack([z, -o, z], -1), np.stack([s, z, -c], -1)], -1)


def _motion(pose, t_end=0.5):
    frames, table = render_leg_camera(pose, CAM, 0.0, t_end, load_texture("gravel"), seed=2)
    return HomographyCameraMotion(focal_px=CAM.focal_px, cx_px=CAM.cx_px, cy_px=CAM.cy_px).estimate(frames, table.t_s).motion_


@pytest.mark.parametrize("tilt_deg", [0.0, 20.0])
def test_homography_reads_the_height_ratio_the_floor_displacement_and_the_tilt(tilt_deg):
    # rising 0.1 m/s while gliding at 1 m/s, the shank tilted: the floor's displacement and the tilt are read to a few
    # percent and a degree; the height's change, the motion's smallest part (1 mm a frame against 10 mm along the
    # floor), to a third: +26% and -33% here, an offset of under 0.001 a frame pair, which the odometry's two
    # anchors take out (README, Known limits)
    tilt = math.radians(tilt_deg)
    pose = Pose(1.0, lambda t: 0.55 + 0.1 * t, lambda t: np.full_like(t, tilt))
    m = _motion(pose)
    assert m.height_log_ratio.notna().all()
    height = lambda t: pose.z(t) - 0.25 * math.cos(tilt)  # noqa: E731 - the camera over the floor
    t0, t1 = m.t_s - 0.5 * m.dt_s, m.t_s + 0.5 * m.dt_s
    np.testing.assert_allclose(m.height_log_ratio.sum(), math.log(height(t1.iloc[-1]) / height(t0.iloc[0])), rtol=0.35)
    assert np.abs(m.height_log_ratio - np.log(height(t1) / height(t0))).max() < 0.003
    # the camera moved 1 m/s x dt over the floor along the image x axis: per height of the first frame
    forward = m.floor_x_per_height * height(t0)
    np.testing.assert_allclose(np.median(forward / m.dt_s), 1.0, rtol=0.03)
    assert np.abs(m.floor_y_per_height * height(t0) / m.dt_s).max() < 0.05
    np.testing.assert_allclose(np.degrees(np.nanmedian(m.tilt_rad)), tilt_deg, atol=1.0)


@pytest.mark.parametrize("turn_deg, shift_px", [(10.0, 10.0), (30.0, 25.0)])
def test_homography_follows_a_fast_turn_over_a_repeating_floor(turn_deg, shift_px):
    # brick, the frame turned about its centre and shifted in one frame interval (a swinging shank's camera at 60
    # frames/s): no shift start is near, the matched features' is; the centre moves by the shift, the height stays
    floor = cv2.resize(load_texture("brick"), (320, 320))
    turn = cv2.getRotationMatrix2D((159.5, 159.5), turn_deg, 1.0)
    turn[0, 2] += shift_px
    frames = np.stack([floor[100:220, 80:240], cv2.warpAffine(floor, turn, (320, 320))[100:220, 80:240]])
    m = HomographyCameraMotion(focal_px=120.0, cx_px=79.5, cy_px=59.5).estimate(frames, [0.0, 0.01]).motion_
    np.testing.assert_allclose(m[["flow_x_pxps", "flow_y_pxps"]].iloc[0], [100 * shift_px, 0.0], atol=2.0)
    assert abs(m.height_log_ratio.iloc[0]) < 1e-3 and m.quality.iloc[0] > 0.9


def test_homography_on_a_blank_floor_measures_nothing_and_bad_input_is_an_error():
    frames = np.full((5, 120, 160), 120, np.uint8)
    m = HomographyCameraMotion(focal_px=120.0, cx_px=79.5, cy_px=59.5).estimate(frames, np.arange(5) / 100.0).motion_
    assert len(m) == 4 and m.height_log_ratio.isna().all()
    with pytest.raises(InputError, match="focal_px"):
        HomographyCameraMotion(focal_px=0.0, cx_px=79.5, cy_px=59.5).estimate(frames, np.arange(5) / 100.0)
    with pytest.raises(InputError, match="increasing"):
        HomographyCameraMotion(focal_px=120.0, cx_px=79.5, cy_px=59.5).estimate(frames, [0, 0.01, 0.01, 0.02, 0.03])


def _synthetic_walk(lever_m=0.2, ankle_m=0.07, period_s=1.1, n_strides=5, rate_hz=100.0, filmed_after_s=0.0):
    """A camera motion table of a walk with a known stride: mid-stance heights from the leg, a higher swing; the
    frames go on ``filmed_after_s`` after the last stride's heel strike (the walk goes on)."""
    t = np.arange(0.0, n_strides * period_s + filmed_after_s + 1e-9, 1.0 / rate_hz)
    phase = (t % period_s) / period_s
    tilt = np.radians(25.0 * np.sin(2 * np.pi * phase))
    swing = np.clip((phase - 0.6) / 0.4, 0, 1)
    h = ankle_m + lever_m * np.cos(tilt) + 0.08 * np.sin(np.pi * swing) ** 2  # the leg's in stance, higher in swing
    v = 1.3 * (1 + 0.9 * np.sin(2 * np.pi * phase))  # m/s, stride 1.3 x period
    tm = 0.5 * (t[1:] + t[:-1])
    dt = np.diff(t)
    motion = pd.DataFrame({"t_s": tm, "dt_s": dt, "height_log_ratio": np.log(h[1:] / h[:-1]),
                           "floor_x_per_height": np.interp(tm, t, v) * dt / h[:-1], "floor_y_per_height": 0.0 * dt,
                           "tilt_rad": np.interp(tm, t, np.abs(tilt)), "lean_x": -np.sin(np.interp(tm, t, tilt)),
                           "lean_y": 0.0 * dt, "quality": 1.0})
    starts = np.arange(n_strides) * period_s
    segments = pd.DataFrame({"t_start_s": starts, "t_toe_off_s": starts + 0.6 * period_s, "t_end_s": starts + period_s})
    return motion, segments, 1.3 * period_s


def test_odometry_stride_is_the_displacement_between_mid_stances_in_the_leg_s_metres():
    motion, segments, stride = _synthetic_walk()
    est = FloorOdometryStride(shank_length_m=0.52, ankle_height_m=0.07, camera_from_knee_m=0.25).estimate(motion, segments)
    s = est.strides_
    assert len(s) == len(segments) - 1  # the last stride's closing mid-stance is past the last frame
    np.testing.assert_allclose(s.length_m, stride, rtol=0.005)
    # filmed on for half a stride: the last stride ends at the mid-stance after its own closing heel strike
    motion_on, _, _ = _synthetic_walk(filmed_after_s=0.55)
    on = FloorOdometryStride(shank_length_m=0.52, ankle_height_m=0.07, camera_from_knee_m=0.25).estimate(motion_on, segments)
    assert len(on.strides_) == len(segments)
    np.testing.assert_allclose(on.strides_.length_m, stride, rtol=0.005)
    # the shank leaning 0.1 (sine) further back from the fourth stride's swing on: the camera is 0.1 x lever less
    # ahead of the ankle at its closing mid-stance, so the foot's third stride is longer than the camera's travel
    leaning = motion.assign(lean_x=motion.lean_x + 0.1 * (motion.t_s > 2.2 + 0.7 * 1.1))
    lean = FloorOdometryStride(shank_length_m=0.52, ankle_height_m=0.07, camera_from_knee_m=0.25).estimate(leaning, segments)
    np.testing.assert_allclose(lean.strides_.length_m - s.length_m, [0, 0, 0.1 * 0.2, 0], atol=1e-9)
    np.testing.assert_allclose(lean.anchors_.ahead_m - est.anchors_.ahead_m, [0, 0, 0, -0.02, -0.02], atol=1e-9)
    assert (s.source == "leg_camera").all() and (s.foot == "left").all()
    np.testing.assert_allclose(s.length_std_m / s.length_m, math.hypot(0.035, 0.007), rtol=1e-6)
    # a knee 2 cm higher than the leg's true one: the anchor, hence every stride, is that much higher
    high = FloorOdometryStride(shank_length_m=0.54, ankle_height_m=0.07, camera_from_knee_m=0.25).estimate(motion, segments)
    ratio = high.strides_.length_m / s.length_m
    np.testing.assert_allclose(ratio, ratio.iloc[0], rtol=1e-3)
    assert 1.05 < ratio.iloc[0] < 1.10  # 2 cm on a 0.2 m lever, less the ankle's share
    calibrated = FloorOdometryStride(shank_length_m=0.52, ankle_height_m=0.07, camera_from_knee_m=0.25, length_scale=0.95,
                                     length_scale_std=0.01).estimate(motion, segments).strides_
    np.testing.assert_allclose(calibrated.length_m, 0.95 * s.length_m)
    np.testing.assert_allclose(calibrated.length_std_m / calibrated.length_m, math.hypot(0.01, 0.007), rtol=1e-6)


def test_odometry_bridges_short_losses_and_drops_long_ones():
    motion, segments, stride = _synthetic_walk()
    lost = motion.copy()
    swing = (lost.t_s > 1.1 + 0.75 * 1.1) & (lost.t_s < 1.1 + 0.80 * 1.1)  # 5% of the second stride, in its swing
    lost.loc[swing, ["height_log_ratio", "floor_x_per_height", "floor_y_per_height", "tilt_rad"]] = np.nan
    est = FloorOdometryStride(shank_length_m=0.52, ankle_height_m=0.07, camera_from_knee_m=0.25).estimate(lost, segments)
    assert len(est.strides_) == 4 and abs(est.strides_.length_m.iloc[1] / stride - 1) < 0.03
    assert est.strides_.length_std_m.iloc[1] > est.strides_.length_std_m.iloc[0]
    gone = motion.copy()
    gone.loc[(gone.t_s > 1.1 + 0.4) & (gone.t_s < 1.1 + 0.8), "height_log_ratio"] = np.nan
    with warns("unmeasured"):
        est = FloorOdometryStride(shank_length_m=0.52, ankle_height_m=0.07, camera_from_knee_m=0.25).estimate(gone, segments)
    assert len(est.strides_) == 3 and not np.isclose(est.strides_.t_start_s, 1.1).any()
    # a tenth of a stride lost where the camera moves fastest (a fifth of its travel) drops it; in the slowest, not
    fast, slow = motion.copy(), motion.copy()
    fast.loc[(fast.t_s > 1.1 + 0.20 * 1.1) & (fast.t_s < 1.1 + 0.30 * 1.1), "height_log_ratio"] = np.nan
    slow.loc[(slow.t_s > 1.1 + 0.70 * 1.1) & (slow.t_s < 1.1 + 0.80 * 1.1), "height_log_ratio"] = np.nan
    with warns("travel"):
        assert len(FloorOdometryStride(shank_length_m=0.52).estimate(fast, segments).strides_) == 3
    assert len(FloorOdometryStride(shank_length_m=0.52).estimate(slow, segments).strides_) == 4


def test_odometry_bad_input():
    motion, segments, _ = _synthetic_walk()
    with pytest.raises(InputError, match="foot"):
        FloorOdometryStride(foot="middle").estimate(motion, segments)
    with pytest.raises(InputError, match="missing tilt_rad"):
        FloorOdometryStride().estimate(motion.drop(columns="tilt_rad"), segments)
    with pytest.raises(InputError, match="positive camera_from_knee_m"):
        FloorOdometryStride(camera_from_knee_m=-0.1).estimate(motion, segments)
    with warns("off the shank"):
        est = FloorOdometryStride(shank_length_m=0.4, ankle_height_m=0.07, camera_from_knee_m=0.35).estimate(motion, segments)
    assert est.strides_.empty and list(est.strides_.columns) == ["t_start_s", "t_end_s", "foot", "length_m",
                                                                 "length_std_m", "source"]
    with warns("no stride"):
        assert FloorOdometryStride().estimate(motion.iloc[:5], segments).strides_.empty
    slow, slow_segments, _ = _synthetic_walk(rate_hz=3.0, n_strides=10)  # 3 frames a second, 1.8 steps a second
    with warns("below twice the cadence"):
        assert FloorOdometryStride().estimate(slow, slow_segments).strides_.empty


def test_odometry_strides_hold_across_frame_rates_and_the_camera_leg():
    """Metamorphic: one walk filmed at 100, 60 and 30 frames/s, and from the right shank, reads the same strides."""
    from pdr.pipelines.leg_camera import cut_strides
    from pdr.sim.gait import WalkKinematics

    kin = WalkKinematics.steady(speed_mps=1.3, duration_s=6.0, seed=4)
    body = kin.body
    out = {}
    for name, cam in (("100", CAM), ("60", dataclasses.replace(CAM, fps=60.0)), ("30", dataclasses.replace(CAM, fps=30.0)),
                      ("right", dataclasses.replace(CAM, segment="shank_right"))):
        frames, table = render_leg_camera(kin, cam, 0.5, 6.5, load_texture("gravel"), seed=5)
        motion = HomographyCameraMotion(focal_px=cam.focal_px, cx_px=cam.cx_px, cy_px=cam.cy_px).estimate(frames, table.t_s).motion_
        est = FloorOdometryStride(shank_length_m=body.shank_m + body.ankle_height_m, ankle_height_m=body.ankle_height_m,
                                  camera_from_knee_m=cam.distance_from_knee_m, foot=cam.side).estimate(motion, cut_strides(motion))
        true = kin.true_strides()
        true = true[true.foot == cam.side]
        k = np.abs(true.t_start_s.to_numpy()[None, :] - est.strides_.t_start_s.to_numpy()[:, None]).argmin(axis=1)
        out[name] = est.strides_.length_m.to_numpy() / true.length_m.to_numpy()[k] - 1
        assert len(out[name]) >= 3 and (est.strides_.foot == cam.side).all()
    for name, errors in out.items():
        assert np.abs(errors).max() < 0.04, (name, errors)
    assert abs(np.mean(out["60"]) - np.mean(out["100"])) < 0.02
    assert abs(np.mean(out["30"]) - np.mean(out["100"])) < 0.02
    assert abs(np.mean(out["right"]) - np.mean(out["100"])) < 0.02


def test_odometry_strides_hold_with_the_camera_rolled_on_the_shank():
    """Metamorphic: the camera turned 45 degrees about its optical axis (image x no longer along the walk) reads the
    same strides: the floor directions are orthonormal whatever the roll."""
    from pdr.pipelines.leg_camera import cut_strides
    from pdr.sim.gait import WalkKinematics

    kin = WalkKinematics.steady(speed_mps=1.3, duration_s=5.0, seed=4)
    wide = dataclasses.replace(CAM, width_px=240, height_px=240, cx_px=119.5, cy_px=119.5)
    frames, table = render_leg_camera(kin, wide, 0.5, 5.5, load_texture("gravel"), seed=5)
    turn = cv2.getRotationMatrix2D((119.5, 119.5), 45.0, 1.0)
    views = {"level": frames[:, 60:180, 40:200],
             "rolled": np.stack([cv2.warpAffine(f, turn, (240, 240), flags=cv2.INTER_LINEAR)[60:180, 40:200] for f in frames])}
    body = kin.body
    true = kin.true_strides()
    true = true[true.foot == "left"]
    for name, view in views.items():
        motion = HomographyCameraMotion(focal_px=CAM.focal_px, cx_px=CAM.cx_px, cy_px=CAM.cy_px).estimate(view, table.t_s).motion_
        est = FloorOdometryStride(shank_length_m=body.shank_m + body.ankle_height_m, ankle_height_m=body.ankle_height_m,
                                  camera_from_knee_m=CAM.distance_from_knee_m).estimate(motion, cut_strides(motion))
        k = np.abs(true.t_start_s.to_numpy()[None, :] - est.strides_.t_start_s.to_numpy()[:, None]).argmin(axis=1)
        errors = est.strides_.length_m.to_numpy() / true.length_m.to_numpy()[k] - 1
        assert len(errors) >= 2 and np.abs(errors).max() < 0.015, (name, errors)


def test_a_texture_less_stretch_of_floor_loses_its_strides_only(tmp_path):
    """Bad input: a stretch of blank floor (a painted line, a wet patch) in the middle of the walk: the strides over it
    are not given, with a warning, and the others stay right."""
    from pdr.pipelines.leg_camera import cut_strides
    from pdr.sim.gait import WalkKinematics

    gravel = load_texture("gravel")
    floor = np.tile(gravel, (1, 4))  # 2048 px = 4.1 m of floor along the walk, then mirrored
    floor[:, 1100:1500] = int(gravel.mean())  # 0.8 m without texture, about 2.2-3.0 m into the walk
    kin = WalkKinematics.steady(speed_mps=1.3, duration_s=7.0, seed=4)
    frames, table = render_leg_camera(kin, CAM, 0.5, 7.5, floor, seed=6)
    motion = HomographyCameraMotion(focal_px=CAM.focal_px, cx_px=CAM.cx_px, cy_px=CAM.cy_px).estimate(frames, table.t_s).motion_
    body = kin.body
    with warns(r"no stride cut over [\d.]+-[\d.]+ s, where frame pairs are unmeasured"):
        est = FloorOdometryStride(shank_length_m=body.shank_m + body.ankle_height_m, ankle_height_m=body.ankle_height_m,
                                  camera_from_knee_m=CAM.distance_from_knee_m).estimate(motion, cut_strides(motion))
    true = kin.true_strides()
    true = true[true.foot == "left"]
    k = np.abs(true.t_start_s.to_numpy()[None, :] - est.strides_.t_start_s.to_numpy()[:, None]).argmin(axis=1)
    errors = est.strides_.length_m.to_numpy() / true.length_m.to_numpy()[k] - 1
    assert 1 <= len(errors) <= len(true) - 3 and np.abs(errors).max() < 0.04
