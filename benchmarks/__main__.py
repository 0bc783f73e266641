"""Run every ``benchmarks/bench_*.py`` (or those named), print one table, write ``out/bench/results.csv``.

Each module has ``run(quick: bool) -> list[dict]``; a row has ``area, case, metric, ours, target, anchor, unit``
(``anchor``: the published figure we compare with, as text with its source).
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys
import time
from pathlib import Path

import pandas as pd

COLUMNS = ["area", "case", "metric", "ours", "unit", "target", "anchor"]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks")
    parser.add_argument("names", nargs="*", help="benchmark modules to run (default: all), e.g. steps fusion")
    parser.add_argument("--quick", action="store_true", help="smaller cases, for a smoke run")
    parser.add_argument("-o", "--output", default="out/bench/results.csv")
    args = parser.parse_args(argv)
    here = Path(__file__).parent
    names = args.names or sorted(m.name[len("bench_"):] for m in pkgutil.iter_modules([str(here)]) if m.name.startswith("bench_"))
    rows = []
    for name in names:
        t0 = time.perf_counter()
        module = importlib.import_module(f"benchmarks.bench_{name}")
        rows += module.run(quick=args.quick)
        print(f"[{name}: {time.perf_counter() - t0:.1f} s]", file=sys.stderr)
    table = pd.DataFrame(rows, columns=COLUMNS)
    with pd.option_context("display.max_rows", None, "display.max_colwidth", 60, "display.width", 250):
        print(table.to_string(index=False))
    out = Path(args.output)
    out.parent.mkdir(parents=True, exist_ok=True)
    table.to_csv(out, index=False)
    return 0


if __name__ == "__main__":
    sys.exit(main())
