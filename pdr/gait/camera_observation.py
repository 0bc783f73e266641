"""The observation model h of the thigh camera (Watanabe et al., WACV 2011, eq. 8), its analytic Jacobian H, and
the body pose (joint positions) a state and a form imply."""

from __future__ import annotations

import numpy as np

from pdr.gait.camera_model import SIDES, ThighCameraModel, _drot, _rot
from pdr.gait.camera_templates import _P, FourierFormTemplates

_R0 = np.diag([1.0, -1.0, -1.0])  # thigh frame of a vertical thigh, in the body frame


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
