"""Short counted phone walks: the Oxford step-counting recordings cut into pieces of 20-40 steps, and simulated
walks of 20-40 steps with the phone in the hand, taken out before and put away after.

Each Oxford recording (a phone in a hand, pocket, bag, armband... taken out, walked with, put away) is cut into
consecutive pieces of 20, 30, 40, 20, ... true steps. A piece runs from midway between its first step and the one
before to midway between its last step and the one after; the first piece starts at the file's start and the last
ends at its end, so they hold the real pick-up and put-away of the phone. The count is ``pdr.pipelines.steps.
detect_steps`` with its defaults (nothing tuned on these pieces: left-out data).

Simulated: stand 4 s, walk 20-40 steps at 1.3 m/s, stand 4 s, the phone in the hand; during each stand the phone is
handled (``phone_handling``): tilted by 60-100° over 1.8 s while lifted 0.4 m, with hand tremor and sway.
"""

from __future__ import annotations

import warnings

import numpy as np

from benchmarks.bench_steps import oxford_recordings
from pdr.io.recording import Recording
from pdr.pipelines.steps import detect_steps
from pdr.sim.simulator import simulate

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


def phone_handling(imu, t0_s: float, duration_s: float, rng: np.random.Generator, tilt_rad: float, lift_m: float):
    """``imu`` with the phone handled in ``[t0_s, t0_s + duration_s]``: rotated by ``tilt_rad`` about its x axis (a
    smoothstep), lifted by ``lift_m`` along its z axis (the smoothstep's acceleration), plus 0.8 m/s² tremor and a
    1-3 m/s² sway along x; the gyroscope sees the rotation."""
    imu = imu.copy()
    t = imu["t_s"].to_numpy()
    w = (t >= t0_s) & (t <= t0_s + duration_s)
    u = (t[w] - t0_s) / duration_s
    angle = tilt_rad * u * u * (3 - 2 * u)
    cols = ["acc_x_mps2", "acc_y_mps2", "acc_z_mps2"]
    acc = imu.loc[w, cols].to_numpy().copy()
    c, s = np.cos(angle), np.sin(angle)
    acc[:, 1], acc[:, 2] = c * acc[:, 1] - s * acc[:, 2], s * acc[:, 1] + c * acc[:, 2]
    acc[:, 2] += lift_m * (6 - 12 * u) / duration_s**2 + rng.normal(0.0, 0.8, int(w.sum()))
    acc[:, 0] += rng.uniform(1.0, 3.0) * np.sin(2 * np.pi * rng.uniform(1.0, 3.0) * u)
    imu.loc[w, cols] = acc
    if "gyr_x_radps" in imu:
        imu.loc[w, "gyr_x_radps"] += tilt_rad * 6 * u * (1 - u) / duration_s
    return imu


def simulated_handled_walks(n_seeds: int) -> list[tuple[int, int]]:
    """``(true steps, counted steps)`` of simulated hand-phone walks with pick-up and put-away."""
    out = []
    for seed in range(n_seeds):
        rng = np.random.default_rng([seed, 16])
        n_steps = PIECE_STEPS[seed % len(PIECE_STEPS)] + int(rng.integers(0, 6))
        sc = {"simulation": {"id": f"handled_{seed}"}, "route": {"waypoints_m": [[0.0, 0.0], [200.0, 0.0]], "loop": False},
              "segment": [{"duration_s": 4.0, "speed_mps": 0.0}, {"duration_s": n_steps / 1.8, "speed_mps": 1.3},
                          {"duration_s": 4.0, "speed_mps": 0.0}],
              "imu": [{"placement": "hand", "rate_hz": 100.0}], "gnss": {"enabled": False}}
        rec = simulate(sc, seed=seed)
        truth = len(rec.reference["steps"])
        end = float(rec.imu["t_s"].iloc[-1])
        imu = phone_handling(rec.imu, 0.8, 1.8, rng, np.radians(rng.uniform(60, 100)), 0.4)
        rec.imu = phone_handling(imu, end - 3.2, 1.8, rng, -np.radians(rng.uniform(60, 100)), -0.4)
        out.append((truth, len(detect_steps(rec, {}))))
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
    sim = np.array(simulated_handled_walks(2 if quick else 12), float)
    sim_err = 100.0 * np.abs(sim[:, 1] - sim[:, 0]) / sim[:, 0]
    rows.append(_row(f"simulated hand walks, pick-up + put-away ({len(sim)}, 20-45 steps)", "mean |count error|",
                     sim_err.mean(), "%", "<= 5", ANCHOR))
    rows.append(_row("simulated hand walks", "max |count error|", sim_err.max(), "%", "<= 10", ANCHOR))
    return rows
