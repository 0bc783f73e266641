"""Data-only readers of TOML (tomllib) and JSON files, and a small writer for the flat tables pdr writes (meta.toml,
camera.toml)."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from typing import Any

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
