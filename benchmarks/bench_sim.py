"""The walking simulator: speed of writing a 30-minute walk, and the realism figures its truth is built on.

Run with ``.venv/bin/python -m benchmarks sim`` (``--quick``: the 2-minute scenario instead of the 30-minute one).
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from pdr.constants import GRAVITY_MPS2
from pdr.io.recording import load_recording
from pdr.sim import WalkKinematics, simulate, simulate_to_disk
from pdr.sim.sensors import ImuSpec, SensorPose, true_motion
from pdr.sim.simulator import build_walk, parse_scenario

ROOT = Path(__file__).resolve().parents[1]
SEED = 1


def _row(case, metric, ours, unit, target, anchor):
    return {"area": "sim", "case": case, "metric": metric, "ours": ours, "unit": unit, "target": target, "anchor": anchor}


def _straight(segments, **tables):
    sc = {"route": {"waypoints_m": [[0.0, 0.0], [1000.0, 0.0]], "loop": False},
          "segment": [{"duration_s": d, "speed_mps": v} for d, v in segments], "gnss": {"enabled": False},
          "imu": [{"placement": "waist", "rate_hz": 20.0}]}
    sc.update(tables)
    return sc


def run(quick: bool = False) -> list[dict]:
    rows = []
    name = "walk_short" if quick else "walk_30min_gps"
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        out = simulate_to_disk(ROOT / "configs" / "sim" / f"{name}.toml", Path(tmp) / "rec", seed=SEED)
        elapsed = time.perf_counter() - t0
        rec = load_recording(out)
    summ = rec.reference["summary"]
    rows.append(_row(name, "wall time to write the recording", round(elapsed, 2), "s", "< 10 (30 min walk)",
                     "target: a 30-minute walk in under 10 s"))
    rows.append(_row(name, "simulated duration", summ["duration_s"], "s", "", ""))
    rows.append(_row(name, "true steps / distance", f"{summ['n_steps']} / {summ['distance_m']:.0f} m", "", "", ""))
    want, got = np.array(summ["segment_target_speed_mps"]), np.array(summ["segment_speed_mps"])
    moving = want > 0
    rows.append(_row(name, "segment speed error (max over segments)",
                     round(float(np.max(np.abs(got[moving] / want[moving] - 1)) * 100), 1), "%", "< 8",
                     "speed follows the scenario; step length and frequency from the walk-ratio law"))
    if "gnss_error_rms_m" in summ:
        rows.append(_row(name, "GNSS horizontal error RMS (no outliers)", round(summ["gnss_error_rms_m"], 2), "m", "2-8",
                         "consumer GNSS: a few metres (white + Gauss-Markov)"))
    # per-step step-length variability, slow vs fast
    for v, anchor in ((0.6, 15.0), (1.8, 4.0)):
        r = simulate(_straight([(2.0, 0.0), (120.0 if quick else 300.0, v), (2.0, 0.0)]), seed=SEED)
        lengths = r.reference["steps"]["step_length_m"].to_numpy()[3:-3]
        rows.append(_row(f"steady walk {v} m/s", "step length coefficient of variation",
                         round(float(lengths.std() / lengths.mean() * 100), 1), "%", f"~{anchor:g}",
                         "Ladetto et al. 2000: about 15% at a slow pace, 4% at a fast one"))
    # outliers: the fraction written equals the fraction asked
    sc = _straight([(2.0, 0.0), (600.0, 1.3)], gnss={"outlier_fraction": 0.1, "outlier_m": 50.0})
    sc["route"] = {"waypoints_m": [[0, 0], [150, 0], [150, 80], [0, 80]], "loop": True}
    truth = simulate(sc, seed=SEED).reference["gnss_truth"]
    rows.append(_row("GNSS 10% outliers of 50 m", "outlier fraction written", round(float(truth["outlier"].mean() * 100), 2),
                     "%", "10", "target: 10% of the fixes replaced by 50 m jumps"))
    # physics: specific force at rest, gyro over a 90 deg turn
    kin = WalkKinematics.steady(speed_mps=1.3, duration_s=5.0, seed=SEED, standing_s=2.0)
    f, _, _, _ = true_motion(SensorPose(kin, ImuSpec(placement="waist"), np.random.default_rng(0)), np.arange(0.0, 1.5, 0.01))
    rows.append(_row("waist IMU standing", "|mean specific force| - g", float(f"{np.linalg.norm(f.mean(0)) - GRAVITY_MPS2:.2e}"),
                     "m/s²", "0", "specific force = R^T (a - g), g = 9.80665"))
    sc = parse_scenario(_straight([(2.0, 0.0), (30.0, 1.3), (2.0, 0.0)]) | {"route": {"waypoints_m": [[0, 0], [15, 0], [15, 40]], "loop": False}})
    kin = build_walk(sc, seed=SEED)
    rate = 200.0
    t = np.arange(0.0, 34.0, 1.0 / rate)
    _, w, _, rot = true_motion(SensorPose(kin, ImuSpec(placement="waist"), np.random.default_rng(0)), t)
    yaw_gyro = np.degrees(np.sum(0.5 * (w[1:, 2] + w[:-1, 2]) / rate))  # the pelvis stays nearly upright
    yaw_true = np.degrees(np.unwrap(np.arctan2(rot[:, 1, 0], rot[:, 0, 0]))[-1] - np.arctan2(rot[0, 1, 0], rot[0, 0, 0]))
    rows.append(_row("90 deg left turn, waist gyro", "integrated z rate - true yaw change", round(float(yaw_gyro - yaw_true), 2),
                     "deg", "|.| < 2", "gyro from the rotation sequence"))
    return rows
