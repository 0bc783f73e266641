"""The filter and the smoother of the thigh-camera gait estimator (Watanabe et al., WACV 2011): the state
prediction (eq. 1, 4, 5, 9), the EKF update (eq. 10-11), the most likely sequence of forms over the whole walk, and
the gait cycles of an estimated phase."""

from __future__ import annotations

import numpy as np
import pandas as pd

from pdr.gait.camera_model import TWO_PI
from pdr.gait.camera_templates import _P, FourierFormTemplates


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
