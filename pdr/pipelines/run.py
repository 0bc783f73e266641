"""``pdr run REC -o OUT``: the full reconstruction of one recording, and every output of CONTRACT.md.

Stages (each timed in ``summary.json``): load (never ``reference/``) -> GNSS in the local frame (``--no-gnss``, ``[gnss]
mask_intervals_s``) -> steps (``[steps]``, ``[heading]``; stretches not walked dropped) -> step lengths (``--model`` or
``[step_length]``) -> strides (foot IMUs ``[foot]``, leg camera ``[flow]``/``[slip]``) -> faults -> fusion (``[fusion] method = "graph" | "incremental" | "ekf"`` plus
that class's parameters; default the batch factor graph) -> outputs, written in a temporary folder renamed onto OUT at
the end (no half-written output, ever). An existing OUT needs ``--force``; then only the files ``pdr run`` writes are
replaced in it.
"""

from __future__ import annotations

import copy
import hashlib
import time
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pdr import __version__
from pdr.config import load_config
from pdr.errors import InputError, check_keys, collect_warnings, warn
from pdr.fusion import EkfFusion, FactorGraphFusion, IncrementalFusion
from pdr.geo import latlon_to_en
from pdr.heading import AttitudeStepHeading
from pdr.io.atomic import atomic_outputs
from pdr.io.recording import Recording
from pdr.pipelines.bouts import recording_bouts
from pdr.pipelines.check import check_recording
from pdr.pipelines.faults import rejected_gnss, sensor_faults, warning_line, warning_objects, widen_steps
from pdr.pipelines.foot import foot_chain, foot_strides
from pdr.pipelines.gait_forms import per_form_step_lengths
from pdr.pipelines.leg_camera import camera_strides
from pdr.pipelines.not_walking import drop_not_walking, gnss_only_trajectory, interval_message, not_walking_intervals
from pdr.pipelines.steps import detect_steps, make_detector
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
from pdr.step_length import choose_model
from pdr.step_length.models import MAX_STEP_M

STEP_SOURCE = "accelerometer"
GNSS_KEYS = ("mask_intervals_s",)
FUSION_METHODS = {"graph": FactorGraphFusion, "incremental": IncrementalFusion, "ekf": EkfFusion}
HASH_CHUNK_BYTES = 1 << 20
RUN_OUTPUT_FILES = ("steps.csv", "strides.csv", "trajectory.csv", "trajectory.geojson", "trajectory.tum", "trajectory.gpx",
                    "trajectory.png", "bouts.csv", "bouts.png", "run.json", "summary.json")  # --force replaces these in OUT, nothing else


# ----------------------------------------------------------------------------------------------------------------
# Stages
# ----------------------------------------------------------------------------------------------------------------


def gnss_settings(config: dict[str, Any]) -> dict[str, Any]:
    """The ``[gnss]`` section, checked: ``mask_intervals_s = [[t0, t1], ...]`` (fixes inside are ignored, to make
    GNSS-denied runs from recordings that have GNSS). The accuracy given to fixes without ``h_acc_m`` is the fusion's
    ``default_h_acc_m`` (``[fusion]``)."""
    section = dict(config.get("gnss", {}))
    check_keys(section, GNSS_KEYS, "configuration [gnss]")
    intervals = section.get("mask_intervals_s", [])
    ok = isinstance(intervals, list) and all(
        isinstance(iv, list) and len(iv) == 2 and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in iv)
        and iv[0] <= iv[1] for iv in intervals)
    if not ok:
        raise InputError(f"configuration [gnss] mask_intervals_s: expected a list of [t_start_s, t_end_s] pairs with start <= end, "
                         f"found {intervals!r}")
    return {"mask_intervals_s": [[float(a), float(b)] for a, b in intervals]}


def gnss_local(rec: Recording, settings: dict[str, Any]) -> pd.DataFrame | None:
    """GNSS fixes in the local east-north frame: ``t_s, e_m, n_m, h_acc_m, masked``.

    ``e_m``/``n_m`` are taken as they are when ``gnss.csv`` has them, else converted from ``lat_deg``/``lon_deg`` about the
    recording's ``[geo]`` origin. Rows inside a mask interval have ``masked`` True; invalid fixes keep NaN positions.
    """
    if rec.gnss is None:
        return None
    g = rec.gnss
    if {"e_m", "n_m"} <= set(g.columns):
        e, n = g["e_m"].to_numpy(float), g["n_m"].to_numpy(float)
    else:
        e, n = latlon_to_en(g["lat_deg"].to_numpy(float), g["lon_deg"].to_numpy(float), rec.geo_origin)
    h_acc = g["h_acc_m"].to_numpy(float) if "h_acc_m" in g.columns else np.full(len(g), np.nan)
    t = g["t_s"].to_numpy(float)
    masked = np.zeros(len(g), bool)
    for t0, t1 in settings["mask_intervals_s"]:
        masked |= (t >= t0) & (t <= t1)
    return pd.DataFrame({"t_s": t, "e_m": e, "n_m": n, "h_acc_m": h_acc, "masked": masked})


def make_fusion(section: dict[str, Any] | None):
    """The ``[fusion]`` section: ``method = "graph" | "incremental" | "ekf"`` (default graph: batch smoothing) plus
    that fusion's parameters."""
    section = dict(section or {})
    method = section.pop("method", "graph")
    if method not in FUSION_METHODS:
        raise InputError(f"configuration [fusion]: expected method one of {', '.join(FUSION_METHODS)}, found {method!r}")
    return method, FUSION_METHODS[method].from_config(section)


def fusion_gnss(gnss: pd.DataFrame | None) -> pd.DataFrame | None:
    """The fixes as the fusion takes them (``t_s, e_m, n_m, h_acc_m``): masked fixes become invalid (NaN) rows."""
    if gnss is None:
        return None
    masked = gnss["masked"].to_numpy(bool)
    return pd.DataFrame({"t_s": gnss["t_s"], "e_m": np.where(masked, np.nan, gnss["e_m"]),
                         "n_m": np.where(masked, np.nan, gnss["n_m"]), "h_acc_m": gnss["h_acc_m"]})


def clipped_lengths(length_m: np.ndarray, rec_id: str) -> np.ndarray:
    """Fused step lengths within ``[0, MAX_STEP_M]``: a longer one spans a gap (a stop, missed steps, a stretch not
    walked) whose distance the trajectory keeps; ``steps.csv`` says what a step can be."""
    bad = (length_m < 0) | (length_m > MAX_STEP_M)
    if bad.any():
        warn(f"{rec_id}: {int(bad.sum())} fused step length(s) outside [0, {MAX_STEP_M:g}] m (up to "
             f"{float(np.max(np.abs(length_m[bad]))):.1f} m: gaps the trajectory keeps) clipped in steps.csv")
    return np.clip(length_m, 0.0, MAX_STEP_M)


def start_only_trajectory(t_s: float) -> pd.DataFrame:
    """The trajectory of a recording without steps: the start pose at the origin, heading 0, known exactly."""
    return pd.DataFrame({"t_s": [t_s], "e_m": [0.0], "n_m": [0.0], "heading_rad": [0.0], "e_std_m": [0.0], "n_std_m": [0.0]})


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


# ----------------------------------------------------------------------------------------------------------------
# The pipeline
# ----------------------------------------------------------------------------------------------------------------


def run_recording(rec: Path, out: Path, *, config_path=None, model_path=None, use_gnss: bool = True, plot: bool = False,
                  force: bool = False) -> dict[str, Any]:
    """Reconstruct the trajectory of recording ``rec`` and write every ``pdr run`` output into ``out``.

    Returns the summary (what ``summary.json`` holds); its ``one_line`` is what the CLI prints.
    """
    rec, out = Path(rec), Path(out)
    _check_output(out, force)
    timings: dict[str, float] = {}
    clock = time.perf_counter()

    def lap(stage: str) -> None:
        nonlocal clock
        now = time.perf_counter()
        timings[stage] = now - clock
        clock = now

    with collect_warnings() as caught:
        recording = check_recording(rec, with_reference=False)
        config = load_config(config_path)
        settings = gnss_settings(config)
        method, fusion = make_fusion(config.get("fusion"))
        model, model_choice = choose_model(config, recording.subject, recording.placement, model_path)
        model_given = {"model": type(model).__name__, "params": copy.deepcopy(model.get_params())}  # run.json: the input
        lap("load_s")

        gnss = gnss_local(recording, settings) if use_gnss else None
        lap("gnss_s")

        steps = detect_steps(recording, config).reset_index(drop=True)
        not_walking = not_walking_intervals(steps, gnss, recording.subject.get("height_m"))
        for iv in not_walking:
            warn(interval_message(recording.id, iv))
        steps = drop_not_walking(steps, not_walking)
        lap("steps_s")

        model.estimate(model.prepare(steps, recording), subject=recording.subject)
        steps["step_length_m"] = np.asarray(model.step_length_m_, float)
        steps["step_length_std_m"] = np.asarray(model.step_length_std_m_, float)
        gait_forms_info = None
        if config.get("gait_forms") is not None and len(steps):  # per-form step models (issue 7)
            steps, gait_forms_info = per_form_step_lengths(
                recording, steps, config["gait_forms"], config, Path(config_path).parent if config_path else None)
            if gait_forms_info["steps_per_form_model"] and hasattr(fusion, "calibrate_step_scale"):
                # keep the forms' relative step lengths: GNSS calibrates one scale of them, not one regression
                fusion.calibrate_step_model, fusion.calibrate_step_scale = False, True
        lap("step_length_s")

        stride_tables = [t for t in (foot_strides(recording, config), camera_strides(recording, config)) if t is not None]
        strides = pd.concat(stride_tables, ignore_index=True).sort_values("t_end_s", kind="stable") if stride_tables else None
        lap("strides_s")

        faults = sensor_faults(recording.imu, gnss, config.get("faults"))  # [faults]: SensorFaultDetection
        steps = widen_steps(steps, faults.faults_, float(recording.imu["t_s"].iloc[0]))
        gnss_suspect = faults.gnss_suspect_ if gnss is not None else None
        lap("faults_s")

        # with foot INS strides the graph's chain is the INS path (relative poses between mid-stances), not the steps
        chain = foot_chain(strides)
        fusion.fuse(steps if chain is None else chain[0],
                    gnss=fusion_gnss(gnss if gnss is None else gnss.assign(masked=gnss["masked"] | gnss_suspect)),
                    strides=strides if chain is None else chain[1], step_model=model)
        traj = fusion.trajectory_.reset_index(drop=True)
        gnss_used = np.asarray(fusion.gnss_used_, bool) if gnss is not None else None
        if chain is not None:
            model = fusion.step_model_ if fusion.step_model_ is not None else model
        elif len(steps):
            steps["step_length_m"] = clipped_lengths(np.asarray(fusion.step_length_m_, float), recording.id)
            steps["heading_rad"] = traj["heading_rad"].to_numpy(float)[1:]  # the fused east-north heading of each step
            model = fusion.step_model_ if fusion.step_model_ is not None else model
        else:
            usable = None if gnss is None else (np.isfinite(gnss["e_m"]) & np.isfinite(gnss["n_m"]) & ~gnss["masked"]
                                                & ~gnss_suspect).to_numpy(bool)
            traj = gnss_only_trajectory(gnss, usable) if gnss is not None else None
            if traj is None:
                traj = start_only_trajectory(float(recording.imu["t_s"].iloc[0]))
            else:
                gnss_used = usable
                warn(f"{recording.id}: no steps; the trajectory follows the GNSS alone ({int(usable.sum())} fixes)")
        solver = {"fusion": method, **fusion.solver_}
        stride_scales = getattr(fusion, "stride_scales_", None) or {}  # per source; the EKF does not use strides
        lap("fusion_s")

        bouts, bout_steps = recording_bouts(recording, steps, gnss)  # bouts.csv: walking bouts and their mechanics
        lap("bouts_s")

    run_warnings = list(caught)
    rejected = (rejected_gnss(gnss, gnss_suspect, gnss_used, float(traj["t_s"].iloc[0]), float(traj["t_s"].iloc[-1]))
                if gnss is not None else [])
    warning_list = warning_objects(faults.faults_, rejected, run_warnings)

    steps.insert(0, "step_id", np.arange(len(steps), dtype=int))
    steps["source"] = STEP_SOURCE
    origin = recording.geo_origin
    distance = float(np.sum(np.hypot(np.diff(traj["e_m"]), np.diff(traj["n_m"]))))
    imu_t = recording.imu["t_s"].to_numpy(float)
    gnss_counts = None
    if gnss is not None:
        valid = np.isfinite(gnss["e_m"].to_numpy()) & np.isfinite(gnss["n_m"].to_numpy())
        gnss_counts = {"fixes": len(gnss), "valid": int(valid.sum()), "masked": int((gnss["masked"] & valid).sum()),
                       "jumped": int((gnss_suspect & ~faults.gnss_inaccurate_ & valid).sum()),
                       "inaccurate": int((faults.gnss_inaccurate_ & valid).sum()), "used": int(gnss_used.sum())}
    step_model = {"model": type(model).__name__, "params": model.get_params(), "choice": model_choice}
    summary: dict[str, Any] = {
        "recording_id": recording.id,
        "distance_m": distance,
        "n_steps": len(steps),
        "n_strides": len(strides) if strides is not None else 0,
        "duration_s": float(imu_t[-1] - imu_t[0]),
        "walking_duration_s": float(steps["t_s"].iloc[-1] - steps["t_s"].iloc[0]) if len(steps) > 1 else 0.0,
        "step_model": step_model,
        "solver": solver,
        "gnss": gnss_counts or {"fixes": 0, "valid": 0, "masked": 0, "jumped": 0, "inaccurate": 0, "used": 0},
        "warnings": warning_list,
        "not_walking": not_walking,
    }
    step_scale = getattr(fusion, "step_scale_", None)
    if step_scale and step_scale["calibrated"]:
        summary["step_scale"] = step_scale  # steps.csv holds the fused lengths; the per-form models' x scale
    if stride_scales:
        summary["stride_scales"] = stride_scales  # strides.csv keeps the sources' lengths; the fusion used them x scale
    if gait_forms_info is not None:
        summary["gait_forms"] = gait_forms_info
    gnss_part = f"GNSS {gnss_counts['used']}/{gnss_counts['valid']} fixes used" if gnss_counts else "no GNSS"
    summary["one_line"] = (f"{recording.id}: {len(steps)} steps, {distance:.1f} m in {summary['duration_s']:.1f} s "
                           f"({method} fusion, {gnss_part}) -> {out}")
    provenance = {
        "pdr_version": __version__,
        "recording": {"id": recording.id, "placement": recording.placement, "geo_origin": list(origin) if origin else None},
        "inputs": input_hashes(rec),
        "config_file_sha256": sha256_file(Path(config_path)) if config_path is not None else None,
        "model_file_sha256": sha256_file(Path(model_path)) if model_path is not None else None,
        "options": {"use_gnss": use_gnss, "plot": plot},
        "config": {"input": config, "steps": make_detector(config.get("steps"), recording.placement).get_params(),
                   "heading": AttitudeStepHeading.from_config(config.get("heading")).get_params(),
                   "gnss": settings, "step_length": model_given, "faults": faults.get_params(),
                   "fusion": {"method": method, "params": fusion.get_params()}},
    }

    with atomic_outputs(out, RUN_OUTPUT_FILES) as tmp:
        write_steps_csv(tmp / "steps.csv", steps)
        if strides is not None:
            write_strides_csv(tmp / "strides.csv", strides)
        write_trajectory_csv(tmp / "trajectory.csv", traj, origin)
        write_bouts_csv(tmp / "bouts.csv", bouts)
        write_geojson(tmp / "trajectory.geojson", traj, origin, name=recording.id)
        write_tum(tmp / "trajectory.tum", traj)
        if origin is not None:
            write_gpx(tmp / "trajectory.gpx", traj, origin, name=recording.id,
                      start_unix_s=recording.meta["recording"].get("start_unix_s"))
        if plot:
            plot_gnss = None
            if gnss is not None:
                plot_gnss = gnss[["t_s", "e_m", "n_m", "masked"]].assign(used=gnss_used)
            write_plot(tmp / "trajectory.png", traj, gnss=plot_gnss,
                       title=f"{recording.id}: {len(steps)} steps, {distance:.1f} m ({method} fusion)")
            write_bouts_plot(tmp / "bouts.png", bouts, bout_steps, title=f"{recording.id}: walking bouts")
        write_json(tmp / "run.json", provenance)
        lap("write_s")
        summary["timings_s"] = {**timings, "total_s": sum(timings.values())}
        write_json(tmp / "summary.json", summary)
    for message in [warning_line(w) for w in warning_list if w["kind"] != "general"] + run_warnings:
        warn(message)
    return summary
