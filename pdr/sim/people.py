"""Who walks and how they plan it: body proportions, per-person gait laws and cohorts, and the heel-strike plan of a
walk from speed segments. :mod:`pdr.sim.gait` turns the plan into body kinematics.

Public objects
--------------
``Body`` (segment lengths from height and leg proportion), ``GaitUser`` (per-person speed-step-length law,
:data:`COHORTS`), ``Bout`` and ``plan_walk`` (heel-strike instants and target step lengths from speed segments).
"""

from __future__ import annotations

import dataclasses
from typing import Sequence

import numpy as np

from pdr.constants import GRAVITY_MPS2
from pdr.errors import InputError, warn

# Anthropometry (Winter 2009, Table 4.1, fractions of body height H).
THIGH_RATIO = 0.245
SHANK_RATIO = 0.246
FOOT_RATIO = 0.152
ANKLE_HEIGHT_RATIO = 0.039
HIP_SEPARATION_RATIO = 0.095  # distance between the hip joint centres
REF_FROUDE_SPEED = 0.45  # v / sqrt(g l) of a natural walking pace
GAIT_START_FRACTION = 0.5  # the pelvis moves about half a step on the first step of a bout and on the last


@dataclasses.dataclass(frozen=True)
class Body:
    """Segment lengths from body height (Winter's ratios) and per-person leg proportions.

    Attributes: ``thigh_m``, ``shank_m``, ``foot_m`` (heel to toe), ``ankle_height_m``, ``hip_separation_m``,
    ``leg_length_m`` (standing hip height = thigh + shank + ankle height, about 0.53 H). ``leg_scale`` multiplies
    thigh and shank: people of one height differ in relative leg length by about 2.5% (1 SD; Bogin & Varela-Silva
    2010, "Leg length, body proportion, and health"). ``knee_scale`` multiplies the shank and gives the thigh the
    difference, so the leg length stays: where the knee sits within the leg (:data:`KNEE_SCALE_SD`).
    """

    height_m: float = 1.75
    leg_scale: float = 1.0
    knee_scale: float = 1.0

    def __post_init__(self):
        if not 1.0 <= self.height_m <= 2.3:
            raise InputError(f"subject.height_m: expected 1.0-2.3 m, found {self.height_m}")
        if not 0.85 <= self.leg_scale <= 1.15:
            raise InputError(f"subject leg_scale: expected 0.85-1.15, found {self.leg_scale}")
        if not 0.85 <= self.knee_scale <= 1.15:
            raise InputError(f"subject knee_scale: expected 0.85-1.15, found {self.knee_scale}")

    thigh_m = property(lambda self: (THIGH_RATIO + (1.0 - self.knee_scale) * SHANK_RATIO) * self.leg_scale
                       * self.height_m)
    shank_m = property(lambda self: SHANK_RATIO * self.knee_scale * self.leg_scale * self.height_m)
    foot_m = property(lambda self: FOOT_RATIO * self.height_m)
    ankle_height_m = property(lambda self: ANKLE_HEIGHT_RATIO * self.height_m)
    hip_separation_m = property(lambda self: HIP_SEPARATION_RATIO * self.height_m)
    leg_length_m = property(lambda self: self.thigh_m + self.shank_m + self.ankle_height_m)

    def subject(self, mass_kg: float | None = None) -> dict[str, float]:
        """The ``[subject]`` table of ``meta.toml``: what a person knows of their body, the height to the
        centimetre and the leg length (not the segment lengths, which nobody knows without a motion lab)."""
        out = {"height_m": round(self.height_m, 2), "leg_length_m": round(self.leg_length_m, 4)}
        if mass_kg is not None:
            out["mass_kg"] = float(mass_kg)
        return out


LEG_SCALE_SD = 0.025  # relative leg length, 1 SD (Bogin & Varela-Silva 2010)
# Knee height (heel to knee) correlates with stature at r = 0.68-0.73 (1,179 adults: "Estimating stature from knee
# height for adults in Taiwan", Chang Gung Med J 2001): with its population spread of about 5% that leaves 1 SD of about
# 3.5% at a given height, of which the leg length's own 2.5% (LEG_SCALE_SD) is part; the rest, sqrt(3.5^2 - 2.5^2),
# is where the knee sits within the leg
KNEE_SCALE_SD = 0.025


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

    def close(run: list[tuple[float, float, float]], phase: float) -> float:
        """Plan the bout of the consecutive moving segments ``run`` from gait ``phase``; the phase after it."""
        if not run:
            return phase
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
        return phase

    for duration, speed in segments:
        if speed > 0:
            moving.append((t, t + duration, float(speed)))
        else:
            phase = close(moving, phase)
            moving = []
        t += duration
    close(moving, phase)
    return bouts
