"""GNSS fixes with a receiver's error behaviour: white noise, a slowly varying correlated error (first-order
Gauss-Markov), outliers (multipath jumps), outages, a convergence transient after each outage, and a reported
``h_acc_m`` that is the receiver's own smoothed, optimistic estimate rather than the true error.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd

from pdr.errors import InputError


@dataclasses.dataclass(frozen=True)
class GnssSpec:
    """The ``[gnss]`` table of a scenario.

    Parameters
    ----------
    enabled : write ``gnss.csv`` at all.
    rate_hz : fix rate.
    noise_m : white horizontal noise per axis (1-sigma).
    markov_sigma_m, markov_tau_s : the correlated error per axis (stationary 1-sigma, correlation time).
    vertical_factor : vertical errors are this many times the horizontal ones.
    outlier_fraction, outlier_m : this fraction of the fixes (exactly, rounded) is displaced by ``outlier_m`` in a
        random direction (the receiver does not know; its h_acc_m stays as it was).
    outages_s : list of [start, end] intervals without fixes (indoor segments are added to them).
    reacquire_s : after an outage the error is inflated (x3) and decays with this time constant.
    h_acc_bias : the reported accuracy is this factor times the modelled 1-sigma (receivers are optimistic).
    """

    enabled: bool = True
    rate_hz: float = 1.0
    noise_m: float = 1.5
    markov_sigma_m: float = 2.5
    markov_tau_s: float = 120.0
    vertical_factor: float = 1.6
    outlier_fraction: float = 0.01
    outlier_m: float = 30.0
    outages_s: tuple = ()
    reacquire_s: float = 15.0
    h_acc_bias: float = 0.8

    def __post_init__(self):
        if not 0.1 <= self.rate_hz <= 20:
            raise InputError(f"gnss.rate_hz: expected 0.1-20 Hz, found {self.rate_hz}")
        if not 0.0 <= self.outlier_fraction <= 0.5:
            raise InputError(f"gnss.outlier_fraction: expected 0-0.5, found {self.outlier_fraction}")
        for name in ("noise_m", "markov_sigma_m", "outlier_m", "reacquire_s", "vertical_factor"):
            v = getattr(self, name)
            if not np.isfinite(v) or v < 0:
                raise InputError(f"gnss.{name}: expected a number >= 0, found {v}")
        if self.markov_tau_s <= 0 or self.h_acc_bias <= 0:
            raise InputError("gnss.markov_tau_s and gnss.h_acc_bias: expected positive numbers")
        for iv in self.outages_s:
            if len(iv) != 2 or not iv[0] < iv[1]:
                raise InputError(f"gnss.outages_s: expected [start, end] pairs with start < end, found {list(iv)}")


def _gauss_markov(rng: np.random.Generator, n: int, dt: float, sigma: float, tau: float, dims: int) -> np.ndarray:
    phi = np.exp(-dt / tau)
    q = sigma * np.sqrt(1.0 - phi * phi)
    out = np.empty((n, dims))
    x = sigma * rng.standard_normal(dims)
    for k in range(n):  # n ~ 1 per second: a loop is fine
        out[k] = x
        x = phi * x + q * rng.standard_normal(dims)
    return out


def simulate_gnss(spec: GnssSpec, t_s: np.ndarray, truth_enu: np.ndarray, available: np.ndarray,
                  rng: np.random.Generator) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Fixes at the times ``t_s`` where ``available``; returns (fixes ``t_s, e_m, n_m, u_m, h_acc_m``,
    truth ``t_s, e_m, n_m, u_m, error_m, outlier``)."""
    n = len(t_s)
    dt = 1.0 / spec.rate_hz
    gm = _gauss_markov(rng, n, dt, spec.markov_sigma_m, spec.markov_tau_s, 3)
    white = spec.noise_m * rng.standard_normal((n, 3))
    err = gm + white
    err[:, 2] *= spec.vertical_factor
    # convergence after each outage (and at power-on)
    since = np.full(n, np.inf)
    last_gap = -np.inf
    for k in range(n):
        if not available[k]:
            last_gap = t_s[k]
        elif k == 0 or not available[k - 1]:
            last_gap = t_s[k - 1] if k > 0 else t_s[k] - 1.0
        since[k] = t_s[k] - last_gap
    inflate = 1.0 + 2.0 * np.exp(-since / spec.reacquire_s)
    err *= inflate[:, None]
    sigma = np.hypot(spec.noise_m, spec.markov_sigma_m)
    slow = _gauss_markov(rng, n, dt, 0.15, 60.0, 1)[:, 0]
    h_acc = np.maximum(spec.h_acc_bias * sigma * inflate * np.exp(slow), min(0.3, spec.noise_m))  # DGPS: cm-level
    idx_ok = np.flatnonzero(available)
    outlier = np.zeros(n, bool)
    n_out = int(round(spec.outlier_fraction * len(idx_ok)))
    if n_out:
        pick = np.sort(rng.choice(idx_ok, n_out, replace=False))
        outlier[pick] = True
        ang = rng.uniform(0, 2 * np.pi, n_out)
        err[pick, 0] = spec.outlier_m * np.cos(ang)
        err[pick, 1] = spec.outlier_m * np.sin(ang)
    meas = truth_enu + err
    fixes = pd.DataFrame({"t_s": t_s, "e_m": meas[:, 0], "n_m": meas[:, 1], "u_m": meas[:, 2], "h_acc_m": h_acc})[available]
    truth = pd.DataFrame({"t_s": t_s, "e_m": truth_enu[:, 0], "n_m": truth_enu[:, 1], "u_m": truth_enu[:, 2],
                          "error_m": np.hypot(err[:, 0], err[:, 1]), "outlier": outlier.astype(int)})[available]
    return fixes.reset_index(drop=True), truth.reset_index(drop=True)
