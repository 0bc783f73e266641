"""Body kinematics of walking and running: the gait model behind every simulated sensor.

The legs move by sagittal joint angles (hip, knee, ankle) given as Fourier series of the gait phase, scaled with
step length, with a speed-dependent stance fraction (about 60% of the cycle at a normal pace, less when faster, a
flight phase when running). The pelvis travels the planned steps with a within-step speed fluctuation and an
inverted-pendulum height; a swing leg follows the curves, a stance foot rolls on a rocker sole without slipping
and its leg reaches it by inverse kinematics. Speed, step frequency and step length come from a per-person
speed-step-length law that is not linear in frequency (:class:`GaitUser`), with individual offsets, body proportions,
cohorts (healthy, older, impaired slow gait) and per-step variability, never from the step-length models the
estimator fits.

Public objects
--------------
``Body`` (segment lengths from height and leg proportion), ``GaitUser`` (per-person coefficients, :data:`COHORTS`),
``plan_walk`` (heel-strike instants
and target step lengths from speed segments), ``WalkKinematics`` (positions and rotations at any time).

Frames: world = local east-north-up (m). Segment frames: ``pelvis`` and ``foot_*``: x forward, y left, z up;
``thigh_*`` and ``shank_*``: x forward, y right, z along the segment (hip to knee, knee to ankle).
"""

from __future__ import annotations

import dataclasses
from typing import Sequence

import numpy as np
import pandas as pd
from scipy.interpolate import CubicSpline

from pdr.constants import GRAVITY_MPS2
from pdr.errors import InputError, warn
from pdr.sim.route import Route

# ------------------------------------------------------------------------------------------------------------------
# Normative joint angles as Fourier series of the gait cycle (phase 0 = heel strike of that leg), degrees.
# Each tuple is (a0, (a1..a6), (b1..b6)) of  a0 + sum_k a_k cos(2 pi k q) + b_k sin(2 pi k q).
# Origin: least-squares 6-harmonic fits (max residual < 1 deg) to key points of the mean sagittal curves of
# normal adult walking at a natural pace in Winter (2009, Biomechanics and Motor Control of Human Movement, 4th ed.,
# ch. 4/7) and Perry & Burnfield (2010, Gait Analysis, ch. 4-6): hip +30 deg flexion at heel strike, -10 deg peak
# extension near 50%, +33 deg in late swing; knee 18 deg loading peak, ~5 deg in mid stance, 62 deg in swing;
# ankle -6 deg at loading, +10 deg dorsiflexion at 45%, -18 deg plantarflexion at push-off (62%); toe-off at 62%.
# Running: key points of Novacheck (1998, Gait & Posture 7:77-95, jogging): toe-off at 39%, knee 40 deg at
# mid stance and 95 deg in swing, hip 45 deg flexion in late swing, ankle 20 deg dorsiflexion in stance.
# ------------------------------------------------------------------------------------------------------------------
WALK_HIP_DEG = (14.43, (20.05, -3.44, -0.34, -0.44, -0.32, -0.04), (-3.45, -1.75, 1.29, 0.20, 0.08, 0.15))
WALK_KNEE_DEG = (22.97, (-1.70, -13.02, -2.11, -0.79, -0.93, -0.37), (-21.29, 6.16, 3.90, 0.66, -0.20, 0.76))
WALK_ANKLE_DEG = (-0.10, (-0.84, 1.41, -3.34, 2.13, -0.05, 0.24), (6.21, -6.97, 0.23, -0.84, -1.30, 0.33))
RUN_HIP_DEG = (19.80, (19.17, -3.99, -0.65, 0.64, -0.03, 0.07), (-15.91, 0.76, -0.07, 0.58, 0.00, -0.11))
RUN_KNEE_DEG = (47.90, (-11.78, -13.13, -2.47, 0.18, -0.72, 0.14), (-26.70, 15.50, -2.02, 0.08, -0.01, -0.19))
RUN_ANKLE_DEG = (2.45, (12.24, -8.79, -0.88, 0.60, -0.65, 0.05), (2.66, 7.16, -4.16, 0.99, -0.01, -0.18))
WALK_TOE_OFF = 0.62  # phase of toe-off in the walking curves above
RUN_TOE_OFF = 0.39  # and in the running curves
PELVIC_TILT_DEG = 10.0  # hip angles are relative to the pelvis, tilted forward: thigh angle = hip - tilt

# Anthropometry (Winter 2009, Table 4.1, fractions of body height H).
THIGH_RATIO = 0.245
SHANK_RATIO = 0.246
FOOT_RATIO = 0.152
ANKLE_HEIGHT_RATIO = 0.039
HIP_SEPARATION_RATIO = 0.095  # distance between the hip joint centres
HEEL_BEHIND_ANKLE = 0.23  # fraction of the foot length behind the ankle
ROCKER_RADIUS_FOOT = 1.5  # roll-over radius of the sole, in foot lengths (Hansen et al. 2004: ~0.3 leg length)

FOOT_FLAT_PHASE = (0.03, 0.07, 0.30, 0.12)  # (start, ramp, end, ramp) of foot flat, in phase of the walking curves
REF_FROUDE_SPEED = 0.45  # v / sqrt(g l) of a natural walking pace
GAIT_START_FRACTION = 0.5  # the pelvis moves about half a step on the first step of a bout and on the last
RUN_SPEED_MPS = (2.0, 2.6)  # walk-to-run blend of the curves, from fully walking to fully running
SEGMENTS = ("pelvis", "thigh_left", "shank_left", "foot_left", "thigh_right", "shank_right", "foot_right")
JOINTS = ("pelvis", "hip", "knee", "ankle", "heel", "toe")
SIDES = ("left", "right")


def fourier_deg(coef, q: np.ndarray) -> np.ndarray:
    """Evaluate a Fourier series ``(a0, (a_k), (b_k))`` at cycle phases ``q`` (0..1); degrees."""
    a0, a, b = coef
    out = np.full(np.shape(q), a0, float)
    for k, (ak, bk) in enumerate(zip(a, b), start=1):
        out += ak * np.cos(2 * np.pi * k * q) + bk * np.sin(2 * np.pi * k * q)
    return out


def _smoothstep(x: np.ndarray) -> np.ndarray:
    """Quintic 0->1 ramp with zero first and second derivatives at both ends."""
    x = np.clip(x, 0.0, 1.0)
    return x * x * x * (10.0 + x * (-15.0 + 6.0 * x))


def _warp(p: np.ndarray, stance: np.ndarray, curve_toe_off: float) -> np.ndarray:
    """Map the leg's phase p (toe-off at ``stance``) to the phase of a normative curve (toe-off at
    ``curve_toe_off``): q = p + c (1 - cos 2 pi p) / 2 pi, smooth, periodic, monotone for |c| < 1."""
    c = 2 * np.pi * (curve_toe_off - stance) / (1.0 - np.cos(2 * np.pi * stance))
    c = np.clip(c, -0.95, 0.95)
    return p + c * (1.0 - np.cos(2 * np.pi * p)) / (2 * np.pi)


@dataclasses.dataclass(frozen=True)
class Body:
    """Segment lengths from body height (Winter's ratios) and a per-person leg proportion.

    Attributes: ``thigh_m``, ``shank_m``, ``foot_m`` (heel to toe), ``ankle_height_m``, ``hip_separation_m``,
    ``leg_length_m`` (standing hip height = thigh + shank + ankle height, about 0.53 H). ``leg_scale`` multiplies
    thigh and shank: people of one height differ in relative leg length by about 2.5% (1 SD; Bogin & Varela-Silva
    2010, "Leg length, body proportion, and health").
    """

    height_m: float = 1.75
    leg_scale: float = 1.0

    def __post_init__(self):
        if not 1.0 <= self.height_m <= 2.3:
            raise InputError(f"subject.height_m: expected 1.0-2.3 m, found {self.height_m}")
        if not 0.85 <= self.leg_scale <= 1.15:
            raise InputError(f"subject leg_scale: expected 0.85-1.15, found {self.leg_scale}")

    thigh_m = property(lambda self: THIGH_RATIO * self.leg_scale * self.height_m)
    shank_m = property(lambda self: SHANK_RATIO * self.leg_scale * self.height_m)
    foot_m = property(lambda self: FOOT_RATIO * self.height_m)
    ankle_height_m = property(lambda self: ANKLE_HEIGHT_RATIO * self.height_m)
    hip_separation_m = property(lambda self: HIP_SEPARATION_RATIO * self.height_m)
    leg_length_m = property(lambda self: self.thigh_m + self.shank_m + self.ankle_height_m)

    def subject(self, mass_kg: float | None = None) -> dict[str, float]:
        """The ``[subject]`` table of ``meta.toml``."""
        out = {"height_m": self.height_m, "leg_length_m": self.leg_length_m, "thigh_length_m": self.thigh_m,
               "shank_length_m": self.shank_m, "foot_length_m": self.foot_m}
        if mass_kg is not None:
            out["mass_kg"] = float(mass_kg)
        return {k: round(v, 4) for k, v in out.items()}


LEG_SCALE_SD = 0.025  # relative leg length, 1 SD (Bogin & Varela-Silva 2010)


@dataclasses.dataclass(frozen=True)
class Cohort:
    """How a group walks relative to healthy adults: factors on the step length at a given dimensionless speed, on
    the per-step variability (length and duration), and on the vertical excursion of the pelvis. A group measured
    directly gives its own per-step variability instead of the factor: ``length_cv_range`` (each person's
    coefficient of variation of step length drawn uniformly in it, at every speed) and ``duration_cv`` (of the step
    duration)."""

    length_factor: float = 1.0
    variability_factor: float = 1.0
    arc_factor: float = 1.0
    length_cv_range: tuple[float, float] | None = None
    duration_cv: float | None = None


COHORTS = {
    # healthy adults: the reference
    "healthy": Cohort(),
    # older adults: about 10% shorter steps at the same speed, 30% more step-to-step variability (Winter et al. 1990,
    # "Biomechanical walking pattern changes in the fit and healthy elderly"; Hausdorff 2005, gait variability)
    "older": Cohort(length_factor=0.90, variability_factor=1.3),
    # impaired slow gait (multiple sclerosis, Parkinson's, after stroke; scenarios at 0.4-0.9 m/s): about 20% shorter
    # steps at the same speed, the cadence carrying more of the speed (Comber, Galvin & Coote 2017, meta-analysis of
    # gait in MS), and a 7% larger pelvis excursion for a given step: the inverted-pendulum factor fitted on people
    # with MS is 4.587/4 against 4.739/4 for all participants (Soltani et al. 2021), and (4.739 / 4.587)^2 = 1.07.
    # Per-step variability as measured on instrumented walkways: step-length CV 5.5% (EDSS 4.0-4.5) and 9.3% (EDSS
    # 5.0-5.5) in 381 people with MS (Kalron 2016, J Neurol Sci 361:1-6), 7.5% in the 90 stroke patients walking
    # faster than 0.34 m/s (Oken et al. 2008, Gait Posture 27:506-511); step-duration CV 6.3% (their single-support
    # time CV, the same walkers)
    "impaired": Cohort(length_factor=0.80, arc_factor=1.07, length_cv_range=(0.055, 0.093), duration_cv=0.063),
}


@dataclasses.dataclass(frozen=True)
class GaitUser:
    """Per-person gait coefficients (drawn once per simulated person).

    Step length follows a Froude-scaled power law of speed: L / l = c (v_hat / v_ref) ** beta with the dimensionless
    speed v_hat = v / sqrt(g l) (l = leg length, v_ref = 0.45, about 1.35 m/s for an adult). The exponent beta = 0.42
    is the preferred speed-step length relation of humans (Grieve 1968; Kuo 2001, "A simple model of bipedal walking
    predicts the preferred speed-step length relationship"), so with f = v / L the step length grows as
    f ** (beta / (1 - beta)) = f ** 0.72: concave in frequency, not a line, and each person has their own c and beta
    (5% and 0.04 SD: individual offsets and curvature). Per-step variability of length has a coefficient of variation
    ``cv_slow`` at 0.6 m/s falling to ``cv_fast`` at 1.7 m/s and above (Ladetto et al. 2000 observed about 15% and
    4%). ``arc_gain`` is the pelvis vertical excursion over the compass-gait arc: measured centre-of-mass excursions
    of 2.7 cm at 0.7 m/s to 4.8 cm at 1.6 m/s (Orendurff et al. 2004) are 0.5-0.65 of the arc; per person N(0.6, 0.04).
    """

    length_coef: float = 0.78  # step length / leg length at the reference speed
    length_exponent: float = 0.42
    cv_slow: float = 0.15
    cv_fast: float = 0.04
    cv_time: float = 0.02  # independent step-duration jitter
    step_width_m: float = 0.10
    sway_m: float = 0.025  # lateral pelvis sway amplitude
    pelvic_rotation_deg: float = 4.0
    obliquity_deg: float = 3.5
    pitch_deg: float = 1.5
    arc_gain: float = 0.6  # pelvis vertical excursion / compass-gait arc
    cohort: str = "healthy"

    @classmethod
    def draw(cls, rng: np.random.Generator, *, cv_slow: float | None = None, cv_fast: float | None = None,
             cohort: str = "healthy") -> "GaitUser":
        """A random person of ``cohort`` (population spreads of the coefficients). ``cv_slow`` / ``cv_fast`` given
        replace the cohort's step-length variability (default: 0.15 / 0.04 times its factor, or its own range)."""
        if cohort not in COHORTS:
            raise InputError(f"subject.cohort: expected one of {', '.join(COHORTS)}, found {cohort!r}")
        group = COHORTS[cohort]
        z = rng.standard_normal(8)
        extra = rng.standard_normal(1)
        v = group.variability_factor
        if group.length_cv_range is None:
            cv_own = (0.15 * v, 0.04 * v)
        else:
            lo, hi = group.length_cv_range
            cv_own = (float(rng.uniform(lo, hi)),) * 2
        cv_slow = cv_own[0] if cv_slow is None else cv_slow
        cv_fast = cv_own[1] if cv_fast is None else cv_fast
        if group.duration_cv is None:
            cv_time = 0.02 * v
        else:  # the part of the duration's variability not shared with the length (plan_walk: 0.3 of its CV)
            cv_time = float(np.sqrt(max(group.duration_cv ** 2 - (0.3 * cv_slow) ** 2, 0.0)))
        return cls(length_coef=float(0.78 * group.length_factor * (1 + 0.05 * z[0])),
                   length_exponent=float(np.clip(0.42 + 0.04 * z[1], 0.32, 0.52)),
                   cv_slow=float(cv_slow), cv_fast=float(cv_fast), cv_time=cv_time,
                   step_width_m=float(np.clip(0.10 + 0.02 * z[2], 0.05, 0.16)),
                   sway_m=float(np.clip(0.025 + 0.006 * z[3], 0.01, 0.04)),
                   pelvic_rotation_deg=float(np.clip(4.0 + 1.0 * z[4], 1.5, 7.0)),
                   obliquity_deg=float(np.clip(3.5 + 0.8 * z[5], 1.5, 6.0)), pitch_deg=float(np.clip(1.5 + 0.4 * z[6], 0.5, 3.0)),
                   arc_gain=float(np.clip(group.arc_factor * (0.6 + 0.04 * extra[0]), 0.4, 0.75)), cohort=cohort)

    def step_length_m(self, speed_mps, leg_length_m: float):
        v_hat = np.maximum(np.asarray(speed_mps, float), 0.05) / np.sqrt(GRAVITY_MPS2 * leg_length_m)
        return leg_length_m * self.length_coef * (v_hat / REF_FROUDE_SPEED) ** self.length_exponent

    def step_freq_hz(self, speed_mps, leg_length_m: float):
        return np.maximum(np.asarray(speed_mps, float), 0.05) / self.step_length_m(speed_mps, leg_length_m)

    def length_cv(self, speed_mps):
        return np.interp(speed_mps, [0.6, 1.7], [self.cv_slow, self.cv_fast])


def stance_fraction(speed_mps) -> np.ndarray:
    """Stance as a fraction of the gait cycle: ~0.64 slow, 0.60 at 1.5 m/s (walking); 0.40 falling to 0.32 (running)."""
    v = np.asarray(speed_mps, float)
    walk = np.clip(0.62 - 0.05 * (v - 1.3), 0.57, 0.68)
    run = np.clip(0.40 - 0.03 * (v - 2.6), 0.30, 0.42)
    w = run_weight(v)
    return (1 - w) * walk + w * run


def run_weight(speed_mps) -> np.ndarray:
    """0 = walking curves, 1 = running curves; smooth in between."""
    return _smoothstep((np.asarray(speed_mps, float) - RUN_SPEED_MPS[0]) / (RUN_SPEED_MPS[1] - RUN_SPEED_MPS[0]))


@dataclasses.dataclass
class Bout:
    """One walking bout: heel strikes ``t_s[0..n]`` (the first is the start from standing, not a step; the last
    brings the feet together), gait phase at each (+0.5 per step; integer = left heel strike), target step
    lengths and the nominal speed of each step (``n`` values)."""

    t_s: np.ndarray
    phase: np.ndarray
    target_length_m: np.ndarray
    speed_mps: np.ndarray


def plan_walk(segments: Sequence[tuple[float, float]], user: GaitUser, body: Body, rng: np.random.Generator,
              t0_s: float = 0.0) -> list[Bout]:
    """Heel-strike instants and target step lengths for consecutive speed segments ``(duration_s, speed_mps)``.

    A speed of 0 is a stop (standing). Consecutive moving segments form one bout; each step's duration is
    1 / f(v) and its length L(v) with per-step variability (partly shared with the duration: longer steps take a
    little longer); the first and last steps of a bout move the pelvis half as far. A bout shorter than three
    steps is spent standing.
    """
    bouts: list[Bout] = []
    t = t0_s
    phase = 0.0
    moving: list[tuple[float, float, float]] = []  # (start, end, speed)

    def close(run):
        nonlocal phase
        if not run:
            return
        tb, te = run[0][0], run[-1][1]
        starts = np.array([r[0] for r in run])
        speeds = np.array([r[2] for r in run])
        times, lengths, vs = [tb], [], []
        tk = tb
        while True:
            v = float(speeds[np.searchsorted(starts, tk, side="right") - 1])
            f = float(user.step_freq_hz(v, body.leg_length_m))
            cv = float(user.length_cv(v))
            eps, eta = rng.standard_normal(2)
            dur = (1.0 / f) * float(np.clip(1.0 + 0.3 * cv * eps + user.cv_time * eta, 0.6, 1.5))
            if tk + dur > te:
                break
            tk += dur
            times.append(tk)
            lengths.append(float(user.step_length_m(v, body.leg_length_m)) * float(np.clip(1.0 + cv * eps, 0.4, 1.8)))
            vs.append(v)
        if len(times) < 4:
            warn(f"walk: the moving segments from {tb:.1f} s to {te:.1f} s are too short for 3 steps; "
                 f"the person stands instead")
        else:
            n = len(times) - 1
            lengths[0] *= GAIT_START_FRACTION  # from standing, and back to feet together
            lengths[-1] *= GAIT_START_FRACTION
            bouts.append(Bout(np.array(times), phase + 0.5 * np.arange(n + 1), np.array(lengths), np.array(vs)))
            phase += 0.5 * n

    for duration, speed in segments:
        if speed > 0:
            moving.append((t, t + duration, float(speed)))
        else:
            close(moving)
            moving = []
        t += duration
    close(moving)
    return bouts


STEP_LENGTH_REF_RATIO = 0.40  # step length (fraction of height) at which the normative curves are used unscaled
SPEED_FLUCTUATION = 0.08  # forward speed fluctuation within a step, fraction of the mean (max at heel strike)
TOUCH_DOWN_PHASE = 0.06  # fraction of the cycle over which a landing foot settles onto its footprint
LIFT_OFF_PHASE = 0.12
WALK_DROP_M = 0.02  # mean lowering of the hip in mid stance (knee flexion), walking
WALK_LOW_PHASE = 0.04  # the pelvis is lowest this fraction of a stride after heel strike
RUN_DROP_M = 0.05  # running: knee flexion of ~40 deg in mid stance
RUN_ARC_GAIN = 0.4  # running vertical excursion ~7-9 cm (Cavanagh & Lafortune 1980)
IMPACT_TAU_S = 0.025  # heel-strike transient at the trunk: u(x) = x^2 exp(-x), x = time since contact / tau
IMPACT_ACC_MPS2 = (2.0, 1.5)  # its peak vertical acceleration = a + b * speed (m/s²); forward braking half of it
MAX_REACH = 0.998  # a swinging leg never straightens fully (knee >= ~4 deg); beyond, the foot is pulled in smoothly
REACH_SOFTNESS_M = 0.004  # and over which a leaving foot blends from its stance pose into the swing curves
MAX_REACH_ROLL_RAD = 0.3  # a planted foot beyond the straight leg's reach rolls forward (heel rise) by at most this
REACH_ROLL_SLOPE_M = 0.03  # rolling fully replaces the pull when it brings the ankle >= 3 cm nearer the hip per rad
REACH_ROLL_END = 0.8  # fraction of stance from which push-off takes over (the planted weight is 0 at toe-off)


class _BoutCurves:
    """Smooth per-bout functions of time: gait phase, pelvis path length, amplitude, nominal speed, envelope."""

    def __init__(self, bout: Bout, s0_m: float, step_ref_m: float):
        t = bout.t_s
        self.t0, self.t1, self.tn1, self.tn = t[0], t[1], t[-2], t[-1]
        self.phase = CubicSpline(t, bout.phase)
        self.phase_end = float(bout.phase[-1])
        self.s = CubicSpline(t, s0_m + np.concatenate([[0.0], np.cumsum(bout.target_length_m)]), bc_type="clamped")
        self.s_end = float(self.s(t[-1]))
        mid = 0.5 * (t[1:] + t[:-1])
        self._mid = mid
        amp = bout.target_length_m / step_ref_m
        amp[0], amp[-1] = amp[min(1, len(amp) - 1)], amp[max(len(amp) - 2, 0)]
        self.amp = CubicSpline(mid, amp, bc_type="clamped")
        self.speed = CubicSpline(mid, bout.speed_mps, bc_type="clamped")

    def envelope(self, t):
        return _smoothstep((t - self.t0) / (self.t1 - self.t0)) * (1.0 - _smoothstep((t - self.tn1) / (self.tn - self.tn1)))

    def clip_mid(self, t):
        return np.clip(t, self._mid[0], self._mid[-1])


class WalkKinematics:
    """Full-body walking kinematics along a route, evaluated at any times.

    Parameters
    ----------
    body : segment lengths.
    user : per-user gait coefficients.
    bouts : from :func:`plan_walk` (heel-strike instants, target step lengths).
    route : the path; the walk starts standing at path length 0.

    Attributes
    ----------
    heel_strikes : DataFrame ``t_s, foot, bout`` of the real foot contacts (the true steps), in time order.
    duration_s : end of the last bout (the recording may continue standing).

    Methods: ``joint_positions_m(t_s)`` -> dict of (N, 3) world arrays for ``pelvis`` and
    ``hip/knee/ankle/heel/toe_<side>``; ``segment_rotation(t_s, segment)`` -> (N, 3, 3) segment-to-world;
    ``pelvis_state(t_s)``.

    Notes
    -----
    The pelvis moves along the route by a C2 spline through its positions at the heel strikes (spaced by the
    planned step lengths), with a within-step speed fluctuation (fastest at heel strike, slowest in mid stance)
    and a heel-strike transient. Its height follows an inverted-pendulum arc (compass-gait excursion
    l - sqrt(l^2 - (L/2)^2) scaled by the person's ``arc_gain`` for the determinants of gait; lowest just after heel
    strike), or when
    running is lowest in mid stance and highest in flight. Pelvic rotation, obliquity and tilt oscillate with the
    gait phase. Joint angles are Fourier series of normative walking and running curves (constants above),
    blended by speed, phase-warped to the stance fraction, and scaled about the standing posture by the step
    length and by an envelope that starts and ends each bout from standing. Swing legs follow the curves (forward
    kinematics from the hip). A stance foot rolls without slipping on a circular rocker sole (Hansen, Childress &
    Knox 2004, roll-over shapes) with its pitch from the curves, lying flat from the end of loading to heel rise;
    the leg reaches it by two-link inverse kinematics (so stance hip and knee angles follow from the geometry); where
    the straight leg is too short for the prescribed pelvis, the heel rises earlier (the foot never slides).
    Lift-off and touch-down blend the stance and swing ankle paths in position and velocity. Lateral: pelvis sway
    toward the stance side, feet on lanes half a step width either side of the route.

    Example
    -------
    >>> kin = WalkKinematics.steady(speed_mps=1.3, duration_s=10.0, seed=1)
    >>> kin.joint_positions_m(np.array([2.0, 3.0]))["ankle_left"].shape
    (2, 3)
    """

    def __init__(self, body: Body, user: GaitUser, bouts: list[Bout], route: Route):
        if not bouts:
            raise InputError("walk: expected at least one walking bout of 3 steps or more, found none")
        self.body, self.user, self.route = body, user, route
        self.bouts = bouts
        self.duration_s = float(bouts[-1].t_s[-1])
        b = body
        self._R = ROCKER_RADIUS_FOOT * b.foot_m
        x_heel, x_toe = -HEEL_BEHIND_ANKLE * b.foot_m, (1 - HEEL_BEHIND_ANKLE) * b.foot_m
        self._C = np.array([x_heel + 0.55 * b.foot_m, -b.ankle_height_m + self._R])
        self._g_heel = float(np.arcsin((self._C[0] - x_heel) / self._R))
        self._g_toe = float(np.arcsin((self._C[0] - x_toe) / self._R))
        self._heel_f = self._C + self._R * np.array([-np.sin(self._g_heel), -np.cos(self._g_heel)])
        self._toe_f = self._C + self._R * np.array([-np.sin(self._g_toe), -np.cos(self._g_toe)])
        self._bout_t0 = np.array([bt.t_s[0] for bt in bouts])
        step_ref = STEP_LENGTH_REF_RATIO * b.height_m
        self._curves = []
        s0 = 0.0
        for bt in bouts:
            c = _BoutCurves(bt, s0, step_ref)
            self._curves.append(c)
            s0 = c.s_end
        ev_t = np.concatenate([bt.t_s[1:] for bt in bouts])
        ev_phase = np.concatenate([bt.phase[1:] for bt in bouts])
        ev_leg = np.round(2 * ev_phase).astype(int) % 2  # 0 = left (integer phase), 1 = right
        self._hs_t = ev_t
        self.heel_strikes = pd.DataFrame({"t_s": ev_t, "foot": np.where(ev_leg == 0, "left", "right"),
                                          "bout": np.concatenate([np.full(len(bt.t_s) - 1, i) for i, bt in enumerate(bouts)])})
        # Footprints: where each landing foot's contact point is at its heel strike (forward kinematics of the
        # swing leg from the prescribed pelvis), and how far above the ground the curves put it then (the foot
        # settles over TOUCH_DOWN_PHASE). Index 0: standing before the first step.
        stand = self._fk(self._state(np.array([-1e6])), 0)
        self._fp_t, self._fp_s, self._fp_gc, self._fp_dh = {}, {}, {}, {}
        for leg in (0, 1):
            tt = ev_t[ev_leg == leg]
            st = self._state(tt)
            fk = self._fk(st, leg)
            off = self._pelvis_offsets(st)
            self._fp_t[leg] = np.concatenate([[-np.inf], tt])
            self._fp_s[leg] = np.concatenate([stand["contact"][:, 0], self._pelvis_s(tt, st) + off[f"fwd{leg}"] + fk["contact"][:, 0]])
            self._fp_gc[leg] = np.concatenate([stand["gc"], fk["gc"]])
            height = self._pelvis_h(tt, st) + off[f"up{leg}"] + fk["contact"][:, 1] * np.cos(self._tilt(fk, off, leg))
            self._fp_dh[leg] = np.concatenate([[0.0], height])

    # ---------------------------------------------------------------------------------------------------------
    @classmethod
    def steady(cls, *, speed_mps: float = 1.3, duration_s: float = 20.0, height_m: float = 1.75, seed: int = 0,
               standing_s: float = 1.0, heading_rad: float = 0.0) -> "WalkKinematics":
        """A straight walk at one speed (standing ``standing_s`` before and after), for renderers and tests."""
        rng = np.random.default_rng(seed)
        body = Body(height_m)
        user = GaitUser.draw(rng)
        bouts = plan_walk([(standing_s, 0.0), (duration_s, speed_mps), (standing_s, 0.0)], user, body, rng)
        return cls(body, user, bouts, Route.straight(speed_mps * duration_s * 1.5 + 50.0, heading_rad))

    # ---------------------------------------------------------------------------------------------------------
    def _state(self, t: np.ndarray) -> dict[str, np.ndarray]:
        """Phase (strides), its rate, envelope, amplitude and nominal speed at times t (standing between bouts)."""
        t = np.asarray(t, float)
        b = np.searchsorted(self._bout_t0, t, side="right") - 1
        k = np.searchsorted(self._hs_t, t, side="right") - 1
        since = np.where(k >= 0, t - self._hs_t[np.maximum(k, 0)], np.inf)
        out = {"t": t, "bout": b, "phase": np.zeros_like(t), "env": np.zeros_like(t), "amp": np.ones_like(t),
               "speed": np.ones_like(t), "rate": np.zeros_like(t), "since_hs": since}
        for i, c in enumerate(self._curves):
            m = b == i
            if not m.any():
                continue
            tt = t[m]
            inside = tt <= c.tn
            tc = np.minimum(tt, c.tn)
            out["phase"][m] = np.where(inside, c.phase(tc), c.phase_end)
            out["rate"][m] = np.where(inside, c.phase(tc, 1), 0.0)
            out["env"][m] = np.where(inside, c.envelope(tt), 0.0)
            out["amp"][m] = c.amp(c.clip_mid(tt))
            out["speed"][m] = np.maximum(c.speed(c.clip_mid(tt)), 0.05)
        return out

    def _pelvis_s(self, t: np.ndarray, st: dict) -> np.ndarray:
        """Pelvis path length: the bout's spline plus the within-step fluctuation."""
        s = np.zeros_like(t)
        for i, c in enumerate(self._curves):
            m = st["bout"] == i
            if m.any():
                s[m] = c.s(np.minimum(t[m], c.tn))
        step_ref = STEP_LENGTH_REF_RATIO * self.body.height_m
        brake = 0.5 * _impact(st) * (1.0 - run_weight(st["speed"]))
        return s + st["env"] * SPEED_FLUCTUATION * st["amp"] * step_ref / (2 * np.pi) * np.sin(4 * np.pi * st["phase"]) - brake

    def _fk(self, st: dict, leg: int) -> dict[str, np.ndarray]:
        """Sagittal forward kinematics of one leg from the joint-angle curves, relative to its hip (x fwd, z up)."""
        p = np.mod(st["phase"] - 0.5 * leg, 1.0)
        v, e, a = st["speed"], st["env"], st["amp"]
        stance = stance_fraction(v)
        w_run = run_weight(v)
        qw, qr = _warp(p, stance, WALK_TOE_OFF), _warp(p, stance, RUN_TOE_OFF)
        hip = (1 - w_run) * fourier_deg(WALK_HIP_DEG, qw) + w_run * fourier_deg(RUN_HIP_DEG, qr)
        knee = (1 - w_run) * fourier_deg(WALK_KNEE_DEG, qw) + w_run * fourier_deg(RUN_KNEE_DEG, qr)
        ankle = (1 - w_run) * fourier_deg(WALK_ANKLE_DEG, qw) + w_run * fourier_deg(RUN_ANKLE_DEG, qr)
        sa = np.sqrt(a)
        th = np.radians(e * a * (hip - PELVIC_TILT_DEG))  # thigh from vertical, forward positive
        kn = np.radians(e * sa * knee)
        sh = th - kn
        gam = sh + np.radians(e * sa * ankle)  # foot pitch, toe up positive
        # foot flat: from the end of loading to heel rise the sole lies on the ground (walking)
        flat = _smoothstep((qw - FOOT_FLAT_PHASE[0]) / FOOT_FLAT_PHASE[1]) * \
            (1.0 - _smoothstep((qw - FOOT_FLAT_PHASE[2]) / FOOT_FLAT_PHASE[3]))
        gam = gam * (1.0 - flat * (1.0 - w_run))
        b = self.body
        knee_p = b.thigh_m * np.stack([np.sin(th), -np.cos(th)], -1)
        ankle_p = knee_p + b.shank_m * np.stack([np.sin(sh), -np.cos(sh)], -1)
        gc = np.clip(gam, self._g_toe, self._g_heel)
        contact_f = self._C + self._R * np.stack([-np.sin(gc), -np.cos(gc)], -1)
        return {"p": p, "stance": stance, "ankle": ankle_p, "contact": ankle_p + _rot2(gam, contact_f), "gc": gc,
                "gamma": gam, "knee_flex": kn}

    def _pelvis_offsets(self, st: dict) -> dict[str, np.ndarray]:
        """Pelvis yaw/roll/pitch oscillations, lateral sway, and each hip's forward/up/lateral offset."""
        u, e, ph = self.user, st["env"], st["phase"]
        yaw = -e * np.radians(u.pelvic_rotation_deg) * np.cos(2 * np.pi * ph)
        roll = e * np.radians(u.obliquity_deg) * np.sin(2 * np.pi * ph)
        pitch = e * np.radians(u.pitch_deg) * np.sin(4 * np.pi * ph)
        sway = e * u.sway_m * np.sin(2 * np.pi * ph)
        half = 0.5 * self.body.hip_separation_m
        out = {"yaw": yaw, "roll": roll, "pitch": pitch, "sway": sway}
        for leg, sgn in ((0, 1.0), (1, -1.0)):
            out[f"fwd{leg}"] = -sgn * half * np.sin(yaw)
            out[f"up{leg}"] = sgn * half * np.sin(roll)
            out[f"lat{leg}"] = sway + sgn * half * np.cos(yaw) * np.cos(roll)
            out[f"lane{leg}"] = np.full_like(e, sgn * 0.5 * u.step_width_m)
        return out

    def _tilt(self, fk: dict, off: dict, leg: int) -> np.ndarray:
        depth = np.maximum(-fk["contact"][..., 1], 0.2)
        return np.arcsin(np.clip((off[f"lane{leg}"] - off[f"lat{leg}"]) / depth, -0.5, 0.5))

    def _anchored(self, t: np.ndarray, st: dict, fk: dict, leg: int, ahead: bool = False,
                  pitch: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Ankle (s, h above ground) of a foot rolling on its latest footprint (``ahead``: on the next one),
        settling onto the ground over the first part of stance; ``pitch``: the foot's pitch (default: the curves')."""
        j = np.searchsorted(self._fp_t[leg], t, side="right") - 1
        if ahead:
            j = np.minimum(j + 1, len(self._fp_t[leg]) - 1)
        gam = fk["gamma"] if pitch is None else pitch
        gc = np.clip(gam, self._g_toe, self._g_heel)
        c_s = self._fp_s[leg][j] + self._R * (self._fp_gc[leg][j] - gc)
        rel = -_rot2(gam, self._C + self._R * np.stack([-np.sin(gc), -np.cos(gc)], -1))  # ankle - contact point
        settle = np.ones_like(t) if ahead else 1.0 - _smoothstep(fk["p"] / TOUCH_DOWN_PHASE)
        return c_s + rel[..., 0], rel[..., 1] + self._fp_dh[leg][j] * settle

    def _rolled_in_reach(self, t: np.ndarray, st: dict, fk: dict, leg: int, hip: np.ndarray, lane: np.ndarray,
                         planted: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """A foot on the ground that the leg cannot reach rolls forward instead of sliding.

        The stance leg straightens fully (the knee of a swinging leg keeps ~4 deg); where the hip has moved so far
        ahead that even the straight leg is too short, the foot rolls forward on its sole (an earlier, larger heel
        rise) until the ankle is within reach. The segments stay rigid and the contact point does not slip; before,
        the two-link leg dragged the flat foot along the ground (up to 3 cm per stride at 0.8-1.0 m/s, at up to
        3 cm/s with no rotation, which no zero-velocity detector can see). Returns the ankle (s, h) on the latest
        footprint, the pitch change (<= 0: toe down) and the hip-ankle distance the leg takes. ``planted`` (0-1)
        weighs the roll (0 in the air). Newton steps on the pitch; where rolling hardly brings the ankle nearer
        the hip (hip above or behind the contact, at heel strike) the foot rolls proportionally less and the leg
        pulls the rest in (a slip of a few mm while the foot settles)."""
        a_s, a_h = self._anchored(t, st, fk, leg)
        lat2 = (lane - hip[:, 1]) ** 2

        def dist(d):
            s_, h_ = self._anchored(t, st, fk, leg, pitch=fk["gamma"] + d)
            return np.sqrt((s_ - hip[:, 0]) ** 2 + lat2 + (h_ - hip[:, 2]) ** 2), s_, h_

        d0 = np.sqrt((a_s - hip[:, 0]) ** 2 + lat2 + (a_h - hip[:, 2]) ** 2)
        leg_m = self.body.thigh_m + self.body.shank_m
        reach = leg_m - _straight_margin(d0, leg_m)  # a planted leg may straighten fully
        delta = np.zeros_like(t)
        todo = (planted > 0) & (d0 - reach > 1e-6)
        if not todo.any():
            return a_s, a_h, delta, reach
        eps = 1e-4
        slope0 = (dist(delta + eps)[0] - dist(delta - eps)[0]) / (2 * eps)  # > 0: rolling forward brings it nearer
        for _ in range(8):
            slope = (dist(delta + eps)[0] - dist(delta - eps)[0]) / (2 * eps)
            f0 = dist(delta)[0] - reach
            ok = todo & (slope > 1e-3)
            step = np.where(ok, -f0 / np.where(ok, slope, 1.0), 0.0)
            delta = np.where(ok, np.clip(delta + np.clip(step, -0.2, 0.2), -3 * MAX_REACH_ROLL_RAD, 0.0), delta)
            todo = ok & (np.abs(f0) > 1e-7)
            if not todo.any():
                break
        # less where rolling hardly helps; saturating smoothly at MAX_REACH_ROLL_RAD
        delta = MAX_REACH_ROLL_RAD * np.tanh(delta * _smoothstep(slope0 / REACH_ROLL_SLOPE_M) / MAX_REACH_ROLL_RAD)
        delta = planted * delta
        _, a_s, a_h = dist(delta)
        return a_s, a_h, delta, reach

    def _pelvis_h(self, t: np.ndarray, st: dict) -> np.ndarray:
        """Pelvis height above the ground: standing hip height, lowered while walking by an inverted-pendulum
        arc (lowest just after each heel strike, highest in mid stance; compass-gait amplitude
        l - sqrt(l^2 - (L/2)^2) reduced by the determinants of gait) or, running, lowest in mid stance and
        highest in flight."""
        b, e, ph = self.body, st["env"], st["phase"]
        l = b.leg_length_m
        step = st["amp"] * STEP_LENGTH_REF_RATIO * b.height_m
        arc = l - np.sqrt(np.maximum(l * l - (0.5 * step) ** 2, 0.25 * l * l))
        w_run = run_weight(st["speed"])
        stance = stance_fraction(st["speed"])
        walk = WALK_DROP_M + self.user.arc_gain * arc * 0.5 * (1.0 + np.cos(4 * np.pi * (ph - WALK_LOW_PHASE)))
        run = RUN_DROP_M + RUN_ARC_GAIN * arc * 0.5 * (1.0 + np.cos(4 * np.pi * ph - 2 * np.pi * stance))
        return b.leg_length_m - e * ((1 - w_run) * walk + w_run * run) + _impact(st)

    # ---------------------------------------------------------------------------------------------------------
    def _check_t(self, t_s) -> np.ndarray:
        t = np.atleast_1d(np.asarray(t_s, float))
        if t.ndim != 1 or not np.isfinite(t).all():
            raise InputError("kinematics: expected a 1-D array of finite times (s)")
        return t

    def _body(self, t: np.ndarray) -> dict:
        """Everything at times t in path coordinates (s, d, h): pelvis, hips, knees, ankles, feet."""
        st = self._state(t)
        ps = self._pelvis_s(t, st)
        ph = self._pelvis_h(t, st)
        off = self._pelvis_offsets(st)
        out = {"st": st, "off": off, "pelvis": np.stack([ps, off["sway"], ph], -1)}
        b = self.body
        for leg, side in enumerate(SIDES):
            fk = self._fk(st, leg)
            hip = np.stack([ps + off[f"fwd{leg}"], off[f"lat{leg}"], ph + off[f"up{leg}"]], -1)
            p, stance = fk["p"], fk["stance"]
            in_stance = p <= stance
            # weight of a foot held on the ground: from touch-down (settled) to late stance (push-off takes over)
            planted = _smoothstep(p / TOUCH_DOWN_PHASE) * \
                (1.0 - _smoothstep((p / stance - REACH_ROLL_END) / (1.0 - REACH_ROLL_END)))
            a_s, a_h, d_roll, reach = self._rolled_in_reach(t, st, fk, leg, hip, off[f"lane{leg}"], planted)
            # swing: the curves' ankle from the hip, blended (position and velocity) from the foot still rolling
            # on its toe at lift-off, and into the next footprint before touch-down
            tilt = np.cos(self._tilt(fk, off, leg))
            sw_s = hip[:, 0] + fk["ankle"][:, 0]
            sw_h = hip[:, 2] + fk["ankle"][:, 1] * tilt
            lift = 1.0 - _smoothstep((p - stance) / LIFT_OFF_PHASE)
            sw_s = lift * a_s + (1 - lift) * sw_s
            sw_h = lift * a_h + (1 - lift) * sw_h
            land = _smoothstep((p - (1.0 - TOUCH_DOWN_PHASE)) / TOUCH_DOWN_PHASE)
            if (land > 0).any():
                n_s, n_h = self._anchored(t, st, fk, leg, ahead=True)
                sw_s = land * n_s + (1 - land) * sw_s
                sw_h = land * n_h + (1 - land) * sw_h
            ankle = np.stack([np.where(in_stance, a_s, sw_s), off[f"lane{leg}"], np.where(in_stance, a_h, sw_h)], -1)
            knee, ankle = _two_link(hip, ankle, b.thigh_m, b.shank_m, planted=planted, reach_m=reach)
            gam = fk["gamma"] + d_roll
            out[f"hip_{side}"], out[f"knee_{side}"], out[f"ankle_{side}"] = hip, knee, ankle
            for name, pt in (("heel", self._heel_f), ("toe", self._toe_f)):
                d = _rot2(gam, np.broadcast_to(pt, (len(t), 2)))
                out[f"{name}_{side}"] = ankle + np.stack([d[:, 0], np.zeros(len(t)), d[:, 1]], -1)
        return out

    def joint_positions_m(self, t_s) -> dict[str, np.ndarray]:
        """World (east, north, up) positions in metres of ``pelvis`` and ``hip/knee/ankle/heel/toe_left/right``."""
        t = self._check_t(t_s)
        body = self._body(t)
        return {k: self.route.to_world(v[:, 0], v[:, 1], v[:, 2]) for k, v in body.items() if k not in ("st", "off")}

    def pelvis_state(self, t_s) -> dict[str, np.ndarray]:
        """Pelvis path length ``s_m``, height ``h_m``, heading (route + pelvic rotation) and the gait state."""
        t = self._check_t(t_s)
        st = self._state(t)
        ps = self._pelvis_s(t, st)
        off = self._pelvis_offsets(st)
        return {"s_m": ps, "h_m": self._pelvis_h(t, st), "heading_rad": self.route.heading_rad(ps) + off["yaw"],
                "phase": st["phase"], "envelope": st["env"], "speed_mps": st["speed"]}

    def true_steps(self) -> pd.DataFrame:
        """``reference/steps.csv``: ``t_s, foot, step_length_m`` (horizontal pelvis distance since the previous
        contact, or since the start of the bout), ``step_duration_s``, ``bout_id``, ``speed_mps`` (the planned speed of
        the segment the step belongs to: the walking form's truth)."""
        hs = self.heel_strikes
        t_hs = hs["t_s"].to_numpy()
        bout = hs["bout"].to_numpy()
        starts = np.array([b.t_s[0] for b in self.bouts])
        first = np.r_[True, bout[1:] != bout[:-1]]
        t_prev = np.where(first, starts[bout], np.r_[t_hs[0], t_hs[:-1]])
        now, before = self.pelvis_position_m(t_hs), self.pelvis_position_m(t_prev)
        return pd.DataFrame({"t_s": t_hs, "foot": hs["foot"].to_numpy(),
                             "step_length_m": np.hypot(*(now[:, :2] - before[:, :2]).T),
                             "step_duration_s": t_hs - t_prev, "bout_id": bout,
                             "speed_mps": np.concatenate([b.speed_mps for b in self.bouts])})

    def true_strides(self) -> pd.DataFrame:
        """``reference/strides.csv``: heel strike to the next heel strike of the same foot within a bout,
        ``length_m`` = horizontal displacement of that heel."""
        rows = []
        hs = self.heel_strikes
        for foot in SIDES:
            sel = hs[hs["foot"] == foot]
            tt, bb = sel["t_s"].to_numpy(), sel["bout"].to_numpy()
            heel = self.joint_positions_m(tt)[f"heel_{foot}"] if len(tt) else np.zeros((0, 3))
            for k in range(len(sel) - 1):
                if bb[k] == bb[k + 1]:
                    rows.append((tt[k], tt[k + 1], foot, float(np.hypot(*(heel[k + 1, :2] - heel[k, :2])))))
        out = pd.DataFrame(rows, columns=["t_start_s", "t_end_s", "foot", "length_m"])
        return out.sort_values(["t_start_s", "foot"]).reset_index(drop=True)

    def pelvis_position_m(self, t_s) -> np.ndarray:
        """(N, 3) world position of the pelvis centre (cheaper than :meth:`joint_positions_m`)."""
        t = self._check_t(t_s)
        st = self._state(t)
        off = self._pelvis_offsets(st)
        return self.route.to_world(self._pelvis_s(t, st), off["sway"], self._pelvis_h(t, st))

    def segment_rotation(self, t_s, segment: str) -> np.ndarray:
        """(N, 3, 3) rotation matrices segment frame -> world for ``pelvis``, ``thigh_*``, ``shank_*``, ``foot_*``."""
        return self.segment_pose(t_s, segment)[1]

    def segment_pose(self, t_s, segment: str) -> tuple[dict[str, np.ndarray] | None, np.ndarray]:
        """Joint positions (None for the pelvis) and the segment's rotation, computed together."""
        if segment not in SEGMENTS:
            raise InputError(f"kinematics: expected a segment among {', '.join(SEGMENTS)}, found {segment!r}")
        t = self._check_t(t_s)
        st = self._state(t)
        ps = self._pelvis_s(t, st)
        off = self._pelvis_offsets(st)
        psi = self.route.heading_rad(ps)
        if segment == "pelvis":
            return None, rotation_zyx(psi + off["yaw"], off["pitch"], off["roll"])
        part, side = segment.split("_")
        j = self.joint_positions_m(t)
        left = np.stack([-np.sin(psi), np.cos(psi), np.zeros_like(psi)], -1)
        if part == "foot":
            x = j[f"toe_{side}"] - j[f"heel_{side}"]
            x /= np.linalg.norm(x, axis=-1, keepdims=True)
            y = left - np.sum(left * x, -1, keepdims=True) * x
            y /= np.linalg.norm(y, axis=-1, keepdims=True)
            return j, np.stack([x, y, np.cross(x, y)], axis=-1)
        top, bottom = ("hip", "knee") if part == "thigh" else ("knee", "ankle")
        z = j[f"{bottom}_{side}"] - j[f"{top}_{side}"]
        z /= np.linalg.norm(z, axis=-1, keepdims=True)
        y = -left - np.sum(-left * z, -1, keepdims=True) * z
        y /= np.linalg.norm(y, axis=-1, keepdims=True)
        return j, np.stack([np.cross(y, z), y, z], axis=-1)


def _impact(st: dict) -> np.ndarray:
    """Displacement (m) of the heel-strike transient: the downward motion of the trunk is arrested within tens of
    ms of contact (Zijlstra & Hof 2003 show the peak in lower-trunk acceleration right after initial contact)."""
    x = np.minimum(st["since_hs"], 1e3) / IMPACT_TAU_S
    peak = IMPACT_ACC_MPS2[0] + IMPACT_ACC_MPS2[1] * st["speed"]
    return st["env"] * peak * IMPACT_TAU_S**2 / 2.0 * x * x * np.exp(-x)


def _rot2(angle: np.ndarray, pt: np.ndarray) -> np.ndarray:
    """Rotate sagittal points (x fwd, z up) by ``angle`` (toe-up positive)."""
    c, s = np.cos(angle), np.sin(angle)
    return np.stack([c * pt[..., 0] - s * pt[..., 1], s * pt[..., 0] + c * pt[..., 1]], -1)


def _straight_margin(dist: np.ndarray, leg_m: float) -> np.ndarray:
    """How much shorter than the full leg a planted leg stays: a smooth max(leg - dist, 0) at 1 mm scale."""
    return 1e-3 * np.logaddexp(0.0, (leg_m - dist) / 1e-3)


def _reach_pull(dist: np.ndarray, leg_m: float) -> np.ndarray:
    """How far the leg pulls in a target ``dist`` from the hip: a smooth max(dist - reach, 0)."""
    return REACH_SOFTNESS_M * np.logaddexp(0.0, (dist - leg_m * MAX_REACH) / REACH_SOFTNESS_M)


def _two_link(hip: np.ndarray, ankle: np.ndarray, l1: float, l2: float, planted: np.ndarray | float = 0.0,
              reach_m: np.ndarray | float = np.inf) -> np.ndarray:
    """Knee position reaching from hip toward the ankle target with segment lengths l1, l2, bending forward
    (path coordinates), and the ankle actually reached: a target out of reach is pulled in smoothly; a foot on the
    ground (weight ``planted``, 0-1) only as far as needed to be ``reach_m`` from the hip (it has rolled towards the
    hip already: ``WalkKinematics._rolled_in_reach``)."""
    d = ankle - hip
    dist = np.linalg.norm(d, axis=-1)
    free = dist - _reach_pull(dist, l1 + l2)
    dist_c = np.maximum((1.0 - planted) * free + planted * np.minimum(dist, reach_m), abs(l1 - l2) + 1e-6)
    u = d / np.maximum(dist, 1e-9)[:, None]
    cos_a = np.clip((l1**2 + dist_c**2 - l2**2) / (2 * l1 * dist_c), -1.0, 1.0)
    fwd = np.array([1.0, 0.0, 0.0])
    n = fwd - (u @ fwd)[:, None] * u
    n /= np.maximum(np.linalg.norm(n, axis=-1), 1e-9)[:, None]
    knee = hip + l1 * (cos_a[:, None] * u + np.sqrt(1 - cos_a**2)[:, None] * n)
    return knee, hip + dist_c[:, None] * u



def rotation_zyx(yaw, pitch, roll) -> np.ndarray:
    """(N, 3, 3) body -> world for yaw about z, then pitch about y, then roll about x (intrinsic z-y-x)."""
    cy, sy = np.cos(yaw), np.sin(yaw)
    cp, sp = np.cos(pitch), np.sin(pitch)
    cr, sr = np.cos(roll), np.sin(roll)
    r = np.empty(np.shape(yaw) + (3, 3))
    r[..., 0, 0] = cy * cp
    r[..., 0, 1] = cy * sp * sr - sy * cr
    r[..., 0, 2] = cy * sp * cr + sy * sr
    r[..., 1, 0] = sy * cp
    r[..., 1, 1] = sy * sp * sr + cy * cr
    r[..., 1, 2] = sy * sp * cr - cy * sr
    r[..., 2, 0] = -sp
    r[..., 2, 1] = cp * sr
    r[..., 2, 2] = cp * cr
    return r
