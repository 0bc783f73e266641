"""``pdr run REC -o OUT``: the full reconstruction of one recording, and every output of CONTRACT.md.

Stages (each timed in ``summary.json``): load (never ``reference/``) -> steps (``[steps]``, ``[heading]``) -> step lengths
(``--model`` or ``[step_length]``) -> strides (foot IMUs ``[foot]``, leg camera ``[flow]``/``[slip]``; written, not yet fused)
-> GNSS in the local frame (``--no-gnss``, ``[gnss] mask_intervals_s``) -> trajectory
-> outputs, written in a temporary folder renamed onto OUT at the end (no half-written output, ever).

The trajectory stage is, for now, a plain dead reckoning of the steps along their heading (:func:`dead_reckon`), with a
first-order covariance propagation for ``e_std_m`` / ``n_std_m``; GNSS fixes are converted, masked and plotted but not fused.
"""

from __future__ import annotations

import hashlib
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pdr import __version__
from pdr.config import load_config
from pdr.errors import InputError
from pdr.geo import latlon_to_en
from pdr.heading import AttitudeStepHeading
from pdr.io.atomic import atomic_dir
from pdr.io.recording import Recording, load_recording
from pdr.pipelines.foot import foot_strides
from pdr.pipelines.leg_camera import camera_strides
from pdr.pipelines.steps import detect_steps, make_detector
from pdr.report import (
    write_geojson,
    write_gpx,
    write_json,
    write_plot,
    write_steps_csv,
    write_strides_csv,
    write_trajectory_csv,
    write_tum,
)
from pdr.step_length import load_model, model_from_config

STEP_SOURCE = "accelerometer"
GNSS_KEYS = ("mask_intervals_s", "default_h_acc_m")
DEFAULT_H_ACC_M = 5.0  # 1-sigma accuracy given to fixes without h_acc_m (a consumer receiver in the open)
DR_HEADING_CHANGE_STD_RAD = 0.02  # per-step heading noise of the dead reckoning where the steps table gives none
HASH_CHUNK_BYTES = 1 << 20


# ----------------------------------------------------------------------------------------------------------------
# Stages
# ----------------------------------------------------------------------------------------------------------------


def gnss_settings(config: dict[str, Any]) -> dict[str, Any]:
    """The ``[gnss]`` section, checked: ``mask_intervals_s = [[t0, t1], ...]`` (fixes inside are ignored, to make
    GNSS-denied runs from recordings that have GNSS) and ``default_h_acc_m`` (accuracy of fixes without ``h_acc_m``)."""
    section = dict(config.get("gnss", {}))
    unknown = sorted(set(section) - set(GNSS_KEYS))
    if unknown:
        raise InputError(f"configuration [gnss]: unknown key(s) {', '.join(unknown)}; expected some of: {', '.join(GNSS_KEYS)}")
    intervals = section.get("mask_intervals_s", [])
    ok = isinstance(intervals, list) and all(
        isinstance(iv, list) and len(iv) == 2 and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in iv)
        and iv[0] <= iv[1] for iv in intervals)
    if not ok:
        raise InputError(f"configuration [gnss] mask_intervals_s: expected a list of [t_start_s, t_end_s] pairs with start <= end, "
                         f"found {intervals!r}")
    h_acc = section.get("default_h_acc_m", DEFAULT_H_ACC_M)
    if isinstance(h_acc, bool) or not isinstance(h_acc, (int, float)) or not h_acc > 0:
        raise InputError(f"configuration [gnss] default_h_acc_m: expected a number > 0 (metres), found {h_acc!r}")
    return {"mask_intervals_s": [[float(a), float(b)] for a, b in intervals], "default_h_acc_m": float(h_acc)}


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
    h_acc = np.where(np.isfinite(h_acc), h_acc, settings["default_h_acc_m"])
    t = g["t_s"].to_numpy(float)
    masked = np.zeros(len(g), bool)
    for t0, t1 in settings["mask_intervals_s"]:
        masked |= (t >= t0) & (t <= t1)
    return pd.DataFrame({"t_s": t, "e_m": e, "n_m": n, "h_acc_m": h_acc, "masked": masked})


def dead_reckon(steps: pd.DataFrame, *, t_start_s: float,
                heading_change_std_rad: float = DR_HEADING_CHANGE_STD_RAD) -> tuple[pd.DataFrame, dict[str, Any]]:
    """Plain dead reckoning: each step moves ``step_length_m`` along its ``heading_rad`` from the origin.

    Returns the trajectory (``t_s, e_m, n_m, heading_rad, e_std_m, n_std_m``; first row = the start at ``t_start_s``,
    then one row per step) and a solver dict.

    Notes
    -----
    Uncertainty by first-order (EKF-style) propagation of the state (e, n, heading): ``P <- F P F^T + G Q G^T`` with
    ``F = [[1, 0, -L sin h], [0, 1, L cos h], [0, 0, 1]]``, ``G = [[cos h, 0], [sin h, 0], [0, 1]]`` and
    ``Q = diag(step_length_std_m^2, heading_change_std_rad^2)``; the start pose is known exactly (it defines the frame).
    The per-step heading noise is the steps table's ``heading_change_std_rad`` where finite, else the default.
    """
    t0 = time.perf_counter()
    n_steps = len(steps)
    length = steps["step_length_m"].to_numpy(float)
    length_std = steps["step_length_std_m"].to_numpy(float)
    heading = steps["heading_rad"].to_numpy(float)
    if "heading_change_std_rad" in steps.columns:
        dh_std = steps["heading_change_std_rad"].to_numpy(float)
        dh_std = np.where(np.isfinite(dh_std), dh_std, heading_change_std_rad)
    else:
        dh_std = np.full(n_steps, heading_change_std_rad)
    bad = ~(np.isfinite(length) & np.isfinite(heading))
    if bad.any():
        raise InputError(f"steps: expected finite step_length_m and heading_rad, found {int(bad.sum())} non-finite value(s)")
    e = np.concatenate([[0.0], np.cumsum(length * np.cos(heading))])
    n = np.concatenate([[0.0], np.cumsum(length * np.sin(heading))])
    e_std = np.zeros(n_steps + 1)
    n_std = np.zeros(n_steps + 1)
    p = np.zeros((3, 3))
    for k in range(n_steps):
        c, s = np.cos(heading[k]), np.sin(heading[k])
        f = np.array([[1.0, 0.0, -length[k] * s], [0.0, 1.0, length[k] * c], [0.0, 0.0, 1.0]])
        g = np.array([[c, 0.0], [s, 0.0], [0.0, 1.0]])
        q = np.diag([np.nan_to_num(length_std[k]) ** 2, dh_std[k] ** 2])
        p = f @ p @ f.T + g @ q @ g.T
        e_std[k + 1], n_std[k + 1] = np.sqrt(p[0, 0]), np.sqrt(p[1, 1])
    traj = pd.DataFrame({
        "t_s": np.concatenate([[t_start_s], steps["t_s"].to_numpy(float)]),
        "e_m": e, "n_m": n,
        "heading_rad": np.concatenate([[heading[0] if n_steps else 0.0], heading]),
        "e_std_m": e_std, "n_std_m": n_std,
    })
    solver = {"method": "dead_reckoning", "iterations": 0, "final_error": 0.0, "time_s": time.perf_counter() - t0,
              "heading_change_std_rad": heading_change_std_rad}
    return traj, solver


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
    """OUT may be new, empty, a previous ``pdr run`` output (it has ``run.json``), or anything with ``--force``."""
    if not out.exists() or force:
        return
    if not out.is_dir():
        raise InputError(f"{out}: expected an output folder, found a file (use --force to replace it)")
    if (out / "run.json").is_file() or not any(out.iterdir()):
        return
    raise InputError(f"{out}: expected a new output folder or a previous pdr run output (with run.json), "
                     f"found a folder with other content (use --force to replace it)")


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

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        recording = load_recording(rec, with_reference=False)
        config = load_config(config_path)
        settings = gnss_settings(config)
        model = load_model(model_path) if model_path is not None else model_from_config(config)
        lap("load_s")

        steps = detect_steps(recording, config).reset_index(drop=True)
        lap("steps_s")

        model.estimate(model.prepare(steps, recording), subject=recording.subject)
        steps["step_length_m"] = np.asarray(model.step_length_m_, float)
        steps["step_length_std_m"] = np.asarray(model.step_length_std_m_, float)
        lap("step_length_s")

        stride_tables = [t for t in (foot_strides(recording, config), camera_strides(recording, config)) if t is not None]
        strides = pd.concat(stride_tables, ignore_index=True).sort_values("t_end_s", kind="stable") if stride_tables else None
        lap("strides_s")

        gnss = gnss_local(recording, settings) if use_gnss else None
        lap("gnss_s")

        t_start = float(recording.imu["t_s"].iloc[0])
        traj, solver = dead_reckon(steps, t_start_s=t_start)
        gnss_used = np.zeros(len(gnss), bool) if gnss is not None else None
        lap("trajectory_s")

    run_warnings = [" ".join(str(w.message).split()) for w in caught]
    if gnss is not None and len(gnss):
        run_warnings.append("GNSS fixes are not fused yet: the trajectory is plain dead reckoning")

    steps.insert(0, "step_id", np.arange(len(steps), dtype=int))
    steps["source"] = STEP_SOURCE
    origin = recording.geo_origin
    distance = float(np.sum(np.hypot(np.diff(traj["e_m"]), np.diff(traj["n_m"]))))
    imu_t = recording.imu["t_s"].to_numpy(float)
    gnss_counts = None
    if gnss is not None:
        valid = np.isfinite(gnss["e_m"].to_numpy()) & np.isfinite(gnss["n_m"].to_numpy())
        gnss_counts = {"fixes": len(gnss), "valid": int(valid.sum()), "masked": int((gnss["masked"] & valid).sum()),
                       "used": int(gnss_used.sum())}
    step_model = {"model": type(model).__name__, "params": model.get_params()}
    summary: dict[str, Any] = {
        "recording_id": recording.id,
        "distance_m": distance,
        "n_steps": len(steps),
        "n_strides": len(strides) if strides is not None else 0,
        "duration_s": float(imu_t[-1] - imu_t[0]),
        "walking_duration_s": float(steps["t_s"].iloc[-1] - steps["t_s"].iloc[0]) if len(steps) > 1 else 0.0,
        "step_model": step_model,
        "solver": solver,
        "gnss": gnss_counts or {"fixes": 0, "valid": 0, "masked": 0, "used": 0},
        "warnings": run_warnings,
    }
    gnss_part = f"GNSS {gnss_counts['used']}/{gnss_counts['valid']} fixes used" if gnss_counts else "no GNSS"
    summary["one_line"] = (f"{recording.id}: {len(steps)} steps, {distance:.1f} m in {summary['duration_s']:.1f} s "
                           f"({solver['method']}, {gnss_part}) -> {out}")
    provenance = {
        "pdr_version": __version__,
        "recording": {"id": recording.id, "placement": recording.placement, "geo_origin": list(origin) if origin else None},
        "inputs": input_hashes(rec),
        "config_file_sha256": sha256_file(Path(config_path)) if config_path is not None else None,
        "model_file_sha256": sha256_file(Path(model_path)) if model_path is not None else None,
        "options": {"use_gnss": use_gnss, "plot": plot},
        "config": {"input": config, "steps": make_detector(config.get("steps"), recording.placement).get_params(),
                   "heading": AttitudeStepHeading.from_config(config.get("heading")).get_params(),
                   "gnss": settings, "step_length": step_model,
                   "trajectory": {k: v for k, v in solver.items() if k not in ("iterations", "final_error", "time_s")}},
    }

    with atomic_dir(out, force=True) as tmp:
        write_steps_csv(tmp / "steps.csv", steps)
        if strides is not None:
            write_strides_csv(tmp / "strides.csv", strides)
        write_trajectory_csv(tmp / "trajectory.csv", traj, origin)
        write_geojson(tmp / "trajectory.geojson", traj, origin, name=recording.id)
        write_tum(tmp / "trajectory.tum", traj)
        if origin is not None:
            write_gpx(tmp / "trajectory.gpx", traj, origin, name=recording.id)
        if plot:
            plot_gnss = None
            if gnss is not None:
                plot_gnss = gnss[["t_s", "e_m", "n_m", "masked"]].assign(used=gnss_used)
            write_plot(tmp / "trajectory.png", traj, gnss=plot_gnss,
                       title=f"{recording.id}: {len(steps)} steps, {distance:.1f} m ({solver['method']})")
        write_json(tmp / "run.json", provenance)
        lap("write_s")
        summary["timings_s"] = {**timings, "total_s": sum(timings.values())}
        write_json(tmp / "summary.json", summary)
    for message in run_warnings:
        warnings.warn(message, stacklevel=2)
    return summary
