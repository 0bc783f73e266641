"""The full reconstruction of one recording as one algorithm object, :class:`Pipeline` (what ``pdr run`` runs).

Stages: GNSS in the local frame (``[gnss] mask_intervals_s``) -> steps (``[steps]``, ``[heading]``; stretches not walked
dropped) -> step lengths (``--model`` or ``[step_length]``, else the body model of the recording; ``[gait_forms]``) ->
strides (foot IMUs ``[foot]``, leg camera ``[leg_camera]``, ``[flow]`` and ``[homography]`` / ``[odometry]`` or
``[slip_of]``) -> faults (``[faults]``) -> fusion (``[fusion] method = "graph" | "incremental" | "ekf"`` plus that
class's parameters; default the batch factor graph) -> walking bouts.

Example
-------
>>> import pdr
>>> res = pdr.Pipeline.from_config("run.toml").run(pdr.load_recording("rec"))  # doctest: +SKIP
>>> res.trajectory_, res.steps_, res.summary_["distance_m"]  # doctest: +SKIP
"""

from __future__ import annotations

import copy
import time
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pdr.base import Algorithm
from pdr.config import load_config
from pdr.errors import InputError, check_keys, collect_warnings, warn
from pdr.fusion import EkfFusion, FactorGraphFusion, IncrementalFusion
from pdr.geo import latlon_to_en
from pdr.heading import AttitudeStepHeading
from pdr.io.recording import Recording
from pdr.pipelines.bouts import recording_bouts
from pdr.pipelines.faults import rejected_gnss, sensor_faults, warning_line, warning_objects, widen_steps
from pdr.pipelines.foot import FOOT_SOURCE, foot_chain, foot_strides
from pdr.pipelines.gait_forms import GAIT_FORMS_KEYS, per_form_step_lengths
from pdr.pipelines.leg_camera import CALIBRATED_PARAMS, camera_sections, camera_strides
from pdr.pipelines.not_walking import drop_not_walking, gnss_only_trajectory, interval_message, not_walking_intervals
from pdr.pipelines.steps import DETECTORS, make_detector, steps_table
from pdr.signals import ImuSignals
from pdr.signals.faults import SensorFaultDetection
from pdr.step_length import choose_model, leg_camera_calibration
from pdr.step_length.body import body_model
from pdr.step_length.io import model_from_dict, model_to_dict
from pdr.step_length.models import MAX_STEP_M, StepLengthModel

STEP_SOURCE = "accelerometer"
GNSS_KEYS = ("mask_intervals_s",)
FUSION_METHODS = {"graph": FactorGraphFusion, "incremental": IncrementalFusion, "ekf": EkfFusion}
MODEL_DOC_KEYS = ("pdr_model_version", "model", "params")  # a step model as data: what ``pdr calibrate`` writes


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
# A stage parameter: the algorithm, or its configuration section (JSON data)
# ----------------------------------------------------------------------------------------------------------------


def _method_of(algorithm: Algorithm, methods: dict[str, type]) -> str:
    return next(name for name, cls in methods.items() if type(algorithm) is cls)


def _section(value: Any, methods: dict[str, type] | None = None, key: str = "method") -> Any:
    """A stage parameter as JSON data: an algorithm becomes its parameters (with its ``method`` when the stage has
    several); a section (a dict) or None stays as it is."""
    if isinstance(value, StepLengthModel):
        doc = model_to_dict(value)
        return {k: doc[k] for k in MODEL_DOC_KEYS}
    if isinstance(value, Algorithm):
        params = copy.deepcopy(value.get_params())
        return {key: _method_of(value, methods), **params} if methods else params
    return copy.deepcopy(value)


def _built(value: Any, build) -> Any:
    """A fresh algorithm of a stage: a copy of the one given, or built from the section (``build(section)``)."""
    return copy.deepcopy(value) if isinstance(value, Algorithm) else build(value)


class Pipeline(Algorithm):
    """Steps, step lengths, strides, faults, fusion and walking bouts of one recording (see the module docstring).

    Every stage parameter is the stage's algorithm or its configuration section (a dict, as in the TOML file);
    :meth:`get_params` gives every stage as its section, so it is JSON data and ``Pipeline(**p.get_params())`` rebuilds
    ``p``. :meth:`run` works on copies of the stages: it never changes the parameters.

    Parameters
    ----------
    steps : a step detector or the ``[steps]`` section (``method = "wavelet" | "peak"`` and its parameters); a section's
        wavelet detector does not check strides for a trunk placement unless the section says so (built per recording).
    heading : :class:`pdr.heading.AttitudeStepHeading` or the ``[heading]`` section.
    step_length : a step-length model, or its document (``pdr_model_version, model, params``: what ``pdr calibrate``
        writes), or None: the model of each recording's body and placement (:func:`pdr.step_length.body.body_model`).
    step_length_choice : ``{"source", "reason"}`` of a given ``step_length`` (``summary_["step_model"]["choice"]``).
    gait_forms : the ``[gait_forms]`` section (``forms`` = a forms.json path; its forms' step models replace the
        lengths of their steps) or None.
    foot : the ``[foot]`` section (shoe IMUs; built per foot, see :mod:`pdr.pipelines.foot`).
    leg_camera : ``{"leg_camera": [leg_camera], "flow": [flow], "homography": [homography], METHOD: [METHOD]}`` sections
        (METHOD the ``[leg_camera] method``, "odometry" or "slip_of"; defaults from the camera and the subject).
    faults : :class:`pdr.signals.faults.SensorFaultDetection` or the ``[faults]`` section.
    fusion : a fusion (:class:`FactorGraphFusion`, :class:`IncrementalFusion`, :class:`EkfFusion`) or the ``[fusion]``
        section (``method = "graph" | "incremental" | "ekf"`` and its parameters).
    gnss : the ``[gnss]`` section (``mask_intervals_s``).
    use_gnss : False: the recording's GNSS is not used (``pdr run --no-gnss``).

    Attributes
    ----------
    trajectory_ : ``t_s, e_m, n_m, heading_rad, e_std_m, n_std_m`` (the start, then one row per step or stride).
    steps_ : the steps table (``step_id, t_s, ..., step_length_m`` fused, ``heading_rad`` fused, ``source``).
    strides_ : the strides of the foot IMUs and the leg camera, None without a stride source.
    bouts_, bout_steps_ : the walking bouts and their steps' mechanics (:mod:`pdr.pipelines.bouts`).
    gnss_ : the fixes in the local frame (``t_s, e_m, n_m, h_acc_m, masked``), None without GNSS; ``gnss_used_`` the
        fixes the trajectory follows.
    summary_ : what ``summary.json`` holds, without ``one_line`` and ``timings_s``; ``timings_s_`` the stages' times.
    config_ : the configuration of the stages as they ran (``run.json`` ``config``).
    warnings_ : the warnings of the run, one line each (the faults first, then the others in order).
    """

    def __init__(self, *, steps: Any = None, heading: Any = None, step_length: Any = None,
                 step_length_choice: dict[str, str] | None = None, gait_forms: dict[str, Any] | None = None,
                 foot: dict[str, Any] | None = None, leg_camera: dict[str, Any] | None = None, faults: Any = None,
                 fusion: Any = None, gnss: dict[str, Any] | None = None, use_gnss: bool = True):
        self.steps = steps
        self.heading = heading
        self.step_length = step_length
        self.step_length_choice = step_length_choice
        self.gait_forms = gait_forms
        self.foot = foot
        self.leg_camera = leg_camera
        self.faults = faults
        self.fusion = fusion
        self.gnss = gnss
        self.use_gnss = use_gnss

    @classmethod
    def from_config(cls, config: str | Path | dict[str, Any] | None = None, *, model_path: str | Path | None = None,
                    use_gnss: bool = True, config_dir: str | Path | None = None) -> "Pipeline":
        """The pipeline of a configuration (a TOML file, its sections as a dict, or None for the defaults) and a step
        model file (``pdr run --model``; its leg-camera length scale, if any, goes to the ``[leg_camera] method``'s
        section unless that section sets one, or, calibrated for the other method, is not applied, with a warning).
        A relative ``[gait_forms] forms`` path is relative to ``config_dir`` (default: the configuration file's
        folder)."""
        base_dir = Path(config_dir) if config_dir is not None else None
        if config is None or isinstance(config, (str, Path)):
            base_dir = Path(config).parent if config is not None and base_dir is None else base_dir
            config = load_config(config)
        if not isinstance(config, dict):
            raise InputError(f"configuration: expected a dict of sections, found {type(config).__name__}")
        settings = gnss_settings(config)
        _, fusion = make_fusion(config.get("fusion"))
        model, choice = None, None
        if model_path is not None or (config.get("step_length") or {}):
            model, choice = choose_model(config, None, "unknown", model_path)
            choice = {"source": choice["source"], "reason": choice["reason"]}
        steps = dict(config.get("steps") or {})
        make_detector(steps)  # a wrong [steps] section is an error before any recording is read
        forms = None
        if config.get("gait_forms") is not None:
            forms = dict(config["gait_forms"])
            check_keys(forms, sorted(GAIT_FORMS_KEYS), "configuration [gait_forms]")
            for key in ("forms", "forms_file"):
                if base_dir is not None and isinstance(forms.get(key), str) and not Path(forms[key]).is_absolute():
                    forms[key] = str(base_dir / forms[key])
        method, camera = camera_sections(config)
        calibration = leg_camera_calibration(model_path) if model_path is not None else None
        if calibration is not None and "length_scale" not in camera[method]:  # the configuration's own scale wins
            if calibration["method"] == method:
                camera[method].update({k: calibration[k] for k in CALIBRATED_PARAMS[method] if k in calibration})
            else:
                warn(f"model file {model_path}: its leg-camera scale was calibrated for the {calibration['method']!r} "
                     f"strides, this run's [leg_camera] method is {method!r}: the scale is not applied")
        return cls(steps=steps, heading=AttitudeStepHeading.from_config(config.get("heading")), step_length=model,
                   step_length_choice=choice, gait_forms=forms, foot=dict(config.get("foot", {})),
                   leg_camera=camera,
                   faults=SensorFaultDetection.from_config(config.get("faults")), fusion=fusion, gnss=settings,
                   use_gnss=use_gnss)

    @classmethod
    def from_json(cls, params: dict[str, Any]) -> "Pipeline":
        """The pipeline of :meth:`params_to_json` data (its parameters are JSON data already)."""
        return cls().set_params(**params)

    def get_params(self) -> dict[str, Any]:
        """The parameters as JSON data: every stage as its configuration section (see the class docstring)."""
        params = super().get_params()
        params["steps"] = _section(self.steps, DETECTORS)
        params["fusion"] = _section(self.fusion, FUSION_METHODS)
        for name in ("heading", "step_length", "step_length_choice", "gait_forms", "foot", "leg_camera", "faults",
                     "gnss"):
            params[name] = _section(params[name])
        return params

    def _step_model(self, rec: Recording) -> tuple[StepLengthModel, dict[str, Any]]:
        if self.step_length is None:
            return body_model(rec.subject, rec.placement)
        model = _built(self.step_length, lambda doc: model_from_dict(doc, "pipeline step_length"))
        choice = self.step_length_choice or {"source": "pipeline", "reason": "the step model given to the pipeline"}
        return model, {"model": model.name, **choice}

    def run(self, recording: Recording, *, earlier_warnings: list[str] | tuple[str, ...] = ()) -> "Pipeline":
        """Reconstruct the trajectory of ``recording``; returns ``self`` with the results set.

        ``earlier_warnings``: warnings already reported about this recording (its loading), listed first in
        ``summary_`` and ``warnings_``. The run's warnings are shown once at its end (``warnings_``).
        """
        if not isinstance(recording, Recording):
            raise InputError(f"pipeline: expected a recording (pdr.load_recording), found {type(recording).__name__}")
        rec = recording
        timings: dict[str, float] = {}
        clock = time.perf_counter()

        def lap(stage: str) -> None:
            nonlocal clock
            now = time.perf_counter()
            timings[stage] = now - clock
            clock = now

        with collect_warnings() as caught:
            settings = gnss_settings({"gnss": self.gnss or {}})
            fusion = _built(self.fusion, lambda section: make_fusion(section)[1])
            method = _method_of(fusion, FUSION_METHODS)
            detector = _built(self.steps, lambda section: make_detector(section, rec.placement))
            heading = _built(self.heading, AttitudeStepHeading.from_config)
            model, model_choice = self._step_model(rec)
            model_given = {"model": type(model).__name__, "params": copy.deepcopy(model.get_params())}
            lap("load_s")

            gnss = gnss_local(rec, settings) if self.use_gnss else None
            lap("gnss_s")

            signals = ImuSignals(rec.imu)  # resampled and its attitude estimated once, for every stage
            steps = steps_table(rec, detector, heading, signals).reset_index(drop=True)
            not_walking = not_walking_intervals(steps, gnss, rec.subject.get("height_m"))
            for iv in not_walking:
                warn(interval_message(rec.id, iv))
            steps = drop_not_walking(steps, not_walking)
            lap("steps_s")

            model.estimate(model.prepare(steps, rec, signals), subject=rec.subject)
            steps["step_length_m"] = np.asarray(model.step_length_m_, float)
            steps["step_length_std_m"] = np.asarray(model.step_length_std_m_, float)
            gait_forms_info = None
            if self.gait_forms is not None and len(steps):
                steps, gait_forms_info = per_form_step_lengths(rec, steps, self.gait_forms, signals=signals)
                if gait_forms_info["steps_per_form_model"] and hasattr(fusion, "calibrate_step_scale"):
                    # keep the forms' relative step lengths: GNSS calibrates one scale of them, not one regression
                    fusion = type(fusion)(**{**fusion.get_params(), "calibrate_step_model": False,
                                             "calibrate_step_scale": True})
            lap("step_length_s")

            stride_tables = [t for t in (foot_strides(rec, {"foot": self.foot or {}}),
                                         camera_strides(rec, self.leg_camera or {})) if t is not None]
            strides = (pd.concat(stride_tables, ignore_index=True).sort_values("t_end_s", kind="stable")
                       if stride_tables else None)
            lap("strides_s")

            faults = _built(self.faults, SensorFaultDetection.from_config)
            sensor_faults(faults, rec.imu, gnss)
            steps = widen_steps(steps, faults.faults_, float(rec.imu["t_s"].iloc[0]))
            gnss_suspect = faults.gnss_suspect_ if gnss is not None else None
            lap("faults_s")

            # with foot INS strides the graph's chain is the INS path (relative poses between mid-stances), not the steps
            chain = foot_chain(strides)
            if chain is not None and hasattr(fusion, "calibrate_step_scale"):
                # the chain is the foot INS path, not the step model's steps: GNSS calibrates one scale of it under the
                # INS's own prior (its stride source's), and the step model is left as given
                fusion = type(fusion)(**{**fusion.get_params(), "calibrate_step_model": False, "calibrate_step_scale": True,
                                         "step_scale_prior_std": fusion.source_scale_prior_std(FOOT_SOURCE)})
            fusion.fuse(steps if chain is None else chain[0],
                        gnss=fusion_gnss(gnss if gnss is None else gnss.assign(masked=gnss["masked"] | gnss_suspect)),
                        strides=strides if chain is None else chain[1], step_model=model if chain is None else None)
            traj = fusion.trajectory_.reset_index(drop=True)
            gnss_used = np.asarray(fusion.gnss_used_, bool) if gnss is not None else None
            # with a foot chain the steps keep the step model's lengths (the path is the INS's)
            if chain is None and len(steps):
                steps["step_length_m"] = clipped_lengths(np.asarray(fusion.step_length_m_, float), rec.id)
                steps["heading_rad"] = traj["heading_rad"].to_numpy(float)[1:]  # the fused east-north heading of each step
                model = fusion.step_model_ if fusion.step_model_ is not None else model
            elif chain is None:
                usable = None if gnss is None else (np.isfinite(gnss["e_m"]) & np.isfinite(gnss["n_m"]) & ~gnss["masked"]
                                                    & ~gnss_suspect).to_numpy(bool)
                traj = gnss_only_trajectory(gnss, usable) if gnss is not None else None
                if traj is None:
                    traj = start_only_trajectory(float(rec.imu["t_s"].iloc[0]))
                else:
                    gnss_used = usable
                    warn(f"{rec.id}: no steps; the trajectory follows the GNSS alone ({int(usable.sum())} fixes)")
            solver = {"fusion": method, **fusion.solver_}
            stride_scales = getattr(fusion, "stride_scales_", None) or {}  # per source; the EKF does not use strides
            lap("fusion_s")

            bouts, bout_steps = recording_bouts(rec, steps, gnss, signals)  # bouts.csv: walking bouts and their mechanics
            lap("bouts_s")

        run_warnings = [*earlier_warnings, *caught]
        rejected = (rejected_gnss(gnss, gnss_suspect, gnss_used, float(traj["t_s"].iloc[0]), float(traj["t_s"].iloc[-1]))
                    if gnss is not None else [])
        warning_list = warning_objects(faults.faults_, rejected, run_warnings)

        steps.insert(0, "step_id", np.arange(len(steps), dtype=int))
        steps["source"] = STEP_SOURCE
        distance = float(np.sum(np.hypot(np.diff(traj["e_m"]), np.diff(traj["n_m"]))))
        imu_t = rec.imu["t_s"].to_numpy(float)
        gnss_counts = None
        if gnss is not None:
            valid = np.isfinite(gnss["e_m"].to_numpy()) & np.isfinite(gnss["n_m"].to_numpy())
            gnss_counts = {"fixes": len(gnss), "valid": int(valid.sum()), "masked": int((gnss["masked"] & valid).sum()),
                           "jumped": int((gnss_suspect & ~faults.gnss_inaccurate_ & valid).sum()),
                           "inaccurate": int((faults.gnss_inaccurate_ & valid).sum()), "used": int(gnss_used.sum())}
        summary: dict[str, Any] = {
            "recording_id": rec.id,
            "distance_m": distance,
            "n_steps": len(steps),
            "n_strides": len(strides) if strides is not None else 0,
            "duration_s": float(imu_t[-1] - imu_t[0]),
            "walking_duration_s": float(steps["t_s"].iloc[-1] - steps["t_s"].iloc[0]) if len(steps) > 1 else 0.0,
            "step_model": {"model": type(model).__name__, "params": model.get_params(), "choice": model_choice},
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

        self.trajectory_, self.steps_, self.strides_ = traj, steps, strides
        self.bouts_, self.bout_steps_ = bouts, bout_steps
        self.gnss_, self.gnss_used_ = gnss, gnss_used
        self.summary_, self.timings_s_ = summary, timings
        self.config_ = {"steps": detector.get_params(), "heading": heading.get_params(), "gnss": settings,
                        "step_length": model_given, "faults": faults.get_params(),
                        "fusion": {"method": method, "params": fusion.get_params()}}
        self.warnings_ = [warning_line(w) for w in warning_list if w["kind"] != "general"] + run_warnings
        for message in self.warnings_:
            warn(message)
        return self

