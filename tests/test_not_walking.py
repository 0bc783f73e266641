"""Not walking: vehicle and bicycle stretches inside a simulated phone walk, and a recording too slow for steps.

The stretches are built at test time from a simulated walk with a stop: during the stop the phone gets the
vibration of a car (broadband, with 1.5 Hz body bounce) or the pedalling of a bicycle (1.4 Hz sway), and the GNSS
moves on at the vehicle's speed, every later fix shifted by the distance driven."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from pdr.cli.main import main
from pdr.io.recording import load_recording, save_recording
from pdr.pipelines.run import run_recording
from pdr.sim.simulator import simulate
from pdr.errors import collect_warnings

WALK_S, RIDE_S = 60.0, 120.0


def _scenario() -> dict:
    return {"simulation": {"id": "ride"}, "subject": {"height_m": 1.72},
            "route": {"waypoints_m": [[0.0, 0.0], [400.0, 0.0]], "loop": False},
            "segment": [{"duration_s": WALK_S, "speed_mps": 1.3}, {"duration_s": RIDE_S, "speed_mps": 0.0},
                        {"duration_s": WALK_S, "speed_mps": 1.3}],
            "imu": [{"placement": "hand", "rate_hz": 100.0}],
            "gnss": {"enabled": True, "noise_m": 1.5, "markov_sigma_m": 2.0, "markov_tau_s": 60.0}}


def _ride(rec, kind: str, speed_mps: float, seed: int = 3):
    """The stop of ``rec`` turned into a ride of ``kind`` ("car" or "bicycle") at ``speed_mps`` heading north."""
    rng = np.random.default_rng(seed)
    imu = rec.imu.copy()
    t = imu["t_s"].to_numpy()
    a, b = WALK_S + 2.0, WALK_S + RIDE_S - 2.0
    w = (t >= a) & (t <= b)
    n = int(w.sum())
    if kind == "car":
        shake = np.cumsum(rng.normal(0.0, 0.6, (n, 3)), axis=0)
        shake -= pd.DataFrame(shake).rolling(25, center=True, min_periods=1).mean().to_numpy()
        bounce = 1.2 * np.sin(2 * np.pi * 1.5 * t[w] + rng.uniform(0, 6))[:, None] * np.array([0.2, 0.3, 1.0])
        extra = shake + bounce
    else:
        phase = 2 * np.pi * 1.4 * t[w]
        extra = np.column_stack([0.8 * np.sin(phase), 0.3 * np.sin(2 * phase), 0.5 * np.sin(2 * phase + 0.4)])
    for j, c in enumerate(("acc_x_mps2", "acc_y_mps2", "acc_z_mps2")):
        imu.loc[w, c] = imu.loc[w, c].to_numpy() + extra[:, j]
    gnss = rec.gnss.copy()
    tg = gnss["t_s"].to_numpy()
    north_m = speed_mps * np.clip(tg - a, 0.0, b - a)
    gnss["lat_deg"] = gnss["lat_deg"] + np.degrees(north_m / 6_378_137.0)
    rec.imu = imu
    rec.gnss = gnss
    return rec, (a, b)


@pytest.mark.parametrize("kind, speed_mps", [("car", 6.0), ("bicycle", 4.5)])
def test_vehicle_and_bicycle_stretches_have_no_steps_and_a_warning(tmp_path, kind, speed_mps):
    rec = simulate(_scenario(), seed=1)
    truth = rec.reference["steps"]["t_s"].to_numpy()
    rec, (a, b) = _ride(rec, kind, speed_mps)
    path = save_recording(rec, tmp_path / "rec")
    with collect_warnings() as caught:
        summary = run_recording(path, tmp_path / "out")
    messages = list(caught)
    steps = pd.read_csv(tmp_path / "out" / "steps.csv")
    t = steps["t_s"].to_numpy()
    assert not ((t > a) & (t < b)).any()
    intervals = summary["not_walking"]
    assert len(intervals) == 1 and intervals[0]["t_start_s"] < a + 10 and intervals[0]["t_end_s"] > b - 10
    assert sum("not walking from" in m for m in messages) == 1
    assert steps["step_length_m"].between(0.0, 2.0).all()  # clipped means clipped
    # the walks on either side keep their steps (the interval may take a window's width of them)
    assert len(steps) >= 0.8 * len(truth)
    gnss_dist = speed_mps * (b - a)
    assert summary["distance_m"] > 0.8 * gnss_dist
    json.loads((tmp_path / "out" / "summary.json").read_text())


def _five_hz_walk(duration_s: float, seed: int):
    """A 1.3 m/s walk whose IMU is averaged down from 100 Hz to 5 Hz (the mean of each 0.2 s, as a phone's low-rate
    sensor delivers it)."""
    sc = _scenario()
    sc["segment"] = [{"duration_s": duration_s, "speed_mps": 1.3}]
    rec = simulate(sc, seed=seed)
    block = 20
    imu = rec.imu.iloc[: len(rec.imu) // block * block]
    rec.imu = imu.groupby(np.arange(len(imu)) // block).mean().reset_index(drop=True)
    return rec


def test_five_hz_recording_follows_the_gnss_and_says_why(tmp_path, capsys):
    rec = _five_hz_walk(180.0, seed=2)
    path = save_recording(rec, tmp_path / "rec")
    with collect_warnings() as caught:
        summary = run_recording(path, tmp_path / "out")
    messages = " ".join(caught)
    assert summary["n_steps"] == 0
    assert "below twice the highest cadence" in messages and "follows the GNSS alone" in messages
    truth_m = 1.3 * 180.0
    assert 0.85 * truth_m < summary["distance_m"] < 1.3 * truth_m
    assert summary["gnss"]["used"] > 150
    traj = pd.read_csv(tmp_path / "out" / "trajectory.csv")
    assert len(traj) == summary["gnss"]["used"]
    assert load_recording(path).sample_rate_hz == pytest.approx(5.0)
    assert main(["validate", str(path)]) == 0  # the CLI prints each warning as one line
    assert "sampling rate 5.0 Hz is below twice the highest cadence (7 Hz)" in capsys.readouterr().err


def _sensor_logger_export(rec, folder, epoch_ns: int = 1717236000000000000) -> None:
    """``rec`` written as Sensor Logger 1.31 on Android writes it (the layout of tests/importers/sensorlogger_android):
    nanosecond ``time`` and ``seconds_elapsed``, axes in the order z, y, x, six decimals, ``Metadata.csv`` without a
    final line break."""
    folder.mkdir(parents=True)
    t = rec.imu["t_s"].to_numpy()

    def motion(name, cols):
        table = pd.DataFrame({"time": epoch_ns + np.round(t * 1e9).astype(np.int64), "seconds_elapsed": t,
                              "z": rec.imu[cols[2]], "y": rec.imu[cols[1]], "x": rec.imu[cols[0]]})
        table.to_csv(folder / name, index=False, float_format="%.6f", lineterminator="\n")

    motion("TotalAcceleration.csv", ["acc_x_mps2", "acc_y_mps2", "acc_z_mps2"])
    motion("Gyroscope.csv", ["gyr_x_radps", "gyr_y_radps", "gyr_z_radps"])
    g = rec.gnss
    zero = np.zeros(len(g))
    pd.DataFrame({"time": epoch_ns + np.round(g["t_s"].to_numpy() * 1e9).astype(np.int64),
                  "seconds_elapsed": g["t_s"], "bearingAccuracy": zero, "speedAccuracy": zero,
                  "verticalAccuracy": g["h_acc_m"], "horizontalAccuracy": g["h_acc_m"], "speed": zero, "bearing": zero,
                  "altitude": g["alt_m"], "longitude": g["lon_deg"], "latitude": g["lat_deg"]}).to_csv(
        folder / "Location.csv", index=False, float_format="%.7f", lineterminator="\n")
    rate_ms = int(round(1e3 * np.median(np.diff(t))))
    (folder / "Metadata.csv").write_bytes(
        b"version,device name,recording epoch time,recording time,recording timezone,platform,appVersion,device id,"
        b"sensors,sampleRateMs,standardisation\n"
        + f"3,Pixel 7,{epoch_ns // 10**6},2024-06-01_10-00-00,Europe/Berlin,android,1.31.0,5f2a9c1e,"
          f"Gyroscope|Location|TotalAcceleration,{rate_ms}|1000|{rate_ms},false".encode())


def test_five_hz_sensor_logger_export_follows_the_gnss_and_says_why(tmp_path, capsys):
    """The issue's case from the user's side: a Sensor Logger export whose motion sensors ran at 5 Hz imports,
    validates with the rate warning, and runs on the GNSS alone, saying why there are no steps."""
    rec = _five_hz_walk(120.0, seed=4)
    _sensor_logger_export(rec, tmp_path / "export")
    assert not (tmp_path / "export" / "Metadata.csv").read_bytes().endswith(b"\n")
    assert main(["import", "sensorlogger", str(tmp_path / "export"), str(tmp_path / "recs")]) == 0
    path = capsys.readouterr().out.split()[0]
    assert main(["validate", path]) == 0
    assert "sampling rate 5.0 Hz is below twice the highest cadence (7 Hz)" in capsys.readouterr().err
    assert main(["run", path, "-o", str(tmp_path / "out")]) == 0
    err = capsys.readouterr().err
    assert "below twice the highest cadence" in err and "follows the GNSS alone" in err
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["n_steps"] == 0 and summary["gnss"]["used"] > 100
    assert 0.85 * 1.3 * 120.0 < summary["distance_m"] < 1.3 * 1.3 * 120.0
