"""Walking bouts and the external mechanical work of walking (``pdr.gait.mechanics``, ``bouts.csv`` of ``pdr run``)."""

from __future__ import annotations


import numpy as np
import pandas as pd
import pytest
from scipy.spatial.transform import Rotation

from pdr.cli.main import main
from pdr.constants import GRAVITY_MPS2
from pdr.errors import InputError, collect_warnings
from pdr.gait.mechanics import sensor_above_hip_m, step_energies, walking_bouts
from pdr.schema import BOUT_COLUMNS
from pdr.io.recording import save_recording
from pdr.signals import uniform_imu
from pdr.sim import simulate

MASS_KG = 70.0


def _scenario(placement: str = "waist", gnss: dict | None = None, mass: bool = True) -> dict:
    sc = {"subject": {"height_m": 1.75}, "route": {"waypoints_m": [[0.0, 0.0], [60.0, 0.0], [60.0, 30.0], [0.0, 30.0]]},
          "segment": [{"duration_s": 3.0, "speed_mps": 0.0}, {"duration_s": 25.0, "speed_mps": 1.3},
                      {"duration_s": 3.0, "speed_mps": 0.0}, {"duration_s": 20.0, "speed_mps": 0.9},
                      {"duration_s": 3.0, "speed_mps": 0.0}],
          "imu": [{"placement": placement, "rate_hz": 100.0}], "gnss": gnss or {"enabled": False}}
    if mass:
        sc["subject"]["mass_kg"] = MASS_KG
    return sc


@pytest.fixture(scope="module")
def walk():
    return simulate(_scenario(), seed=3)


def _bouts(rec, **kw):
    kw.setdefault("mass_kg", rec.subject.get("mass_kg"))
    kw.setdefault("sensor_above_hip_m", sensor_above_hip_m(rec.subject))
    with collect_warnings() as caught:
        bouts, steps = walking_bouts(rec.reference["steps"], placement=kw.pop("placement", rec.placement),
                                     imu=uniform_imu(rec.imu), **kw)
    return bouts, steps, list(caught)


def test_positive_increments_of_a_known_oscillation():
    """z = A cos(2 pi t / T) over steps of T: lift 2A per step; a climb is not a lift; lowering is not work."""
    t = np.arange(0.0, 10.0, 0.001)
    amp, period = 0.02, 0.5
    starts = np.arange(0.0, 9.5, period)
    z = amp * np.cos(2 * np.pi * t / period) + 0.05 * t  # + a 5 % slope
    v = 1.2 - 0.1 * np.cos(2 * np.pi * t / period)  # fastest when lowest, as in walking
    e = step_energies(t, z, v, starts, starts + period, MASS_KG)
    np.testing.assert_allclose(e["lift_m"], 2 * amp, rtol=2e-3)
    np.testing.assert_allclose(e["work_gravity_j"], MASS_KG * GRAVITY_MPS2 * 2 * amp, rtol=2e-3)
    np.testing.assert_allclose(e["speed_range_mps"], 0.2, rtol=1e-3)
    # kinetic energy from 1.1 to 1.3 m/s once per step: 1/2 m (1.3^2 - 1.1^2)
    np.testing.assert_allclose(e["work_inertia_j"], 0.5 * MASS_KG * (1.3**2 - 1.1**2), rtol=2e-3)
    assert (e["work_external_j"] <= e["work_gravity_j"] + e["work_inertia_j"] + 1e-9).all()
    down = step_energies(t, -0.05 * t, v, starts, starts + period, MASS_KG)  # walking downhill, no oscillation
    np.testing.assert_allclose(down["lift_m"], 0.0, atol=1e-12)
    no_mass = step_energies(t, z, v, starts, starts + period, None)
    assert no_mass["work_gravity_j"].isna().all() and no_mass["lift_m"].notna().all()


def test_trunk_imu_against_the_simulated_pelvis(walk):
    bouts, steps, messages = _bouts(walk)
    truth = walk.reference["bouts"]
    assert list(bouts.columns) == list(BOUT_COLUMNS) and len(bouts) == len(truth) == 2 and not messages
    assert (bouts["mechanics_source"] == "trunk_imu").all()
    np.testing.assert_allclose(bouts["vertical_lift_m"], truth["vertical_lift_m"], atol=0.005)
    np.testing.assert_allclose(bouts["power_gravity_w"], truth["power_gravity_w"], rtol=0.15)
    np.testing.assert_allclose(bouts["power_inertia_w"], truth["power_inertia_w"], rtol=0.15)
    assert bouts["vertical_lift_m"].iloc[0] > bouts["vertical_lift_m"].iloc[1]  # faster walking lifts more
    assert (steps["lift_m"] > 0).all() and len(steps) == bouts["n_steps"].sum() - len(bouts)
    # the sensor rides above the hips on a pitching pelvis: taken at the hips, its forward speed varies too much
    at_hips, _, _ = _bouts(walk, sensor_above_hip_m=0.0)
    assert (at_hips["power_inertia_w"] > 1.3 * truth["power_inertia_w"]).all()


def test_lever_arm_of_a_pitching_sensor():
    """A rigid trunk pitching about hips that move at a constant speed and height: the sensor above the hips sees a
    forward speed varying by 2 h A w, the hips' does not vary (v_sensor = v_hip + omega x r)."""
    rate, period, speed, lever, amp = 100.0, 0.55, 1.3, 0.14, np.radians(2.0)
    t = np.arange(0.0, 30.0, 1.0 / rate)
    w = 2 * np.pi / period
    th, dth, ddth = amp * np.sin(w * t), amp * w * np.cos(w * t), -amp * w * w * np.sin(w * t)
    # sensor at (v t + h sin(th), h cos(th)): world specific force, then in the pitched sensor frame
    fx = lever * (np.cos(th) * ddth - np.sin(th) * dth**2)
    fz = lever * (-np.sin(th) * ddth - np.cos(th) * dth**2) + GRAVITY_MPS2
    zero = np.zeros_like(t)
    imu = pd.DataFrame({"t_s": t, "acc_x_mps2": np.cos(th) * fx - np.sin(th) * fz, "acc_y_mps2": zero,
                        "acc_z_mps2": np.sin(th) * fx + np.cos(th) * fz, "gyr_x_radps": zero, "gyr_y_radps": dth,
                        "gyr_z_radps": zero})
    contacts = np.arange(2.0, 28.0, period)
    steps = pd.DataFrame({"t_s": contacts, "bout_id": 0, "step_length_m": speed * period})
    sensor_range = 2 * lever * amp * w
    with collect_warnings():
        at_sensor, _ = walking_bouts(steps, placement="waist", imu=uniform_imu(imu), mass_kg=MASS_KG)
        at_hips, _ = walking_bouts(steps, placement="waist", imu=uniform_imu(imu), mass_kg=MASS_KG,
                                   sensor_above_hip_m=lever)
    np.testing.assert_allclose(at_sensor["speed_variation_mps"], sensor_range, rtol=0.03)
    assert at_hips["speed_variation_mps"].iloc[0] < 0.02 * sensor_range
    assert at_hips["power_inertia_w"].iloc[0] < 0.02 * at_sensor["power_inertia_w"].iloc[0]


def test_sensor_height_above_the_hips():
    assert sensor_above_hip_m({"sensor_height_m": 1.02, "leg_length_m": 0.90}) == pytest.approx(0.12)
    assert sensor_above_hip_m({"sensor_height_m": 1.02, "height_m": 1.75}) == pytest.approx(1.02 - 0.53 * 1.75)
    for subject in ({}, {"height_m": 1.75}, {"sensor_height_m": 1.0}, {"sensor_height_m": 0.85, "leg_length_m": 0.9}):
        assert sensor_above_hip_m(subject) == 0.0


def test_sensor_mounting_and_mass_do_not_matter(walk):
    """Metamorphic: the same walk seen by a sensor mounted in any orientation gives the same mechanics; the powers
    scale with the mass and the lift does not."""
    bouts, _, _ = _bouts(walk)
    rot = Rotation.from_euler("xyz", [70.0, -30.0, 125.0], degrees=True)
    turned = walk.imu.copy()
    for kind in ("acc", "gyr", "mag"):
        cols = [f"{kind}_{a}_{'mps2' if kind == 'acc' else 'radps' if kind == 'gyr' else 'ut'}" for a in "xyz"]
        turned[cols] = rot.inv().apply(walk.imu[cols].to_numpy(float, copy=True))
    rec = type(walk)(meta=walk.meta, imu=turned, reference=walk.reference)
    other, _, _ = _bouts(rec)
    np.testing.assert_allclose(other["vertical_lift_m"], bouts["vertical_lift_m"], atol=5e-4)
    np.testing.assert_allclose(other[["power_gravity_w", "power_inertia_w"]], bouts[["power_gravity_w", "power_inertia_w"]], rtol=0.03)
    heavy, _, _ = _bouts(walk, mass_kg=2 * MASS_KG)
    np.testing.assert_allclose(heavy["power_external_w"], 2 * bouts["power_external_w"], rtol=1e-9)
    np.testing.assert_allclose(heavy["vertical_lift_m"], bouts["vertical_lift_m"], rtol=1e-12)


def test_no_mass_phone_in_pocket_and_one_step_bouts(walk):
    bouts, _, messages = _bouts(walk, mass_kg=None)
    assert bouts[["power_gravity_w", "power_inertia_w", "power_external_w"]].isna().all().all()
    assert bouts["vertical_lift_m"].notna().all()
    assert len(messages) == 1 and "mass_kg" in messages[0]
    pocket, _, messages = _bouts(walk, placement="pocket")
    assert pocket[["vertical_lift_m", "speed_variation_mps", "power_gravity_w"]].isna().all().all()
    assert (pocket["mechanics_source"] == "").all() and pocket["speed_mps"].notna().all()
    assert len(messages) == 1 and "pocket" in messages[0]
    steps = walk.reference["steps"]
    lone = pd.concat([steps, pd.DataFrame({"t_s": [steps["t_s"].max() + 5.0], "bout_id": [9],
                                           "step_length_m": [0.3]})], ignore_index=True)
    with collect_warnings() as caught:
        out, _ = walking_bouts(lone, placement="waist", imu=uniform_imu(walk.imu), mass_kg=MASS_KG)
    last = out.iloc[-1]
    assert last["n_steps"] == 1 and np.isnan(last["speed_mps"]) and np.isnan(last["vertical_lift_m"])
    assert [m for m in caught if "one step" in m]


def test_gnss_only_when_fast_and_precise():
    rec = simulate(_scenario("pocket", {"rate_hz": 5.0, "noise_m": 0.003, "markov_sigma_m": 0.003,
                                        "outlier_fraction": 0.0}), seed=4)
    fixes = rec.gnss.rename(columns={"alt_m": "u_m"})
    from pdr.geo import latlon_to_en

    fixes["e_m"], fixes["n_m"] = latlon_to_en(fixes["lat_deg"].to_numpy(), fixes["lon_deg"].to_numpy(), rec.geo_origin)
    bouts, _, messages = _bouts(rec, gnss=fixes)
    assert (bouts["mechanics_source"] == "gnss").all() and not messages
    assert bouts["vertical_lift_m"].between(0.01, 0.08).all()
    for slow in (fixes.iloc[::5], fixes.assign(h_acc_m=2.0)):  # 1 Hz / metre-level
        bouts, _, messages = _bouts(rec, gnss=slow)
        assert bouts["vertical_lift_m"].isna().all() and len(messages) == 1 and "GNSS" in messages[0]


def test_bad_input(walk):
    with pytest.raises(InputError, match="steps table"):
        walking_bouts(pd.DataFrame({"t_s": [1.0, 2.0]}), placement="waist")
    with pytest.raises(InputError, match="mass"):
        walking_bouts(walk.reference["steps"], placement="waist", imu=uniform_imu(walk.imu), mass_kg=-3.0)
    empty, steps = walking_bouts(walk.reference["steps"].iloc[:0], placement="waist")
    assert len(empty) == 0 and list(empty.columns) == list(BOUT_COLUMNS) and len(steps) == 0


def test_pdr_run_writes_bouts(tmp_path, capsys):
    rec = save_recording(simulate(_scenario(), seed=5), tmp_path / "rec")
    out = tmp_path / "out"
    assert main(["run", str(rec), "-o", str(out), "--plot"]) == 0
    bouts = pd.read_csv(out / "bouts.csv")
    truth = pd.read_csv(rec / "reference" / "bouts.csv")
    assert list(bouts.columns) == list(BOUT_COLUMNS) and (out / "bouts.png").is_file()
    assert len(bouts) == len(truth) and list(truth.columns) == list(BOUT_COLUMNS)
    np.testing.assert_allclose(bouts["vertical_lift_m"], truth["vertical_lift_m"], atol=0.005)
    # bad input: a mass that is not a number is one error line, exit 1, nothing written
    meta = (rec / "meta.toml").read_text().replace(f"mass_kg = {MASS_KG}", 'mass_kg = "heavy"')
    assert 'mass_kg = "heavy"' in meta
    (rec / "meta.toml").write_text(meta)
    capsys.readouterr()
    assert main(["run", str(rec), "-o", str(tmp_path / "bad")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:") and not (tmp_path / "bad").exists()


@pytest.mark.parametrize("case, placement, gnss, mass, says, empty", [
    ("no body mass", "waist", None, False, "mass_kg", ["power_gravity_w", "power_inertia_w", "power_external_w"]),
    ("phone in a pocket", "pocket", None, True, "pocket", ["vertical_lift_m", "speed_variation_mps", "power_external_w"]),
    ("phone in a hand, GNSS at 1 Hz", "hand", {"rate_hz": 1.0}, True, "GNSS at 1.0 Hz", ["vertical_lift_m"]),
    ("metre-level GNSS at 5 Hz", "pocket", {"rate_hz": 5.0}, True, "h_acc_m", ["vertical_lift_m", "power_gravity_w"]),
])
def test_pdr_run_says_once_what_bouts_csv_lacks(tmp_path, capsys, case, placement, gnss, mass, says, empty):
    """Bad input of the mechanics through ``pdr run``: the columns that cannot be had are empty, with one warning."""
    rec = save_recording(simulate(_scenario(placement, gnss, mass), seed=6), tmp_path / "rec")
    capsys.readouterr()
    assert main(["run", str(rec), "-o", str(tmp_path / "out")]) == 0
    lines = [line for line in capsys.readouterr().err.splitlines() if "bouts.csv" in line]
    assert len(lines) == 1 and lines[0].startswith("warning:") and says in lines[0], case
    bouts = pd.read_csv(tmp_path / "out" / "bouts.csv")
    assert len(bouts) == 2 and bouts[empty].isna().all().all() and bouts["speed_mps"].notna().all(), case
