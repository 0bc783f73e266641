"""Per-form Fourier templates of the gait and the transition diagram between forms (Watanabe et al., WACV 2011,
Sec. 3-4), learnt from motion-capture tables of training walks."""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from pdr.base import Algorithm
from pdr.errors import InputError
from pdr.gait.camera_model import JOINTS, SIDES, TWO_PI
from pdr.gait.fourier import DEFAULT_ORDER, fourier_coefficients, fourier_derivative, fourier_design_matrix
from pdr.io.recording import numeric_frame
from pdr.schema import require_table

# Template parameters (columns of each form's coefficient matrix). rho: path advance per radian of phase.
PARAMS = ("rho_m_per_rad", "pelvis_f_m", "pelvis_l_m", "pelvis_u_m") + tuple(
    f"{side}_{p}" for side in SIDES for p in ("hip_f_m", "hip_l_m", "hip_u_m", "thigh_pitch_rad", "thigh_roll_rad", "knee_flex_rad"))
_P = {name: i for i, name in enumerate(PARAMS)}


def joint_columns(joint: str) -> list[str]:
    """The world-position columns of a joint in the motion-capture and joint tables: ``<joint>_{e,n,u}_m``."""
    return [f"{joint}_{a}_m" for a in "enu"]


MOCAP_COLUMNS = ["t_s", "e_m", "n_m", "heading_rad", "phase_rad", "phase_rate_radps", "form"] + [
    c for j in JOINTS for c in joint_columns(j)]


def _numeric(df: pd.DataFrame, columns: list[str], what: str, also: list[str] = ()) -> pd.DataFrame:
    """``df`` with ``columns`` as numbers (:func:`pdr.io.recording.numeric_frame`) and ``also`` present."""
    require_table(df, list(columns) + list(also), what)
    return df.assign(**numeric_frame(df[list(columns)], what))


def body_frame_parameters(mocap: pd.DataFrame) -> pd.DataFrame:
    """The template parameters (``PARAMS``) of every sample of a motion-capture table, plus the segment lengths
    ``thigh_m``, ``shank_m``: joints relative to the path point in the body frame, thigh pitch and roll from the
    hip->knee direction, knee flexion = thigh pitch - shank pitch in the thigh's plane, and the path advance per
    radian of phase (forward path speed / phase rate)."""
    psi = mocap["heading_rad"].to_numpy(float)
    c, s = np.cos(psi), np.sin(psi)
    base = np.stack([mocap["e_m"].to_numpy(float), mocap["n_m"].to_numpy(float), np.zeros(len(psi))], -1)

    def body(joint):
        d = mocap[joint_columns(joint)].to_numpy(float) - base
        return np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], d[:, 2]], -1)

    out = {}
    t = mocap["t_s"].to_numpy(float)
    v_e = np.gradient(base[:, 0], t)
    v_n = np.gradient(base[:, 1], t)
    rate = mocap["phase_rate_radps"].to_numpy(float)
    out["rho_m_per_rad"] = (c * v_e + s * v_n) / np.maximum(rate, 1e-6)
    pel = body("pelvis")
    out["pelvis_f_m"], out["pelvis_l_m"], out["pelvis_u_m"] = pel.T
    thigh, shank = [], []
    for side in SIDES:
        hip, knee, ankle = body(f"hip_{side}"), body(f"knee_{side}"), body(f"ankle_{side}")
        out[f"{side}_hip_f_m"], out[f"{side}_hip_l_m"], out[f"{side}_hip_u_m"] = hip.T
        a, b = knee - hip, ankle - knee
        la, lb = np.linalg.norm(a, axis=1), np.linalg.norm(b, axis=1)
        thigh.append(la)
        shank.append(lb)
        za = a / la[:, None]
        pitch = np.arcsin(np.clip(za[:, 0], -1, 1))
        roll = np.arctan2(za[:, 1], -za[:, 2])
        # the shank in the thigh's plane: undo the roll
        cr, sr = np.cos(roll), np.sin(roll)
        zb = b / lb[:, None]
        b_u = -sr * zb[:, 1] + cr * zb[:, 2]
        out[f"{side}_thigh_pitch_rad"] = pitch
        out[f"{side}_thigh_roll_rad"] = roll
        out[f"{side}_knee_flex_rad"] = pitch - np.arctan2(zb[:, 0], -b_u)
    frame = pd.DataFrame(out)[list(PARAMS)]
    frame["thigh_m"] = np.mean(thigh, axis=0)
    frame["shank_m"] = np.mean(shank, axis=0)
    return frame


class FourierFormTemplates(Algorithm):
    """Per-form Fourier templates of the gait (Watanabe et al. Sec. 3-4) and the transition diagram between forms.

    Parameters
    ----------
    order : Fourier order of every template (the paper: 5, eq. 2).
    transition_margin_cycles : samples closer than this (in gait cycles) to a change of form label are left out of
        the fit (the gait is in between two forms there).
    min_cycles : a form needs at least this many cycles of samples.

    Attributes
    ----------
    forms_ : form names, in order of first appearance.
    coefficients_ : (n_forms, 2*order+1, n_params) array, ``[a0, a1, b1, ...]`` per parameter (``PARAMS``):
        path advance per radian of phase, pelvis and hip offsets in the body frame, thigh pitch and roll and knee
        flexion of both legs, all as functions of the phase eta (rad; 0 = left heel strike).
    phase_rate_radps_ : nominal phase rate (cadence, 2*pi per stride) of each form (median).
    speed_mps_ : nominal walking speed of each form (median path speed; the paper's forms hold the speed, eq. 2).
    transitions_ : (n_forms, n_forms) bool, ``[a, b]`` = form b may follow form a (the diagonal is true).
    thigh_m_, shank_m_ : segment lengths of the subject (median of the training samples).
    n_cycles_ : cycles of training samples per form.

    Notes
    -----
    The paper stores each form as the Fourier coefficients of the waist height, speed, turn rate and relative joint
    positions sampled by motion capture (eq. 2) and draws the transition diagram from the order in which forms
    follow each other in the samples (Fig. 3, 5, 10). Here the joints are represented by angles and segment
    lengths (so that the thigh camera's orientation follows directly), the speed by the path advance per radian of
    phase (so that a form's speed scales with the estimated cadence), and the turn rate is left to the state's
    heading (the training walks are straight and turning; turns are tracked, not templated). The form labels of
    the training samples come with the table (the PCA + k-means forms of ``pdr.gait`` can supply them).
    Each template is one least-squares fit over all the cycles of a form, the mean cycle (the paper keeps the one
    sample closest to the cluster centre).

    Example
    -------
    >>> templates = FourierFormTemplates().fit(mocap_table)        # doctest: +SKIP
    >>> templates.forms_                                           # doctest: +SKIP
    ['slow_walk', 'walk', 'fast_walk', 'run']
    """

    def __init__(self, *, order: int = DEFAULT_ORDER, transition_margin_cycles: float = 1.0, min_cycles: float = 3.0):
        self.order = order
        self.transition_margin_cycles = transition_margin_cycles
        self.min_cycles = min_cycles

    def fit(self, mocap: pd.DataFrame) -> "FourierFormTemplates":
        """Learn the templates from a motion-capture table (``MOCAP_COLUMNS``; several walks may be concatenated,
        told apart by an optional ``walk`` column, each with increasing ``t_s``)."""
        require_table(mocap, MOCAP_COLUMNS, "form templates: training table")
        walks = mocap["walk"].to_numpy() if "walk" in mocap.columns else np.zeros(len(mocap), int)
        forms: list[str] = []
        for f in mocap["form"].astype(str):
            if f not in forms:
                forms.append(f)
        params, phase, label, keep, rates = [], [], [], [], []
        trans = np.eye(len(forms), dtype=bool)
        for w in pd.unique(walks):
            sub = mocap[walks == w].sort_values("t_s")
            if len(sub) < 3 or not np.all(np.diff(sub["t_s"].to_numpy(float)) > 0):
                raise InputError(f"form templates: expected strictly increasing t_s within walk {w!r}, found otherwise")
            eta = sub["phase_rad"].to_numpy(float)
            lab = sub["form"].astype(str).to_numpy()
            change = np.flatnonzero(lab[1:] != lab[:-1])
            for i in change:
                trans[forms.index(lab[i]), forms.index(lab[i + 1])] = True
            ok = sub["phase_rate_radps"].to_numpy(float) > 0.5  # walking, not standing
            for i in change:
                ok &= np.abs(eta - 0.5 * (eta[i] + eta[i + 1])) > TWO_PI * self.transition_margin_cycles
            params.append(body_frame_parameters(sub))
            phase.append(eta)
            label.append(lab)
            keep.append(ok)
            rates.append(sub["phase_rate_radps"].to_numpy(float))
        params_df = pd.concat(params, ignore_index=True)
        eta, lab, ok, rate = np.concatenate(phase), np.concatenate(label), np.concatenate(keep), np.concatenate(rates)
        coef, med_rate, med_speed, cycles = [], [], [], []
        for f in forms:
            m = ok & (lab == f)
            n_cyc = float(np.unique(np.floor(eta[m] / TWO_PI)).size) if m.any() else 0.0
            if m.sum() < 2 * self.order + 1:
                raise InputError(f"form templates: expected samples over whole gait cycles of form {f!r}, found {m.sum()} samples")
            coef.append(fourier_coefficients(eta[m], params_df.loc[m, list(PARAMS)].to_numpy(float), self.order))
            med_rate.append(float(np.median(rate[m])))
            med_speed.append(float(np.median(params_df.loc[m, "rho_m_per_rad"].to_numpy() * rate[m])))
            cycles.append(n_cyc)
        short = [f for f, c in zip(forms, cycles) if c < self.min_cycles]
        if short:
            raise InputError(f"form templates: expected at least {self.min_cycles:g} cycles per form, found fewer for {', '.join(short)}")
        self.forms_ = forms
        self.coefficients_ = np.stack(coef)
        self.phase_rate_radps_ = np.array(med_rate)
        self.speed_mps_ = np.array(med_speed)
        self.transitions_ = trans
        self.thigh_m_ = float(np.median(params_df["thigh_m"]))
        self.shank_m_ = float(np.median(params_df["shank_m"]))
        self.n_cycles_ = dict(zip(forms, cycles))
        return self

    # JSON round trip: a fitted template set is the estimator's per-user model
    def to_dict(self) -> dict[str, Any]:
        return {"order": self.order, "forms": self.forms_, "params": list(PARAMS),
                "coefficients": self.coefficients_.tolist(), "phase_rate_radps": self.phase_rate_radps_.tolist(),
                "speed_mps": self.speed_mps_.tolist(),
                "transitions": self.transitions_.astype(int).tolist(), "thigh_m": self.thigh_m_, "shank_m": self.shank_m_}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "FourierFormTemplates":
        if list(d.get("params", [])) != list(PARAMS):
            raise InputError(f"form templates: expected parameters {', '.join(PARAMS)}, found {d.get('params')}")
        out = cls(order=int(d["order"]))
        out.forms_ = list(d["forms"])
        out.coefficients_ = np.asarray(d["coefficients"], float)
        out.phase_rate_radps_ = np.asarray(d["phase_rate_radps"], float)
        out.speed_mps_ = np.asarray(d["speed_mps"], float)
        out.transitions_ = np.asarray(d["transitions"], bool)
        out.thigh_m_, out.shank_m_ = float(d["thigh_m"]), float(d["shank_m"])
        out.n_cycles_ = {}
        return out

    def evaluate(self, form: np.ndarray, phase_rad: np.ndarray, derivative: bool = False) -> np.ndarray:
        """(B, n_params) template values (or d/d eta) of forms ``form`` (indices) at phases ``phase_rad``."""
        coef = self._dcoef if derivative else self.coefficients_
        design = fourier_design_matrix(phase_rad, self.order)
        return np.einsum("bc,bcp->bp", design, coef[np.asarray(form, int)])

    @property
    def _dcoef(self) -> np.ndarray:
        if getattr(self, "_dcoef_cache", None) is None:
            self._dcoef_cache = np.stack([fourier_derivative(c) for c in self.coefficients_])
        return self._dcoef_cache
