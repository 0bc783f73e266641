"""``pdr evaluate OUT REC``: metrics of a ``pdr run`` output against the recording's ``reference/``.

Metrics whose reference is absent are omitted (never reported as zero). Every position metric states its alignment:
``"none"`` when the run used GNSS fixes (its frame is absolute), else ``"origin+heading"``: the estimate is moved so that
it passes through the first reference point at that point's time, then rotated about it to best fit the other
reference points (trajectory if the reference has one, else landmarks). A reference point used as the anchor has zero
error by construction and is left out of the landmark statistics.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pdr.errors import InputError
from pdr.eval.metrics import (
    event_f1,
    fit_rotation_about,
    interpolate_positions,
    match_events,
    path_length_m,
    position_errors_m,
    rmse_m,
    rotate_about,
)
from pdr.io.recording import check_time, load_recording, read_csv
from pdr.io.tomlio import read_json
from pdr.schema import require_table

STEP_F1_TOLERANCE_S = 0.25
SIGNIFICANT_DIGITS = 7  # metrics are printed to 7 significant digits (far beyond their accuracy)
STRIDE_MATCH_MIN_OVERLAP = 0.5  # share of the longer stride covered by both


def _read_out_table(out: Path, name: str, columns: tuple[str, ...]) -> pd.DataFrame:
    df = read_csv(out / name, f"{out / name}")
    require_table(df, columns, f"{out / name}")
    for c in columns:
        if not pd.api.types.is_numeric_dtype(df[c]) and c not in ("foot", "source"):
            raise InputError(f"{out / name}: expected numbers in column {c}, found text")
    return df


def _read_summary(out: Path) -> dict[str, Any]:
    summary = read_json(out / "summary.json", what=str(out), missing="expected a pdr run output folder with summary.json, found none")
    if not isinstance(summary, dict):
        raise InputError(f"{out}/summary.json: expected a JSON object, found {type(summary).__name__}")
    return summary


def _step_metrics(est_steps: pd.DataFrame, ref: dict[str, Any], tolerance_s: float) -> dict[str, Any]:
    m: dict[str, Any] = {}
    n_est = len(est_steps)
    ref_steps = ref.get("steps")
    # summary.n_steps first: a reference may count contacts whose time it does not know (no row in steps.csv)
    n_ref = ref.get("summary", {}).get("n_steps", len(ref_steps) if ref_steps is not None else None)
    if n_ref is not None:
        n_ref = int(n_ref)
        m["n_steps_ref"] = n_ref
        m["step_count_error"] = n_est - n_ref
        if n_ref > 0:
            m["step_count_error_pct"] = 100.0 * (n_est - n_ref) / n_ref
    if ref_steps is not None:
        t_ref = ref_steps["t_s"].to_numpy(float)
        t_est = est_steps["t_s"].to_numpy(float)
        check_time(t_ref, "reference/steps.csv", min_rows=0)
        scores = event_f1(t_ref, t_est, tolerance_s)
        m.update(step_f1=scores["f1"], step_precision=scores["precision"], step_recall=scores["recall"],
                 step_f1_tolerance_s=tolerance_s, n_steps_matched=scores["n_matched"])
        if "step_length_m" in ref_steps.columns and "step_length_m" in est_steps.columns:
            i_ref, i_est = match_events(t_ref, t_est, tolerance_s)
            lr = ref_steps["step_length_m"].to_numpy(float)[i_ref]
            le = est_steps["step_length_m"].to_numpy(float)[i_est]
            ok = np.isfinite(lr) & np.isfinite(le)
            if ok.any():
                m["step_length_mae_m"] = float(np.mean(np.abs(le[ok] - lr[ok])))
                m["n_step_lengths_compared"] = int(ok.sum())
    return m


def _match_intervals(ref: pd.DataFrame, est: pd.DataFrame, min_overlap: float) -> tuple[np.ndarray, np.ndarray]:
    """One-to-one matches of estimated to reference intervals, largest overlap first; the overlap, as a fraction of
    the longer of the two, must reach ``min_overlap``. Stride sources cut strides at different gait events (a foot
    INS at mid-stance, a reference at heel strike), so boundaries are not compared, only the share of time covered."""
    rs, re_ = ref["t_start_s"].to_numpy(float), ref["t_end_s"].to_numpy(float)
    es, ee = est["t_start_s"].to_numpy(float), est["t_end_s"].to_numpy(float)
    overlap = np.minimum(ee[:, None], re_[None, :]) - np.maximum(es[:, None], rs[None, :])
    longer = np.maximum((ee - es)[:, None], (re_ - rs)[None, :])
    share = np.where(longer > 0, overlap / np.where(longer > 0, longer, 1.0), 0.0)
    i_est, i_ref = [], []
    used_e, used_r = set(), set()
    for k in np.argsort(-share, axis=None, kind="stable"):
        e, r = divmod(int(k), share.shape[1])
        if share[e, r] < min_overlap:
            break
        if e not in used_e and r not in used_r:
            used_e.add(e)
            used_r.add(r)
            i_est.append(e)
            i_ref.append(r)
    return np.asarray(i_ref, int), np.asarray(i_est, int)


def _stride_metrics(est: pd.DataFrame | None, ref: dict[str, Any], min_overlap: float) -> dict[str, Any]:
    ref_strides = ref.get("strides")
    if est is None or ref_strides is None or not len(est) or not len(ref_strides):
        return {}
    errors = []
    for foot in sorted(set(ref_strides["foot"].astype(str)) & set(est["foot"].astype(str))):
        r = ref_strides[ref_strides["foot"].astype(str) == foot]
        e = est[est["foot"].astype(str) == foot]
        i_ref, i_est = _match_intervals(r, e, min_overlap)
        diff = e["length_m"].to_numpy(float)[i_est] - r["length_m"].to_numpy(float)[i_ref]
        errors.extend(np.abs(diff[np.isfinite(diff)]))
    m = {"n_strides_ref": len(ref_strides), "n_strides_matched": len(errors), "stride_match_min_overlap": min_overlap}
    if errors:
        m["stride_length_mae_m"] = float(np.mean(errors))
    return m


def _position_metrics(traj: pd.DataFrame, ref: dict[str, Any], gnss_used: bool, distance_ref_m: float | None) -> dict[str, Any]:
    ref_traj, landmarks = ref.get("trajectory"), ref.get("landmarks")
    fit_name = "trajectory" if ref_traj is not None and len(ref_traj) else "landmarks"
    fit_on = ref_traj if fit_name == "trajectory" else landmarks
    if fit_on is None or not len(fit_on):
        return {}
    t_est = traj["t_s"].to_numpy(float)
    xy_est = traj[["e_m", "n_m"]].to_numpy(float)

    def estimate_at(t_s: np.ndarray) -> np.ndarray:
        return interpolate_positions(t_est, xy_est, t_s)

    m: dict[str, Any] = {}
    fit_on = fit_on.sort_values("t_s")
    anchor_t = float(fit_on["t_s"].iloc[0])
    if gnss_used:
        m["alignment"] = "none"

        def align(xy: np.ndarray) -> np.ndarray:
            return xy
    else:
        m["alignment"] = "origin+heading"
        m["alignment_fit_on"] = fit_name
        anchor_ref = fit_on[["e_m", "n_m"]].to_numpy(float)[0]
        anchor_est = estimate_at(np.array([anchor_t]))[0]
        angle = fit_rotation_about(estimate_at(fit_on["t_s"].to_numpy(float)), fit_on[["e_m", "n_m"]].to_numpy(float),
                                   anchor_est, anchor_ref)
        m["alignment_rotation_rad"] = angle

        def align(xy: np.ndarray) -> np.ndarray:
            return rotate_about(xy, angle, anchor_est, anchor_ref)

    if ref_traj is not None and len(ref_traj):
        rt = ref_traj.sort_values("t_s")
        est_xy = align(estimate_at(rt["t_s"].to_numpy(float)))
        m["ate_rmse_m"] = rmse_m(est_xy, rt[["e_m", "n_m"]].to_numpy(float))
        m["n_ate_points"] = len(rt)
    end = fit_on.iloc[-1]
    final = float(position_errors_m(align(estimate_at(np.array([end["t_s"]]))), np.array([[end["e_m"], end["n_m"]]]))[0])
    m["final_error_m"] = final
    if distance_ref_m:
        m["final_error_pct"] = 100.0 * final / distance_ref_m
    if landmarks is not None and len(landmarks):
        lm = landmarks.sort_values("t_s")
        if m["alignment"] != "none" and fit_name == "landmarks":
            lm = lm.iloc[1:]  # the anchor has zero error by construction
        if len(lm):
            err = position_errors_m(align(estimate_at(lm["t_s"].to_numpy(float))), lm[["e_m", "n_m"]].to_numpy(float))
            m.update(landmark_error_mean_m=float(err.mean()), landmark_error_max_m=float(err.max()), n_landmarks=len(lm))
            if distance_ref_m:
                m["landmark_error_mean_pct"] = 100.0 * float(err.mean()) / distance_ref_m
                m["landmark_error_max_pct"] = 100.0 * float(err.max()) / distance_ref_m
    return m


def _loop_metrics(traj: pd.DataFrame, ref: dict[str, Any], distance_m: float) -> dict[str, Any]:
    """Loop closure when the reference says the walk is closed (``summary.toml`` ``loop_closure = true``): the final
    displacement from the start (m) and as % of the estimated path (a closed walk's truth is 0 m whatever its length,
    so no reference distance is needed)."""
    if ref.get("summary", {}).get("loop_closure") is not True or len(traj) < 2:
        return {}
    xy = traj[["e_m", "n_m"]].to_numpy(float)
    closure = float(np.hypot(*(xy[-1] - xy[0])))
    m = {"loop_closure_m": closure}
    if distance_m > 0:
        m["loop_closure_pct"] = 100.0 * closure / distance_m
    return m


def evaluate_run(out: Path, rec: Path, *, step_tolerance_s: float = STEP_F1_TOLERANCE_S) -> dict[str, Any]:
    """Metrics of the ``pdr run`` output folder ``out`` against ``rec/reference/`` (see the module docstring).

    Keys (each present only when its reference exists): ``n_steps``, ``n_steps_ref``, ``step_count_error`` (estimated
    minus reference), ``step_count_error_pct`` (signed like it, % of reference: negative = steps missed), ``step_f1`` / ``step_precision`` /
    ``step_recall`` with ``step_f1_tolerance_s``, ``step_length_mae_m``, ``stride_length_mae_m``, ``distance_m``,
    ``distance_ref_m``, ``distance_error_pct`` (signed), ``ate_rmse_m`` with ``alignment``, ``final_error_m`` /
    ``final_error_pct`` (% of the reference distance), ``landmark_error_mean_m`` / ``_max_m`` / ``_mean_pct`` / ``_max_pct``,
    ``loop_closure_m`` / ``loop_closure_pct`` (a closed walk: :func:`_loop_metrics`).
    """
    out, rec = Path(out), Path(rec)
    if not out.is_dir():
        raise InputError(f"{out}: expected a pdr run output folder, found {'a file' if out.exists() else 'nothing'}")
    summary = _read_summary(out)
    recording = load_recording(rec, with_reference=True)
    ref = recording.reference
    if not ref:
        raise InputError(f"{rec}: expected a reference/ folder with ground truth to evaluate against, found none")
    traj = _read_out_table(out, "trajectory.csv", ("t_s", "e_m", "n_m"))
    check_time(traj["t_s"].to_numpy(float), f"{out / 'trajectory.csv'}")
    steps = _read_out_table(out, "steps.csv", ("t_s",))
    check_time(steps["t_s"].to_numpy(float), f"{out / 'steps.csv'}", min_rows=0)
    strides = _read_out_table(out, "strides.csv", ("t_start_s", "t_end_s", "foot", "length_m")) if (out / "strides.csv").is_file() else None

    metrics: dict[str, Any] = {"recording_id": recording.id, "n_steps": len(steps)}
    metrics.update(_step_metrics(steps, ref, step_tolerance_s))
    metrics.update(_stride_metrics(strides, ref, STRIDE_MATCH_MIN_OVERLAP))

    distance_m = path_length_m(traj[["e_m", "n_m"]].to_numpy(float))
    metrics["distance_m"] = distance_m
    distance_ref = ref.get("summary", {}).get("distance_m")
    if distance_ref is None and ref.get("trajectory") is not None and len(ref["trajectory"]) > 1:
        distance_ref = path_length_m(ref["trajectory"].sort_values("t_s")[["e_m", "n_m"]].to_numpy(float))
    if distance_ref is not None and float(distance_ref) > 0:
        distance_ref = float(distance_ref)
        metrics["distance_ref_m"] = distance_ref
        metrics["distance_error_pct"] = 100.0 * (distance_m - distance_ref) / distance_ref
    else:
        distance_ref = None
    gnss_used = int(summary.get("gnss", {}).get("used", 0) or 0) > 0
    metrics.update(_position_metrics(traj, ref, gnss_used, distance_ref))
    metrics.update(_loop_metrics(traj, ref, distance_m))
    return {k: float(f"{v:.{SIGNIFICANT_DIGITS}g}") if isinstance(v, float) else v for k, v in metrics.items()}
