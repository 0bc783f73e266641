"""Gait estimation from a single wearable camera on the thigh (Watanabe, Hatanaka, Komuro & Ishikawa, "Human Gait
Estimation Using a Wearable Camera", WACV 2011; the seed ``001_259ca8b931a5f432``).

A camera fixed to one thigh looks down at ground points of known world coordinates (the corners of a chessboard on
the floor, as in the paper's experiment). The walking state ``(x, y, heading, phase, phase rate)`` (the paper's
reduced state, Sec. 5.1) is tracked with several candidate states; each candidate is tried in the walking forms the
transition diagram allows (Sec. 5.2), predicted with the form's gait model (eq. 1, 4, 5), weighted by the
re-projection error of the observed points (eq. 6-7, with the bonus C for staying in a form), the best kept
(resampling, Sec. 5.4) and corrected by an extended Kalman filter (eq. 8-11). The whole body pose (hip, knee and
ankle of both legs) follows from the state and the form's joint-angle templates.

Modules
-------
:mod:`pdr.gait.camera_model` (``ThighCameraModel``: pinhole intrinsics and the thigh mount),
:mod:`pdr.gait.camera_templates` (``FourierFormTemplates``: per-form Fourier templates of the gait parameters and
joint angles, learnt from motion-capture-like tables of training walks, and the transition diagram),
:mod:`pdr.gait.camera_observation` (``project_points`` / ``observation_jacobian``: the observation model h and its
Jacobian H; ``joint_positions``: the body pose), :mod:`pdr.gait.camera_filter` (``predict``, ``ekf_update``,
``most_likely_forms``, ``cycles_from_phase``) and this module (``WearableCameraGaitEstimation``, the estimator), which
also exports the public names of the others.

Frames: world = local east-north-up (m), heading counter-clockwise from east. Body frame: origin on the ground below
the walker on the path (the state's ``x, y``), ``f`` forward along the heading, ``l`` to the left, ``u`` up.
Thigh frame (as :mod:`pdr.sim.gait`): x forward, y to the right, z along the thigh from hip to knee. Camera frame:
x = image right (u), y = image down (v), z = optical axis.
"""

from __future__ import annotations

import time

import numpy as np
import pandas as pd

from pdr.base import Algorithm
from pdr.errors import InputError, warn
from pdr.gait.camera_filter import cycles_from_phase, ekf_update, most_likely_forms, predict
from pdr.gait.camera_model import JOINTS, SIDES, TWO_PI, ThighCameraModel
from pdr.gait.camera_observation import joint_positions, observation_jacobian, project_points
from pdr.gait.camera_templates import MOCAP_COLUMNS, PARAMS, FourierFormTemplates, _numeric, body_frame_parameters, joint_columns

__all__ = [
    "JOINTS", "MIN_POINTS", "MOCAP_COLUMNS", "PARAMS", "SIDES", "STATE", "FourierFormTemplates", "ThighCameraModel",
    "WearableCameraGaitEstimation", "body_frame_parameters", "cycles_from_phase", "ekf_update", "joint_columns",
    "joint_positions", "most_likely_forms", "observation_jacobian", "predict", "project_points",
]

STATE = ("e_m", "n_m", "heading_rad", "phase_rad", "phase_rate_radps")
MIN_POINTS = 4  # fewer than this cannot fix a camera pose: the frame is predicted only


class WearableCameraGaitEstimation(Algorithm):
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
