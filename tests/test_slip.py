"""SLIP dynamics, leg kinematics, flow simulation and the model-to-flow fit (Liu, MS thesis ch. 3-4)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pdr.constants import GRAVITY_MPS2, REFERENCE_CADENCE_HZ
from pdr.errors import InputError, collect_warnings
from pdr.slip import SlipBody, simulate_flow, simulate_step, stride_kinematics
from pdr.slip.fit import SlipOpticalFlowStride, segment_strides
from pdr.slip.model import HIP_HEIGHT_RATIO, SWING_DESCENT_FRACTION, SWING_MIN_KNEE_RAD
from pdr.step_length.models import HEIGHT_STEP_RATIO, LEVEL_REL_STD
from conftest import warns

BODY = SlipBody()


def test_step_conserves_energy_and_ends_at_heel_strike():
    step = simulate_step(1.3, -0.2, math.radians(15), 12000.0, BODY)
    assert step is not None and step.length_m > 0.2 and 0.2 < step.duration_s < 1.5
    t = np.linspace(0, step.duration_s, 200)
    x, vx, y, vy = step.sol(t)
    length = np.hypot(x - step.heel_x_m, y)
    spring = 0.5 * 12000.0 * np.clip(BODY.leg_length_m - length, 0, None) ** 2
    energy = 0.5 * BODY.mass_kg * (vx ** 2 + vy ** 2) + BODY.mass_kg * GRAVITY_MPS2 * y + spring
    assert np.ptp(energy) / energy[0] < 1e-4
    assert abs(y[-1] - BODY.leg_length_m * math.cos(math.radians(15))) < 1e-6 and vy[-1] < 0  # h_crit, descending


def test_falling_model_returns_none():
    assert simulate_step(0.3, -1.0, math.radians(25), 3000.0, BODY) is None


def test_kinematics_lengths_contact_and_flow():
    step = simulate_step(1.3, -0.2, math.radians(15), 12000.0, BODY)
    kin = stride_kinematics(step, BODY, 0.3, stance_fraction=0.6, swing_profile="heel")
    np.testing.assert_allclose(np.hypot(*(kin.knee_m - kin.hip_m).T), BODY.thigh_length_m, atol=1e-9)
    np.testing.assert_allclose(np.hypot(*(kin.heel_m - kin.knee_m).T), BODY.shank_length_m, atol=1e-9)
    heel = kin.heel_m[kin.phase == 0]
    assert np.ptp(heel[:, 0]) == 0 and np.all(heel[:, 1] == 0)  # heel fixed during heel contact
    assert np.max(np.abs(np.diff(kin.shank_angle_rad))) < 0.05  # no jump between configurations
    assert set(np.unique(kin.phase)) == {0, 1, 2}
    flow = simulate_flow(kin, 140.0)
    # pivoting about the heel under the optical axis: no flow in heel contact; a large forward burst in swing
    assert np.max(np.abs(flow[kin.phase == 0][2:-2])) < 5.0
    assert np.max(flow[kin.phase == 2]) > 500.0
    assert kin.length_m == pytest.approx(2 * step.length_m)


def test_heel_swing_is_down_by_the_end_of_mid_swing_with_a_bent_knee():
    # Perry & Burnfield / Winter: the foot comes down to the floor by the end of mid swing and skims it to heel
    # contact; the clearance lifts the heel before that only; the knee extends to about 5 deg, straight only at contact
    step = simulate_step(1.3, -0.2, math.radians(15), 12000.0, BODY)
    kins = [stride_kinematics(step, BODY, 0.3, stance_fraction=0.6, swing_profile="heel", swing_clearance_m=c)
            for c in (0.0, 0.08)]
    low, high = kins
    sw = low.phase == 2
    i0 = int(np.flatnonzero(sw)[0]) - 1
    tau = (low.t_s - low.t_s[i0]) / (low.duration_s - low.t_s[i0])
    late, early = sw & (tau >= SWING_DESCENT_FRACTION), sw & (tau < SWING_DESCENT_FRACTION)
    np.testing.assert_allclose(high.heel_m[late], low.heel_m[late], atol=1e-12)
    assert np.max(high.heel_m[early, 1] - low.heel_m[early, 1]) > 0.05
    assert np.max(low.heel_m[late, 1]) < 0.05 < np.max(low.heel_m[sw, 1])
    # without a clearance bump the heel leaves the toe rocker at its vertical velocity (no kink at toe off)
    vy = np.diff(low.heel_m[:, 1]) / np.diff(low.t_s)
    assert vy[i0] == pytest.approx(vy[i0 - 1], rel=0.1)
    for kin in kins:
        thigh, shank = kin.knee_m - kin.hip_m, kin.heel_m - kin.knee_m
        flex = np.arccos(np.clip(np.sum(thigh * shank, axis=1) / (BODY.thigh_length_m * BODY.shank_length_m), -1, 1))
        assert np.min(flex[early]) >= SWING_MIN_KNEE_RAD - 1e-9
        # over terminal swing the least flexion fades to the SLIP's straight leg at heel strike, on the floor
        assert np.min(flex[late]) >= 0 and flex[-1] < 1e-6
        np.testing.assert_allclose(kin.heel_m[-1], [step.heel_x_m + 2 * step.length_m, 0.0], atol=1e-9)


def test_frame_displacement_flow_is_the_instantaneous_flow_at_short_intervals_and_less_at_oblique_view():
    step = simulate_step(1.3, -0.2, math.radians(15), 12000.0, BODY)
    kin = stride_kinematics(step, BODY, 0.3, stance_fraction=0.6, swing_profile="heel", swing_clearance_m=0.05)
    inst = simulate_flow(kin, 120.0)
    np.testing.assert_allclose(simulate_flow(kin, 120.0, 1e-4), inst, atol=0.01 * np.abs(inst).max())
    # over a frame of 1/60 s the floor point seen at the centre crosses the perspective of the tilted view:
    # the stride's image displacement reads less than the instantaneous flow's (about 1% with the foot down on the
    # floor in late swing, the shank steep, in this stride; up to 20% per sample on rendered walks)
    ratio = np.trapezoid(simulate_flow(kin, 120.0, 1 / 60), kin.t_s) / np.trapezoid(inst, kin.t_s)
    assert 0.9 < ratio < 0.995
    with pytest.raises(InputError, match="frame_interval_s"):
        simulate_flow(kin, 120.0, -0.01)
    with pytest.raises(InputError, match="frame_interval_s"):
        SlipOpticalFlowStride(frame_interval_s=-1.0).estimate(np.arange(100) * 0.01, np.ones(100))


def test_thesis_parabola_swing_runs():
    step = simulate_step(1.5, 0.0, math.radians(12), 18000.0, BODY)
    kin = stride_kinematics(step, BODY, 0.28, swing_profile="parabola")
    assert np.isfinite(simulate_flow(kin, 1340.0)).all()


def _measured(est, params, n_strides=4, noise=20.0, seed=0):
    tau, flow, length, dur = est.simulate(params, 0.6)
    t = np.arange(0, n_strides * dur + 0.5, 0.01) + 0.005
    f = np.interp(np.mod(t - 0.2, dur), tau, flow)
    f[t < 0.2] = 0.0
    return t, f + np.random.default_rng(seed).normal(0, noise, len(t)), length, dur


def test_segmentation_finds_heel_strikes():
    est = SlipOpticalFlowStride(camera_from_knee_m=0.3, focal_px=140.0)
    t, f, _, dur = _measured(est, (1.3, -0.2, math.radians(15), 12000.0))
    seg = segment_strides(t, f)
    assert len(seg) == 3
    np.testing.assert_allclose(np.diff(seg.t_start_s), dur, atol=0.03)
    assert np.all((seg.t_toe_off_s - seg.t_start_s) / (seg.t_end_s - seg.t_start_s) > 0.5)


def test_segmentation_leaves_out_a_stride_with_a_locked_stance():
    # a flow tracker locked on the floor pattern reads swing-level flow through the stance after a heel strike
    # (the 60 fps brick walk of the leg-camera benchmark): the burst then runs past the heel strike, and the stride
    # it forms has a stance under half of it, which no walking stride has
    est = SlipOpticalFlowStride(camera_from_knee_m=0.3, focal_px=140.0)
    t, f, _, dur = _measured(est, (1.3, -0.2, math.radians(15), 12000.0))
    clean = segment_strides(t, f)
    hs = clean.t_end_s.iloc[0]
    f[(t > hs) & (t < hs + 0.5 * dur)] = np.percentile(f, 95)
    unchecked = segment_strides(t, f, min_stance_fraction=0.0)
    stance = (unchecked.t_toe_off_s - unchecked.t_start_s) / (unchecked.t_end_s - unchecked.t_start_s)
    assert (stance < 0.5).sum() == 1  # the merged stride is cut without the check
    seg = segment_strides(t, f)
    assert len(seg) == len(unchecked) - 1
    assert np.all((seg.t_toe_off_s - seg.t_start_s) / (seg.t_end_s - seg.t_start_s) >= 0.5)
    assert seg.t_start_s.iloc[0] == clean.t_start_s.iloc[-1]  # the clean stride after the lock is kept


def test_fit_recovers_its_own_model_roughly():
    est = SlipOpticalFlowStride(camera_from_knee_m=0.3, focal_px=140.0, foot="right")
    t, f, length, _ = _measured(est, (1.3, -0.2, math.radians(15), 12000.0))
    est.estimate(t, f)
    s = est.strides_
    assert list(s.columns) == ["t_start_s", "t_end_s", "foot", "length_m", "length_std_m", "source"]
    assert len(s) == 3 and (s.foot == "right").all() and (s.source == "leg_camera").all()
    assert np.all(np.abs(s.length_m / length - 1) < 0.15)
    assert np.all(s.length_std_m > 0.02 * s.length_m)
    assert (est.fits_.time_s > 0).all()  # the fit time is reported; its speed is a benchmark row (bench_leg_camera)


def test_fit_bad_and_degenerate_input():
    est = SlipOpticalFlowStride()
    with pytest.raises(InputError, match="strictly increasing"):
        est.estimate([0.0, 0.2, 0.1], [1.0, 2.0, 3.0])
    with pytest.raises(InputError, match="one length"):
        est.estimate([0.0, 0.1], [1.0])
    with warns(match="no complete stride"):
        assert est.estimate(np.arange(100) * 0.01, np.zeros(100)).strides_.empty
    t = np.arange(0, 5, 0.01)
    with warns(match="no complete stride"):  # no flow at all (blank floor): no stride
        assert est.estimate(t, np.full(len(t), np.nan)).strides_.empty
    with pytest.raises(InputError, match="positive"):
        SlipBody(thigh_length_m=-0.5)


def test_short_flow_gaps_do_not_shorten_strides():
    est = SlipOpticalFlowStride(camera_from_knee_m=0.3, focal_px=140.0, strides_per_fit=1)
    t, f, _, dur = _measured(est, (1.3, -0.2, math.radians(15), 12000.0), n_strides=3)
    full = est.estimate(t, f).strides_.length_m.to_numpy()
    q = np.ones_like(f)
    gap = (np.mod(t - 0.2, dur) > 0.75 * dur) & (np.mod(t - 0.2, dur) < 0.80 * dur)  # 5% of each stride, mid swing
    g = np.where(gap, np.nan, f)
    holed = SlipOpticalFlowStride(**est.get_params()).estimate(t, g, np.where(gap, 0.0, q)).strides_.length_m.to_numpy()
    # the lost samples are bridged, not counted as zero flow (which would cut ~10%); the refit itself moves a little
    assert len(holed) == len(full) and np.all(holed / full > 0.97) and np.all(holed / full < 1.15)


def test_a_backward_window_gives_no_scale_and_no_crash():
    """A window whose fitted stride is negative and whose flow moved backwards (a tracker lock, a camera turned
    round) is left by the clearance passes as it is, without a division by its unchanged stride."""
    est = SlipOpticalFlowStride()
    fit = dict(flag="length", length_m=-0.4, m_per_px=0.002, length_std_m=0.05, meas_disp_px=-200.0, spread_m=0.0)
    est._clearance_from_flow([fit])
    assert fit["length_m"] == -0.4 and fit["clearance_converged"] and fit["flag"] == "length"
    fit = dict(flag="length", length_m=-0.4, m_per_px=0.002, length_std_m=0.05, meas_disp_px=-200.0, spread_m=0.0,
               meas_duration_s=1.1)
    est._clearance_from_cadence([fit])  # the default: its clearance from the cadence leaves the window as it is too
    assert fit["length_m"] == -0.4 and fit["clearance_gain"] == 0.0 and fit["flag"] == "length"


def test_swing_clearance_follows_the_measured_stride():
    # the fitted SLIP's own stride saturates near 1.0-1.2 m on rendered walks (true up to 1.6 m); the swing clearance,
    # which sets the flow-to-metres scale, is taken from the stride measured from the flow instead (a fixed point)
    est = SlipOpticalFlowStride(camera_from_knee_m=0.3, focal_px=140.0, strides_per_fit=1, scale_windows=1,
                                clearance_from="flow")
    t, f, _, _ = _measured(est, (1.3, -0.2, math.radians(15), 12000.0))
    fits = est.estimate(t, f).fits_
    np.testing.assert_allclose(fits.clearance_stride_m, fits.length_m, rtol=0.01)  # converged, self-consistent
    lengths = est.strides_.length_m.to_numpy()
    scaled = SlipOpticalFlowStride(**{**est.get_params(), "length_scale": 1.1}).estimate(t, f).strides_.length_m
    np.testing.assert_allclose(scaled, 1.1 * lengths, rtol=1e-6)  # the per-user scale stays a pure factor
    old = SlipOpticalFlowStride(**{**est.get_params(), "clearance_from": "model"}).estimate(t, f)
    assert "clearance_stride_m" not in old.fits_.columns
    # the clearance of the measured stride, not of the SLIP's own, sets the scale
    assert np.all(est.fits_.length_m.to_numpy() != old.fits_.length_m.to_numpy())
    with pytest.raises(InputError, match="clearance_from"):
        SlipOpticalFlowStride(clearance_from="thigh").estimate(t, f)


def test_swing_clearance_from_the_cadence_does_not_feed_back():
    # the clearance stride is the pedometer rule's for the body's height at the measured cadence: the stride the
    # camera measures does not set its own scale, and the walk ratio's spread joins the sigma through the gain
    est = SlipOpticalFlowStride(camera_from_knee_m=0.3, focal_px=140.0, strides_per_fit=1, scale_windows=1)
    assert est.clearance_from == "cadence"
    t, f, _, _ = _measured(est, (1.3, -0.2, math.radians(15), 12000.0))
    fits = est.estimate(t, f).fits_
    height = est.body.leg_length_m / HIP_HEIGHT_RATIO
    expected = 2.0 * HEIGHT_STEP_RATIO * height * (2.0 / fits.meas_duration_s) / REFERENCE_CADENCE_HZ
    np.testing.assert_allclose(fits.clearance_stride_m, expected, rtol=1e-5)
    g = fits.clearance_gain.to_numpy()
    assert np.all((g > 0) & (g < 1))
    assert np.all(fits.length_std_m >= g * LEVEL_REL_STD * fits.length_m - 1e-12)
    longer = SlipOpticalFlowStride(**est.get_params()).estimate(t, 1.1 * f, segments=est.segments_).fits_
    np.testing.assert_allclose(longer.clearance_stride_m, fits.clearance_stride_m, rtol=1e-12)  # timing only
    flow = SlipOpticalFlowStride(**{**est.get_params(), "clearance_from": "flow"}).estimate(t, f).fits_
    assert not np.allclose(flow.clearance_stride_m, fits.clearance_stride_m, rtol=0.01)


def test_body_from_what_a_user_knows():
    body = SlipBody.from_user(1.80)  # Winter's ratios: hip 0.530 H, knee 0.285 H, foot 0.152 H
    assert body.leg_length_m == pytest.approx(0.530 * 1.80)
    assert body.shank_length_m == pytest.approx(0.285 * 1.80) and body.foot_length_m == pytest.approx(0.152 * 1.80)
    long_legs = SlipBody.from_user(1.80, leg_length_m=1.0)  # a measured leg rescales thigh and knee height alike
    assert long_legs.leg_length_m == pytest.approx(1.0)
    assert long_legs.shank_length_m / long_legs.thigh_length_m == pytest.approx(body.shank_length_m / body.thigh_length_m)
    assert long_legs.foot_length_m == pytest.approx(body.foot_length_m)  # the toe pivot's lever: Winter's foot
    shank = SlipBody.from_user(1.80, leg_length_m=0.95, shank_length_m=0.42)  # knee to ankle + the ankle height
    assert shank.shank_length_m == pytest.approx(0.42 + 0.039 * 1.80) and shank.leg_length_m == pytest.approx(0.95)
    with pytest.raises(InputError, match="height_m"):
        SlipBody.from_user(-1.7)
    with pytest.raises(InputError, match="knee between hip and floor"):
        SlipBody.from_user(1.80, leg_length_m=0.5, shank_length_m=0.45)


def test_a_fit_that_cannot_explain_the_flow_is_flagged():
    est = SlipOpticalFlowStride(camera_from_knee_m=0.3, focal_px=140.0, strides_per_fit=1)
    t, f, length, dur = _measured(est, (1.3, -0.2, math.radians(15), 12000.0))
    good = est.estimate(t, f)
    assert (good.fits_.flag == "").all() and len(good.strides_) == 3  # the model's own flow: no failure
    assert (good.fits_.spread_m >= 0).all()
    # the same stride timing, but the swing burst replaced by flow of random sign: no SLIP stride explains it
    rng = np.random.default_rng(1)
    swing = np.mod(t - 0.2, dur) > 0.6 * dur
    bad = np.where(swing, rng.normal(0.0, np.std(f), len(t)) + 0.5 * f, f)
    with warns(match="fits failed"):
        flagged = SlipOpticalFlowStride(**est.get_params()).estimate(t, bad, segments=good.segments_)
    assert (flagged.fits_.flag != "").all() and flagged.strides_.empty


def test_impossible_mount_and_too_slow_video_give_no_stride():
    est = SlipOpticalFlowStride(camera_from_knee_m=0.3, focal_px=140.0, strides_per_fit=1)
    t, f, _, dur = _measured(est, (1.3, -0.2, math.radians(15), 12000.0))
    segs = est.estimate(t, f).segments_
    with warns(match="under the floor"):
        assert SlipOpticalFlowStride(camera_from_knee_m=0.7, focal_px=140.0).estimate(t, f).strides_.empty
    slow = slice(None, None, int(round(0.5 * dur / 0.01)))  # two samples per stride: one per step
    with warns(match="twice the cadence"):
        assert SlipOpticalFlowStride(**est.get_params()).estimate(t[slow], f[slow], segments=segs).strides_.empty


def test_a_runaway_swing_clearance_keeps_the_slip_clearance_with_a_wide_sigma():
    # a camera low over the floor (the most sensitive set-up)
    est = SlipOpticalFlowStride(camera_from_knee_m=0.45, focal_px=140.0, strides_per_fit=1, scale_windows=1,
                                clearance_from="flow")
    t, f, _, _ = _measured(est, (1.3, -0.2, math.radians(15), 12000.0))
    assert est.estimate(t, f).fits_.clearance_converged.all()
    # a clearance law this steep makes the scale grow faster than the stride: the passes run away
    steep = {**est.get_params(), "swing_clearance_ratio": 0.25}
    with collect_warnings():
        runaway = SlipOpticalFlowStride(**steep).estimate(t, f)
        own = SlipOpticalFlowStride(**{**steep, "clearance_iterations": 0}).estimate(t, f)
    fits, ref = runaway.fits_, own.fits_
    away = ~fits.clearance_converged.to_numpy()
    assert away.any()
    np.testing.assert_allclose(fits.length_m[away], ref.length_m[away], rtol=1e-9)  # the SLIP's own clearance
    assert np.all(fits.length_std_m[away] > ref.length_std_m[away])
    assert np.all(fits.length_std_m[away] >= 0.5 * fits.spread_m[away])


def test_the_clearance_fixed_point_widens_the_sigma_by_its_gain():
    # s = m(s) d: a scale error e becomes e / (1 - g); a steeper clearance law has a larger gain and a wider sigma
    est = SlipOpticalFlowStride(camera_from_knee_m=0.3, focal_px=140.0, strides_per_fit=1, scale_windows=1,
                                clearance_from="flow")
    t, f, _, _ = _measured(est, (1.3, -0.2, math.radians(15), 12000.0))
    gains = {}
    for ratio in (0.005, 0.025, 0.05):
        with collect_warnings():
            fits = SlipOpticalFlowStride(**{**est.get_params(), "swing_clearance_ratio": ratio}).estimate(t, f).fits_
        assert fits.clearance_converged.all()
        g = fits.clearance_gain.to_numpy()
        assert np.all((g >= 0) & (g < 1))
        assert np.all(fits.length_std_m / fits.length_m >= est.model_sigma_fraction / (1 - g) - 1e-9)
        # a fixed point that doubles any error of the scale (1 / (1 - g) >= 2) fails
        np.testing.assert_array_equal(fits.flag == "gain", g >= 0.5)
        gains[ratio] = float(np.median(g))
    assert gains[0.005] < 0.05 < gains[0.025] < gains[0.05]
    own = SlipOpticalFlowStride(**{**est.get_params(), "clearance_iterations": 0}).estimate(t, f).fits_
    assert (own.clearance_gain == 0).all()  # the SLIP's own clearance: no fixed point, no gain
