"""Attitude (offline VQF), yaw increments, walking direction and the heading columns of the steps table."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from pdr.constants import GRAVITY_MPS2
from pdr.heading import gait_phase_sign, walking_direction
from pdr.schema import wrap_rad
from pdr.io.recording import Recording
from pdr.pipelines.steps import detect_steps
from pdr.signals import estimate_attitude, uniform_imu, yaw_increments
from pdr.signals.attitude import quat_mul
from conftest import warns


def rz(a: np.ndarray) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    out = np.zeros((len(a), 3, 3))
    out[:, 0, 0], out[:, 0, 1], out[:, 1, 0], out[:, 1, 1], out[:, 2, 2] = c, -s, s, c, 1.0
    return out


def turning_walk(*, offset_rad: float, turn_rad: float, rate_hz: float = 100.0, step_hz: float = 1.8, seed: int = 0,
                 with_mag: bool = False) -> tuple[pd.DataFrame, np.ndarray]:
    """A walker going straight, turning by ``turn_rad`` over 4 s, going straight again; the sensor is tilted and
    yawed by ``offset_rad`` from the walking direction. Trunk accelerations: impacts at each contact, a forward
    push/brake leading the vertical peak, a lateral sway at stride frequency. Returns (imu, heading(t))."""
    rng = np.random.default_rng(seed)
    t = np.arange(0, 40.0, 1 / rate_hz)
    s = np.clip((t - 18.0) / 4.0, 0, 1)
    psi = 0.4 + turn_rad * (3 * s ** 2 - 2 * s ** 3)
    dpsi = np.gradient(psi, t)
    contacts = np.arange(1.0, 39.0, 1 / step_hz)
    vert = np.zeros_like(t)
    fwd = np.zeros_like(t)
    for c in contacts:
        vert += 4.0 * np.exp(-0.5 * ((t - c - 0.02) / 0.04) ** 2) + 1.5 * np.exp(-0.5 * ((t - c - 0.12) / 0.05) ** 2)
        fwd += 1.5 * np.exp(-0.5 * ((t - c + 0.08) / 0.06) ** 2) - 1.5 * np.exp(-0.5 * ((t - c - 0.1) / 0.06) ** 2)
    vert -= vert.mean()
    lat = 0.8 * np.sin(np.pi * step_hz * t)
    a_world = np.column_stack([fwd * np.cos(psi) - lat * np.sin(psi), fwd * np.sin(psi) + lat * np.cos(psi), GRAVITY_MPS2 + vert])
    tilt = np.array([[1, 0, 0], [0, np.cos(0.5), -np.sin(0.5)], [0, np.sin(0.5), np.cos(0.5)]])
    r = rz(psi + offset_rad) @ tilt  # sensor -> world
    acc = np.einsum("nji,nj->ni", r, a_world) + 0.05 * rng.standard_normal((len(t), 3))
    gyr = np.einsum("nji,nj->ni", r, np.column_stack([np.zeros_like(t), np.zeros_like(t), dpsi]))
    gyr += 0.002 * rng.standard_normal(gyr.shape)
    cols = {"t_s": t, "acc_x_mps2": acc[:, 0], "acc_y_mps2": acc[:, 1], "acc_z_mps2": acc[:, 2],
            "gyr_x_radps": gyr[:, 0], "gyr_y_radps": gyr[:, 1], "gyr_z_radps": gyr[:, 2]}
    if with_mag:
        b_world = np.array([0.0, 20.0, -40.0])  # north and down, µT
        mag = np.einsum("nji,j->ni", r, b_world)
        cols.update(mag_x_ut=mag[:, 0], mag_y_ut=mag[:, 1], mag_z_ut=mag[:, 2])
    return pd.DataFrame(cols), psi


def test_vqf_earth_frame_is_enu():
    n = 400
    imu = pd.DataFrame({"t_s": np.arange(n) / 100.0, "acc_x_mps2": 0.0, "acc_y_mps2": 0.0, "acc_z_mps2": GRAVITY_MPS2,
                        "gyr_x_radps": 0.0, "gyr_y_radps": 0.0, "gyr_z_radps": 0.0,
                        "mag_x_ut": 0.0, "mag_y_ut": 20.0, "mag_z_ut": -40.0})
    att = estimate_attitude(uniform_imu(imu))
    assert np.allclose(np.abs(att.q9_wxyz[-1]), [1, 0, 0, 0], atol=1e-3)  # x east, y north, z up: identity


def test_yaw_increments_independent_of_device_tilt():
    psi = np.linspace(0, 3.0, 200)
    half = 0.5 * psi
    qz = np.column_stack([np.cos(half), 0 * half, 0 * half, np.sin(half)])
    tilt = np.tile([np.cos(0.7), np.sin(0.7), 0.0, 0.0], (200, 1))  # device pitched by 80 degrees
    q = quat_mul(qz, tilt)
    assert np.sum(yaw_increments(q)) == pytest.approx(3.0, abs=1e-9)


@pytest.mark.parametrize("direction", [0.3, 2.0, -2.5])
def test_walking_direction_resolves_180_degrees(direction):
    rate, f = 100.0, 1.8
    t = np.arange(0, 4, 1 / rate)
    w = 2 * np.pi * f
    fwd, vert, lat = np.sin(w * t), -np.cos(w * t), 0.7 * np.sin(0.5 * w * t)  # forward leads vertical by 90 degrees
    a = np.column_stack([fwd * np.cos(direction) - lat * np.sin(direction), fwd * np.sin(direction) + lat * np.cos(direction), vert])
    d, quality = walking_direction(a, rate, 1 / f)
    assert wrap_rad(d - direction) == pytest.approx(0.0, abs=0.05)
    assert quality > 0.5


@pytest.mark.parametrize("offset", [0.0, 1.2, np.pi])
def test_heading_follows_turn_whatever_device_offset(offset):
    imu, psi = turning_walk(offset_rad=offset, turn_rad=np.pi / 2)
    table = detect_steps(Recording(meta={"recording": {"id": "turn", "placement": "hand"}}, imu=imu), {})
    assert len(table) > 60
    before = table[table.t_s < 16]
    after = table[table.t_s > 24]
    turned = wrap_rad(np.angle(np.mean(np.exp(1j * after.heading_rad))) - np.angle(np.mean(np.exp(1j * before.heading_rad))))
    assert turned == pytest.approx(np.pi / 2, abs=0.1)
    assert table.heading_change_rad.sum() == pytest.approx(np.pi / 2, abs=0.15)
    assert (table.heading_change_std_rad > 0).all() and table.mag_heading_rad.isna().all()


@pytest.mark.parametrize("offset", [0.8, -2.0])
def test_mag_heading_absolute(offset):
    """With a magnetometer the walking direction (0.4 rad from east) is found whatever the device's yaw offset."""
    imu, psi = turning_walk(offset_rad=offset, turn_rad=0.0, with_mag=True)
    table = detect_steps(Recording(meta={"recording": {"id": "mag", "placement": "hand"}}, imu=imu), {})
    ok = table.mag_heading_rad.dropna()
    assert len(ok) > 0.8 * len(table)
    assert wrap_rad(np.angle(np.mean(np.exp(1j * ok))) - 0.4) == pytest.approx(0.0, abs=0.1)


def test_no_gyro_heading_change_zero_with_large_std():
    imu, _ = turning_walk(offset_rad=0.0, turn_rad=0.0)
    imu = imu[["t_s", "acc_x_mps2", "acc_y_mps2", "acc_z_mps2"]]
    with warns(match="no gyroscope"):
        table = detect_steps(Recording(meta={"recording": {"id": "ng", "placement": "hand"}}, imu=imu), {})
    assert (table.heading_change_rad == 0).all() and (table.heading_change_std_rad >= 1.0).all()


def running_stretch(direction: float, *, rate: float = 100.0, step_hz: float = 2.8, duration_s: float = 6.0,
                    duty: float = 0.6) -> np.ndarray:
    """Earth-frame acceleration (gravity removed) of a spring-mass run: in each step a stance of ``duty`` of the step
    with a half-sine vertical force (mean 1 g over the step) and braking then propulsion, then a flight at 0 g."""
    t = np.arange(0, duration_s, 1 / rate)
    ph = (t * step_hz) % 1.0
    stance = ph < duty
    fz = np.where(stance, np.pi / (2 * duty) * np.sin(np.pi * ph / duty), 0.0) * GRAVITY_MPS2
    fwd = np.where(stance, -3.0 * np.sin(2 * np.pi * ph / duty), 0.0)  # braking first half of stance, then propulsion
    lat = 0.7 * np.sin(np.pi * step_hz * t)
    return np.column_stack([fwd * np.cos(direction) - lat * np.sin(direction),
                            fwd * np.sin(direction) + lat * np.cos(direction), fz - GRAVITY_MPS2])


@pytest.mark.parametrize("direction", [0.3, 2.0, -2.5])
def test_walking_direction_of_a_run_with_a_flight_phase(direction):
    """Running reverses the walking phase relation (the forward acceleration lags the vertical one by a quarter
    step); the flight phase (0 g) tells the two gaits apart, so a run does not point backwards."""
    rate, step_hz = 100.0, 2.8
    a = running_stretch(direction, rate=rate, step_hz=step_hz)
    assert (gait_phase_sign(a[:, 2], rate, 1 / step_hz) == -1.0).all()
    d, quality = walking_direction(a, rate, 1 / step_hz)
    assert wrap_rad(d - direction) == pytest.approx(0.0, abs=0.1)
    assert quality > 0.3


def test_gait_phase_sign_walking_and_in_between():
    rate, step_hz = 100.0, 1.8
    t = np.arange(0, 4, 1 / rate)
    walk = -0.3 * GRAVITY_MPS2 * np.cos(2 * np.pi * step_hz * t)  # vertical specific force 0.7-1.3 g: no flight
    assert (gait_phase_sign(walk, rate, 1 / step_hz) == 1.0).all()
    unsure = -0.675 * GRAVITY_MPS2 * np.cos(2 * np.pi * step_hz * t)  # trough at 0.325 g: half-way, no vote
    assert np.abs(gait_phase_sign(unsure, rate, 1 / step_hz)[50:-50]).max() < 0.1


def test_run_inside_a_walk_keeps_the_heading():
    """A waist IMU walking, running at 3 m/s, walking again along an L-shaped route (``pdr simulate``): the heading
    of every step, running ones included, within 30 degrees of the truth and the running steps' median within 6
    degrees (before the flight-phase rule the running steps pointed backwards, 175 degrees off)."""
    from pdr.sim import simulate

    rec = simulate({"route": {"waypoints_m": [[0.0, 0.0], [60.0, 0.0], [60.0, 80.0]], "loop": False},
                    "segment": [{"duration_s": 2.0, "speed_mps": 0.0}, {"duration_s": 20.0, "speed_mps": 1.3},
                                {"duration_s": 20.0, "speed_mps": 3.0}, {"duration_s": 20.0, "speed_mps": 1.3},
                                {"duration_s": 2.0, "speed_mps": 0.0}],
                    "imu": [{"placement": "waist", "rate_hz": 100.0, "magnetometer": False}],
                    "gnss": {"enabled": False}}, seed=1)
    table = detect_steps(rec, {})
    ref, ref_steps = rec.reference["trajectory"], rec.reference["steps"]
    t = table.t_s.to_numpy()
    truth = np.interp(t, ref.t_s, np.unwrap(ref.heading_rad))
    speed = ref_steps.speed_mps.to_numpy()[np.clip(np.searchsorted(ref_steps.t_s, t), 0, len(ref_steps) - 1)]
    running = speed > 2.2
    assert running.sum() > 40 and (~running).sum() > 40
    diff = table.heading_rad.to_numpy() - truth
    err = np.abs(wrap_rad(diff - np.angle(np.mean(np.exp(1j * diff[~running])))))  # the 6D frame's yaw zero is arbitrary
    assert np.degrees(err.max()) < 30.0
    assert np.degrees(np.median(err[running])) < 6.0
