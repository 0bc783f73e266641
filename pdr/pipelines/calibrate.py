"""``pdr calibrate REC [REC ...] -o model.json``: the per-user step-length model from the recordings' GNSS.

Load each recording (``reference/`` is never read), detect its steps, put its GNSS in the local east-north frame,
run :class:`pdr.calibration.AdaptiveKalmanCalibration` over all of them, and write the calibrated model with how
many steps and metres of GNSS walking it saw (atomically). Configuration sections: ``[steps]``, ``[heading]``
(step detection), ``[step_length]`` (the model to calibrate and its prior, default the regression preset),
``[calibration]`` (AdaptiveKalmanCalibration parameters), ``[gnss]`` (as ``pdr run``: ``mask_intervals_s``,
``default_h_acc_m``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pdr.calibration import AdaptiveKalmanCalibration
from pdr.config import load_config
from pdr.errors import InputError
from pdr.io.recording import load_recording
from pdr.pipelines.run import gnss_local, gnss_settings
from pdr.pipelines.steps import detect_steps
from pdr.step_length import model_from_config, save_model


def _why_no_segment(steps_list, gnss_list, akf) -> str:
    """Which gate left no GNSS segment: no valid fix, the accuracy gate, or no fix inside a walking bout."""
    n_valid = n_accurate = n_in_bout = 0
    for steps, gnss in zip(steps_list, gnss_list):
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


def calibrate_recordings(recs: list[Path], out: Path, config_path=None) -> str:
    """Calibrate the step model on ``recs`` and write it to ``out``; return a one-line summary."""
    if not recs:
        raise InputError("calibrate: expected at least one recording, found none")
    config = load_config(config_path)
    model = model_from_config(config)
    akf = AdaptiveKalmanCalibration.from_config(config.get("calibration"))
    settings = gnss_settings(config)
    recordings = [load_recording(Path(r), with_reference=False) for r in recs]
    without = [str(r.path) for r in recordings if r.gnss is None]
    if without:
        raise InputError(f"calibrate: calibration needs GNSS (gnss.csv) in every recording, found none in {', '.join(without)}")
    steps_list, gnss_list, subjects = [], [], []
    for rec in recordings:
        steps = model.prepare(detect_steps(rec, config), rec)
        gnss = gnss_local(rec, settings)
        gnss.loc[gnss["masked"], ["e_m", "n_m"]] = np.nan
        steps_list.append(steps)
        gnss_list.append(gnss.drop(columns="masked"))
        subjects.append(rec.subject)
    akf.fit(steps_list, gnss_list, model, subjects)
    segs = akf.model_segments_
    if akf.updated_ == "none":
        reasons = segs.loc[~segs["used"], "reason"].value_counts().to_dict() if len(segs) else {}
        found = ", ".join(f"{n} {why}" for why, n in reasons.items()) or _why_no_segment(steps_list, gnss_list, akf)
        raise InputError(f"calibrate: expected GNSS segments of walking (usable fixes, steps, straight path), found none "
                         f"usable in {len(recordings)} recording(s): {found}")
    save_model(akf.model_, out, n_steps=int(round(akf.n_steps_)), distance_m=round(akf.distance_m_, 2), n_segments=int(segs["used"].sum()),
               n_segments_rejected=int((~segs["used"]).sum()), updated=akf.updated_,
               recordings=[rec.id for rec in recordings], calibration=akf.get_params())
    params = ", ".join(f"{n}={getattr(akf.model_, n):.4g}" for n in akf.model_.theta_names)
    what = "all parameters" if akf.updated_ == "all" else f"{akf.updated_} only (one walking frequency)"
    return (f"calibrated {akf.model_.name} model on {len(recordings)} recording(s): {akf.n_steps_:.0f} steps, "
            f"{akf.distance_m_:.1f} m of GNSS walking in {int(segs['used'].sum())} segments, {what}: {params} -> {out}")
