"""``pdr batch``: ``pdr run`` over many recordings, one output folder each, plus ``OUT/summary.csv``.

Engines: a local process pool (default, no set-up) or Dask distributed (``--engine dask``: an existing cluster with
``--scheduler ADDR``, else a ``LocalCluster`` started here). Both run the same function, :func:`run_one`, in worker
processes with one thread each for the numeric libraries, so the outputs are identical whichever engine ran them
(``summary.csv`` has no timings; ``summary.json`` keeps the per-run timings of CONTRACT.md).

- One bad recording never stops the batch: an error becomes a ``failed`` row with its one-line message; a worker
  process that dies (a crash in native code, the kernel's out-of-memory killer) breaks only the pool, whose
  unfinished recordings are then re-run one at a time in their own process, so only the culprit fails.
- Resume: a second run skips a recording whose output folder is complete (it appears only once complete, by
  atomic rename) and was made with the same options (``--config``/``--model`` file hashes and ``--no-gnss``, read
  from its ``run.json``); anything else is run again.
- A scheduler address that does not answer (nothing listening, a silent or foreign service) is an InputError
  within :data:`SCHEDULER_TIMEOUT_S` seconds, before any work is sent.
- ``summary.csv`` is written (atomically) before the first run and again as each recording finishes, so an
  interrupted batch still says what finished; recordings not finished have status ``pending``.
- Progress: a one-line counter on stderr when stderr is a terminal; silent otherwise.
"""

from __future__ import annotations

import json
import multiprocessing
import os
import signal
import sys
import time
from collections import deque
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path
from typing import Any, Iterable, Iterator

import pandas as pd
from tqdm import tqdm

from pdr.errors import InputError, collect_warnings
from pdr.io.importers._common import safe_id
from pdr.io.atomic import write_csv
from pdr.io.tomlio import read_toml

SUMMARY_COLUMNS = ["recording_id", "recording_path", "status", "distance_m", "n_steps", "duration_s", "error", "output_folder"]
SCHEDULER_TIMEOUT_S = 4.0  # connect + handshake with --scheduler; with the imports (4-6 s on a loaded 2-core machine)
# the command fails within 10 s
COMPLETE_MARKERS = ("run.json", "summary.json", "trajectory.csv")
# One thread per worker process for the numeric libraries (what Dask's nanny sets for its workers too): the
# processes are the parallelism, and more threads than cores would only compete.
THREAD_ENV = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS")

Job = tuple[Path, Path, str]  # absolute recording path, absolute output folder, the recording path as given


def _recording_id(rec: Path) -> str:
    """The id in meta.toml, or the folder name when meta.toml cannot be read (the run will then report why)."""
    try:
        return str(read_toml(rec / "meta.toml")["recording"]["id"])
    except (InputError, KeyError, TypeError, OSError):
        return rec.name


def is_complete(out_dir: Path) -> bool:
    return all((out_dir / name).is_file() for name in COMPLETE_MARKERS)


def _options_match(out_dir: Path, run_kwargs: dict[str, Any]) -> bool:
    """Whether the complete output in ``out_dir`` was made with the options of this batch (its run.json says)."""
    from pdr.pipelines.run import sha256_file

    try:
        prov = json.loads((out_dir / "run.json").read_text())
        expected = {name: sha256_file(Path(path)) if path is not None else None
                    for name, path in (("config_file_sha256", run_kwargs["config_path"]),
                                       ("model_file_sha256", run_kwargs["model_path"]))}
        return (all(prov.get(k) == v for k, v in expected.items())
                and prov.get("options", {}).get("use_gnss") == run_kwargs["use_gnss"])
    except (OSError, ValueError, AttributeError):
        return False


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split())[:300] or type(exc).__name__


def _failed_row(given: str, message: str) -> dict[str, Any]:
    return {"recording_path": given, "status": "failed", "error": message}


def run_one(rec: Path, out_dir: Path, run_kwargs: dict[str, Any], given: str | None = None) -> dict[str, Any]:
    """Run one recording; never raises: a failure becomes a row with its one-line error.

    The run's warnings are not shown (a batch of hundreds would flood the terminal): each output's summary.json
    lists them.
    """
    from pdr.pipelines.run import run_recording

    _one_thread()
    row: dict[str, Any] = {"recording_path": given if given is not None else str(rec), "status": "ok", "error": ""}
    try:
        with collect_warnings(), _pandas_one_thread():
            summary = run_recording(rec, out_dir, force=True, **run_kwargs)
        row.update(distance_m=summary["distance_m"], n_steps=summary["n_steps"], duration_s=summary["duration_s"])
    except Exception as exc:  # the batch goes on; the row says why this recording failed
        row.update(status="failed", error=_one_line(exc))
    return row


def _completed_row(given: str, out_dir: Path) -> dict[str, Any]:
    summary = json.loads((out_dir / "summary.json").read_text())
    return {"recording_path": given, "status": "skipped", "error": "", "distance_m": summary["distance_m"],
            "n_steps": summary["n_steps"], "duration_s": summary["duration_s"]}


class _Progress:
    """A one-line progress bar (tqdm) on stderr when it is a terminal; silent otherwise."""

    def __init__(self, total: int, stream=None):
        stream = stream if stream is not None else sys.stderr
        self.failed = 0
        self.bar = tqdm(total=total, file=stream, unit="recording", dynamic_ncols=True,
                        disable=total == 0 or not stream.isatty())

    def tick(self, row: dict[str, Any]) -> None:
        if row["status"] == "failed":
            self.failed += 1
            self.bar.set_postfix_str(f"{self.failed} failed", refresh=False)
        self.bar.update(1)
        if self.bar.n == self.bar.total:
            self.bar.close()


def _pandas_one_thread():
    """pandas >= 3.1 parses a large CSV on several threads: one here (the worker processes are the parallelism)."""
    import contextlib

    try:
        pd.get_option("mode.max_threads")
    except (KeyError, pd.errors.OptionError):
        return contextlib.nullcontext()
    return pd.option_context("mode.max_threads", 1)


def _one_thread() -> None:
    """One thread for the numeric libraries of this worker process (libraries that read these at start-up)."""
    for name in THREAD_ENV:
        os.environ[name] = "1"
    try:
        import cv2

        cv2.setNumThreads(1)
    except ImportError:  # pragma: no cover - a core dependency
        pass


def _isolated_target(conn, job: Job, run_kwargs: dict[str, Any]) -> None:
    _one_thread()
    conn.send(run_one(job[0], job[1], run_kwargs, job[2]))
    conn.close()


def _run_isolated(job: Job, run_kwargs: dict[str, Any]) -> dict[str, Any]:
    """Run one recording in a process of its own: a crash of that process fails this row only, and says how it died."""
    ctx = multiprocessing.get_context()
    receive, send = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_isolated_target, args=(send, job, run_kwargs), daemon=True)
    proc.start()
    send.close()
    row = None
    try:
        while row is None:
            if receive.poll(0.2):
                try:
                    row = receive.recv()
                except EOFError:  # the process ended without sending a row
                    break
            elif not proc.is_alive() and not receive.poll(0):
                break
    finally:
        proc.join()
    if row is not None:
        return row
    code = proc.exitcode
    how = f"signal {-code} ({signal.Signals(-code).name})" if code is not None and code < 0 else f"exit code {code}"
    return _failed_row(job[2], f"the worker process died while running this recording ({how}): a crash in native code "
                                f"or the out-of-memory killer")


def _run_local(jobs: list[Job], run_kwargs: dict, workers: int, progress: _Progress) -> Iterator[dict]:
    """A process pool with at most ``workers`` recordings in flight, so that when a worker dies the suspects are few."""
    queue = deque(jobs)
    while queue:
        suspects: list[Job] = []  # in flight when the pool broke
        pool = ProcessPoolExecutor(max_workers=min(workers, len(queue)), initializer=_one_thread)
        running: dict[Any, Job] = {}
        broken = False
        try:
            while not broken and (queue or running):
                while queue and len(running) < workers:
                    try:
                        running[pool.submit(run_one, queue[0][0], queue[0][1], run_kwargs, queue[0][2])] = queue[0]
                    except BrokenProcessPool:
                        broken = True
                        break
                    queue.popleft()
                done, _ = wait(running, return_when=FIRST_COMPLETED)
                for fut in done:
                    job = running.pop(fut)
                    try:
                        row = fut.result()
                    except BrokenProcessPool:
                        suspects.append(job)
                        broken = True
                        continue
                    except Exception as exc:  # e.g. arguments that cannot be sent to the worker
                        row = _failed_row(job[2], _one_line(exc))
                    progress.tick(row)
                    yield row
            suspects += running.values()
            if broken and not suspects:  # broke before anything ran: isolate the next one, so the batch moves on
                suspects.append(queue.popleft())
        finally:
            pool.shutdown(wait=True, cancel_futures=True)
        for job in suspects:
            row = _run_isolated(job, run_kwargs)
            progress.tick(row)
            yield row


async def _identity(address: str, deadline: float) -> dict:
    """Open a plain TCP connection first (nothing listening or an unknown host fails at once, without the dask
    import or its connect retries), then ask the peer for its identity the Dask way, all before ``deadline``."""
    import asyncio

    scheme, _, rest = address.rpartition("://")
    if scheme in ("", "tcp"):
        host, _, port = rest.rpartition(":")
        _, writer = await asyncio.wait_for(asyncio.open_connection(host.strip("[]"), int(port)),
                                           deadline - time.monotonic())
        writer.close()
    from distributed.comm import connect

    comm = await connect(address, timeout=max(deadline - time.monotonic(), 0.1))
    try:
        await comm.write({"op": "identity", "reply": True})
        return await comm.read()
    finally:
        comm.abort()


def _check_scheduler(address: str) -> None:
    """Fail within SCHEDULER_TIMEOUT_S unless a Dask scheduler answers at ``address`` (dask's own connect timeout does
    not bound a peer that accepts the connection and then stays silent, and retries a refused one until it ends)."""
    import asyncio

    what = f"--scheduler {address}: expected a Dask scheduler answering within {SCHEDULER_TIMEOUT_S:g} s"
    scheme, _, rest = address.rpartition("://")
    host, sep, port = rest.rpartition(":")
    if not (scheme or "tcp").isidentifier() or not host or not sep or not port.isdigit():
        raise InputError(f"--scheduler: expected an address like tcp://HOST:PORT, found {address!r}")
    deadline = time.monotonic() + SCHEDULER_TIMEOUT_S
    try:
        reply = asyncio.run(asyncio.wait_for(_identity(address, deadline), SCHEDULER_TIMEOUT_S))
    except (asyncio.TimeoutError, TimeoutError):
        raise InputError(f"{what}, found no answer") from None
    except ConnectionRefusedError:
        raise InputError(f"{what}, found nothing listening (connection refused)") from None
    except Exception as exc:  # unknown host, bad address, a service speaking another protocol
        raise InputError(f"{what}, found {type(exc).__name__}: {_one_line(exc)}") from None
    if not isinstance(reply, dict) or reply.get("type") != "Scheduler":
        raise InputError(f"{what}, found a peer that is not a Dask scheduler ({str(reply)[:80]})")


def _check_dask_installed() -> None:
    import importlib.util

    if importlib.util.find_spec("distributed") is None:
        raise InputError("--engine dask: expected the dask[distributed] package, found it not installed (pip install 'pdr[dask]')")


def _dask_client(scheduler: str | None, workers: int):
    import logging

    _check_dask_installed()
    from dask.distributed import Client, LocalCluster

    if scheduler:
        try:
            return Client(scheduler, timeout=f"{SCHEDULER_TIMEOUT_S}s"), None
        except (OSError, TimeoutError) as exc:
            raise InputError(f"--scheduler {scheduler}: the scheduler answered, then the client could not connect ({_one_line(exc)})") from None
    cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None,
                           silence_logs=logging.ERROR)
    return Client(cluster), cluster


def _run_dask(jobs: list[Job], run_kwargs: dict, workers: int, scheduler: str | None, progress: _Progress) -> Iterator[dict]:
    from dask.distributed import as_completed as dask_as_completed

    client, cluster = _dask_client(scheduler, workers)
    try:
        futures = {client.submit(run_one, job[0], job[1], run_kwargs, job[2], pure=False): job for job in jobs}
        for fut in dask_as_completed(futures):
            try:
                row = fut.result()
            except Exception as exc:  # KilledWorker (the task's worker died, every retry) or a lost scheduler
                row = _failed_row(futures[fut][2], f"dask: {type(exc).__name__}: {_one_line(exc)}")
            progress.tick(row)
            yield row
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def _default_workers() -> int:
    try:
        return len(os.sched_getaffinity(0)) or 1
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def output_folders(recs: list[Path]) -> dict[str, tuple[str, Path]]:
    """``{output folder name: (recording id, recording)}``: the recording id, or for recordings that share an id (seeds of one
    scenario, two phones exporting the same name) the recording's folder name, then ``_2``, ``_3``... until unique.
    The same recording given twice is an error."""
    seen: dict[Path, Path] = {}
    for rec in recs:
        key = rec.resolve()
        if key in seen:
            raise InputError(f"{rec}: expected each recording once, found it twice ({seen[key]} and {rec})")
        seen[key] = rec
    ids = [_recording_id(rec) for rec in recs]
    shared = {rid for rid in ids if ids.count(rid) > 1}
    unique = {rid for rid in ids if rid not in shared}
    out: dict[str, tuple[str, Path]] = {}
    for rec, rid in zip(recs, ids):
        name = rid if rid in unique else safe_id(rec.name)
        base, k = name, 2
        while name in out or (rid in shared and name in unique):
            name, k = f"{base}_{k}", k + 1
        out[name] = (rid, rec)
    return out


def run_batch(recs: list[Path], out: Path, *, engine: str = "local", workers: int | None = None, scheduler: str | None = None,
              config_path: str | None = None, model_path: str | None = None, use_gnss: bool = True,
              progress_stream=None) -> str:
    """Run every recording into ``out/<recording id>/`` and write ``out/summary.csv``; return a one-line summary.

    Recordings that share an id get unique folders (``output_folders``); ``summary.csv`` names each one's folder.

    Raises InputError (after writing the summary) when any recording failed, so the exit code tells.
    """
    if engine not in ("local", "dask"):
        raise InputError(f"--engine: expected local or dask, found {engine!r}")
    if scheduler is not None and engine != "dask":
        raise InputError("--scheduler: expected it with --engine dask only")
    workers = _default_workers() if workers is None else workers
    if workers < 1:
        raise InputError(f"--workers: expected at least 1, found {workers}")
    for path in (config_path, model_path):
        if path is not None and not Path(path).is_file():
            raise InputError(f"{path}: expected a file, found nothing there")
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: expected an output folder, found a file")
    if engine == "dask" and scheduler:  # first: its answer bounds the time to an error, whatever the recordings
        _check_dask_installed()
        _check_scheduler(scheduler)
    ids = output_folders([Path(r) for r in recs])
    run_kwargs = {"config_path": str(Path(config_path).resolve()) if config_path is not None else None,
                  "model_path": str(Path(model_path).resolve()) if model_path is not None else None,
                  "use_gnss": use_gnss}

    rows: dict[str, dict] = {}
    jobs: list[Job] = []
    for folder, (_, rec) in ids.items():
        if is_complete(out / folder) and _options_match(out / folder, run_kwargs):
            rows[str(rec)] = _completed_row(str(rec), out / folder)
        else:  # absolute paths: a Dask worker may run in another folder
            jobs.append((rec.resolve(), (out / folder).resolve(), str(rec)))
    progress = _Progress(len(jobs), progress_stream)
    results: Iterable[dict]
    if engine == "local":
        results = _run_local(jobs, run_kwargs, workers, progress)
    else:
        results = _run_dask(jobs, run_kwargs, workers, scheduler, progress)

    def summary_table() -> pd.DataFrame:  # recordings not finished yet have status "pending"
        return pd.DataFrame([{"recording_id": rid, **rows.get(str(rec), {"recording_path": str(rec), "status": "pending",
                                                                         "error": ""}), "output_folder": folder}
                             for folder, (rid, rec) in sorted(ids.items())], columns=SUMMARY_COLUMNS)

    write_csv(out / "summary.csv", summary_table())
    for row in results:  # summary.csv rewritten (atomically) as each row completes: an interrupted batch says what finished
        rows[row["recording_path"]] = row
        write_csv(out / "summary.csv", summary_table())

    table = summary_table()
    counts = table["status"].value_counts()
    line = (f"{len(table)} recordings: {counts.get('ok', 0)} ok, {counts.get('skipped', 0)} skipped (complete), "
            f"{counts.get('failed', 0)} failed -> {out / 'summary.csv'}")
    if counts.get("failed", 0):
        first = table[table["status"] == "failed"].iloc[0]
        raise InputError(f"{line}; first failure {first['recording_id']}: {first['error']}")
    return line
