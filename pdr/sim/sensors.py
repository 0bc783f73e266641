"""Sensor synthesis from the body kinematics: IMU (specific force, angular rate), magnetometer, barometer.

Specific force is ``R^T (a_world - g_world)`` with ``a_world`` the second derivative of the sensor's world position
(a 5-point central difference at the IMU rate, fourth-order accurate) and ``g_world = (0, 0, -9.80665)``, so a
sensor at rest reads +9.80665 m/s² along its world-up axis. Angular rate is the body-frame rate of the rotation
sequence, ``log(R(t-dt)^T R(t+dt)) / 2 dt``. Errors: white noise, a constant bias per axis, a gyro bias random
walk, a magnetometer hard-iron offset and local disturbances near steel, barometer noise and a weather drift.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from pdr.constants import GRAVITY_MPS2
from pdr.errors import InputError
from pdr.sim.gait import WalkKinematics, _smoothstep, rotation_zyx

WAIST_ABOVE_HIP_PER_HEIGHT = 0.08  # lower-back sensor height minus hip height, per body height (see below)


def waist_sensor_above_hip_m(body) -> float:
    """Height of a lower-back (L4-L5) sensor above the hip joints: 0.08 H. The Mobilise-D lab participants' measured
    sensor heights are 0.61-0.62 of their height (mobgap example data, ``infoForAlgo.mat`` SensorHeight / Height),
    the hip joints 0.53 H (Winter 2009)."""
    return WAIST_ABOVE_HIP_PER_HEIGHT * body.height_m


IMU_PLACEMENTS = ("waist", "pocket", "hand", "foot_left", "foot_right", "shank_left", "shank_right")
G_WORLD = np.array([0.0, 0.0, -GRAVITY_MPS2])
CHUNK_SAMPLES = 20000
STEEL_RANGE_M = 10.0  # a steel dipole of 25 µT at 1 m adds < 0.03 µT beyond

# Sensor axes expressed in the segment frame they ride on (columns: sensor x, y, z).
_POCKET_IN_THIGH = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])  # phone upright, screen forward
_PHONE_IN_BODY = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # x right, y forward, z up


@dataclasses.dataclass(frozen=True)
class ImuSpec:
    """One simulated IMU (a ``[[imu]]`` table of the scenario).

    Parameters: ``placement`` (one of IMU_PLACEMENTS), ``rate_hz``, white noise ``acc_noise_mps2`` /
    ``gyr_noise_radps`` (1-sigma per sample), constant bias spreads ``acc_bias_mps2`` / ``gyr_bias_radps``
    (1-sigma of the draw), ``gyr_bias_walk_radps_per_sqrt_s`` (random walk), ``magnetometer`` and ``barometer``
    (columns on or off), ``mag_noise_ut``, ``mag_hard_iron_ut``, ``hand_yaw_offset_deg`` (phone in hand: yaw
    between the phone's forward axis and the walking direction), ``hand_tilt_deg`` (screen tilt towards the face),
    ``in_pocket_s`` (phone in hand: [start, end] intervals in which it is in the trouser pocket instead; it is put away
    over the ``handling_s`` before each and taken out over the ``handling_s`` after each, see :func:`handling_intervals`).
    Defaults are those of a consumer MEMS unit (angle random walk ~1.4 deg/sqrt(h), turn-on bias ~0.1 deg/s, bias
    random walk 1e-5 rad/s/sqrt(s), accelerometer bias ~0.05 m/s²).
    """

    placement: str = "waist"
    rate_hz: float = 100.0
    acc_noise_mps2: float = 0.04
    gyr_noise_radps: float = 0.004
    acc_bias_mps2: float = 0.05
    gyr_bias_radps: float = 0.002
    gyr_bias_walk_radps_per_sqrt_s: float = 1e-5
    magnetometer: bool = True
    barometer: bool = True
    mag_noise_ut: float = 0.4
    mag_hard_iron_ut: float = 2.0
    baro_noise_hpa: float = 0.03
    hand_yaw_offset_deg: float = 12.0
    hand_tilt_deg: float = 35.0
    in_pocket_s: tuple = ()
    handling_s: float = 2.0

    def __post_init__(self):
        if self.placement not in IMU_PLACEMENTS:
            raise InputError(f"imu.placement: expected one of {', '.join(IMU_PLACEMENTS)}, found {self.placement!r}")
        if self.in_pocket_s and self.placement != "hand":
            raise InputError(f"imu.in_pocket_s: expected only for a phone in the hand, found placement {self.placement!r}")
        if not 0.5 <= self.handling_s <= 10.0:
            raise InputError(f"imu.handling_s: expected 0.5-10 s, found {self.handling_s}")
        if any(len(iv) != 2 or not 0 <= iv[0] < iv[1] for iv in self.in_pocket_s):
            raise InputError(f"imu.in_pocket_s: expected [start, end] pairs with 0 <= start < end, found {list(self.in_pocket_s)}")
        if not 10.0 <= self.rate_hz <= 2000.0:
            raise InputError(f"imu.rate_hz: expected 10-2000 Hz, found {self.rate_hz}")
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if f.type == "float" and (not np.isfinite(v) or v < 0) and f.name != "hand_yaw_offset_deg":
                raise InputError(f"imu.{f.name}: expected a finite number >= 0, found {v}")


def _smooth_random(rng: np.random.Generator, t: np.ndarray, amplitude: float, periods_s=(2.7, 5.3, 11.0, 23.0)) -> np.ndarray:
    """A smooth zero-mean random signal: sinusoids of the given periods with random phases, RMS ~ amplitude."""
    out = np.zeros_like(t)
    for p in periods_s:
        out += np.sin(2 * np.pi * t / (p * rng.uniform(0.8, 1.25)) + rng.uniform(0, 2 * np.pi))
    return amplitude * out * np.sqrt(2.0 / len(periods_s))


def handling_intervals(spec: ImuSpec, duration_s: float) -> pd.DataFrame:
    """``reference/handling.csv`` of a phone in the hand: ``t_start_s, t_end_s, action`` (``put_away`` over the
    ``handling_s`` before each ``in_pocket_s`` interval, ``take_out`` over the ``handling_s`` after it), within the recording."""
    rows = []
    for a, b in spec.in_pocket_s:
        for t0, action in ((a - spec.handling_s, "put_away"), (b, "take_out")):
            lo, hi = max(t0, 0.0), min(t0 + spec.handling_s, duration_s)
            if hi > lo:
                rows.append((lo, hi, action))
    return pd.DataFrame(sorted(rows), columns=["t_start_s", "t_end_s", "action"])


class SensorPose:
    """Position and orientation (sensor -> world) of a sensor at a placement, at any times.

    A phone in the hand with ``in_pocket_s`` intervals rides in the left trouser pocket during them (the pocket
    placement's pose) and moves between pocket and hand over ``handling_s`` (a minimum-jerk blend of the two poses,
    the quintic ramp of a reach, Flash & Hogan 1985:
    positions interpolated, the rotation from pocket to hand followed along its geodesic), fumbled on the way: a
    smooth random offset of about 3 cm and turn of about 30° that vanish at both ends (the fingers gripping, turning
    the phone to find its screen).
    """

    def __init__(self, kin: WalkKinematics, spec: ImuSpec, rng: np.random.Generator):
        self.kin, self.spec = kin, spec
        # the phone's own slow motions in the hand (fixed at construction, so any times can be asked)
        self._sway_seed = int(rng.integers(2**31))

    def _hand(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        kin, spec = self.kin, self.spec
        rng = np.random.default_rng(self._sway_seed)
        psi = kin.route.heading_rad(kin.pelvis_state(t)["s_m"])
        sway = [_smooth_random(rng, t, a) for a in (0.02, 0.015, 0.015)]
        d_yaw, d_tilt, d_roll = (np.radians(_smooth_random(rng, t, a)) for a in (3.0, 3.0, 2.0))
        zero = np.zeros_like(t)
        local = np.stack([0.38 + sway[0], -0.12 + sway[1], 0.30 + sway[2]], -1)  # before the chest, right hand
        pos = kin.pelvis_position_m(t) + np.einsum("nij,nj->ni", rotation_zyx(psi, zero, zero), local)
        yaw = rotation_zyx(psi + np.radians(spec.hand_yaw_offset_deg) + d_yaw, zero, zero)
        tilt = Rotation.from_rotvec(np.stack([np.radians(spec.hand_tilt_deg) + d_tilt, zero, d_roll], -1)).as_matrix()
        return pos, yaw @ _PHONE_IN_BODY @ tilt

    def _pocket(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        j, rot = self.kin.segment_pose(t, "thigh_left")
        pos = j["hip_left"] + np.einsum("nij,j->ni", rot, np.array([0.07, 0.0, 0.3 * self.kin.body.thigh_m]))
        return pos, rot @ _POCKET_IN_THIGH

    def _handled(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The hand pose, the pocket pose during ``in_pocket_s`` and the moves between them."""
        h = self.spec.handling_s
        w = np.ones_like(t)  # 1: in the hand, 0: in the pocket
        for a, b in self.spec.in_pocket_s:
            w *= 1.0 - _smoothstep((t - (a - h)) / h) * (1.0 - _smoothstep((t - b) / h))
        pos, rot = self._hand(t)
        if (w < 1.0).any():
            p_pocket, r_pocket = self._pocket(t)
            rel = Rotation.from_matrix(np.einsum("nji,njk->nik", r_pocket, rot)).as_rotvec()
            rng = np.random.default_rng([self._sway_seed, 1])
            envelope = (4.0 * w * (1.0 - w)) ** 2
            fumble = np.stack([_smooth_random(rng, t, 0.03, (0.6, 1.1, 1.9)) for _ in range(3)], -1)
            turn = np.stack([np.radians(_smooth_random(rng, t, 30.0, (0.8, 1.5, 2.6))) for _ in range(3)], -1)
            pos = p_pocket + w[:, None] * (pos - p_pocket) + envelope[:, None] * fumble
            rot = r_pocket @ Rotation.from_rotvec(w[:, None] * rel).as_matrix() @ \
                Rotation.from_rotvec(envelope[:, None] * turn / np.sqrt(3.0)).as_matrix()
        return pos, rot

    def __call__(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        kin, spec = self.kin, self.spec
        place = spec.placement
        if place == "waist":
            rot = kin.segment_rotation(t, "pelvis")
            # on the lower back (L4-L5, a belt): behind and above the hip joints
            return kin.pelvis_position_m(t) + rot @ np.array([-0.10, 0.0, waist_sensor_above_hip_m(kin.body)]), rot
        if place == "hand":
            return self._handled(t) if spec.in_pocket_s else self._hand(t)
        if place == "pocket":
            return self._pocket(t)
        part, side = place.split("_")
        j, rot = kin.segment_pose(t, place)
        if part == "foot":
            return j[f"ankle_{side}"] + np.einsum("nij,j->ni", rot, np.array([0.05, 0.0, 0.01])), rot  # on the instep
        return j[f"knee_{side}"] + np.einsum("nij,j->ni", rot, np.array([0.04, 0.0, 0.5 * kin.body.shank_m])), rot


def true_motion(pose: SensorPose, t: np.ndarray, oversample: int = 4, dt_s: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Noise-free specific force (N, 3), body angular rate (N, 3), positions and rotations at times t
    (uniformly spaced by ``dt_s``, by default the first interval).

    Like a real IMU's anti-aliasing, each sample is the mean over its interval [t - dt/2, t + dt/2] of the signals
    computed on a grid ``oversample`` times finer (so integrating the samples gives the true velocity and angle
    increments even through heel-strike transients).
    """
    dt = float(t[1] - t[0]) if dt_s is None else float(dt_s)
    k = max(int(oversample), 1)
    h = dt / k
    offs = (np.arange(k) + 0.5) * h - 0.5 * dt
    tf = (t[:, None] + offs[None, :]).ravel()
    te = np.concatenate([tf[0] - h * np.arange(2, 0, -1), tf, tf[-1] + h * np.arange(1, 3)])
    pos, rot = pose(te)
    acc = (-pos[4:] + 16 * pos[3:-1] - 30 * pos[2:-2] + 16 * pos[1:-3] - pos[:-4]) / (12 * h * h)
    f = np.einsum("nji,nj->ni", rot[2:-2], acc - G_WORLD)
    rel = np.einsum("nji,njk->nik", rot[1:-3], rot[3:-1])  # R(t-h)^T R(t+h)
    gyr = Rotation.from_matrix(rel).as_rotvec() / (2 * h)
    f = f.reshape(len(t), k, 3).mean(axis=1)
    gyr = gyr.reshape(len(t), k, 3).mean(axis=1)
    p_at, r_at = pose(t)
    return f, gyr, p_at, r_at


@dataclasses.dataclass(frozen=True)
class MagneticField:
    """Earth field (``field_ut``, ``inclination_deg`` (+ = pointing down), ``declination_deg``) plus steel
    disturbances: point dipoles of strength ``steel_ut`` (µT at 1 m) at ``sources_enu`` (N, 3) with unit moments."""

    field_ut: float = 48.0
    inclination_deg: float = 64.0
    declination_deg: float = 2.0
    steel_ut: float = 25.0
    sources_enu: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 3)))
    moments: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 3)))

    def earth_enu(self) -> np.ndarray:
        inc, dec = np.radians(self.inclination_deg), np.radians(self.declination_deg)
        return self.field_ut * np.array([np.cos(inc) * np.sin(dec), np.cos(inc) * np.cos(dec), -np.sin(inc)])

    def at(self, pos: np.ndarray) -> np.ndarray:
        """World field (µT) at positions (N, 3); sources farther than ``STEEL_RANGE_M`` are neglected."""
        b = np.broadcast_to(self.earth_enu(), pos.shape).copy()
        if not len(self.sources_enu):
            return b
        near = cKDTree(self.sources_enu).query(pos, distance_upper_bound=STEEL_RANGE_M)[0] < np.inf
        p = pos[near]
        for src, m in zip(self.sources_enu, self.moments):
            r = p - src
            d = np.maximum(np.linalg.norm(r, axis=1), 0.3)
            rh = r / d[:, None]
            b[near] += self.steel_ut * (3 * (rh @ m)[:, None] * rh - m) / d[:, None] ** 3
        return b


def place_steel(positions_enu: np.ndarray, spacing_m: float, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Steel sources beside a path (every ``spacing_m`` of it, 0.5-2 m to a random side, 0-2.5 m high)."""
    if len(positions_enu) < 2 or spacing_m <= 0:
        return np.zeros((0, 3)), np.zeros((0, 3))
    d = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(positions_enu[:, :2], axis=0), axis=1))])
    marks = np.arange(0.5 * spacing_m, d[-1], spacing_m)
    idx = np.searchsorted(d, marks)
    base = positions_enu[idx]
    ang = rng.uniform(0, 2 * np.pi, len(idx))
    dist = rng.uniform(0.5, 2.0, len(idx))
    src = np.column_stack([base[:, 0] + dist * np.cos(ang), base[:, 1] + dist * np.sin(ang), rng.uniform(0.0, 2.5, len(idx))])
    m = rng.standard_normal((len(idx), 3))
    m /= np.linalg.norm(m, axis=1, keepdims=True)
    return src, m


def pressure_hpa(alt_m: np.ndarray) -> np.ndarray:
    """International standard atmosphere (ICAO), sea-level 1013.25 hPa."""
    return 1013.25 * (1.0 - 2.25577e-5 * alt_m) ** 5.25588


def synthesize_imu(kin: WalkKinematics, spec: ImuSpec, t: np.ndarray, rng: np.random.Generator, *,
                   mag: MagneticField, origin_alt_m: float = 0.0, baro_drift_hpa_per_h: float = 0.3) -> pd.DataFrame:
    """An ``imu.csv`` table of one placement at times t (uniform grid), with all sensor errors."""
    pose = SensorPose(kin, spec, rng)
    parts = [true_motion(pose, t[i:i + CHUNK_SAMPLES], dt_s=1.0 / spec.rate_hz) for i in range(0, len(t), CHUNK_SAMPLES)]  # bounded memory
    f, w, pos, rot = (np.concatenate([p[k] for p in parts]) for k in range(4))
    n = len(t)
    dt = float(t[1] - t[0])
    acc = f + spec.acc_bias_mps2 * rng.standard_normal(3) + spec.acc_noise_mps2 * rng.standard_normal((n, 3))
    walk = np.cumsum(spec.gyr_bias_walk_radps_per_sqrt_s * np.sqrt(dt) * rng.standard_normal((n, 3)), axis=0)
    gyr = w + spec.gyr_bias_radps * rng.standard_normal(3) + walk + spec.gyr_noise_radps * rng.standard_normal((n, 3))
    out = {"t_s": t, "acc_x_mps2": acc[:, 0], "acc_y_mps2": acc[:, 1], "acc_z_mps2": acc[:, 2],
           "gyr_x_radps": gyr[:, 0], "gyr_y_radps": gyr[:, 1], "gyr_z_radps": gyr[:, 2]}
    if spec.magnetometer:
        b = np.einsum("nji,nj->ni", rot, mag.at(pos))
        b += spec.mag_hard_iron_ut * rng.standard_normal(3) + spec.mag_noise_ut * rng.standard_normal((n, 3))
        out.update({"mag_x_ut": b[:, 0], "mag_y_ut": b[:, 1], "mag_z_ut": b[:, 2]})
    if spec.barometer:
        drift = rng.normal(0.0, baro_drift_hpa_per_h) * (t - t[0]) / 3600.0
        out["baro_hpa"] = pressure_hpa(origin_alt_m + pos[:, 2]) + drift + spec.baro_noise_hpa * rng.standard_normal(n)
    return pd.DataFrame(out)
