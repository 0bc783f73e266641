"""Importers of ``pdr import``: the real data in ``datasets/`` (units, clocks, reference truth), hand-written
Sensor Logger / phyphox / GPX files in ``tests/importers/``, hostile archives and bad input through the CLI."""

from __future__ import annotations

import shutil
import stat
import zipfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pdr.cli.main import main
from pdr.constants import GRAVITY_MPS2
from pdr.errors import InputError, collect_warnings
from pdr.io.importers import import_recordings
from pdr.io.importers import _common
from pdr.io.recording import load_recording

from conftest import DATASETS, real_dataset, warns

ROOT = Path(__file__).resolve().parents[1]
HAND = Path(__file__).resolve().parent / "importers"
OXFORD = DATASETS / "oxford_step_counter"
MOBGAP = DATASETS / "mobgap_lowerback_tvs_lab" / "lab" / "HA"
HUMOLIRE = DATASETS / "humolire_phone_landmarks" / "data" / "imus" / "1" / "square_2x"
GAITMAP = DATASETS / "gaitmap_foot_imu_mocap"
XIO = DATASETS / "xio_foot_imu_loop_walk" / "short_walk.csv"
REAL_FORMATS = {"xio": "xio_foot_imu_loop_walk", "oxford": "oxford_step_counter", "humolire": "humolire_phone_landmarks",
                "gaitmap": "gaitmap_foot_imu_mocap", "mobgap": "mobgap_lowerback_tvs_lab"}


def _import(fmt, src, dest, **kw):
    with collect_warnings() as caught:
        paths = import_recordings(fmt, Path(src), Path(dest), **kw)
    return paths, list(caught)


def _median_acc(rec) -> float:
    return float(np.median(np.linalg.norm(rec.imu[["acc_x_mps2", "acc_y_mps2", "acc_z_mps2"]].to_numpy(), axis=1)))


def _cli(argv, capsys):
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


def _assert_one_error(rc, err):
    lines = [line for line in err.splitlines() if line.strip()]
    errors = [line for line in lines if line.startswith("error:")]
    assert rc == 1 and len(errors) == 1, err
    assert not any("Traceback" in line for line in lines)


def _entries(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir()) if folder.exists() else []


# ---------------------------------------------------------------------------------------------------------------
# Real data
# ---------------------------------------------------------------------------------------------------------------

OXFORD_TRUTH = {"armband": 335, "backpocket": 343, "bag": 346, "frontpocket": 327, "hand": 326, "neckpouch": 346}
OXFORD_PLACEMENT = {"armband": "arm", "backpocket": "pocket", "bag": "bag", "frontpocket": "pocket", "hand": "hand",
                    "neckpouch": "neck"}


@pytest.fixture(scope="module")
def oxford_validation(tmp_path_factory):
    real_dataset("oxford_step_counter")
    dest = tmp_path_factory.mktemp("oxford")
    paths, messages = _import("oxford", OXFORD / "validation", dest)
    return paths, messages


def test_oxford_validation_truth_and_units(oxford_validation):
    paths, messages = oxford_validation
    assert sorted(p.name for p in paths) == sorted(f"user1_{k}" for k in OXFORD_TRUTH)
    for path in paths:
        rec = load_recording(path)
        position = path.name.split("_", 1)[1]
        summary = rec.reference["summary"]
        assert summary["n_steps"] == OXFORD_TRUTH[position]
        assert len(rec.reference["steps"]) == OXFORD_TRUTH[position]
        assert summary["n_steps_app"] > 0
        assert rec.placement == OXFORD_PLACEMENT[position]
        assert 9.0 < _median_acc(rec) < 11.0
        assert abs(rec.sample_rate_hz - 100.0) < 1.0
        steps = rec.reference["steps"]["t_s"].to_numpy()
        assert rec.imu["t_s"].iloc[0] == 0.0 and 0 <= steps[0] and steps[-1] <= rec.imu["t_s"].iloc[-1] + 1e-9
        assert np.all(np.diff(steps) >= 0) and 150 < rec.imu["t_s"].iloc[-1] < 210
        assert rec.meta["recording"]["source"] == "oxford" and rec.meta["recording"]["start_unix_s"] > 1.5e9
    assert any("leading all-zero row" in m for m in messages)  # user1_hand starts with a zero row
    assert any("repeats or steps back" in m for m in messages)  # armband and neckpouch repeat a time stamp


@pytest.mark.real_data("oxford_step_counter")
def test_oxford_optimisation_irregular_clock_passes(tmp_path):
    paths, _ = _import("oxford", OXFORD / "optimisation" / "data" / "Samsung_Carmelo_Hard_Purse_1", tmp_path)
    rec = load_recording(paths[0])
    assert rec.id == "Samsung_Carmelo_Hard_Purse_1" and rec.placement == "bag"
    assert rec.reference["summary"]["n_steps"] == 288 == len(rec.reference["steps"])
    dt = np.diff(rec.imu["t_s"].to_numpy())
    q25, q75 = np.percentile(dt, [25, 75])
    assert 1.0 < q75 / q25 < 4.0  # irregular (~204 Hz) but kept as recorded: the validator accepts it
    assert len(rec.imu) == 35236


def test_foot_device_steps_make_the_feet_alternate():
    from pdr.io.importers.oxford import foot_device_steps

    right = np.array([0.0, 1.1, 2.2, 2.5, 3.3, 10.0])  # 2.5: the 2.2 contact bouncing; 10.0: after standing
    left = np.array([0.55, 2.75, 10.6])  # the contact near 1.65 missed by the device
    steps, dropped, added = foot_device_steps((right, left))
    np.testing.assert_allclose(steps, [0.0, 0.55, 1.1, 1.65, 2.2, 2.75, 3.3, 10.0, 10.6])
    assert (dropped, added) == (1, 1)
    alternating = np.arange(20) * 0.5
    assert len(foot_device_steps((alternating[::2], alternating[1::2]))[0]) == 20


@pytest.mark.real_data("oxford_step_counter")
def test_oxford_optimisation_foot_device_contacts_alternate(tmp_path):
    paths, messages = _import("oxford", OXFORD / "optimisation" / "data" / "Samsung_Dario_Hard_FrontPocket_1", tmp_path)
    summary = load_recording(paths[0]).reference["summary"]
    assert summary["n_steps_device"] == 306  # upstream stats.csv
    assert summary["n_steps"] == 306 - 6 + 15  # 6 bouncing contacts, 15 strides with the other foot's contact missed
    assert any("6 bouncing contact(s) dropped, 15 missed" in m for m in messages)


@pytest.fixture(scope="module")
def mobgap_recs(tmp_path_factory):
    real_dataset("mobgap_lowerback_tvs_lab")
    dest = tmp_path_factory.mktemp("mobgap")
    out = {}
    for participant in ("001", "002"):
        paths, messages = _import("mobgap", MOBGAP / participant, dest / participant)
        out[participant] = ({p.name: load_recording(p) for p in paths}, messages)
    return out


@pytest.mark.parametrize("participant, trial, n_ic, distance_m, system", [
    ("001", "Test5_Trial1", 9, 5.0, "INDIP"), ("001", "Test5_Trial2", 9, 4.8, "INDIP"),
    ("001", "Test11_Trial1", 63, 23.4, "INDIP"), ("002", "Test5_Trial2", 6, 4.1, "Stereophoto"),
    ("002", "Test11_Trial1", 54, 12.8, "INDIP"),
])
def test_mobgap_reference_matches_readme(mobgap_recs, participant, trial, n_ic, distance_m, system):
    rec = mobgap_recs[participant][0][trial]
    summary = rec.reference["summary"]
    assert summary["reference_system"] == system
    assert summary["n_steps"] == n_ic
    assert abs(summary["distance_m"] - distance_m) < 0.06
    steps = rec.reference["steps"]
    assert len(steps) == summary["n_steps_timed"] <= n_ic
    assert set(steps["foot"]) <= {"left", "right"}
    strides = rec.reference["strides"]
    assert len(strides) > 0 and (strides["t_end_s"] > strides["t_start_s"]).all()
    assert strides["length_m"].between(0.05, 2.0).all() and set(strides["foot"]) <= {"left", "right"}
    # stride start instants are initial contacts of the same foot (INDIP samples / 100 Hz -> s)
    for _, row in strides.iterrows():
        match = steps[np.isclose(steps["t_s"], row["t_start_s"], atol=0.011)]
        assert len(match) and row["foot"] in set(match["foot"])
    assert 9.4 < _median_acc(rec) < 10.1  # g -> m/s²
    assert rec.imu[["gyr_x_radps", "gyr_y_radps", "gyr_z_radps"]].abs().max().max() < 6.0  # deg/s -> rad/s
    assert rec.placement == "waist" and "baro_hpa" in rec.imu and "mag_x_ut" in rec.imu


def test_mobgap_turns_subject_and_missing_reference(mobgap_recs):
    recs, messages = mobgap_recs["001"]
    turns = recs["Test11_Trial1"].reference["summary"]["turn_angles_deg"]
    np.testing.assert_allclose(turns, [-56, 90, -133, 88, -80, 46, -50], atol=1.0)
    assert recs["Test5_Trial1"].subject == {"height_m": 1.59, "mass_kg": 73.0, "sensor_height_m": 0.964, "foot_length_m": 0.25}
    bouts = pd.read_csv(recs["Test11_Trial1"].path / "reference" / "bouts.csv")
    assert len(bouts) == 6 and bouts["n_initial_contacts"].sum() == 63
    recs2, messages2 = mobgap_recs["002"]
    np.testing.assert_allclose(recs2["Test11_Trial1"].reference["summary"]["turn_angles_deg"], [-135, -147, 149], atol=1.0)
    assert recs2["Test11_Trial1"].subject["sensor_height_m"] == 1.08
    assert recs2["Test5_Trial1"].reference == {}  # neither INDIP nor Stereophoto has a bout
    assert any("no walking bout" in m for m in messages2)
    # StartDateTime 2020-08-21T12:50:00.388+02:00
    assert abs(recs2["Test11_Trial1"].meta["recording"]["start_unix_s"] - 1598007000.388) < 1.0


@pytest.mark.real_data("humolire_phone_landmarks")
def test_humolire_landmarks_and_common_clock(tmp_path):
    paths, _ = _import("humolire", HUMOLIRE, tmp_path)
    rec = load_recording(paths[0])
    assert rec.id == "square_2x" and rec.placement == "hand" and rec.subject == {"height_m": 1.86}
    assert abs(rec.sample_rate_hz - 200.0) < 1e-6
    dt = np.diff(rec.imu["t_s"].to_numpy())
    assert np.allclose(dt, 0.005, atol=2e-6)
    assert 9.4 < _median_acc(rec) < 10.2
    marks = rec.reference["landmarks"]
    assert len(marks) == 8
    np.testing.assert_allclose(marks["t_s"].iloc[[0, -1]], [10.546, 80.799])
    np.testing.assert_allclose(marks[["e_m", "n_m"]].iloc[0], [23.191, 6.481])
    summary = rec.reference["summary"]
    assert abs(summary["distance_m"] - 120.8) < 0.1 and summary["loop_closure"] is True
    traj = rec.reference["trajectory"]
    assert len(traj) == 9 and np.allclose(traj[["e_m", "n_m"]].iloc[0], [7.147, 6.154])
    assert rec.imu["t_s"].iloc[0] < 0.2 and 80.9 < rec.imu["t_s"].iloc[-1] < 81.4


@pytest.mark.real_data("humolire_phone_landmarks")
def test_humolire_box_average_matches_mean_of_raw_samples(tmp_path):
    """The 200 Hz sample at t is the time-weighted mean of the raw samples within t +- 2.5 ms (checked on raw data)."""
    paths, _ = _import("humolire", HUMOLIRE, tmp_path)
    rec = load_recording(paths[0])
    raw = pd.read_csv(HUMOLIRE / "accelerometer-calibrated.txt", sep=r"\s+", skiprows=5)
    t_raw, z_raw = raw["elapsed-time-sensor"].to_numpy(), raw["z"].to_numpy()
    for k in (1000, 8000, 15000):
        t = rec.imu["t_s"].iloc[k]
        fine = np.linspace(t - 0.0025, t + 0.0025, 2001)
        expected = np.trapezoid(np.interp(fine, t_raw, z_raw), fine) / 0.005
        assert abs(rec.imu["acc_z_mps2"].iloc[k] - expected) < 1e-4


@pytest.fixture(scope="module")
def gaitmap_recs(tmp_path_factory):
    real_dataset("gaitmap_foot_imu_mocap")
    dest = tmp_path_factory.mktemp("gaitmap")
    paths, messages = _import("gaitmap", GAITMAP, dest)
    return {p.name: load_recording(p) for p in paths}, messages


def test_gaitmap_strides_and_feet(gaitmap_recs):
    recs, messages = gaitmap_recs
    assert sorted(recs) == ["stairs_down", "stairs_up", "walk_2x20m"]
    assert any("--rate-hz was not given" in m for m in messages)
    walk = recs["walk_2x20m"]
    assert walk.placement == "foot_left" and list(walk.extra_imus) == ["foot_right"]
    assert abs(walk.sample_rate_hz - 204.8) < 1e-3
    strides = walk.reference["strides"]
    assert len(strides) == 57 and (strides["foot"] == "left").sum() == 28 and (strides["foot"] == "right").sum() == 29
    lengths = np.sort(strides["length_m"].to_numpy())
    assert np.all(lengths[:2] < 0.7)  # the two strides of the 180° turn: 0.47 m and 0.62 m
    straight = lengths[(lengths > 1.25)]
    assert len(straight) >= 50 and straight.min() > 1.28 and straight.max() < 1.47
    steps = walk.reference["steps"]
    assert set(steps["foot"]) == {"left", "right"} and np.all(np.diff(steps["t_s"]) >= 0)
    assert walk.reference["summary"]["n_strides"] == 57
    for rec in recs.values():
        assert 8.0 < _median_acc(rec) < 11.5
        for imu in rec.imus_by_placement().values():
            assert imu[["gyr_x_radps", "gyr_y_radps", "gyr_z_radps"]].abs().max().max() < 40  # deg/s -> rad/s
    assert recs["stairs_up"].reference["summary"]["activity"] == "stairs_up"
    assert abs(recs["stairs_down"].sample_rate_hz - 204.8) < 1e-3


@pytest.mark.real_data("gaitmap_foot_imu_mocap")
def test_gaitmap_rate_hz_sets_the_clock(tmp_path):
    paths, messages = _import("gaitmap", GAITMAP / "imu_sample.csv", tmp_path, rate_hz=102.4)
    rec = load_recording(paths[0])
    assert abs(rec.sample_rate_hz - 102.4) < 1e-3 and not any("--rate-hz" in m for m in messages)
    assert abs(rec.reference["strides"]["t_start_s"].min() - 371 / 102.4) < 1e-6


@pytest.mark.real_data("xio_foot_imu_loop_walk")
def test_xio_repaired_clock_units_and_loop(tmp_path):
    paths, messages = _import("xio", XIO, tmp_path)
    rec = load_recording(paths[0])
    assert rec.id == "short_walk" and rec.placement == "foot_right"
    assert any("dropped 205 sample(s)" in m for m in messages)
    assert len(rec.imu) == 16539 - 205 and np.all(np.diff(rec.imu["t_s"]) > 0)
    assert 9.5 < _median_acc(rec) < 10.1
    np.testing.assert_allclose(rec.imu[["acc_x_mps2", "acc_y_mps2", "acc_z_mps2"]].iloc[0],
                               np.array([-0.4937814, 0.2420433, 0.8312204]) * GRAVITY_MPS2, rtol=1e-7)
    np.testing.assert_allclose(rec.imu["gyr_x_radps"].iloc[0], np.radians(-0.1428319), rtol=1e-7)
    assert not rec.reference  # the CSV carries no truth: nothing is assumed
    rec = load_recording(_import("xio", XIO, tmp_path / "loop", closed_loop=True, foot="left")[0][0])
    assert rec.reference["summary"] == {"loop_closure": True, "final_displacement_m": 0.0}
    assert rec.placement == "foot_left" and "placement_assumed" not in rec.meta["recording"]


@pytest.mark.real_data("openshoe_foot_imu_figure8")
def test_openshoe_units_rate_foot_and_declared_loop(tmp_path):
    src = real_dataset("openshoe_foot_imu_figure8") / "data_inert_left.txt"
    rec = load_recording(_import("openshoe", src, tmp_path / "a", closed_loop=True)[0][0])
    assert rec.id == "data_inert_left" and rec.placement == "foot_left" and len(rec.imu) == 51055
    assert abs(rec.sample_rate_hz - 820.0) < 0.1 and 9.0 < _median_acc(rec) < 14.0
    assert rec.reference["summary"]["loop_closure"] is True
    renamed = tmp_path / "walk.txt"
    renamed.write_bytes(src.read_bytes())
    with pytest.raises(InputError, match="--foot"):
        import_recordings("openshoe", renamed, tmp_path / "b")
    rec = load_recording(import_recordings("openshoe", renamed, tmp_path / "b", foot="right", rate_hz=410.0)[0])
    assert rec.placement == "foot_right" and abs(rec.sample_rate_hz - 410.0) < 0.1 and not rec.reference
    deg = tmp_path / "data_inert_right.txt"
    a = np.loadtxt(src, delimiter=",")
    np.savetxt(deg, np.column_stack([a[:, :3], np.degrees(a[:, 3:])]), delimiter=",")
    with pytest.raises(InputError, match="deg/s"):
        import_recordings("openshoe", deg, tmp_path / "c")
    with pytest.raises(InputError, match="--closed-loop"):
        import_recordings("gaitmap", deg, tmp_path / "d", closed_loop=True)


@pytest.mark.real_data("gaitmap_foot_imu_mocap")
def test_gaitmap_any_file_name_and_layout(tmp_path):
    src = tmp_path / "src"
    src.mkdir()
    (src / "imu_two_feet_walk.csv").write_bytes((GAITMAP / "imu_sample.csv").read_bytes())
    (src / "stride_borders_two_feet_walk.csv").write_bytes((GAITMAP / "stride_borders_sample.csv").read_bytes())
    (src / "notes.csv").write_text("a,b\n1,2\n")
    paths, _ = _import("gaitmap", src, tmp_path / "out", rate_hz=102.4)
    assert [p.name for p in paths] == ["imu_two_feet_walk"]
    rec = load_recording(paths[0])
    assert abs(rec.sample_rate_hz - 102.4) < 1e-3 and len(rec.reference["strides"]) == 58
    assert rec.reference["strides"]["length_m"].isna().all()


# ---------------------------------------------------------------------------------------------------------------
# Hand-written app exports
# ---------------------------------------------------------------------------------------------------------------


def _zip_folder(folder: Path, zip_path: Path, prefix: str = "") -> Path:
    with zipfile.ZipFile(zip_path, "w", zipfile.ZIP_DEFLATED) as zf:
        for p in sorted(folder.rglob("*")):
            if p.is_file():
                zf.write(p, prefix + p.relative_to(folder).as_posix())
    return zip_path


def test_sensorlogger_android_folder_and_zip(tmp_path):
    src = HAND / "sensorlogger_android"
    rec = load_recording(_import("sensorlogger", src, tmp_path / "a")[0][0])
    total = pd.read_csv(src / "TotalAcceleration.csv")
    gyr = pd.read_csv(src / "Gyroscope.csv")
    t_acc = (total["time"] - total["time"].iloc[0]).to_numpy() / 1e9
    assert rec.meta["recording"]["start_unix_s"] == total["time"].iloc[0] / 1e9
    # acc = TotalAcceleration (columns are z, y, x in the file), gyro interpolated onto the accelerometer clock
    k = 10
    row = rec.imu.iloc[k]
    j = int(np.flatnonzero(np.isclose(t_acc, row["t_s"]))[0])
    np.testing.assert_allclose(row[["acc_x_mps2", "acc_z_mps2"]], total[["x", "z"]].iloc[j], rtol=1e-7)
    t_gyr = (gyr["time"] - total["time"].iloc[0]).to_numpy() / 1e9
    np.testing.assert_allclose(row["gyr_x_radps"], np.interp(row["t_s"], t_gyr, gyr["x"]), rtol=1e-6)
    assert rec.imu["mag_z_ut"].iloc[0] == -40.0 and 1013.2 < rec.imu["baro_hpa"].iloc[0] < 1013.3
    gnss = rec.gnss
    assert len(gnss) == 3 and np.isnan(gnss["h_acc_m"].iloc[1]) and gnss["h_acc_m"].iloc[0] == 8.0
    np.testing.assert_allclose(gnss["t_s"], [0.3, 1.3, 1.9])
    assert rec.geo_origin == (50.78, 7.59)
    zipped = load_recording(_import("sensorlogger", _zip_folder(src, tmp_path / "export.zip", "2024-06-01_10-00-00/"),
                                    tmp_path / "b")[0][0])
    assert zipped.id == "export"
    pd.testing.assert_frame_equal(zipped.imu, rec.imu)


def test_sensorlogger_ios_gravity_added_and_sign_flipped(tmp_path):
    paths, messages = _import("sensorlogger", HAND / "sensorlogger_ios", tmp_path)
    rec = load_recording(paths[0])
    assert any("iOS" in m for m in messages)
    assert 9.5 < np.median(rec.imu["acc_z_mps2"]) < 10.5  # +z up when flat, gravity added back
    android = load_recording(_import("sensorlogger", HAND / "sensorlogger_android", tmp_path / "a")[0][0])
    np.testing.assert_allclose(rec.imu["acc_z_mps2"].to_numpy(), android.imu["acc_z_mps2"].to_numpy(), atol=1e-5)


def test_fixtures_are_byte_faithful():
    """What the apps write: Sensor Logger's Metadata.csv without a final line break, an empty Location.csv when no
    fix came; phyphox data files ending without a line break, often with an empty row ``""``."""
    for name in ("sensorlogger_android", "sensorlogger_ios", "sensorlogger_ios_uncalibrated", "sensorlogger_ios_clocks"):
        assert not (HAND / name / "Metadata.csv").read_bytes().endswith(b"\n")
    assert (HAND / "sensorlogger_ios_uncalibrated" / "Location.csv").stat().st_size == 0
    assert (HAND / "phyphox_multi" / "Accelerometer.csv").read_bytes().endswith(b'\n""')
    assert not (HAND / "phyphox_multi" / "Gyroscope.csv").read_bytes().endswith(b"\n")
    assert (HAND / "phyphox_custom" / "Acceleration.csv").read_bytes().startswith(b'"time","Acceleration x"')


def test_sensorlogger_ios_uncalibrated_in_g_and_empty_location(tmp_path):
    paths, messages = _import("sensorlogger", HAND / "sensorlogger_ios_uncalibrated", tmp_path / "u")
    rec = load_recording(paths[0])
    android = load_recording(_import("sensorlogger", HAND / "sensorlogger_android", tmp_path / "a")[0][0])
    np.testing.assert_allclose(rec.imu["acc_z_mps2"].to_numpy(), android.imu["acc_z_mps2"].to_numpy(), atol=1e-5)
    assert rec.gnss is None and any("Location.csv: empty file" in m for m in messages)


def test_sensorlogger_android_uncalibrated_in_mps2(tmp_path):
    """An Android export whose only accelerometer file is ``AccelerometerUncalibrated.csv`` (the same columns as every
    motion file, m/s² with gravity: on Android the same data as ``TotalAcceleration.csv``) is read unscaled."""
    src = tmp_path / "export"
    shutil.copytree(HAND / "sensorlogger_android", src)
    (src / "TotalAcceleration.csv").rename(src / "AccelerometerUncalibrated.csv")
    for name in ("Accelerometer.csv", "Gravity.csv"):
        (src / name).unlink()
    rec = load_recording(_import("sensorlogger", src, tmp_path / "u")[0][0])
    android = load_recording(_import("sensorlogger", HAND / "sensorlogger_android", tmp_path / "a")[0][0])
    pd.testing.assert_frame_equal(rec.imu, android.imu)
    assert 9.0 < _median_acc(rec) < 10.6


def test_sensorlogger_ios_clock_origins_aligned(tmp_path):
    paths, messages = _import("sensorlogger", HAND / "sensorlogger_ios_clocks", tmp_path)
    rec = load_recording(paths[0])
    np.testing.assert_allclose(rec.gnss["t_s"], [0.3, 1.3, 1.9], atol=1e-6)
    assert any("-20562.0 s from the accelerometer" in m or "+20562.0 s" in m for m in messages), messages
    # the absolute time kept is the one Metadata.csv's recording epoch time agrees with (the location's)
    assert abs(rec.meta["recording"]["start_unix_s"] - 1717236000.2) < 1e-3


def test_sensorlogger_clock_apart_without_seconds_elapsed_refused(tmp_path, capsys):
    src = tmp_path / "export"
    shutil.copytree(HAND / "sensorlogger_ios_clocks", src)
    loc = pd.read_csv(src / "Location.csv").drop(columns="seconds_elapsed")
    loc.to_csv(src / "Location.csv", index=False)
    rc, _, err = _cli(["import", "sensorlogger", src, tmp_path / "out"], capsys)
    _assert_one_error(rc, err)
    assert "Location.csv" in err and "another origin" in err and not (tmp_path / "out").exists()


def test_phyphox_custom_experiment_paused_gives_one_recording_per_run(tmp_path):
    paths, messages = _import("phyphox", HAND / "phyphox_custom", tmp_path)
    assert [p.name for p in paths] == ["phyphox_custom_run1", "phyphox_custom_run2"]
    runs = [load_recording(p) for p in paths]
    assert [r.meta["recording"]["start_unix_s"] for r in runs] == [1717236000.0, 1717236030.75]
    for r in runs:
        assert r.imu["t_s"].iloc[0] < 0.02 and r.imu["t_s"].iloc[-1] < 0.76 and "baro_hpa" in r.imu
        assert len(r.gnss) == 2 and np.all(np.diff(r.gnss["t_s"]) > 0)
    assert any("paused 1 time" in m for m in messages)


@pytest.mark.parametrize("fmt, folder, name", [("phyphox", "phyphox_multi", "Linear Accelerometer.csv"),
                                               ("sensorlogger", "sensorlogger_android", "Accelerometer.csv")])
def test_linear_acceleration_named_accelerometer_refused_naming_the_file(tmp_path, capsys, fmt, folder, name):
    src = tmp_path / "export"
    src.mkdir()
    if fmt == "phyphox":
        shutil.copy(HAND / folder / name, src / "Accelerometer.csv")  # gravity removed, in a file named Accelerometer.csv
    else:
        shutil.copy(HAND / folder / name, src / "TotalAcceleration.csv")
    rc, _, err = _cli(["import", fmt, src, tmp_path / "out"], capsys)
    _assert_one_error(rc, err)
    expected = "Accelerometer.csv" if fmt == "phyphox" else "TotalAcceleration.csv"
    assert "linear acceleration (gravity removed)" in err and expected in err and "imu.csv" not in err
    assert not (tmp_path / "out").exists()


def test_other_apps_zip_mixed_exports_and_unknown_columns_refused(tmp_path, capsys):
    other = _zip_folder(HAND / "phyphox_multi", tmp_path / "phyphox.zip")
    rc, _, err = _cli(["import", "sensorlogger", other, tmp_path / "out"], capsys)
    _assert_one_error(rc, err)
    assert "Sensor Logger" in err
    mixed = tmp_path / "mixed"
    shutil.copytree(HAND / "sensorlogger_android", mixed / "a")
    shutil.copytree(HAND / "sensorlogger_ios", mixed / "b")
    rc, _, err = _cli(["import", "sensorlogger", mixed, tmp_path / "out"], capsys)
    _assert_one_error(rc, err)
    assert "found 2" in err
    odd = tmp_path / "odd"
    shutil.copytree(HAND / "sensorlogger_android", odd)
    (odd / "TotalAcceleration.csv").write_text("when,a,b,c\n1,2,3,4\n")
    rc, _, err = _cli(["import", "sensorlogger", odd, tmp_path / "out"], capsys)
    _assert_one_error(rc, err)
    assert "TotalAcceleration.csv" in err and "time, x, y, z" in err
    assert not (tmp_path / "out").exists()


def _export(tmp_path: Path, parts: dict[str, str], drop: tuple[str, ...] = (), header: dict[str, str] | None = None) -> Path:
    """A folder made of fixture exports: ``parts`` maps a subfolder ("" = the folder itself) to a fixture, ``drop``
    removes files, ``header`` replaces a file's content."""
    src = tmp_path / "export"
    for sub, fixture in parts.items():
        shutil.copytree(HAND / fixture, src / sub, dirs_exist_ok=True)
    for name in drop:
        (src / name).unlink()
    for name, text in (header or {}).items():
        (src / name).write_text(text)
    return src


BAD_EXPORTS = {
    "sensorlogger no accelerometer": ("sensorlogger", {"": "sensorlogger_android"},
                                      ("Accelerometer.csv", "TotalAcceleration.csv", "Gravity.csv"), None,
                                      ("export", "expected a Sensor Logger export with Accelerometer.csv", "Gyroscope.csv")),
    "phyphox no accelerometer": ("phyphox", {"": "phyphox_multi"}, ("Accelerometer.csv", "Linear Accelerometer.csv"), None,
                                 ("export", "expected a phyphox export with acceleration including gravity", "Gyroscope.csv")),
    "sensorlogger given phyphox's zip": ("sensorlogger", {"": "phyphox_multi"}, (), None,
                                         ("export.zip", "expected a Sensor Logger export, found a phyphox export",
                                          "pdr import phyphox")),
    "phyphox given sensor logger's zip": ("phyphox", {"": "sensorlogger_android"}, (), None,
                                          ("export.zip", "expected a phyphox export, found a Sensor Logger export",
                                           "pdr import sensorlogger")),
    "sensorlogger two exports": ("sensorlogger", {"a": "sensorlogger_android", "b": "sensorlogger_ios"}, (), None,
                                 ("export", "expected one Sensor Logger export, found 2 (a, b)")),
    "phyphox two exports": ("phyphox", {"a": "phyphox_multi", "b": "phyphox_custom"}, (), None,
                            ("export", "expected one phyphox export, found 2 (a, b)")),
    "sensorlogger files mixed with phyphox's": ("sensorlogger", {"": "sensorlogger_ios", "x": "phyphox_multi"}, (), None,
                                                ("export", "expected one export per folder", "Pressure.csv")),
    "phyphox files mixed with sensor logger's": ("phyphox", {"": "phyphox_custom", "x": "sensorlogger_ios"}, (), None,
                                                 ("export", "expected one export per folder", "Gravity.csv")),
    "sensorlogger unknown columns": ("sensorlogger", {"": "sensorlogger_android"}, (),
                                     {"TotalAcceleration.csv": "when,a,b,c\n1,2,3,4\n"},
                                     ("TotalAcceleration.csv", "expected Sensor Logger columns time, x, y, z", "when, a, b, c")),
    "phyphox unknown columns": ("phyphox", {"": "phyphox_multi"}, (), {"Accelerometer.csv": "when,a,b,c\n1,2,3,4\n"},
                                ("Accelerometer.csv", "expected phyphox columns", "when, a, b, c")),
}


@pytest.mark.parametrize("case", list(BAD_EXPORTS))
def test_bad_phone_exports_one_error_line_naming_the_file_nothing_written(tmp_path, capsys, case):
    """Each bad input of a phone export, through ``main(argv)``: one ``error:`` line naming the user's file or
    folder and what was expected, exit 1, no output folder."""
    fmt, parts, drop, header, words = BAD_EXPORTS[case]
    src = _export(tmp_path, parts, drop, header)
    if "zip" in case:
        src = _zip_folder(src, tmp_path / "export.zip")
    if "mixed" in case:  # the other app's files copied into the export folder itself
        for p in sorted((src / "x").iterdir()):
            if p.is_file() and not (src / p.name).exists():
                shutil.move(p, src / p.name)
        shutil.rmtree(src / "x")
    rc, out, err = _cli(["import", fmt, src, tmp_path / "out"], capsys)
    _assert_one_error(rc, err)
    for w in words:
        assert w in err, (w, err)
    assert not (tmp_path / "out").exists() and out == ""


def test_sensorlogger_without_gravity_is_refused(tmp_path):
    src = tmp_path / "export"
    shutil.copytree(HAND / "sensorlogger_ios", src)
    (src / "Gravity.csv").unlink()
    with pytest.raises(InputError, match="Gravity.csv"):
        import_recordings("sensorlogger", src, tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_phyphox_folder_zip_and_decimal_comma(tmp_path):
    src = HAND / "phyphox_multi"
    rec = load_recording(_import("phyphox", src, tmp_path / "a")[0][0])
    acc = pd.read_csv(src / "Accelerometer.csv")
    assert abs(rec.imu["acc_y_mps2"].iloc[0] - acc["Y (m/s^2)"].iloc[1]) < 1e-7  # not the linear file, trimmed to gyro
    assert "gyr_z_radps" in rec.imu and "baro_hpa" in rec.imu and "mag_x_ut" not in rec.imu
    assert rec.meta["recording"]["start_unix_s"] == 1717236000.0
    assert len(rec.gnss) == 2 and rec.geo_origin == (48.15, 11.58) and list(rec.gnss["alt_m"]) == [520.0, 520.2]
    zipped = load_recording(_import("phyphox", _zip_folder(src, tmp_path / "walk.zip"), tmp_path / "b")[0][0])
    pd.testing.assert_frame_equal(zipped.imu, rec.imu)
    semi = load_recording(_import("phyphox", HAND / "phyphox_rawdata_semicolon", tmp_path / "c")[0][0])
    np.testing.assert_allclose(semi.imu["acc_y_mps2"], acc["Y (m/s^2)"].dropna(), rtol=1e-8)


def test_phyphox_tab_separated_export(tmp_path):
    """phyphox's "Tabulator" export: the same quoted headers, tab-separated, ending without a line break."""
    src = tmp_path / "tabs"
    shutil.copytree(HAND / "phyphox_multi", src)
    for path in sorted(src.glob("*.csv")):
        path.write_bytes(path.read_bytes().replace(b'","', b'"\t"').replace(b",", b"\t"))
    rec = load_recording(_import("phyphox", src, tmp_path / "a")[0][0])
    comma = load_recording(_import("phyphox", HAND / "phyphox_multi", tmp_path / "b")[0][0])
    pd.testing.assert_frame_equal(rec.imu, comma.imu)


def test_phyphox_linear_only_and_g_units_are_refused(tmp_path, capsys):
    lin = tmp_path / "lin"
    lin.mkdir()
    shutil.copy(HAND / "phyphox_multi" / "Linear Accelerometer.csv", lin)
    rc, _, err = _cli(["import", "phyphox", lin, tmp_path / "out"], capsys)
    _assert_one_error(rc, err)
    assert "linear" in err and not (tmp_path / "out").exists()
    g = tmp_path / "g"
    g.mkdir()
    acc = pd.read_csv(HAND / "phyphox_multi" / "Accelerometer.csv")
    acc.iloc[:, 1:] = acc.iloc[:, 1:] / GRAVITY_MPS2  # a file in g mislabelled m/s^2
    acc.to_csv(g / "Accelerometer.csv", index=False)
    rc, _, err = _cli(["import", "phyphox", g, tmp_path / "out"], capsys)
    _assert_one_error(rc, err)
    assert "look like g" in err and not (tmp_path / "out").exists()


@pytest.fixture
def android_rec(tmp_path) -> Path:
    return _import("sensorlogger", HAND / "sensorlogger_android", tmp_path / "recs")[0][0]


def test_gpx_on_the_recording_clock(android_rec, capsys):
    (android_rec / "gnss.csv").unlink()
    extra = android_rec / "reference"
    extra.mkdir()
    (extra / "notes.txt").write_text("kept")
    rc, out, err = _cli(["import", "gpx", HAND / "track.gpx", android_rec], capsys)
    assert rc == 0 and out.strip() == str(android_rec), err
    rec = load_recording(android_rec)
    # start_unix_s = 10:00:00.200 UTC; points at :01, :02, :03.5 and 12:00:04+02:00
    np.testing.assert_allclose(rec.gnss["t_s"], [0.8, 1.8, 3.3, 3.8])
    assert np.isnan(rec.gnss["alt_m"].iloc[3]) and rec.gnss["alt_m"].iloc[0] == 52.3
    assert rec.geo_origin == (50.78, 7.59)  # kept from the import
    assert (extra / "notes.txt").read_text() == "kept"  # the rest of the recording is carried over


def test_gpx_without_start_time_and_existing_gnss(android_rec, capsys):
    meta = (android_rec / "meta.toml").read_text()
    (android_rec / "meta.toml").write_text(meta.replace("start_unix_s", "# start_unix_s"))
    rc, _, err = _cli(["import", "gpx", HAND / "track.gpx", android_rec], capsys)
    _assert_one_error(rc, err)  # gnss.csv from the Sensor Logger import exists
    assert "--force" in err
    rc, _, err = _cli(["import", "gpx", HAND / "track.gpx", android_rec, "--force"], capsys)
    assert rc == 0 and "warning:" in err and "first point is taken as t_s = 0" in err
    rec = load_recording(android_rec)
    np.testing.assert_allclose(rec.gnss["t_s"], [0.0, 1.0, 2.5, 3.0])


def test_gpx_entity_declarations_refused(android_rec, tmp_path, capsys):
    bomb = tmp_path / "bomb.gpx"
    bomb.write_text('<?xml version="1.0"?>\n<!DOCTYPE gpx [<!ENTITY a "aaaaaaaaaa"><!ENTITY b "&a;&a;&a;&a;">]>\n'
                    '<gpx><trk><trkseg><trkpt lat="1" lon="2"><time>&b;</time></trkpt></trkseg></trk></gpx>\n')
    before = (android_rec / "gnss.csv").read_bytes()
    rc, _, err = _cli(["import", "gpx", bomb, android_rec, "--force"], capsys)
    _assert_one_error(rc, err)
    assert "DOCTYPE" in err and (android_rec / "gnss.csv").read_bytes() == before


# ---------------------------------------------------------------------------------------------------------------
# Hostile archives and bad input, through the CLI: exit 1, one error line, nothing written
# ---------------------------------------------------------------------------------------------------------------


def _zip_with(path: Path, members: dict[str, bytes], symlink: str | None = None) -> Path:
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
        for name, data in members.items():
            zf.writestr(name, data)
        if symlink:
            info = zipfile.ZipInfo(symlink)
            info.external_attr = (stat.S_IFLNK | 0o777) << 16
            zf.writestr(info, "/etc/passwd")
    return path


@pytest.mark.parametrize("members, symlink, message", [
    ({"../evil.csv": b"x"}, None, "escapes"),
    ({"/abs/Accelerometer.csv": b"x"}, None, "absolute"),
    ({"Gravity.csv": b"x"}, "Accelerometer.csv", "symbolic link"),
    ({"Accelerometer.csv": b"0" * 2_000_000}, None, "compression ratio"),
])
def test_hostile_zip_refused(tmp_path, capsys, members, symlink, message):
    archive = _zip_with(tmp_path / "export.zip", members, symlink)
    for fmt in ("sensorlogger", "phyphox"):
        rc, _, err = _cli(["import", fmt, archive, tmp_path / "out"], capsys)
        _assert_one_error(rc, err)
        assert message in err
    assert not (tmp_path / "out").exists() and not (tmp_path / "evil.csv").exists()


def test_zip_total_size_limit(tmp_path, capsys, monkeypatch):
    archive = _zip_folder(HAND / "sensorlogger_android", tmp_path / "export.zip")
    monkeypatch.setattr(_common, "MAX_ZIP_TOTAL_BYTES", 10_000)
    rc, _, err = _cli(["import", "sensorlogger", archive, tmp_path / "out"], capsys)
    _assert_one_error(rc, err)
    assert "bytes" in err and not (tmp_path / "out").exists()


def _truncated(src: Path, dest: Path) -> Path:
    data = src.read_bytes()
    dest.write_bytes(data[: len(data) // 2 + 7])  # cut in the middle of a row
    return dest


def _text_in_numbers(src: Path, dest: Path) -> Path:
    lines = src.read_text().splitlines()
    sep = "," if "," in lines[50] else " "
    fields = lines[50].split(sep)
    fields[3] = "abc"
    lines[50] = sep.join(fields)
    dest.write_text("\n".join(lines) + "\n")
    return dest


@pytest.mark.parametrize("case", ["missing", "empty", "truncated", "text", "wrong_folder", "wrong_file", "not_zip"])
@pytest.mark.parametrize("fmt", ["xio", "oxford", "humolire", "gaitmap", "mobgap", "sensorlogger", "phyphox"])
def test_bad_input_exit_1_one_line_no_output(tmp_path, capsys, fmt, case):
    src_by_fmt = {"xio": XIO, "oxford": OXFORD / "validation" / "user1_hand_1506421989895.csv",
                  "humolire": HUMOLIRE / "accelerometer-calibrated.txt", "gaitmap": GAITMAP / "imu_sample.csv",
                  "mobgap": MOBGAP / "001" / "data.mat", "sensorlogger": HAND / "sensorlogger_android" / "TotalAcceleration.csv",
                  "phyphox": HAND / "phyphox_multi" / "Accelerometer.csv"}
    if fmt in REAL_FORMATS:
        real_dataset(REAL_FORMATS[fmt])
    real = src_by_fmt[fmt]
    folder_fmt = fmt in ("humolire", "mobgap", "sensorlogger", "phyphox")
    if case == "missing":
        src = tmp_path / "nothing"
    elif case == "wrong_folder":
        src = tmp_path / "wrong"
        src.mkdir()
        (src / "readme.txt").write_text("not a recording")
    elif case == "not_zip":
        src = tmp_path / "export.zip"
        src.write_bytes(b"PK\x03\x04 not really a zip")
    else:
        work = tmp_path / "src"
        if folder_fmt:
            shutil.copytree(real.parent, work)
        else:
            work.mkdir()
        target = work / real.name
        if case == "empty":
            target.write_bytes(b"")
        elif case == "truncated":
            _truncated(real, target)
        elif case == "text":
            if real.suffix == ".mat":
                target.write_bytes(b"MATLAB 5.0 MAT-file, text where numbers should be" + b" " * 200)
            else:
                _text_in_numbers(real, target)
        elif case == "wrong_file":
            target.write_text("hello,world\n1,2\n")
        src = work if folder_fmt else target
    dest = tmp_path / "out"
    rc, _, err = _cli(["import", fmt, src, dest], capsys)
    _assert_one_error(rc, err)
    assert _entries(dest) == []


@pytest.mark.real_data("mobgap_lowerback_tvs_lab", "gaitmap_foot_imu_mocap")
def test_existing_recording_needs_force_and_nothing_partial(tmp_path, capsys):
    dest = tmp_path / "recs"
    rc, out, _ = _cli(["import", "mobgap", MOBGAP / "001", dest], capsys)
    assert rc == 0 and len(out.split()) == 3
    shutil.rmtree(dest / "Test5_Trial1")
    shutil.rmtree(dest / "Test11_Trial1")
    rc, _, err = _cli(["import", "mobgap", MOBGAP / "001", dest], capsys)  # Test5_Trial2 still exists
    _assert_one_error(rc, err)
    assert _entries(dest) == ["Test5_Trial2"]  # none of the three written
    rc, out, _ = _cli(["import", "mobgap", MOBGAP / "001", dest, "--force"], capsys)
    assert rc == 0 and _entries(dest) == ["Test11_Trial1", "Test5_Trial1", "Test5_Trial2"]
    with pytest.raises(SystemExit) as exc:  # a usage error
        _cli(["import", "gaitmap", GAITMAP, dest, "--rate-hz", "-3"], capsys)
    assert exc.value.code == 2 and "--rate-hz" in capsys.readouterr().err


@pytest.mark.real_data("gaitmap_foot_imu_mocap")
def test_cli_prints_one_path_per_recording(tmp_path, capsys):
    rc, out, err = _cli(["import", "gaitmap", GAITMAP, tmp_path, "--rate-hz", "204.8"], capsys)
    assert rc == 0 and "warning:" not in err  # no warning when the rate is given
    assert out.split() == [str(tmp_path / n) for n in ("walk_2x20m", "stairs_down", "stairs_up")]  # file-name order


# ---------------------------------------------------------------------------------------------------------------
# Helpers: clock repair and resampling
# ---------------------------------------------------------------------------------------------------------------


def test_wild_jitter_is_resampled_with_a_warning_and_steady_clock_is_kept():
    t = np.cumsum(np.tile([0.001, 0.009], 200))  # interquartile ratio 9: "varies wildly"
    values = np.column_stack([np.sin(t), 2 * t])
    with warns(match="resampled linearly to a uniform 200 Hz grid"):
        t_new, v_new = _common.steady_clock(t, values, "x")
    np.testing.assert_allclose(np.diff(t_new), 0.005)
    np.testing.assert_allclose(v_new[:, 1], 2 * t_new, atol=1e-12)
    t_ok = np.arange(100) * 0.01 + np.tile([0.0, 0.002], 50)  # mild jitter: kept as recorded
    same_t, same_v = _common.steady_clock(t_ok, t_ok[:, None], "x")
    assert same_t is t_ok


def test_resample_mean_is_the_window_average():
    rng = np.random.default_rng(1)
    t = np.cumsum(rng.uniform(0.001, 0.004, 2000))
    grid = _common.uniform_grid(t[0] + 0.01, t[-1] - 0.01, 100.0)
    out = _common.resample_mean(grid, t, np.column_stack([np.full_like(t, 3.0), 5 * t]), 100.0)
    np.testing.assert_allclose(out[:, 0], 3.0)
    np.testing.assert_allclose(out[:, 1], 5 * grid, rtol=1e-12)  # the mean of a line over a centred window


def test_increasing_mask_drops_repeats_and_back_steps():
    t = np.r_[0.0, 0.1, 0.1, 0.2, 0.15, 0.3, np.arange(0.4, 10.0, 0.1)]
    with warns(match="dropped 2 sample"):
        keep = _common.increasing_mask(t, "x")
    assert keep[:6].tolist() == [True, True, False, True, False, True] and keep[6:].all()
    with pytest.raises(InputError, match="clock jump or an unsorted file"):
        _common.increasing_mask(np.r_[np.arange(50.0), 1000.0, np.arange(50.0, 100.0)], "x")


def test_phyphox_unsorted_time_repaired(tmp_path):
    src = tmp_path / "exp"
    src.mkdir()
    lines = (HAND / "phyphox_multi" / "Accelerometer.csv").read_text().splitlines()
    lines.insert(40, lines[38])  # a row that steps back in time
    (src / "Accelerometer.csv").write_text("\n".join(lines) + "\n")
    paths, messages = _import("phyphox", src, tmp_path / "out")
    rec = load_recording(paths[0])
    assert any("dropped 1 sample" in m for m in messages) and len(rec.imu) == 150


@pytest.mark.real_data("oxford_step_counter")
def test_oxford_optimisation_position_from_folder_name(tmp_path):
    src = tmp_path / "Pixel_Ann_Carpet_InHand_2"
    shutil.copytree(OXFORD / "optimisation" / "data" / "Samsung_Carmelo_Hard_Purse_1", src)
    rec = load_recording(_import("oxford", src, tmp_path / "out")[0][0])
    assert rec.id == "Pixel_Ann_Carpet_InHand_2" and rec.placement == "hand"


@pytest.mark.parametrize("fmt, name", [("sensorlogger", "sensorlogger_android"), ("sensorlogger", "sensorlogger_ios"),
                                       ("sensorlogger", "sensorlogger_ios_uncalibrated"),
                                       ("sensorlogger", "sensorlogger_ios_clocks"), ("phyphox", "phyphox_multi"),
                                       ("phyphox", "phyphox_rawdata_semicolon"), ("phyphox", "phyphox_custom")])
def test_every_phone_fixture_imports_validates_and_runs(tmp_path, capsys, fmt, name):
    rc, out, err = _cli(["import", fmt, HAND / name, tmp_path / "recs"], capsys)
    assert rc == 0, err
    for rec in out.split():
        rc, out_v, err = _cli(["validate", rec], capsys)
        assert rc == 0 and out_v.startswith("ok:"), err
        rc, out_r, err = _cli(["run", rec, "-o", tmp_path / "runs" / Path(rec).name], capsys)
        assert rc == 0 and "steps" in out_r, err
