"""Stride length by fitting the SLIP model's optical flow to the measured flow (Liu, MS thesis ch. 4)."""

from __future__ import annotations

import itertools
import math
import time

import numpy as np
import pandas as pd
from scipy.optimize import minimize

from pdr.base import Algorithm
from pdr.errors import InputError, warn
from pdr.schema import STRIDE_COLUMNS
from pdr.slip.model import HIP_HEIGHT_RATIO, SlipBody, simulate_flow, simulate_step, stride_kinematics
from pdr.step_length.models import LEVEL_REL_STD, height_cadence_params

SEGMENT_COLUMNS = ["t_start_s", "t_toe_off_s", "t_end_s"]
# the swing-clearance fixed point has converged when its last pass moves the stride by less than this fraction
# (well inside the model's own error, ``model_sigma_fraction``)
CLEARANCE_TOLERANCE = 0.02
# walking has double support, so each foot's stance is more than half the stride (Perry & Burnfield 2010, Gait Analysis,
# ch. 1: 60% at free speed, nearing 50% only where walking turns into running); a shorter measured stance means the
# "swing burst" is not a swing (e.g. the flow tracker locked onto the floor pattern through the next stance)
MIN_STANCE_FRACTION = 0.5
MAX_CLEARANCE_AMPLIFICATION = 2.0  # the fixed point may at most double the first pass's change of the stride
GAIN_STEP = 1.05  # relative step of the clearance stride in the finite difference of the fixed point's gain
# Thesis Table 2 (vx m/s, vy m/s, leg angle 10 deg, K); K read as tens of kN/m (its code uses 18,000 N/m).
TABLE2_STARTS = tuple((vx, vy, math.radians(10.0), k) for vx, vy, k in (
    (1.6, -0.5, 17000.0), (1.5, -0.5, 16000.0), (1.6, -0.5, 15000.0), (1.4, -0.5, 17000.0), (1.2, -0.5, 18000.0)))
BOUNDS = ((0.4, 2.5), (-1.0, 0.6), (math.radians(4.0), math.radians(30.0)), (3000.0, 40000.0))
GRID = ((0.8, 1.0, 1.2, 1.4, 1.6, 1.9), (-0.5, -0.2, 0.0), tuple(math.radians(d) for d in (10, 14, 18, 22)),
        (6000.0, 9000.0, 12000.0, 18000.0, 26000.0))


def segment_strides(t_s: np.ndarray, flow_pxps: np.ndarray, *, high_fraction: float = 0.4, low_fraction: float = 0.12,
                    min_stride_s: float = 0.6, max_stride_s: float = 2.2,
                    min_stance_fraction: float = MIN_STANCE_FRACTION) -> pd.DataFrame:
    """Cut the forward flow of the camera leg into strides, heel strike to heel strike.

    The swing of the camera leg is a burst of large positive flow; stance flow is near zero (the shank pivots
    about the contact point under the camera's optical axis). A burst is a run above ``high_fraction`` of the
    95th percentile; it starts (toe off) and ends (heel strike) where the flow crosses ``low_fraction`` of it.
    A stride whose stance (heel strike to toe off) is under ``min_stance_fraction`` of it is not a walking stride
    (``MIN_STANCE_FRACTION``): the flow or the cut failed there, and it is left out.
    Returns ``t_start_s, t_toe_off_s, t_end_s`` (one row per complete stride).
    """
    t = np.asarray(t_s, float)
    f = np.asarray(flow_pxps, float)
    ok = np.isfinite(f)
    empty = pd.DataFrame({c: np.zeros(0) for c in SEGMENT_COLUMNS})
    if ok.sum() < 10:
        return empty
    f = np.interp(t, t[ok], f[ok])
    f = np.convolve(np.pad(f, 1, mode="edge"), np.ones(3) / 3.0, mode="valid")
    ref = float(np.percentile(f, 95))
    if ref <= 0:
        return empty
    above = f > high_fraction * ref
    edges = np.flatnonzero(np.diff(above.astype(int)))
    starts = list(edges[~above[edges]] + 1)
    ends = list(edges[above[edges]] + 1)
    if above[0]:
        starts = [0] + starts
    if above[-1]:
        ends = ends + [len(f)]
    bursts = []
    for s, e in zip(starts, ends):
        if bursts and t[s] - t[bursts[-1][1] - 1] < 0.1:
            bursts[-1] = (bursts[-1][0], e)
        else:
            bursts.append((s, e))
    low = low_fraction * ref
    marks = []
    for s, e in bursts:
        if t[e - 1] - t[s] < 0.05 or s == 0 or e >= len(f):
            continue
        i = s
        while i > 0 and f[i] > low:
            i -= 1
        j = e - 1
        while j < len(f) - 1 and f[j] > low:
            j += 1
        if i == 0 or j == len(f) - 1:
            continue
        marks.append((t[i], t[j]))
    rows = []
    for (_, hs0), (to1, hs1) in zip(marks[:-1], marks[1:]):
        if min_stride_s <= hs1 - hs0 <= max_stride_s and hs0 + min_stance_fraction * (hs1 - hs0) <= to1 < hs1:
            rows.append((hs0, to1, hs1))
    return pd.DataFrame(rows, columns=SEGMENT_COLUMNS) if rows else empty


def swing_unsampled(who: str, what: str, rate_hz: float, segments: pd.DataFrame) -> bool:
    """True, with a warning from ``who``, when ``what`` (the flow, the frames) at ``rate_hz`` is below twice the
    cadence of the strides cut (``segments``): the swing is not sampled (Nyquist) and no stride can be read."""
    cadence_hz = 2.0 / float(np.median(segments["t_end_s"] - segments["t_start_s"]))  # steps per second
    if rate_hz >= 2.0 * cadence_hz:
        return False
    warn(f"{who}: {what} at {rate_hz:.1f} Hz, below twice the cadence ({cadence_hz:.2f} steps/s): the swing is not "
         "sampled; no stride estimated")
    return True


def _burst_start(t_s: np.ndarray, flow: np.ndarray, low_fraction: float = 0.12) -> float:
    """Time where the swing burst of one stride of flow starts, by the rule of :func:`segment_strides`."""
    ref = float(np.percentile(flow, 95))
    i = int(np.argmax(flow))
    while i > 0 and flow[i] > low_fraction * ref:
        i -= 1
    return float(t_s[i])


def _running_median(x: np.ndarray, half: int) -> np.ndarray:
    """Median of the finite values within ``half`` samples either side (NaN where there is none)."""
    x = np.asarray(x, float)
    out = np.full(len(x), np.nan)
    for j in range(len(x)):
        v = x[max(0, j - half):j + half + 1]
        v = v[np.isfinite(v)]
        if len(v):
            out[j] = float(np.median(v))
    return out


class SlipOpticalFlowStride(Algorithm):
    """Stride length of the camera leg by fitting SLIP-simulated optical flow to the measured flow.

    Parameters
    ----------
    thigh_length_m, shank_length_m, foot_length_m, mass_kg : SLIP body (thesis Table 1 as defaults).
    camera_from_knee_m : mount distance of the camera below the knee along the shank (L_cam).
    focal_px : focal length of the camera in pixels.
    swing_ratio : eta, shank swing peak over its toe-off angle (eq. 3.16).
    swing_peak_fraction : where in the swing the shank angle peaks (thesis Appendix E: 1/4).
    swing_profile : "parabola" (thesis eq. 3.17) or "heel" (heel path and inverse kinematics; default).
    swing_clearance_ratio : c in the peak heel lift of the "heel" swing, c x stride x (stride / leg length)
        (dimensionless: the lift over the leg length grows with the square of the stride over the leg length).
        0.04 is the best of 0.035, 0.04, 0.045, 0.05 and 0.055 on the tuning people of
        ``benchmarks/bench_leg_camera.py`` with ``clearance_from="cadence"`` (stride MAE 4.65, 4.21, 4.27, 4.54 and
        5.10%). With the former fixed point (``"flow"``), 0.05 was the best of 0.04, 0.045, 0.05 and 0.055
        (their knees drawn, the flow pre-blurred by a twelfth of a patch: stride MAE 5.1, 4.5, 4.4 and 4.8%); with
        the thesis' 1 px blur and every knee Winter's, 0.055 was the best of 0.05-0.07 (5.2, 4.7, 4.9, 5.2, 5.9%),
        and with the former heel height, which kept the bump to heel strike, 0.0175 (5.8%); the scale is that
        sensitive to it. The flow's own cost does not pin the
        clearance (fitting it per window picks near-zero lifts on long strides), so it is not fitted. A
        quadratic law keeps the fixed point of ``clearance_from="flow"`` stable for most bodies; where it is
        not, see :meth:`_clearance_from_flow`.
    clearance_from : the stride that sets the swing clearance. "cadence" (default): the stride a person of the
        body's height takes at the window's measured cadence (the pedometer rule of
        :meth:`pdr.step_length.RegressionStepLength.for_height`, height = leg length / 0.53; see
        :meth:`_clearance_from_cadence`); "flow": the stride measured from the flow (a fixed point over
        neighbouring windows, the default before 2026-12-06); "model": the fitted SLIP's own stride (that stride
        saturates near 1.0-1.2 m on rendered walks, so long strides were under-read). "cadence" and "flow" act
        with ``length_from="flow"`` and the "heel" swing only.
    clearance_iterations : fixed-point passes of ``clearance_from="flow"``.
    integral_weight : weight of the per-stride mean-flow difference (the image displacement of the stride,
        which fixes the stride length through f / D) relative to the sample-by-sample differences.
    strides_per_fit : strides fitted together (thesis: 2, assumed equal).
    length_from : "model": the fitted SLIP's stride length (eq. 4.3, the thesis); "flow": that length times the
        ratio of the measured to the simulated image displacement over the stride (the fitted model supplies the
        flow-to-metres scale f / D, the measurement the displacement; default, far less sensitive to the fit).
    scale_windows : with "flow", the metres-per-pixel scale of each window is the running median over this many
        neighbouring windows (1: each window its own).
    n_refine : best starts (grid and Table 2) refined by the local optimiser.
    max_evals : function evaluations per local refinement.
    duration_weight : weight of the squared log ratio of simulated to measured stride time in the cost
        (the time warp absorbs small mismatches; a large one means the fitted dynamics are wrong).
    length_scale : per-user factor on the model's stride length (1: none; see :func:`calibrated_length_scale`,
        which `pdr calibrate` runs on a walk of known length).
    model_sigma_fraction : model error floor of the stride sigma, as a fraction of the length (with
        ``clearance_from="flow"`` before the fixed point multiplies it by 1 / (1 - gain)). 0.04: the former 0.035
        times the RMS error over the RMS sigma, 1.14, of the tuning people of ``benchmarks/bench_leg_camera.py``
        with ``clearance_from="cadence"`` (89% of their errors within 2 sigma at 0.035); 0.035 was the former 0.05
        times 0.70 there once the flow was pre-blurred by a twelfth of a patch.
    min_quality : windows whose mean flow quality is below this give no stride (with a warning).
    multimodal_cost_ratio : refined starts whose cost is within this fraction of the best are other minima of the
        fit; half the spread of their strides joins the sigma.
    max_residual_fraction : a window whose RMS residual exceeds this fraction of the RMS measured flow failed
        (the model's own mismatch to a real gait is far above the flow noise, so the residual is judged against
        the flow: 0.23-0.41 on the tuning people of ``benchmarks/bench_leg_camera.py``, hence 0.5, which loses
        none of their strides), as does one whose solution
        lies at a bound of the parameters: a failed window gives no flow-to-metres scale; its strides take the
        scale of neighbouring windows that did not fail, or none.
    foot : "left" or "right", the leg carrying the camera.
    frame_interval_s : the camera's frame interval, over which the tracker measures each displacement; the model
        predicts that displacement of the floor point at the image centre (:func:`pdr.slip.model.simulate_flow`).
        None: the spacing of the flow samples (one per frame pair); 0: the instantaneous flow (the thesis).

    Attributes
    ----------
    strides_ : DataFrame ``t_start_s, t_end_s, foot, length_m, length_std_m, source`` (source "leg_camera").
    segments_ : the strides cut from the flow (``t_start_s, t_toe_off_s, t_end_s``).
    fits_ : one row per fitted window: ``flag`` ("" or the failures, "bound" / "residual"), ``spread_m`` (stride
        spread of the near-best minima), ``residual_fraction``, ``vx_mps, vy_mps, leg_angle_rad, stiffness_npm, cost, rms_pxps,
        sim_duration_s, meas_duration_s, length_m, length_std_m, m_per_px, meas_disp_px, time_s`` (and with
        ``clearance_from`` "cadence" or "flow" ``clearance_stride_m``, the stride that set the swing clearance,
        ``clearance_converged`` and ``clearance_gain`` g = d ln(stride) / d ln(clearance stride); with "flow" a
        gain of 0.5 or more, the fixed point doubling any error of the scale (``MAX_CLEARANCE_AMPLIFICATION``), or
        none computed, flags the fit "gain").
    frame_interval_s_ : the frame interval the model's flow was predicted over (``frame_interval_s``, or the flow's
        sample spacing; 0: the instantaneous flow).

    Notes
    -----
    Liu, MS thesis ch. 4 (eq. 4.1-4.3, Appendix E): the sum of squared differences between measured and simulated
    flow over two strides is minimised over the start velocity (vx, vy), the leg angle at heel strike and the
    leg stiffness, from several starts (Table 2, plus the best points of a coarse grid here); the stride length
    is the SLIP's from the fitted states. Beyond the thesis: the simulated stride is aligned with the measured
    one in time (heel strikes matched, toe off at the measured stance fraction, flow rescaled by the time warp),
    which removes the stance/swing timing mismatch it names as its main error; samples are weighted by the flow
    quality; the stride sigma comes from the Gauss-Newton curvature of the cost and the residual variance.

    Example
    -------
    >>> est = SlipOpticalFlowStride(camera_from_knee_m=0.25, focal_px=140).estimate(t_s, forward_flow_pxps)
    >>> est.strides_
    """

    def __init__(self, *, thigh_length_m: float = 0.5, shank_length_m: float = 0.6, foot_length_m: float = 0.2,
                 mass_kg: float = 50.0, camera_from_knee_m: float = 0.28, focal_px: float = 1340.0,
                 swing_ratio: float = 1.2, swing_peak_fraction: float = 0.25, swing_profile: str = "heel", swing_clearance_ratio: float = 0.04,
                 integral_weight: float = 10.0,
                 strides_per_fit: int = 2,
                 length_from: str = "flow", scale_windows: int = 5, n_refine: int = 2, max_evals: int = 60, duration_weight: float = 0.0, length_scale: float = 1.0,
                 model_sigma_fraction: float = 0.04, min_quality: float = 0.3, foot: str = "left",
                 clearance_from: str = "cadence", clearance_iterations: int = 4, multimodal_cost_ratio: float = 0.1,
                 max_residual_fraction: float = 0.5, frame_interval_s: float | None = None):
        self.thigh_length_m = thigh_length_m
        self.shank_length_m = shank_length_m
        self.foot_length_m = foot_length_m
        self.mass_kg = mass_kg
        self.camera_from_knee_m = camera_from_knee_m
        self.focal_px = focal_px
        self.swing_ratio = swing_ratio
        self.swing_peak_fraction = swing_peak_fraction
        self.swing_profile = swing_profile
        self.swing_clearance_ratio = swing_clearance_ratio
        self.integral_weight = integral_weight
        self.strides_per_fit = strides_per_fit
        self.length_from = length_from
        self.scale_windows = scale_windows
        self.n_refine = n_refine
        self.max_evals = max_evals
        self.duration_weight = duration_weight
        self.length_scale = length_scale
        self.model_sigma_fraction = model_sigma_fraction
        self.min_quality = min_quality
        self.foot = foot
        self.clearance_from = clearance_from
        self.clearance_iterations = clearance_iterations
        self.multimodal_cost_ratio = multimodal_cost_ratio
        self.max_residual_fraction = max_residual_fraction
        self.frame_interval_s = frame_interval_s

    # -- model ---------------------------------------------------------------------------------------------------
    @property
    def body(self) -> SlipBody:
        return SlipBody(self.thigh_length_m, self.shank_length_m, self.foot_length_m, self.mass_kg)

    def simulate(self, params, stance_fraction: float, dt_s: float = 0.004, clearance_stride_m: float | None = None):
        """(tau_s, flow_pxps, stride_length_m, stride_duration_s) of the SLIP stride, or None if it fails.

        ``clearance_stride_m``: the stride that sets the swing clearance (None: the SLIP's own stride)."""
        vx, vy, delta, k = params
        step = simulate_step(vx, vy, delta, k, self.body)
        if step is None or not 0.2 < step.duration_s < 1.5:
            return None
        kin = stride_kinematics(step, self.body, self.camera_from_knee_m, stance_fraction=stance_fraction,
                                swing_ratio=self.swing_ratio, swing_peak_fraction=self.swing_peak_fraction,
                                swing_profile=self.swing_profile,
                                swing_clearance_m=self._clearance_m(2.0 * step.length_m if clearance_stride_m is None
                                                                     else clearance_stride_m), dt_s=dt_s)
        if kin.heel_m[:, 1].min() < -0.1 or not np.isfinite(kin.distance_m).all():
            return None  # the swing foot goes through the floor, or the camera looks above the horizon
        interval = getattr(self, "frame_interval_s_", self.frame_interval_s)  # before a fit: as given
        return kin.t_s, simulate_flow(kin, self.focal_px, interval or None), kin.length_m, kin.duration_s

    def _clearance_m(self, stride_m: float) -> float:
        """Peak heel lift of the swing: ratio x stride x (stride / leg length) (grows with the square of the stride)."""
        return self.swing_clearance_ratio * stride_m * (stride_m / self.body.leg_length_m)

    def _residuals(self, sim, windows) -> np.ndarray | None:
        """Quality-weighted differences, the simulated stride warped onto each measured stride, and per stride
        the difference of the mean flows (weighted by ``integral_weight`` and the stride's sample count)."""
        if sim is None:
            return None
        tau, fsim, _, tsim = sim
        mean_sim = float(np.trapezoid(fsim, tau)) / tsim
        out = []
        for t, f, w, t0, tm, _ in windows:
            scale = tsim / tm
            r = np.sqrt(w) * (f - scale * np.interp((t - t0) * scale, tau, fsim))
            mean_meas = float(np.sum(w * f) / max(np.sum(w), 1e-9))
            out.append(r)
            out.append([math.sqrt(self.integral_weight * len(t)) * (mean_meas - mean_sim * scale)])
        return np.concatenate(out)

    # -- estimation ------------------------------------------------------------------------------------------------
    def estimate(self, t_s, forward_flow_pxps, quality=None, *, segments: pd.DataFrame | None = None
                 ) -> "SlipOpticalFlowStride":
        """Fit every window of ``strides_per_fit`` consecutive strides.

        Parameters
        ----------
        t_s : (N,) times of the flow samples (frame-pair mid times), strictly increasing.
        forward_flow_pxps : (N,) flow along the walking direction, positive forward (swing bursts positive).
        quality : (N,) per-sample quality in [0, 1] (None: all 1); NaN flow counts as quality 0.
        segments : strides to fit (``t_start_s, t_toe_off_s, t_end_s``), e.g. cut at IMU step instants;
            None: cut from the flow by :func:`segment_strides`.
        """
        t = np.asarray(t_s, float)
        f = np.asarray(forward_flow_pxps, float)
        q = np.ones_like(f) if quality is None else np.asarray(quality, float)
        if t.ndim != 1 or f.shape != t.shape or q.shape != t.shape:
            raise InputError(f"SlipOpticalFlowStride: expected t_s, flow and quality of one length, found {t.shape}, {f.shape}, {q.shape}")
        if len(t) > 1 and (not np.isfinite(t).all() or (np.diff(t) <= 0).any()):
            raise InputError("SlipOpticalFlowStride: expected finite, strictly increasing t_s, found unsorted, repeated or NaN times")
        if self.length_from not in ("flow", "model"):
            raise InputError(f"SlipOpticalFlowStride: expected length_from 'flow' or 'model', found {self.length_from!r}")
        if self.clearance_from not in ("cadence", "flow", "model"):
            raise InputError("SlipOpticalFlowStride: expected clearance_from 'cadence', 'flow' or 'model', found "
                             f"{self.clearance_from!r}")
        if self.frame_interval_s is not None and not (isinstance(self.frame_interval_s, (int, float))
                                                      and math.isfinite(self.frame_interval_s) and self.frame_interval_s >= 0):
            raise InputError(f"SlipOpticalFlowStride: expected frame_interval_s None or >= 0 s, found {self.frame_interval_s!r}")
        if self.foot not in ("left", "right"):
            raise InputError(f"SlipOpticalFlowStride: expected foot 'left' or 'right', found {self.foot!r}")
        q = np.where(np.isfinite(f) & np.isfinite(q), np.clip(q, 0.0, 1.0), 0.0)
        segs = segment_strides(t, np.where(q > 0, f, np.nan)) if segments is None else segments
        missing = [c for c in SEGMENT_COLUMNS if c not in segs.columns]
        if missing:
            raise InputError(f"segments: expected columns {', '.join(SEGMENT_COLUMNS)}, found {', '.join(segs.columns)}")
        self.segments_ = segs.reset_index(drop=True)
        self.strides_ = pd.DataFrame({c: pd.Series(dtype=object if c in ("foot", "source") else float) for c in STRIDE_COLUMNS})
        self.fits_ = pd.DataFrame()
        n = len(segs)
        per = max(1, int(self.strides_per_fit))
        if n < 1:
            warn("SlipOpticalFlowStride: no complete stride found in the flow; no stride estimated")
            return self
        if self.camera_from_knee_m >= self.shank_length_m:
            warn(f"SlipOpticalFlowStride: camera {self.camera_from_knee_m:g} m below the knee, the shank "
                 f"(knee to ground) is {self.shank_length_m:g} m: the camera would be under the floor; "
                 "no stride estimated")
            return self
        rate_hz = 1.0 / float(np.median(np.diff(t)))
        # one flow sample per frame pair: their spacing is the frame interval
        self.frame_interval_s_ = 1.0 / rate_hz if self.frame_interval_s is None else self.frame_interval_s
        if swing_unsampled("SlipOpticalFlowStride", "flow", rate_hz, segs):
            return self
        fnan = np.where(q > 0, f, 0.0)
        ok = q > 0
        # displacement integrals bridge short gaps of lost flow by interpolation (zeros would shorten the stride)
        fint = np.interp(t, t[ok], f[ok]) if ok.any() else fnan
        median_stance = float(np.median((segs.t_toe_off_s - segs.t_start_s) / (segs.t_end_s - segs.t_start_s)))
        grid = self._grid(median_stance)
        rows, fits = [], []
        for w0 in range(0, n, per):
            idx = list(range(w0, min(w0 + per, n)))
            if len(idx) < per and n >= per:
                idx = list(range(n - per, n))
            win = segs.iloc[idx]
            windows = []
            for _, s in win.iterrows():
                m = (t >= s.t_start_s) & (t <= s.t_end_s)
                windows.append((t[m], fnan[m], q[m], s.t_start_s, s.t_end_s - s.t_start_s, fint[m]))
            mean_q = float(np.mean(np.concatenate([w[2] for w in windows]))) if windows else 0.0
            if mean_q < self.min_quality:
                warn(f"SlipOpticalFlowStride: flow quality {mean_q:.2f} below {self.min_quality} for the strides "
                     f"from {win.t_start_s.iloc[0]:.2f} s to {win.t_end_s.iloc[-1]:.2f} s; no stride there")
                continue
            stance = float(np.mean((win.t_toe_off_s - win.t_start_s) / (win.t_end_s - win.t_start_s)))
            fit = self._fit_window(windows, stance, grid, median_stance)
            if fit is None:
                continue
            fits.append(fit)
            for i in idx:
                if w0 + per > n and i < w0:
                    continue  # the last, short window re-used earlier strides: keep their first estimate
                s = segs.iloc[i]
                disp = float(np.trapezoid(windows[idx.index(i)][5], windows[idx.index(i)][0]))
                rows.append((s.t_start_s, s.t_end_s, self.foot, fit["length_m"], fit["length_std_m"], "leg_camera",
                             len(fits) - 1, disp))
        if fits and self.length_from == "flow" and self.swing_profile == "heel":
            if self.clearance_from == "cadence":
                self._clearance_from_cadence(fits)
            elif self.clearance_from == "flow":
                self._clearance_from_flow(fits)
        failed = np.array([bool(f["flag"]) for f in fits])
        if failed.any():
            warn(f"SlipOpticalFlowStride: {failed.sum()} of {len(fits)} fits failed "
                 f"({', '.join(sorted({f['flag'] for f in fits if f['flag']}))}); their strides take the "
                 "scale of neighbouring fits or are left out")
        if rows and self.length_from == "flow":
            # each stride its own image displacement, at a flow-to-metres scale smoothed over neighbouring windows
            # (a running median: the body's geometry does not change from one stride to the next, single fits do);
            # failed fits give no scale
            half = max(0, int(self.scale_windows) // 2)
            scale = _running_median(np.where(failed, np.nan, [f["m_per_px"] for f in fits]), half)
            rel_sigma = _running_median(np.where(failed, np.nan, [f["length_std_m"] / f["length_m"] for f in fits]), half)
            for j, f in enumerate(fits):
                f["m_per_px_smoothed"] = scale[j]
            rows = [(a, b, c, scale[j] * disp, rel_sigma[j] * scale[j] * disp, src, j, disp)
                    for a, b, c, _, _, src, j, disp in rows if np.isfinite(scale[j])]
        else:
            rows = [r for r in rows if not failed[r[6]]]
        rows = [r[:6] for r in rows]
        if rows:
            self.strides_ = pd.DataFrame(rows, columns=STRIDE_COLUMNS)
        self.fits_ = pd.DataFrame(fits)
        return self

    def _clearance_from_cadence(self, fits: list[dict]) -> None:
        """Re-derive each window's flow-to-metres scale with the swing clearance of the stride that a person of the
        body's height takes at the window's cadence: 2 x 0.414 H x cadence / 110 steps/min (Sekiya & Nagasaki 1998,
        as :meth:`pdr.step_length.RegressionStepLength.for_height`), H = leg length / 0.53 (Winter).

        Unlike the fixed point of ``clearance_from="flow"``, the stride the camera measures does not feed back into
        its own scale, so an error of the fit is not multiplied by 1 / (1 - g). The clearance's own error is the
        walk ratio's: a person's stride at a cadence is known to ``LEVEL_REL_STD`` (8%) from the height, which moves
        the stride by g times that (g = :meth:`_clearance_gain`, 0.2-0.5): added to the sigma. On the leg-camera
        benchmark's tuning people: stride MAE 4.37 -> 4.21%, bias per speed +3.4 / -1.1 / -1.4 -> -0.1 / -0.8 /
        -1.8%, worst walk 9.3 -> 5.3% (the clearance ratio re-chosen, see ``swing_clearance_ratio``).
        """
        walk_ratio_m_per_hz = height_cadence_params(self.body.leg_length_m / HIP_HEIGHT_RATIO)["b_m_per_hz"]
        for f in fits:
            f["clearance_converged"], f["clearance_gain"] = True, 0.0
            if not (f["meas_disp_px"] > 0 and f["meas_duration_s"] > 0):
                continue
            stride_m = 2.0 * walk_ratio_m_per_hz * 2.0 / f["meas_duration_s"]  # two steps at the cadence (steps/s)
            if not self._rescale(f, stride_m):
                continue
            gain = self._clearance_gain(f)
            if np.isfinite(gain):
                f["clearance_gain"] = gain
                f["length_std_m"] = math.hypot(f["length_std_m"], max(gain, 0.0) * LEVEL_REL_STD * f["length_m"])

    def _clearance_from_flow(self, fits: list[dict]) -> None:
        """Re-derive each window's flow-to-metres scale with the swing clearance of the measured stride.

        The fit pins the SLIP's shape, not its stride: on rendered walks its leg angle stays near 14 deg and its own
        stride near 1.0-1.2 m at every speed (true 1.08-1.44 m), so a clearance taken from the SLIP stride is too low
        for long strides and jumps between fit minima. The clearance belongs to the stride the camera measures:
        the fitted states are re-simulated with the clearance of the flow stride (median over neighbouring
        windows, as for the scale), a few fixed-point passes. The metres per pixel the clearance sets must grow
        slower than the stride for the fixed point to be stable: with a law cubic in the stride it diverged on
        rendered walks, quadratic converges in 3-4 passes. At the fixed point s = m(s) d (m the metres per pixel,
        d the image displacement) an error e of the scale becomes e / (1 - g), g = d ln m / d ln s the gain
        (:meth:`_clearance_gain`): the sigma of a converged window is multiplied by 1 / (1 - g) (0.2-0.5 on the
        tuning people, the most for short legs with a camera low over the floor and long strides), and one whose
        1 / (1 - g) reaches ``MAX_CLEARANCE_AMPLIFICATION`` fails (flag "gain": no scale of its own).
        """
        half = max(0, int(self.scale_windows) // 2)
        start = [(f["length_m"], f["m_per_px"], f["length_std_m"]) for f in fits]
        previous = first = [f["length_m"] for f in fits]
        for k in range(max(0, int(self.clearance_iterations))):
            previous = [f["length_m"] for f in fits]
            if k == 1:
                first = previous
            lengths = np.array([np.nan if f["flag"] else f["length_m"] for f in fits]) / self.length_scale
            ref = _running_median(lengths, half)  # the length scale stays a pure factor
            for j, f in enumerate(fits):
                if np.isfinite(ref[j]) and f["meas_disp_px"] > 0:
                    self._rescale(f, ref[j])
        # a fixed point still moving in the last pass runs away (a camera low over the floor, long strides of a short
        # leg: the scale grows faster than the stride), and one that moved the stride over twice as far as its
        # first pass did multiplies the fit's error as much (x 1 / (1 - gain) for a map of that gain): keep the
        # SLIP's own clearance, with a sigma that covers the strides the passes went through
        for f, (length0, scale0, sigma0), prev, one in zip(fits, start, previous, first):
            moved = abs(f["length_m"] - prev) / max(abs(f["length_m"]), 1e-9)
            step = one - length0
            amplification = (f["length_m"] - length0) / step if abs(step) > 1e-3 * abs(length0) else 1.0
            f["clearance_converged"] = bool(moved <= CLEARANCE_TOLERANCE and amplification <= MAX_CLEARANCE_AMPLIFICATION)
            f["clearance_gain"] = 0.0
            if not f["clearance_converged"]:
                spread = abs(f["length_m"] - length0)
                f["length_m"], f["m_per_px"] = length0, scale0
                f["length_std_m"] = math.sqrt(sigma0 ** 2 + (0.5 * spread) ** 2)
                f["spread_m"] = max(f["spread_m"], spread)
            elif "clearance_stride_m" in f:
                # an error of the scale e becomes e / (1 - g) at the fixed point of gain g
                # (over MAX_CLEARANCE_AMPLIFICATION the window fails: the scale doubles any error of the fit)
                f["clearance_gain"] = gain = self._clearance_gain(f)
                if not np.isfinite(gain) or gain >= 1.0 - 1.0 / MAX_CLEARANCE_AMPLIFICATION:
                    f["flag"] = "+".join(x for x in (f["flag"], "gain") if x)
                if np.isfinite(gain) and gain < 1.0:
                    f["length_std_m"] /= 1.0 - max(gain, 0.0)

    def _simulated_stride(self, fit: dict, clearance_stride_m: float) -> tuple[float, float] | None:
        """(stride m, image displacement px) of a window's fitted SLIP re-simulated with the swing clearance of
        ``clearance_stride_m``; None when the simulation fails or does not move the image forward."""
        p = (fit["vx_mps"], fit["vy_mps"], fit["leg_angle_rad"], fit["stiffness_npm"])
        sim = self.simulate(p, fit["stance_fraction"], clearance_stride_m=clearance_stride_m)
        disp = float(np.trapezoid(sim[1], sim[0])) if sim is not None else 0.0
        return (sim[2], disp) if disp > 0 else None

    def _rescale(self, fit: dict, clearance_stride_m: float) -> bool:
        """Give a window the length, scale and sigma of the swing clearance of ``clearance_stride_m`` (its measured
        image displacement kept); False, the window unchanged, when that simulation fails."""
        sim = self._simulated_stride(fit, clearance_stride_m)
        if sim is None:
            return False
        length_m = sim[0] * fit["meas_disp_px"] / sim[1] * self.length_scale
        fit["length_std_m"] *= length_m / fit["length_m"]
        fit["length_m"], fit["m_per_px"] = length_m, length_m / fit["meas_disp_px"]
        fit["clearance_stride_m"] = clearance_stride_m
        return True

    def _clearance_gain(self, fit: dict) -> float:
        """d ln(stride) / d ln(clearance stride) of a window at its fixed point: how much a stride longer than the
        window's grows its own flow-to-metres scale through the swing clearance (finite difference of 5%)."""
        ref = fit["clearance_stride_m"]
        out = []
        for s in (ref, GAIN_STEP * ref):
            sim = self._simulated_stride(fit, s)
            if sim is None:
                return float("nan")
            out.append(sim[0] / sim[1])
        return math.log(out[1] / out[0]) / math.log(GAIN_STEP)

    def _grid(self, stance_fraction: float) -> list[tuple]:
        """Coarse grid of SLIP strides (the first stage of the multi-start)."""
        out = []
        for p in itertools.chain(itertools.product(*GRID), TABLE2_STARTS):
            sim = self.simulate(p, stance_fraction, dt_s=0.006)
            if sim is not None:
                out.append((p, sim))
        return out

    def _fit_window(self, windows, stance: float, grid, grid_stance: float) -> dict | None:
        t0 = time.perf_counter()
        tm_total = sum(w[4] for w in windows)

        def cost_of(sim):
            r = self._residuals(sim, windows)
            if r is None:
                return 1e30
            dur = sim[3]
            # the SLIP's own stride time must stay near the measured one (the warp only absorbs small mismatches)
            pen = (math.log(dur * len(windows) / tm_total)) ** 2
            return float(r @ r) * (1.0 + self.duration_weight * pen)

        ranked = sorted(grid, key=lambda ps: cost_of(ps[1]))[: max(1, self.n_refine)]
        # the measured toe off is where the flow burst starts; move the model's toe off by the lag between the two
        # in the best grid stride, so that both are cut the same way
        tau, fsim, _, tsim = ranked[0][1]
        lag = float(np.clip(_burst_start(tau, fsim) / tsim - grid_stance, -0.1, 0.1))
        stance = float(np.clip(stance - lag, 0.4, 0.75))
        lo = np.array([b[0] for b in BOUNDS])
        hi = np.array([b[1] for b in BOUNDS])
        scale = hi - lo

        def obj(z):
            p = lo + np.clip(z, 0, 1) * scale
            return cost_of(self.simulate(p, stance))

        best, results = None, []
        for p0, _ in ranked:
            z0 = (np.asarray(p0) - lo) / scale
            res = minimize(obj, z0, method="Nelder-Mead",
                           options=dict(maxfev=self.max_evals, xatol=1e-3, fatol=1e-6, initial_simplex=None))
            results.append(res)
            if best is None or res.fun < best.fun:
                best = res
        p = lo + np.clip(best.x, 0, 1) * scale
        sim = self.simulate(p, stance)
        if sim is None or best.fun >= 1e29:
            return None
        r = self._residuals(sim, windows)
        meas_disp = float(np.mean([np.trapezoid(w[5], w[0]) for w in windows]))  # image displacement per stride, px

        def stride_length(sm):
            if self.length_from == "model":
                return sm[2]  # eq. 4.3: the SLIP's own stride
            return sm[2] * meas_disp / max(float(np.trapezoid(sm[1], sm[0])), 1e-9)

        length = stride_length(sim)
        # Gauss-Newton covariance of the parameters -> sigma of the stride length
        n_res = len(r)
        s2 = float(r @ r) / max(n_res - 4, 1)
        jac, grad = np.zeros((n_res, 4)), np.zeros(4)
        for j in range(4):
            h = 1e-3 * scale[j]
            pj = p.copy()
            pj[j] = p[j] + h if p[j] + h <= hi[j] else p[j] - h
            simj = self.simulate(pj, stance)
            rj = self._residuals(simj, windows)
            if rj is None:
                continue
            d = pj[j] - p[j]
            jac[:, j] = (rj - r) / d
            grad[j] = (stride_length(simj) - length) / d
        jtj = jac.T @ jac
        try:
            var_fit = float(grad @ np.linalg.pinv(jtj, rcond=1e-10) @ grad) * s2
        except np.linalg.LinAlgError:
            var_fit = float("inf")
        length_m = length * self.length_scale
        # other minima of (nearly) the same cost: the spread of their strides is an error the curvature misses
        near = [length]
        for res in results:
            if res is not best and res.fun <= best.fun * (1.0 + self.multimodal_cost_ratio):
                sm = self.simulate(lo + np.clip(res.x, 0, 1) * scale, stance)
                if sm is not None:
                    near.append(stride_length(sm))
        spread_m = (max(near) - min(near)) * self.length_scale
        sigma = math.sqrt(min(var_fit, 1.0) * self.length_scale ** 2 + (self.model_sigma_fraction * length_m) ** 2
                          + (0.5 * spread_m) ** 2)
        w = np.concatenate([x[2] for x in windows])
        z = np.clip(best.x, 0, 1)
        samples = np.concatenate([np.r_[np.ones(len(x[0]), bool), False] for x in windows])  # not the mean terms
        rms = float(np.sqrt(float(r[samples] @ r[samples]) / max(w.sum(), 1e-9)))
        f_all = np.concatenate([x[1] for x in windows])
        rel_rms = rms / max(float(np.sqrt(np.sum(w * f_all ** 2) / max(w.sum(), 1e-9))), 1e-9)
        flags = []
        if np.any((z < 0.01) | (z > 0.99)):
            flags.append("bound")
        if rel_rms > self.max_residual_fraction:
            flags.append("residual")
        if not length_m > 0:  # the model stepped backwards or not at all: a broken flow, not a stride
            flags.append("length")
        return dict(flag="+".join(flags), spread_m=spread_m, residual_fraction=rel_rms,
                    vx_mps=p[0], vy_mps=p[1], leg_angle_rad=p[2], stiffness_npm=p[3], cost=float(best.fun),
                    rms_pxps=float(np.sqrt(float(r @ r) / max(w.sum(), 1e-9))), sim_duration_s=sim[3],
                    meas_duration_s=tm_total / len(windows), stance_fraction=stance, length_m=length_m,
                    length_std_m=sigma, m_per_px=length_m / meas_disp if meas_disp > 0 else float("nan"),
                    meas_disp_px=meas_disp,
                    time_s=time.perf_counter() - t0)


# Per-user length scale of the SLIP-OF strides: the spread of a walk's mean stride error between people and, within
# one person, from walk to walk (floor, camera set-up, pace). Both read on the tuning group of
# ``python -m benchmarks leg_camera`` (its rows "SD between them" and "SD within a person": 4 people x 3 walks,
# 3.2% and 1.4% with the swing clearance from the cadence (``clearance_from="cadence"``); 3.5% and 3.1% with the
# former fixed point, each person's knee drawn within the leg and the flow pre-blurred by a twelfth of a patch; 3.65%
# and 4.6% with the thesis' 1 px blur; 2.0% and 4.2% with every knee Winter's), before the calibrated test rows were run.
SCALE_PERSON_STD = 0.032
SCALE_WALK_STD = 0.014


def calibrated_length_scale(known_m, camera_m, known_std_m, walk, *, person_std: float = SCALE_PERSON_STD,
                            walk_std: float = SCALE_WALK_STD) -> tuple[float, float]:
    """A user's ``length_scale`` from stretches of known length: ``(scale, std)``.

    ``known_m`` (std ``known_std_m``) and ``camera_m`` (the camera strides' metres over the same stretches, the
    estimator's scale 1) per stretch, ``walk`` the walk (recording) of each. A hierarchical model: the person's scale
    ``s ~ N(1, person_std^2)``, each walk's camera off it by its own factor, ``N(1, walk_std^2)``
    (its floor, camera, pace), shared by the walk's stretches; so with the SLIP-OF's spreads (the defaults,
    :data:`SCALE_PERSON_STD`, :data:`SCALE_WALK_STD`) one walk moves the scale by 84% of what it reads
    (3.2^2 / (3.2^2 + 1.4^2)), and walks of several floors and paces pin a person's own scale down. The std is
    the person's scale's; a later walk adds its own ``walk_std``.
    """
    known_m, camera_m = np.asarray(known_m, float), np.asarray(camera_m, float)
    known_std_m, walk = np.asarray(known_std_m, float), np.asarray(walk)
    if not (len(known_m) == len(camera_m) == len(known_std_m) == len(walk)) or len(known_m) == 0:
        raise InputError("calibrated_length_scale: expected as many known and camera distances, stds and walks, "
                         f"at least one, found {len(known_m)}, {len(camera_m)}, {len(known_std_m)}, {len(walk)}")
    if not (np.all(known_m > 0) and np.all(camera_m > 0) and np.all(known_std_m >= 0)):
        raise InputError("calibrated_length_scale: expected positive distances and stds >= 0")
    _, index = np.unique(walk, return_inverse=True)
    known_w = np.bincount(index, known_m)
    camera_w = np.bincount(index, camera_m)
    std_w = np.sqrt(np.bincount(index, known_std_m ** 2) + (walk_std * camera_w) ** 2)
    info = float(np.sum(camera_w ** 2 / std_w ** 2)) + 1.0 / person_std ** 2
    scale = (float(np.sum(camera_w * known_w / std_w ** 2)) + 1.0 / person_std ** 2) / info
    return scale, 1.0 / math.sqrt(info)
