"""``pdr batch``: ``pdr run`` over many recordings, one output folder each, plus ``OUT/summary.csv``.

Engines: a local process pool (default, no set-up) or Dask distributed (``--engine dask``: an existing cluster with
``--scheduler ADDR``, else a ``LocalCluster`` started here). One bad recording never stops the batch; a second run
skips recordings whose outputs are complete (each output folder appears only once complete, by atomic rename);
outputs are identical whichever engine ran them (the summary has no timings).
"""

from __future__ import annotations

import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path
from typing import Any, Iterable

import pandas as pd

from pdr.errors import InputError
from pdr.io.atomic import write_csv
from pdr.io.tomlio import read_toml

SUMMARY_COLUMNS = ["recording_id", "recording_path", "status", "distance_m", "n_steps", "duration_s", "error"]
SCHEDULER_TIMEOUT_S = 10
COMPLETE_MARKERS = ("run.json", "summary.json", "trajectory.csv")


def _recording_id(rec: Path) -> str:
    """The id in meta.toml, or the folder name when meta.toml cannot be read (the run will then report why)."""
    try:
        return str(read_toml(rec / "meta.toml")["recording"]["id"])
    except (InputError, KeyError, TypeError):
        return rec.name


def is_complete(out_dir: Path) -> bool:
    return all((out_dir / name).is_file() for name in COMPLETE_MARKERS)


def run_one(rec: Path, out_dir: Path, run_kwargs: dict[str, Any]) -> dict[str, Any]:
    """Run one recording; never raises: a failure becomes a row with its one-line error."""
    from pdr.pipelines.run import run_recording

    row: dict[str, Any] = {"recording_path": str(rec), "status": "ok", "error": ""}
    try:
        summary = run_recording(rec, out_dir, force=True, **run_kwargs)
        row.update(distance_m=summary["distance_m"], n_steps=summary["n_steps"], duration_s=summary["duration_s"])
    except Exception as exc:  # the batch goes on; the row says why this recording failed
        row.update(status="failed", error=" ".join(str(exc).split())[:300] or type(exc).__name__)
    return row


def _completed_row(rec: Path, out_dir: Path) -> dict[str, Any]:
    import json

    summary = json.loads((out_dir / "summary.json").read_text())
    return {"recording_path": str(rec), "status": "ok", "error": "", "distance_m": summary["distance_m"],
            "n_steps": summary["n_steps"], "duration_s": summary["duration_s"]}


class _Progress:
    """A one-line progress counter on a terminal; silent otherwise."""

    def __init__(self, total: int):
        self.total, self.done, self.t0 = total, 0, time.perf_counter()
        self.enabled = sys.stderr.isatty() and total > 0

    def tick(self) -> None:
        self.done += 1
        if self.enabled:
            elapsed = time.perf_counter() - self.t0
            eta = elapsed / self.done * (self.total - self.done)
            print(f"\r[{self.done}/{self.total}] {elapsed:.0f} s elapsed, about {eta:.0f} s left ", end="", file=sys.stderr)
            if self.done == self.total:
                print(file=sys.stderr)


def _run_local(jobs: list[tuple[Path, Path]], run_kwargs: dict, workers: int, progress: _Progress) -> Iterable[dict]:
    if workers == 1:
        for rec, out in jobs:
            yield run_one(rec, out, run_kwargs)
            progress.tick()
        return
    with ProcessPoolExecutor(max_workers=workers) as pool:
        futures = [pool.submit(run_one, rec, out, run_kwargs) for rec, out in jobs]
        for fut in as_completed(futures):
            progress.tick()
            yield fut.result()


def _dask_client(scheduler: str | None, workers: int):
    try:
        from dask.distributed import Client, LocalCluster
    except ImportError:
        raise InputError("--engine dask: expected the dask[distributed] package, found it not installed (pip install 'pdr[dask]')") from None
    if scheduler:
        try:
            return Client(scheduler, timeout=f"{SCHEDULER_TIMEOUT_S}s"), None
        except (OSError, TimeoutError) as exc:
            raise InputError(f"--scheduler {scheduler}: expected a Dask scheduler answering within {SCHEDULER_TIMEOUT_S} s, found none ({exc})") from None
    cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None)
    return Client(cluster), cluster


def _run_dask(jobs: list[tuple[Path, Path]], run_kwargs: dict, workers: int, scheduler: str | None,
              progress: _Progress) -> Iterable[dict]:
    from dask.distributed import as_completed as dask_as_completed

    client, cluster = _dask_client(scheduler, workers)
    try:
        futures = [client.submit(run_one, rec, out, run_kwargs, pure=False) for rec, out in jobs]
        for fut in dask_as_completed(futures):
            progress.tick()
            yield fut.result()
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def run_batch(recs: list[Path], out: Path, *, engine: str = "local", workers: int | None = None, scheduler: str | None = None,
              config_path: str | None = None, model_path: str | None = None, use_gnss: bool = True) -> str:
    """Run every recording into ``out/<recording id>/`` and write ``out/summary.csv``; return a one-line summary.

    Raises InputError (after writing the summary) when any recording failed, so the exit code tells.
    """
    if engine not in ("local", "dask"):
        raise InputError(f"--engine: expected local or dask, found {engine!r}")
    workers = workers or os.cpu_count() or 1
    if workers < 1:
        raise InputError(f"--workers: expected at least 1, found {workers}")
    for path in (config_path, model_path):
        if path is not None and not Path(path).is_file():
            raise InputError(f"{path}: expected a file, found nothing there")
    ids: dict[str, Path] = {}
    for rec in recs:
        rid = _recording_id(rec)
        if rid in ids:
            raise InputError(f"recording id {rid!r}: expected unique ids, found it in both {ids[rid]} and {rec}")
        ids[rid] = rec
    run_kwargs = {"config_path": config_path, "model_path": model_path, "use_gnss": use_gnss}

    rows: dict[str, dict] = {}
    jobs: list[tuple[Path, Path]] = []
    for rid, rec in ids.items():
        if is_complete(out / rid):
            rows[str(rec)] = {**_completed_row(rec, out / rid), "status": "skipped"}
        else:
            jobs.append((rec, out / rid))
    progress = _Progress(len(jobs))
    if engine == "local":
        results = _run_local(jobs, run_kwargs, workers, progress)
    else:
        results = _run_dask(jobs, run_kwargs, workers, scheduler, progress)
    for row in results:
        rows[row["recording_path"]] = row

    table = pd.DataFrame(
        [{"recording_id": rid, **rows[str(rec)]} for rid, rec in sorted(ids.items())], columns=SUMMARY_COLUMNS
    )
    write_csv(out / "summary.csv", table)
    counts = table["status"].value_counts()
    line = (f"{len(table)} recordings: {counts.get('ok', 0)} ok, {counts.get('skipped', 0)} skipped (complete), "
            f"{counts.get('failed', 0)} failed -> {out / 'summary.csv'}")
    if counts.get("failed", 0):
        raise InputError(line)
    return line
