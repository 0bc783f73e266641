"""``pdr batch`` throughput: N simulated 10-minute walks through the local process pool with 1 and 2 workers, and
through a Dask ``LocalCluster`` of 2 workers (its start-up included), on this machine.

Target: with 100 recordings the pool with 2 workers reaches at least 1.8 times the throughput of 1 worker.
The walks: ``configs/sim/walk_30min_gps.toml`` cut to its first 10 minutes, ``DISTINCT`` seeds (different walkers,
speeds and noise), each copied under several recording ids up to N (simulating 100 walks would cost more than running
them; a copy costs a run exactly what the original does). The machine is shared: the load average before and after
each timing is in the ``anchor`` column, since other processes on the 2 cores lower every figure here.

Run: ``.venv/bin/python -m benchmarks batch`` (100 recordings, about 10 minutes on an idle machine);
``--quick``: 8 recordings.
"""

from __future__ import annotations

import os
import resource
import shutil
import tempfile
import time
from pathlib import Path

from pdr.errors import InputError
from pdr.io.recording import save_recording
from pdr.io.tomlio import read_toml
from pdr.pipelines.batch import run_batch
from pdr.sim import simulate

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "configs" / "sim" / "walk_30min_gps.toml"
LENGTH_S = 600.0
DISTINCT = 4
N_FULL, N_QUICK = 100, 8
TARGET_RATIO = 1.8


def scenario_of_length(length_s: float, scenario: Path = SCENARIO) -> dict:
    """The scenario's segments, repeated and cut so that they last ``length_s``."""
    raw = read_toml(scenario, what="scenario")
    segments, total = [], 0.0
    while total < length_s - 1e-9:
        for seg in raw["segment"]:
            d = min(float(seg["duration_s"]), length_s - total)
            if d <= 0:
                break
            segments.append({**seg, "duration_s": d})
            total += d
    raw["segment"] = segments
    return raw


def make_walks(base: Path, n: int, length_s: float = LENGTH_S, distinct: int = DISTINCT) -> list[Path]:
    """``n`` recordings of ``length_s`` under ids ``walk_000``...: ``distinct`` simulated ones, the rest copies."""
    raw = scenario_of_length(length_s)
    originals = []
    for seed in range(min(distinct, n)):
        raw["simulation"]["id"] = f"walk_{seed:03d}"
        originals.append(save_recording(simulate(raw, seed), base / f"walk_{seed:03d}"))
    recs = list(originals)
    for i in range(len(originals), n):
        src, dest = originals[i % len(originals)], base / f"walk_{i:03d}"
        shutil.copytree(src, dest, copy_function=os.link)  # hard links: same bytes, no copy
        meta = dest / "meta.toml"
        text = meta.read_text().replace(f'"{src.name}"', f'"{dest.name}"')
        meta.unlink()  # the link is shared with the original: write a file of its own
        meta.write_text(text)
        recs.append(dest)
    return recs


def _load() -> str:
    return " ".join(f"{x:.1f}" for x in os.getloadavg())


def _children_cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)  # worker processes, once they have ended
    return usage.ru_utime + usage.ru_stime


def _timed_batch(recs: list[Path], out: Path, **kwargs) -> tuple[float, float, str]:
    """Wall time, CPU time of the worker processes, and the machine's load around the run."""
    before, cpu0 = _load(), _children_cpu_s()
    t0 = time.perf_counter()
    try:
        run_batch(recs, out, **kwargs)
    except InputError as exc:  # a failed row: the timing would not be of N runs
        raise RuntimeError(f"bench_batch: a recording failed ({exc})") from None
    return (time.perf_counter() - t0, _children_cpu_s() - cpu0,
            f"load average (1, 5, 15 min) before {before}, after {_load()}")


def run(quick: bool = False) -> list[dict]:
    n = N_QUICK if quick else N_FULL
    rows: list[dict] = []
    with tempfile.TemporaryDirectory(prefix="bench_batch_") as tmp:
        tmp_path = Path(tmp)
        recs = make_walks(tmp_path / "recs", n)
        case = f"{n} simulated 10-min walks ({min(DISTINCT, n)} distinct)"
        timings = {}
        for label, kwargs in [("local pool, 1 worker", {"engine": "local", "workers": 1}),
                              ("local pool, 2 workers", {"engine": "local", "workers": 2}),
                              ("Dask LocalCluster, 2 workers (start-up included)", {"engine": "dask", "workers": 2})]:
            if kwargs["engine"] == "dask":
                try:
                    import distributed  # noqa: F401
                except ImportError:
                    continue
            elapsed, cpu, load = _timed_batch(recs, tmp_path / f"out_{len(timings)}", **kwargs)
            timings[label] = elapsed
            rows.append({"area": "batch", "case": case, "metric": f"throughput, {label}",
                         "ours": round(n / elapsed * 60.0, 2), "unit": "recordings/min", "target": "",
                         "anchor": f"{elapsed:.1f} s wall; {load}"})
            rows.append({"area": "batch", "case": case, "metric": f"worker CPU time per recording, {label}",
                         "ours": round(cpu / n, 3), "unit": "s", "target": "",
                         "anchor": "user + system of the worker processes; equal across rows = no overhead from "
                                   "running two at once (the throughput ratio then depends only on free cores)"})
        one = timings["local pool, 1 worker"]
        for label in ("local pool, 2 workers", "Dask LocalCluster, 2 workers (start-up included)"):
            if label in timings:
                rows.append({"area": "batch", "case": case, "metric": f"throughput ratio, {label} / 1 worker",
                             "ours": round(one / timings[label], 2), "unit": "x",
                             "target": f">= {TARGET_RATIO} (100 recordings)" if label.startswith("local") else "",
                             "anchor": "target: 100 simulated 10-minute recordings on this 2-core machine"})
    return rows
