"""``pdr gait-camera simulate / fit / estimate / evaluate``: the wearable thigh-camera gait estimator (Watanabe et
al. 2011) from files.

A thigh-camera folder (what ``estimate`` reads, what ``simulate`` writes):

- ``camera.toml``: ``[camera] fps, focal_px, cx_px, cy_px, width_px, height_px``; ``[mount] side, along_thigh_m,
  outward_m, tilt_out_deg`` (:class:`pdr.gait.camera_estimator.ThighCameraModel`); ``[start] e_m, n_m,
  heading_rad`` (the start pose on the board, heading counter-clockwise from east).
- ``frames.csv``: ``t_s`` per frame; ``observations.csv``: ``frame`` (0-based row of frames.csv), ``point_id``,
  ``u_px``, ``v_px`` (the detected chessboard corners); ``points.csv``: ``point_id, e_m, n_m, u_m`` (the corners'
  world coordinates).
- ``reference/`` (simulated truth, read only by ``evaluate``): ``mocap.csv`` per frame (the motion-capture columns
  :data:`pdr.gait.camera_estimator.MOCAP_COLUMNS`), ``cycles.csv`` (``t_start_s, t_end_s, form``),
  ``segments.csv`` (``form, t_start_s, t_end_s, speed_mps``).

``fit`` learns the per-form templates and the transition diagram from motion-capture tables (``MOCAP_COLUMNS``, one
walk per file: e.g. the ``reference/mocap.csv`` of simulated training walks) -> ``templates.json``. ``estimate``
writes ``states.csv``, ``joints.csv``, ``cycles.csv`` and ``summary.json`` into a new output folder.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pdr.errors import InputError, check_keys
from pdr.gait.camera_estimator import MOCAP_COLUMNS, FourierFormTemplates, ThighCameraModel, WearableCameraGaitEstimation
from pdr.io.atomic import atomic_dir, write_csv, write_text
from pdr.io.recording import read_csv
from pdr.io.tomlio import dumps_toml, read_json, read_toml

TEMPLATES_FORMAT = "pdr-gait-camera-templates"
MOUNT_KEYS = ("side", "along_thigh_m", "outward_m", "tilt_out_deg")
CAMERA_KEYS = ("fps", "focal_px", "cx_px", "cy_px", "width_px", "height_px")
START_KEYS = ("e_m", "n_m", "heading_rad")


# ----------------------------------------------------------------------------------------------------------------
# The folder
# ----------------------------------------------------------------------------------------------------------------
def _section(doc: dict, name: str, keys: tuple[str, ...], what: str, required: bool) -> dict[str, Any]:
    sec = doc.get(name) or {}
    if not isinstance(sec, dict):
        raise InputError(f"{what}: expected a [{name}] table, found {type(sec).__name__}")
    check_keys(sec, keys, f"{what} [{name}]")
    missing = [k for k in keys if k not in sec] if required else []
    if missing:
        raise InputError(f"{what} [{name}]: expected {', '.join(missing)}, found none")
    return dict(sec)


def read_thigh_camera(folder: Path) -> tuple[ThighCameraModel, dict[str, float], pd.DataFrame, pd.DataFrame, pd.DataFrame]:
    """The camera, the start pose and the frames, observations and ground points of a thigh-camera folder."""
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(f"{folder}: expected a thigh-camera folder, found nothing there")
    what = f"{folder}/camera.toml"
    doc = read_toml(folder / "camera.toml", what=what)
    cam = _section(doc, "camera", CAMERA_KEYS, what, required=True) | _section(doc, "mount", MOUNT_KEYS, what, required=False)
    start = _section(doc, "start", START_KEYS, what, required=True)
    bad = [k for k, v in (cam | start).items() if k != "side" and (isinstance(v, bool) or not isinstance(v, (int, float)))]
    if bad:
        raise InputError(f"{what}: expected numbers for {', '.join(bad)}, found {', '.join(repr((cam | start)[k]) for k in bad)}")
    camera = ThighCameraModel(**cam)
    start = {k: float(v) for k, v in start.items()}
    frames = read_csv(folder / "frames.csv", f"{folder}/frames.csv")
    observations = read_csv(folder / "observations.csv", f"{folder}/observations.csv")
    points = read_csv(folder / "points.csv", f"{folder}/points.csv")
    return camera, start, frames, observations, points


def write_thigh_camera(folder: Path, sim, *, force: bool = False) -> Path:
    """Write a simulated :class:`pdr.sim.thigh_camera.ThighCameraWalk` as a thigh-camera folder with its
    ``reference/``; return the folder."""
    tr = sim.truth
    start = {"e_m": float(tr.e_m.iloc[0]), "n_m": float(tr.n_m.iloc[0]), "heading_rad": float(tr.heading_rad.iloc[0])}
    cam = sim.camera.to_dict()
    with atomic_dir(folder, force=force) as tmp:
        write_text(tmp / "camera.toml", dumps_toml({"camera": {k: cam[k] for k in CAMERA_KEYS},
                                                    "mount": {k: cam[k] for k in MOUNT_KEYS}, "start": start}))
        write_csv(tmp / "frames.csv", sim.frames)
        write_csv(tmp / "observations.csv", sim.observations[["frame", "point_id", "u_px", "v_px"]])
        write_csv(tmp / "points.csv", sim.points)
        write_csv(tmp / "reference" / "mocap.csv", tr[MOCAP_COLUMNS])
        write_csv(tmp / "reference" / "cycles.csv", sim.cycles)
        write_csv(tmp / "reference" / "segments.csv", sim.segments)
    return Path(folder)


# ----------------------------------------------------------------------------------------------------------------
# Commands
# ----------------------------------------------------------------------------------------------------------------
def simulate_thigh_camera_to_disk(config_path: Path, out: Path, *, seed: int = 0, force: bool = False) -> Path:
    """``pdr gait-camera simulate CONFIG -o DIR``: a simulated walk of labelled forms seen by a thigh camera over a
    chessboard floor (:mod:`pdr.sim.thigh_camera`). CONFIG: ``[subject] seed, height_m``; ``[[segment]] form,
    duration_s, speed_mps``; optional ``[camera]`` / ``[mount]`` as in ``camera.toml``. ``seed`` draws the steps
    and the detections (the subject's gait is ``[subject] seed``)."""
    from pdr.sim.thigh_camera import form_walk, simulate_thigh_camera

    what = str(config_path)
    doc = read_toml(config_path, what=what)
    check_keys(doc, ("subject", "segment", "camera", "mount", "simulation"), what, what="table")
    subject = _section(doc, "subject", ("seed", "height_m"), what, required=False)
    segments = doc.get("segment") or []
    if not isinstance(segments, list) or not segments:
        raise InputError(f"{what}: expected [[segment]] tables with form, duration_s, speed_mps, found none")
    try:
        plan = [(str(s["form"]), float(s["duration_s"]), float(s["speed_mps"])) for s in segments]
        camera = ThighCameraModel(**(_section(doc, "camera", CAMERA_KEYS, what, required=False)
                                     | _section(doc, "mount", MOUNT_KEYS, what, required=False)))
        walk = form_walk(plan, subject_seed=int(subject.get("seed", 0)), walk_seed=seed,
                         height_m=float(subject.get("height_m", 1.75)))
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"{what}: expected [[segment]] form, duration_s, speed_mps and numeric settings, found "
                         f"otherwise ({exc})") from None
    return write_thigh_camera(out, simulate_thigh_camera(walk, camera, seed=seed), force=force)


def fit_templates(mocap_paths: list[Path], out: Path) -> Path:
    """``pdr gait-camera fit MOCAP [MOCAP ...] -o templates.json``: per-form templates and transition diagram from
    motion-capture tables (one walk per file)."""
    if not mocap_paths:
        raise InputError("gait-camera fit: expected at least one motion-capture table, found none")
    tables = [read_csv(Path(p)).assign(walk=i) for i, p in enumerate(mocap_paths)]
    templates = FourierFormTemplates().fit(pd.concat(tables, ignore_index=True))
    doc = {"format": TEMPLATES_FORMAT, "sources": [str(p) for p in mocap_paths], "n_cycles": templates.n_cycles_,
           **templates.to_dict()}
    write_text(out, json.dumps(doc, indent=1, allow_nan=False) + "\n")
    return Path(out)


def load_templates(path: Path) -> FourierFormTemplates:
    doc = read_json(path, what=str(path), missing="expected a templates file (pdr gait-camera fit), found none")
    if not isinstance(doc, dict) or doc.get("format") != TEMPLATES_FORMAT:
        found = doc.get("format") if isinstance(doc, dict) else type(doc).__name__
        raise InputError(f"{path}: expected a {TEMPLATES_FORMAT} file (pdr gait-camera fit), found {found!r}")
    try:
        return FourierFormTemplates.from_dict(doc)
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"{path}: expected complete templates, found a damaged file ({exc})") from None


def _finite_or_none(x) -> float | None:
    return float(x) if np.isfinite(x) else None


def estimate_gait(folder: Path, templates_path: Path, out: Path, *, force: bool = False) -> str:
    """``pdr gait-camera estimate DIR --templates F -o OUT``: walking state, form and joint positions per frame.
    Returns the one-line summary."""
    templates = load_templates(templates_path)
    camera, start, frames, observations, points = read_thigh_camera(folder)
    est = WearableCameraGaitEstimation(templates=templates, camera=camera)
    est.estimate(frames, observations, points, initial_e_m=start["e_m"], initial_n_m=start["n_m"],
                 initial_heading_rad=start["heading_rad"])
    st = est.states_
    forms = st["form"][st["form"].astype(bool)]
    summary = {"n_frames": int(len(st)), "n_cycles": int(len(est.cycles_)),
               "form_frames": {str(k): int(v) for k, v in forms.value_counts().sort_index().items()},
               "n_predicted_only": int(est.n_predicted_only_), "n_relocalised": int(est.n_relocalised_),
               "median_reprojection_error_px": _finite_or_none(st.get("reprojection_error_px", pd.Series(dtype=float)).median()),
               "time_s": round(float(est.time_s_), 3), "forms": templates.forms_}
    with atomic_dir(out, force=force) as tmp:
        write_csv(tmp / "states.csv", st)
        write_csv(tmp / "joints.csv", est.joints_)
        write_csv(tmp / "cycles.csv", est.cycles_)
        write_text(tmp / "summary.json", json.dumps(summary, indent=1, allow_nan=False) + "\n")
    speed = len(st) / max(est.time_s_, 1e-9)
    return (f"{Path(folder).name}: {len(st)} frames, {len(est.cycles_)} gait cycles, forms "
            f"{', '.join(f'{k} {v}' for k, v in summary['form_frames'].items()) or 'none'} (frames), "
            f"{speed:.0f} frames/s -> {out}")


def evaluate_gait(out: Path, folder: Path) -> dict[str, float]:
    """``pdr gait-camera evaluate OUT DIR``: metrics of an estimate against the folder's ``reference/``."""
    from pdr.eval.gait_camera import score_gait_camera

    ref = Path(folder) / "reference"
    truth = read_csv(ref / "mocap.csv", f"{ref}/mocap.csv")
    true_cycles = read_csv(ref / "cycles.csv", f"{ref}/cycles.csv")
    segments = read_csv(ref / "segments.csv", f"{ref}/segments.csv")
    states = read_csv(Path(out) / "states.csv")
    joints = read_csv(Path(out) / "joints.csv")
    cycles = read_csv(Path(out) / "cycles.csv")
    return score_gait_camera(truth, true_cycles, segments, states, joints, cycles)
