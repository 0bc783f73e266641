"""Sensor faults injected into a (simulated) recording, with their truth: what ``pdr run`` must survive and report.

Fault tables (a scenario's ``[[fault]]`` tables, or dicts given to :func:`inject_faults`): ``kind``, ``t_start_s``,
``duration_s`` and per kind:

- ``dropout``: no IMU samples in the interval (0.1 s to minutes);
- ``stuck``: ``sensor`` (``acc``, ``gyr`` or ``mag``; default ``acc``) repeats its value at the start;
- ``saturation``: ``sensor`` (``acc`` / ``gyr``) clipped at ``+-level`` (default 2 g / 125 deg/s, the smallest MEMS ranges);
- ``clock_jump``: the clock jumps forward by ``duration_s`` at ``t_start_s`` (every later time stamp, of the IMU, the
  GNSS and the reference, is shifted; the truth interval is the jump);
- ``duplicated``: every other IMU sample repeats the previous one (a driver delivering a sample twice);
- ``rate_change``: the IMU is resampled at ``factor`` (default 0.5) times its rate inside the interval;
- ``mag_steel``: a steel beam: a field bump of ``field_ut`` (default 40 µT) on the magnetometer, smooth in and out;
- ``gnss_jump``: GNSS fixes shifted by ``distance_m`` (default 300 m) in a random direction while reporting the same
  ``h_acc_m`` (an accuracy they do not have).

Duplicated or back-stepping *time stamps* are not injected: by CONTRACT.md they are errors of a recording
(``pdr validate``), repaired or refused by the importers, so ``pdr run`` never sees them.

A scenario's ``[faults]`` table draws faults at random instead: ``fraction`` (of the duration, default 0.05),
``kinds`` (default all), ``min_s`` / ``max_s`` (durations, default 1 and 8 s), ``start_s`` (none before; default 10).

Example
-------
>>> from pdr.sim import simulate
>>> rec = simulate({"route": {"waypoints_m": [[0, 0], [80, 0]]}, "segment": [{"duration_s": 30, "speed_mps": 1.3}]}, seed=1)
>>> faulty, truth = inject_faults(rec, [{"kind": "dropout", "t_start_s": 10.0, "duration_s": 2.0}], seed=1)
>>> len(faulty.imu) < len(rec.imu), truth[["kind", "t_start_s", "t_end_s"]].values.tolist()
(True, [['dropout', 10.0, 12.0]])
"""

from __future__ import annotations

import copy
from typing import Any

import numpy as np
import pandas as pd

from pdr.constants import GRAVITY_MPS2
from pdr.errors import InputError, check_keys
from pdr.geo import en_to_latlon, latlon_to_en
from pdr.io.recording import ACC_COLUMNS, GYR_COLUMNS, MAG_COLUMNS, Recording

FAULT_KINDS = ("dropout", "stuck", "saturation", "clock_jump", "duplicated", "rate_change", "mag_steel", "gnss_jump")
TRIADS = {"acc": ACC_COLUMNS, "gyr": GYR_COLUMNS, "mag": MAG_COLUMNS}
DEFAULT_LEVEL = {"acc": 2.0 * GRAVITY_MPS2, "gyr": float(np.radians(125.0))}
KEYS = {"kind", "t_start_s", "duration_s", "sensor", "level", "factor", "field_ut", "distance_m"}
RANDOM_KEYS = {"fraction", "kinds", "min_s", "max_s", "start_s"}


def _check(fault: dict[str, Any], i: int) -> dict[str, Any]:
    if not isinstance(fault, dict):
        raise InputError(f"fault {i + 1}: expected a table, found {type(fault).__name__}")
    check_keys(fault, sorted(KEYS), f"fault {i + 1}")
    if fault.get("kind") not in FAULT_KINDS:
        raise InputError(f"fault {i + 1}: expected kind one of {', '.join(FAULT_KINDS)}, found {fault.get('kind')!r}")
    for key in ("t_start_s", "duration_s"):
        v = fault.get(key)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v) or v < 0:
            raise InputError(f"fault {i + 1} ({fault['kind']}): expected {key} a number >= 0, found {v!r}")
    if fault["duration_s"] <= 0:
        raise InputError(f"fault {i + 1} ({fault['kind']}): expected duration_s > 0, found {fault['duration_s']}")
    sensor = fault.get("sensor", "acc")
    allowed = ("acc", "gyr") if fault["kind"] == "saturation" else tuple(TRIADS)
    if fault["kind"] in ("stuck", "saturation") and sensor not in allowed:
        raise InputError(f"fault {i + 1} ({fault['kind']}): expected sensor one of {', '.join(allowed)}, found {sensor!r}")
    factor = fault.get("factor", 0.5)
    if fault["kind"] == "rate_change" and not (isinstance(factor, (int, float)) and 0.25 <= factor <= 4.0):
        raise InputError(f"fault {i + 1} (rate_change): expected factor in [0.25, 4], found {factor!r}")
    return fault


def random_faults(duration_s: float, rng: np.random.Generator, *, fraction: float = 0.05,
                  kinds: tuple[str, ...] | list[str] = FAULT_KINDS, min_s: float = 1.0, max_s: float = 8.0,
                  start_s: float = 10.0) -> list[dict[str, Any]]:
    """Faults of the given kinds (each at least once, in random order) at random, non-overlapping places,
    ``fraction`` of the time in all (durations drawn in ``[min_s, max_s]``, then scaled to that total).

    Each fault keeps 3 s clear of the next, and none starts before ``start_s`` nor ends within 5 s of the end."""
    kinds = list(kinds)
    bad = [k for k in kinds if k not in FAULT_KINDS]
    if bad or not kinds:
        raise InputError(f"faults: expected kinds among {', '.join(FAULT_KINDS)}, found {kinds!r}")
    if not (0 < fraction < 0.5) or not (0 < min_s <= max_s):
        raise InputError(f"faults: expected 0 < fraction < 0.5 and 0 < min_s <= max_s, found {fraction}, {min_s}, {max_s}")
    budget = fraction * duration_s
    n = max(len(kinds), int(round(budget / (0.5 * (min_s + max_s)))))
    draws = rng.uniform(min_s, max_s, n)
    durations = [float(d) for d in draws * budget / draws.sum()]  # scaled to the budget exactly
    order = [kinds[i % len(kinds)] for i in range(n)]
    order = [order[i] for i in rng.permutation(n)]
    free = duration_s - start_s - 5.0 - sum(durations) - 3.0 * len(durations)
    if free <= 0:
        raise InputError(f"faults: {budget:.0f} s of faults do not fit in a recording of {duration_s:.0f} s")
    cuts = np.sort(rng.uniform(0.0, free, len(durations)))
    faults, t = [], start_s
    prev = 0.0
    for cut, dur, kind in zip(cuts, durations, order):
        t += cut - prev
        prev = cut
        faults.append({"kind": kind, "t_start_s": round(float(t), 3), "duration_s": round(dur, 3)})
        t += dur + 3.0
    return faults


def _window(t: np.ndarray, a: float, b: float) -> np.ndarray:
    return (t >= a) & (t < b)


def inject_faults(rec: Recording, faults: list[dict[str, Any]], seed: int = 0) -> tuple[Recording, pd.DataFrame]:
    """A copy of ``rec`` with ``faults`` injected, and their truth: ``kind, sensor, t_start_s, t_end_s, n_samples``
    (the interval on the faulty recording's clock; ``n_samples`` the samples or fixes changed).

    Faults are applied in time order; a clock jump shifts the later faults with the clock.
    """
    rng = np.random.default_rng([seed, 77])
    faults = sorted((_check(dict(f), i) for i, f in enumerate(faults)), key=lambda f: f["t_start_s"])
    out = copy.deepcopy(rec)
    imu = out.imu.copy()
    gnss = out.gnss.copy() if out.gnss is not None else None
    truth = []
    shift = 0.0
    for f in faults:
        kind = f["kind"]
        a = float(f["t_start_s"]) + shift
        b = a + float(f["duration_s"])
        t = imu["t_s"].to_numpy(float)
        w = _window(t, a, b)
        sensor = "imu"
        n = int(w.sum())
        if kind == "dropout":
            imu = imu[~w].reset_index(drop=True)
        elif kind == "stuck":
            sensor = f.get("sensor", "acc")
            cols = list(TRIADS[sensor])
            if not all(c in imu.columns for c in cols) or not w.any():
                continue
            i0 = int(np.flatnonzero(w)[0])
            imu.loc[w, cols] = imu.loc[i0, cols].to_numpy()[None, :]
        elif kind == "saturation":
            sensor = f.get("sensor", "acc")
            cols = list(TRIADS[sensor])
            if not all(c in imu.columns for c in cols):
                continue
            level = float(f.get("level", DEFAULT_LEVEL[sensor]))
            x = imu.loc[w, cols].to_numpy()
            n = int((np.abs(x) > level).any(axis=1).sum())
            imu.loc[w, cols] = np.clip(x, -level, level)
            if n == 0:
                continue  # nothing was beyond the range: not a fault
            clipped = np.flatnonzero(w)[(np.abs(x) > level).any(axis=1)]
            a, b = float(t[clipped[0]]), float(t[clipped[-1]])
        elif kind == "clock_jump":
            jump = float(f["duration_s"])
            imu.loc[imu["t_s"] >= a, "t_s"] += jump
            if gnss is not None:
                gnss.loc[gnss["t_s"] >= a, "t_s"] += jump
            for name, table in out.reference.items():
                if isinstance(table, pd.DataFrame):
                    for col in [c for c in table.columns if c.startswith("t_") and c.endswith("_s") or c == "t_s"]:
                        table.loc[table[col] >= a, col] += jump
            shift += jump
            n = 0
        elif kind == "duplicated":
            idx = np.flatnonzero(w)[1::2]
            cols = [c for c in imu.columns if c != "t_s"]
            imu.loc[idx, cols] = imu.loc[idx - 1, cols].to_numpy()
            n = len(idx)
        elif kind == "rate_change":
            factor = float(f.get("factor", 0.5))
            dt = float(np.median(np.diff(t)))
            if not w.any():
                continue
            grid = np.arange(t[w][0], t[w][-1], dt / factor)
            cols = [c for c in imu.columns if c != "t_s"]
            new = pd.DataFrame({"t_s": grid, **{c: np.interp(grid, t, imu[c].to_numpy(float)) for c in cols}})
            imu = pd.concat([imu[t < grid[0]], new, imu[t > t[w][-1]]], ignore_index=True)
            n = len(grid)
        elif kind == "mag_steel":
            sensor = "mag"
            cols = list(MAG_COLUMNS)
            if not all(c in imu.columns for c in cols) or not w.any():
                continue
            direction = rng.normal(size=3)
            direction /= np.linalg.norm(direction)
            bump = np.sin(np.pi * (t[w] - a) / (b - a)) ** 2 * float(f.get("field_ut", 40.0))
            imu.loc[w, cols] = imu.loc[w, cols].to_numpy() + bump[:, None] * direction[None, :]
        elif kind == "gnss_jump":
            sensor = "gnss"
            if gnss is None:
                continue
            g = _window(gnss["t_s"].to_numpy(float), a, b)
            ok = g & gnss[[c for c in ("lat_deg", "e_m") if c in gnss.columns][0]].notna().to_numpy()
            if not ok.any():
                continue
            angle = rng.uniform(0, 2 * np.pi)
            de, dn = float(f.get("distance_m", 300.0)) * np.cos(angle), float(f.get("distance_m", 300.0)) * np.sin(angle)
            if "e_m" in gnss.columns:
                gnss.loc[ok, "e_m"] += de
                gnss.loc[ok, "n_m"] += dn
            else:
                origin = rec.geo_origin
                e, nn = latlon_to_en(gnss.loc[ok, "lat_deg"].to_numpy(), gnss.loc[ok, "lon_deg"].to_numpy(), origin)
                lat, lon = en_to_latlon(e + de, nn + dn, origin)
                gnss.loc[ok, "lat_deg"], gnss.loc[ok, "lon_deg"] = lat, lon
            gt = gnss["t_s"].to_numpy(float)[ok]
            a, b, n = float(gt[0]), float(gt[-1]), int(ok.sum())
        if kind == "clock_jump":
            truth.append({"kind": kind, "sensor": "clock", "t_start_s": a, "t_end_s": a + float(f["duration_s"]), "n_samples": 0})
        else:
            truth.append({"kind": kind, "sensor": sensor, "t_start_s": a, "t_end_s": b, "n_samples": n})
    out.imu = imu.reset_index(drop=True)
    out.gnss = gnss
    return out, pd.DataFrame(truth, columns=["kind", "sensor", "t_start_s", "t_end_s", "n_samples"])


def scenario_faults(raw: dict[str, Any], duration_s: float, seed: int) -> list[dict[str, Any]]:
    """The faults of a scenario: its ``[[fault]]`` tables plus those drawn by its ``[faults]`` table (if any)."""
    tables = raw.get("fault", [])
    if isinstance(tables, dict):
        tables = [tables]
    if not isinstance(tables, list):
        raise InputError("scenario [[fault]]: expected tables (kind, t_start_s, duration_s, ...)")
    faults = [_check(dict(f) if isinstance(f, dict) else f, i) for i, f in enumerate(tables)]
    spec = raw.get("faults")
    if spec is not None:
        if not isinstance(spec, dict):
            raise InputError("scenario [faults]: expected a table (fraction, kinds, min_s, max_s, start_s)")
        check_keys(spec, sorted(RANDOM_KEYS), "scenario [faults]")
        for key in ("fraction", "min_s", "max_s", "start_s"):
            if key in spec and (isinstance(spec[key], bool) or not isinstance(spec[key], (int, float))):
                raise InputError(f"scenario [faults] {key}: expected a number, found {spec[key]!r}")
        kinds = spec.get("kinds", list(FAULT_KINDS))
        if not isinstance(kinds, list):
            raise InputError(f"scenario [faults] kinds: expected a list of fault kinds, found {kinds!r}")
        faults += random_faults(duration_s, np.random.default_rng([seed, 8]), kinds=kinds,
                                **{k: float(spec[k]) for k in ("fraction", "min_s", "max_s", "start_s") if k in spec})
    return faults
