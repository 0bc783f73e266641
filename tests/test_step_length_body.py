"""The step model of a person never calibrated (body and placement), Bayesian calibration toward it, known-distance
calibration, the graph's in-run calibration guard, and the simulated people it is measured on."""

from __future__ import annotations

import json
import re
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pdr.calibration import AdaptiveKalmanCalibration
from pdr.calibration.segments import distance_segments, landmark_distances, trajectory_distances
from pdr.cli.main import main
from pdr.errors import InputError, collect_warnings
from pdr.fusion import FactorGraphFusion
from pdr.fusion._linear import bounded_map
from pdr.io.recording import check_subject, load_recording, save_recording
from pdr.sim import simulate
from pdr.sim.people import Body, GaitUser
from pdr.step_length import RegressionStepLength, ZijlstraStepLength, body_model, choose_model, load_model
from conftest import warns

ROOT = Path(__file__).resolve().parents[1]


# ------------------------------------------------------------------------------------------------ the body default
def test_trunk_sensor_gets_the_pendulum_with_the_best_length_known():
    m, choice = body_model({"height_m": 1.62, "leg_length_m": 0.85, "sensor_height_m": 0.98}, "waist")
    assert isinstance(m, ZijlstraStepLength) and m.sensor_height_m == 0.98 and choice["source"] == "subject.sensor_height_m"
    m, choice = body_model({"height_m": 1.62, "leg_length_m": 0.85}, "trunk")
    assert m.sensor_height_m == 0.85 and choice["source"] == "subject.leg_length_m"
    m, choice = body_model({"height_m": 1.80}, "waist")
    assert m.sensor_height_m == pytest.approx(0.53 * 1.80) and choice["source"] == "subject.height_m"


def test_phone_gets_the_height_and_cadence_model_scaled_with_height():
    short, _ = body_model({"height_m": 1.50}, "hand")
    tall, choice = body_model({"height_m": 1.95}, "pocket")
    assert isinstance(tall, RegressionStepLength) and "height" in choice["reason"]
    steps = pd.DataFrame({"step_freq_hz": [1.8], "acc_var_m2ps4": [4.0]})
    ratio = tall.estimate(steps).step_length_m_[0] / short.estimate(steps).step_length_m_[0]
    assert ratio == pytest.approx(1.95 / 1.50, rel=1e-3)  # the model scales with the body
    assert tall.b_m_per_hz > 0 and np.sqrt(tall.covariance[1][1]) < tall.b_m_per_hz / 3  # a negative slope is > 3 sigma


def test_nothing_known_says_so_once_and_uses_the_population():
    with warns(match="nothing known about the person") as record:
        m, choice = body_model({}, "waist")
    assert len(record) == 1 and choice["source"] == "population"
    assert m.sensor_height_m == pytest.approx(0.53 * 1.70)


def test_an_explicit_choice_wins():
    m, choice = choose_model({"step_length": {"model": "kim"}}, {"height_m": 1.7, "sensor_height_m": 1.0}, "waist")
    assert m.name == "kim" and choice["source"] == "configuration"


@pytest.mark.parametrize("subject, message", [
    ({"height_m": 175}, "centimetres"),
    ({"height_m": 1.75, "leg_length_m": 1.9}, "leg longer than the body"),
    ({"height_m": 1.75, "sensor_height_m": 1.8}, "sensor above the head"),
    ({"sensor_height_m": 98}, "centimetres"),
    ({"height_m": 1.75, "leg_length_m": 0.4}, "of height_m"),
])
def test_implausible_subjects_are_one_error(subject, message):
    with pytest.raises(InputError, match=message):
        check_subject(subject)


@pytest.mark.parametrize("key, value, message", [("height_m", "175", "centimetres"),
                                                 ("leg_length_m", "1.9", "leg longer than the body"),
                                                 ("sensor_height_m", "1.9", "sensor above the head")])
def test_cli_run_with_an_implausible_subject_is_one_error_line(tmp_path, capsys, key, value, message):
    rec = simulate({"route": {"waypoints_m": [[0, 0], [50, 0]]},
                    "segment": [{"duration_s": 2, "speed_mps": 0}, {"duration_s": 8, "speed_mps": 1.3}]}, seed=1)
    path = save_recording(rec, tmp_path / "rec")
    meta = (path / "meta.toml").read_text()
    meta, n = re.subn(rf"^{key} = .*$", f"{key} = {value}", meta, flags=re.M)
    assert n == 1
    (path / "meta.toml").write_text(meta)
    assert main(["run", str(path), "-o", str(tmp_path / "out")]) == 1
    err = capsys.readouterr().err
    assert err.startswith("error:") and message in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()


def test_run_records_the_choice_in_summary(tmp_path):
    from pdr.pipelines.run import run_recording

    rec = simulate({"route": {"waypoints_m": [[0, 0], [80, 0]]}, "gnss": {"enabled": False},
                    "segment": [{"duration_s": 2, "speed_mps": 0}, {"duration_s": 20, "speed_mps": 1.2}]}, seed=2)
    path = save_recording(rec, tmp_path / "rec")
    with collect_warnings():
        summary = run_recording(path, tmp_path / "out")
    choice = json.loads((tmp_path / "out" / "summary.json").read_text())["step_model"]["choice"]
    assert choice == summary["step_model"]["choice"]
    assert choice["model"] == "zijlstra" and choice["source"] == "subject.sensor_height_m"


# ------------------------------------------------------------------------------------------------ Bayesian calibration
def test_bounded_map_holds_a_negative_parameter_at_zero():
    info = np.array([[4.0, 1.0], [1.0, 2.0]])
    rhs = info @ np.array([0.5, -0.3])
    free, _ = bounded_map(info, rhs)
    held, cov = bounded_map(info, rhs, (1,))
    assert free[1] == pytest.approx(-0.3) and held[1] == 0.0
    assert held[0] == pytest.approx(rhs[0] / info[0, 0])  # the conditional mean of the other
    assert cov.shape == (2, 2) and cov[1, 1] > 0


def _steps(freq: np.ndarray, seed: int) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    t = np.cumsum(1.0 / freq)
    return pd.DataFrame({"t_s": t, "bout_id": 0, "step_freq_hz": freq, "acc_var_m2ps4": 3.0 + 0.1 * rng.standard_normal(len(t))})


def test_calibration_never_reaches_a_negative_slope():
    freq = np.repeat([1.5, 1.8, 2.1], 200)
    steps = _steps(freq, 1)
    length = 1.3 - 0.3 * freq  # a walker whose steps shorten as the cadence rises (what noisy GNSS can suggest)
    known = pd.DataFrame({"t_start_s": [steps.t_s[k] for k in range(0, 580, 20)],
                          "t_end_s": [steps.t_s[k + 20] for k in range(0, 580, 20)],
                          "distance_m": [length[k + 1:k + 21].sum() for k in range(0, 580, 20)], "distance_std_m": 0.05})
    with warns(match="held at 0"):  # a steady level (the default): only the slope can follow the cadence
        akf = AdaptiveKalmanCalibration().fit(steps, None, RegressionStepLength.population(), distances=known)
    assert akf.updated_ == "all" and akf.model_.b_m_per_hz == 0.0
    with collect_warnings():  # the level may drift instead (the cadence rose through the walk): never a negative slope
        akf = AdaptiveKalmanCalibration(level_drift_std_m=None).fit(steps, None, RegressionStepLength.population(),
                                                                    distances=known)
    assert akf.model_.b_m_per_hz >= 0.0


def _leg_distances(steps: pd.DataFrame, length: np.ndarray, every: int, std_m: float, seed: int) -> pd.DataFrame:
    """Known distances of consecutive legs of ``every`` steps, measured to ``std_m``."""
    rng = np.random.default_rng(seed)
    starts = range(0, len(steps) - every, every)
    return pd.DataFrame({"t_start_s": [steps.t_s[k] for k in starts], "t_end_s": [steps.t_s[k + every] for k in starts],
                         "distance_m": [length[k + 1:k + every + 1].sum() + std_m * rng.standard_normal() for k in starts],
                         "distance_std_m": std_m})


def test_calibration_follows_a_drifting_level_and_keeps_a_steady_one():
    freq = np.full(600, 1.8)
    steps = _steps(freq, 4)
    prior = RegressionStepLength.population()
    table = _leg_distances(steps, np.full(600, 0.75), 20, 0.3, 1)
    akf = AdaptiveKalmanCalibration(level_drift_std_m=None).fit(steps, None, prior, distances=table)
    static = AdaptiveKalmanCalibration().fit(steps, None, prior, distances=table)
    assert akf.level_drift_std_m_ == 0.0 and np.allclose(akf.model_.theta, static.model_.theta)
    shortening = np.linspace(0.85, 0.70, 600)  # the step shortens through the walk at the same cadence
    table = _leg_distances(steps, shortening, 20, 0.3, 2)
    akf = AdaptiveKalmanCalibration(level_drift_std_m=None).fit(steps, None, prior, distances=table)
    static = AdaptiveKalmanCalibration().fit(steps, None, prior, distances=table)  # the default: steady
    last = {m: float(m.estimate(steps.iloc[-1:]).step_length_m_[0]) for m in (akf.model_, static.model_)}
    assert akf.level_drift_std_m_ > 0
    assert abs(last[akf.model_] - 0.70) < 0.02 and abs(last[static.model_] - 0.775) < 0.02  # the end, not the mean
    # a TOML [calibration] section has no None: "estimate" asks for the same
    toml = AdaptiveKalmanCalibration.from_config(tomllib.loads('level_drift_std_m = "estimate"')).fit(
        steps, None, prior, distances=table)
    assert toml.level_drift_std_m_ == akf.level_drift_std_m_ and np.allclose(toml.model_.theta, akf.model_.theta)
    for bad in (-1.0, "auto"):
        with pytest.raises(InputError, match="level_drift_std_m"):
            AdaptiveKalmanCalibration(level_drift_std_m=bad).fit(steps, None, prior, distances=table)


def test_running_does_not_calibrate_a_walking_model():
    freq = np.repeat([1.8, 2.8], 200)  # walking at 0.75 m x 1.8/s = 1.35 m/s, then running at 1.0 m x 2.8/s = 2.8 m/s
    steps = _steps(freq, 3)
    length = np.where(freq < 2.5, 0.75, 1.0)
    table = _leg_distances(steps, length, 20, 0.05, 3)
    akf = AdaptiveKalmanCalibration().fit(steps, None, RegressionStepLength.population(), {"height_m": 1.75},
                                          distances=table)
    segs = akf.model_segments_
    running = segs["freq_hz"] > 2.5
    assert running.any() and not segs.loc[running, "used"].any() and segs.loc[~running, "used"].all()
    assert segs.loc[running, "reason"].str.startswith("running").all()
    walking = AdaptiveKalmanCalibration().fit(steps, None, RegressionStepLength.population(), {"height_m": 1.75},
                                              distances=table[~running.to_numpy()].reset_index(drop=True))
    assert np.allclose(akf.model_.theta, walking.model_.theta)  # the run adds nothing to the walking model


# ------------------------------------------------------------------------------------------------ known distances
def test_a_walk_of_known_length_sets_the_level_and_scales_with_it():
    freq = np.full(300, 1.8)
    steps = _steps(freq, 2)
    prior = RegressionStepLength.population()
    models = []
    for d in (240.0, 264.0):
        table = pd.DataFrame({"t_start_s": [np.nan], "t_end_s": [np.nan], "distance_m": [d], "distance_std_m": [0.01 * d]})
        akf = AdaptiveKalmanCalibration().fit(steps, None, prior, distances=table)
        models.append(akf.model_.estimate(steps).step_length_m_.sum())
        assert akf.updated_ == "level" and akf.n_steps_ == 300
    assert models[0] == pytest.approx(240.0, rel=0.01) and models[1] / models[0] == pytest.approx(1.1, rel=0.01)


def test_landmark_and_trajectory_distances():
    lm = pd.DataFrame({"t_s": [0.0, 10.0, 20.0], "e_m": [0.0, 12.0, 12.0], "n_m": [0.0, 0.0, 5.0]})
    d = landmark_distances(lm, 0.3)
    assert list(d["distance_m"]) == [12.0, 5.0] and np.allclose(d["distance_std_m"], np.sqrt(2) * 0.3)
    traj = pd.DataFrame({"t_s": np.arange(0, 61.0), "e_m": np.arange(0, 61.0), "n_m": 0.0})
    d = trajectory_distances(traj, 30.0, 0.05)
    assert list(d["distance_m"]) == pytest.approx([30.0, 30.0])
    steps = _steps(np.full(120, 2.0), 3)  # contacts every 0.5 s from 0.5 s
    seg = distance_segments(steps, d, min_segment_steps=8, min_step_m=0.2, max_step_m=1.6)
    assert seg["used"].all() and seg["n_steps"].iloc[1] == pytest.approx(60.0)


def _pocket_walk(path: Path, with_gnss: bool, seed: int) -> Path:
    scenario = {"subject": {"height_m": 1.72}, "route": {"waypoints_m": [[0, 0], [300, 0]], "loop": False},
                "imu": [{"placement": "pocket", "rate_hz": 100.0}], "gnss": {"enabled": with_gnss},
                "segment": [{"duration_s": 2, "speed_mps": 0}, {"duration_s": 60, "speed_mps": 1.3},
                            {"duration_s": 2, "speed_mps": 0}]}
    return save_recording(simulate(scenario, seed), path)


def test_cli_calibrate_from_a_known_distance_mixed_with_gnss(tmp_path, capsys):
    corridor = _pocket_walk(tmp_path / "corridor", with_gnss=False, seed=4)
    outdoor = _pocket_walk(tmp_path / "outdoor", with_gnss=True, seed=5)
    truth = load_recording(corridor).reference["summary"]["distance_m"]
    out = tmp_path / "model.json"
    assert main(["calibrate", str(corridor), str(outdoor), "-o", str(out), "--distance-m", f"{truth:.2f}"]) == 0
    line = capsys.readouterr().out
    assert "distance, gnss" in line
    doc = json.loads(out.read_text())
    assert doc["info"]["sources"] == ["distance", "gnss"] and doc["info"]["prior"]["model"] == "regression"
    assert load_model(out).b_m_per_hz >= 0


@pytest.mark.parametrize("value", ["0", "-5", "nan", "ten"])
def test_cli_distance_must_be_positive_metres(tmp_path, capsys, value):
    with pytest.raises(SystemExit) as exc:
        main(["calibrate", str(tmp_path), "-o", str(tmp_path / "m.json"), "--distance-m", value])
    assert exc.value.code == 2 and "--distance-m" in capsys.readouterr().err


def test_cli_calibrate_more_distances_than_recordings_is_an_error(tmp_path, capsys):
    corridor = _pocket_walk(tmp_path / "corridor", with_gnss=False, seed=4)
    assert main(["calibrate", str(corridor), "-o", str(tmp_path / "m.json"), "--distance-m", "50",
                 "--distance-m", "60"]) == 1
    assert "at most one --distance-m per recording" in capsys.readouterr().err


# ------------------------------------------------------------------------------------------------ graph guard
def test_graph_warns_when_the_calibration_does_not_converge_and_keeps_the_model():
    rec = simulate({"route": {"waypoints_m": [[0, 0], [100, 0], [100, 60]]},
                    "imu": [{"placement": "pocket", "rate_hz": 100.0}],
                    "segment": [{"duration_s": 2, "speed_mps": 0}, {"duration_s": 60, "speed_mps": 1.4}]}, seed=6)
    from pdr.pipelines.pipeline import fusion_gnss, gnss_local, gnss_settings
    from pdr.pipelines.steps import detect_steps

    with collect_warnings():
        steps = detect_steps(rec, {})
    model = RegressionStepLength.for_height(rec.subject["height_m"])
    model.estimate(steps)
    steps["step_length_m"], steps["step_length_std_m"] = model.step_length_m_, model.step_length_std_m_
    gnss = fusion_gnss(gnss_local(rec, gnss_settings({})))
    with warns(match="did not converge in 1 alternations"):
        fusion = FactorGraphFusion(max_alternations=1).fuse(steps, gnss=gnss, step_model=model)
    assert not fusion.solver_["converged"] and fusion.solver_["last_change_m"] > 0
    assert fusion.step_model_ is model
    with collect_warnings():
        full = FactorGraphFusion().fuse(steps, gnss=gnss, step_model=model)
    assert full.step_model_.b_m_per_hz >= 0


# ------------------------------------------------------------------------------------------------ simulated people
def test_simulated_step_length_is_not_a_line_in_frequency():
    user, body = GaitUser(), Body(1.75)
    leg = body.leg_length_m
    v = np.linspace(1.1, 1.5, 5)  # a line fitted at normal paces ...
    line = np.polyfit(user.step_freq_hz(v, leg), user.step_length_m(v, leg), 1)
    slow = user.step_freq_hz(0.5, leg)  # ... is 3% long for the same person at 0.5 m/s (the law is concave)
    assert np.polyval(line, slow) / user.step_length_m(0.5, leg) - 1 > 0.025
    assert RegressionStepLength.population().b_m_per_hz != pytest.approx(float(line[0]), abs=0.01)


def test_cohorts_differ_and_unknown_ones_are_errors():
    rng = np.random.default_rng(0)
    healthy = GaitUser.draw(np.random.default_rng(1))
    impaired = GaitUser.draw(np.random.default_rng(1), cohort="impaired")
    leg = Body(1.7).leg_length_m
    assert impaired.step_length_m(0.8, leg) < 0.85 * healthy.step_length_m(0.8, leg)
    # per-step variability as published for MS and stroke walkers (Kalron 2016; Oken et al. 2008), at every speed
    assert 0.055 <= impaired.length_cv(0.5) == impaired.length_cv(0.9) <= 0.093
    assert healthy.length_cv(0.6) == pytest.approx(0.15)
    with pytest.raises(InputError, match="cohort"):
        GaitUser.draw(rng, cohort="athlete")


def test_simulated_impaired_walkers_vary_as_published():
    """Step-length and step-duration CV of a simulated impaired walk within the walkway studies' range (MS: 5.5-9.3%,
    Kalron 2016; stroke: 7.5%, duration 6.3%, Oken et al. 2008), not twice the healthy law's 15-30%."""
    sc = {"route": {"waypoints_m": [[0, 0], [60, 0], [60, 30], [0, 30]]}, "subject": {"height_m": 1.65, "cohort": "impaired"},
          "segment": [{"duration_s": 2, "speed_mps": 0}, {"duration_s": 40, "speed_mps": 0.6}], "gnss": {"enabled": False}}
    for seed in (0, 1):
        steps = simulate(sc, seed=seed).reference["steps"].iloc[2:-2]  # without the start and stop
        for col in ("step_length_m", "step_duration_s"):
            cv = steps[col].std() / steps[col].mean()
            assert 0.04 < cv < 0.11, (seed, col, cv)


def test_simulated_subject_is_measured_not_exact():
    rec = simulate({"route": {"waypoints_m": [[0, 0], [50, 0]]}, "subject": {"height_m": 1.6, "cohort": "older"},
                    "segment": [{"duration_s": 2, "speed_mps": 0}, {"duration_s": 8, "speed_mps": 1.0}]}, seed=3)
    summary = rec.reference["summary"]
    assert summary["cohort"] == "older" and rec.subject["height_m"] == 1.6
    assert rec.subject["leg_length_m"] != pytest.approx(summary["leg_length_m"], abs=1e-4)
    assert abs(rec.subject["leg_length_m"] - summary["leg_length_m"]) < 0.05
    assert rec.subject["sensor_height_m"] > summary["leg_length_m"]  # a lower-back sensor sits above the hips


def test_cli_calibrate_from_landmarks_and_a_trajectory(tmp_path, capsys):
    rec_a = _pocket_walk(tmp_path / "a", with_gnss=False, seed=7)
    rec_b = _pocket_walk(tmp_path / "b", with_gnss=False, seed=8)
    traj = load_recording(rec_a).reference["trajectory"]
    passings = traj[traj["t_s"].isin([5.0, 20.0, 35.0, 50.0])][["t_s", "e_m", "n_m"]]  # points along the straight walk
    passings.to_csv(tmp_path / "points.csv", index=False)
    load_recording(rec_b).reference["trajectory"][["t_s", "e_m", "n_m"]].to_csv(tmp_path / "path.csv", index=False)
    out = tmp_path / "model.json"
    assert main(["calibrate", str(rec_a), str(rec_b), "-o", str(out), "--landmarks", str(tmp_path / "points.csv"),
                 "--trajectory", str(tmp_path / "path.csv")]) == 1  # two sources for the first recording
    assert "one distance source per recording" in capsys.readouterr().err
    assert main(["calibrate", str(rec_a), "-o", str(out), "--landmarks", str(tmp_path / "points.csv")]) == 0
    doc = json.loads(out.read_text())
    assert doc["info"]["sources"] == ["landmarks"] and doc["info"]["n_segments"] == 3
    from pdr.pipelines.steps import detect_steps

    rec = load_recording(rec_a)
    with collect_warnings():
        steps = detect_steps(rec, {})
    between = ((steps["t_s"] > 5.0) & (steps["t_s"] <= 50.0)).to_numpy()  # the walk between the first and last point
    walked = float(np.hypot(*(passings[["e_m", "n_m"]].iloc[-1] - passings[["e_m", "n_m"]].iloc[0])))
    assert load_model(out).estimate(steps[between]).step_length_m_.sum() == pytest.approx(walked, rel=0.03)
