"""Leg-camera stride length from the camera's floor odometry, scaled by the leg's stance geometry.

The frames give the camera's motion over the floor in units of its own height, and the ratio of its heights from
frame to frame (:class:`pdr.flow.HomographyCameraMotion`); metres come from the leg: in mid-stance (Perry & Burnfield
2010: 12-31% of the gait cycle, after the loading response and before the heel rises) the foot is flat and the
shank pivots about the ankle, so the camera, ``camera_from_knee_m`` below the knee on the shank, is
``a + (S - a - L) cos(theta)`` over the floor (``S`` the knee's height, ``a`` the ankle's, ``theta`` the shank's
tilt, which the floor's normal gives), ``(S - a - L) sin(theta)`` ahead of the ankle in the direction the shank
leans. Each stride is the foot's displacement from one mid-stance to the next: the camera's, less the change of
that lever (which matters where the walker stops: a standing shank is near vertical).
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from pdr.base import Algorithm
from pdr.errors import InputError, warn
from pdr.schema import STRIDE_COLUMNS
from pdr.slip.fit import SEGMENT_COLUMNS, swing_unsampled

MIDSTANCE_PHASE = (0.12, 0.31)  # Perry & Burnfield 2010: mid-stance, fraction of the gait cycle from heel strike
# Per-user scale of the odometry strides: the spread of a person's mean stride error about none (their knee and mount
# as a user measures them: 3.5%) and of a walk's mean around its person's (0.7%), read on the tuning group of
# ``python -m benchmarks leg_camera`` (rows "people's mean stride error, RMS" and "SD within a person").
ODOMETRY_PERSON_STD = 0.035
ODOMETRY_WALK_STD = 0.007
ANCHOR_COLUMNS = ["t_s", "height_m", "tilt_rad", "log_offset", "ahead_m"]


class FloorOdometryStride(Algorithm):
    """Stride length of the camera leg: the camera's floor odometry from one mid-stance to the next, in metres.

    Parameters
    ----------
    shank_length_m : the knee's height over the floor (the SLIP's shank: knee to ankle plus the ankle's height).
    ankle_height_m : the ankle joint's height over the floor.
    camera_from_knee_m : mount distance of the camera below the knee along the shank.
    foot : "left" or "right", the leg carrying the camera.
    midstance_phase : (start, end) of the gait cycle's mid-stance, fractions from heel strike, where the camera's
        height is the leg's (Perry & Burnfield 2010: 0.12-0.31).
    length_scale : per-user factor on the strides (1: none; ``pdr calibrate`` fits it on a walk of known length).
    length_scale_std : the calibrated scale's std; None: uncalibrated, the person's spread ``person_rel_std``.
    person_rel_std : relative std of an uncalibrated person's scale (their knee and mount as measured).
    walk_rel_std : relative std of one stride's odometry (the height chain, the measured motion).
    max_bridged_fraction : a stride more than this fraction of whose travel falls on frame pairs not measured
        gives no stride (their motion is bridged from the neighbouring pairs' rate; half the bridged travel is
        added to the sigma).

    Attributes
    ----------
    strides_ : DataFrame ``t_start_s, t_end_s, foot, length_m, length_std_m, source`` (source "leg_camera").
    anchors_ : one row per stride cut: ``t_s`` (mid-stance), ``height_m`` (the leg's camera height there),
        ``tilt_rad``, ``log_offset`` (the measured height chain's offset to metres there), ``ahead_m`` (the camera
        ahead of the ankle).

    Notes
    -----
    Between two mid-stances the height chain (the cumulated log height ratios) drifts by the measurement's small
    bias; the two anchors' offsets are joined linearly in time. The strides are the ``segments`` given, heel strike
    to heel strike (:func:`pdr.pipelines.leg_camera.cut_strides` cuts them from the homographies' own flow); the last
    one of a walk, or one whose next stride was not cut, ends at the mid-stance after its own closing heel strike
    (the walker standing, or walking on), where the frames cover it.

    Example
    -------
    >>> est = FloorOdometryStride(shank_length_m=0.5, ankle_height_m=0.07, camera_from_knee_m=0.25)
    >>> est.estimate(motion, segments).strides_
    """

    def __init__(self, *, shank_length_m: float = 0.5, ankle_height_m: float = 0.07, camera_from_knee_m: float = 0.25,
                 foot: str = "left", midstance_phase: tuple[float, float] = MIDSTANCE_PHASE, length_scale: float = 1.0,
                 length_scale_std: float | None = None, person_rel_std: float = ODOMETRY_PERSON_STD,
                 walk_rel_std: float = ODOMETRY_WALK_STD, max_bridged_fraction: float = 0.15):
        self.shank_length_m = shank_length_m
        self.ankle_height_m = ankle_height_m
        self.camera_from_knee_m = camera_from_knee_m
        self.foot = foot
        self.midstance_phase = midstance_phase
        self.length_scale = length_scale
        self.length_scale_std = length_scale_std
        self.person_rel_std = person_rel_std
        self.walk_rel_std = walk_rel_std
        self.max_bridged_fraction = max_bridged_fraction

    def _check(self) -> None:
        if self.foot not in ("left", "right"):
            raise InputError(f"FloorOdometryStride: expected foot 'left' or 'right', found {self.foot!r}")
        for name in ("shank_length_m", "ankle_height_m", "camera_from_knee_m", "length_scale"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v > 0):
                raise InputError(f"FloorOdometryStride: expected a positive {name}, found {v!r}")
        lo, hi = self.midstance_phase
        if not 0.0 <= lo < hi <= 0.6:
            raise InputError(f"FloorOdometryStride: expected a midstance_phase 0 <= start < end <= 0.6, found {self.midstance_phase!r}")

    @property
    def lever_m(self) -> float:
        """The camera's distance from the ankle along the shank."""
        return self.shank_length_m - self.ankle_height_m - self.camera_from_knee_m

    def camera_height_m(self, tilt_rad: np.ndarray) -> np.ndarray:
        """The camera's height over the floor in mid-stance (foot flat, the shank ``tilt_rad`` from the vertical)."""
        return self.ankle_height_m + self.lever_m * np.cos(tilt_rad)

    @staticmethod
    def _warn_lost_stretches(t_pair: np.ndarray, measured: np.ndarray, segments: pd.DataFrame) -> None:
        """One warning naming the gaps between the strides cut where frame pairs were not measured: the flow there
        could not be cut into strides (no texture, blur, a lost view)."""
        ends, starts = segments["t_end_s"].to_numpy(float)[:-1], segments["t_start_s"].to_numpy(float)[1:]
        periods = (segments["t_end_s"] - segments["t_start_s"]).to_numpy(float)[:-1]
        lost = [(a, b) for a, b, p in zip(ends, starts, periods)
                if b - a > 0.1 * p and not measured[(t_pair > a) & (t_pair < b)].all()]
        if lost:
            where = ", ".join(f"{a:.2f}-{b:.2f} s" for a, b in lost)
            warn(f"FloorOdometryStride: no stride cut over {where}, where frame pairs are unmeasured (no texture, "
                 "blur, a lost view)")

    def estimate(self, motion: pd.DataFrame, segments: pd.DataFrame) -> "FloorOdometryStride":
        """Strides from the camera's ``motion`` (:attr:`pdr.flow.HomographyCameraMotion.motion_`) cut at ``segments``
        (``t_start_s, t_toe_off_s, t_end_s``, heel strike to heel strike of the camera leg)."""
        self._check()
        need = ["t_s", "dt_s", "height_log_ratio", "floor_x_per_height", "floor_y_per_height", "tilt_rad", "lean_x",
                "lean_y"]
        missing = [c for c in need if c not in motion.columns] + [c for c in SEGMENT_COLUMNS if c not in segments.columns]
        if missing:
            raise InputError(f"FloorOdometryStride: expected motion columns {', '.join(need)} and segment columns "
                             f"{', '.join(SEGMENT_COLUMNS)}, missing {', '.join(missing)}")
        self.strides_ = pd.DataFrame({c: pd.Series(dtype=object if c in ("foot", "source") else float) for c in STRIDE_COLUMNS})
        self.anchors_ = pd.DataFrame({c: np.zeros(0) for c in ANCHOR_COLUMNS})
        if self.lever_m <= 0:
            warn(f"FloorOdometryStride: camera {self.camera_from_knee_m:g} m below the knee, the shank (knee to ankle) "
                 f"is {self.shank_length_m - self.ankle_height_m:g} m: the mount is off the shank; no stride estimated")
            return self
        t_pair = motion["t_s"].to_numpy(float)
        dt = motion["dt_s"].to_numpy(float)
        log_ratio = motion["height_log_ratio"].to_numpy(float)
        floor_xy = motion[["floor_x_per_height", "floor_y_per_height"]].to_numpy(float)
        tilt = motion["tilt_rad"].to_numpy(float)
        measured = np.isfinite(log_ratio) & np.isfinite(floor_xy).all(axis=1)
        has_tilt = measured & np.isfinite(tilt)
        if len(segments) < 2 or measured.sum() < 10 or has_tilt.sum() < 2:
            warn(f"FloorOdometryStride: {len(segments)} strides cut, {int(measured.sum())} of {len(t_pair)} frame pairs "
                 "measured: no stride estimated")
            return self
        if swing_unsampled("FloorOdometryStride", "frames", 1.0 / float(np.median(dt)), segments):
            return self
        self._warn_lost_stretches(t_pair, measured, segments)
        # the walking direction on the floor: the principal axis of the camera's displacements, signed forward
        _, _, vt = np.linalg.svd(floor_xy[measured], full_matrices=False)
        ahead = vt[0] if np.nansum(floor_xy @ vt[0]) >= 0 else -vt[0]
        forward = floor_xy @ ahead
        lean = motion[["lean_x", "lean_y"]].to_numpy(float) @ ahead  # the optical axis' forward part, sin(tilt)
        rate = forward / dt  # heights per second; unmeasured pairs take their neighbours' rate and log-height rate
        rate = np.interp(t_pair, t_pair[measured], rate[measured])
        log_rate = np.interp(t_pair, t_pair[measured], log_ratio[measured] / dt[measured])
        t_frame = np.concatenate([[t_pair[0] - 0.5 * dt[0]], t_pair + 0.5 * dt])
        log_height = np.concatenate([[0.0], np.cumsum(log_rate * dt)])  # at the frames, up to an offset
        tilt_frame = np.interp(t_frame, t_pair[has_tilt], tilt[has_tilt])
        lean_frame = np.interp(t_frame, t_pair[has_tilt], lean[has_tilt])
        lo, hi = self.midstance_phase

        def anchor(heel_strike_s: float, period_s: float) -> tuple | None:
            """The mid-stance after a heel strike: (time, camera height m, tilt, chain offset, camera ahead of the
            ankle m), or None where the frames do not cover it."""
            m = (t_frame >= heel_strike_s + lo * period_s) & (t_frame <= heel_strike_s + hi * period_s)
            if m.sum() < 2 or t_frame[-1] < heel_strike_s + hi * period_s:
                return None
            h = self.camera_height_m(tilt_frame[m])
            t_mid = heel_strike_s + 0.5 * (lo + hi) * period_s
            ahead_m = -self.lever_m * float(np.interp(t_mid, t_frame, lean_frame))
            offset = float(np.median(np.log(h) - log_height[m]))
            return t_mid, float(np.median(h)), float(np.median(tilt_frame[m])), offset, ahead_m

        anchors = [anchor(s.t_start_s, s.t_end_s - s.t_start_s) for s in segments.itertuples(index=False)]
        self.anchors_ = pd.DataFrame([a for a in anchors if a is not None], columns=ANCHOR_COLUMNS)
        rel_std = math.hypot(self.person_rel_std if self.length_scale_std is None else self.length_scale_std,
                             self.walk_rel_std)
        rows, n_bridged = [], 0
        starts = segments["t_start_s"].to_numpy(float)
        for k, s in enumerate(segments.itertuples(index=False)):
            # a stride runs from its mid-stance to the next one's; the last stride of a walk, or one whose successor
            # was not cut, to the mid-stance after its own closing heel strike (standing still, or walking on)
            period = s.t_end_s - s.t_start_s
            follows = k + 1 < len(anchors) and abs(starts[k + 1] - s.t_end_s) <= 0.1 * period
            second = anchors[k + 1] if follows else anchor(s.t_end_s, period)
            if anchors[k] is None or second is None:
                continue
            (ta, _, _, oa, ahead_a), (tb, _, _, ob, ahead_b) = anchors[k], second
            p = (t_pair >= ta) & (t_pair < tb)
            w = np.clip((t_frame[:-1] - ta) / (tb - ta), 0.0, 1.0)  # each pair's first frame, between the anchors
            step_m = rate * dt * np.exp(log_height[:-1] + oa + w * (ob - oa))
            travel_m = float(np.sum(step_m[p]))
            if not travel_m > 0:
                continue
            # the part of the travel bridged over unmeasured pairs: a gap in the fastest swing weighs more than one
            # in stance
            bridged = float(np.sum(step_m[p & ~measured])) / travel_m
            if bridged > self.max_bridged_fraction:
                n_bridged += 1
                continue
            # the foot's stride: the camera's travel less the change of its lever ahead of the ankle
            length = (travel_m - (ahead_b - ahead_a)) * self.length_scale
            if not length > 0:
                continue
            std = length * math.hypot(rel_std, 0.5 * bridged)
            rows.append((s.t_start_s, s.t_end_s, self.foot, length, std, "leg_camera"))
        if n_bridged:
            warn(f"FloorOdometryStride: {n_bridged} strides had more than {self.max_bridged_fraction:.0%} of their travel "
                 "on frame pairs unmeasured (no texture, blur, a lost view); no stride there")
        if rows:
            self.strides_ = pd.DataFrame(rows, columns=STRIDE_COLUMNS)
        return self
