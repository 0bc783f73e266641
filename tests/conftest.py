"""Shared fixtures: small canonical recordings and the paths of the real data."""

from __future__ import annotations

import os
import re
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

import numpy as np
import pandas as pd
import pytest

from pdr.constants import GRAVITY_MPS2
from pdr.errors import collect_warnings
from pdr.io.datasets import DATA_DIR_VARIABLE, data_dir, missing_files
from pdr.io.recording import Recording, save_recording

ROOT = Path(__file__).resolve().parents[1]
DATASETS = data_dir()  # the public recordings of datasets/registry.toml (PDR_DATA_DIR, ../shared/datasets or the cache)
REQUIRE_REAL_DATA = "PDR_REQUIRE_REAL_DATA"  # set by .ci/run: a missing dataset fails the test instead of skipping it


def real_dataset(name: str) -> Path:
    """The local folder of a registered dataset. Without its files the test is skipped with a reason that says how to
    get them (failed when PDR_REQUIRE_REAL_DATA is set, as in CI)."""
    missing = missing_files(name, DATASETS)
    if missing:
        reason = (f"real data: {name} not under {DATASETS} ({len(missing)} file(s) missing); run `pdr datasets fetch "
                  f"{name}` and set {DATA_DIR_VARIABLE}, or place ../shared/datasets beside the repository")
        if os.environ.get(REQUIRE_REAL_DATA):
            pytest.fail(reason, pytrace=False)
        pytest.skip(reason)
    return DATASETS / name


@contextmanager
def warns(match: str | None = None) -> Iterator[list[str]]:
    """Assert that the block reports a warning (pdr's logger or a Python warning) whose text matches ``match`` (a regex
    searched in each line; any warning when None). Yields the collected lines."""
    with collect_warnings() as messages:
        yield messages
    if not any(match is None or re.search(match, m) for m in messages):
        pytest.fail(f"no warning matching {match!r}; got {messages}", pytrace=False)


def pytest_configure(config):
    config.addinivalue_line("markers", "real_data(*names): the test reads these registered datasets (skipped without them)")


def pytest_runtest_setup(item):
    for mark in item.iter_markers("real_data"):
        for name in mark.args:
            real_dataset(name)


def make_imu(duration_s: float = 10.0, rate_hz: float = 100.0, step_hz: float = 1.8, seed: int = 0) -> pd.DataFrame:
    """A plain walking-like IMU table in SI units (for I/O tests, not for accuracy)."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration_s, 1.0 / rate_hz)
    vert = GRAVITY_MPS2 + 2.0 * np.sin(2 * np.pi * step_hz * t)
    return pd.DataFrame({
        "t_s": t,
        "acc_x_mps2": 0.3 * rng.standard_normal(len(t)),
        "acc_y_mps2": 0.3 * rng.standard_normal(len(t)),
        "acc_z_mps2": vert,
        "gyr_x_radps": 0.05 * rng.standard_normal(len(t)),
        "gyr_y_radps": 0.05 * rng.standard_normal(len(t)),
        "gyr_z_radps": 0.05 * rng.standard_normal(len(t)),
    })


@pytest.fixture
def small_recording(tmp_path: Path) -> Path:
    rec = Recording(meta={"recording": {"id": "small", "placement": "waist"}, "subject": {"height_m": 1.75}}, imu=make_imu())
    return save_recording(rec, tmp_path / "small")
