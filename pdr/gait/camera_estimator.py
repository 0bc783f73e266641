"""Gait estimation from a single wearable camera on the thigh (Watanabe, Hatanaka, Komuro & Ishikawa, "Human Gait
Estimation Using a Wearable Camera", WACV 2011; the seed ``001_259ca8b931a5f432``).

A camera fixed to one thigh looks down at ground points of known world coordinates (the corners of a chessboard on
the floor, as in the paper's experiment). The walking state ``(x, y, heading, phase, phase rate)`` (the paper's
reduced state, Sec. 5.1) is tracked with several candidate states; each candidate is tried in the walking forms the
transition diagram allows (Sec. 5.2), predicted with the form's gait model (eq. 1, 4, 5), weighted by the
re-projection error of the observed points (eq. 6-7, with the bonus C for staying in a form), the best kept
(resampling, Sec. 5.4) and corrected by an extended Kalman filter (eq. 8-11). The whole body pose (hip, knee and
ankle of both legs) follows from the state and the form's joint-angle templates.

Public objects
--------------
``ThighCameraModel`` (pinhole intrinsics and the thigh mount), ``FourierFormTemplates`` (per-form Fourier templates
of the gait parameters and joint angles, learnt from motion-capture-like tables of training walks, and the
transition diagram), ``WearableCameraGaitEstimation`` (the estimator), ``project_points`` / ``observation_jacobian``
(the observation model h and its Jacobian H, public for tests).

Frames: world = local east-north-up (m), heading counter-clockwise from east. Body frame: origin on the ground below
the walker on the path (the state's ``x, y``), ``f`` forward along the heading, ``l`` to the left, ``u`` up.
Thigh frame (as :mod:`pdr.sim.gait`): x forward, y to the right, z along the thigh from hip to knee. Camera frame:
x = image right (u), y = image down (v), z = optical axis.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
import pandas as pd

from pdr.errors import InputError, warn
from pdr.gait.fourier import DEFAULT_ORDER, fourier_coefficients, fourier_derivative, fourier_design_matrix
from pdr.io.recording import numeric_frame

TWO_PI = 2.0 * np.pi
SIDES = ("left", "right")
JOINTS = ("pelvis", "hip_left", "knee_left", "ankle_left", "hip_right", "knee_right", "ankle_right")
STATE = ("e_m", "n_m", "heading_rad", "phase_rad", "phase_rate_radps")
# Template parameters (columns of each form's coefficient matrix). rho: path advance per radian of phase.
PARAMS = ("rho_m_per_rad", "pelvis_f_m", "pelvis_l_m", "pelvis_u_m") + tuple(
    f"{side}_{p}" for side in SIDES for p in ("hip_f_m", "hip_l_m", "hip_u_m", "thigh_pitch_rad", "thigh_roll_rad", "knee_flex_rad"))
_P = {name: i for i, name in enumerate(PARAMS)}
MIN_POINTS = 4  # fewer than this cannot fix a camera pose: the frame is predicted only
_R0 = np.diag([1.0, -1.0, -1.0])  # thigh frame of a vertical thigh, in the body frame


# ----------------------------------------------------------------------------------------------------------------
# Rotations (batched over leading axes)
# ----------------------------------------------------------------------------------------------------------------
def _rot(axis: int, a: np.ndarray) -> np.ndarray:
    a = np.asarray(a, float)
    c, s = np.cos(a), np.sin(a)
    r = np.zeros(a.shape + (3, 3))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    r[..., axis, axis] = 1.0
    r[..., i, i] = c
    r[..., j, j] = c
    r[..., i, j] = -s
    r[..., j, i] = s
    return r


def _drot(axis: int, a: np.ndarray) -> np.ndarray:
    """d/da of :func:`_rot`."""
    a = np.asarray(a, float)
    c, s = np.cos(a), np.sin(a)
    r = np.zeros(a.shape + (3, 3))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    r[..., i, i] = -s
    r[..., j, j] = -s
    r[..., i, j] = -c
    r[..., j, i] = c
    return r


# ----------------------------------------------------------------------------------------------------------------
# The camera
# ----------------------------------------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class ThighCameraModel:
    """A pinhole camera (no lens distortion, as the paper's undistorted images) fixed to a thigh.

    Parameters
    ----------
    fps, focal_px, cx_px, cy_px, width_px, height_px : frame rate and intrinsics.
    side : ``"left"`` or ``"right"`` thigh (the paper: the outer side of the right thigh).
    along_thigh_m : distance of the optical centre from the hip joint centre along the thigh.
    outward_m : offset from the thigh axis to the outer side (skin and mount).
    tilt_out_deg : the optical axis points down the thigh, turned outward by this angle (so that it sees the floor
        beside the foot rather than the own leg).
    """

    fps: float = 100.0
    focal_px: float = 200.0
    cx_px: float = 159.5
    cy_px: float = 119.5
    width_px: int = 320
    height_px: int = 240
    side: str = "right"
    along_thigh_m: float = 0.15
    outward_m: float = 0.08
    tilt_out_deg: float = 20.0

    def __post_init__(self):
        if self.side not in SIDES:
            raise InputError(f"thigh camera: expected side 'left' or 'right', found {self.side!r}")
        positive = ("fps", "focal_px", "width_px", "height_px", "along_thigh_m")
        for k in positive + ("cx_px", "cy_px", "outward_m", "tilt_out_deg"):
            v = getattr(self, k)
            try:
                x = float(v)
            except (TypeError, ValueError, OverflowError):
                x = float("nan")
            if not np.isfinite(x) or (k in positive and x <= 0):
                raise InputError(f"thigh camera: expected a {'positive ' if k in positive else ''}number for {k}, found {v!r}")

    @property
    def _out(self) -> float:
        return 1.0 if self.side == "right" else -1.0  # thigh y points right: outward on the right leg

    @property
    def offset_thigh_m(self) -> np.ndarray:
        """Optical centre in the thigh frame (x fwd, y right, z hip->knee)."""
        return np.array([0.0, self._out * self.outward_m, self.along_thigh_m])

    @property
    def rotation_thigh(self) -> np.ndarray:
        """Camera axes (columns: image x, image y, optical axis) in the thigh frame."""
        return _rot(0, -self._out * np.radians(self.tilt_out_deg))

    @property
    def intrinsics(self) -> np.ndarray:
        return np.array([[self.focal_px, 0.0, self.cx_px], [0.0, self.focal_px, self.cy_px], [0.0, 0.0, 1.0]])

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


# ----------------------------------------------------------------------------------------------------------------
# Per-form templates
# ----------------------------------------------------------------------------------------------------------------
def joint_columns(joint: str) -> list[str]:
    """The world-position columns of a joint in the motion-capture and joint tables: ``<joint>_{e,n,u}_m``."""
    return [f"{joint}_{a}_m" for a in "enu"]


MOCAP_COLUMNS = ["t_s", "e_m", "n_m", "heading_rad", "phase_rad", "phase_rate_radps", "form"] + [
    c for j in JOINTS for c in joint_columns(j)]


def _check_table(df: pd.DataFrame, columns: list[str], what: str) -> None:
    if not isinstance(df, pd.DataFrame):
        raise InputError(f"{what}: expected a DataFrame, found {type(df).__name__}")
    missing = [c for c in columns if c not in df.columns]
    if missing:
        raise InputError(f"{what}: expected columns {', '.join(missing)}, found {', '.join(map(str, df.columns)) or 'none'}")


def _numeric(df: pd.DataFrame, columns: list[str], what: str, also: list[str] = ()) -> pd.DataFrame:
    """``df`` with ``columns`` as numbers (:func:`pdr.io.recording.numeric_frame`) and ``also`` present."""
    _check_table(df, list(columns) + list(also), what)
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


class FourierFormTemplates:
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
        _check_table(mocap, MOCAP_COLUMNS, "form templates: training table")
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


# ----------------------------------------------------------------------------------------------------------------
# The observation model h (eq. 8) and its Jacobian H
# ----------------------------------------------------------------------------------------------------------------
def _camera_in_body(tp: np.ndarray, dtp: np.ndarray | None, camera: ThighCameraModel):
    """Camera centre c_b and rotation R_bc in the body frame from template values (B, n_params), and their
    derivatives with respect to the phase when ``dtp`` is given."""
    side = camera.side
    hip = tp[:, [_P[f"{side}_hip_f_m"], _P[f"{side}_hip_l_m"], _P[f"{side}_hip_u_m"]]]
    th, ph = tp[:, _P[f"{side}_thigh_pitch_rad"]], tp[:, _P[f"{side}_thigh_roll_rad"]]
    rx, ry = _rot(0, ph), _rot(1, -th)
    r_bt = rx @ ry @ _R0
    m = camera.offset_thigh_m
    r_tc = camera.rotation_thigh
    c_b = hip + r_bt @ m
    r_bc = r_bt @ r_tc
    if dtp is None:
        return c_b, r_bc, None, None
    dhip = dtp[:, [_P[f"{side}_hip_f_m"], _P[f"{side}_hip_l_m"], _P[f"{side}_hip_u_m"]]]
    dth, dph = dtp[:, _P[f"{side}_thigh_pitch_rad"]], dtp[:, _P[f"{side}_thigh_roll_rad"]]
    dr_bt = (_drot(0, ph) @ ry @ _R0) * dph[:, None, None] - (rx @ _drot(1, -th) @ _R0) * dth[:, None, None]
    return c_b, r_bc, dhip + dr_bt @ m, dr_bt @ r_tc


def project_points(state: np.ndarray, form: np.ndarray, points_m: np.ndarray, templates: FourierFormTemplates,
                   camera: ThighCameraModel, jacobian: bool = False):
    """The observation model h: image points (B, N, 2) of world points ``points_m`` (N, 3) seen by the thigh camera
    of the walker in states ``state`` (B, 5) walking in forms ``form`` (B,), and the depth (B, N) along the optical
    axis (points with depth <= 0 are behind the camera).

    With ``jacobian``: also H = dh/dstate (B, N, 2, 5) and dh/d(camera pose error) (B, N, 2, 6), the derivative
    with respect to a small rotation (3, rad, camera axes) and translation (3, m, camera axes) of the camera away
    from where the templates put it (used to model the template error as one pose error shared by all points)."""
    state = np.atleast_2d(np.asarray(state, float))
    form = np.broadcast_to(np.asarray(form, int), (len(state),))
    x, y, xi, eta = state[:, 0], state[:, 1], state[:, 2], state[:, 3]
    tp = templates.evaluate(form, eta)
    dtp = templates.evaluate(form, eta, derivative=True) if jacobian else None
    c_b, r_bc, dc_b, dr_bc = _camera_in_body(tp, dtp, camera)
    c, s = np.cos(xi)[:, None], np.sin(xi)[:, None]
    dx = points_m[None, :, 0] - x[:, None]
    dy = points_m[None, :, 1] - y[:, None]
    r = np.stack([c * dx + s * dy, -s * dx + c * dy, np.broadcast_to(points_m[None, :, 2], dx.shape)], -1)
    q = r - c_b[:, None, :]
    pc = q @ r_bc  # R_bc^T q, row-wise
    z = pc[..., 2]
    zs = np.where(np.abs(z) < 1e-6, 1e-6, z)
    f = camera.focal_px
    uv = np.stack([f * pc[..., 0] / zs + camera.cx_px, f * pc[..., 1] / zs + camera.cy_px], -1)
    if not jacobian:
        return uv, z
    zero = np.zeros_like(dx)
    # d pc / d (x, y, xi, eta, camera rotation (3), camera translation (3)): (B, N, 3, 10)
    dq = np.empty(dx.shape + (3, 4))  # d q / d (x, y, xi, eta)
    dq[..., 0] = np.stack([-np.broadcast_to(c, dx.shape), np.broadcast_to(s, dx.shape), zero], -1)
    dq[..., 1] = np.stack([-np.broadcast_to(s, dx.shape), -np.broadcast_to(c, dx.shape), zero], -1)
    dq[..., 2] = np.stack([r[..., 1], -r[..., 0], zero], -1)
    dq[..., 3] = -np.broadcast_to(dc_b[:, None, :], dx.shape + (3,))
    dpc = np.zeros(dx.shape + (3, 10))
    dpc[..., :4] = np.einsum("bnik,bij->bnjk", dq, r_bc)  # R_bc^T dq
    dpc[..., 3] += q @ dr_bc  # dR_bc^T q
    # pose error, camera axes: the scene turned by a small rotation w and the camera moved by t: pc' = pc + w x pc - t
    px, py, pz = pc[..., 0], pc[..., 1], pc[..., 2]
    dpc[..., 0, 5], dpc[..., 0, 6] = pz, -py
    dpc[..., 1, 4], dpc[..., 1, 6] = -pz, px
    dpc[..., 2, 4], dpc[..., 2, 5] = py, -px
    dpc[..., 0, 7] = dpc[..., 1, 8] = dpc[..., 2, 9] = -1.0
    inv = (f / zs)[..., None]
    jac = np.stack([inv * (dpc[..., 0, :] - (pc[..., 0] / zs)[..., None] * dpc[..., 2, :]),
                    inv * (dpc[..., 1, :] - (pc[..., 1] / zs)[..., None] * dpc[..., 2, :])], -2)
    out = np.zeros(dx.shape + (2, 5))
    out[..., :4] = jac[..., :4]
    return uv, z, out, jac[..., 4:]


def observation_jacobian(state, form, points_m, templates, camera) -> np.ndarray:
    """H (B, N, 2, 5): the Jacobian of :func:`project_points` with respect to the state."""
    return project_points(state, form, points_m, templates, camera, jacobian=True)[2]


def joint_positions(state: np.ndarray, form: np.ndarray, templates: FourierFormTemplates) -> dict[str, np.ndarray]:
    """World positions (B, 3) of ``JOINTS`` for states (B, 5) in forms (B,): the body pose of the templates."""
    state = np.atleast_2d(np.asarray(state, float))
    tp = templates.evaluate(np.broadcast_to(np.asarray(form, int), (len(state),)), state[:, 3])
    c, s = np.cos(state[:, 2]), np.sin(state[:, 2])

    def world(b):
        return np.stack([state[:, 0] + c * b[:, 0] - s * b[:, 1], state[:, 1] + s * b[:, 0] + c * b[:, 1], b[:, 2]], -1)

    out = {"pelvis": world(tp[:, [_P["pelvis_f_m"], _P["pelvis_l_m"], _P["pelvis_u_m"]]])}
    for side in SIDES:
        hip = tp[:, [_P[f"{side}_hip_f_m"], _P[f"{side}_hip_l_m"], _P[f"{side}_hip_u_m"]]]
        th, ph, kn = (tp[:, _P[f"{side}_{k}"]] for k in ("thigh_pitch_rad", "thigh_roll_rad", "knee_flex_rad"))
        cr, sr = np.cos(ph), np.sin(ph)

        def seg(angle, length):  # R_x(roll) (sin a, 0, -cos a) * length
            return length * np.stack([np.sin(angle), sr * np.cos(angle), -cr * np.cos(angle)], -1)

        knee = hip + seg(th, templates.thigh_m_)
        ankle = knee + seg(th - kn, templates.shank_m_)
        out[f"hip_{side}"], out[f"knee_{side}"], out[f"ankle_{side}"] = world(hip), world(knee), world(ankle)
    return out


def predict(state: np.ndarray, cov: np.ndarray, form: np.ndarray, dt_s: float, templates: FourierFormTemplates,
            process_std: np.ndarray, cadence_std_fraction: float, cadence_tau_s: float):
    """State prediction g (eq. 1, 4, 5) over ``dt_s`` in the given forms, its Jacobian G and the predicted
    covariance (eq. 9). ``process_std``: white-noise densities of (x, y, heading, phase) per sqrt(s), (4,) or per
    candidate (B, 4). The phase rate returns to the form's cadence (a first-order Gauss-Markov process with time
    constant ``cadence_tau_s`` and a spread of ``cadence_std_fraction`` of the cadence): a form walks at its own
    pace (the paper's forms have their own periods, Fig. 9), give or take the step-to-step timing."""
    x, y, xi, eta, rate = state.T
    rho = templates.evaluate(form, eta)[:, _P["rho_m_per_rad"]]
    drho = templates.evaluate(form, eta, derivative=True)[:, _P["rho_m_per_rad"]]
    nominal = templates.phase_rate_radps_[np.asarray(form, int)]
    keep = np.exp(-dt_s / cadence_tau_s)
    step = rho * rate * dt_s
    c, s = np.cos(xi), np.sin(xi)
    out = np.stack([x + step * c, y + step * s, xi, eta + rate * dt_s, nominal + keep * (rate - nominal)], -1)
    g = np.broadcast_to(np.eye(5), (len(state), 5, 5)).copy()
    g[:, 0, 2], g[:, 1, 2] = -step * s, step * c
    g[:, 0, 3], g[:, 1, 3] = drho * rate * dt_s * c, drho * rate * dt_s * s
    g[:, 0, 4], g[:, 1, 4] = rho * dt_s * c, rho * dt_s * s
    g[:, 3, 4] = dt_s
    g[:, 4, 4] = keep
    var = np.empty((len(state), 5))
    var[:, :4] = np.broadcast_to(process_std, (len(state), 4)) ** 2 * dt_s
    var[:, 4] = (cadence_std_fraction * nominal) ** 2 * (1.0 - keep**2)
    cov_bar = g @ cov @ np.swapaxes(g, 1, 2) + np.einsum("bi,ij->bij", var, np.eye(5))
    return out, cov_bar, g


def ekf_update(state_bar: np.ndarray, cov_bar: np.ndarray, residual: np.ndarray, jac: np.ndarray,
               weight: np.ndarray, pixel_std_px: float, jac_pose: np.ndarray | None = None,
               pose_cov: np.ndarray | None = None):
    """EKF update (eq. 10-11) of B candidates with residuals u - h (B, N, 2), H (B, N, 2, 5) and per-point
    inlier weights (B, N) in {0, 1}.

    The observation noise is Q = D + J Sigma_pose J^T: independent pixel noise D (``pixel_std_px``^2 for inliers,
    infinite for outliers) plus, when ``jac_pose`` (B, N, 2, 6) and ``pose_cov`` (6, 6) are given, one camera pose
    error shared by all points of the frame (the stored form never fits the observed step exactly, and that
    error moves all points together; without it 60 points would count as 60 independent measurements).
    Written in the information form with the matrix inversion lemma,
    K (u - h) = (Sigma^-1 + H^T Q^-1 H)^-1 H^T Q^-1 (u - h),  Q^-1 = D^-1 - D^-1 J (Sigma_pose^-1 + J^T D^-1 J)^-1 J^T D^-1,
    so that only 5x5 and 6x6 systems are solved whatever the number of points."""
    w = weight / pixel_std_px**2
    a = np.einsum("bnik,bn,bnil->bkl", jac, w, jac)
    b = np.einsum("bnik,bn,bni->bk", jac, w, residual)
    if jac_pose is not None:
        c = np.einsum("bnik,bn,bnil->bkl", jac, w, jac_pose)
        m = np.linalg.inv(pose_cov) + np.einsum("bnik,bn,bnil->bkl", jac_pose, w, jac_pose)
        f = np.einsum("bnik,bn,bni->bk", jac_pose, w, residual)
        c_minv = np.swapaxes(np.linalg.solve(m, np.swapaxes(c, 1, 2)), 1, 2)  # C M^-1 (M symmetric)
        a = a - c_minv @ np.swapaxes(c, 1, 2)
        b = b - np.einsum("bkl,bl->bk", c_minv, f)
    info = np.linalg.inv(cov_bar) + a
    cov = np.linalg.inv(info)
    cov = 0.5 * (cov + np.swapaxes(cov, 1, 2))
    return state_bar + np.einsum("bkl,bl->bk", cov, b), cov


# ----------------------------------------------------------------------------------------------------------------
# The estimator
# ----------------------------------------------------------------------------------------------------------------
class WearableCameraGaitEstimation:
    """Walking state, walking form and body pose from a thigh camera observing known ground points
    (Watanabe et al. 2011).

    Parameters
    ----------
    templates : fitted :class:`FourierFormTemplates` (the forms, their gait templates and the transition diagram).
    camera : the :class:`ThighCameraModel` (intrinsics and mount; the body-camera transformation is known, Sec. 3).
    n_candidates : candidate states kept after resampling (the paper's M_t).
    max_points : at most this many detections per frame are used (spread over the detections in their given
        order). The stored gait, not the pixel noise, limits what one frame tells (see ``template_*``): more
        points cost time and add little.
    n_initial_phases : the unknown initial phase is tried on this grid, in every form.
    keep_every_form : resampling keeps the heaviest candidate of every form besides the heaviest overall.
    likelihood_sigma_px, likelihood_mean_px : sigma and nu of the reliability lambda (eq. 7): the spread of the
        mean re-projection error of a correct candidate. The paper set sigma^2 = 10 px^2, nu = 0 for its camera
        and gaits; on the simulated walks here the stored forms leave a mean error of about 8-10 px (1-sigma
        spread ~8 px) at the true state, from stride-to-stride variability, so sigma = 8 px.
    error_correlation_s : that error belongs to the step, not to the frame: it persists for about this long, so
        lambda is counted once per this time (log lambda x frame time / correlation time; 0: every frame, as the
        paper at 250 fps).
    mean_form_duration_s : sets the bonus C for staying in a form (eq. 6) as the prior odds of staying rather than
        changing in one frame: C = mean form duration x frame rate (a form lasts seconds, a frame 1/fps).
    pixel_std_px : independent noise of one image point in the EKF (Q of eq. 10): corner detection.
    template_rotation_std_deg, template_position_std_m : the stored form never matches the observed step exactly
        (stride-to-stride variability, other speeds): that puts the camera off its templated pose by about this
        much, an error shared by all points of a frame (part of Q).
    gate_px : a point whose re-projection error exceeds max(gate_px, 3 x the candidate's median error) is an
        outlier (a mismatched corner): capped in eq. 7 and left out of the update.
    position_noise_mps, heading_noise_radps, phase_noise_radps : process noise P (eq. 9) as white-noise
        densities (per sqrt(s)) of x/y, heading and phase.
    cadence_std_fraction, speed_std_fraction, cadence_tau_s : a form walks at its own cadence and speed, give or
        take these fractions (step-to-step timing, speeds between the stored forms). The phase rate is predicted
        to return to the form's cadence with the time constant ``cadence_tau_s`` (about one step), and the weight
        of a candidate (eq. 6) is multiplied by a pace factor kappa: the Gaussian of the cadence and speed it
        has shown over about the last step (phase and path advance per second, the EKF corrections included)
        about its form's, counted once per ``cadence_tau_s``. A fraction of 0 leaves that part out. The image
        alone tells nearby forms apart poorly (the stored form misses a real step by 20-30 px at the true
        state, and a wrong form's pose is absorbed by a shifted phase); the pace, part of what a form is (the
        paper's forms hold the speed, eq. 2, and have their own periods, Fig. 9), does.
    initial_position_std_m, initial_heading_std_rad : uncertainty of the start pose given to :meth:`estimate`
        (and of the pose kept when the track is lost).
    lost_error_sigmas, lost_frames : the track is lost when the best candidate's mean re-projection error after
        the update exceeds this many ``likelihood_sigma_px`` for this many frames in a row; phase and form are
        then searched again (as at the start) around the current position and heading. Near a turning point of
        the thigh swing the phase is locally unobservable and a lagging phase can be held there by the update.
    smooth_forms : True: the output forms are the most likely sequence given the whole walk
        (:func:`most_likely_forms`, Viterbi backtracking over the filter's per-form scores), and each frame's
        state is the heaviest candidate of its form; False: the heaviest candidate of each frame, online (the
        paper).

    Attributes
    ----------
    states_ : per frame ``t_s, e_m, n_m, heading_rad, phase_rad, phase_rate_radps, form, n_points, n_inliers,
        reprojection_error_px`` (of the output candidate after the update, see ``smooth_forms``; ``n_points`` 0:
        predicted only).
    joints_ : per frame ``t_s`` and ``<joint>_{e,n,u}_m`` for ``JOINTS`` (the estimated body pose).
    cycles_ : estimated gait cycles (phase from one multiple of 2 pi to the next) ``t_start_s, t_end_s, form``
        (the form held for most of the cycle).
    n_predicted_only_ : frames with fewer than 4 points (predicted, not updated).
    n_relocalised_ : times the track was lost and phase and form searched again.
    time_s_ : processing time of the filter.

    Notes
    -----
    Per frame (paper Fig. 4): every candidate is tried in its form and in the forms the transition diagram allows
    after it (Sec. 5.2); each trial is predicted with that form's template, eq. 1 for the position and heading with
    the speed = path advance per radian x phase rate, eq. 5 for the phase, and the covariance by eq. 9 (Sec. 5.3);
    its weight is w = C lambda w_prev (eq. 6) with lambda the Gaussian of the mean re-projection error of the
    observed points (eq. 7); the heaviest trials are kept (resampling, Sec. 5.4) and each is corrected by the EKF
    (eq. 10-11) with the analytic Jacobian of the pinhole projection. The output is the heaviest candidate.

    Deviations, each for a reason found on the simulated walks (where the stored gait of a form misses a given
    step by a few degrees of thigh angle, 10-20 px):

    - Q of eq. 10 holds, besides the pixel noise, one camera pose error shared by all points of a frame. With
      independent pixel noise only, sixty points overrule the gait model and the state bends to fit each step.
    - lambda (eq. 7) is counted once per ``error_correlation_s`` and the weight has a pace factor kappa
      (w = C lambda kappa w_prev): a wrong form's pose is absorbed by a shifted phase within a few frames, so
      per-frame image evidence alone flips between neighbouring forms; the cadence and speed seen over the
      last step tell them apart. The phase rate returns to the form's cadence (eq. 5 with a first-order
      Gauss-Markov rate instead of a random walk): with a free rate, the phase sank behind the truth by up to
      3 rad over slow steps while the re-projection error stayed under 15 px.
    - resampling keeps the heaviest candidate of every form (``keep_every_form``); a lost track (error
      above ``lost_error_sigmas`` x sigma for ``lost_frames`` frames) is searched again over phase and form
      around the current pose, keeping the forms' weights. Near the turning points of the thigh swing the phase
      is locally unobservable and a lagging phase can be held there by the update.
    - by default the forms are smoothed over the whole walk (``smooth_forms``): the online choice switches
      only once the new form's evidence outweighs the bonus C, about half a cycle late, and a passing mismatch
      can flip it for a few frames.
    - outlier gating (the paper had clean chessboard correspondences); the information form of eq. 10 (fewer
      operations, same result); the unknown initial phase is searched on a grid with three iterated updates per
      trial (the paper does not say how it starts); the heading has no turn template (turns are followed through
      the process noise and the camera).

    Example
    -------
    >>> est = WearableCameraGaitEstimation(templates=templates, camera=ThighCameraModel())     # doctest: +SKIP
    >>> est.estimate(frames, observations, points, initial_e_m=0.0, initial_n_m=0.0,
    ...              initial_heading_rad=0.0).states_["form"].iloc[-1]                          # doctest: +SKIP
    'walk'
    """

    def __init__(self, *, templates: FourierFormTemplates, camera: ThighCameraModel, n_candidates: int = 8, max_points: int = 60,
                 n_initial_phases: int = 16, keep_every_form: bool = True, likelihood_sigma_px: float = 8.0,
                 error_correlation_s: float = 0.1,
                 likelihood_mean_px: float = 0.0, mean_form_duration_s: float = 3.0, pixel_std_px: float = 1.5,
                 template_rotation_std_deg: float = 3.0, template_position_std_m: float = 0.01,
                 gate_px: float = 12.0, position_noise_mps: float = 0.1, heading_noise_radps: float = 0.5,
                 phase_noise_radps: float = 0.3,
                 cadence_std_fraction: float = 0.08, cadence_tau_s: float = 0.3, speed_std_fraction: float = 0.1,
                 initial_position_std_m: float = 0.2, initial_heading_std_rad: float = 0.15,
                 lost_error_sigmas: float = 4.0, lost_frames: int = 5, smooth_forms: bool = True):
        self.templates = templates
        self.camera = camera
        self.n_candidates = n_candidates
        self.max_points = max_points
        self.n_initial_phases = n_initial_phases
        self.keep_every_form = keep_every_form
        self.likelihood_sigma_px = likelihood_sigma_px
        self.likelihood_mean_px = likelihood_mean_px
        self.error_correlation_s = error_correlation_s
        self.mean_form_duration_s = mean_form_duration_s
        self.pixel_std_px = pixel_std_px
        self.template_rotation_std_deg = template_rotation_std_deg
        self.template_position_std_m = template_position_std_m
        self.gate_px = gate_px
        self.position_noise_mps = position_noise_mps
        self.heading_noise_radps = heading_noise_radps
        self.phase_noise_radps = phase_noise_radps
        self.cadence_std_fraction = cadence_std_fraction
        self.cadence_tau_s = cadence_tau_s
        self.speed_std_fraction = speed_std_fraction
        self.smooth_forms = smooth_forms
        self.initial_position_std_m = initial_position_std_m
        self.initial_heading_std_rad = initial_heading_std_rad
        self.lost_error_sigmas = lost_error_sigmas
        self.lost_frames = lost_frames

    # ------------------------------------------------------------------------------------------------------------
    def _residuals(self, state, form, pts, uv, jacobian=True):
        """Residuals u - h, Jacobians (state and camera pose error, or None), per-point errors capped at the gate,
        and inlier masks."""
        h, depth, *jac = project_points(state, form, pts, self.templates, self.camera, jacobian=jacobian)
        jac = jac if jacobian else None
        res = uv[None] - h
        err = np.hypot(res[..., 0], res[..., 1])
        err = np.where(depth > 1e-3, err, np.inf)
        gate = np.maximum(self.gate_px, 3.0 * np.median(np.minimum(err, 1e6), axis=1))[:, None]
        inlier = err <= gate
        return res, jac, np.minimum(err, gate), inlier

    def _update(self, s_bar, c_bar, res, jac, inlier):
        rot, pos = np.radians(self.template_rotation_std_deg) ** 2, self.template_position_std_m**2
        pose_cov = np.diag([rot, rot, rot, pos, pos, pos])
        return ekf_update(s_bar, c_bar, res, jac[0], inlier.astype(float), self.pixel_std_px, jac[1], pose_cov)

    def _resample(self, logw, form):
        """Indices of the survivors: the heaviest candidate of every form present (so that no form's best
        hypothesis is lost to a passing mismatch), then the heaviest of the rest up to ``n_candidates``."""
        order = np.argsort(-logw, kind="stable")
        if not self.keep_every_form:
            return order[: self.n_candidates]
        _, first = np.unique(form[order], return_index=True)
        best_each = order[np.sort(first)]
        rest = order[~np.isin(order, best_each)]
        return np.concatenate([best_each, rest])[: max(self.n_candidates, len(best_each))]

    def _log_kappa(self, seen, form, dt_s):
        """log of the pace factor kappa: the cadence and speed seen over about the last step (``seen``, (B, 2):
        phase advance in rad/s and path advance in m/s, corrections included) against the form's own (Gaussian,
        ``cadence_std_fraction`` and ``speed_std_fraction`` of them), counted once per ``cadence_tau_s``. Nothing
        seen yet (NaN): no evidence."""
        tp = self.templates
        nominal = np.stack([tp.phase_rate_radps_[form], tp.speed_mps_[form]], -1)
        spread = np.array([self.cadence_std_fraction, self.speed_std_fraction])
        with np.errstate(invalid="ignore", divide="ignore"):
            z = np.nan_to_num((seen - nominal) / (spread * nominal), nan=0.0, posinf=0.0, neginf=0.0)
        return -0.5 * (z * z).sum(axis=1) * (dt_s / self.cadence_tau_s)

    def _log_lambda(self, capped_err):
        """log of eq. 7 (without the constant): mean capped re-projection error per candidate, counted once per
        ``error_correlation_s``."""
        e = capped_err.mean(axis=1)
        per_frame = max(self.error_correlation_s * self.camera.fps, 1.0)
        return -((e - self.likelihood_mean_px) ** 2) / (2.0 * self.likelihood_sigma_px**2) / per_frame

    def estimate(self, frames: pd.DataFrame, observations: pd.DataFrame, points: pd.DataFrame, *, initial_e_m: float,
                 initial_n_m: float, initial_heading_rad: float) -> "WearableCameraGaitEstimation":
        """Track the walk over the camera frames.

        Parameters
        ----------
        frames : ``t_s`` per camera frame (strictly increasing).
        observations : ``frame`` (row index into ``frames``), ``point_id``, ``u_px``, ``v_px``: the detected image
            points and which known ground point each is.
        points : ``point_id, e_m, n_m, u_m``: the known world coordinates of the ground points.
        initial_e_m, initial_n_m, initial_heading_rad : the start pose (e.g. the start mark on the chessboard),
            with the uncertainty of the ``initial_*_std`` parameters; phase and form are searched.
        """
        import time

        frames = _numeric(frames, ["t_s"], "thigh camera frames")
        observations = _numeric(observations, ["frame", "u_px", "v_px"], "thigh camera observations", also=["point_id"])
        points = _numeric(points, ["e_m", "n_m", "u_m"], "ground points", also=["point_id"])
        t = frames["t_s"].to_numpy(float)
        if len(t) == 0:
            warn("thigh camera: no frames; empty estimate")
            self._empty()
            return self
        if not np.all(np.isfinite(t)) or not np.all(np.diff(t) > 0):
            raise InputError("thigh camera frames: expected finite, strictly increasing t_s, found otherwise")
        tp = self.templates
        obs = observations.sort_values("frame", kind="stable")
        fr = obs["frame"].to_numpy()
        if len(fr) and not (np.issubdtype(fr.dtype, np.integer) or np.all(np.mod(fr, 1) == 0)):
            raise InputError("thigh camera observations: expected whole frame indices, found fractions or missing values")
        fr = fr.astype(int)
        if len(fr) and (fr.min() < 0 or fr.max() >= len(t)):
            raise InputError(f"thigh camera observations: expected frame indices 0..{len(t) - 1}, found {fr.min()}..{fr.max()}")
        pid = points["point_id"].to_numpy()
        lookup = pd.Series(np.arange(len(pid)), index=pid)
        if not lookup.index.is_unique:
            raise InputError("ground points: expected unique point_id, found duplicates")
        idx = lookup.reindex(obs["point_id"].to_numpy()).to_numpy()
        if np.isnan(idx).any():
            raise InputError(f"thigh camera observations: expected point ids listed in the ground points, found {int(np.isnan(idx).sum())} unknown")
        world = points[["e_m", "n_m", "u_m"]].to_numpy(float)[idx.astype(int)]
        uv_all = obs[["u_px", "v_px"]].to_numpy(float)
        if not np.isfinite(uv_all).all() or not np.isfinite(world).all():
            raise InputError("thigh camera observations: expected finite pixel and world coordinates, found NaN/inf")
        bounds = np.searchsorted(fr, np.arange(len(t) + 1))

        def frame_points(i):
            pts, uv = world[bounds[i]:bounds[i + 1]], uv_all[bounds[i]:bounds[i + 1]]
            if len(pts) > self.max_points:  # an even spread over the detections
                pick = np.linspace(0, len(pts) - 1, self.max_points).round().astype(int)
                pts, uv = pts[pick], uv[pick]
            return pts, uv

        t0 = time.perf_counter()
        n_forms = len(tp.forms_)
        log_c = float(np.log(max(self.mean_form_duration_s * self.camera.fps, 1.0)))
        pstd = np.array([self.position_noise_mps, self.position_noise_mps, self.heading_noise_radps, self.phase_noise_radps])
        allowed = tp.transitions_ | np.eye(n_forms, dtype=bool)
        out_state = np.zeros((len(t), 5))
        out_form = np.zeros(len(t), int)
        out_n = np.zeros(len(t), int)
        out_in = np.zeros(len(t), int)
        out_err = np.full(len(t), np.nan)
        form_score = np.full((len(t), n_forms), -np.inf)  # per frame, the heaviest candidate of each form
        form_state = np.full((len(t), n_forms, 5), np.nan)
        n_pred_only = n_relocalised = lost = 0
        state = cov = form = logw = seen = None
        for i in range(len(t)):
            pts, uv = frame_points(i)
            enough = len(pts) >= MIN_POINTS
            if state is None:
                if not enough:  # nothing to start from yet
                    n_pred_only += 1
                    out_state[i] = np.nan
                    out_form[i] = -1
                    continue
                state, cov, form, logw = self._initial(pts, uv, initial_e_m, initial_n_m, initial_heading_rad)
                seen = np.full((len(state), 2), np.nan)
            else:
                dt = t[i] - t[i - 1]
                if enough:
                    parent, child = np.nonzero(allowed[form])
                else:  # no evidence to change form: predict only
                    parent, child = np.arange(len(form)), form
                    n_pred_only += 1
                s_bar, c_bar, _ = predict(state[parent], cov[parent], child, dt, tp, pstd, self.cadence_std_fraction,
                                          self.cadence_tau_s)
                lw = logw[parent] + log_c * (child == form[parent])
                lw = lw + self._log_kappa(seen[parent], child, dt)
                before, seen_before = state[parent], seen[parent]
                if enough:
                    _, _, err, _ = self._residuals(s_bar, child, pts, uv, jacobian=False)
                    lw = lw + self._log_lambda(err)
                    keep = self._resample(lw, child)
                    res, jac, _, inl = self._residuals(s_bar[keep], child[keep], pts, uv)
                    state, cov = self._update(s_bar[keep], c_bar[keep], res, jac, inl)
                    form, logw = child[keep], lw[keep]
                    before, seen_before = before[keep], seen_before[keep]
                else:
                    state, cov, form, logw = s_bar, c_bar, child, lw
                # the pace seen: phase and path advance per second, corrections included, smoothed over a step
                step = state[:, :2] - before[:, :2]  # along the heading: unbiased by the jitter of the corrections
                forward = np.cos(state[:, 2]) * step[:, 0] + np.sin(state[:, 2]) * step[:, 1]
                advance = np.stack([state[:, 3] - before[:, 3], forward], -1) / dt
                gain = min(dt / self.cadence_tau_s, 1.0)
                seen = np.where(np.isfinite(seen_before), seen_before + gain * (advance - seen_before), advance)
            logw = logw - logw.max()
            best = int(np.argmax(logw))
            if enough:
                out_n[i], out_in[i], out_err[i] = self._fit_stats(state[best], form[best], pts, uv)
                lost = lost + 1 if not out_err[i] <= self.lost_error_sigmas * self.likelihood_sigma_px else 0
                if lost >= self.lost_frames:  # track lost: search phase and form again around the pose
                    b = state[best]
                    memory = np.full(n_forms, logw.min() - log_c)  # the forms' weights so far are kept
                    np.maximum.at(memory, form, logw)
                    seen_best = seen[best]
                    state, cov, form, logw = self._initial(pts, uv, b[0], b[1], b[2], b[4], memory, b[3])
                    seen = np.tile(seen_best, (len(state), 1))
                    logw = logw - logw.max()
                    best, lost = 0, 0
                    n_relocalised += 1
            out_state[i], out_form[i] = state[best], form[best]
            top = np.argsort(-logw, kind="stable")
            top = top[np.unique(form[top], return_index=True)[1]]
            form_score[i, form[top]], form_state[i, form[top]] = logw[top], state[top]
        if self.smooth_forms:
            for i, f in enumerate(most_likely_forms(form_score, allowed, log_c)):
                if f >= 0 and f != out_form[i]:
                    out_state[i], out_form[i] = form_state[i, f], f
                    pts, uv = frame_points(i)
                    if len(pts) >= MIN_POINTS:
                        out_n[i], out_in[i], out_err[i] = self._fit_stats(out_state[i], f, pts, uv)
        self.time_s_ = time.perf_counter() - t0
        self.n_predicted_only_ = n_pred_only
        self.n_relocalised_ = n_relocalised
        if n_pred_only:
            warn(f"thigh camera: {n_pred_only} of {len(t)} frames had fewer than {MIN_POINTS} known points "
                 f"in view; they were predicted only, not updated")
        names = np.array(tp.forms_ + [""], dtype=object)
        self.states_ = pd.DataFrame({"t_s": t, **{k: out_state[:, j] for j, k in enumerate(STATE)},
                                     "form": names[out_form], "n_points": out_n, "n_inliers": out_in,
                                     "reprojection_error_px": out_err})
        ok = out_form >= 0
        joints = {k: np.full((len(t), 3), np.nan) for k in JOINTS}
        if ok.any():
            jp = joint_positions(out_state[ok], out_form[ok], tp)
            for k in JOINTS:
                joints[k][ok] = jp[k]
        self.joints_ = pd.DataFrame({"t_s": t, **{c: joints[k][:, j] for k in JOINTS for j, c in enumerate(joint_columns(k))}})
        self.cycles_ = cycles_from_phase(t, out_state[:, 3], self.states_["form"].to_numpy())
        return self

    def _fit_stats(self, state, form, pts, uv):
        """Points, inliers and mean inlier re-projection error (px) of one state in one form."""
        h, depth = project_points(state[None], np.array([form]), pts, self.templates, self.camera)
        e = np.where(depth[0] > 0, np.hypot(*(uv - h[0]).T), np.inf)
        inlier = e <= max(self.gate_px, 3.0 * float(np.median(np.minimum(e, 1e6))))
        return len(pts), int(inlier.sum()), float(np.mean(e[inlier])) if inlier.any() else np.nan

    def _initial(self, pts, uv, e0, n0, psi0, rate0=None, log_prior=None, phase0=0.0):
        """Candidates on a grid of phases in every form at the start pose (with the forms' cadences, or
        ``rate0``), each corrected by three iterated updates, weighted by eq. 7 on the corrected errors (plus the
        forms' ``log_prior``); the best ``n_candidates`` are kept. The grid phases run from a quarter cycle
        behind ``phase0`` to three quarters ahead, so that a search during the walk keeps the count of cycles: a
        lost track has lagged (its phase held at a turning point of the thigh while the walker went on)."""
        tp = self.templates
        n_forms, n_ph = len(tp.forms_), self.n_initial_phases
        form = np.repeat(np.arange(n_forms), n_ph)
        eta = np.tile(TWO_PI * np.arange(n_ph) / n_ph, n_forms)
        eta = phase0 - 0.25 * TWO_PI + np.mod(eta - phase0 + 0.25 * TWO_PI, TWO_PI)
        rate = tp.phase_rate_radps_[form] if rate0 is None else np.full(len(form), rate0)
        state = np.stack([np.full(len(form), e0), np.full(len(form), n0), np.full(len(form), psi0), eta, rate], -1)
        std = np.stack([np.full(len(form), self.initial_position_std_m), np.full(len(form), self.initial_position_std_m),
                        np.full(len(form), self.initial_heading_std_rad), np.full(len(form), np.pi / n_ph),
                        0.25 * tp.phase_rate_radps_[form]], -1)
        cov0 = np.einsum("bi,ij->bij", std**2, np.eye(5))
        s = state
        for _ in range(3):  # iterated EKF (Gauss-Newton on the prior + points)
            res, jac, err, inl = self._residuals(s, form, pts, uv)
            res = res + np.einsum("bnik,bk->bni", jac[0], s - state)
            s, cov = self._update(state, cov0, res, jac, inl)
        res, jac, err, inl = self._residuals(s, form, pts, uv)
        lw = self._log_lambda(err) + (0.0 if log_prior is None else log_prior[form])
        keep = self._resample(lw, form)
        return s[keep], cov[keep], form[keep], lw[keep]

    def _empty(self):
        self.states_ = pd.DataFrame({k: pd.Series(dtype=float) for k in ("t_s",) + STATE} | {"form": pd.Series(dtype=object)})
        self.joints_ = pd.DataFrame({"t_s": pd.Series(dtype=float)})
        self.cycles_ = pd.DataFrame({"t_start_s": [], "t_end_s": [], "form": []})
        self.n_predicted_only_ = 0
        self.n_relocalised_ = 0
        self.time_s_ = 0.0


def most_likely_forms(form_score: np.ndarray, allowed: np.ndarray, log_stay: float) -> np.ndarray:
    """The most likely sequence of forms given the whole walk (Viterbi backtracking): ``form_score`` (frames,
    forms) holds, per frame, the log weight of the heaviest candidate of each form (the filter's max-product
    forward score; -inf: none), ``allowed[a, b]`` whether form b may follow form a, ``log_stay`` the bonus C for
    staying (eq. 6). From the best form of the last frame, each earlier frame takes the form whose score plus the
    transition into the later frame's form is highest. -1 where no candidate exists."""
    n = len(form_score)
    out = np.full(n, -1)
    log_t = np.where(allowed, 0.0, -np.inf) + log_stay * np.eye(len(allowed))
    started = np.isfinite(form_score).any(axis=1)
    if not started.any():
        return out
    last = int(np.flatnonzero(started)[-1])
    out[last] = int(np.argmax(form_score[last]))
    for i in range(last - 1, -1, -1):
        if not started[i]:
            break
        into = form_score[i] + log_t[:, out[i + 1]]
        out[i] = int(np.argmax(into if np.isfinite(into).any() else form_score[i]))  # a re-search may jump forms
    return out


def cycles_from_phase(t_s: np.ndarray, phase_rad: np.ndarray, form: np.ndarray) -> pd.DataFrame:
    """Gait cycles between consecutive first crossings of multiples of 2 pi by the phase, with the form held for
    most of each cycle: ``t_start_s, t_end_s, form``."""
    ok = np.isfinite(phase_rad)
    t, ph, fm = t_s[ok], phase_rad[ok], np.asarray(form)[ok]
    k = np.floor(np.maximum.accumulate(ph) / TWO_PI) if len(ph) else ph  # a phase stepping back starts no cycle
    starts = np.flatnonzero(np.diff(k) > 0) + 1
    rows = []
    for a, b in zip(starts[:-1], starts[1:]):
        vals, counts = np.unique(fm[a:b].astype(str), return_counts=True)
        rows.append((t[a], t[b], vals[np.argmax(counts)]))
    return pd.DataFrame(rows, columns=["t_start_s", "t_end_s", "form"])
