"""``pdr calibrate REC [REC ...] -o model.json``: the per-user step-length model from known distances.

Each recording brings its distances from one source: ``--distance-m D`` (the whole walk was D metres: a measured
corridor, a track lap), ``--landmarks CSV`` (``t_s, e_m, n_m``: surveyed points passed in turn, walked straight
between), ``--trajectory CSV`` (``t_s, e_m, n_m``: a reference path, its length over 30 s windows), else its GNSS.
The k-th ``--distance-m`` / ``--landmarks`` / ``--trajectory`` belongs to the k-th recording (give the walks of known
length first); the others use their GNSS. ``reference/`` is never read (a file given on the command line is the
user's own distance information).

Load each recording, detect its steps, take the prior of the person (``[step_length]``, else the body-based model of
the first recording's ``[subject]`` and placement, :func:`pdr.step_length.body_model`), run
:class:`pdr.calibration.AdaptiveKalmanCalibration` over all of them, and write the calibrated model with how many
steps and metres it saw (atomically). Recordings with a leg camera also calibrate its strides' length scale on the
same segments of known distance (:func:`leg_camera_scale`; the model file's ``leg_camera``, which ``pdr run
--model`` applies). Configuration sections: ``[steps]``, ``[heading]`` (step detection), ``[step_length]``,
``[calibration]`` (AdaptiveKalmanCalibration parameters), ``[gnss]`` (as ``pdr run``), ``[leg_camera]``, ``[flow]``,
``[homography]``, ``[odometry]`` and ``[slip_of]`` (the leg camera, as ``pdr run``; the method's ``length_scale`` is
what is calibrated, so it is not read).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from pdr.calibration import AdaptiveKalmanCalibration
from pdr.calibration.segments import landmark_distances, trajectory_distances
from pdr.config import load_config
from pdr.errors import InputError, warn
from pdr.io.recording import load_recording, read_csv
from pdr.pipelines.leg_camera import CALIBRATED_PARAMS, camera_sections, camera_strides
from pdr.pipelines.pipeline import gnss_local, gnss_settings
from pdr.pipelines.steps import detect_steps
from pdr.slip import calibrated_length_scale
from pdr.slip.fit import SCALE_PERSON_STD, SCALE_WALK_STD
from pdr.slip.odometry import ODOMETRY_PERSON_STD, ODOMETRY_WALK_STD
from pdr.step_length import choose_model, save_model
from pdr.step_length.io import LEG_CAMERA_SCALE_RANGE

KNOWN_DISTANCE_REL_STD = 0.01  # a walk "of known length" follows its measured line to about 1%
LANDMARK_POSITION_STD_M = 0.3  # a landmark passing: the click lags the passing by ~0.2 s at ~1.5 m/s
TRAJECTORY_POSITION_STD_M = 0.05  # a reference system (motion capture, RTK, a surveyed path)
TRAJECTORY_SEGMENT_S = 30.0
MIN_CAMERA_COVERAGE = 0.8  # a segment calibrates the camera when its strides cover 80% of the segment's steps


def _step_index(t_s: np.ndarray, step_t_s: np.ndarray) -> np.ndarray:
    """Fractional step count at times ``t_s``: step k (0-based) covers ``(k - 1, k]`` (it ends at its contact), so the
    time before the first contact is extrapolated by the first step's duration."""
    knots_t = np.concatenate([[2 * step_t_s[0] - step_t_s[1]], step_t_s])
    return np.interp(t_s, knots_t, np.arange(-1, len(step_t_s), dtype=float))


# the person's and the walk's spreads of each leg-camera stride method's scale (the calibration's prior)
SCALE_SPREADS = {"odometry": (ODOMETRY_PERSON_STD, ODOMETRY_WALK_STD), "slip_of": (SCALE_PERSON_STD, SCALE_WALK_STD)}


def leg_camera_scale(strides_list: list[pd.DataFrame | None], steps_list: list[pd.DataFrame],
                     segments: pd.DataFrame, *, method: str = "odometry") -> dict | None:
    """The leg camera's length scale from segments of known distance (the ``model_segments_`` of
    :class:`AdaptiveKalmanCalibration`: the steps the step model is fitted on).

    A camera stride adds the part of its length that falls on a segment's steps (its span in fractional steps, two
    steps per stride); a segment whose strides cover at least :data:`MIN_CAMERA_COVERAGE` of its steps counts, its
    camera metres divided by the coverage. The scale is :func:`pdr.slip.calibrated_length_scale` of those (each
    segment's distance std ``measured_std_m x n_steps``: the GNSS chord's or the known distance's; the recordings
    are the walks; the person's and the walk's spreads those of the stride ``method``, :data:`SCALE_SPREADS`).
    Returns None when no recording has camera strides; warns when no segment is covered.
    """
    known, camera, known_std, walk, n_strides = [], [], [], [], 0
    have_strides = False
    for r, (strides, steps) in enumerate(zip(strides_list, steps_list)):
        if strides is None or len(steps) < 2:
            continue
        strides = strides[np.isfinite(strides["length_m"].to_numpy(float))]
        have_strides = have_strides or len(strides) > 0
        if strides.empty:
            continue
        t_step = steps["t_s"].to_numpy(float)
        lo = _step_index(strides["t_start_s"].to_numpy(float), t_step)
        hi = _step_index(strides["t_end_s"].to_numpy(float), t_step)
        length = strides["length_m"].to_numpy(float)
        for seg in segments[(segments["rec_index"] == r) & segments["used"]].itertuples(index=False):
            if np.isfinite(seg.t_start_s) and seg.n_steps != len(t_step):
                a, b = _step_index(np.array([seg.t_start_s, seg.t_end_s]), t_step)
            else:  # the whole walk: every step, the first one's stretch before its contact too
                a, b = -1.0, len(t_step) - 1.0
            overlap = np.clip(np.minimum(hi, b) - np.maximum(lo, a), 0.0, None)
            coverage = float(overlap.sum() / (b - a))
            if coverage < MIN_CAMERA_COVERAGE:
                continue
            known.append(float(seg.distance_m))
            camera.append(float(np.sum(length * overlap / np.maximum(hi - lo, 1e-9))) / coverage)
            known_std.append(float(seg.measured_std_m * seg.n_steps))
            walk.append(r)
            n_strides += int(np.count_nonzero(overlap > 0))
    if not have_strides:
        return None
    if not known:
        warn(f"calibrate: no segment of known distance is {MIN_CAMERA_COVERAGE:.0%} covered by leg-camera strides; "
             f"the camera's length scale is not calibrated")
        return None
    ratio = sum(known) / sum(camera)
    lo_ok, hi_ok = LEG_CAMERA_SCALE_RANGE
    if not lo_ok <= ratio <= hi_ok:
        warn(f"calibrate: the leg camera's strides read {1.0 / ratio:.2f} x the known distance (outside "
             f"[{1 / hi_ok:.3g}, {1 / lo_ok:.3g}]): check camera.toml and [subject]; the camera's scale is not stored")
        return None
    person_std, walk_std = SCALE_SPREADS[method]
    scale, scale_std = calibrated_length_scale(known, camera, known_std, walk, person_std=person_std, walk_std=walk_std)
    return {"method": method, "length_scale": scale, "length_scale_std": scale_std, "measured_ratio": ratio,
            "n_walks": len(set(walk)), "n_segments": len(known), "n_strides": n_strides, "distance_m": round(sum(known), 2)}


def _why_no_segment(steps_list, gnss_list, akf) -> str:
    """Which gate left no GNSS segment: no valid fix, the accuracy gate, or no fix inside a walking bout."""
    n_valid = n_accurate = n_in_bout = 0
    for steps, gnss in zip(steps_list, gnss_list):
        if gnss is None:  # a recording calibrated by a known distance
            continue
        valid = np.isfinite(gnss["e_m"].to_numpy(float)) & np.isfinite(gnss["n_m"].to_numpy(float))
        h = gnss["h_acc_m"].to_numpy(float) if "h_acc_m" in gnss else np.full(len(gnss), np.nan)
        accurate = valid & (np.where(np.isfinite(h), h, akf.assumed_h_acc_m) <= akf.max_h_acc_m)
        t = gnss["t_s"].to_numpy(float)
        in_bout = np.zeros(len(t), bool)
        if len(steps):
            for _, b in steps.groupby("bout_id")["t_s"]:
                in_bout |= (t >= b.min()) & (t <= b.max())
        n_valid, n_accurate, n_in_bout = n_valid + int(valid.sum()), n_accurate + int(accurate.sum()), \
            n_in_bout + int((accurate & in_bout).sum())
    if n_valid == 0:
        return "no valid (unmasked) GNSS fix"
    if n_accurate == 0:
        return (f"all {n_valid} valid fixes fail the accuracy gate h_acc_m <= {akf.max_h_acc_m:g} m "
                "([calibration] max_h_acc_m)")
    if n_in_bout < 2:
        return f"{n_accurate} of {n_valid} valid fixes pass the accuracy gate but fewer than 2 lie inside a walking bout"
    return f"{n_in_bout} accurate fixes inside walking bouts, but no segment of {akf.min_segment_steps:g}+ steps between them"


def known_distances(n_recs: int, distance_m: list[float] | None = None, landmarks: list[Path] | None = None,
                    trajectory: list[Path] | None = None) -> list[tuple[str, pd.DataFrame | None]]:
    """Per recording: the source of its distances (``"distance"``, ``"landmarks"``, ``"trajectory"``, ``"gnss"``) and
    the table of known distances (None for GNSS)."""
    out: list[tuple[str, pd.DataFrame | None]] = [("gnss", None)] * n_recs
    given = {"--distance-m": distance_m or [], "--landmarks": landmarks or [], "--trajectory": trajectory or []}
    for flag, values in given.items():
        if len(values) > n_recs:
            raise InputError(f"calibrate: expected at most one {flag} per recording ({n_recs}), found {len(values)}")
        for k, value in enumerate(values):
            if out[k][0] != "gnss":
                raise InputError(f"calibrate: expected one distance source per recording, found {out[k][0]} and "
                                 f"{flag} for recording {k + 1}")
            if flag == "--distance-m":
                if not (np.isfinite(value) and value > 0):
                    raise InputError(f"calibrate: expected --distance-m > 0 (metres walked), found {value}")
                table = pd.DataFrame({"t_start_s": [np.nan], "t_end_s": [np.nan], "distance_m": [float(value)],
                                      "distance_std_m": [KNOWN_DISTANCE_REL_STD * float(value)]})
                out[k] = ("distance", table)
            elif flag == "--landmarks":
                out[k] = ("landmarks", landmark_distances(read_csv(Path(value)), LANDMARK_POSITION_STD_M))
            else:
                out[k] = ("trajectory", trajectory_distances(read_csv(Path(value)), TRAJECTORY_SEGMENT_S,
                                                             TRAJECTORY_POSITION_STD_M))
    return out


def calibrate_recordings(recs: list[Path], out: Path, config_path=None, *, distance_m: list[float] | None = None,
                         landmarks: list[Path] | None = None, trajectory: list[Path] | None = None) -> str:
    """Calibrate the step model on ``recs`` and write it to ``out``; return a one-line summary."""
    if not recs:
        raise InputError("calibrate: expected at least one recording, found none")
    config = load_config(config_path)
    akf = AdaptiveKalmanCalibration.from_config(config.get("calibration"))
    settings = gnss_settings(config)
    sources = known_distances(len(recs), distance_m, landmarks, trajectory)
    recordings = [load_recording(Path(r), with_reference=False) for r in recs]
    without = [str(r.path) for r, (kind, _) in zip(recordings, sources) if kind == "gnss" and r.gnss is None]
    if without:
        raise InputError(f"calibrate: expected GNSS (gnss.csv) or a known distance (--distance-m, --landmarks, "
                         f"--trajectory) for every recording, found neither for {', '.join(without)}")
    model, choice = choose_model(config, recordings[0].subject, recordings[0].placement)
    method, camera_config = camera_sections(config)
    camera_config[method] = {k: v for k, v in camera_config[method].items() if k not in CALIBRATED_PARAMS[method]}
    steps_list, gnss_list, subjects, strides_list = [], [], [], []
    for rec, (kind, _) in zip(recordings, sources):
        strides_list.append(camera_strides(rec, camera_config))
        steps = model.prepare(detect_steps(rec, config), rec)
        gnss = None
        if kind == "gnss":
            gnss = gnss_local(rec, settings)
            gnss.loc[gnss["masked"], ["e_m", "n_m"]] = np.nan
            gnss = gnss.drop(columns="masked")
        steps_list.append(steps)
        gnss_list.append(gnss)
        subjects.append(rec.subject)
    akf.fit(steps_list, gnss_list, model, subjects, distances=[table for _, table in sources])
    segs = akf.model_segments_
    if akf.updated_ == "none":
        reasons = segs.loc[~segs["used"], "reason"].value_counts().to_dict() if len(segs) else {}
        found = ", ".join(f"{n} {why}" for why, n in reasons.items()) or _why_no_segment(steps_list, gnss_list, akf)
        raise InputError(f"calibrate: expected segments of walking of known length (GNSS fixes, distances), found none "
                         f"usable in {len(recordings)} recording(s): {found}")
    camera = leg_camera_scale(strides_list, steps_list, segs, method=method)
    save_model(akf.model_, out, camera, n_steps=int(round(akf.n_steps_)), distance_m=round(akf.distance_m_, 2), n_segments=int(segs["used"].sum()),
               n_segments_rejected=int((~segs["used"]).sum()), updated=akf.updated_,
               recordings=[rec.id for rec in recordings], sources=[kind for kind, _ in sources], prior=choice,
               calibration=akf.get_params())
    params = ", ".join(f"{n}={getattr(akf.model_, n):.4g}" for n in akf.model_.theta_names)
    what = "all parameters" if akf.updated_ == "all" else "mainly the level (one walking frequency)"
    kinds = ", ".join(sorted({kind for kind, _ in sources}))
    camera_line = ("" if camera is None else f"; leg camera: {camera['n_strides']} strides over {camera['distance_m']:.1f} m"
                   f", known / camera {camera['measured_ratio']:.4g}, length_scale={camera['length_scale']:.4g}"
                   f" +- {camera['length_scale_std']:.2g}")
    return (f"calibrated {akf.model_.name} model on {len(recordings)} recording(s) ({kinds}): {akf.n_steps_:.0f} steps, "
            f"{akf.distance_m_:.1f} m of walking in {int(segs['used'].sum())} segments, {what}: {params}{camera_line} -> {out}")
