"""I/O speed: loading + validating one hour of 100 Hz IMU (target: under 1 s), and the import time of every real dataset.

Run: ``.venv/bin/python -m benchmarks io`` (``--quick``: one repetition instead of the best of three).
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from pdr.io.datasets import data_dir
from pdr.constants import GRAVITY_MPS2
from pdr.io.importers import import_recordings
from pdr.io.recording import Recording, load_recording, save_recording
from pdr.errors import collect_warnings

ROOT = Path(__file__).resolve().parents[1]
DATASETS = data_dir()
HOUR_ROWS = 360_000  # one hour at 100 Hz
LOAD_TARGET_S = 1.0
IMPORTS = [  # case, format, source, rate_hz
    ("oxford validation (6 files)", "oxford", DATASETS / "oxford_step_counter" / "validation", None),
    ("oxford optimisation purse", "oxford",
     DATASETS / "oxford_step_counter" / "optimisation" / "data" / "Samsung_Carmelo_Hard_Purse_1", None),
    ("mobgap HA/001 (3 trials)", "mobgap", DATASETS / "mobgap_lowerback_tvs_lab" / "lab" / "HA" / "001", None),
    ("mobgap HA/002 (3 trials)", "mobgap", DATASETS / "mobgap_lowerback_tvs_lab" / "lab" / "HA" / "002", None),
    ("humolire square_2x", "humolire", DATASETS / "humolire_phone_landmarks" / "data" / "imus" / "1" / "square_2x", None),
    ("gaitmap walk + stairs", "gaitmap", DATASETS / "gaitmap_foot_imu_mocap", 204.8),
    ("xio short_walk", "xio", DATASETS / "xio_foot_imu_loop_walk" / "short_walk.csv", None),
]


def _hour_of_imu(seed: int = 0) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    t = np.arange(HOUR_ROWS) / 100.0
    n = len(t)
    return pd.DataFrame({
        "t_s": t,
        "acc_x_mps2": rng.normal(0.0, 1.0, n), "acc_y_mps2": rng.normal(0.0, 1.0, n),
        "acc_z_mps2": GRAVITY_MPS2 + 2.0 * np.sin(2 * np.pi * 1.8 * t) + rng.normal(0.0, 0.5, n),
        "gyr_x_radps": rng.normal(0.0, 0.3, n), "gyr_y_radps": rng.normal(0.0, 0.3, n), "gyr_z_radps": rng.normal(0.0, 0.3, n),
        "mag_x_ut": 20.0 + rng.normal(0.0, 1.0, n), "mag_y_ut": rng.normal(0.0, 1.0, n), "mag_z_ut": -40.0 + rng.normal(0.0, 1.0, n),
        "baro_hpa": 1013.0 + rng.normal(0.0, 0.05, n),
    })


def _best_of(fn, repeats: int) -> float:
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def run(quick: bool = False) -> list[dict]:
    repeats = 1 if quick else 3
    rows = []
    with tempfile.TemporaryDirectory(prefix="pdr-bench-io-") as tmp:
        rec_path = save_recording(Recording(meta={"recording": {"id": "hour", "placement": "waist"}}, imu=_hour_of_imu()),
                                  Path(tmp) / "hour")
        size_mb = (rec_path / "imu.csv").stat().st_size / 1e6
        loaded = load_recording(rec_path)
        assert len(loaded.imu) == HOUR_ROWS
        t_load = _best_of(lambda: load_recording(rec_path), repeats)
        anchor = f"target: {HOUR_ROWS:,} rows (acc, gyr, mag, baro; {size_mb:.0f} MB CSV) under {LOAD_TARGET_S:g} s"
        rows.append({"area": "io", "case": "load + validate 1 h of 100 Hz IMU", "metric": "time", "ours": round(t_load, 3),
                     "unit": "s", "target": f"< {LOAD_TARGET_S:g}", "anchor": anchor})
        if _has_option("mode.max_threads"):  # pandas >= 3.1 reads large CSVs on several threads; also time one
            with pd.option_context("mode.max_threads", 1):
                t_one = _best_of(lambda: load_recording(rec_path), repeats)
            rows.append({"area": "io", "case": "load + validate 1 h of 100 Hz IMU, one thread", "metric": "time",
                         "ours": round(t_one, 3), "unit": "s", "target": f"< {LOAD_TARGET_S:g}", "anchor": anchor})
        counter = iter(range(10_000))  # a fresh output folder for every import
        for case, fmt, src, rate in IMPORTS:
            if not src.exists():
                continue

            def one_import() -> None:
                with collect_warnings():
                    import_recordings(fmt, src, Path(tmp) / f"imp{next(counter)}", rate_hz=rate)

            rows.append({"area": "io", "case": f"import {case}", "metric": "time", "ours": round(_best_of(one_import, repeats), 3),
                         "unit": "s", "target": "", "anchor": "import, validate and write atomically"})
    return rows


def _has_option(name: str) -> bool:
    try:
        pd.get_option(name)
    except (KeyError, pd.errors.OptionError):
        return False
    return True
