"""Sensor faults on simulated walks: 5% of the time in injected faults of every kind of
:mod:`pdr.sim.faults` (dropouts, stuck and saturated sensors, clock jumps, duplicated samples, rate changes, steel
near the magnetometer, 300 m GNSS jumps reporting a few metres of accuracy), placed at random.

Rows: the final position error of ``pdr run`` on the faulty recordings against the same walks without faults (mean
over the seeds; target: at most 20% more), and the fraction of injected intervals that ``summary.json`` ``warnings``
reports with the matching kind (target 100%). A saturation drawn where the signal stays inside the sensor's range
changes nothing and is not counted as injected (the injector gives no truth for it).

Run with ``.venv/bin/python -m benchmarks faults`` (``--quick``: two 3-minute walks instead of four 10-minute walks).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

from pdr.eval import evaluate_run
from pdr.io.recording import save_recording
from pdr.pipelines.run import run_recording
from pdr.sim import simulate
from pdr.sim.faults import inject_faults, random_faults
from pdr.errors import collect_warnings

DETECTED_AS = {"dropout": "gap", "clock_jump": "gap", "stuck": "stuck", "saturation": "saturation",
               "duplicated": "duplicated_samples", "rate_change": "rate_change", "mag_steel": "mag_disturbance",
               "gnss_jump": "gnss_jump"}
FAULT_FRACTION = 0.05
MATCH_TOLERANCE_S = 0.5
ANCHOR = "targets (no published figure for this injection set)"


def scenario(duration_s: float) -> dict:
    """An outdoor walk at changing speeds with short runs (where a +-2 g accelerometer saturates) and stops; GNSS 1 Hz."""
    pattern = [(1.3, 0.30), (0.8, 0.15), (1.7, 0.20), (2.8, 0.10), (0.0, 0.03), (1.2, 0.22)]
    segments = [{"duration_s": 5.0, "speed_mps": 0.0}]
    segments += [{"duration_s": round(frac * (duration_s - 10.0), 1), "speed_mps": v} for v, frac in pattern]
    segments.append({"duration_s": 5.0, "speed_mps": 0.0})
    return {"simulation": {"id": "faults_walk"},
            "route": {"waypoints_m": [[0, 0], [120, 0], [120, 60], [200, 60], [200, 140], [0, 140]], "loop": True},
            "segment": segments, "imu": [{"placement": "waist", "rate_hz": 100.0}],
            "gnss": {"enabled": True, "noise_m": 1.5, "markov_sigma_m": 2.5, "markov_tau_s": 120.0}}


def covered(truth: pd.DataFrame, reported: list[dict]) -> np.ndarray:
    rep = pd.DataFrame([w for w in reported if w["kind"] != "general"])
    out = []
    for f in truth.itertuples():
        same = rep[rep["kind"] == DETECTED_AS[f.kind]] if len(rep) else rep
        out.append(bool(len(same) and ((same["t_start_s"] <= f.t_end_s + MATCH_TOLERANCE_S)
                                       & (same["t_end_s"] >= f.t_start_s - MATCH_TOLERANCE_S)).any()))
    return np.array(out, bool)


def run(quick: bool = False) -> list[dict]:
    duration = 180.0 if quick else 600.0
    seeds = [1, 2] if quick else [1, 2, 3, 4]
    clean_err, faulty_err, hits, kinds, injected_s = [], [], [], [], 0.0
    with tempfile.TemporaryDirectory(prefix="pdr-bench-faults-") as tmp, collect_warnings():
        base = Path(tmp)
        for seed in seeds:
            rec = simulate(scenario(duration), seed)
            faults = random_faults(duration, np.random.default_rng([seed, 9]), fraction=FAULT_FRACTION)
            faulty, truth = inject_faults(rec, faults, seed)
            injected_s += float(sum(f["duration_s"] for f in faults))
            for name, r in (("clean", rec), ("faulty", faulty)):
                save_recording(r, base / f"{name}{seed}")
                summary = run_recording(base / f"{name}{seed}", base / f"out_{name}{seed}", force=True)
                err = float(evaluate_run(base / f"out_{name}{seed}", base / f"{name}{seed}")["final_error_m"])
                (clean_err if name == "clean" else faulty_err).append(err)
                if name == "faulty":
                    hits += list(covered(truth, summary["warnings"]))
                    kinds += list(truth["kind"])
    growth = 100.0 * (np.mean(faulty_err) / np.mean(clean_err) - 1.0)
    missed = sorted({k for k, h in zip(kinds, hits) if not h})
    case = f"{len(seeds)} simulated walks x {duration:.0f} s, {100 * FAULT_FRACTION:.0f}% of the time in faults"
    return [
        {"area": "faults", "case": case, "metric": "final position error, clean walks (mean)",
         "ours": round(float(np.mean(clean_err)), 2), "unit": "m", "target": "", "anchor": "per seed: "
         + ", ".join(f"{e:.2f}" for e in clean_err)},
        {"area": "faults", "case": case, "metric": "final position error, with faults (mean)",
         "ours": round(float(np.mean(faulty_err)), 2), "unit": "m", "target": "", "anchor": "per seed: "
         + ", ".join(f"{e:.2f}" for e in faulty_err)},
        {"area": "faults", "case": case, "metric": "final position error growth vs clean", "ours": round(growth, 1),
         "unit": "%", "target": "<= 20", "anchor": ANCHOR},
        {"area": "faults", "case": case, "metric": "injected intervals reported in warnings",
         "ours": round(100.0 * float(np.mean(hits)), 1), "unit": "%", "target": "100",
         "anchor": f"{len(hits)} intervals, {injected_s:.0f} s in all; missed kinds: {', '.join(missed) or 'none'}"},
    ]


if __name__ == "__main__":
    print(pd.DataFrame(run(quick=True)).to_string(index=False))
