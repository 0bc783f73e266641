"""Data-only readers of TOML (tomllib) and JSON files, the plain JSON values every JSON file of pdr is written from,
and a small writer for the flat tables pdr writes (meta.toml, camera.toml)."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

from pdr.errors import InputError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib


def read_toml(path: str | Path, *, what: str = "TOML file") -> dict[str, Any]:
    """The TOML document at ``path``; errors start with ``what`` and the path (the path once when ``what`` is it)."""
    path = Path(path)
    label = what if what.endswith(str(path)) or what == path.as_posix() else f"{what} {path}"
    if not path.is_file():
        raise InputError(f"{label}: expected a file, found nothing there")
    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"{label}: expected valid TOML, found {exc}") from None


def read_json(path: str | Path, *, what: str, missing: str) -> Any:
    """The JSON document at ``path``; an InputError ``"{what}: {missing}"`` when there is no file, and one that says
    the content is unreadable when it is not JSON."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{what}: {missing}")
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"{what}: expected JSON, found unreadable content ({exc})") from None


def jsonable(value: Any, float_digits: int | None = 9) -> Any:
    """Plain JSON values: numpy scalars and arrays converted, NaN/inf -> null, floats to ``float_digits``
    significant digits (None: exactly, as Python's shortest repr that reads back to the same float)."""
    if isinstance(value, dict):
        return {str(k): jsonable(v, float_digits) for k, v in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [jsonable(v, float_digits) for v in value]
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        value = float(value)
        if not math.isfinite(value):
            return None
        return value if float_digits is None else float(f"{value:.{float_digits}g}")
    if isinstance(value, Path):
        return str(value)
    if value is None or isinstance(value, str):
        return value
    raise TypeError(f"cannot write {type(value).__name__} to JSON")


def dumps_json(obj: Any, float_digits: int | None = 9) -> str:
    """The JSON text of ``obj`` (:func:`jsonable`), sorted keys, 2-space indent (deterministic)."""
    return json.dumps(jsonable(obj, float_digits), indent=2, sort_keys=True, allow_nan=False) + "\n"


def _value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if not math.isfinite(v):
            return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf")
        return repr(v)
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n") + '"'
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {type(v).__name__} to TOML")


def dumps_toml(tables: dict[str, dict[str, Any]]) -> str:
    """Serialise ``{table: {key: scalar or list}}`` (one level of tables) to TOML text."""
    lines: list[str] = []
    for name, table in tables.items():
        lines.append(f"[{name}]")
        lines.extend(f"{k} = {_value(v)}" for k, v in table.items() if v is not None)
        lines.append("")
    return "\n".join(lines)
