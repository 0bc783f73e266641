"""OpenShoe inertial log ``data_inert_*.txt`` (one foot-mounted OpenShoe unit): headerless rows
``acc_x, acc_y, acc_z, gyr_x, gyr_y, gyr_z`` in m/s² (specific force with gravity) and rad/s, no time column.

The sampling rate comes from ``--rate-hz`` (default ``DEFAULT_RATE_HZ`` = 820 Hz, OpenShoe's ``settings.m``:
``Ts = 1/820``); ``t_s = row / rate``. The foot comes from ``--foot`` or else from the file name
(``data_inert_left.txt`` -> ``foot_left``); neither is an InputError. The recording is named after the file.
The log carries no ground truth: a walk known to be closed is declared with ``--closed-loop`` (``reference/summary.toml``
``loop_closure = true``, ``final_displacement_m = 0``).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from pdr.errors import InputError
from pdr.io.importers._common import imu_frame, numeric_array, read_table, require_finite, safe_id, write_recordings
from pdr.io.recording import Recording

DEFAULT_RATE_HZ = 820.0
OPTIONS = ("foot", "closed_loop")
_FOOT = re.compile(r"(?:^|[^a-z])(left|right)(?:[^a-z]|$)", re.I)
# an OpenShoe accelerometer in g, or a gyroscope in deg/s, would read |a| ~ 1 at rest or rates of hundreds
MIN_REST_ACC_MPS2 = 5.0
MAX_GYR_RADPS = 50.0


def foot_of(src: Path, foot: str | None) -> str:
    """``left`` / ``right`` from ``--foot`` or from the file name."""
    if foot is not None:
        if foot not in ("left", "right"):
            raise InputError(f"import openshoe: expected --foot left or right, found {foot!r}")
        return foot
    m = _FOOT.search(src.stem)
    if not m:
        raise InputError(f"{src.name}: expected the foot in the file name (data_inert_left.txt / _right) or --foot "
                         "left|right, found neither")
    return m[1].lower()


def closed_loop_reference(closed_loop: bool) -> dict:
    """The reference a user declares: a closed walk ends where it started."""
    return {"summary": {"loop_closure": True, "final_displacement_m": 0.0}} if closed_loop else {}


def import_source(src: Path, dest: Path, *, rate_hz: float | None = None, force: bool = False, foot: str | None = None,
                  closed_loop: bool = False) -> list[Path]:
    what = src.name
    if src.is_dir():
        raise InputError(f"{src}: expected an OpenShoe data_inert_*.txt file, found a folder")
    side = foot_of(src, foot)
    df = read_table(src, what, header=None, sep=r"[,\s]+", engine="python")
    if df.shape[1] != 6:
        raise InputError(f"{what}: expected 6 columns (acc_x,y,z m/s², gyr_x,y,z rad/s), found {df.shape[1]}")
    a = numeric_array(df, what)
    require_finite(a, what, "all columns")
    if len(a) < 2:
        raise InputError(f"{what}: expected at least 2 samples, found {len(a)}")
    rate = DEFAULT_RATE_HZ if rate_hz is None else float(rate_hz)
    g = float(np.median(np.linalg.norm(a[:, :3], axis=1)))
    if g < MIN_REST_ACC_MPS2:
        raise InputError(f"{what}: expected the accelerometer in m/s² (|a| about 9.8 at rest), found a median |a| of "
                         f"{g:.3g}; is it in g?")
    if np.abs(a[:, 3:]).max() > MAX_GYR_RADPS:
        raise InputError(f"{what}: expected the gyroscope in rad/s, found rates up to {np.abs(a[:, 3:]).max():.3g}; "
                         "is it in deg/s?")
    imu = imu_frame(np.arange(len(a)) / rate, a[:, :3], a[:, 3:])
    meta = {"recording": {"id": safe_id(src.stem), "placement": f"foot_{side}", "source": "openshoe"}}
    return write_recordings([Recording(meta=meta, imu=imu, reference=closed_loop_reference(closed_loop))], dest,
                            force=force)
