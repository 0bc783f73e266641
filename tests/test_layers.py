"""Imports flow only downward (DESIGN.md): io <- algorithms <- pipelines <- cli; all gtsam code lives in pdr.fusion."""

from __future__ import annotations

import ast
from pathlib import Path

PKG = Path(__file__).resolve().parents[1] / "pdr"
ALGORITHMS = ("signals", "steps", "heading", "step_length", "flow", "slip", "foot", "gait", "calibration", "fusion")
# For each area: the top-level pdr subpackages it must never import.
FORBIDDEN = {
    "io": {"pipelines", "cli", "sim", "report", "eval", *ALGORITHMS},
    **{area: {"pipelines", "cli", "sim", "report", "eval"} for area in ALGORITHMS},
    "sim": {"pipelines", "cli", "report", "eval"},
    "report": {"pipelines", "cli"},
    "eval": {"pipelines", "cli"},
    "pipelines": {"cli"},
}


def _imports(path: Path) -> set[str]:
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
    return names


def test_imports_flow_downward():
    violations = []
    for path in sorted(PKG.rglob("*.py")):
        area = path.relative_to(PKG).parts[0] if len(path.relative_to(PKG).parts) > 1 else None
        for name in _imports(path):
            parts = name.split(".")
            if parts[0] == "gtsam" and area != "fusion":
                violations.append(f"{path.relative_to(PKG)} imports gtsam outside pdr/fusion")
            if parts[0] != "pdr" or len(parts) < 2:
                continue
            if parts[1] in FORBIDDEN.get(area, ()):
                violations.append(f"{path.relative_to(PKG)} ({area}) imports {name}")
    assert not violations, "\n".join(violations)
