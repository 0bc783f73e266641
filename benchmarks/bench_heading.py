"""Per-step heading in walking and running: the simulated mixed-gait walk ``configs/sim/walk_forms.toml`` (waist IMU,
no GNSS, no magnetometer use) against its reference heading, steps split by the speed of their segment (> 2.2 m/s:
running, a flight phase in the simulator's spring-mass gait).

The steps table of ``pdr steps`` (``detect_steps``) gives ``heading_rad`` in VQF's 6D frame, whose yaw zero is
arbitrary: the frame offset is the circular mean of (heading - truth) over the walking steps, so a running step
pointing backwards (the walking phase relation applied to running) shows as a 180-degree error.
Run with ``.venv/bin/python -m benchmarks heading`` (``--quick``: one seed).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from pdr.schema import wrap_rad
from pdr.io.recording import load_recording
from pdr.pipelines.steps import detect_steps
from pdr.sim import simulate_to_disk
from pdr.errors import collect_warnings

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "configs" / "sim" / "walk_forms.toml"
RUN_SPEED_MPS = 2.2


def heading_errors(rec) -> tuple[np.ndarray, np.ndarray]:
    """|heading error| (rad) of each detected step and whether its segment is a run."""
    table = detect_steps(rec, {})
    ref, ref_steps = rec.reference["trajectory"], rec.reference["steps"]
    t = table["t_s"].to_numpy(float)
    truth = np.interp(t, ref["t_s"], np.unwrap(ref["heading_rad"]))
    j = np.clip(np.searchsorted(ref_steps["t_s"].to_numpy(float), t), 0, len(ref_steps) - 1)
    running = ref_steps["speed_mps"].to_numpy(float)[j] > RUN_SPEED_MPS
    diff = table["heading_rad"].to_numpy(float) - truth
    frame = np.angle(np.mean(np.exp(1j * diff[~running])))
    return np.abs(wrap_rad(diff - frame)), running


def run(quick: bool = False) -> list[dict]:
    seeds = [1] if quick else [1, 2, 3]
    err, running = [], []
    with tempfile.TemporaryDirectory() as tmp, collect_warnings():
        for seed in seeds:
            path = simulate_to_disk(SCENARIO, Path(tmp) / f"wf{seed}", seed=seed, force=True)
            e, r = heading_errors(load_recording(path))
            err.append(e)
            running.append(r)
    err, running = np.degrees(np.concatenate(err)), np.concatenate(running)
    case = f"simulated walk_forms, waist, seeds {', '.join(map(str, seeds))}"
    rows = []
    for name, m in (("running", running), ("walking", ~running)):
        rows.append({"area": "heading", "case": f"{case}: {int(m.sum())} {name} steps",
                     "metric": "median |heading error|", "ours": round(float(np.median(err[m])), 2), "unit": "deg",
                     "target": "< 5", "anchor": "-"})
        rows.append({"area": "heading", "case": f"{case}: {int(m.sum())} {name} steps",
                     "metric": "steps > 90 deg off (reversed)", "ours": round(100.0 * float(np.mean(err[m] > 90.0)), 2),
                     "unit": "%", "target": "0", "anchor": "-"})
    return rows
