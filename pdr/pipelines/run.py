"""``pdr run REC -o OUT``: load the recording, build the :class:`~pdr.pipelines.pipeline.Pipeline` of the configuration,
run it, and write every output of CONTRACT.md.

The stages (each timed in ``summary.json``) are the pipeline's; loading never reads ``reference/``. The outputs are
written in a temporary folder renamed onto OUT at the end (no half-written output, ever). An existing OUT needs
``--force``; then only the files ``pdr run`` writes are replaced in it.
"""

from __future__ import annotations

import hashlib
import time
from pathlib import Path
from typing import Any

from pdr import __version__
from pdr.config import load_config
from pdr.errors import InputError, collect_warnings, warn
from pdr.io.atomic import atomic_outputs
from pdr.pipelines.check import check_recording
from pdr.pipelines.pipeline import Pipeline
from pdr.report import (
    write_bouts_csv,
    write_bouts_plot,
    write_geojson,
    write_gpx,
    write_json,
    write_plot,
    write_steps_csv,
    write_strides_csv,
    write_trajectory_csv,
    write_tum,
)

HASH_CHUNK_BYTES = 1 << 20
RUN_OUTPUT_FILES = ("steps.csv", "strides.csv", "trajectory.csv", "trajectory.geojson", "trajectory.tum", "trajectory.gpx",
                    "trajectory.png", "bouts.csv", "bouts.png", "run.json", "summary.json")  # --force replaces these in OUT, nothing else


# ----------------------------------------------------------------------------------------------------------------
# Provenance
# ----------------------------------------------------------------------------------------------------------------


def sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(HASH_CHUNK_BYTES), b""):
            h.update(chunk)
    return h.hexdigest()


def input_hashes(rec_dir: Path) -> dict[str, str]:
    """sha256 of every file of the recording the run may read (``reference/`` excluded), by relative path."""
    files = sorted(p for p in rec_dir.rglob("*") if p.is_file() and p.relative_to(rec_dir).parts[0] != "reference")
    return {p.relative_to(rec_dir).as_posix(): sha256_file(p) for p in files}


def _check_output(out: Path, force: bool) -> None:
    """OUT may be new or empty; an existing one (an earlier run, the user's folder) needs ``--force``, and then only
    the files ``pdr run`` writes (``RUN_OUTPUT_FILES``) are replaced: the user's own files in it stay."""
    if not out.exists():
        return
    if not out.is_dir():
        raise InputError(f"{out}: expected an output folder, found a file")
    if force or not any(out.iterdir()):
        return
    kind = "an earlier pdr run output" if (out / "run.json").is_file() else "a folder with other files"
    raise InputError(f"{out}: expected a new or empty output folder, found {kind} (use --force to replace the files "
                     f"pdr run writes; other files in it are kept)")


def run_recording(rec: Path, out: Path, *, config_path=None, model_path=None, use_gnss: bool = True, plot: bool = False,
                  force: bool = False) -> dict[str, Any]:
    """Reconstruct the trajectory of recording ``rec`` and write every ``pdr run`` output into ``out``.

    Returns the summary (what ``summary.json`` holds); its ``one_line`` is what the CLI prints.
    """
    rec, out = Path(rec), Path(out)
    _check_output(out, force)
    clock = time.perf_counter()
    with collect_warnings() as loading:
        recording = check_recording(rec, with_reference=False)
        config = load_config(config_path)
        pipeline = Pipeline.from_config(config, model_path=model_path, use_gnss=use_gnss,
                                        config_dir=Path(config_path).parent if config_path is not None else None)
    load_s = time.perf_counter() - clock
    with collect_warnings():  # shown below, once the outputs are written
        pipeline.run(recording, earlier_warnings=loading)
    timings = {**pipeline.timings_s_, "load_s": load_s + pipeline.timings_s_["load_s"]}
    clock = time.perf_counter()

    steps, traj, gnss, origin = pipeline.steps_, pipeline.trajectory_, pipeline.gnss_, recording.geo_origin
    summary = dict(pipeline.summary_)
    method = summary["solver"]["fusion"]
    gnss_counts = summary["gnss"]
    gnss_part = f"GNSS {gnss_counts['used']}/{gnss_counts['valid']} fixes used" if gnss is not None else "no GNSS"
    summary["one_line"] = (f"{recording.id}: {len(steps)} steps, {summary['distance_m']:.1f} m in "
                           f"{summary['duration_s']:.1f} s ({method} fusion, {gnss_part}) -> {out}")
    provenance = {
        "pdr_version": __version__,
        "recording": {"id": recording.id, "placement": recording.placement, "geo_origin": list(origin) if origin else None},
        "inputs": input_hashes(rec),
        "config_file_sha256": sha256_file(Path(config_path)) if config_path is not None else None,
        "model_file_sha256": sha256_file(Path(model_path)) if model_path is not None else None,
        "options": {"use_gnss": use_gnss, "plot": plot},
        "config": {"input": config, **pipeline.config_},
        "pipeline": pipeline.get_params(),
    }

    with atomic_outputs(out, RUN_OUTPUT_FILES) as tmp:
        write_steps_csv(tmp / "steps.csv", steps)
        if pipeline.strides_ is not None:
            write_strides_csv(tmp / "strides.csv", pipeline.strides_)
        write_trajectory_csv(tmp / "trajectory.csv", traj, origin)
        write_bouts_csv(tmp / "bouts.csv", pipeline.bouts_)
        write_geojson(tmp / "trajectory.geojson", traj, origin, name=recording.id)
        write_tum(tmp / "trajectory.tum", traj)
        if origin is not None:
            write_gpx(tmp / "trajectory.gpx", traj, origin, name=recording.id,
                      start_unix_s=recording.meta["recording"].get("start_unix_s"))
        if plot:
            plot_gnss = None
            if gnss is not None:
                plot_gnss = gnss[["t_s", "e_m", "n_m", "masked"]].assign(used=pipeline.gnss_used_)
            write_plot(tmp / "trajectory.png", traj, gnss=plot_gnss,
                       title=f"{recording.id}: {len(steps)} steps, {summary['distance_m']:.1f} m ({method} fusion)")
            write_bouts_plot(tmp / "bouts.png", pipeline.bouts_, pipeline.bout_steps_,
                             title=f"{recording.id}: walking bouts")
        write_json(tmp / "run.json", provenance, float_digits=None)  # exact: Pipeline(**pipeline) rebuilds it
        timings["write_s"] = time.perf_counter() - clock
        summary["timings_s"] = {**timings, "total_s": sum(timings.values())}
        write_json(tmp / "summary.json", summary)
    for message in pipeline.warnings_:
        warn(message)
    return summary
