"""End-to-end ``pdr run`` + ``pdr evaluate``: wall time and accuracy on the real HuMoLiRe phone walk and a simulated walk.

Run with ``.venv/bin/python -m benchmarks run`` (``--quick`` for the short simulated walk only).
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

from pdr.io.datasets import dataset_dir
from pdr.eval import evaluate_run
from pdr.io.importers import import_recordings
from pdr.pipelines.run import run_recording
from pdr.sim import simulate_to_disk

ROOT = Path(__file__).resolve().parents[1]
HUMOLIRE = Path("data/imus/1/square_2x")  # inside the humolire_phone_landmarks dataset
SIM_SCENARIOS = {"quick": "configs/sim/walk_short.toml", "full": "configs/sim/walk_30min_gps.toml"}
SIM_SEED = 7
LADETTO = "Ladetto et al. 2000: 1.8% over 2,300 m with a DGPS-calibrated per-user model"


def _run_and_evaluate(rec: Path, out: Path) -> tuple[dict, dict, float]:
    t0 = time.perf_counter()
    summary = run_recording(rec, out, plot=True, force=True)
    elapsed = time.perf_counter() - t0
    return summary, evaluate_run(out, rec), elapsed


def _rows(case: str, summary: dict, metrics: dict, elapsed: float, anchor_position: str) -> list[dict]:
    rows = [{"area": "run", "case": case, "metric": "end-to-end time (run, plot included)", "ours": round(elapsed, 2), "unit": "s",
             "target": "", "anchor": f"{summary['n_steps']} steps, {summary['duration_s']:.0f} s of data"}]
    spec = [
        ("step_count_error_pct", "step count error (signed)", "%", "", ""),
        ("step_f1", f"step timing F1 (+-{metrics.get('step_f1_tolerance_s', '')} s)", "", "", ""),
        ("distance_error_pct", "distance error", "%", "", LADETTO + (
            f"; here calibrated in the graph from {summary['gnss']['used']} GNSS fixes" if summary["gnss"]["used"]
            else "; here the population preset (no GNSS)")),
        ("ate_rmse_m", f"ATE RMSE (alignment {metrics.get('alignment', '')})", "m", "", ""),
        ("final_error_pct", "final position error", "% of distance", "", anchor_position),
        ("landmark_error_mean_pct", "mean landmark error", "% of distance", "", anchor_position),
        ("landmark_error_max_pct", "max landmark error", "% of distance", "", anchor_position),
    ]
    for key, name, unit, target, anchor in spec:
        if key in metrics:
            rows.append({"area": "run", "case": case, "metric": name, "ours": round(float(metrics[key]), 3), "unit": unit,
                         "target": target, "anchor": anchor})
    return rows


def run(quick: bool = False) -> list[dict]:
    rows: list[dict] = []
    with tempfile.TemporaryDirectory(prefix="bench_run_") as tmp:
        tmp_path = Path(tmp)
        if not quick:
            (rec,) = import_recordings("humolire", dataset_dir("humolire_phone_landmarks") / HUMOLIRE, tmp_path / "humolire")
            summary, metrics, elapsed = _run_and_evaluate(Path(rec), tmp_path / "out_humolire")
            rows += _rows("HuMoLiRe square_2x (real phone, 120.8 m, no fixes)", summary, metrics, elapsed,
                          "target: <= 2% with the first two landmarks as fixes; here no fix at all (origin+heading alignment)")
        scenario = SIM_SCENARIOS["quick" if quick else "full"]
        rec = simulate_to_disk(ROOT / scenario, tmp_path / "sim", seed=SIM_SEED, force=True)
        summary, metrics, elapsed = _run_and_evaluate(Path(rec), tmp_path / "out_sim")
        rows += _rows(f"simulated {Path(scenario).stem} (seed {SIM_SEED})", summary, metrics, elapsed,
                      "target: <= 1.5% of the outage distance at the end of the 5-min GNSS outage (here: % of the whole walk)")
    return rows
