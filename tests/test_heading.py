"""Attitude (offline VQF), yaw increments, walking direction and the heading columns of the steps table."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from pdr.constants import GRAVITY_MPS2
from pdr.heading import walking_direction
from pdr.heading.step_heading import wrap
from pdr.io.recording import Recording
from pdr.pipelines.steps import detect_steps
from pdr.signals import estimate_attitude, uniform_imu, yaw_increments
from pdr.signals.attitude import quat_mul


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
    assert wrap(d - direction) == pytest.approx(0.0, abs=0.05)
    assert quality > 0.5


@pytest.mark.parametrize("offset", [0.0, 1.2, np.pi])
def test_heading_follows_turn_whatever_device_offset(offset):
    imu, psi = turning_walk(offset_rad=offset, turn_rad=np.pi / 2)
    table = detect_steps(Recording(meta={"recording": {"id": "turn", "placement": "hand"}}, imu=imu), {})
    assert len(table) > 60
    before = table[table.t_s < 16]
    after = table[table.t_s > 24]
    turned = wrap(np.angle(np.mean(np.exp(1j * after.heading_rad))) - np.angle(np.mean(np.exp(1j * before.heading_rad))))
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
    assert wrap(np.angle(np.mean(np.exp(1j * ok))) - 0.4) == pytest.approx(0.0, abs=0.1)


def test_no_gyro_heading_change_zero_with_large_std():
    imu, _ = turning_walk(offset_rad=0.0, turn_rad=0.0)
    imu = imu[["t_s", "acc_x_mps2", "acc_y_mps2", "acc_z_mps2"]]
    with pytest.warns(UserWarning, match="no gyroscope"):
        table = detect_steps(Recording(meta={"recording": {"id": "ng", "placement": "hand"}}, imu=imu), {})
    assert (table.heading_change_rad == 0).all() and (table.heading_change_std_rad >= 1.0).all()
