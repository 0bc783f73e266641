"""Fusion: factor graph (batch), iSAM2 (causal), EKF baseline; Jacobian of the custom factor; bad input."""

from __future__ import annotations

from pathlib import Path

import gtsam
from gtsam.utils.numerical_derivative import numericalDerivative21, numericalDerivative22
import numpy as np
import pandas as pd
import pytest

from benchmarks.bench_fusion import synthetic_walk
from pdr.errors import InputError, collect_warnings
from pdr.fusion import EkfFusion, FactorGraphFusion, IncrementalFusion
from pdr.fusion import factors
from pdr.step_length import RegressionStepLength
from conftest import warns

ROOT = Path(__file__).resolve().parents[1]

ALL = [FactorGraphFusion, IncrementalFusion, EkfFusion]


def rmse(traj: pd.DataFrame, truth: pd.DataFrame) -> float:
    return float(np.sqrt(np.mean((traj.e_m - truth.e_m) ** 2 + (traj.n_m - truth.n_m) ** 2)))


@pytest.fixture(scope="module")
def walk():
    return synthetic_walk(duration_s=400.0, seed=0)


@pytest.fixture(scope="module")
def graph_result(walk):
    return FactorGraphFusion().fuse(walk["steps"], gnss=walk["gnss"], step_model=RegressionStepLength.population())


def simple_steps(n: int, length_m: float = 0.7, heading_rad: float = 0.3) -> pd.DataFrame:
    t = 1.0 + 0.55 * np.arange(n)
    return pd.DataFrame({"t_s": t, "step_length_m": length_m, "step_length_std_m": 0.05,
                         "heading_rad": heading_rad, "heading_change_rad": 0.0, "heading_change_std_rad": 0.01})


# ------------------------------------------------------------------------------------------------------------------
# The custom factor
# ------------------------------------------------------------------------------------------------------------------


def test_interpolated_gnss_factor_jacobian_matches_numerical():
    for alpha in (0.0, 0.3, 0.9):
        p0 = gtsam.Pose2(1.0, -2.0, 0.7)
        p1 = gtsam.Pose2(1.5, -1.4, 1.1)
        noise = gtsam.noiseModel.Isotropic.Sigma(2, 2.0)
        factor = factors.gnss_interpolated_factor(3, alpha, np.array([1.2, -1.0]), noise)

        def whitened_error(a: gtsam.Pose2, b: gtsam.Pose2) -> np.ndarray:
            values = gtsam.Values()
            values.insert(factors.pose_key(3), a)
            values.insert(factors.pose_key(4), b)
            return factor.whitenedError(values)

        values = gtsam.Values()
        values.insert(factors.pose_key(3), p0)
        values.insert(factors.pose_key(4), p1)
        analytic = factor.linearize(values).jacobian()[0]  # whitened [H0 H1]
        numeric = np.hstack([numericalDerivative21(whitened_error, p0, p1), numericalDerivative22(whitened_error, p0, p1)])
        np.testing.assert_allclose(analytic, numeric, atol=1e-5)


def test_step_factor_moves_along_new_heading():
    factor = factors.step_factor(0, 0.8, np.pi / 2, 0.05, 0.01, 0.02)
    moved = gtsam.Pose2(0.0, 0.0, 0.0).compose(factor.measured())
    np.testing.assert_allclose([moved.x(), moved.y(), moved.theta()], [0.0, 0.8, np.pi / 2], atol=1e-12)


# ------------------------------------------------------------------------------------------------------------------
# Accuracy on a synthetic walk (richer generator than the estimators' models)
# ------------------------------------------------------------------------------------------------------------------


def test_graph_beats_ekf_and_dead_reckoning(walk, graph_result):
    truth = walk["truth"]
    ekf = EkfFusion().fuse(walk["steps"], gnss=walk["gnss"])
    dr = FactorGraphFusion().fuse(walk["steps"])
    e_graph, e_ekf = rmse(graph_result.trajectory_, truth), rmse(ekf.trajectory_, truth)
    assert e_graph < 4.0
    assert e_graph < e_ekf
    # dead reckoning starts at the origin, so compare shapes after a rigid shift of the start
    assert e_graph < rmse(dr.trajectory_.assign(e_m=dr.trajectory_.e_m + truth.e_m[0]), truth)


def test_outputs_are_well_formed(walk, graph_result):
    traj = graph_result.trajectory_
    assert list(traj.columns) == ["t_s", "e_m", "n_m", "heading_rad", "e_std_m", "n_std_m"]
    assert len(traj) == len(walk["steps"]) + 1
    assert traj.t_s.iloc[0] < walk["steps"].t_s.iloc[0]
    assert np.isfinite(traj.to_numpy()).all()
    assert (traj.e_std_m > 0).all() and (traj.e_std_m < 10).all()
    assert graph_result.gnss_used_.shape == (len(walk["gnss"]),)
    assert graph_result.step_length_m_.shape == (len(walk["steps"]),)
    assert graph_result.solver_["iterations"] > 0


def test_step_model_is_calibrated_towards_the_truth(walk, graph_result):
    steps = walk["steps"]
    model = graph_result.step_model_
    assert isinstance(model, RegressionStepLength)
    predicted = model.a_m + model.b_m_per_hz * steps.step_freq_hz + model.c_m_per_m2ps4 * steps.acc_var_m2ps4
    prior = 0.384 * steps.step_freq_hz
    true_total = walk["true_length_m"].sum()
    assert abs(prior.sum() - true_total) / true_total > 0.03  # the population model is off for this walker
    assert abs(predicted.sum() - true_total) / true_total < 0.015
    assert abs(graph_result.step_length_m_.sum() - true_total) / true_total < 0.015


def test_step_scale_keeps_the_given_lengths_and_calibrates_their_level(walk):
    # per-form step lengths that are 8% short for this walker: GNSS calibrates one scale of them, the relative lengths
    # stay; without GNSS (or with the regression calibrated) the scale stays 1. On this walk the fixes read the steps
    # 1.3% longer than the truth; the std is the marginal one with GNSS's correlated error (about 1.4%), so the
    # truth lies within 2 sigma
    steps = walk["steps"].assign(step_length_m=0.92 * walk["true_length_m"])
    fusion = FactorGraphFusion(calibrate_step_model=False, calibrate_step_scale=True)
    fusion.fuse(steps, gnss=walk["gnss"])
    scale = fusion.step_scale_
    assert scale["calibrated"] and 0.005 < scale["std"] < 0.02
    assert abs(scale["scale"] - 1 / 0.92) < 2 * scale["std"]
    true_total = walk["true_length_m"].sum()
    assert abs(fusion.step_length_m_.sum() - true_total) / true_total < 0.015
    assert FactorGraphFusion(calibrate_step_model=False, calibrate_step_scale=True).fuse(steps).step_scale_ == {
        "scale": 1.0, "std": 0.1, "prior_std": 0.1, "calibrated": False}
    assert not FactorGraphFusion(calibrate_step_scale=True).fuse(steps, gnss=walk["gnss"]).step_scale_["calibrated"]


def test_the_calibration_converges_to_the_joint_optimum(tmp_path):
    # the README's walk: waist IMU with a magnetometer, GNSS with outliers. The gyro bias and the magnetometer deviation
    # both turn the path; solved block by block they undid each other and the alternation stopped unconverged after
    # 12 rounds (then 19-26 rounds without the cap). With the joint Gauss-Newton step: a few rounds, and a further
    # alternation from the solution moves nothing.
    from pdr.pipelines.run import run_recording
    from pdr.sim import simulate_to_disk

    rec = simulate_to_disk(ROOT / "configs" / "sim" / "walk_short.toml", tmp_path / "walk", seed=2)
    with collect_warnings():
        summary = run_recording(rec, tmp_path / "out", force=True)
    assert summary["solver"]["converged"] and summary["solver"]["alternations"] <= 6
    assert not any("did not converge" in w["message"] for w in summary["warnings"])


def test_an_unconverged_heading_calibration_is_said(walk):
    # without GNSS nothing of the step model is calibrated, but the gyro bias and the magnetometer deviation are: when
    # their alternation stops short, the run says so (it kept no step model, so it does not say that)
    fusion = FactorGraphFusion(max_alternations=1)
    with warns(r"did not converge in 1 alternations .*largest in the (gyro bias|magnetometer deviation)\)$") as caught:
        fusion.fuse(walk["steps"])
    assert not fusion.solver_["converged"] and not any("step model given is kept" in m for m in caught)


def test_joint_step_agrees_with_the_normal_equations():
    # the banded Cholesky solve of the poses' normal matrix and the sparse LU give the same answer; a wide band falls
    # back to the LU
    import scipy.sparse
    from pdr.fusion import _calibration

    rng = np.random.default_rng(0)
    n = 60
    a = scipy.sparse.random(3 * n, n, density=0.05, random_state=1) + scipy.sparse.eye(3 * n, n)
    chain = scipy.sparse.diags([np.ones(n), -0.5 * np.ones(n - 1), 0.2 * np.ones(n - 3)], [0, 1, 3])
    h_band = (chain.T @ chain + 0.1 * scipy.sparse.eye(n)).tocsc()
    rhs = rng.standard_normal((n, 4))
    np.testing.assert_allclose(_calibration.solve_normal(h_band, rhs), np.linalg.solve(h_band.toarray(), rhs), atol=1e-9)
    h_wide = (a.T @ a).tocsc()
    np.testing.assert_allclose(_calibration.solve_normal(h_wide, rhs), np.linalg.solve(h_wide.toarray(), rhs), atol=1e-8)
    singular = scipy.sparse.diags(np.r_[np.ones(n - 1), 0.0]).tocsc()
    assert _calibration.solve_normal(singular, rhs) is None


def test_gnss_outliers_are_rejected_and_do_not_pull_the_path():
    clean = synthetic_walk(duration_s=300.0, seed=5)
    dirty = synthetic_walk(duration_s=300.0, seed=5, outlier_fraction=0.1)
    jumped = np.hypot(dirty["gnss"].e_m - clean["gnss"].e_m, dirty["gnss"].n_m - clean["gnss"].n_m).to_numpy() > 1
    f_clean = FactorGraphFusion().fuse(clean["steps"], gnss=clean["gnss"])
    f_dirty = FactorGraphFusion().fuse(dirty["steps"], gnss=dirty["gnss"])
    assert jumped.sum() > 10
    assert (~f_dirty.gnss_used_[jumped]).mean() > 0.9
    assert f_dirty.gnss_used_[~jumped].mean() > 0.9
    assert rmse(f_dirty.trajectory_, dirty["truth"]) < 1.2 * rmse(f_clean.trajectory_, clean["truth"])


def test_shifted_and_interpolated_gnss_factors_agree():
    w = synthetic_walk(duration_s=120.0, seed=2)
    a = FactorGraphFusion(gnss_factor="shifted").fuse(w["steps"], gnss=w["gnss"])
    b = FactorGraphFusion(gnss_factor="interpolated").fuse(w["steps"], gnss=w["gnss"])
    diff = np.hypot(a.trajectory_.e_m - b.trajectory_.e_m, a.trajectory_.n_m - b.trajectory_.n_m)
    assert diff.max() < 0.1


def test_rotating_the_inputs_rotates_the_path():
    w = synthetic_walk(duration_s=150.0, seed=4, with_mag=False)
    angle = 0.9
    c, s = np.cos(angle), np.sin(angle)
    steps = w["steps"].assign(heading_rad=w["steps"].heading_rad + angle)
    gnss = w["gnss"].assign(e_m=c * w["gnss"].e_m - s * w["gnss"].n_m, n_m=s * w["gnss"].e_m + c * w["gnss"].n_m)
    a = FactorGraphFusion().fuse(w["steps"], gnss=w["gnss"]).trajectory_
    b = FactorGraphFusion().fuse(steps, gnss=gnss).trajectory_
    np.testing.assert_allclose(b.e_m, c * a.e_m - s * a.n_m, atol=0.05)
    np.testing.assert_allclose(b.n_m, s * a.e_m + c * a.n_m, atol=0.05)


def test_strides_correct_the_scale_without_gnss():
    steps = simple_steps(40, length_m=0.7, heading_rad=0.0)
    t = steps.t_s.to_numpy()
    strides = pd.DataFrame({"t_start_s": t[0:-2:2], "t_end_s": t[2::2], "foot": "left", "length_m": 1.54,
                            "length_std_m": 0.02, "source": "foot_imu"})
    plain = FactorGraphFusion().fuse(steps)
    fused = FactorGraphFusion().fuse(steps, strides=strides)
    assert plain.trajectory_.e_m.iloc[-1] == pytest.approx(40 * 0.7, abs=0.01)
    assert fused.trajectory_.e_m.iloc[-1] > 40 * 0.75


def test_magnetometer_heading_and_gyro_bias_without_gnss():
    steps = simple_steps(300, heading_rad=0.0)
    drift = 0.002  # rad per step of gyro drift; the true walk is straight east
    steps["heading_change_rad"] = drift
    steps["heading_rad"] = drift * np.arange(300)
    steps["mag_heading_rad"] = 0.0
    steps["mag_heading_std_rad"] = 0.05
    fused = FactorGraphFusion().fuse(steps)
    dr = FactorGraphFusion().fuse(steps.drop(columns=["mag_heading_rad", "mag_heading_std_rad"]))
    assert abs(fused.trajectory_.n_m.iloc[-1]) < 0.2 * abs(dr.trajectory_.n_m.iloc[-1])


# ------------------------------------------------------------------------------------------------------------------
# iSAM2 and the EKF
# ------------------------------------------------------------------------------------------------------------------


def test_incremental_is_causal_and_close_to_batch():
    w = synthetic_walk(duration_s=200.0, seed=6)
    full = IncrementalFusion().fuse(w["steps"], gnss=w["gnss"])
    half_steps = w["steps"].iloc[:150]
    half = IncrementalFusion().fuse(half_steps, gnss=w["gnss"][w["gnss"].t_s <= half_steps.t_s.iloc[-1]])
    np.testing.assert_allclose(full.trajectory_.e_m.iloc[:151], half.trajectory_.e_m, atol=1e-9)
    assert rmse(full.smoothed_trajectory_, w["truth"]) < 10.0
    assert full.solver_["causal"] and full.solver_["time_per_step_ms"] > 0


@pytest.mark.parametrize("cls", ALL)
def test_without_gnss_the_start_is_the_origin_and_the_first_heading(cls):
    steps = simple_steps(10, heading_rad=0.3)
    traj = cls().fuse(steps).trajectory_
    assert traj.e_m.iloc[0] == pytest.approx(0.0, abs=1e-3) and traj.n_m.iloc[0] == pytest.approx(0.0, abs=1e-3)
    assert traj.e_m.iloc[-1] == pytest.approx(7.0 * np.cos(0.3), abs=0.01)
    assert traj.n_m.iloc[-1] == pytest.approx(7.0 * np.sin(0.3), abs=0.01)
    assert traj.e_std_m.iloc[-1] > traj.e_std_m.iloc[1]


# ------------------------------------------------------------------------------------------------------------------
# Bad and degenerate input
# ------------------------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("cls", ALL)
def test_zero_steps_warns_and_returns_empty(cls):
    with warns(match="empty"):
        f = cls().fuse(simple_steps(0), gnss=pd.DataFrame({"t_s": [1.0], "e_m": [0.0], "n_m": [0.0]}))
    assert len(f.trajectory_) == 0 and list(f.trajectory_.columns)[:3] == ["t_s", "e_m", "n_m"]
    assert f.gnss_used_.shape == (1,) and not f.gnss_used_.any()


@pytest.mark.parametrize("cls", ALL)
def test_one_step_and_single_fix(cls):
    gnss = pd.DataFrame({"t_s": [1.0], "e_m": [10.0], "n_m": [5.0], "h_acc_m": [1.0]})
    f = cls().fuse(simple_steps(1), gnss=gnss)
    assert len(f.trajectory_) == 2 and np.isfinite(f.trajectory_[["e_m", "n_m"]].to_numpy()).all()
    assert f.trajectory_.e_m.iloc[1] == pytest.approx(10.0, abs=0.5)
    assert f.gnss_used_.tolist() == [True]


@pytest.mark.parametrize("cls", ALL)
def test_all_fixes_invalid_is_dead_reckoning(cls):
    gnss = pd.DataFrame({"t_s": [1.5, 2.5], "e_m": [np.nan, np.nan], "n_m": [np.nan, np.nan], "h_acc_m": [3.0, 3.0]})
    f = cls().fuse(simple_steps(10), gnss=gnss)
    assert not f.gnss_used_.any()
    assert f.trajectory_.e_m.iloc[0] == pytest.approx(0.0, abs=1e-3)


def test_fixes_before_the_first_step_are_not_used():
    gnss = pd.DataFrame({"t_s": [-50.0, 2.0, 4.0], "e_m": [0.0, 1.0, 2.0], "n_m": [0.0, 0.5, 1.0]})
    with warns(match="before the first step"):
        f = FactorGraphFusion().fuse(simple_steps(10), gnss=gnss)
    assert f.gnss_used_.tolist() == [False, True, True]


def test_duplicate_fixes():
    gnss = pd.DataFrame({"t_s": [2.0, 2.0, 4.0], "e_m": [1.0, 1.0, 2.0], "n_m": [0.5, 0.5, 1.0]})
    with warns(match="duplicated"):
        f = FactorGraphFusion().fuse(simple_steps(10), gnss=gnss)
    assert f.gnss_used_.tolist() == [True, False, True]
    conflicting = gnss.assign(e_m=[1.0, 30.0, 2.0])
    with pytest.raises(InputError, match="two different fixes at t_s = 2.0"):
        FactorGraphFusion().fuse(simple_steps(10), gnss=conflicting)


@pytest.mark.parametrize("mutate, message", [
    (lambda s: s.drop(columns=["step_length_m"]), "missing step_length_m"),
    (lambda s: s.assign(step_length_m=s.step_length_m * 100), "metres"),
    (lambda s: s.assign(t_s=s.t_s[::-1].to_numpy()), "strictly increasing"),
    (lambda s: s.assign(t_s=np.where(np.arange(len(s)) == 3, np.nan, s.t_s)), "finite t_s"),
    (lambda s: s.assign(step_length_m=np.nan), "finite step_length_m"),
    (lambda s: s.drop(columns=["heading_rad", "heading_change_rad"]), "heading"),
])
def test_bad_steps_are_input_errors(mutate, message):
    for cls in ALL:
        with pytest.raises(InputError, match=message):
            cls().fuse(mutate(simple_steps(10)))


def test_bad_gnss_and_params_are_input_errors():
    steps = simple_steps(10)
    with pytest.raises(InputError, match="increasing order"):
        FactorGraphFusion().fuse(steps, gnss=pd.DataFrame({"t_s": [3.0, 2.0], "e_m": [0.0, 1.0], "n_m": [0.0, 1.0]}))
    with pytest.raises(InputError, match="missing n_m"):
        FactorGraphFusion().fuse(steps, gnss=pd.DataFrame({"t_s": [3.0], "e_m": [0.0]}))
    with pytest.raises(InputError, match="degrees"):
        FactorGraphFusion().fuse(steps, gnss=pd.DataFrame({"t_s": [3.0], "e_m": [4.0e6], "n_m": [5.0e6]}))
    with pytest.raises(InputError, match="gnss_factor"):
        FactorGraphFusion(gnss_factor="snap").fuse(steps)
    with pytest.raises(InputError, match="unknown parameter"):
        FactorGraphFusion.from_config({"huber": 2.0})


def test_indeterminate_graph_never_leaks_a_gtsam_error():
    # no GNSS, no heading information at all after a bout break: still a documented default, never a gtsam error
    steps = simple_steps(10).drop(columns=["heading_change_rad"])
    steps["heading_rad"] = np.nan
    with collect_warnings() as caught:
        traj = FactorGraphFusion().fuse(steps).trajectory_
    assert not caught
    assert traj.heading_rad.iloc[0] == 0.0 and np.isfinite(traj.e_m).all()


# ------------------------------------------------------------------------------------------------------------------
# Gaps, gating, magnetometer deviation
# ------------------------------------------------------------------------------------------------------------------


def square_walk(n: int = 400, seed: int = 0, deviation=(0.05, 0.1, 0.0, 0.0, 0.0)):
    """Laps of a square (50 steps a side) with GNSS every 2 steps and a magnetometer with a deviation curve."""
    rng = np.random.default_rng(seed)
    heading = (np.arange(n) // 50) * (np.pi / 2)
    steps = simple_steps(n, heading_rad=0.0)
    steps["heading_rad"] = heading
    steps["heading_change_rad"] = np.diff(heading, prepend=heading[0])
    dev = np.column_stack([np.ones(n), np.cos(heading), np.sin(heading), np.cos(2 * heading), np.sin(2 * heading)])
    steps["mag_heading_rad"] = heading + dev @ np.asarray(deviation) + 0.02 * rng.standard_normal(n)
    steps["mag_heading_std_rad"] = 0.05
    e = np.concatenate([[0.0], np.cumsum(0.7 * np.cos(heading))])
    nn = np.concatenate([[0.0], np.cumsum(0.7 * np.sin(heading))])
    t = np.concatenate([[steps.t_s[0] - 0.55], steps.t_s])
    gnss = pd.DataFrame({"t_s": t[::2] + 0.1, "e_m": e[::2] + rng.standard_normal(len(t[::2])),
                         "n_m": nn[::2] + rng.standard_normal(len(t[::2])), "h_acc_m": 1.0})
    return steps, gnss, e, nn


def test_magnetometer_deviation_curve_is_calibrated():
    steps, gnss, _, _ = square_walk()
    f = FactorGraphFusion().fuse(steps, gnss=gnss)
    # sin 2h is zero on a square's four headings (not observable here): compare the rest and the curve where walked
    np.testing.assert_allclose(f.mag_deviation_coef_[:4], [0.05, 0.1, 0.0, 0.0], atol=0.03)
    true = 0.05 + 0.1 * np.cos(steps.heading_rad.to_numpy())
    np.testing.assert_allclose(f.mag_deviation_rad_, true, atol=0.02)


def test_gate_keeps_long_runs_of_rejected_fixes():
    from pdr.fusion._solve import gate

    d2 = np.ones(40)
    d2[3] = 100.0  # a lone outlier
    d2[10:25] = 100.0  # 15 in a row: the path is wrong, not the fixes
    use = gate(d2, 13.8, 10)
    assert not use[3] and use[10:25].all() and use.sum() == 39


def test_gap_step_lets_gnss_say_where_the_walker_went():
    steps = simple_steps(60, heading_rad=0.0)
    t = steps.t_s.to_numpy().copy()
    t[30:] += 40.0  # 40 s of missed steps, walked at 1 m/s east
    steps["t_s"] = t
    truth_e = np.where(np.arange(60) < 30, 0.7 * (np.arange(60) + 1), 0.7 * (np.arange(60) + 1) + 40.0)
    fix_t = np.arange(t[0], t[-1], 1.0)
    fix_e = np.interp(fix_t, t, truth_e)
    gnss = pd.DataFrame({"t_s": fix_t, "e_m": fix_e, "n_m": 0.0, "h_acc_m": 1.0})
    f = FactorGraphFusion(calibrate_step_model=False).fuse(steps, gnss=gnss)
    assert f.trajectory_.e_m.iloc[-1] == pytest.approx(truth_e[-1], abs=1.0)
    assert f.gnss_used_.mean() > 0.95


def test_masked_fixes_are_not_used():
    steps, gnss, _, _ = square_walk(100)
    gnss["masked"] = gnss.t_s > 20.0
    f = FactorGraphFusion().fuse(steps, gnss=gnss)
    assert not f.gnss_used_[gnss.masked.to_numpy()].any() and f.gnss_used_[~gnss.masked.to_numpy()].all()


def test_incremental_uses_a_given_calibration():
    steps, gnss, e, n = square_walk(200)
    batch = FactorGraphFusion().fuse(steps, gnss=gnss)
    plain = IncrementalFusion().fuse(steps)
    calibrated = IncrementalFusion(mag_deviation_coef=batch.mag_deviation_coef_.tolist()).fuse(steps)
    err = lambda tr: np.hypot(tr.e_m - e, tr.n_m - n).max()  # noqa: E731
    assert err(calibrated.trajectory_) < 0.5 * err(plain.trajectory_)
    with pytest.raises(InputError, match="mag_deviation_coef"):
        IncrementalFusion(mag_deviation_coef=[0.1]).fuse(steps)
