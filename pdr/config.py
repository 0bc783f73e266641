"""Run configuration: a TOML file whose sections are the parameters of the algorithm objects.

Each section (``[steps]``, ``[step_length]``, ``[heading]``, ``[fusion]``, ...) is passed to the algorithm's
``from_config``; unknown keys are errors, so a typo never goes unnoticed. The file is parsed as data only.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from pdr.errors import InputError
from pdr.io.tomlio import read_toml


def load_config(path: str | Path | None) -> dict[str, Any]:
    """Read a configuration file (or return an empty configuration when ``path`` is None)."""
    if path is None:
        return {}
    cfg = read_toml(path, what="configuration")
    for key, value in cfg.items():
        if not isinstance(value, dict):
            raise InputError(f"configuration {path}: expected only [sections] at top level, found key {key!r}")
    return cfg
