"""Fusion benchmark: graph smoothing vs forward EKF vs dead reckoning, outages, GNSS outliers, speed and memory.

Walks come from :func:`synthetic_walk`, a generator richer than any of the estimators' models (non-linear and
autocorrelated step lengths, a gyro bias with a slow periodic part and a scale-factor error, Gauss-Markov GNSS errors,
drop-outs, outliers).
"""

from __future__ import annotations

import resource
import time
import warnings

import numpy as np
import pandas as pd

AREA = "fusion"


# ----------------------------------------------------------------------------------------------------------------
# A walk with known truth
# ----------------------------------------------------------------------------------------------------------------


def _ou(rng: np.random.Generator, t: np.ndarray, tau_s: float, std: float) -> np.ndarray:
    """Ornstein-Uhlenbeck (Gauss-Markov) process sampled at times ``t``, stationary standard deviation ``std``."""
    out = np.empty(len(t))
    out[0] = std * rng.standard_normal()
    for i in range(1, len(t)):
        phi = np.exp(-(t[i] - t[i - 1]) / tau_s)
        out[i] = phi * out[i - 1] + std * np.sqrt(1.0 - phi * phi) * rng.standard_normal()
    return out


def synthetic_walk(*, duration_s: float = 600.0, seed: int = 0, gnss_rate_hz: float = 1.0,
                   gnss_until_s: float | None = None, outlier_fraction: float = 0.0, outlier_m: float = 50.0,
                   with_mag: bool = True, dropouts: int = 2) -> dict:
    """A walk with its truth: ``steps`` (the steps table + ``step_length_m`` of the population model), ``gnss``
    (``t_s, e_m, n_m, h_acc_m``), ``truth`` (epochs ``t_s, e_m, n_m, heading_rad``: start, then one per step),
    ``true_length_m`` and ``t_start_s``. GNSS stops at ``gnss_until_s`` (the indoor part); ``outlier_fraction`` of
    the fixes are replaced by jumps of ``outlier_m`` in a random direction."""
    rng = np.random.default_rng(seed)
    # cadence: slow periodic changes + a Gauss-Markov wander + step-to-step jitter
    n_max = int(duration_s * 2.5) + 10
    t_grid = np.arange(n_max) * 0.5
    phase = rng.uniform(0, 2 * np.pi)
    freq_grid = 1.85 + 0.12 * np.sin(2 * np.pi * t_grid / 400.0 + phase) + _ou(rng, t_grid, 60.0, 0.08)
    durations, t = [], 0.0
    while t < duration_s:
        f = np.interp(t, t_grid, freq_grid)
        d = (1.0 / f) * (1.0 + 0.02 * rng.standard_normal())
        durations.append(d)
        t += d
    dt = np.array(durations)
    t_start = 1.0
    epochs = t_start + np.concatenate([[0.0], np.cumsum(dt)])
    t_steps = epochs[1:]
    n = len(dt)
    f_true = 1.0 / dt
    f_meas = pd.Series(f_true).rolling(5, min_periods=1, center=True).mean().to_numpy() + 0.02 * rng.standard_normal(n)
    acc_var = (1.5 + 6.0 * np.clip(f_true - 1.4, 0, None) ** 1.5) * np.exp(0.15 * rng.standard_normal(n))
    # true step length: non-linear in cadence, autocorrelated (fatigue, terrain) + white scatter
    ar = _ou(rng, t_steps, 30.0, 0.03)
    length = 0.15 + 0.30 * f_true + 0.012 * acc_var + 0.4 * (f_true - 1.85) ** 2 + ar + 0.03 * rng.standard_normal(n)
    # true heading: smooth wander + discrete turns of 30-120 deg over 2-4 s
    rate = _ou(rng, t_steps, 20.0, 0.02)
    t_turn = t_start + np.cumsum(rng.uniform(20.0, 90.0, size=int(duration_s / 20) + 2))
    for tt in t_turn[t_turn < epochs[-1]]:
        angle = np.deg2rad(rng.uniform(30, 120)) * rng.choice([-1, 1])
        width = rng.uniform(2.0, 4.0)
        inside = (t_steps > tt) & (t_steps <= tt + width)
        rate[inside] += angle / width
    dtheta_true = rate * dt
    heading0 = rng.uniform(-np.pi, np.pi)
    heading = heading0 + np.concatenate([[0.0], np.cumsum(dtheta_true)])
    e = np.concatenate([[0.0], np.cumsum(length * np.cos(heading[1:]))])
    nn = np.concatenate([[0.0], np.cumsum(length * np.sin(heading[1:]))])
    # gyro: turn-on bias 0.17 deg/s, a slow periodic part and a random walk (bias instability of a phone-grade MEMS
    # gyro, ~10-20 deg/h), 0.5 % scale-factor error, white noise
    bias = (rng.choice([-1, 1]) * 0.003 + 1e-4 * np.sin(2 * np.pi * t_steps / 1200.0 + phase)
            + np.cumsum(5e-6 * np.sqrt(dt) * rng.standard_normal(n)))
    dtheta_meas = dtheta_true * 1.005 + bias * dt + 0.003 * rng.standard_normal(n)
    heading_meas = heading0 + 0.05 + np.cumsum(dtheta_meas)
    steps = pd.DataFrame({
        "t_s": t_steps, "bout_id": 0, "step_duration_s": dt, "step_freq_hz": f_meas, "step_freq_fft_hz": f_meas,
        "acc_var_m2ps4": acc_var, "slope_rad": np.nan, "heading_rad": (heading_meas + np.pi) % (2 * np.pi) - np.pi,
        "heading_change_rad": dtheta_meas, "heading_change_std_rad": 0.004,
    })
    steps.loc[0, "step_duration_s"] = np.nan
    steps.loc[0, "heading_change_rad"] = np.nan
    until = np.inf if gnss_until_s is None else t_start + gnss_until_s
    if with_mag:
        offset = 0.05 + 0.04 * np.sin(2 * np.pi * t_steps / 900.0)
        mag = heading[1:] + offset + 0.08 * rng.standard_normal(n)
        steps["mag_heading_rad"] = np.where(t_steps < until, (mag + np.pi) % (2 * np.pi) - np.pi, np.nan)
        steps["mag_heading_std_rad"] = np.where(t_steps < until, 0.1, np.nan)
    else:
        steps["mag_heading_rad"] = np.nan
        steps["mag_heading_std_rad"] = np.nan
    # population step model (what an uncalibrated user gets)
    steps["step_length_m"] = 0.384 * f_meas
    steps["step_length_std_m"] = 0.07

    t_fix = np.arange(t_start + 0.3, min(epochs[-1], until), 1.0 / gnss_rate_hz)
    for _ in range(dropouts):
        a = rng.uniform(t_fix[0], t_fix[-1]) if len(t_fix) else 0.0
        t_fix = t_fix[(t_fix < a) | (t_fix > a + rng.uniform(20.0, 60.0))]
    err = np.column_stack([_ou(rng, t_fix, 20.0, 2.0), _ou(rng, t_fix, 20.0, 2.0)]) + 0.8 * rng.standard_normal((len(t_fix), 2))
    fix = np.column_stack([np.interp(t_fix, epochs, e), np.interp(t_fix, epochs, nn)]) + err
    if outlier_fraction > 0 and len(t_fix):
        out = rng.random(len(t_fix)) < outlier_fraction
        ang = rng.uniform(0, 2 * np.pi, out.sum())
        fix[out] += outlier_m * np.column_stack([np.cos(ang), np.sin(ang)])
    gnss = pd.DataFrame({"t_s": t_fix, "e_m": fix[:, 0], "n_m": fix[:, 1],
                         "h_acc_m": 3.0 * np.exp(0.2 * rng.standard_normal(len(t_fix)))})
    truth = pd.DataFrame({"t_s": epochs, "e_m": e, "n_m": nn, "heading_rad": heading})
    return {"steps": steps, "gnss": gnss, "truth": truth, "true_length_m": length, "t_start_s": t_start}
