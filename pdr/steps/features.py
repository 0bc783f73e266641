"""Per-step features of Ladetto et al. (2000), section 4: step frequency (spacing of maxima, and FFT over a window),
variance of the acceleration over the step, duration, and slope where an altitude source exists."""

from __future__ import annotations

import numpy as np
import pandas as pd

from pdr.geo import latlon_to_en
from pdr.signals.resample import UniformImu, moving_average

FREQ_SMOOTH_STEPS = 4  # step frequency: mean spacing of the maxima over this many neighbouring intervals
FFT_WINDOW_S = 4.0  # FFT window centred on each step (about 7 steps, cf. the paper's 7 s GPS periods)
FFT_RESOLUTION_HZ = 0.02  # zero padding of the FFT
ALTITUDE_SMOOTH_S = 8.0  # barometric altitude smoothing (indoor barometers wander by tenths of a metre within seconds)
SLOPE_WINDOW_STEPS = 20  # slope over this many steps around each step (about 14 m: 0.3 m of baro noise -> 0.02 rad)
NOMINAL_STEP_LENGTH_M = 0.7  # horizontal distance per step for a barometric slope when no GNSS gives it
STANDARD_PRESSURE_HPA = 1013.25


def step_durations(t_s: np.ndarray, bout_id: np.ndarray) -> np.ndarray:
    """Time since the previous step of the same bout (NaN for each bout's first step)."""
    d = np.full(len(t_s), np.nan)
    if len(t_s) > 1:
        same = bout_id[1:] == bout_id[:-1]
        d[1:][same] = np.diff(t_s)[same]
    return d


def spacing_frequency(t_s: np.ndarray, bout_id: np.ndarray, n_smooth: int = FREQ_SMOOTH_STEPS) -> np.ndarray:
    """1 / mean spacing of the maxima over ``n_smooth`` intervals centred on each step, within its bout."""
    f = np.full(len(t_s), np.nan)
    for b in np.unique(bout_id):
        idx = np.flatnonzero(bout_id == b)
        if len(idx) < 2:
            continue
        t = t_s[idx]
        k = np.arange(len(t))
        half = n_smooth // 2
        lo = np.clip(k - half, 0, len(t) - 1)
        hi = np.clip(k + half, 0, len(t) - 1)
        short = hi - lo < 1
        hi = np.where(short, np.minimum(lo + 1, len(t) - 1), hi)
        lo = np.where(short, np.maximum(hi - 1, 0), lo)
        f[idx] = (hi - lo) / (t[hi] - t[lo])
    return f


def fft_frequency(x: np.ndarray, rate_hz: float, t0_s: float, t_s: np.ndarray, f_guess_hz: np.ndarray,
                  window_s: float = FFT_WINDOW_S) -> np.ndarray:
    """Dominant frequency of ``x`` (Hann window of ``window_s`` centred on each step) in the octave around the guess.

    The octave ``f / sqrt 2 .. f sqrt 2`` is the one the wavelet detector keeps: the stride frequency and the
    second harmonic are outside it.
    """
    out = np.full(len(t_s), np.nan)
    ok = np.isfinite(f_guess_hz)
    if not ok.any() or len(x) < 4:
        return out
    win = max(4, int(round(window_s * rate_hz)))
    nfft = 1 << int(np.ceil(np.log2(max(win, rate_hz / FFT_RESOLUTION_HZ))))
    centre = np.round((t_s[ok] - t0_s) * rate_hz).astype(int)
    offsets = np.arange(-(win // 2), win - win // 2)[None, :]
    hann = np.hanning(win)[None, :]
    freqs = np.fft.rfftfreq(nfft, 1.0 / rate_hz)
    out_ok = np.full(len(centre), np.nan)
    chunk = 2048  # bounded memory for long recordings: the windows too are cut per chunk
    for s in range(0, len(centre), chunk):
        seg = x[np.clip(centre[s: s + chunk, None] + offsets, 0, len(x) - 1)]
        seg = (seg - seg.mean(axis=1, keepdims=True)) * hann
        p = np.abs(np.fft.rfft(seg, nfft, axis=1)) ** 2
        g = f_guess_hz[ok][s: s + chunk]
        band = (freqs[None, :] >= g[:, None] / np.sqrt(2)) & (freqs[None, :] <= g[:, None] * np.sqrt(2))
        p = np.where(band, p, -1.0)
        k = np.argmax(p, axis=1)
        kk = np.clip(k, 1, len(freqs) - 2)
        rows = np.arange(len(k))
        a, b, c = np.log(p[rows, kk - 1].clip(1e-30)), np.log(p[rows, kk].clip(1e-30)), np.log(p[rows, kk + 1].clip(1e-30))
        den = a - 2 * b + c
        off = np.where(np.abs(den) > 1e-12, 0.5 * (a - c) / np.where(np.abs(den) > 1e-12, den, 1.0), 0.0).clip(-0.5, 0.5)
        out_ok[s: s + chunk] = freqs[kk] + off * (freqs[1] - freqs[0])
    out[ok] = out_ok
    return out


def step_variance(x: np.ndarray, rate_hz: float, t0_s: float, t_s: np.ndarray, duration_s: np.ndarray) -> np.ndarray:
    """Variance of ``x`` over each step (from the previous contact; a bout's first step: one median step back)."""
    out = np.full(len(t_s), np.nan)
    if not len(t_s):
        return out
    med = np.nanmedian(duration_s) if np.isfinite(duration_s).any() else 0.5
    d = np.where(np.isfinite(duration_s), duration_s, med)
    hi = np.clip(np.round((t_s - t0_s) * rate_hz).astype(int) + 1, 1, len(x))
    lo = np.clip(np.round((t_s - d - t0_s) * rate_hz).astype(int), 0, len(x) - 1)
    lo = np.minimum(lo, hi - 2).clip(0)
    c1 = np.concatenate([[0.0], np.cumsum(x)])
    c2 = np.concatenate([[0.0], np.cumsum(x * x)])
    n = hi - lo
    mean = (c1[hi] - c1[lo]) / n
    var = (c2[hi] - c2[lo]) / n - mean ** 2
    return np.maximum(var, 0.0)


def baro_altitude_m(p_hpa: np.ndarray) -> np.ndarray:
    """Barometric altitude of the standard atmosphere (ICAO), m (only differences are used)."""
    return 44330.0 * (1.0 - (np.asarray(p_hpa, float) / STANDARD_PRESSURE_HPA) ** (1.0 / 5.255))


def step_slope(t_s: np.ndarray, alt_t_s: np.ndarray, alt_m: np.ndarray, horiz_t_s: np.ndarray | None,
               horiz_dist_m: np.ndarray | None, window_steps: int = SLOPE_WINDOW_STEPS) -> np.ndarray:
    """Slope (rad) around each step: altitude change over horizontal distance across ``window_steps`` steps.

    Horizontal distance from GNSS (cumulative track length) when given, else ``NOMINAL_STEP_LENGTH_M`` per step.
    """
    out = np.full(len(t_s), np.nan)
    if len(t_s) < 2 or len(alt_t_s) < 2:
        return out
    k = np.arange(len(t_s))
    half = window_steps // 2
    lo, hi = np.clip(k - half, 0, len(t_s) - 1), np.clip(k + half, 0, len(t_s) - 1)
    inside = (t_s[lo] >= alt_t_s[0]) & (t_s[hi] <= alt_t_s[-1])
    dh = np.interp(t_s[hi], alt_t_s, alt_m) - np.interp(t_s[lo], alt_t_s, alt_m)
    if horiz_t_s is not None and horiz_dist_m is not None and len(horiz_t_s) >= 2:
        dist = np.interp(t_s[hi], horiz_t_s, horiz_dist_m) - np.interp(t_s[lo], horiz_t_s, horiz_dist_m)
        inside &= (t_s[lo] >= horiz_t_s[0]) & (t_s[hi] <= horiz_t_s[-1])
    else:
        dist = (hi - lo) * NOMINAL_STEP_LENGTH_M
    ok = inside & (dist > 0)
    out[ok] = np.arctan2(dh[ok], dist[ok])
    return out


def step_features(steps: pd.DataFrame, u: UniformImu, x: np.ndarray, *, gnss: pd.DataFrame | None = None) -> pd.DataFrame:
    """The feature columns of the steps table for detected steps (``t_s``, ``bout_id``) on the signal ``x`` (|a|)."""
    t = steps["t_s"].to_numpy(float)
    b = steps["bout_id"].to_numpy(int)
    dur = step_durations(t, b)
    f = spacing_frequency(t, b)
    out = pd.DataFrame({
        "step_duration_s": dur,
        "step_freq_hz": f,
        "step_freq_fft_hz": fft_frequency(x, u.rate_hz, u.t_s[0], t, f),
        "acc_var_m2ps4": step_variance(x, u.rate_hz, u.t_s[0], t, dur),
        "slope_rad": np.full(len(t), np.nan),
    })
    alt_t = alt = None
    horiz_t = horiz = None
    if gnss is not None and len(gnss) >= 2:
        g = gnss
        if {"e_m", "n_m"} <= set(g.columns) or {"lat_deg", "lon_deg"} <= set(g.columns):
            if {"e_m", "n_m"} <= set(g.columns):
                e, n = g["e_m"].to_numpy(float), g["n_m"].to_numpy(float)
            else:
                lat, lon = g["lat_deg"].to_numpy(float), g["lon_deg"].to_numpy(float)
                e, n = latlon_to_en(lat, lon, (float(np.nanmean(lat)), float(np.nanmean(lon))))
                e, n = np.asarray(e, float), np.asarray(n, float)
            okg = np.isfinite(e) & np.isfinite(n)
            if okg.sum() >= 2:
                gt = g["t_s"].to_numpy(float)[okg]
                horiz_t, horiz = gt, np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(e[okg]), np.diff(n[okg])))])
                for col in ("alt_m", "u_m"):
                    if col in g.columns:
                        a = g[col].to_numpy(float)[okg]
                        if np.isfinite(a).sum() >= 2:
                            alt_t, alt = gt[np.isfinite(a)], a[np.isfinite(a)]
                            break
    if u.baro_hpa is not None:
        alt_t = u.t_s[u.valid]
        alt = moving_average(baro_altitude_m(u.baro_hpa), int(round(ALTITUDE_SMOOTH_S * u.rate_hz)))[u.valid]
    if alt is not None and len(t):
        out["slope_rad"] = step_slope(t, alt_t, alt, horiz_t, horiz)
    return out
