"""The IMU on a uniform time grid, with gaps of the original clock marked (not bridged)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd

from pdr.errors import InputError, warn
from pdr.io.recording import ACC_COLUMNS, GYR_COLUMNS, MAG_COLUMNS, check_time
from pdr.schema import require_table

GAP_FACTOR = 5.0  # an original sample interval longer than this many median intervals is a gap ...
GAP_MIN_S = 0.2  # ... and at least this long (shorter holes are interpolated: they are well inside one step)


@dataclasses.dataclass
class UniformImu:
    """IMU channels on a uniform grid ``t_s = t0 + k / rate_hz``.

    ``valid`` is False for grid samples inside a gap of the original clock (their values are interpolated
    across the gap and must not be used for detection). Optional channels are None when absent.
    """

    t_s: np.ndarray
    rate_hz: float
    acc_mps2: np.ndarray
    gyr_radps: np.ndarray | None
    mag_ut: np.ndarray | None
    baro_hpa: np.ndarray | None
    valid: np.ndarray

    def __len__(self) -> int:
        return len(self.t_s)

    def valid_segments(self) -> list[tuple[int, int]]:
        """``[start, stop)`` index ranges of consecutive valid samples."""
        return runs(self.valid)


def runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """``[start, stop)`` ranges where a boolean mask is True."""
    m = np.concatenate([[False], np.asarray(mask, bool), [False]])
    edges = np.flatnonzero(np.diff(m.astype(np.int8)))
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2])]


def moving_average(x: np.ndarray, n: int, axis: int = 0) -> np.ndarray:
    """Centred moving average over ``n`` samples (odd; shrinking window at the ends), O(N) via cumulative sums."""
    x = np.asarray(x, float)
    n = max(1, int(n) | 1)
    if n == 1 or x.shape[axis] == 0:
        return x.copy()
    x = np.moveaxis(x, axis, 0)
    half = n // 2
    c = np.concatenate([np.zeros((1, *x.shape[1:])), np.cumsum(x, axis=0)])
    idx = np.arange(x.shape[0])
    lo = np.clip(idx - half, 0, x.shape[0])
    hi = np.clip(idx + half + 1, 0, x.shape[0])
    shape = (-1,) + (1,) * (x.ndim - 1)
    out = c[hi]  # in place from here: a long recording holds few arrays of its size at once
    out -= c[lo]
    out /= (hi - lo).reshape(shape)
    return np.moveaxis(out, 0, axis)


def uniform_imu(imu: pd.DataFrame, rate_hz: float | None = None) -> UniformImu:
    """Interpolate an IMU table (columns of CONTRACT.md) onto a uniform grid.

    Parameters
    ----------
    imu : the table; ``t_s`` strictly increasing, ``acc_*_mps2`` required.
    rate_hz : grid rate; default the nominal rate (1 / median interval).

    Gaps (original intervals longer than ``max(5 median intervals, 0.2 s)``) are marked invalid with a warning.
    """
    require_table(imu, ("t_s", *ACC_COLUMNS), "imu")
    t = imu["t_s"].to_numpy(float)
    check_time(t, "imu", min_rows=2)
    dt = np.diff(t)
    med = float(np.median(dt))
    rate = float(rate_hz) if rate_hz is not None else 1.0 / med
    if not np.isfinite(rate) or rate <= 0:
        raise InputError(f"imu: expected a positive sampling rate, found {rate}")
    n = int(np.floor((t[-1] - t[0]) * rate + 1e-9)) + 1
    grid = t[0] + np.arange(n) / rate

    def interp(cols: tuple[str, ...]) -> np.ndarray | None:
        if not all(c in imu.columns for c in cols):
            return None
        vals = imu[list(cols)].to_numpy(float)
        if not np.isfinite(vals).all():
            raise InputError(f"imu: expected finite values in {', '.join(cols)}, found NaN/inf")
        return np.column_stack([np.interp(grid, t, vals[:, k]) for k in range(vals.shape[1])])

    acc = interp(ACC_COLUMNS)
    gyr = interp(GYR_COLUMNS)
    mag = interp(MAG_COLUMNS)
    baro = interp(("baro_hpa",))
    valid = np.ones(n, bool)
    gap_s = max(GAP_FACTOR * med, GAP_MIN_S)
    gaps = np.flatnonzero(dt > gap_s)
    if len(gaps):
        for g in gaps:
            lo = np.searchsorted(grid, t[g], side="right")
            hi = np.searchsorted(grid, t[g + 1], side="left")
            valid[lo:hi] = False
        longest = float(dt[gaps].max())
        warn(f"imu: {len(gaps)} gap(s) in the clock (longest {longest:.2f} s); no steps are detected inside them")
    return UniformImu(t_s=grid, rate_hz=rate, acc_mps2=acc, gyr_radps=gyr, mag_ut=mag,
                      baro_hpa=None if baro is None else baro[:, 0], valid=valid)
