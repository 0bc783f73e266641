"""Short counted phone walks: the Oxford step-counting recordings cut into pieces of 20-40 steps.

Each Oxford recording (a phone in a hand, pocket, bag, armband... taken out, walked with, put away) is cut into
consecutive pieces of 20, 30, 40, 20, ... true steps. A piece runs from midway between its first step and the one
before to midway between its last step and the one after; the first piece starts at the file's start and the last
ends at its end, so they hold the real pick-up and put-away of the phone. The count is ``pdr.pipelines.steps.
detect_steps`` with its defaults (nothing tuned on these pieces: left-out data).
"""

from __future__ import annotations

import warnings

import numpy as np

from benchmarks.bench_steps import oxford_recordings
from pdr.io.recording import Recording
from pdr.pipelines.steps import detect_steps

PIECE_STEPS = (20, 30, 40)
ANCHOR = "issue target: mean |count error| <= 5 %, none > 10 %"


def _row(case: str, metric: str, ours: float, unit: str, target: str, anchor: str) -> dict:
    return {"area": "phone_walks", "case": case, "metric": metric, "ours": round(float(ours), 3), "unit": unit,
            "target": target, "anchor": anchor}


def pieces(truth: np.ndarray, t_end_s: float) -> list[tuple[float, float, int]]:
    """``(t_start_s, t_end_s, n_true)`` of consecutive pieces of ``PIECE_STEPS`` steps (cycled)."""
    out, k, c = [], 0, 0
    while k + PIECE_STEPS[c % len(PIECE_STEPS)] <= len(truth):
        n = PIECE_STEPS[c % len(PIECE_STEPS)]
        a = 0.0 if k == 0 else 0.5 * (truth[k - 1] + truth[k])
        last = k + n - 1
        b = t_end_s if last == len(truth) - 1 else 0.5 * (truth[last] + truth[last + 1])
        out.append((a, b, n))
        k, c = k + n, c + 1
    if out and k < len(truth):  # the remainder joins the last piece, which then ends at the file's end
        a, _, n = out[-1]
        out[-1] = (a, t_end_s, n + len(truth) - k)
    return out


def run(quick: bool = False) -> list[dict]:
    warnings.simplefilter("ignore")
    rows, errors, edge_errors = [], [], []
    recordings = oxford_recordings()[: 2 if quick else None]
    for name, imu, truth, _ in recordings:
        t = imu["t_s"].to_numpy()
        rec_errors = []
        for i, (a, b, n) in enumerate(pieces(truth, float(t[-1]))):
            part = imu[(t >= a) & (t <= b)].reset_index(drop=True)
            part["t_s"] -= part["t_s"].iloc[0]
            rec = Recording(meta={"recording": {"id": f"{name}_{i}", "placement": "unknown"}}, imu=part)
            e = 100.0 * (len(detect_steps(rec, {})) - n) / n
            rec_errors.append(e)
            if a == 0.0 or b == float(t[-1]):
                edge_errors.append(e)
        errors += rec_errors
        rows.append(_row(f"oxford/{name} ({len(rec_errors)} pieces)", "mean |count error|",
                         np.mean(np.abs(rec_errors)), "%", "<= 5", ANCHOR))
        rows.append(_row(f"oxford/{name}", "max |count error|", np.max(np.abs(rec_errors)), "%", "<= 10", ANCHOR))
    errors = np.abs(errors)
    rows.append(_row(f"oxford/all ({len(errors)} pieces)", "mean |count error|", errors.mean(), "%", "<= 5", ANCHOR))
    rows.append(_row("oxford/all", "pieces over 10 %", int((errors > 10).sum()), "", "0", ANCHOR))
    rows.append(_row("oxford/all", "max |count error|", errors.max(), "%", "<= 10", ANCHOR))
    rows.append(_row(f"oxford/all first+last pieces ({len(edge_errors)}, with pick-up / put-away)", "mean |count error|",
                     np.mean(np.abs(edge_errors)), "%", "<= 5", ANCHOR))
    return rows
