"""A peer side by side: mobgap's ``SlZijlstra`` stride length against pdr's ``ZijlstraStepLength`` (population
preset) on the Mobilise-D TVS lab lower-back walks of the dataset registry, both fed the INDIP reference initial contacts of
each walking bout, both scored against the INDIP bout distance (``reference/bouts.csv`` ``step_length_sum_m``).

mobgap is not a dependency of pdr (it brings numba, scikit-learn, pingouin and more), so it runs in an environment of
its own: ``PDR_PEER_PYTHON`` (a Python with mobgap), else ``out/peers/mobgap/bin/python``. Set it up once with
``python3 -m venv out/peers/mobgap && out/peers/mobgap/bin/pip install mobgap``. Without it the rows say so.

Run: ``.venv/bin/python -m benchmarks peer`` (``--quick`` is the same: the data are small).
"""

from __future__ import annotations

import json
import os
import subprocess
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

from benchmarks.bench_step_length import DATASETS, _bout_distance_reference_ics, _mobgap_recordings, _reference_steps
from pdr.step_length import MODELS
from pdr.errors import collect_warnings

ROOT = Path(__file__).resolve().parents[1]
PEER_SCRIPT = Path(__file__).parent / "peers" / "mobgap_stride_length.py"
TESTS = {"Test5": "straight walk (Test5)", "Test11": "daily living with turns (Test11)"}
MATCH_S = 0.05  # bouts matched by start time (mobgap's sample / rate against the importer's t_start_s)


def peer_python() -> Path | None:
    for candidate in (os.environ.get("PDR_PEER_PYTHON"), ROOT / "out" / "peers" / "mobgap" / "bin" / "python"):
        if candidate and Path(candidate).is_file():
            return Path(candidate)
    return None


def _row(case: str, metric: str, ours: float, unit: str, target: str, anchor: str) -> dict:
    return {"area": "peer", "case": case, "metric": metric, "ours": ours, "unit": unit, "target": target, "anchor": anchor}


def _ours(tmp: Path) -> pd.DataFrame:
    """pdr's per-bout distance with the reference ICs (the zijlstra population preset), and the reference."""
    rows = []
    with collect_warnings():
        for rec in _mobgap_recordings(tmp):
            path = rec.path / "reference" / "bouts.csv"
            bouts = pd.read_csv(path) if path.is_file() else pd.DataFrame()
            if not len(bouts):
                continue
            est = _bout_distance_reference_ics(MODELS["zijlstra"].population(), _reference_steps(rec, bouts), bouts,
                                               rec.subject)
            test, trial = rec.id.split("_")[:2]
            for (_, b), d in zip(bouts.iterrows(), est):
                rows.append({"participant": rec.path.parent.name, "test": test, "trial": trial, "t_start_s": b.t_start_s,
                             "n_ic": int(b.n_initial_contacts), "reference_m": b.step_length_sum_m, "pdr_m": d})
    return pd.DataFrame(rows)


def _peer(python: Path) -> pd.DataFrame:
    proc = subprocess.run([str(python), str(PEER_SCRIPT), str(DATASETS / "mobgap_lowerback_tvs_lab" / "lab")],
                          capture_output=True, text=True, timeout=900)
    if proc.returncode != 0:
        raise RuntimeError(f"bench_peer: mobgap failed: {proc.stderr.strip()[-500:]}")
    return pd.DataFrame(json.loads(proc.stdout.strip().splitlines()[-1]))


def _matched(ours: pd.DataFrame, peer: pd.DataFrame) -> pd.DataFrame:
    out = ours.copy()
    for factor in sorted(peer["factor"].unique()):
        values = []
        for _, r in ours.iterrows():
            cand = peer[(peer.factor == factor) & (peer.participant == r.participant) & (peer.test == r.test)
                        & (peer.trial == r.trial) & ((peer.t_start_s - r.t_start_s).abs() <= MATCH_S)]
            # the reference's step count for both: mean stride / 2 x (n_ic - 1)
            values.append(float(cand.mean_stride_m.iloc[0]) / 2.0 * (r.n_ic - 1) if len(cand) == 1 else np.nan)
        out[f"mobgap_{factor}_m"] = values
    return out


def run(quick: bool = False) -> list[dict]:
    python = peer_python()
    anchor = "same reference ICs and bout distances for both; K = 4.739/4 (ms_all) in both"
    if python is None:
        return [_row("mobgap SlZijlstra vs pdr ZijlstraStepLength, Mobilise-D lab lower back", "not run", float("nan"), "",
                     "", "mobgap not installed: python3 -m venv out/peers/mobgap && out/peers/mobgap/bin/pip install "
                         "mobgap (or PDR_PEER_PYTHON=...)")]
    with tempfile.TemporaryDirectory(prefix="bench_peer_") as tmp:
        table = _matched(_ours(Path(tmp)), _peer(python))
    rows = []
    for test, name in TESTS.items():
        t = table[(table.test == test)].dropna(subset=["pdr_m", "mobgap_ms_all_m"])
        if not len(t):
            continue
        ref = t.reference_m.to_numpy()
        case = f"mobgap lower back, {name}, {len(t)} bouts, {ref.sum():.1f} m, reference ICs"
        errs = {}
        for label, col, note in (("pdr ZijlstraStepLength (population preset)", "pdr_m", anchor),
                                 ("mobgap SlZijlstra (ms_all, same K)", "mobgap_ms_all_m", anchor),
                                 ("mobgap SlZijlstra (ms_ms, its default)", "mobgap_ms_ms_m",
                                  "mobgap's default K = 4.587/4; same reference ICs and bout distances")):
            est = t[col].to_numpy()
            total = 100.0 * (est.sum() / ref.sum() - 1.0)
            per_bout = 100.0 * float(np.mean(np.abs(est / ref - 1.0)))
            errs[col] = per_bout
            rows.append(_row(case, f"{label}: distance error, sum of bouts", round(total, 1), "%", "", note))
            rows.append(_row(case, f"{label}: mean |bout distance error|", round(per_bout, 1), "%", "", note))
        rows.append(_row(case, "ratio of mean |bout error|, pdr / mobgap (same K)",
                         round(errs["pdr_m"] / errs["mobgap_ms_all_m"], 2), "x", "<= 1", "below 1: pdr closer to INDIP"))
    return rows
