"""``pdr gait-forms fit`` / ``classify``: walking forms from the Fourier features of gait cycles (Watanabe et al.).

- :func:`recording_cycles`: the gait cycles of a recording with their features. Shoe IMUs (``foot_left`` /
  ``foot_right``) give strides from their stance phases; otherwise the main IMU's steps (the step pipeline, with the
  configured step-length model for the speed) are cut into strides of two steps.
- :func:`fit_forms`: learn the forms of one or more recordings -> ``forms.json`` (data only). When the recordings
  carry reference step lengths (``reference/steps.csv``, e.g. simulated ones) a step-length model is also fitted per
  form kind (and one for all steps), which ``pdr run`` uses with a ``[gait_forms]`` configuration section.
- :func:`classify_forms`: label the cycles of a recording -> ``forms.csv`` (``t_start_s, t_end_s, form`` + ``form_id,
  kind, distance, source``).
- :func:`per_form_step_lengths`: the step lengths of a steps table from per-form models (used by ``pdr run``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pdr.config import load_config
from pdr.errors import InputError, check_keys, collect_warnings, warn
from pdr.eval.metrics import match_events
from pdr.gait.cycles import empty_cycles, foot_cycles, foot_layout, imu_cycles, imu_layout
from pdr.gait.forms import FORMS_COLUMNS, LEG_LENGTH_PER_HEIGHT, FourierGaitForms, load_forms
from pdr.io.atomic import atomic_path, write_csv
from pdr.io.recording import TRUNK_PLACEMENTS, Recording, load_recording
from pdr.pipelines.foot import foot_imus
from pdr.pipelines.steps import detect_steps
from pdr.signals import ImuSignals
from pdr.step_length.io import model_from_config, model_from_dict, model_to_dict

STEP_MATCH_TOLERANCE_S = 0.15  # a detected step and a reference contact closer than this are the same step
MIN_STEPS_PER_MODEL = 30  # fewer matched steps than this do not fit a per-form step model (3 parameters)
# default number of forms: about twice the kinds of gait each source can show (body IMU: slow / normal / fast walk,
# run, turns; shoe IMU, a few recordings: level walking, turns, stairs up and down) -- see FourierGaitForms.n_forms
BODY_N_FORMS = 10
FOOT_N_FORMS = 6
GAIT_FORMS_KEYS = {"forms", "forms_file", "n_forms", "smoothing", "cycle_speed_check", "cycle_turn_check"}
CLASSIFY_KEYS = ("smoothing", "cycle_speed_check", "cycle_turn_check")  # FourierGaitForms settings that [gait_forms] may set


def _leg_length_m(rec: Recording) -> float:
    subj = rec.subject or {}
    if subj.get("leg_length_m"):
        return float(subj["leg_length_m"])
    if subj.get("height_m"):
        return LEG_LENGTH_PER_HEIGHT * float(subj["height_m"])
    return float("nan")


def recording_cycles(rec: Recording, config: dict | None = None, *, steps: pd.DataFrame | None = None,
                     signals: ImuSignals | None = None) -> pd.DataFrame:
    """Gait cycles of ``rec`` with their Fourier features (:mod:`pdr.gait.cycles`) and a ``recording`` and a
    ``leg_length_m`` and a ``trunk_sensor`` column. ``steps``: the steps table with ``step_length_m`` when already
    computed, ``signals`` the main IMU's shared signals (``pdr run``)."""
    config = config or {}
    feet = foot_imus(rec)
    if feet:
        tables = [foot_cycles(imu, foot) for foot, imu in sorted(feet.items())]
        cycles = pd.concat([t for t in tables if len(t)] or [empty_cycles(foot_layout())], ignore_index=True)
    else:
        signals = signals or ImuSignals(rec.imu)
        if steps is None:
            steps = detect_steps(rec, config)
            if len(steps):
                model = model_from_config(config)
                model.estimate(model.prepare(steps, rec, signals), subject=rec.subject)
                steps = steps.assign(step_length_m=model.step_length_m_)
        if len(steps) < 3:
            warn(f"{rec.id}: fewer than three steps, no gait cycle")
            cycles = empty_cycles(imu_layout())
        else:
            cycles = imu_cycles(signals.uniform, signals.attitude, steps, what=f"{rec.id}: gait cycles")
    cycles.insert(0, "recording", rec.id)
    cycles["leg_length_m"] = _leg_length_m(rec)
    cycles["trunk_sensor"] = rec.placement in TRUNK_PLACEMENTS  # the pendulum speed needs the trunk's excursion
    return cycles.reset_index(drop=True)


def _recording_steps_lengths(rec: Recording, config: dict) -> tuple[pd.DataFrame, np.ndarray] | None:
    """Detected steps (with the model's features) and their reference lengths (NaN where unmatched), or None."""
    ref = (rec.reference or {}).get("steps")
    if ref is None or "step_length_m" not in getattr(ref, "columns", []) or foot_imus(rec):
        return None
    steps = detect_steps(rec, config)
    if len(steps) == 0:
        return None
    i_ref, i_est = match_events(ref["t_s"].to_numpy(float), steps["t_s"].to_numpy(float), STEP_MATCH_TOLERANCE_S)
    lengths = np.full(len(steps), np.nan)
    lengths[i_est] = ref["step_length_m"].to_numpy(float)[i_ref]
    return steps, lengths


def step_forms(steps: pd.DataFrame, labelled: pd.DataFrame) -> np.ndarray:
    """The form kind of each step: the kind of the classified cycle containing it (the cycle's second or third
    contact, ``t_start_s < t_s <= t_end_s``); steps outside every cycle take the kind of the nearest cycle in time,
    or None when there is no cycle."""
    t = steps["t_s"].to_numpy(float)
    kinds = np.full(len(t), None, dtype=object)
    if len(labelled) == 0 or len(t) == 0:
        return kinds
    t0 = labelled["t_start_s"].to_numpy(float)
    t1 = labelled["t_end_s"].to_numpy(float)
    mid = 0.5 * (t0 + t1)
    k = labelled["kind"].to_numpy(object)
    j = np.clip(np.searchsorted(t0, t, side="left") - 1, 0, len(t0) - 1)
    inside = (t > t0[j]) & (t <= t1[j])
    nearest = np.argmin(np.abs(t[:, None] - mid[None, :]), axis=1) if len(t) * len(mid) < 5e7 else j
    kinds[:] = np.where(inside, k[j], k[nearest])
    return kinds


def _checked(section: dict[str, Any]) -> dict[str, Any]:
    """A ``[gait_forms]`` configuration section whose keys are all known."""
    check_keys(section, sorted(GAIT_FORMS_KEYS), "configuration [gait_forms]")
    return section


def _classify_settings(forms: FourierGaitForms, section: dict[str, Any]) -> None:
    """The forms file's classification settings, unless the configuration says otherwise."""
    for key in CLASSIFY_KEYS:
        if key in section:
            setattr(forms, key, bool(section[key]))


def fit_forms(recs: list[Path], out: Path, *, config_path=None, n_forms: int | None = None) -> Path:
    """Learn the walking forms of ``recs`` and write ``out`` (JSON, atomically); return ``out``.

    Configuration: ``[gait_forms]`` ``n_forms`` (default 10 for body-worn IMUs, 6 for shoe IMUs), ``smoothing``,
    ``cycle_speed_check``, ``cycle_turn_check`` (see :class:`FourierGaitForms`; kept in the forms file);
    ``[steps]``, ``[step_length]`` as for ``pdr steps``.
    """
    if not recs:
        raise InputError("gait-forms fit: expected at least one recording, found none")
    config = load_config(config_path)
    section = _checked(dict(config.get("gait_forms") or {}))
    recordings = [load_recording(Path(r)) for r in recs]
    tables = [recording_cycles(r, config) for r in recordings]
    cycles = pd.concat([t for t in tables if len(t)] or tables[:1], ignore_index=True)
    if len(cycles) == 0:
        raise InputError(f"gait-forms fit: expected gait cycles, found none in {len(recs)} recording(s)")
    sources = set(cycles["source"].str.startswith("foot_"))
    if len(sources) > 1:
        raise InputError("gait-forms fit: expected recordings of one kind (all shoe IMUs or all body-worn IMUs), "
                         "found both")
    is_foot = sources == {True}
    k = n_forms if n_forms is not None else section.get("n_forms", FOOT_N_FORMS if is_foot else BODY_N_FORMS)
    forms = FourierGaitForms(n_forms=k, **{key: bool(section[key]) for key in CLASSIFY_KEYS if key in section}).fit(cycles)
    info: dict[str, Any] = {"recordings": [r.id for r in recordings], "n_cycles": int(len(cycles))}
    models = fit_step_models(recordings, forms, config)
    if models:
        info["step_models"] = models
    out = Path(out)
    with atomic_path(out) as tmp:
        import json

        tmp.write_text(json.dumps(forms.to_dict(**info), indent=1, allow_nan=False) + "\n", encoding="utf-8")
    return out


def fit_step_models(recordings: list[Recording], forms: FourierGaitForms, config: dict) -> dict[str, Any]:
    """Step-length models fitted to the reference step lengths: one per form kind with enough steps, and ``"all"``
    (every step; the single-model baseline). Empty when no recording has reference step lengths."""
    steps_all, lengths_all, kinds_all = [], [], []
    base = model_from_config(config)
    for rec in recordings:
        got = _recording_steps_lengths(rec, config)
        if got is None:
            continue
        steps, lengths = got
        steps = base.prepare(steps, rec)
        base.estimate(steps, subject=rec.subject)
        cyc = recording_cycles(rec, config, steps=steps.assign(step_length_m=base.step_length_m_))
        lab = forms.classify(cyc).cycles_forms_
        steps_all.append(steps)
        lengths_all.append(lengths)
        kinds_all.append(step_forms(steps, lab))
    if not steps_all:
        return {}
    steps = pd.concat(steps_all, ignore_index=True)
    lengths = np.concatenate(lengths_all)
    kinds = np.concatenate(kinds_all)
    ok = np.isfinite(lengths) & (lengths > 0)
    models = {}
    with collect_warnings():
        models["all"] = model_to_dict(model_from_config(config).fit(steps[ok], lengths[ok]), n_steps=int(ok.sum()))
        for kind in sorted({k for k in kinds if k is not None}):
            sel = ok & (kinds == kind)
            if sel.sum() >= MIN_STEPS_PER_MODEL:
                models[kind] = model_to_dict(model_from_config(config).fit(steps[sel], lengths[sel]),
                                             n_steps=int(sel.sum()))
    return models


def classify_forms(rec: Path, forms: Path, out: Path, *, config_path=None) -> Path:
    """Label the gait cycles of ``rec`` with the forms of ``forms`` and write ``out`` (CSV, atomically)."""
    config = load_config(config_path)
    model, _ = load_forms(forms)
    _classify_settings(model, _checked(dict(config.get("gait_forms") or {})))
    recording = load_recording(Path(rec), with_reference=False)
    cycles = recording_cycles(recording, config)
    if len(cycles) == 0:
        warn(f"{recording.id}: no gait cycle; empty forms table")
    table = model.classify(cycles).cycles_forms_[FORMS_COLUMNS]
    write_csv(Path(out), table)
    return Path(out)


def per_form_step_lengths(rec: Recording, steps: pd.DataFrame, section: dict[str, Any], base_dir: Path | None = None, *,
                          signals: ImuSignals | None = None) -> tuple[pd.DataFrame, dict[str, Any]]:
    """``pdr run`` with ``[gait_forms] forms = "forms.json"``: classify the cycles of ``rec`` and replace the step
    lengths (``step_length_m``, ``step_length_std_m``) of the steps in each form by that form's step model from the
    forms file (steps of a form without a model keep the configured model's). Returns the steps (with a ``form``
    column) and a summary for ``run.json``."""
    _checked(section)
    path = section.get("forms", section.get("forms_file"))
    if not isinstance(path, str):
        raise InputError(f"configuration [gait_forms]: expected forms = \"path/to/forms.json\", found {path!r}")
    path = Path(path)
    if not path.is_absolute() and base_dir is not None:
        path = base_dir / path
    forms, doc = load_forms(path)
    _classify_settings(forms, section)
    models = {k: model_from_dict(v, f"forms {path}: step model {k!r}") for k, v in (doc.get("step_models") or {}).items()
              if k != "all"}
    steps = steps.copy()
    cycles = recording_cycles(rec, steps=steps, signals=signals)
    labelled = forms.classify(cycles).cycles_forms_
    kinds = step_forms(steps, labelled)
    steps["form"] = pd.Series(kinds, dtype=object).fillna("").to_numpy()
    used = {}
    for kind, model in models.items():
        sel = kinds == kind
        if not sel.any():
            continue
        model.estimate(steps.loc[sel], subject=rec.subject)
        steps.loc[sel, "step_length_m"] = model.step_length_m_
        steps.loc[sel, "step_length_std_m"] = model.step_length_std_m_
        used[kind] = int(sel.sum())
    counts = labelled["form"].value_counts().to_dict() if len(labelled) else {}
    return steps, {"forms_file": str(path), "n_cycles": int(len(labelled)), "cycles_per_form": counts,
                   "steps_per_form_model": used}
