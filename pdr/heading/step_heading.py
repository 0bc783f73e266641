"""Walking direction per step from the attitude (VQF) and the horizontal acceleration of each step."""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy import signal
from scipy.ndimage import minimum_filter1d

from pdr.base import Algorithm
from pdr.constants import FLIGHT_MAX_SPECIFIC_FORCE_G, GRAVITY_MPS2, WALK_MIN_SPECIFIC_FORCE_G
from pdr.errors import InputError, warn
from pdr.schema import wrap_rad
from pdr.signals.attitude import Attitude, earth_acceleration, rotate, yaw_increments
from pdr.signals.resample import UniformImu

# Gait of each stretch from the vertical specific force over one step (pdr.constants: a flight phase at or below
# FLIGHT_MAX_SPECIFIC_FORCE_G, walking at or above WALK_MIN_SPECIFIC_FORCE_G). Between the two bounds the sign of
# the phase relation fades linearly, so an ambiguous stretch gives a weak, not a wrong, vote.
VERTICAL_LOWPASS_HZ = 10.0  # keeps the flight trough (~0.1 s), drops the heel-strike ringing

HEADING_COLUMNS = ["heading_rad", "heading_change_rad", "heading_change_std_rad", "mag_heading_rad", "mag_heading_std_rad"]


def _bandpass(acc_enu: np.ndarray, rate_hz: float, step_s: float) -> np.ndarray | None:
    """Earth-frame acceleration band-passed to the octave around the step frequency (None if too short / too slow a rate)."""
    f = 1.0 / step_s
    nyq = 0.5 * rate_hz
    if len(acc_enu) < 3 * rate_hz * step_s or 1.4 * f >= nyq:
        return None
    sos = signal.butter(2, [f / 1.4 / nyq, 1.4 * f / nyq], btype="band", output="sos")
    return signal.sosfiltfilt(sos, acc_enu, axis=0)


def gait_phase_sign(acc_up_mps2: np.ndarray, rate_hz: float, step_s: float, *,
                    flight_max_g: float = FLIGHT_MAX_SPECIFIC_FORCE_G,
                    walk_min_g: float = WALK_MIN_SPECIFIC_FORCE_G) -> np.ndarray:
    """Per sample, the sign of the forward-vertical phase relation: +1 walking, -1 running (a flight phase), between.

    ``acc_up_mps2`` is the earth-frame vertical acceleration with gravity removed (:func:`earth_acceleration`).
    The vertical specific force is low-passed (``VERTICAL_LOWPASS_HZ``) and its minimum taken over one step centred
    on each sample: at or below ``flight_max_g`` (in g) the stretch holds a flight phase (-1), at or above
    ``walk_min_g`` it does not (+1), linear in between (see the constants above for the physics).
    """
    return _sign_of_gait(_vertical_specific_force_g(acc_up_mps2, rate_hz), rate_hz, step_s, flight_max_g, walk_min_g)


def _vertical_specific_force_g(acc_up_mps2: np.ndarray, rate_hz: float) -> np.ndarray:
    """Vertical specific force in g, low-passed at ``VERTICAL_LOWPASS_HZ`` (at most 0.4 x the rate)."""
    fz = (np.asarray(acc_up_mps2, float) + GRAVITY_MPS2) / GRAVITY_MPS2
    if len(fz) <= 15:
        return fz
    fc = min(VERTICAL_LOWPASS_HZ, 0.4 * rate_hz)
    return signal.sosfiltfilt(signal.butter(2, fc / (0.5 * rate_hz), output="sos"), fz)


def _sign_of_gait(fz_g: np.ndarray, rate_hz: float, step_s: float, flight_max_g: float, walk_min_g: float) -> np.ndarray:
    if len(fz_g) == 0:
        return np.ones(0)
    lowest = minimum_filter1d(fz_g, size=max(1, int(round(step_s * rate_hz))), mode="nearest")
    mid, half = 0.5 * (flight_max_g + walk_min_g), 0.5 * (walk_min_g - flight_max_g)
    return np.clip((lowest - mid) / max(half, 1e-9), -1.0, 1.0)


def _products(a: np.ndarray, q: int, sign: np.ndarray | None = None) -> np.ndarray:
    """Per-sample products whose window sums give the direction: ee, nn, en, vv, s e(t) v(t+q), s n(t) v(t+q)
    (``s``: :func:`gait_phase_sign`, 1 if None)."""
    e, n, v = a[:, 0], a[:, 1], a[:, 2]
    v_adv = np.concatenate([v[q:], np.zeros(q)])
    if sign is not None:
        v_adv = v_adv * sign
    return np.column_stack([e * e, n * n, e * n, v * v, e * v_adv, n * v_adv])


def _direction(sums: np.ndarray, count: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Walking direction and quality from window sums of :func:`_products` (vectorised over windows)."""
    m = sums / np.maximum(count, 1)[:, None]
    ee, nn, en, vv, ce, cn = m.T
    tr, det = ee + nn, ee * nn - en * en
    disc = np.sqrt(np.maximum(0.25 * tr * tr - det, 0.0))
    l1, l2 = 0.5 * tr + disc, 0.5 * tr - disc
    theta = 0.5 * np.arctan2(2.0 * en, ee - nn)  # principal axis
    ax, ay = np.cos(theta), np.sin(theta)
    proj = ce * ax + cn * ay
    theta = np.where(proj < 0, theta + np.pi, theta)
    share = (l1 - l2) / np.maximum(l1 + l2, 1e-12)
    norm = np.sqrt(np.maximum(l1, 1e-12) * np.maximum(vv, 1e-12))
    return wrap_rad(theta), share * np.minimum(1.0, np.abs(proj) / norm)


def walking_direction(acc_enu: np.ndarray, rate_hz: float, step_s: float) -> tuple[float, float]:
    """Walking direction (rad, CCW from the frame's x axis) of a stretch of earth-frame acceleration, and its quality.

    The horizontal acceleration band-passed around the step frequency oscillates along the direction of travel
    (the antero-posterior component repeats every step, the medio-lateral one every stride). Its principal axis gives
    the direction up to 180 degrees; the sign follows from the phase relation of the gait. Walking (inverted
    pendulum): the forward acceleration leads the vertical acceleration by a quarter step (it peaks before the
    vertical peak at double support and turns negative, braking, after it, while the trunk vaults up). Running
    (spring-mass, with a flight phase): the vertical peak is mid-stance, braking comes before it and propulsion
    after, so the forward acceleration lags the vertical by a quarter step. The gait is told apart per sample by the
    flight phase (:func:`gait_phase_sign`). Quality in [0, 1]: the principal axis' share of the horizontal variance
    times the normalised quarter-step correlation.
    """
    acc_enu = np.asarray(acc_enu, float)
    a = _bandpass(acc_enu, rate_hz, step_s)
    if a is None:
        return float("nan"), 0.0
    sign = gait_phase_sign(acc_enu[:, 2], rate_hz, step_s)
    d, q = _direction(_products(a, int(round(0.25 * step_s * rate_hz)), sign).sum(axis=0)[None, :],
                      np.array([len(a)]))
    return float(d[0]), float(q[0])


def circular_smooth(angle: np.ndarray, weight: np.ndarray, half: int) -> np.ndarray:
    """Weighted circular mean over ``2 half + 1`` neighbours (NaN angles ignored)."""
    ok = np.isfinite(angle) & (weight > 0)
    z = np.where(ok, weight * np.exp(1j * np.where(ok, angle, 0.0)), 0.0)
    c = np.concatenate([[0.0], np.cumsum(z)])
    k = np.arange(len(angle))
    lo, hi = np.clip(k - half, 0, len(angle)), np.clip(k + half + 1, 0, len(angle))
    s = c[hi] - c[lo]
    return np.where(np.abs(s) > 1e-12, np.angle(s), np.nan)


class AttitudeStepHeading(Algorithm):
    """Heading per step: device yaw integrated from the attitude plus a smoothed device-to-walking offset.

    Parameters
    ----------
    offset_window_steps : the device-to-walking offset is a weighted circular mean over this many steps
        (a phone held in a hand or carried in a pocket keeps its offset for a while).
    min_direction_quality : steps whose acceleration gives a weaker direction do not vote for the offset.
    gyro_arw_rad_per_sqrt_s : angle random walk of the yaw (gyroscope white noise), rad/sqrt(s).
    step_direction_std_rad : how far one step's direction scatters around the heading (trunk sway).
    no_gyro_std_rad : heading-change std per step when there is no gyroscope (heading unobservable).
    mag_norm_tolerance : a magnetic sample is trusted when |B| is within this fraction of the recording's median.
    mag_dip_tolerance_rad : ... and its dip within this of the median dip.
    mag_heading_std_rad : std of a trusted magnetic heading.
    flight_max_specific_force_g, walk_min_specific_force_g : a stretch whose vertical specific force (low-passed)
        drops to the first within a step has a flight phase (running); one that stays above the second is walking
        (:func:`gait_phase_sign`).

    Attributes
    ----------
    heading_rad_, heading_change_rad_, heading_change_std_rad_, mag_heading_rad_, mag_heading_std_rad_ : per step.
    offset_rad_ : the device-to-walking offset used at each step.
    direction_rad_, direction_quality_ : the raw walking direction of each step from the acceleration.
    gait_sign_ : per step, +1 walking, -1 running (flight phase), between when unsure (:func:`gait_phase_sign`).

    Notes
    -----
    The device yaw is the integral of the attitude's rotation about the earth's up axis (:func:`yaw_increments`), so it
    is defined whatever way the phone is held. ``heading_change_rad`` is the change of the mean device yaw from one
    step to the next (gyro only); ``heading_rad`` adds the smoothed offset, so its differences also follow slow
    changes of how the phone is held. The heading's frame is VQF's 6D frame: up is up, the zero of heading is
    arbitrary (the magnetic heading gives the absolute one). The walking direction's sign uses the phase relation of
    each stretch's gait (walking: forward acceleration leads vertical by a quarter step; running, told by its flight
    phase: it lags), so walking and running steps vote for the same offset and a run inside a walk does not turn the
    path around (without the running relation, every running step pointed backwards). The heading-change std grows
    with the VQF gyro-bias uncertainty times the elapsed time (drift) and with the angle random walk. Without a
    gyroscope, heading changes are unobservable: 0 with ``no_gyro_std_rad`` and a warning.

    Example
    -------
    >>> h = AttitudeStepHeading().estimate(u, attitude, steps)   # doctest: +SKIP
    """

    def __init__(self, *, offset_window_steps: int = 40, min_direction_quality: float = 0.2,
                 gyro_arw_rad_per_sqrt_s: float = 0.005, step_direction_std_rad: float = 0.02,
                 no_gyro_std_rad: float = np.pi / 2, mag_norm_tolerance: float = 0.15,
                 mag_dip_tolerance_rad: float = np.radians(10.0), mag_heading_std_rad: float = 0.1,
                 flight_max_specific_force_g: float = FLIGHT_MAX_SPECIFIC_FORCE_G,
                 walk_min_specific_force_g: float = WALK_MIN_SPECIFIC_FORCE_G):
        self.offset_window_steps = offset_window_steps
        self.min_direction_quality = min_direction_quality
        self.gyro_arw_rad_per_sqrt_s = gyro_arw_rad_per_sqrt_s
        self.step_direction_std_rad = step_direction_std_rad
        self.no_gyro_std_rad = no_gyro_std_rad
        self.mag_norm_tolerance = mag_norm_tolerance
        self.mag_dip_tolerance_rad = mag_dip_tolerance_rad
        self.mag_heading_std_rad = mag_heading_std_rad
        self.flight_max_specific_force_g = flight_max_specific_force_g
        self.walk_min_specific_force_g = walk_min_specific_force_g

    def estimate(self, u: UniformImu, attitude: Attitude, steps: pd.DataFrame) -> "AttitudeStepHeading":
        if "t_s" not in steps.columns:
            raise InputError(f"heading: expected a steps table with t_s, found {', '.join(map(str, steps.columns))}")
        t = steps["t_s"].to_numpy(float)
        n = len(t)
        nan = np.full(n, np.nan)
        self.direction_rad_, self.direction_quality_, self.offset_rad_ = nan.copy(), np.zeros(n), nan.copy()
        self.mag_heading_rad_, self.mag_heading_std_rad_ = nan.copy(), nan.copy()
        self.gait_sign_ = np.ones(n)
        if not attitude.has_gyro:
            if n:
                warn("heading: no gyroscope; heading changes are unobservable (0 with a std of "
                     f"{self.no_gyro_std_rad:.2f} rad per step)")
            self.heading_rad_ = np.zeros(n)
            self.heading_change_rad_ = np.zeros(n)
            self.heading_change_std_rad_ = np.full(n, float(self.no_gyro_std_rad))
            return self
        if n == 0:
            self.heading_rad_ = self.heading_change_rad_ = self.heading_change_std_rad_ = np.zeros(0)
            return self
        psi = np.concatenate([[0.0], np.cumsum(yaw_increments(attitude.q_wxyz))])
        dur = np.diff(t, prepend=np.nan)
        step_s = float(np.nanmedian(dur)) if np.isfinite(dur).any() else 0.5
        prev = np.where(np.isfinite(dur), t - np.minimum(np.nan_to_num(dur, nan=step_s), 2.0 * step_s), t - step_s)
        i_lo = np.clip(np.searchsorted(u.t_s, prev), 0, len(u) - 1)
        i_hi = np.clip(np.searchsorted(u.t_s, t), 0, len(u) - 1)
        cpsi = np.concatenate([[0.0], np.cumsum(psi)])
        cnt = np.maximum(i_hi - i_lo + 1, 1)
        yaw_dev = (cpsi[i_hi + 1] - cpsi[i_lo]) / cnt  # mean device yaw over each step

        acc_e = earth_acceleration(u.acc_mps2, attitude.q_wxyz)
        fz_g = _vertical_specific_force_g(acc_e[:, 2], u.rate_hz)  # once: a filter design per bout costs ~1.5 ms
        bout = steps["bout_id"].to_numpy(int) if "bout_id" in steps.columns else np.zeros(n, int)
        for b in np.unique(bout):
            idx = np.flatnonzero(bout == b)
            tb = t[idx]
            sb = float(np.median(np.diff(tb))) if len(tb) > 1 else step_s
            lo = np.searchsorted(u.t_s, tb[0] - 3.0 * sb)
            hi = np.searchsorted(u.t_s, tb[-1] + 3.0 * sb)
            a = _bandpass(acc_e[lo:hi], u.rate_hz, sb)
            if a is None:
                continue
            sign = _sign_of_gait(fz_g[lo:hi], u.rate_hz, sb, self.flight_max_specific_force_g,
                                 self.walk_min_specific_force_g)
            self.gait_sign_[idx] = sign[np.clip(np.searchsorted(u.t_s, tb) - lo, 0, len(sign) - 1)]
            c = np.vstack([np.zeros((1, 6)),
                           np.cumsum(_products(a, int(round(0.25 * sb * u.rate_hz)), sign), axis=0)])
            w_lo = np.clip(np.searchsorted(u.t_s, tb - 2.0 * sb) - lo, 0, len(a))
            w_hi = np.clip(np.searchsorted(u.t_s, tb + 2.0 * sb) - lo, 0, len(a))
            d, qual = _direction(c[w_hi] - c[w_lo], w_hi - w_lo)
            self.direction_rad_[idx], self.direction_quality_[idx] = d, np.where(w_hi - w_lo > 0, qual, 0.0)
        vote = self.direction_quality_ >= self.min_direction_quality
        raw_offset = wrap_rad(self.direction_rad_ - yaw_dev)
        offset = nan.copy()
        for b in np.unique(bout):
            idx = np.flatnonzero(bout == b)
            w = np.where(vote[idx], self.direction_quality_[idx], 0.0)
            offset[idx] = circular_smooth(raw_offset[idx], w, self.offset_window_steps // 2)
        if np.isnan(offset).all():
            warn("heading: no step gave a walking direction; device yaw used as heading")
            offset[:] = 0.0
        else:  # bouts without a usable direction take the nearest known offset
            known = np.flatnonzero(np.isfinite(offset))
            nearest = known[np.clip(np.searchsorted(known, np.arange(n)), 0, len(known) - 1)]
            offset = np.where(np.isfinite(offset), offset, offset[nearest])
        self.offset_rad_ = offset
        heading_unwrapped = yaw_dev + np.unwrap(offset)
        self.heading_rad_ = wrap_rad(heading_unwrapped)
        change = np.diff(yaw_dev, prepend=yaw_dev[0])  # the gyro's turn between steps; the offset is not in it
        self.heading_change_rad_ = change
        dt = np.diff(t, prepend=t[0])
        bias_sigma = attitude.bias_sigma_radps[i_hi]
        self.heading_change_std_rad_ = np.sqrt((bias_sigma * dt) ** 2 + self.gyro_arw_rad_per_sqrt_s ** 2 * dt
                                               + self.step_direction_std_rad ** 2)
        if u.mag_ut is not None:
            self._mag_heading(u, attitude, i_hi)
        return self

    def _mag_heading(self, u: UniformImu, attitude: Attitude, i_step: np.ndarray) -> None:
        """Absolute heading from the tilt-compensated magnetometer, where the field looks undisturbed.

        The field is rotated into the 6D earth frame; the angle of its horizontal part is magnetic north there, so the
        6D step heading turns into east-north-up by ``pi/2 - angle``. Trusted samples: |B| and dip within the
        tolerances of the recording's medians and not flagged by VQF's disturbance detection (the flag is ignored when
        VQF never accepted a field: it needs rotation to learn the reference field, which a straight walk lacks).
        """
        m_e = rotate(attitude.q_wxyz, u.mag_ut)
        norm = np.linalg.norm(m_e, axis=1)
        dip = np.arcsin(np.clip(-m_e[:, 2] / np.maximum(norm, 1e-9), -1.0, 1.0))
        delta = np.pi / 2 - np.arctan2(m_e[:, 1], m_e[:, 0])
        med_norm, med_dip = np.median(norm[u.valid]), np.median(dip[u.valid])
        trusted = u.valid & (np.abs(norm / med_norm - 1.0) <= self.mag_norm_tolerance) & (np.abs(dip - med_dip) <= self.mag_dip_tolerance_rad)
        if (~attitude.mag_disturbed).any():
            trusted &= ~attitude.mag_disturbed
        ok = trusted[i_step]
        self.mag_heading_rad_ = np.where(ok, wrap_rad(self.heading_rad_ + delta[i_step]), np.nan)
        self.mag_heading_std_rad_ = np.where(ok, self.mag_heading_std_rad, np.nan)
