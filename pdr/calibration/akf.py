"""Adaptive Kalman calibration of the step length with GNSS (Ladetto et al. 2000, section 5)."""

from __future__ import annotations

from collections import deque

import numpy as np
import pandas as pd

from pdr.base import Algorithm
from pdr.calibration.segments import distance_segments, gnss_segments
from pdr.constants import GRAVITY_MPS2
from pdr.errors import InputError, collect_warnings, warn
from pdr.fusion._linear import bounded_map
from pdr.gait.forms import FROUDE_RUN
from pdr.step_length.models import LEG_LENGTH_PER_HEIGHT, POPULATION_HEIGHT_M, StepLengthModel

TRACE_COLUMNS = ("rec_index", "t_s", "model_step_m", "step_length_m", "step_length_std_m", "process_std_m")


class AdaptiveKalmanCalibration(Algorithm):
    """Per-user step length from GNSS: an adaptive Kalman filter on the step length, and the model's parameters.

    Parameters
    ----------
    measurement_std_m : floor of the measurement noise of one segment (the paper: 5 cm, DGPS); the GNSS part,
        ``sqrt(2) * h_acc / (n_steps * straightness)``, is added in quadrature.
    process_std_init_m : initial process noise per step (the paper: 10 cm).
    process_std_min_m : floor of the adapted process noise per step.
    innovation_window : number of recent innovations whose spread sets the process noise.
    segment_steps : steps per GNSS segment of the filter (a segment ends at the first usable fix this many steps
        after its start).
    model_segment_steps : the same for the segments the model's parameters are fitted on: longer chords average the
        slowly varying part of the GNSS error (a 20-step chord of a phone receiver is off by ~10%, a 60-step one ~5%).
    min_segment_steps, max_h_acc_m, assumed_h_acc_m, min_straightness, min_step_m, max_step_m : the segment gates
        of :func:`pdr.calibration.segments.gnss_segments` (``assumed_h_acc_m`` for fixes without ``h_acc_m``).
    min_freq_spread_hz : the segments see "several walking frequencies" when the standard deviation of their mean
        step frequencies reaches this (``updated_ = "all"``); otherwise the data fix mainly the level (``"level"``).
    outlier_h_acc_factor, gnss_smoothing_s : GNSS outlier test and local line fit before the segments
        (:func:`pdr.calibration.segments.clean_fixes`; 0 s = no smoothing).
    adapt_gnss_noise : scale the GNSS part of the measurement noise to the residuals of a first fit (see Notes).
    level_drift_std_m : standard deviation per step of the random walk of the model's level (m of step length);
        None or ``"estimate"`` (the spelling a TOML ``[calibration]`` section can give): estimated from the segments
        (see Notes). Default 0 (a steady level), chosen on the simulated tuning
        people (1.75 m, seeds 0-1, waist and hand, calibrated on known distances, the rest of the walk predicted:
        mean error 1.8% with 0, 2.0% estimated, 2.1% with 2 mm, 3.9% with 5 mm per step).

    Attributes
    ----------
    model_ : the calibrated model (same class as the one given; parameters and covariance updated).
    updated_ : what the data identified: ``"all"`` (several walking frequencies), ``"level"`` (one: the slope stays near
        its prior), or ``"none"`` (no usable segment, model unchanged).
    segments_ : every candidate GNSS segment of the filter (``gnss_segments`` columns + ``rec_index``,
        ``measured_std_m``, ``model_step_m``, ``innovation_m``, ``freq_hz``), with ``used`` and the rejection ``reason``.
    model_segments_ : the same for the (longer) segments of the model fit; those walked faster than the walk-run
        transition are not used (reason ``running``: the step models are walking models, :data:`pdr.gait.forms.FROUDE_RUN`, the walk-run transition).
    trace_ : per step, the filter's course: ``rec_index, t_s, model_step_m`` (uncalibrated prediction),
        ``step_length_m`` / ``step_length_std_m`` (filtered), ``process_std_m`` (adapted).
    step_length_m_, step_length_std_m_ : the filtered step length per step (all recordings, in order).
    n_steps_, distance_m_ : steps and GNSS metres inside the used segments of the model fit.
    gnss_noise_scale_ : factor on the GNSS part of the measurement noise, from the residuals of a first fit.
    level_drift_std_m_ : the random walk of the level per step used by the model fit (m; see Notes).

    Notes
    -----
    Ladetto et al. (2000), section 5. State: the step length, ``step(k) = step(k-1) + u(k-1)``; measurement:
    ``GPS distance / number of steps = step(k) + n(k)`` over a segment. Here the mean of u is the model's predicted
    change from step k-1 to k (zero for a model with A only, which is the paper's filter), so the state is the model's
    prediction plus a slowly varying correction, and a segment measures the mean of the state over its steps.
    Measurement noise: 5 cm plus the GNSS part ``sqrt(2) h_acc / (n straightness)``, scaled (0.25-2) so that the
    residuals of a first fit of the model match it (consecutive fixes share their slowly varying error, so h_acc
    alone overstates the error of a chord); process noise: 10 cm initially, then adapted from
    the distribution of the recent innovations v (innovation-based adaptive estimation, Mohamed & Schwarz 1999):
    ``q = max(q_min, mean(v^2 - R - P+) / steps between updates)`` -- larger residuals, larger process noise, so a
    change of pace is followed within a few segments and a steady pace is averaged over many.
    The model: every used segment is a linear measurement of the parameters (the mean over its steps of the model's
    design row), combined with the model's covariance as prior (Bayesian least squares, i.e. the regression of the
    filtered step lengths on the features with a prior). The prior is the body-based model of the person
    (:func:`pdr.step_length.body_model`), so the parameters shrink toward it: segments at one walking frequency fix
    the level there and leave the slope near its prior (the paper updates A only "until new frequencies can be
    observed"; the Bayesian update does the same in the directions the data do not see), several frequencies fix the
    slope too. The cadence slope is held at >= 0 (with a warning when the data ask for less).
    A walker's step can drift within a walk at the same cadence (stride length is long-range correlated: Terrier et
    al. 2005, "GPS analysis of human locomotion", Hum Mov Sci 24:97-115). The level (the model's first parameter)
    therefore follows a random walk of ``level_drift_std_m`` per step, and the model returned is its state at the end
    of the data (what follows), not the mean over them; with no drift this is the plain Bayesian fit. The drift is
    estimated from the differences between the segments (restricted maximum likelihood) with
    ``level_drift_std_m=None`` (``"estimate"``): the data must show it against their own noise (on steady simulated
    walkers it mostly comes out 0, but a change of pace that the model's cadence law does not follow exactly can pass
    for a drift).

    Example
    -------
    >>> from pdr.step_length import RegressionStepLength
    >>> akf = AdaptiveKalmanCalibration().fit(steps, gnss, RegressionStepLength.population())  # doctest: +SKIP
    >>> akf.model_, akf.updated_  # doctest: +SKIP
    """

    def __init__(self, *, measurement_std_m: float = 0.05, process_std_init_m: float = 0.10,
                 process_std_min_m: float = 0.002, innovation_window: int = 3, segment_steps: float = 20.0,
                 min_segment_steps: float = 8.0, max_h_acc_m: float = 10.0, assumed_h_acc_m: float = 5.0,
                 min_straightness: float = 0.7, min_step_m: float = 0.2, max_step_m: float = 1.6,
                 min_freq_spread_hz: float = 0.1, outlier_h_acc_factor: float = 5.0, gnss_smoothing_s: float = 2.0,
                 adapt_gnss_noise: bool = True, model_segment_steps: float = 60.0,
                 level_drift_std_m: float | str | None = 0.0):
        self.measurement_std_m = measurement_std_m
        self.process_std_init_m = process_std_init_m
        self.process_std_min_m = process_std_min_m
        self.innovation_window = innovation_window
        self.segment_steps = segment_steps
        self.min_segment_steps = min_segment_steps
        self.max_h_acc_m = max_h_acc_m
        self.assumed_h_acc_m = assumed_h_acc_m
        self.min_straightness = min_straightness
        self.min_step_m = min_step_m
        self.max_step_m = max_step_m
        self.min_freq_spread_hz = min_freq_spread_hz
        self.outlier_h_acc_factor = outlier_h_acc_factor
        self.gnss_smoothing_s = gnss_smoothing_s
        self.adapt_gnss_noise = adapt_gnss_noise
        self.model_segment_steps = model_segment_steps
        self.level_drift_std_m = level_drift_std_m

    def _check(self) -> None:
        if not isinstance(self.gnss_smoothing_s, (int, float)) or not self.gnss_smoothing_s >= 0:
            raise InputError(f"AdaptiveKalmanCalibration: expected gnss_smoothing_s >= 0 (s), found {self.gnss_smoothing_s!r}")
        for name in ("measurement_std_m", "process_std_init_m", "process_std_min_m", "segment_steps", "min_segment_steps",
                     "max_h_acc_m", "assumed_h_acc_m", "max_step_m", "outlier_h_acc_factor",
                     "model_segment_steps"):
            v = getattr(self, name)
            if not isinstance(v, (int, float)) or isinstance(v, bool) or not np.isfinite(v) or v <= 0:
                raise InputError(f"AdaptiveKalmanCalibration: expected {name} a positive number, found {v!r}")
        if not isinstance(self.innovation_window, int) or self.innovation_window < 1:
            raise InputError(f"AdaptiveKalmanCalibration: expected innovation_window a positive integer, found {self.innovation_window!r}")
        d = self.level_drift_std_m
        if not self._drift_estimated() and (not isinstance(d, (int, float)) or isinstance(d, bool) or not np.isfinite(d)
                                            or d < 0):
            raise InputError(f"AdaptiveKalmanCalibration: expected level_drift_std_m a number >= 0 (m per step), or "
                             f"\"estimate\" (or None) to estimate it, found {d!r}")
        if not 0 <= self.min_straightness <= 1:
            raise InputError(f"AdaptiveKalmanCalibration: expected min_straightness in [0, 1], found {self.min_straightness!r}")

    def fit(self, steps: pd.DataFrame | list[pd.DataFrame], gnss: pd.DataFrame | list[pd.DataFrame | None],
            model: StepLengthModel, subject: dict | list[dict | None] | None = None,
            distances: pd.DataFrame | list[pd.DataFrame | None] | None = None):
        """Calibrate ``model`` on one recording's steps and GNSS (``t_s, e_m, n_m[, h_acc_m]`` in the local frame), or
        on lists of them (one entry per recording; a None GNSS contributes no segment). ``distances``: per recording,
        None or a table of known walked distances (:func:`pdr.calibration.segments.distance_segments`: a walk of
        known length, landmarks, a reference trajectory), used instead of its GNSS. Returns self."""
        self._check()
        if not isinstance(model, StepLengthModel):
            raise InputError(f"AdaptiveKalmanCalibration: expected a step-length model, found {type(model).__name__}")
        steps_list = steps if isinstance(steps, list) else [steps]
        gnss_list = gnss if isinstance(gnss, list) else [gnss]
        subjects = subject if isinstance(subject, list) else [subject] * len(steps_list)
        known = distances if isinstance(distances, list) else [distances] * len(steps_list)
        if not (len(steps_list) == len(gnss_list) == len(subjects) == len(known)):
            raise InputError(f"AdaptiveKalmanCalibration: expected as many GNSS tables and subjects as steps tables, "
                             f"found {len(steps_list)} steps, {len(gnss_list)} GNSS, {len(subjects)} subjects")
        prepared = []
        for st, subj in zip(steps_list, subjects):
            x = model.design(st, subj) if len(st) else np.empty((0, len(model.theta_names)))
            prepared.append((st, x, np.clip(x @ model.theta, 0.0, None)))
        filt_segs, _ = self._segments(prepared, gnss_list, known, self.segment_steps)
        model_segs, design = self._segments(prepared, gnss_list, known, self.model_segment_steps)
        _reject_running(model_segs, subjects)
        used = model_segs["used"].to_numpy(bool)
        from_gnss = used & ~np.isfinite(model_segs["distance_std_m"].to_numpy(float))
        # measurement noise: 5 cm plus the GNSS part, scaled to the residuals of a first fit (consecutive fixes share
        # their slowly varying error, and smoothing removes white noise, so h_acc alone is pessimistic)
        self.gnss_noise_scale_ = 1.0
        self._set_noise(model_segs)
        if self.adapt_gnss_noise and from_gnss.sum() > len(model.theta_names) + 2:
            with collect_warnings():
                first, _ = self._update_model(model, design[used], model_segs[used])
            g = from_gnss
            resid = model_segs.loc[g, "measured_step_m"].to_numpy() - design[g] @ first.theta
            excess = resid ** 2 - self.measurement_std_m ** 2 - float(model.residual_std_m) ** 2 / model_segs.loc[g, "n_steps"]
            ratio = float(np.mean(excess) / np.mean(model_segs.loc[g, "gnss_std_m"] ** 2))
            self.gnss_noise_scale_ = float(np.clip(np.sqrt(max(ratio, 0.0)), 0.25, 2.0))
            self._set_noise(model_segs)
        self._set_noise(filt_segs)
        traces, innovations = [], []
        for r, (st, x, pred) in enumerate(prepared):
            segs = filt_segs[filt_segs["rec_index"] == r].reset_index(drop=True)
            trace, innov = self._filter(st["t_s"].to_numpy(float), pred, x, segs, model)
            traces.append(trace.assign(rec_index=r))
            innovations.append(innov)
        filt_segs["innovation_m"] = np.concatenate(innovations) if innovations else np.empty(0)
        self.segments_ = filt_segs.drop(columns="gnss_std_m")
        self.model_segments_ = model_segs.drop(columns="gnss_std_m")
        self.trace_ = pd.concat(traces, ignore_index=True)[list(TRACE_COLUMNS)]
        self.step_length_m_ = self.trace_["step_length_m"].to_numpy(float)
        self.step_length_std_m_ = self.trace_["step_length_std_m"].to_numpy(float)
        self.n_steps_ = float(model_segs.loc[used, "n_steps"].sum())
        self.distance_m_ = float(model_segs.loc[used, "distance_m"].sum())
        offset = np.concatenate([[0], np.cumsum([len(st) for st, _, _ in prepared])])
        segs = model_segs[used]
        mid = offset[segs["rec_index"].to_numpy(int)] + 0.5 * (segs["k_first"].to_numpy(float) + segs["k_last"].to_numpy(float))
        self.model_, self.updated_ = self._update_model(model, design[used], segs, steps_to_end=offset[-1] - mid)
        return self

    def _drift_estimated(self) -> bool:
        """Whether the level's drift is estimated from the segments (``level_drift_std_m`` None or "estimate")."""
        return self.level_drift_std_m is None or self.level_drift_std_m == "estimate"

    def _segments(self, prepared: list, gnss_list: list, known: list,
                  segment_steps: float) -> tuple[pd.DataFrame, np.ndarray]:
        """Segments of ``segment_steps`` over all recordings (their known distances instead where given), with each
        one's mean frequency, model step and design row."""
        tables, designs = [], []
        for r, ((st, x, pred), gn, dist) in enumerate(zip(prepared, gnss_list, known)):
            if dist is not None:
                segs = distance_segments(st, dist, min_segment_steps=self.min_segment_steps, min_step_m=self.min_step_m,
                                         max_step_m=self.max_step_m).assign(rec_index=r)
            else:
                segs = gnss_segments(st, gn if gn is not None else _NO_GNSS,
                                     **{**self._seg_args(), "segment_steps": segment_steps}).assign(rec_index=r,
                                                                                                     distance_std_m=np.nan)
            freq = st["step_freq_hz"].to_numpy(float) if "step_freq_hz" in st.columns else np.full(len(st), np.nan)
            spans = list(zip(segs["k_first"], segs["k_last"]))
            segs["freq_hz"] = [float(np.nanmean(freq[a:b + 1])) if b >= a and np.isfinite(freq[a:b + 1]).any() else np.nan
                               for a, b in spans]
            segs["model_step_m"] = [float(pred[a:b + 1].mean()) if b >= a else np.nan for a, b in spans]
            tables.append(segs)
            designs.append(np.array([x[a:b + 1].mean(axis=0) for a, b in spans]).reshape(-1, x.shape[1]))
        return pd.concat(tables, ignore_index=True), np.concatenate(designs)

    def _set_noise(self, segs: pd.DataFrame) -> None:
        """Per segment: the GNSS part of the noise of its measured step, and the whole (a known distance: its own)."""
        segs["gnss_std_m"] = np.sqrt(2.0) * segs["h_acc_m"] / (segs["n_steps"] * segs["straightness"])
        gnss_std = np.hypot(self.measurement_std_m, self.gnss_noise_scale_ * segs["gnss_std_m"])
        segs["measured_std_m"] = np.where(np.isfinite(segs["distance_std_m"]), segs["distance_std_m"] / segs["n_steps"],
                                          gnss_std)

    def _seg_args(self) -> dict:
        return dict(segment_steps=self.segment_steps, min_segment_steps=self.min_segment_steps, max_h_acc_m=self.max_h_acc_m,
                    assumed_h_acc_m=self.assumed_h_acc_m, min_straightness=self.min_straightness,
                    min_step_m=self.min_step_m, max_step_m=self.max_step_m,
                    outlier_h_acc_factor=self.outlier_h_acc_factor, smoothing_s=self.gnss_smoothing_s)

    @staticmethod
    def _prior_cov(model: StepLengthModel) -> np.ndarray:
        cov = model.covariance_matrix
        return np.asarray(type(model).preset["covariance"], float) if cov is None else cov

    def _prior_var(self, model: StepLengthModel, x: np.ndarray) -> float:
        """Initial variance of the state: the model's parameter uncertainty at the mean features (m²)."""
        if len(x) == 0:
            return self.process_std_init_m ** 2
        xm = x.mean(axis=0)
        return float(xm @ self._prior_cov(model) @ xm)

    def _filter(self, t_s: np.ndarray, pred: np.ndarray, x: np.ndarray, segs: pd.DataFrame,
                model: StepLengthModel) -> tuple[pd.DataFrame, np.ndarray]:
        """Run the filter over one recording's steps; returns the per-step trace and the innovation of each segment."""
        n = len(pred)
        est, std, qstd = np.empty(n), np.empty(n), np.empty(n)
        innov = np.full(len(segs), np.nan)
        used = segs.loc[segs["used"]].sort_values("k_last")
        by_step: dict[int, list] = {}
        for j, row in used.iterrows():
            by_step.setdefault(int(row.k_last), []).append((j, row))
        bias = 0.0  # state = pred(k) + bias(k): step(k) = step(k-1) + [pred(k) - pred(k-1)] + u(k-1)
        p = self._prior_var(model, x)
        q = self.process_std_init_m ** 2
        history: deque = deque(maxlen=self.innovation_window)
        p_post_prev, last_k = p, -1
        for k in range(n):
            if k > 0:
                p += q
            for j, row in by_step.get(k, []):
                z = float(row.measured_step_m)
                r = float(row.measured_std_m) ** 2
                v = z - (float(row.model_step_m) + bias)
                s = p + r
                gain = p / s
                bias += gain * v
                p = (1.0 - gain) * p
                innov[j] = v
                history.append((v * v - r - p_post_prev) / max(k - last_k, 1))
                q = max(self.process_std_min_m ** 2, float(np.mean(history)))
                p_post_prev, last_k = p, k
            est[k] = pred[k] + bias
            std[k] = np.sqrt(p + float(model.residual_std_m) ** 2)
            qstd[k] = np.sqrt(q)
        trace = pd.DataFrame({"t_s": t_s, "model_step_m": pred, "step_length_m": est, "step_length_std_m": std,
                              "process_std_m": qstd})
        return trace, innov

    def _update_model(self, model: StepLengthModel, x: np.ndarray, segs: pd.DataFrame,
                      steps_to_end: np.ndarray | None = None) -> tuple[StepLengthModel, str]:
        """Bayesian update of the parameters from the segments, the model's covariance as prior (parameters with zero
        prior variance are kept, those of ``model.nonnegative`` held at >= 0); returns the model and what the data
        identified: ``"all"`` (several walking frequencies), ``"level"`` (one: the slope stays near its prior),
        ``"none"``. With ``steps_to_end`` (per segment, steps from its middle to the end of the data) the level
        parameter follows a random walk (:meth:`_drift_covariance`) and the result is its state at the end."""
        self.level_drift_std_m_ = 0.0
        if len(segs) == 0:
            warn("calibration: no distance segment passed the gates (usable fixes, walking, straight); "
                 "the model is unchanged")
            return model.with_theta(model.theta, model.covariance_matrix), "none"
        theta0 = model.theta
        p = len(theta0)
        prior = self._prior_cov(model)
        n_steps = segs["n_steps"].to_numpy(float)
        w = 1.0 / (segs["measured_std_m"].to_numpy(float) ** 2 + float(model.residual_std_m) ** 2 / n_steps)
        z = segs["measured_step_m"].to_numpy(float)
        freq = segs["freq_hz"].to_numpy(float)
        several = p > 1 and np.isfinite(freq).sum() > 1 and float(np.nanstd(freq)) >= self.min_freq_spread_hz
        cols = [i for i in range(p) if prior[i, i] > 0]  # a parameter with zero prior variance is known exactly
        if not cols:
            warn("calibration: every parameter has zero prior variance in the model's covariance; "
                 "the model is unchanged")
            return model.with_theta(theta0, prior), "none"
        fixed = [i for i in range(p) if i not in cols]
        xf = x[:, cols]
        y = z - x[:, fixed] @ theta0[fixed]
        prior_inv = np.linalg.inv(prior[np.ix_(cols, cols)])
        noise = np.diag(1.0 / w)
        if steps_to_end is not None and cols[0] == 0:  # the level (the first parameter) may drift
            pc = prior[np.ix_(cols, cols)]
            others = pc[1:, 1:] - np.outer(pc[1:, 0], pc[0, 1:]) / pc[0, 0]  # the other parameters given the level
            drift, self.level_drift_std_m_ = self._drift_covariance(xf[:, 0], np.asarray(steps_to_end, float),
                                                                    xf[:, 1:] @ others @ xf[:, 1:].T + noise,
                                                                    y - xf @ theta0[cols])
            noise = noise + drift
        noise_inv = np.linalg.inv(noise)
        info = prior_inv + xf.T @ noise_inv @ xf
        rhs = prior_inv @ theta0[cols] + xf.T @ noise_inv @ y
        bounded = tuple(cols.index(model.theta_names.index(n)) for n in model.nonnegative
                        if model.theta_names.index(n) in cols)
        sol, post_cov = bounded_map(info, rhs, bounded)
        free_sol, _ = bounded_map(info, rhs)
        for j in bounded:
            if free_sol[j] < 0:
                warn(f"calibration: the distances ask for {model.theta_names[cols[j]]} = {free_sol[j]:.3g} "
                     "(step length falling as the cadence rises); held at 0")
        theta = theta0.copy()
        theta[cols] = sol
        cov = prior.copy()
        cov[np.ix_(cols, cols)] = post_cov
        return model.with_theta(theta, cov), "all" if several or p == 1 else "level"

    def _drift_covariance(self, level_design: np.ndarray, steps_to_end: np.ndarray, cov0: np.ndarray,
                          resid0: np.ndarray) -> tuple[np.ndarray, float]:
        """The segments' covariance (m²) from a random walk of the level: its increment per step has the standard
        deviation ``level_drift_std_m`` in step length; a segment ``s`` steps before the end differs from the level
        at the end by the walk over those steps, so two segments share the walk after the later one's middle
        (``q g_i g_j min(s_i, s_j)``, ``g`` the level's design value relative to its mean). None: the drift of
        largest restricted likelihood over 0 and 0.2 mm to 2 cm per step (adaptive estimation from the innovations,
        as Ladetto et al. 2000 adapt the filter's process noise): ``cov0`` is the segments' covariance without drift
        and with the level unknown, ``resid0`` their residuals from the prior model; the level is profiled out, so
        only the differences between segments speak for a drift (one segment: none). Returns the covariance and the
        drift."""
        g = level_design / np.mean(level_design)
        shape = np.outer(g, g) * np.minimum.outer(steps_to_end, steps_to_end)
        if not self._drift_estimated():
            return self.level_drift_std_m ** 2 * shape, float(self.level_drift_std_m)
        best, best_ll = 0.0, -np.inf
        for q_std in (0.0, *np.geomspace(2e-4, 0.02, 21)):
            c = cov0 + q_std ** 2 * shape
            sign, logdet = np.linalg.slogdet(c)
            if sign <= 0:
                continue
            ci_g, ci_r = np.linalg.solve(c, g), np.linalg.solve(c, resid0)
            info = float(g @ ci_g)
            r = resid0 - g * float(g @ ci_r) / info
            ll = -0.5 * (logdet + np.log(info) + r @ np.linalg.solve(c, r))
            if ll > best_ll + 1e-9:
                best, best_ll = float(q_std), ll
        return best ** 2 * shape, best


def _reject_running(segs: pd.DataFrame, subjects: list[dict | None]) -> None:
    """Mark the segments walked faster than the walk-run transition as not used for the model's parameters: the
    step models are walking models (the inverted pendulum does not hold in running, whose steps it reads ~18% short
    on the simulated 2.8 m/s runs). The transition is Froude number v^2 / (g l) = 0.5 (Alexander 1989, "Optimization
    and gaits in the locomotion of vertebrates"), l the leg length: the subject's ``leg_length_m``, else 0.53 x its
    ``height_m``, else of the population height (2.1 m/s at 1.70 m)."""
    if len(segs) == 0:
        return
    legs = []
    for subj in subjects:
        subj = subj or {}
        leg = subj.get("leg_length_m")
        legs.append(float(leg) if leg is not None else LEG_LENGTH_PER_HEIGHT * float(subj.get("height_m") or POPULATION_HEIGHT_M))
    v_run = np.sqrt(FROUDE_RUN * GRAVITY_MPS2 * np.asarray(legs)[segs["rec_index"].to_numpy(int)])
    speed = segs["measured_step_m"] * segs["n_steps"] / (segs["t_end_s"] - segs["t_start_s"])
    running = segs["used"].to_numpy(bool) & (speed > v_run).to_numpy(bool)
    segs.loc[running, "used"] = False
    segs.loc[running, "reason"] = [f"running ({v:.2f} m/s > {r:.2f} m/s, Froude {FROUDE_RUN:g})"
                                   for v, r in zip(speed[running], v_run[running])]


_NO_GNSS = pd.DataFrame({"t_s": pd.Series(dtype=float), "e_m": pd.Series(dtype=float), "n_m": pd.Series(dtype=float)})
