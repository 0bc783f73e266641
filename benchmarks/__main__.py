"""Run every ``benchmarks/bench_*.py`` (or the areas named), print one table, write ``out/bench/results.csv``.

Each module has ``run(quick: bool) -> list[dict]``; a row has ``area, case, metric, ours, target, anchor, unit``
(``anchor``: the published figure we compare with, as text with its source).

Full (default) or ``--quick`` (smaller cases, a smoke run); areas by name (positional or ``--area``), e.g.
``python -m benchmarks batch scale --quick``. ``make bench`` runs them all, full.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import pkgutil
import sys
import time
from pathlib import Path

import pandas as pd

from pdr.errors import LOGGER_NAME

COLUMNS = ["area", "case", "metric", "ours", "unit", "target", "anchor"]


def main(argv: list[str] | None = None) -> int:
    here = Path(__file__).parent
    available = sorted(m.name[len("bench_"):] for m in pkgutil.iter_modules([str(here)]) if m.name.startswith("bench_"))
    parser = argparse.ArgumentParser(
        prog="python -m benchmarks",
        description="Accuracy, speed and memory benchmarks of pdr: one table printed and written as CSV. "
                    "Full size by default (minutes to tens of minutes); --quick for a smoke run.",
        epilog=f"areas: {', '.join(available)}")
    parser.add_argument("names", nargs="*", metavar="AREA", help="areas (benchmark modules) to run; default: all")
    parser.add_argument("--area", action="append", default=[], metavar="AREA",
                        help="an area to run (repeatable; same as the positional names)")
    parser.add_argument("--quick", action="store_true", help="smaller cases, for a smoke run (default: full size)")
    parser.add_argument("-o", "--output", default="out/bench/results.csv", help="CSV of the table (default: %(default)s)")
    args = parser.parse_args(argv)
    logger = logging.getLogger(LOGGER_NAME)  # the library's warnings are not part of the tables (summary.json keeps them)
    logger.addHandler(logging.NullHandler())
    logger.propagate = False
    names = list(dict.fromkeys(args.names + args.area)) or available
    unknown = [n for n in names if n not in available]
    if unknown:
        parser.error(f"unknown area(s) {', '.join(unknown)}: expected one of {', '.join(available)}")
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
