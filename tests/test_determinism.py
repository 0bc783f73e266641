"""Determinism: the same input and configuration give byte-identical outputs, so users can diff runs.

``pdr simulate`` with a seed: every file identical. ``pdr run`` twice into the same OUT: every file identical
(the plot included) except the wall-clock timings, which live only in ``summary.json``: ``timings_s`` (per stage)
and the solver's ``*time_s`` entries; those are dropped before comparing, everything else in it must match.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

from pdr.cli.main import main

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "configs" / "sim" / "walk_faults.toml"  # faults too: the warnings must come in a stable order


def files(folder: Path) -> dict[str, bytes]:
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def without_timings(summary: dict) -> dict:
    out = {k: v for k, v in summary.items() if k != "timings_s"}
    out["solver"] = {k: v for k, v in summary["solver"].items() if not k.endswith("time_s")}
    return out


def test_simulate_same_seed_same_bytes(tmp_path):
    for name, seed in (("a", "3"), ("b", "3"), ("c", "4")):
        assert main(["simulate", str(SCENARIO), "-o", str(tmp_path / name), "--seed", seed]) == 0
    a, b, c = (files(tmp_path / n) for n in "abc")
    assert a == b
    assert a.keys() == c.keys() and a["imu.csv"] != c["imu.csv"]  # the seed matters: the comparison can fail


def test_run_twice_same_bytes_except_timings(tmp_path):
    rec, out = tmp_path / "rec", tmp_path / "out"
    assert main(["simulate", str(SCENARIO), "-o", str(rec), "--seed", "2"]) == 0
    assert main(["run", str(rec), "-o", str(out), "--plot"]) == 0
    first = files(out)
    shutil.rmtree(out)
    assert main(["run", str(rec), "-o", str(out), "--plot"]) == 0
    second = files(out)
    assert first.keys() == second.keys() and "trajectory.png" in first
    s1, s2 = json.loads(first.pop("summary.json")), json.loads(second.pop("summary.json"))
    assert without_timings(s1) == without_timings(s2)
    assert s1["timings_s"].keys() == s2["timings_s"].keys()
    different = sorted(k for k in first if first[k] != second[k])
    assert not different, f"files that differ between two identical runs: {different}"
    kinds = [w["kind"] for w in s1["warnings"]]
    assert "gap" in kinds and "gnss_jump" in kinds
