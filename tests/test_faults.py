"""Sensor faults inside a valid recording: the injector (pdr.sim.faults), the detector (pdr.signals.faults, from the
data only) and ``pdr run`` (keeps going, widens the uncertainty, lists every interval in summary.json ``warnings``)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pdr.cli.main import main
from pdr.constants import GRAVITY_MPS2
from pdr.errors import InputError, collect_warnings
from pdr.io.recording import load_recording, save_recording
from pdr.io.tomlio import read_toml
from pdr.pipelines.faults import FAULT_HEADING_CHANGE_STD_RAD, FAULT_LENGTH_STD_FRACTION, widen_steps
from pdr.signals.faults import SensorFaultDetection
from pdr.sim import simulate
from pdr.sim.faults import FAULT_KINDS, inject_faults, random_faults

ROOT = Path(__file__).resolve().parents[1]
# the detector's kind for each injected kind (a clock jump forward looks like a dropout in the data)
DETECTED_AS = {"dropout": "gap", "clock_jump": "gap", "stuck": "stuck", "saturation": "saturation",
               "duplicated": "duplicated_samples", "rate_change": "rate_change", "mag_steel": "mag_disturbance",
               "gnss_jump": "gnss_jump"}


def walking_imu(duration_s=60.0, rate_hz=100.0, seed=0, mag=True) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration_s, 1.0 / rate_hz)
    cols = {"t_s": t, "acc_x_mps2": 0.5 * rng.standard_normal(len(t)), "acc_y_mps2": 0.5 * rng.standard_normal(len(t)),
            "acc_z_mps2": GRAVITY_MPS2 + 3.0 * np.sin(2 * np.pi * 1.8 * t) + 0.2 * rng.standard_normal(len(t))}
    for a in "xyz":
        cols[f"gyr_{a}_radps"] = 0.3 * np.sin(2 * np.pi * 0.9 * t + ord(a)) + 0.02 * rng.standard_normal(len(t))
    if mag:
        for a, b0 in zip("xyz", (20.0, 5.0, -40.0)):
            cols[f"mag_{a}_ut"] = b0 + 0.5 * rng.standard_normal(len(t))
    return pd.DataFrame(cols)


def kinds(faults: pd.DataFrame) -> set[str]:
    return set(faults["kind"])


def covered(truth: pd.DataFrame, reported: list[dict] | pd.DataFrame, tolerance_s: float = 0.5) -> list[bool]:
    """For each injected interval: is a warning of the matching kind overlapping it (within ``tolerance_s``)?"""
    rep = pd.DataFrame(reported)
    out = []
    for f in truth.itertuples():
        same = rep[rep["kind"] == DETECTED_AS[f.kind]] if len(rep) else rep
        out.append(bool(len(same) and ((same["t_start_s"] <= f.t_end_s + tolerance_s)
                                       & (same["t_end_s"] >= f.t_start_s - tolerance_s)).any()))
    return out


# ---------------------------------------------------------------------------------------------------------------
# Detector
# ---------------------------------------------------------------------------------------------------------------


def test_clean_signal_has_no_faults():
    assert len(SensorFaultDetection().detect(walking_imu()).faults_) == 0


@pytest.mark.parametrize("rate_hz", [50.0, 100.0, 400.0])
def test_gap_threshold_follows_the_rate(rate_hz):
    imu = walking_imu(rate_hz=rate_hz)
    t = imu["t_s"].to_numpy()
    short = imu[~((t > 10.0) & (t < 10.0 + 3.0 / rate_hz))]  # two samples missing: jitter, not a gap
    assert len(SensorFaultDetection().detect(short).faults_) == 0
    holed = imu[~((t > 10.0) & (t < 10.15))]
    f = SensorFaultDetection().detect(holed).faults_
    assert list(f["kind"]) == ["gap"] and f["t_start_s"].iloc[0] <= 10.0 and f["t_end_s"].iloc[0] >= 10.15


def test_stuck_duplicated_saturation_rate_and_mag():
    imu = walking_imu()
    t = imu["t_s"].to_numpy()
    acc = ["acc_x_mps2", "acc_y_mps2", "acc_z_mps2"]
    w = (t >= 5) & (t < 6)
    imu.loc[w, acc] = imu.loc[np.flatnonzero(w)[0], acc].to_numpy()  # stuck accelerometer
    idx = np.flatnonzero((t >= 15) & (t < 17))[1::2]
    imu.loc[idx, ["gyr_x_radps", "gyr_y_radps", "gyr_z_radps"]] = imu.loc[idx - 1, ["gyr_x_radps", "gyr_y_radps", "gyr_z_radps"]].to_numpy()
    w = (t >= 25) & (t < 27)  # a hard landing clipped at 2 g
    imu.loc[w, "acc_z_mps2"] = np.minimum(imu.loc[w, "acc_z_mps2"] + 15.0, 2 * GRAVITY_MPS2)
    w = (t >= 40) & (t < 43)
    imu.loc[w, "mag_x_ut"] += 35.0
    slow = imu[(t >= 32) & (t < 36)].iloc[::2]  # 50 Hz for 4 s
    imu = pd.concat([imu[t < 32], slow, imu[t >= 36]], ignore_index=True)
    f = SensorFaultDetection().detect(imu).faults_
    by = {(r.kind, r.sensor): (r.t_start_s, r.t_end_s) for r in f.itertuples()}
    assert set(by) == {("stuck", "acc"), ("duplicated_samples", "gyr"), ("saturation", "acc"), ("rate_change", "imu"),
                       ("mag_disturbance", "mag")}, f
    assert by[("stuck", "acc")][0] == pytest.approx(5.0, abs=0.02) and by[("stuck", "acc")][1] == pytest.approx(6.0, abs=0.02)
    assert 24.9 <= by[("saturation", "acc")][0] and by[("saturation", "acc")][1] <= 27.1
    assert by[("rate_change", "imu")][0] == pytest.approx(32.0, abs=0.2)
    assert 39.5 <= by[("mag_disturbance", "mag")][0] <= 40.5


def test_sample_and_hold_sensor_and_low_peaks_are_not_faults():
    imu = walking_imu()
    mag = ["mag_x_ut", "mag_y_ut", "mag_z_ut"]
    imu.loc[1::2, mag] = imu.loc[0::2, mag].to_numpy()[: len(imu.loc[1::2])]  # a 50 Hz magnetometer held at 100 Hz
    imu["acc_z_mps2"] = np.minimum(imu["acc_z_mps2"], 12.0)  # flat tops, but below any sensor's full scale
    assert len(SensorFaultDetection().detect(imu).faults_) == 0


def test_gnss_jump_of_hundreds_of_metres_with_small_reported_accuracy():
    t = np.arange(0.0, 120.0)
    rng = np.random.default_rng(1)
    e, n = 1.3 * t + rng.normal(0, 2, len(t)), rng.normal(0, 2, len(t))
    jump = (t >= 50) & (t < 60)
    e[jump] += 250.0
    n[jump] -= 200.0
    e[0] += 40.0  # a first fix far off: the longest consistent run, not the first fix, is trusted
    gnss = pd.DataFrame({"t_s": t, "e_m": e, "n_m": n, "h_acc_m": np.full(len(t), 3.0)})
    det = SensorFaultDetection().detect(walking_imu(120.0), gnss)
    assert det.gnss_suspect_[jump].all() and det.gnss_suspect_[0] and det.gnss_suspect_.sum() == jump.sum() + 1
    f = det.faults_[det.faults_["kind"] == "gnss_jump"]
    assert ((f["t_start_s"] == 50.0) & (f["t_end_s"] == 59.0)).any()


def test_detector_bad_input_and_config():
    with pytest.raises(InputError, match="acc_x_mps2"):
        SensorFaultDetection().detect(pd.DataFrame({"t_s": [0.0, 1.0]}))
    with pytest.raises(InputError, match="unknown parameter"):
        SensorFaultDetection.from_config({"gap_factr": 3})


# ---------------------------------------------------------------------------------------------------------------
# Injector
# ---------------------------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def sim_walk():
    with collect_warnings():
        raw = read_toml(ROOT / "configs" / "sim" / "walk_short.toml")
        raw["segment"][3]["speed_mps"] = 3.0  # a run: the accelerometer goes beyond 2 g
        return simulate(raw, seed=2)


@pytest.mark.parametrize("kind", FAULT_KINDS)
def test_each_injected_fault_keeps_a_valid_recording_and_is_detected(sim_walk, kind, tmp_path):
    start = {"saturation": 80.0}.get(kind, 30.0)
    faulty, truth = inject_faults(sim_walk, [{"kind": kind, "t_start_s": start, "duration_s": 6.0}], seed=1)
    assert len(truth) == 1 and truth["kind"].iloc[0] == kind
    save_recording(faulty, tmp_path / "rec")  # validated on the way
    rec = load_recording(tmp_path / "rec")
    from pdr.geo import latlon_to_en

    e, n = latlon_to_en(rec.gnss["lat_deg"].to_numpy(), rec.gnss["lon_deg"].to_numpy(), rec.geo_origin)
    gnss = pd.DataFrame({"t_s": rec.gnss["t_s"], "e_m": e, "n_m": n, "h_acc_m": rec.gnss["h_acc_m"]})
    f = SensorFaultDetection().detect(rec.imu, gnss).faults_
    assert covered(truth, f) == [True], (truth, f)
    if kind == "clock_jump":  # the reference moves with the clock
        assert rec.imu["t_s"].iloc[-1] == pytest.approx(sim_walk.imu["t_s"].iloc[-1] + 6.0)


def test_random_faults_fill_the_fraction_without_overlap():
    faults = random_faults(600.0, np.random.default_rng(0), fraction=0.05)
    assert sum(f["duration_s"] for f in faults) == pytest.approx(30.0, abs=0.01)  # durations rounded to 1 ms
    ends = [(f["t_start_s"], f["t_start_s"] + f["duration_s"]) for f in faults]
    assert all(b1 + 2.9 < a2 for (_, b1), (a2, _) in zip(ends, ends[1:])) and ends[-1][1] <= 595.0
    assert {f["kind"] for f in faults} == set(FAULT_KINDS)
    with pytest.raises(InputError, match="kind"):
        inject_faults(None, [{"kind": "meteor", "t_start_s": 1.0, "duration_s": 1.0}])


# ---------------------------------------------------------------------------------------------------------------
# pdr run
# ---------------------------------------------------------------------------------------------------------------


def test_widen_steps_only_where_a_fault_touches():
    steps = pd.DataFrame({"t_s": [1.0, 1.5, 2.0, 2.5, 3.0], "step_length_m": 0.7, "step_length_std_m": 0.05,
                          "heading_change_rad": 0.0, "heading_change_std_rad": 0.01,
                          "mag_heading_rad": 0.3, "mag_heading_std_rad": 0.1})
    faults = pd.DataFrame([{"kind": "stuck", "sensor": "gyr", "t_start_s": 1.6, "t_end_s": 1.8, "message": ""},
                           {"kind": "saturation", "sensor": "acc", "t_start_s": 2.6, "t_end_s": 2.7, "message": ""},
                           {"kind": "mag_disturbance", "sensor": "mag", "t_start_s": 0.0, "t_end_s": 1.2, "message": ""}])
    out = widen_steps(steps, faults, 0.5)
    assert out["heading_change_std_rad"].tolist() == [0.01, 0.01, FAULT_HEADING_CHANGE_STD_RAD, 0.01, 0.01]
    assert out["step_length_std_m"].tolist() == [0.05] * 4 + [FAULT_LENGTH_STD_FRACTION * 0.7]
    assert out["mag_heading_rad"].isna().tolist() == [True, True, False, False, False]
    assert steps["step_length_std_m"].tolist() == [0.05] * 5  # the input is not changed


def test_run_keeps_going_reports_every_fault_and_stays_continuous(tmp_path, capsys):
    rec = tmp_path / "rec"
    assert main(["simulate", str(ROOT / "configs" / "sim" / "walk_faults.toml"), "-o", str(rec), "--seed", "1"]) == 0
    truth = pd.read_csv(rec / "reference" / "faults.csv")
    assert sorted(truth["kind"]) == sorted(FAULT_KINDS)
    assert main(["validate", str(rec)]) == 0
    out = tmp_path / "out"
    assert main(["run", str(rec), "-o", str(out)]) == 0
    err = capsys.readouterr().err
    assert "error" not in err and "warning: gnss_jump (gnss)" in err  # the CLI reports every warning on stderr
    summary = json.loads((out / "summary.json").read_text())
    w = summary["warnings"]
    assert all(set(x) == {"kind", "sensor", "t_start_s", "t_end_s", "message"} for x in w)
    assert all(covered(truth, [x for x in w if x["kind"] != "general"])), (truth, w)
    assert summary["gnss"]["jumped"] == int(truth.loc[truth["kind"] == "gnss_jump", "n_samples"].iloc[0])
    traj = pd.read_csv(out / "trajectory.csv")
    assert np.isfinite(traj[["e_m", "n_m", "e_std_m", "n_std_m"]].to_numpy()).all()
    hop = np.hypot(np.diff(traj["e_m"]), np.diff(traj["n_m"]))
    assert hop.max() < max(2.5, 3.0 * float(np.diff(traj["t_s"]).max()))  # no jump towards the 300 m GNSS fixes
    steps = pd.read_csv(out / "steps.csv")
    stuck = truth[truth["kind"] == "stuck"].iloc[0]  # steps over a stuck accelerometer: their length barely known
    inside = steps[(steps["t_s"] > stuck.t_start_s + 0.2) & (steps["t_s"] < stuck.t_end_s)]
    before = steps[(steps["t_s"] > stuck.t_start_s - 5.0) & (steps["t_s"] < stuck.t_start_s - 1.0)]
    assert (inside["step_length_std_m"] > 2.0 * before["step_length_std_m"].median()).all()


def test_clean_simulated_walk_has_no_sensor_fault_warnings(tmp_path):
    rec = tmp_path / "rec"
    assert main(["simulate", str(ROOT / "configs" / "sim" / "walk_short.toml"), "-o", str(rec), "--seed", "1"]) == 0
    assert main(["run", str(rec), "-o", str(tmp_path / "out")]) == 0
    w = json.loads((tmp_path / "out" / "summary.json").read_text())["warnings"]
    assert not [x for x in w if x["sensor"] in ("imu", "acc", "gyr", "mag")], w
