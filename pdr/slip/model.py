"""The SLIP walking model, its leg kinematics and the leg-camera optical flow it predicts (Liu, MS thesis ch. 3).

Sagittal plane, x forward, y up, ground at y = 0, angles from the vertical, positive when the lower end of the
segment is ahead of its upper end. One simulated stride of the camera leg is two identical SLIP steps (the
thesis re-imposes the start velocity at every heel strike): the camera leg's stance (heel contact, then toe
contact) and the other leg's stance, during which the camera leg leaves the ground and swings.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy.integrate import solve_ivp

from pdr.constants import GRAVITY_MPS2
from pdr.errors import InputError

# Winter (2009, Biomechanics and Motor Control of Human Movement, Table 4.1 / Fig. 4.1), fractions of body height H.
HIP_HEIGHT_RATIO = 0.530  # greater trochanter above the floor
KNEE_HEIGHT_RATIO = 0.285  # knee joint above the floor
ANKLE_HEIGHT_RATIO = 0.039  # ankle joint above the floor
FOOT_LENGTH_RATIO = 0.152  # heel to toe
# The SLIP's foot is the lever of its toe pivot, a stand-in for the roll-over of ankle and foot: Winter's foot for the
# height, never a measured one. On rendered walks whose feet are 0.8 or 1.25 times Winter's the flow hardly changes,
# but the toe pivot moves the stride about 1.2% per cm of lever: set to the true foot, the stride bias of the tuning
# people's walks (benchmarks/bench_leg_camera.py, 1.2 m/s, every knee Winter's) swings from -19 to +14%, against -11
# to +5% with this lever.
# Perry & Burnfield (2010, Gait Analysis): stance takes 60% of the gait cycle at free speed, mid swing ends (and
# terminal swing begins) at 87%; Winter (1992, Phys Ther 72:45-53): the swing foot passes the floor at its minimum toe clearance
# (1.29 cm) in mid swing and stays within a few centimetres of it until heel contact, which it makes with negligible
# vertical velocity. The "heel" swing lowers the shank's floor point to the floor by the end of mid swing, at this
# fraction of the swing, and carries it there to heel strike.
SWING_DESCENT_FRACTION = (0.87 - 0.60) / (1.0 - 0.60)
# the swinging knee extends to near full extension, about 5 deg of flexion, by heel contact (Perry & Burnfield 2010);
# the SLIP's contact leg is straight, so in the model this least flexion fades to none over terminal swing
SWING_MIN_KNEE_RAD = math.radians(5.0)


@dataclasses.dataclass(frozen=True)
class SlipBody:
    """Body parameters of the SLIP model (thesis Table 1 as defaults).

    Attributes
    ----------
    thigh_length_m, shank_length_m, foot_length_m : L_th (hip-knee), L_sh (knee-heel), L_ft (heel-toe: the lever
        of the toe pivot, :data:`FOOT_LENGTH_RATIO` of the height).
    mass_kg : the lumped mass m at the hip.
    """

    thigh_length_m: float = 0.5
    shank_length_m: float = 0.6
    foot_length_m: float = 0.2
    mass_kg: float = 50.0

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise InputError(f"SlipBody: expected a positive {f.name}, found {v!r}")

    @classmethod
    def from_user(cls, height_m: float, *, leg_length_m: float | None = None, shank_length_m: float | None = None,
                  thigh_length_m: float | None = None) -> "SlipBody":
        """The SLIP body from what a user knows: the height and, if measured, the leg length (floor to the greater
        trochanter), the shank (knee to ankle joint) and the thigh.

        Missing lengths come from Winter's ratios to height (:data:`HIP_HEIGHT_RATIO`, ...); a measured leg length
        rescales the Winter knee height (where the knee sits within the leg varies too: give the shank). The
        SLIP's shank runs from the knee to the ground: the knee-to-ankle shank plus the Winter ankle height. The
        foot is the toe pivot's lever, Winter's for the height, not a measured foot. The
        mass stays the default: the SLIP's motion depends on stiffness / mass only, and the stiffness is fitted.
        """
        for name, v in (("height_m", height_m), ("leg_length_m", leg_length_m), ("shank_length_m", shank_length_m),
                        ("thigh_length_m", thigh_length_m)):
            if v is not None and not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise InputError(f"SlipBody.from_user: expected a positive {name}, found {v!r}")
        h = float(height_m)
        leg = HIP_HEIGHT_RATIO * h if leg_length_m is None else float(leg_length_m)
        if shank_length_m is not None:
            knee = float(shank_length_m) + ANKLE_HEIGHT_RATIO * h
        elif thigh_length_m is not None and leg_length_m is not None:
            knee = leg - float(thigh_length_m)
        else:
            knee = KNEE_HEIGHT_RATIO * h * leg / (HIP_HEIGHT_RATIO * h)
        thigh = leg - knee if thigh_length_m is None else float(thigh_length_m)
        if not 0.25 < knee / (knee + thigh) < 0.75:
            raise InputError(f"SlipBody.from_user: expected a knee between hip and floor, found thigh {thigh:.3f} m "
                             f"and knee height {knee:.3f} m (leg {leg:.3f} m)")
        return cls(thigh_length_m=thigh, shank_length_m=knee, foot_length_m=FOOT_LENGTH_RATIO * h)

    @property
    def leg_length_m(self) -> float:
        """L_ref = L_th + L_sh (eq. 3.4)."""
        return self.thigh_length_m + self.shank_length_m


@dataclasses.dataclass
class SlipStep:
    """One SLIP step, heel strike to the next heel strike (hip at x = 0 at the start).

    Attributes
    ----------
    duration_s : time to the next heel strike.
    length_m : hip (= contact point) advance over the step.
    heel_x_m : the contact point x_H (eq. 3.6).
    t_hc_s : end of phase 1 (the hip rises back through h_crit): end of heel contact in the kinematics.
    sol : callable t -> (4, n) state (x, vx, y, vy), dense output of both phases.
    """

    duration_s: float
    length_m: float
    heel_x_m: float
    t_hc_s: float
    sol: object
    crit_height_m: float


def _rhs(body: SlipBody, stiffness_npm: float, heel_x_m: float):
    lref, m = body.leg_length_m, body.mass_kg

    def f(_t, s):
        x, vx, y, vy = s
        dx, dy = x - heel_x_m, y
        length = math.hypot(dx, dy)
        force = stiffness_npm * (lref - length) if length < lref else 0.0  # eq. 3.2
        return [vx, force * dx / (m * length), vy, force * dy / (m * length) - GRAVITY_MPS2]  # eq. 3.1

    return f


def simulate_step(vx_mps: float, vy_mps: float, leg_angle_rad: float, stiffness_npm: float,
                  body: SlipBody = SlipBody(), *, max_time_s: float = 2.0) -> SlipStep | None:
    """Integrate one SLIP step (eq. 3.1-3.6) with event detection; None if the model falls or stalls.

    The step starts at heel strike: hip at (0, h_crit) with h_crit = L_ref cos(delta) (eq. 3.5), contact point
    x_H = h_crit tan(delta) ahead (eq. 3.6). Phase 1 ends when the hip rises back through h_crit, phase 2 when it
    descends through h_crit again: the next heel strike (thesis Appendix C).
    """
    lref = body.leg_length_m
    hcrit = lref * math.cos(leg_angle_rad)
    heel_x = hcrit * math.tan(leg_angle_rad)
    f = _rhs(body, stiffness_npm, heel_x)

    def rise(_t, s):
        return s[2] - (hcrit + 1e-9)

    rise.terminal, rise.direction = True, 1

    def fall(_t, s):
        return s[2] - hcrit

    fall.terminal, fall.direction = True, -1

    def collapse(_t, s):
        return s[2] - 0.5 * hcrit

    collapse.terminal, collapse.direction = True, -1

    def stall(_t, s):
        return s[1]

    stall.terminal, stall.direction = True, -1

    # RK45 at rtol 1e-5: over the fit's start grid the step length and duration stay within 0.1% of an integration
    # at 1e-6 (fifty times under the model's 5% error floor), at 85% of the fit time
    opts = dict(method="RK45", rtol=1e-5, atol=1e-7, dense_output=True)
    s0 = [0.0, vx_mps, hcrit, vy_mps]
    p1 = solve_ivp(f, (0.0, max_time_s), s0, events=(rise, collapse, stall), **opts)
    if p1.status != 1 or len(p1.t_events[0]) == 0:
        return None
    t1 = float(p1.t_events[0][0])
    p2 = solve_ivp(f, (t1, max_time_s), p1.y_events[0][0], events=(fall, collapse, stall), **opts)
    if p2.status != 1 or len(p2.t_events[0]) == 0:
        return None
    t2 = float(p2.t_events[0][0])
    x_end = float(p2.y_events[0][0][0])
    if x_end <= 0:
        return None
    s1, s2 = p1.sol, p2.sol

    def sol(t):
        t = np.asarray(t, dtype=float)
        return np.where(t < t1, s1(np.minimum(t, t1)), s2(np.clip(t, t1, t2)))

    return SlipStep(duration_s=t2, length_m=x_end, heel_x_m=heel_x, t_hc_s=t1, sol=sol, crit_height_m=hcrit)


def _two_link_knee(hip: np.ndarray, end: np.ndarray, l_upper: float, l_lower: float) -> np.ndarray:
    """Knee of a two-link chain hip-knee-end (lengths l_upper, l_lower), bent forward (+x); out of reach, the
    chain is straight from the hip toward the end (eq. 3.12 solved with the unit-length constraints)."""
    d = hip - end
    dist = np.hypot(d[:, 0], d[:, 1])
    cos_a = np.clip((dist ** 2 + l_lower ** 2 - l_upper ** 2) / (2 * dist * l_lower), -1.0, 1.0)
    a = np.arccos(cos_a)
    ang = np.arctan2(d[:, 1], d[:, 0]) - a  # rotate end->hip clockwise: the knee comes forward
    knee = end + l_lower * np.column_stack([np.cos(ang), np.sin(ang)])
    far = dist > l_upper + l_lower  # out of reach: the straight leg hangs from the hip, the end leaves the ground
    knee[far] = hip[far] - l_upper * d[far] / dist[far, None]
    return knee


@dataclasses.dataclass
class StrideKinematics:
    """Camera-leg kinematics over one simulated stride, sampled at ``t_s`` (0 = heel strike).

    Attributes
    ----------
    t_s, hip_m, knee_m, heel_m : time and (n, 2) positions.
    shank_angle_rad : angle of the shank from the vertical (heel ahead of knee positive).
    camera_m : (n, 2) camera focal point (eq. 3.7); distance_m: D along the optical axis to the ground (eq. 3.9).
    phase : 0 heel contact, 1 toe contact, 2 swing.
    length_m, duration_s : stride length and duration.
    """

    t_s: np.ndarray
    hip_m: np.ndarray
    knee_m: np.ndarray
    heel_m: np.ndarray
    shank_angle_rad: np.ndarray
    camera_m: np.ndarray
    distance_m: np.ndarray
    phase: np.ndarray
    length_m: float
    duration_s: float


def stride_kinematics(step: SlipStep, body: SlipBody, camera_from_knee_m: float, *, stance_fraction: float = 0.6,
                      swing_ratio: float = 1.2, swing_peak_fraction: float = 0.25, swing_profile: str = "parabola",
                      swing_clearance_m: float = 0.12, dt_s: float = 0.002) -> StrideKinematics:
    """Leg kinematics of the camera leg in the three configurations (eq. 3.7-3.17).

    Parameters
    ----------
    step : the SLIP step; the stride is this step (camera-leg stance) then an identical one (other leg).
    stance_fraction : toe off as a fraction of the stride (thesis code: 0.6).
    swing_ratio : eta = theta_max / theta_int of the shank in swing (eq. 3.16, thesis 1.2).
    swing_peak_fraction : where in the swing the parabola reaches eta theta_int (thesis Appendix E: 1/4).
    swing_profile : "parabola" (eq. 3.16-3.17, the thesis: thigh angle linear, shank angle a parabola) or
        "heel" (the thesis' proposed refinement of the hip-to-shank kinematics: the heel travels from its
        toe-off position to the next heel strike, x_H + 2 step, on a minimum-jerk path; its height comes from the
        toe-off height (a quintic that starts at the toe rocker's vertical velocity) down to the floor by the end of mid swing
        (:data:`SWING_DESCENT_FRACTION` of the swing, Perry & Burnfield 2010; Winter 1992), lifted on the way by a
        clearance bump peaking at a third of that descent, then skims the floor to heel strike; knee and shank
        from the hip by inverse kinematics, the knee flexed at least :data:`SWING_MIN_KNEE_RAD` (fading to none at
        heel strike over terminal swing): out of reach the foot hangs short of the floor).
    swing_clearance_m : peak heel lift of the "heel" swing (a per-user body parameter).

    Notes
    -----
    Heel contact (heel fixed at x_H, until the end of the SLIP phase 1): knee from the two-link chain hip-knee-heel.
    Toe contact (foot pivoting about the toe x_T = x_H + L_ft, eq. 3.13-3.15): thigh and a virtual link
    knee-toe whose length and angle to the shank are frozen when the heel lifts (the thesis takes the foot at
    right angles to the shank, which makes the shank angle jump at heel lift). Swing: thigh angle linear in time
    from its toe-off value to the leg angle delta at the next heel strike; shank angle a parabola through its
    toe-off value, eta times it at the peak, and delta at heel strike.
    """
    T1, T = step.duration_s, 2.0 * step.duration_s
    n = max(int(round(T / dt_s)) + 1, 8)
    t = np.linspace(0.0, T, n)
    s = step.sol(np.where(t <= T1, t, t - T1))
    hip = np.column_stack([s[0] + np.where(t <= T1, 0.0, step.length_m), s[2]])
    lth, lsh, lft = body.thigh_length_m, body.shank_length_m, body.foot_length_m
    t_to = float(np.clip(stance_fraction, 0.3, 0.9)) * T
    t_hc = min(step.t_hc_s, t_to)
    phase = np.where(t <= t_hc, 0, np.where(t <= t_to, 1, 2))
    knee = np.empty_like(hip)
    heel = np.empty_like(hip)
    # heel contact
    m0 = phase == 0
    heel0 = np.array([step.heel_x_m, 0.0])
    heel[m0] = heel0
    knee[m0] = _two_link_knee(hip[m0], np.broadcast_to(heel0, hip[m0].shape), lth, lsh)
    # toe contact: the foot turns about the toe, the ankle keeps the angle it had when the heel lifted
    m1 = phase == 1
    toe = np.array([step.heel_x_m + lft, 0.0])
    if m1.any():
        i_last = int(np.flatnonzero(m0)[-1]) if m0.any() else 0
        k_t = knee[i_last] if m0.any() else _two_link_knee(hip[:1], heel0[None, :], lth, lsh)[0]
        kh, kt = heel0 - k_t, toe - k_t
        lvirt = float(np.hypot(*kt))
        beta = math.atan2(kt[0] * kh[1] - kt[1] * kh[0], kt[0] * kh[0] + kt[1] * kh[1])  # knee->toe to knee->heel
        k1 = _two_link_knee(hip[m1], np.broadcast_to(toe, hip[m1].shape), lth, lvirt)
        knee[m1] = k1
        ktn = (toe - k1) / np.hypot(*(toe - k1).T)[:, None]
        cb, sb = math.cos(beta), math.sin(beta)
        u = np.column_stack([cb * ktn[:, 0] - sb * ktn[:, 1], sb * ktn[:, 0] + cb * ktn[:, 1]])
        heel[m1] = k1 + lsh * u
    # swing
    m2 = phase == 2
    if m2.any():
        i0 = int(np.flatnonzero(m2)[0]) - 1
        k0, h0, g0 = knee[i0], heel[i0], hip[i0]
        th1_0 = math.atan2(k0[0] - g0[0], g0[1] - k0[1])
        th2_0 = math.atan2(h0[0] - k0[0], k0[1] - h0[1])
        delta = math.atan2(step.heel_x_m, step.crit_height_m)
        ts, te = t[i0], T
        tau = (t[m2] - ts) / (te - ts)
        if swing_profile == "parabola":  # eq. 3.16-3.17: thigh linear, shank through th2_0, eta th2_0, delta
            th1 = th1_0 + (delta - th1_0) * tau
            p = float(np.clip(swing_peak_fraction, 0.05, 0.95))
            a_mat = np.array([[0.0, 0.0, 1.0], [p * p, p, 1.0], [1.0, 1.0, 1.0]])
            c2 = np.linalg.solve(a_mat, np.array([th2_0, swing_ratio * th2_0, delta]))
            th2 = c2[0] * tau ** 2 + c2[1] * tau + c2[2]
            knee[m2] = hip[m2] + lth * np.column_stack([np.sin(th1), -np.cos(th1)])
            heel[m2] = knee[m2] + lsh * np.column_stack([np.sin(th2), -np.cos(th2)])
        elif swing_profile == "heel":  # heel path from toe off to the next heel strike, knee by inverse kinematics
            x_hs = step.heel_x_m + 2.0 * step.length_m
            mj = tau ** 3 * (10.0 - 15.0 * tau + 6.0 * tau ** 2)  # minimum-jerk progress
            hx = h0[0] + (x_hs - h0[0]) * mj
            # height: from the toe-off height and vertical velocity (the toe rocker's, over the last samples) down
            # to the floor by the end of mid swing, arriving with no velocity and acceleration (a quintic in
            # s = tau / SWING_DESCENT_FRACTION), plus the clearance bump peaking at s = 1/3; then on the floor
            j = max(i0 - 2, 0)
            vy0 = (h0[1] - heel[j, 1]) / max(t[i0] - t[j], 1e-9) * SWING_DESCENT_FRACTION * (te - ts)
            sd = np.clip(tau / SWING_DESCENT_FRACTION, 0.0, 1.0)
            hz = (h0[1] * (1.0 - 10.0 * sd ** 3 + 15.0 * sd ** 4 - 6.0 * sd ** 5)
                  + vy0 * (sd - 6.0 * sd ** 3 + 8.0 * sd ** 4 - 3.0 * sd ** 5)
                  + swing_clearance_m * 6.75 * sd * (1.0 - sd) ** 2)
            # out of reach (the heel on the floor with the hip far ahead): the foot hangs short toward it, the knee
            # flexed by SWING_MIN_KNEE_RAD instead of snapping straight; through terminal swing that least flexion
            # fades smoothly to the SLIP's straight leg at heel strike
            fade = np.clip((tau - SWING_DESCENT_FRACTION) / (1.0 - SWING_DESCENT_FRACTION), 0.0, 1.0)
            least_knee = SWING_MIN_KNEE_RAD * (1.0 - fade * fade * (3.0 - 2.0 * fade))
            reach = np.sqrt(lth ** 2 + lsh ** 2 + 2.0 * lth * lsh * np.cos(least_knee))
            d = np.column_stack([hx, hz]) - hip[m2]
            span = np.hypot(d[:, 0], d[:, 1])
            heel[m2] = hip[m2] + d * (np.minimum(span, reach) / span)[:, None]
            knee[m2] = _two_link_knee(hip[m2], heel[m2], lth, lsh)
        else:
            raise InputError(f"stride_kinematics: expected swing_profile 'parabola' or 'heel', found {swing_profile!r}")
    sh = heel - knee
    ang = np.arctan2(sh[:, 0], -sh[:, 1])
    u = sh / lsh
    cam = knee + camera_from_knee_m * u
    with np.errstate(divide="ignore", invalid="ignore"):
        dist = np.where(u[:, 1] < -1e-3, -cam[:, 1] / u[:, 1], np.inf)  # eq. 3.9
    return StrideKinematics(t_s=t, hip_m=hip, knee_m=knee, heel_m=heel, shank_angle_rad=ang, camera_m=cam,
                            distance_m=dist, phase=phase, length_m=2.0 * step.length_m, duration_s=T)


def simulate_flow(kin: StrideKinematics, focal_px: float, frame_interval_s: float | None = None) -> np.ndarray:
    """Optical flow at the image centre (eq. 3.18), px/s, positive for forward walking.

    ``frame_interval_s`` None: the instantaneous flow F = f (v_C . x_sh / D + omega_sh), the camera velocity normal
    to the shank over the distance D to the ground plus the shank's angular rate (x_sh: the forward normal of the
    shank), as the thesis has it. Given the camera's frame interval: what a patch tracker measures, the image
    displacement over one frame interval (centred on each sample time) of the floor point seen at the image
    centre, over the interval. The two differ where the shank sees the floor obliquely and moves fast: the point
    travels through the perspective of the image within the interval (on rendered walks, the stride read with the
    true geometry is -0.3% from the instantaneous flow, -2.7% from the displacement, up to -20% late in the swing).
    The stride repeats: beyond its ends the pose is that of the same phase, one stride ahead or behind.
    The image content moves backwards; the sign is flipped so that walking forward gives positive flow, as the
    thesis plots it.
    """
    t = kin.t_s
    a = kin.shank_angle_rad
    if frame_interval_s is None:
        vel = np.gradient(kin.camera_m, t, axis=0)
        omega = np.gradient(np.unwrap(a), t)
        normal = np.column_stack([np.cos(a), np.sin(a)])
        v_n = np.sum(vel * normal, axis=1)
        dist = np.maximum(kin.distance_m, 0.05)
        return focal_px * (v_n / dist + omega)
    if not (math.isfinite(frame_interval_s) and frame_interval_s > 0):
        raise InputError(f"simulate_flow: expected a positive frame_interval_s, found {frame_interval_s!r}")
    period = kin.duration_s
    ang = np.unwrap(a)

    def pose(tq):
        k = np.floor(tq / period)
        tm = tq - k * period
        x = np.interp(tm, t, kin.camera_m[:, 0]) + k * kin.length_m
        return x, np.interp(tm, t, kin.camera_m[:, 1]), np.interp(tm, t, ang)

    x0, y0, a0 = pose(t - 0.5 * frame_interval_s)
    x1, y1, a1 = pose(t + 0.5 * frame_interval_s)
    y0 = np.maximum(y0, 1e-3)
    ground = x0 + y0 * np.tan(a0)  # floor point on the optical axis at the interval's start (eq. 3.9)
    across = (ground - x1) * np.cos(a1) - y1 * np.sin(a1)  # in the camera frame at its end: along x_sh ...
    along = (ground - x1) * np.sin(a1) + y1 * np.cos(a1)  # ... and along the optical axis
    return -focal_px * across / np.maximum(along, 1e-3) / frame_interval_s
