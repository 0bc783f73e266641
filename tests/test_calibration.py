"""Step-length calibration: recursive prediction, the adaptive Kalman filter with GNSS segments, `pdr calibrate`."""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pdr.calibration import AdaptiveKalmanCalibration, RecursiveStepCalibration, gnss_segments
from pdr.calibration.segments import clean_fixes
from pdr.cli.main import main
from pdr.constants import GRAVITY_MPS2
from pdr.errors import InputError, collect_warnings
from pdr.io.recording import Recording, load_recording, save_recording
from pdr.step_length import RegressionStepLength, ZijlstraStepLength, load_model, save_model
from conftest import warns

ROOT = Path(__file__).resolve().parents[1]


def true_length(freq: np.ndarray, slope: float = 0.9) -> np.ndarray:
    """A walker whose step length follows a power law of cadence (richer than the linear model)."""
    return 0.74 * (freq / 1.8) ** slope


def synthetic_walk(freq: np.ndarray, *, h_acc_m: float, seed: int, length_scale: float = 1.0,
                   turn_rate_rad_per_step: float = 0.0):
    """Steps table + GNSS (1 Hz) of a walk with the given per-step cadence; returns (steps, gnss, true lengths)."""
    rng = np.random.default_rng(seed)
    length = length_scale * true_length(freq) + 0.03 * rng.standard_normal(len(freq))
    t = np.cumsum(1.0 / freq)
    heading = 0.4 + turn_rate_rad_per_step * np.arange(len(freq)) + 0.02 * rng.standard_normal(len(freq))
    e = np.cumsum(length * np.cos(heading))
    n = np.cumsum(length * np.sin(heading))
    steps = pd.DataFrame({"t_s": t, "bout_id": 0, "step_freq_hz": freq + 0.03 * rng.standard_normal(len(freq)),
                          "acc_var_m2ps4": 3.0 + 2.0 * (freq - 1.8) + 0.3 * rng.standard_normal(len(freq)),
                          "heading_rad": heading})
    tg = np.arange(np.ceil(t[0]), t[-1], 1.0)
    gnss = pd.DataFrame({"t_s": tg, "e_m": np.interp(tg, t, e) + h_acc_m * rng.standard_normal(len(tg)),
                         "n_m": np.interp(tg, t, n) + h_acc_m * rng.standard_normal(len(tg)), "h_acc_m": h_acc_m})
    return steps, gnss, length


CONSTANT = RegressionStepLength(a_m=0.70, b_m_per_hz=0.0, c_m_per_m2ps4=0.0, residual_std_m=0.05,
                                covariance=np.diag([0.1 ** 2, 1e-12, 1e-12]).tolist())


def test_akf_converges_within_100_steps_after_a_change_of_pace():
    freq = np.r_[np.full(300, 1.7), np.full(300, 2.0), np.full(300, 1.6)]
    steps, gnss, _ = synthetic_walk(freq, h_acc_m=0.05, seed=1)
    akf = AdaptiveKalmanCalibration().fit(steps, gnss, CONSTANT)  # the paper's filter: the model says nothing
    err = np.abs(akf.trace_["step_length_m"].to_numpy() - true_length(freq))
    for change in (300, 600):
        after = err[change:change + 300]
        converged = np.flatnonzero(after > 0.03).max() + 1
        assert converged <= 100, (change, converged)
        assert after[:10].max() > 0.08  # the change was real: the filter had to move
    # the process noise adapted: larger right after a change than in steady walking
    q = akf.trace_["process_std_m"].to_numpy()
    assert q[300:400].max() > 3 * np.median(q[150:300])


def test_recursive_prediction_lags_one_window():
    pred_model = RegressionStepLength(a_m=0.0, b_m_per_hz=0.4, c_m_per_m2ps4=0.0, residual_std_m=0.05)
    freq = np.r_[np.full(40, 1.7), np.full(60, 2.0)]
    steps = pd.DataFrame({"step_freq_hz": freq, "acc_var_m2ps4": 3.0})
    rc = RecursiveStepCalibration(window_steps=20).estimate(steps, pred_model)
    np.testing.assert_allclose(rc.window_step_m_, [0.68, 0.68, 0.68, 0.80, 0.80])
    assert rc.step_length_m_.shape == (100,) and np.all(rc.step_length_std_m_ > 0)
    assert rc.step_length_std_m_[40:60].min() > 0.1  # the window after the change carries its lag as uncertainty
    with pytest.raises(InputError, match="window_steps"):
        RecursiveStepCalibration(window_steps=0).estimate(steps, pred_model)


def test_single_frequency_updates_mainly_the_level():
    freq = np.full(600, 1.85)
    steps, gnss, length = synthetic_walk(freq, h_acc_m=1.0, seed=2, length_scale=1.12)
    prior = RegressionStepLength.population()
    akf = AdaptiveKalmanCalibration().fit(steps, gnss, prior)
    assert akf.updated_ == "level"
    m = akf.model_
    # the data see the level near the prior's reference cadence: the slope stays within a fraction of its prior std
    # (the level is shared between A and C, C * acc_var being a level at one pace)
    prior_sd = np.sqrt(np.diag(np.asarray(prior.covariance)))
    assert abs(m.b_m_per_hz - prior.b_m_per_hz) < 0.2 * prior_sd[1] and abs(m.c_m_per_m2ps4) < 1.5 * prior_sd[2]
    assert m.a_m != prior.a_m
    est = m.estimate(steps).step_length_m_
    assert abs(est.sum() / length.sum() - 1) < 0.02
    assert abs(prior.estimate(steps).step_length_m_.sum() / length.sum() - 1) > 0.05


def test_several_frequencies_update_all_and_generalise():
    freq = np.repeat([1.6, 1.75, 1.9, 2.05, 1.7, 1.95], 150)
    steps, gnss, _ = synthetic_walk(freq, h_acc_m=1.0, seed=3, length_scale=1.08)
    akf = AdaptiveKalmanCalibration().fit(steps, gnss, RegressionStepLength.population())
    assert akf.updated_ == "all"
    assert akf.segments_["used"].sum() >= 30 and akf.distance_m_ > 400
    # a new walk of the same user at other paces
    test_freq = np.repeat([1.65, 2.0, 1.8], 200)
    test_steps, _, test_len = synthetic_walk(test_freq, h_acc_m=1.0, seed=4, length_scale=1.08)
    est = akf.model_.estimate(test_steps).step_length_m_
    assert abs(est.sum() / test_len.sum() - 1) < 0.01
    cov = np.asarray(akf.model_.covariance)
    assert np.all(np.diag(cov) < np.diag(np.asarray(RegressionStepLength.population().covariance)))


def test_gates_reject_poor_fixes_curves_and_pauses():
    freq = np.full(300, 1.8)
    steps, gnss, _ = synthetic_walk(freq, h_acc_m=0.5, seed=5)
    poor = gnss.assign(h_acc_m=25.0)
    with warns(match="no distance segment"):
        akf = AdaptiveKalmanCalibration().fit(steps, poor, CONSTANT)
    assert akf.updated_ == "none" and len(akf.segments_) == 0
    assert akf.model_.get_params() == CONSTANT.get_params()
    # a walk in circles: every segment curves
    curvy, gnss_c, _ = synthetic_walk(freq, h_acc_m=0.5, seed=6, turn_rate_rad_per_step=0.2)
    segs = gnss_segments(curvy, gnss_c, segment_steps=20, min_segment_steps=8, max_h_acc_m=10, assumed_h_acc_m=5,
                         min_straightness=0.7, min_step_m=0.2, max_step_m=1.6)
    assert len(segs) > 5 and not segs["used"].any() and segs["reason"].str.startswith("not straight").all()
    # NaN fixes are skipped, fixes outside the walking bouts give no segment
    holes = gnss.copy()
    holes.loc[::3, ["e_m", "n_m"]] = np.nan
    two_bouts = steps.assign(bout_id=(np.arange(len(steps)) >= 150).astype(int))
    segs = gnss_segments(two_bouts, holes, segment_steps=20, min_segment_steps=8, max_h_acc_m=10, assumed_h_acc_m=5,
                         min_straightness=0.7, min_step_m=0.2, max_step_m=1.6)
    t_split = (steps.t_s[149] + steps.t_s[150]) / 2
    assert segs["used"].sum() > 5
    assert not ((segs.t_start_s < t_split) & (segs.t_end_s > t_split)).any()


def test_bad_gnss_and_steps_input():
    steps, gnss, _ = synthetic_walk(np.full(100, 1.8), h_acc_m=0.5, seed=7)
    akf = AdaptiveKalmanCalibration()
    with pytest.raises(InputError, match="t_s, e_m, n_m"):
        akf.fit(steps, gnss.rename(columns={"e_m": "x"}), CONSTANT)
    with pytest.raises(InputError, match="strictly increasing"):
        akf.fit(steps, gnss.iloc[::-1], CONSTANT)
    with pytest.raises(InputError, match="h_acc_m > 0"):
        akf.fit(steps, gnss.assign(h_acc_m=0.0), CONSTANT)
    with pytest.raises(InputError, match="steps t_s"):
        akf.fit(steps.iloc[::-1], gnss, CONSTANT)
    with pytest.raises(InputError, match="as many GNSS"):
        akf.fit([steps, steps], [gnss], CONSTANT)
    with pytest.raises(InputError, match="segment_steps"):
        AdaptiveKalmanCalibration(segment_steps=0).fit(steps, gnss, CONSTANT)
    with collect_warnings():
        empty = akf.fit(steps.iloc[:0], gnss, CONSTANT)
    assert empty.updated_ == "none" and empty.step_length_m_.shape == (0,)


def walking_recording(path, *, duration_s: float, speed_mps: float, with_gnss: bool = True):
    """A hand-made waist recording: vertical bounce at 1.8 steps/s, no rotation, GNSS along a straight line."""
    rate, f = 100.0, 1.8
    t = np.arange(0.0, duration_s, 1.0 / rate)
    ramp = np.clip(t / 2.0, 0, 1) * np.clip((duration_s - t) / 2.0, 0, 1)
    vert = GRAVITY_MPS2 + ramp * (2.5 * np.sin(2 * np.pi * f * t) + 0.6 * np.sin(4 * np.pi * f * t + 0.5))
    fwd = ramp * 1.0 * np.sin(2 * np.pi * f * t + 1.0)
    imu = pd.DataFrame({"t_s": t, "acc_x_mps2": fwd, "acc_y_mps2": 0.0 * t, "acc_z_mps2": vert,
                        "gyr_x_radps": 0.0 * t, "gyr_y_radps": 0.0 * t, "gyr_z_radps": 0.0 * t})
    gnss = None
    if with_gnss:
        tg = np.arange(0.0, duration_s, 1.0)
        gnss = pd.DataFrame({"t_s": tg, "e_m": speed_mps * tg, "n_m": 0.0 * tg, "h_acc_m": 0.5})
    rec = Recording(meta={"recording": {"id": path.name, "placement": "pocket"}, "subject": {"height_m": 1.8}},
                    imu=imu, gnss=gnss)
    return save_recording(rec, path)


def test_cli_calibrate_on_a_hand_made_recording(tmp_path, capsys):
    rec = walking_recording(tmp_path / "walk", duration_s=60.0, speed_mps=1.44)  # 0.8 m steps at 1.8 Hz
    out = tmp_path / "model.json"
    assert main(["calibrate", str(rec), "-o", str(out)]) == 0
    line = capsys.readouterr().out
    assert "calibrated regression model" in line and str(out) in line
    doc = json.loads(out.read_text())
    assert doc["pdr_model_version"] == 1 and doc["info"]["n_steps"] > 40 and doc["info"]["distance_m"] > 30
    model = load_model(out)
    assert model.estimate(pd.DataFrame({"step_freq_hz": [1.8], "acc_var_m2ps4": [3.0]})).step_length_m_[0] == \
        pytest.approx(0.8, abs=0.04)


def test_cli_calibrate_a_simulated_walk_then_run_with_the_model(tmp_path, capsys):
    from pdr.sim import simulate_to_disk

    rec = simulate_to_disk(ROOT / "configs" / "sim" / "walk_short.toml", tmp_path / "walk", seed=0, force=False)
    model_path = tmp_path / "model.json"
    assert main(["calibrate", str(rec), "-o", str(model_path)]) == 0
    assert "calibrated zijlstra model on 1 recording(s)" in capsys.readouterr().out  # a waist sensor: the pendulum
    model = load_model(model_path)
    assert model.get_params() != ZijlstraStepLength.population().get_params()
    assert main(["run", str(rec), "-o", str(tmp_path / "out"), "--model", str(model_path), "--no-gnss"]) == 0
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["step_model"]["params"]["k_scale"] == pytest.approx(model.k_scale)
    assert summary["step_model"]["choice"]["source"] == "model file"
    truth = load_recording(rec).reference["summary"]["distance_m"]
    assert abs(summary["distance_m"] / truth - 1) < 0.15  # 2 min of phone-grade GNSS: a coarse calibration


def test_cli_calibrate_needs_gnss(tmp_path, capsys):
    rec = walking_recording(tmp_path / "nognss", duration_s=20.0, speed_mps=1.4, with_gnss=False)
    assert main(["calibrate", str(rec), "-o", str(tmp_path / "m.json")]) == 1
    err = capsys.readouterr().err
    assert err.startswith("error:") and "expected GNSS" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "m.json").exists()


def test_unreported_gnss_jumps_are_dropped():
    freq = np.full(600, 1.85)
    steps, gnss, length = synthetic_walk(freq, h_acc_m=1.0, seed=8, length_scale=1.1)
    rng = np.random.default_rng(9)
    jumps = rng.choice(np.arange(5, len(gnss) - 5), 8, replace=False)
    angle = rng.uniform(0, 2 * np.pi, len(jumps))
    gnss.loc[jumps, "e_m"] += 30.0 * np.cos(angle)
    gnss.loc[jumps, "n_m"] += 30.0 * np.sin(angle)
    usable, _, _ = clean_fixes(gnss.t_s.to_numpy(), gnss.e_m.to_numpy(), gnss.n_m.to_numpy(), gnss.h_acc_m.to_numpy(),
                               np.ones(len(gnss), bool), outlier_h_acc_factor=5.0, smoothing_s=2.0)
    assert not usable[jumps].any() and usable.mean() > 0.9
    akf = AdaptiveKalmanCalibration().fit(steps, gnss, RegressionStepLength.population())
    est = akf.model_.estimate(steps).step_length_m_
    assert abs(est.sum() / length.sum() - 1) < 0.02


def test_cli_calibrate_says_which_gate_failed(tmp_path, capsys):
    rec = walking_recording(tmp_path / "poor", duration_s=30.0, speed_mps=1.4, with_gnss=True)
    gnss = pd.read_csv(rec / "gnss.csv")
    gnss["h_acc_m"] = 25.0  # fixes exist, inside the walk, but none passes the accuracy gate
    gnss.to_csv(rec / "gnss.csv", index=False)
    assert main(["calibrate", str(rec), "-o", str(tmp_path / "m.json")]) == 1
    errors = [line for line in capsys.readouterr().err.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and "fail the accuracy gate h_acc_m <= 10 m" in errors[0], errors
    assert not (tmp_path / "m.json").exists()


# ------------------------------------------------------------------------------------------------ leg-camera scale
def _camera_strides(t_contacts: np.ndarray, length_m: float) -> pd.DataFrame:
    return pd.DataFrame({"t_start_s": t_contacts[:-1], "t_end_s": t_contacts[1:], "foot": "left",
                         "length_m": length_m, "length_std_m": 0.1, "source": "leg_camera"})


@pytest.mark.parametrize("method", ["odometry", "slip_of"])
def test_leg_camera_scale_from_known_segments(method):
    from pdr.pipelines.calibrate import SCALE_SPREADS, leg_camera_scale

    person_std, walk_std = SCALE_SPREADS[method]
    steps = pd.DataFrame({"t_s": 1.0 + 0.5 * np.arange(41)})  # 41 steps of 0.7 m (28.7 m) at 2 steps/s
    strides = _camera_strides(steps.t_s.to_numpy()[::2], 1.4 * 1.1)  # the camera foot's contacts, 10% long
    segs = pd.DataFrame({"rec_index": 0, "t_start_s": [1.0, 6.0, 11.0], "t_end_s": [6.0, 11.0, 21.0],
                         "n_steps": [10.0, 10.0, 20.0], "distance_m": [7.0, 7.0, 14.0], "measured_std_m": 0.001,
                         "used": True})
    out = leg_camera_scale([strides], [steps], segs, method=method)
    assert out["measured_ratio"] == pytest.approx(1 / 1.1, rel=1e-6) and out["n_segments"] == 3
    assert out["method"] == method
    # one walk of exactly known length moves the person's scale by w = person^2 / (person^2 + walk^2) of what it reads
    w = person_std ** 2 / (person_std ** 2 + walk_std ** 2)
    assert out["length_scale"] - 1 == pytest.approx(w * (1 / 1.1 - 1), rel=0.01)
    assert out["length_scale_std"] < person_std and out["distance_m"] == 28.0 and out["n_strides"] == 20
    whole = pd.DataFrame({"rec_index": [0], "t_start_s": [1.0], "t_end_s": [21.0], "n_steps": [41.0],
                          "distance_m": [28.7], "measured_std_m": [0.001], "used": [True]})  # --distance-m: every step
    assert leg_camera_scale([strides], [steps], whole, method=method)["measured_ratio"] == pytest.approx(1 / 1.1, rel=0.01)
    coarse = segs.assign(measured_std_m=0.5)  # phone-grade GNSS chords (5 m a segment): the scale moves less
    assert 1 > leg_camera_scale([strides], [steps], coarse, method=method)["length_scale"] > out["length_scale"]
    three = pd.concat([segs.assign(rec_index=r) for r in range(3)])  # three walks reading the same: a firmer scale
    many = leg_camera_scale([strides] * 3, [steps] * 3, three, method=method)
    assert many["n_walks"] == 3 and many["length_scale"] < out["length_scale"]
    assert many["length_scale_std"] < out["length_scale_std"]
    assert leg_camera_scale([None], [steps], segs) is None  # no camera: nothing to calibrate
    with warns("not calibrated"):  # the camera films only the first 5 s: no segment covered
        assert leg_camera_scale([strides[strides.t_end_s <= 6.0]], [steps], segs.iloc[1:]) is None
    with warns("not stored"):  # strides twice the known distance: a wrong camera.toml, not a body to calibrate
        assert leg_camera_scale([_camera_strides(steps.t_s.to_numpy()[::2], 2.8)], [steps], segs) is None


def test_model_file_leg_camera_scale_is_checked(tmp_path):
    from pdr.step_length import leg_camera_calibration

    path = tmp_path / "model.json"
    save_model(ZijlstraStepLength.population(), path, {"length_scale": 0.95, "n_strides": 30})
    assert leg_camera_calibration(path) == {"method": "slip_of", "length_scale": 0.95}  # written before the odometry
    save_model(ZijlstraStepLength.population(), path, {"method": "odometry", "length_scale": 0.95, "length_scale_std": 0.01})
    assert leg_camera_calibration(path) == {"method": "odometry", "length_scale": 0.95, "length_scale_std": 0.01}
    save_model(ZijlstraStepLength.population(), path)
    assert leg_camera_calibration(path) is None
    for key, bad in [("length_scale", v) for v in (0.2, "0.95", None, float("nan"))] + [("length_scale_std", -0.1),
                                                                                        ("method", "visual")]:
        doc = json.loads(path.read_text())
        doc["leg_camera"] = {"length_scale": 0.95, key: bad}
        path.write_text(json.dumps(doc))
        with pytest.raises(InputError, match=f"leg_camera.{key}"):
            leg_camera_calibration(path)


def test_cli_calibrate_a_leg_camera_walk_of_known_length(tmp_path, capsys):
    from pdr.sim import simulate_to_disk

    text = (ROOT / "configs" / "sim" / "leg_camera.toml").read_text()
    assert tomllib.loads(text)["segment"][1]["duration_s"] == 40.0
    config = tmp_path / "walk.toml"
    config.write_text(text.replace("duration_s = 40.0", "duration_s = 16.0"))  # the same person, a shorter walk
    rec = simulate_to_disk(config, tmp_path / "walk", seed=2)
    truth = load_recording(rec).reference
    assert main(["calibrate", str(rec), "-o", str(tmp_path / "model.json"),
                 "--distance-m", str(truth["summary"]["distance_m"])]) == 0
    assert "leg camera: " in capsys.readouterr().out
    doc = json.loads((tmp_path / "model.json").read_text())
    camera = doc["leg_camera"]
    assert camera["method"] == "odometry"
    assert 0.85 < camera["measured_ratio"] < 0.97  # this person's strides read 3-15% long uncalibrated
    assert camera["measured_ratio"] < camera["length_scale"] < 1.0  # one walk: part of the way
    assert main(["run", str(rec), "-o", str(tmp_path / "out"), "--model", str(tmp_path / "model.json"), "--no-gnss"]) == 0
    strides = pd.read_csv(tmp_path / "out" / "strides.csv")
    ref = truth["strides"][truth["strides"].foot == "left"]
    k = np.abs(ref.t_end_s.to_numpy()[None, :] - strides.t_end_s.to_numpy()[:, None]).argmin(axis=1)
    bias = np.mean(strides.length_m.to_numpy() / ref.length_m.to_numpy()[k] - 1)
    assert abs(bias - (camera["length_scale"] / camera["measured_ratio"] - 1)) < 0.01  # the scale applied, no other
    slip = tmp_path / "slip.toml"
    slip.write_text('[leg_camera]\nmethod = "slip_of"\n')
    with warns("not applied"):  # a scale calibrated for the odometry is not the SLIP-OF's
        assert main(["run", str(rec), "-o", str(tmp_path / "out_slip"), "--model", str(tmp_path / "model.json"),
                     "--config", str(slip), "--no-gnss"]) == 0
