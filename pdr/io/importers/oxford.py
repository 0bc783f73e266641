"""Oxford Step Counter dataset (Salvi et al., EMBC 2018): smartphone accelerometer with ground-truth steps.

Sources (see ``datasets/oxford_step_counter/README.md``):

- a validation file ``user1_<position>_<unix-ms>.csv`` (no header: timestamp in ns since boot, acc x/y/z in m/s²,
  cumulative ``steps_algo``, ``steps_ground_truth``, ``steps_hw``);
- an optimisation folder ``<phone>_<user>_<surface>_<Position>_<n>/`` with ``accelerometer.csv``
  (ns, accuracy, acc x/y/z m/s²) and ``stepcounter.csv`` (ns, foot1, foot2: contact states of the foot device);
- a folder holding several of either (all are imported).

Output: ``imu.csv`` (t_s relative to the first sample), ``reference/steps.csv`` (``t_s`` of each ground-truth step:
where ``steps_ground_truth`` goes up, or the 0 -> 1 transitions of the two foot channels with the feet made to
alternate, :func:`foot_device_steps`), ``reference/summary.toml`` (``n_steps``; ``n_steps_app`` = the app's own
algorithm count of validation files; ``n_steps_device`` = every 0 -> 1 transition of either channel, upstream ``stats.js``).
A leading all-zero row is dropped with a warning, and so are repeated time stamps.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pandas as pd

from pdr.errors import InputError, warn
from pdr.io.importers._common import (
    imu_frame, increasing_mask, numeric_array, read_table, require_finite, safe_id, steady_clock, write_recordings,
)
from pdr.io.recording import Recording

NS_PER_S = 1e9
MAX_STEPS_PER_SAMPLE = 3  # a walker makes < 5 steps/s; the files sample at ~100 Hz (the count rises by 0 or 1)
# Walking and running alternate the feet at 1 to 3.5 steps/s (the cadence range of the step detectors), so two
# successive contacts of one foot are a stride apart: 2 / 3.5 = 0.57 s to 2 / 1 = 2 s.
MIN_STRIDE_S = 2.0 / 3.5
MAX_STRIDE_S = 2.0 / 1.0
PLACEMENT_BY_POSITION = {
    "hand": "hand", "inhand": "hand",
    "frontpocket": "pocket", "backpocket": "pocket",
    "bag": "bag", "purse": "bag",
    "neckpouch": "neck",
    "armband": "arm",
}
_VALIDATION_NAME = re.compile(r"^(?P<user>[A-Za-z]+\d*)_(?P<position>[A-Za-z]+)_(?P<start_ms>\d{10,})$")


def _placement(position: str, what: str) -> str:
    placement = PLACEMENT_BY_POSITION.get(position.lower())
    if placement is None:
        warn(f"{what}: unknown carrying position {position!r}; placement set to 'unknown'")
        return "unknown"
    return placement


def _drop_leading_zero_rows(t: np.ndarray, acc: np.ndarray, what: str) -> int:
    """Index of the first row whose acceleration is not exactly (0, 0, 0)."""
    nonzero = np.flatnonzero(np.any(acc != 0.0, axis=1))
    if len(nonzero) == 0:
        raise InputError(f"{what}: expected accelerometer samples, found only all-zero rows")
    first = int(nonzero[0])
    if first:
        warn(f"{what}: dropped {first} leading all-zero row(s) (logger start-up)")
    return first


def foot_device_steps(rises_s: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, int, int]:
    """Step instants (s, sorted) from the 0 -> 1 transitions of the two foot channels, the feet made to alternate.

    A contact of a foot with no contact of the other foot since its previous one is, sooner than the shortest stride
    (``MIN_STRIDE_S``), that contact bouncing: dropped; within the longest stride (``MAX_STRIDE_S``), a stride over
    which the device (about 10 Hz) missed the other foot's contact: one is added midway; later, the walker stood in
    between: kept as it is. Returns ``(steps, n_dropped, n_added)``.
    """
    t = np.concatenate(rises_s)
    foot = np.concatenate([np.full(len(r), k) for k, r in enumerate(rises_s)])
    order = np.argsort(t, kind="stable")
    steps: list[float] = []
    last_foot, dropped, added = -1, 0, 0
    for ti, fi in zip(t[order], foot[order]):
        if fi == last_foot:
            gap = ti - steps[-1]
            if gap < MIN_STRIDE_S:
                dropped += 1
                continue
            if gap <= MAX_STRIDE_S:
                steps.append(steps[-1] + 0.5 * gap)
                added += 1
        steps.append(float(ti))
        last_foot = fi
    return np.asarray(steps, float), dropped, added


def _validation_file(path: Path) -> Recording:
    what = path.name
    m = _VALIDATION_NAME.match(path.stem)
    if not m:
        raise InputError(f"{what}: expected an Oxford validation file named user<N>_<position>_<unix-ms>.csv, found {path.name}")
    df = read_table(path, what, header=None)
    if df.shape[1] != 7:
        raise InputError(f"{what}: expected 7 columns (timestamp_ns, acc x, y, z, steps_algo, steps_ground_truth, steps_hw), "
                         f"found {df.shape[1]}")
    a = numeric_array(df, what)
    require_finite(a, what, "all columns")
    t_ns, acc, algo, truth = a[:, 0], a[:, 1:4], a[:, 4], a[:, 5]
    first = _drop_leading_zero_rows(t_ns, acc, what)
    t_ns, acc, algo, truth = t_ns[first:], acc[first:], algo[first:], truth[first:]
    # Step instants from the full table (before dropping repeated times): the sample where the count goes up.
    inc = np.diff(truth, prepend=truth[0])
    if (inc < 0).any():
        raise InputError(f"{what}: expected a cumulative steps_ground_truth column, found it decreasing")
    if (inc != np.round(inc)).any() or inc.max() > MAX_STEPS_PER_SAMPLE:
        raise InputError(f"{what}: expected steps_ground_truth to count whole steps, at most {MAX_STEPS_PER_SAMPLE} per "
                         f"sample, found a rise of {inc.max():.6g} (columns swapped or damaged?)")
    step_ns = np.repeat(t_ns, inc.astype(int))
    keep = increasing_mask(t_ns, what, row_offset=first)
    t0 = t_ns[keep][0]
    t_s, acc = (t_ns[keep] - t0) / NS_PER_S, acc[keep]
    t_s, acc = steady_clock(t_s, acc, what)
    position = m["position"]
    rec_id = f"{m['user']}_{position}"
    meta = {"recording": {"id": rec_id, "placement": _placement(position, what), "source": "oxford",
                          "start_unix_s": int(m["start_ms"]) / 1000.0}}
    reference = {
        "steps": pd.DataFrame({"t_s": (step_ns - t0) / NS_PER_S}),
        "summary": {"n_steps": int(truth[-1] - truth[0]), "n_steps_app": int(algo[-1] - algo[0]),
                    "steps_source": "foot ground-truth device (steps_ground_truth)",
                    "n_steps_app_source": "Step-Counter-Android-Implementation algorithm (steps_algo)"},
    }
    return Recording(meta=meta, imu=imu_frame(t_s, acc), reference=reference)


def _optimisation_folder(folder: Path) -> Recording:
    what = folder.name
    acc_df = read_table(folder / "accelerometer.csv", f"{what}/accelerometer.csv", header=None)
    if acc_df.shape[1] != 5:
        raise InputError(f"{what}/accelerometer.csv: expected 5 columns (timestamp_ns, accuracy, acc x, y, z), found {acc_df.shape[1]}")
    a = numeric_array(acc_df, f"{what}/accelerometer.csv")
    require_finite(a, f"{what}/accelerometer.csv", "all columns")
    sc_df = read_table(folder / "stepcounter.csv", f"{what}/stepcounter.csv", header=None)
    if sc_df.shape[1] != 3:
        raise InputError(f"{what}/stepcounter.csv: expected 3 columns (timestamp_ns, foot1, foot2), found {sc_df.shape[1]}")
    s = numeric_array(sc_df, f"{what}/stepcounter.csv")
    require_finite(s, f"{what}/stepcounter.csv", "all columns")
    if not np.isin(s[:, 1:], (0.0, 1.0)).all():
        raise InputError(f"{what}/stepcounter.csv: expected foot contact states 0 or 1, found other values")
    t_ns, acc = a[:, 0], a[:, 2:5]
    first = _drop_leading_zero_rows(t_ns, acc, f"{what}/accelerometer.csv")
    t_ns, acc = t_ns[first:], acc[first:]
    keep = increasing_mask(t_ns, f"{what}/accelerometer.csv", row_offset=first)
    t0 = t_ns[keep][0]
    t_s, acc = (t_ns[keep] - t0) / NS_PER_S, acc[keep]
    t_s, acc = steady_clock(t_s, acc, f"{what}/accelerometer.csv")
    rises = tuple((s[1:, 0][(s[1:, c] == 1) & (s[:-1, c] == 0)] - t0) / NS_PER_S for c in (1, 2))
    step_s, dropped, added = foot_device_steps(rises)
    if dropped or added:
        warn(f"{what}/stepcounter.csv: the feet made to alternate in the reference steps: {dropped} bouncing "
             f"contact(s) dropped, {added} missed contact(s) of the other foot added")
    parts = folder.name.split("_")
    position = parts[3] if len(parts) >= 5 else folder.name
    meta = {"recording": {"id": safe_id(folder.name), "placement": _placement(position, what), "source": "oxford"}}
    reference = {
        "steps": pd.DataFrame({"t_s": step_s}),
        "summary": {"n_steps": int(len(step_s)), "n_steps_device": int(sum(len(r) for r in rises)),
                    "steps_source": "foot ground-truth device (0 -> 1 transitions of the two feet, made to alternate)",
                    "n_steps_device_source": "every 0 -> 1 transition of either foot (upstream stats.js)"},
    }
    return Recording(meta=meta, imu=imu_frame(t_s, acc), reference=reference)


def import_source(src: Path, dest: Path, *, rate_hz: float | None = None, force: bool = False) -> list[Path]:
    if src.is_file():
        recs = [_validation_file(src)]
    elif (src / "accelerometer.csv").exists() or (src / "stepcounter.csv").exists():
        recs = [_optimisation_folder(src)]
    else:
        files = sorted(p for p in src.glob("*.csv") if _VALIDATION_NAME.match(p.stem))
        folders = sorted(p for p in src.iterdir() if p.is_dir() and (p / "accelerometer.csv").exists())
        if not files and not folders and (src / "data").is_dir():
            folders = sorted(p for p in (src / "data").iterdir() if p.is_dir() and (p / "accelerometer.csv").exists())
        if not files and not folders:
            raise InputError(f"{src}: expected an Oxford validation CSV (user1_<position>_<unix-ms>.csv) or a folder with "
                             "accelerometer.csv + stepcounter.csv, found neither")
        recs = [_validation_file(p) for p in files] + [_optimisation_folder(p) for p in folders]
    return write_recordings(recs, dest, force=force)
