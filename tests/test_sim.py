"""The walking simulator: determinism, physics of the body kinematics and the sensors, GNSS errors, files, CLI."""

from __future__ import annotations

import copy
import dataclasses
from pathlib import Path

import numpy as np
import pytest
from scipy.ndimage import maximum_filter1d

from pdr.cli.main import main
from pdr.constants import GRAVITY_MPS2
from pdr.errors import InputError
from pdr.geo import latlon_to_en
from pdr.io.recording import load_recording
from pdr.io.tomlio import read_toml
from pdr.sim import WalkKinematics, simulate, simulate_to_disk
from pdr.sim.sensors import ImuSpec, SensorPose, true_motion
from pdr.sim.simulator import build_walk, parse_scenario
from conftest import warns

ROOT = Path(__file__).resolve().parents[1]
SHORT = ROOT / "configs" / "sim" / "walk_short.toml"


def _scenario(segments, *, waypoints=((0.0, 0.0), (200.0, 0.0)), **tables):
    """A scenario dict; ``segments``: (duration_s, speed_mps[, indoor]) tuples."""
    sc = {"route": {"waypoints_m": [list(w) for w in waypoints], "loop": False},
          "segment": [{"duration_s": s[0], "speed_mps": s[1], "indoor": len(s) > 2 and s[2]} for s in segments]}
    sc.update(tables)
    return sc


@pytest.fixture(scope="module")
def steady_walk() -> WalkKinematics:
    return WalkKinematics.steady(speed_mps=1.3, duration_s=20.0, seed=4)


# ---------------------------------------------------------------------------------------------------------------
# Determinism and files
# ---------------------------------------------------------------------------------------------------------------

def _files(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_same_seed_gives_byte_identical_files(tmp_path):
    a = simulate_to_disk(SHORT, tmp_path / "a", seed=7)
    b = simulate_to_disk(SHORT, tmp_path / "b", seed=7)
    c = simulate_to_disk(SHORT, tmp_path / "c", seed=8)
    fa, fb, fc = _files(a), _files(b), _files(c)
    assert set(fa) >= {"meta.toml", "imu.csv", "gnss.csv", "reference/steps.csv", "reference/strides.csv",
                       "reference/trajectory.csv", "reference/summary.toml"}
    assert fa == fb
    assert fa["imu.csv"] != fc["imu.csv"] and fa["gnss.csv"] != fc["gnss.csv"]


def test_recording_validates_and_reference_is_consistent(tmp_path):
    rec = load_recording(simulate_to_disk(SHORT, tmp_path / "rec", seed=1))
    assert rec.placement == "waist" and rec.geo_origin is not None
    assert abs(rec.sample_rate_hz - 100.0) < 1e-6 and {"mag_x_ut", "baro_hpa", "gyr_z_radps"} <= set(rec.imu.columns)
    ref = rec.reference
    steps, strides, summ = ref["steps"], ref["strides"], ref["summary"]
    assert summ["n_steps"] == len(steps) > 100
    assert np.all(np.diff(steps["t_s"]) > 0.2)  # one contact at a time, no double counting
    assert set(steps["foot"]) == {"left", "right"}
    assert (steps["foot"].to_numpy()[1:] != steps["foot"].to_numpy()[:-1]).all()  # feet alternate
    assert summ["distance_m"] == pytest.approx(steps["step_length_m"].sum())
    assert summ["path_length_m"] == pytest.approx(summ["distance_m"], rel=0.01)
    # a stride's heel travel is about the pelvis travel over its two steps
    s = steps.set_index("t_s")["step_length_m"]
    two = np.array([s.loc[(s.index > a) & (s.index <= b)].sum() for a, b in zip(strides.t_start_s, strides.t_end_s)])
    assert np.median(np.abs(strides["length_m"] - two)) < 0.05
    # segment speeds follow the scenario
    got, want = np.array(summ["segment_speed_mps"]), np.array(summ["segment_target_speed_mps"])
    moving = want > 0
    assert np.allclose(got[moving], want[moving], rtol=0.08)


# ---------------------------------------------------------------------------------------------------------------
# Body kinematics
# ---------------------------------------------------------------------------------------------------------------

def test_body_proportions_keep_the_leg_length():
    from pdr.sim.people import Body
    winter, low_knee = Body(1.75), Body(1.75, leg_scale=1.02, knee_scale=0.95)
    assert low_knee.leg_length_m == pytest.approx(Body(1.75, leg_scale=1.02).leg_length_m)  # the knee moves in the leg
    assert low_knee.shank_m == pytest.approx(0.95 * 1.02 * winter.shank_m)
    assert low_knee.thigh_m > 1.02 * winter.thigh_m
    with pytest.raises(InputError, match="knee_scale"):
        Body(1.75, knee_scale=1.3)


def test_kinematics_interface_and_rigid_segments(steady_walk):
    kin = steady_walk
    t = np.linspace(0.0, kin.duration_s, 700)
    j = kin.joint_positions_m(t)
    names = {f"{p}_{s}" for p in ("hip", "knee", "ankle", "heel", "toe") for s in ("left", "right")} | {"pelvis"}
    assert set(j) == names and all(v.shape == (len(t), 3) for v in j.values())
    for side in ("left", "right"):
        thigh = np.linalg.norm(j[f"knee_{side}"] - j[f"hip_{side}"], axis=1)
        shank = np.linalg.norm(j[f"ankle_{side}"] - j[f"knee_{side}"], axis=1)
        assert np.ptp(thigh) < 1e-6 and np.ptp(shank) < 1e-6
        assert thigh[0] == pytest.approx(0.245 * 1.75) and shank[0] == pytest.approx(0.246 * 1.75)
        rot = kin.segment_rotation(t, f"shank_{side}")
        assert np.allclose(rot @ rot.transpose(0, 2, 1), np.eye(3), atol=1e-9)
        assert np.allclose(np.linalg.det(rot), 1.0)
        axis = (j[f"ankle_{side}"] - j[f"knee_{side}"]) / shank[:, None]
        assert np.allclose(rot[:, :, 2], axis, atol=1e-9)  # shank z: knee -> ankle
    with pytest.raises(InputError):
        kin.segment_rotation(t, "forearm_left")


def test_joint_angles_follow_normal_walking(steady_walk):
    kin = steady_walk
    t = np.arange(4.0, kin.duration_s - 3.0, 0.005)
    j = kin.joint_positions_m(t)
    th = j["knee_left"] - j["hip_left"]
    sh = j["ankle_left"] - j["knee_left"]
    knee = np.degrees(np.arccos(np.sum(th * sh, 1) / np.linalg.norm(th, axis=1) / np.linalg.norm(sh, axis=1)))
    assert 50 < knee.max() < 75 and knee.min() < 12  # swing flexion ~60 deg, nearly straight in stance
    thigh_fwd = np.degrees(np.arctan2(th[:, 0], -th[:, 2]))  # walking east: forward = +x
    assert 15 < thigh_fwd.max() < 35 and -30 < thigh_fwd.min() < -5
    pel = j["pelvis"][:, 2]
    assert 0.02 < np.ptp(pel) < 0.08  # vertical excursion of the pelvis, a few cm


def test_heel_strikes_are_contacts_and_stance_feet_do_not_slip(steady_walk):
    kin = steady_walk
    hs = kin.heel_strikes
    assert len(hs) > 25 and (hs["foot"].to_numpy()[1:] != hs["foot"].to_numpy()[:-1]).all()
    for foot in ("left", "right"):
        t_hs = hs.loc[hs.foot == foot, "t_s"].to_numpy()[1:-1]
        heel = kin.joint_positions_m(t_hs)[f"heel_{foot}"]
        assert np.abs(heel[:, 2]).max() < 0.02  # the heel is on the ground at its strike
        # mid stance (20-35% of the stride after the strike): the foot stands still
        stride = np.median(np.diff(t_hs))
        tm = (t_hs[:, None] + stride * np.linspace(0.15, 0.3, 8)[None, :]).ravel()
        dt = 1e-3
        v = (kin.joint_positions_m(tm + dt)[f"ankle_{foot}"] - kin.joint_positions_m(tm - dt)[f"ankle_{foot}"]) / (2 * dt)
        assert np.median(np.linalg.norm(v, axis=1)) < 0.05 and np.linalg.norm(v, axis=1).max() < 0.25
        # in swing the foot moves fast
        ts = t_hs + 0.8 * stride
        vs = (kin.joint_positions_m(ts + dt)[f"ankle_{foot}"] - kin.joint_positions_m(ts - dt)[f"ankle_{foot}"]) / (2 * dt)
        assert np.median(np.linalg.norm(vs, axis=1)) > 2.0


@pytest.mark.parametrize("speed", [0.8, 1.0])
def test_a_foot_on_the_ground_never_slides(speed):
    """Where the straight stance leg is too short for the pelvis path, the heel rises: the foot IMU never translates
    without turning (it slid up to 3 cm per stride at 3 cm/s: a motion no zero-velocity detector can see), and the
    thigh and shank stay rigid."""
    kin = WalkKinematics.steady(speed_mps=speed, duration_s=12.0, seed=1)
    t = np.arange(2.0, kin.duration_s - 1.0, 0.005)
    _, w, pos, _ = true_motion(SensorPose(kin, ImuSpec(placement="foot_left", rate_hz=200.0), np.random.default_rng(0)), t)
    speed_mps = np.linalg.norm(np.gradient(pos, t, axis=0), axis=1)
    # the foot does not turn for 50 ms (not a turning point of the swing): it must stand
    still = maximum_filter1d(np.linalg.norm(w, axis=1), 11) < 0.02
    assert still.mean() > 0.1 and speed_mps[still].max() < 0.003
    j = kin.joint_positions_m(t)
    assert np.ptp(np.linalg.norm(j["ankle_left"] - j["knee_left"], axis=1)) < 1e-6


def test_running_has_a_flight_phase():
    kin = WalkKinematics.steady(speed_mps=3.2, duration_s=10.0, seed=2)
    t = np.arange(3.0, 9.0, 0.002)
    j = kin.joint_positions_m(t)
    low = {s: np.minimum(j[f"heel_{s}"][:, 2], j[f"toe_{s}"][:, 2]) for s in ("left", "right")}
    airborne = (low["left"] > 0.01) & (low["right"] > 0.01)
    assert 0.05 < airborne.mean() < 0.5
    freq = 1.0 / np.median(np.diff(kin.heel_strikes["t_s"]))
    assert 2.4 < freq < 3.6  # running cadence


def test_step_length_variability_is_larger_when_slow():
    cvs = {}
    for v in (0.6, 1.8):
        rec = simulate(_scenario([(2.0, 0.0), (150.0, v), (2.0, 0.0)], waypoints=((0, 0), (400, 0)),
                                 gnss={"enabled": False}, imu=[{"placement": "waist", "rate_hz": 20.0}]), seed=3)
        lengths = rec.reference["steps"]["step_length_m"].to_numpy()[3:-3]
        cvs[v] = lengths.std() / lengths.mean()
    assert 0.10 < cvs[0.6] < 0.20
    assert 0.02 < cvs[1.8] < 0.07


# ---------------------------------------------------------------------------------------------------------------
# IMU physics
# ---------------------------------------------------------------------------------------------------------------

def test_specific_force_at_rest_is_gravity_up():
    kin = WalkKinematics.steady(speed_mps=1.2, duration_s=6.0, seed=1, standing_s=3.0)
    t = np.arange(0.0, 1.5, 0.01)
    for place in ("waist", "foot_left", "shank_right", "hand", "pocket"):
        f, w, _, rot = true_motion(SensorPose(kin, ImuSpec(placement=place), np.random.default_rng(0)), t)
        if place != "hand":  # the phone sways slowly in the hand even when standing
            assert np.abs(w).max() < 1e-6
        up_in_sensor = rot[:, 2, :]  # world z expressed in the sensor frame
        assert np.allclose(f, GRAVITY_MPS2 * up_in_sensor, atol=0.5 if place == "hand" else 1e-6)
    f, _, _, _ = true_motion(SensorPose(kin, ImuSpec(placement="waist"), np.random.default_rng(0)), t)
    assert np.allclose(f.mean(0), [0.0, 0.0, GRAVITY_MPS2], atol=1e-6)


def test_recorded_imu_at_rest_and_walking(tmp_path):
    rec = simulate(_scenario([(5.0, 0.0), (20.0, 1.4)]), seed=5)
    imu = rec.imu
    acc = imu[["acc_x_mps2", "acc_y_mps2", "acc_z_mps2"]].to_numpy()
    rest = imu["t_s"].to_numpy() < 4.5
    assert np.linalg.norm(acc[rest].mean(0)) == pytest.approx(GRAVITY_MPS2, abs=0.25)  # bias included
    assert acc[rest].std(0).max() < 0.1
    walking = imu["t_s"].to_numpy() > 8
    assert 1.0 < acc[walking, 2].std() < 4.0  # vertical trunk acceleration of walking
    assert np.abs(np.linalg.norm(acc[walking], axis=1).mean() - GRAVITY_MPS2) < 0.3


def test_gyro_integrates_to_the_heading_change_of_a_turn():
    sc = parse_scenario(_scenario([(3.0, 0.0), (30.0, 1.3), (3.0, 0.0)], waypoints=((0, 0), (15, 0), (15, 30))))
    kin = build_walk(sc, seed=2)
    rate = 200.0
    t = np.arange(0.0, 36.0, 1.0 / rate)
    f, w, _, rot = true_motion(SensorPose(kin, ImuSpec(placement="waist"), np.random.default_rng(0)), t)
    r = rot[0].copy()
    for k in range(len(t) - 1):  # integrate the body rates (midpoint rate over each interval)
        wm = 0.5 * (w[k] + w[k + 1]) / rate
        ang = np.linalg.norm(wm)
        kx = np.array([[0, -wm[2], wm[1]], [wm[2], 0, -wm[0]], [-wm[1], wm[0], 0]])
        r = r @ (np.eye(3) + np.sin(ang) / max(ang, 1e-12) * kx + (1 - np.cos(ang)) / max(ang, 1e-12) ** 2 * kx @ kx)
    yaw = lambda m: np.degrees(np.arctan2(m[1, 0], m[0, 0]))
    assert yaw(rot[0]) == pytest.approx(0.0, abs=1e-6)
    assert yaw(r) == pytest.approx(yaw(rot[-1]), abs=1.0)
    assert yaw(r) == pytest.approx(90.0, abs=3.0)  # the route turns left by 90 deg


def test_barometer_and_magnetometer():
    sc = _scenario([(3.0, 0.0), (60.0, 1.4, True)], waypoints=((0, 0), (100, 0)), gnss={"enabled": False},
                   magnetic={"field_ut": 50.0, "steel_spacing_m": 5.0, "steel_ut": 40.0})
    sc["route"]["grades"] = [0.08]
    rec = simulate(sc, seed=3)
    imu = rec.imu
    p = imu["baro_hpa"].to_numpy()
    assert p[:200].mean() - p[-200:].mean() == pytest.approx(0.08 * 80 * 0.118, rel=0.35)  # ~0.118 hPa per metre
    b = np.linalg.norm(imu[["mag_x_ut", "mag_y_ut", "mag_z_ut"]].to_numpy(), axis=1)
    flat = simulate(_scenario([(3.0, 0.0), (60.0, 1.4)], gnss={"enabled": False}, magnetic={"field_ut": 50.0}), seed=3)
    b0 = np.linalg.norm(flat.imu[["mag_x_ut", "mag_y_ut", "mag_z_ut"]].to_numpy(), axis=1)
    assert b0.std() < 1.0 and abs(np.median(b0) - 50.0) < 4.0  # the Earth's field (+ hard iron)
    assert b.std() > 3 * b0.std()  # indoors near steel the field varies


def test_foot_imus_rest_in_stance():
    rec = simulate(_scenario([(2.0, 0.0), (20.0, 1.3)], gnss={"enabled": False},
                             imu=[{"placement": "waist"}, {"placement": "foot_left", "rate_hz": 200.0, "magnetometer": False}]),
                   seed=4)
    foot = rec.extra_imus["foot_left"]
    assert abs(np.median(np.diff(foot["t_s"])) - 0.005) < 1e-9
    g = np.linalg.norm(foot[["gyr_x_radps", "gyr_y_radps", "gyr_z_radps"]].to_numpy(), axis=1)
    walking = foot["t_s"].to_numpy() > 5
    assert (g[walking] < 0.3).mean() > 0.15  # a flat foot for part of every stride (zero-velocity intervals)
    assert g[walking].max() > 4.0  # and a fast swing


# ---------------------------------------------------------------------------------------------------------------
# GNSS
# ---------------------------------------------------------------------------------------------------------------

def test_gnss_noise_outliers_and_outages():
    sc = _scenario([(5.0, 0.0), (595.0, 1.3)], waypoints=((0, 0), (120, 0), (120, 60), (0, 60)),
                   gnss={"outlier_fraction": 0.1, "outlier_m": 50.0, "outages_s": [[200.0, 260.0]]},
                   imu=[{"placement": "waist", "rate_hz": 20.0}])
    sc["route"]["loop"] = True
    rec = simulate(sc, seed=11)
    g, truth = rec.gnss, rec.reference["gnss_truth"]
    t = g["t_s"].to_numpy()
    assert not ((t >= 200) & (t < 260)).any() and len(g) == 600 - 60
    e, n = latlon_to_en(g["lat_deg"], g["lon_deg"], rec.geo_origin)
    err = np.hypot(e - truth["e_m"], n - truth["n_m"])
    assert np.allclose(err, truth["error_m"], atol=0.01)
    out = truth["outlier"].to_numpy() == 1
    assert out.mean() == pytest.approx(0.10, abs=0.005)
    assert np.allclose(err[out], 50.0, atol=0.05)
    clean = err[~out]
    assert 2.0 < np.sqrt(np.mean(clean**2)) < 8.0 and clean.max() < 30.0
    h = g["h_acc_m"].to_numpy()
    assert (h > 0).all() and 1.0 < np.median(h) < 6.0
    assert np.corrcoef(h[~out], clean)[0, 1] < 0.9  # the receiver's estimate is not the true error
    # the correlated error wanders slowly: neighbouring fixes share most of it
    de = (e - truth["e_m"].to_numpy())[~out]
    assert np.corrcoef(de[:-1], de[1:])[0, 1] > 0.5


def test_indoor_segments_have_no_fixes(tmp_path):
    rec = simulate(_scenario([(3.0, 0.0), (40.0, 1.3), (30.0, 1.1, True)], imu=[{"placement": "hand"}]), seed=2)
    t = rec.gnss["t_s"].to_numpy()
    assert t.max() < 43.0 and len(t) == 43
    assert rec.placement == "hand"


# ---------------------------------------------------------------------------------------------------------------
# Scenario errors and the CLI
# ---------------------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("mutate, words", [
    (lambda s: s.pop("segment"), "segment"),
    (lambda s: s["segment"][0].update(speed_mps=-1.0), "speed_mps"),
    (lambda s: s["segment"][0].update(speed_mps="fast"), "speed_mps"),
    (lambda s: s.update(imu=[{"placement": "elbow"}]), "placement"),
    (lambda s: s.update(gnss={"outlier_fraction": 0.9}), "outlier_fraction"),
    (lambda s: s.update(gnss={"noise": 2.0}), "noise"),
    (lambda s: s.update(weather={"rain": True}), "weather"),
    (lambda s: s["route"].update(waypoints_m=[[0, 0]]), "waypoints_m"),
    (lambda s: s.update(segment=[{"duration_s": 2.0, "speed_mps": 0.0}]), "standing"),
])
def test_bad_scenarios_are_input_errors(mutate, words):
    sc = copy.deepcopy(_scenario([(2.0, 0.0), (10.0, 1.2)]))
    mutate(sc)
    with pytest.raises(InputError, match=words):
        simulate(sc, seed=0)


def test_cli_simulate_and_errors(tmp_path, capsys):
    out = tmp_path / "rec"
    assert main(["simulate", str(SHORT), "-o", str(out), "--seed", "2"]) == 0
    assert capsys.readouterr().out.strip() == str(out)
    assert main(["validate", str(out)]) == 0
    capsys.readouterr()
    assert main(["simulate", str(SHORT), "-o", str(out)]) == 1  # exists, no --force
    err = capsys.readouterr().err
    assert err.startswith("error:") and len(err.strip().splitlines()) == 1
    bad = tmp_path / "bad.toml"
    for text in ("[route\nwaypoints_m = 3", "[route]\nwaypoints_m = [[0, 0], [10, 0]]\n[[segment]]\nduration_s = 5\n",
                 ""):
        bad.write_text(text)
        assert main(["simulate", str(bad), "-o", str(tmp_path / "x")]) == 1
        err = capsys.readouterr().err
        assert err.startswith("error:") and len(err.strip().splitlines()) == 1
        assert not (tmp_path / "x").exists()
    assert main(["simulate", str(SHORT), "-o", str(tmp_path / "z"), "--seed", "-1"]) == 1
    assert capsys.readouterr().err.startswith("error: simulate: expected a seed")
    assert main(["simulate", str(tmp_path / "missing.toml"), "-o", str(tmp_path / "y")]) == 1
    assert capsys.readouterr().err.startswith("error:")


def test_a_too_short_walk_warns_and_stands():
    with warns(match="too short"):
        rec = simulate(_scenario([(2.0, 0.0), (0.6, 1.2), (3.0, 0.0), (15.0, 1.2)], gnss={"enabled": False}), seed=1)
    assert rec.reference["steps"]["t_s"].min() > 5.6  # no step in the 0.6 s burst


def test_camera_hook_renders_a_leg_camera_video(tmp_path):
    from pdr.sim import camera

    try:
        camera.load_texture("gravel")
    except InputError:
        pytest.skip("ground_textures_cc0 not available")
    sc = _scenario([(1.0, 0.0), (4.0, 1.3)], gnss={"enabled": False})
    sc["camera"] = {"fps": 20.0, "focal_px": 80.0, "cx_px": 39.5, "cy_px": 29.5, "width_px": 80, "height_px": 60,
                    "segment": "shank_left", "distance_from_knee_m": 0.25, "texture": "gravel",
                    "t_start_s": 1.5, "t_end_s": 2.5}
    rec = load_recording(_simulate_and_save(sc, tmp_path / "cam"))
    assert rec.video_path is not None and rec.video_path.name == "video.avi"
    assert rec.camera["mount"]["segment"] == "shank_left" and len(rec.frames) == 21
    assert rec.frames["t_s"].iloc[0] == pytest.approx(1.5)


def _simulate_and_save(scenario: dict, out: Path) -> Path:
    import tempfile

    from pdr.io.recording import save_recording

    with tempfile.TemporaryDirectory() as tmp:
        return save_recording(simulate(scenario, seed=3, workdir=Path(tmp)), out)


def test_phone_taken_out_of_and_put_back_into_the_pocket():
    """``in_pocket_s``: the hand phone rides in the pocket (the pocket placement's pose) inside the intervals, in
    the hand away from the moves, and turns against gravity between them; ``reference/handling.csv`` holds the moves."""
    raw = read_toml(Path(__file__).resolve().parents[1] / "configs" / "sim" / "phone_pocket_handling.toml")
    sc = parse_scenario(raw)
    kin = build_walk(sc, 3)
    spec = sc.imus[0]
    t = np.arange(0.0, 20.0, 0.01)
    pos, rot = SensorPose(kin, spec, np.random.default_rng(0))(t)
    p_pocket, r_pocket = SensorPose(kin, ImuSpec(placement="pocket"), np.random.default_rng(0))(t)
    p_hand, r_hand = SensorPose(kin, dataclasses.replace(spec, in_pocket_s=()), np.random.default_rng(0))(t)
    pocket, hand = t <= 0.5, (t >= 2.3) & (t <= 16.8)
    np.testing.assert_allclose(pos[pocket], p_pocket[pocket], atol=1e-9)
    np.testing.assert_allclose(rot[pocket], r_pocket[pocket], atol=1e-9)
    np.testing.assert_allclose(pos[hand], p_hand[hand], atol=1e-9)
    np.testing.assert_allclose(rot[hand], r_hand[hand], atol=1e-9)
    up = rot[:, 2, :]  # the world's up axis in the phone frame
    assert np.degrees(np.arccos(up[0] @ up[int(3.0 / 0.01)])) > 30.0
    f, _, _, _ = true_motion(SensorPose(kin, spec, np.random.default_rng(0)), t)
    assert np.isfinite(f).all() and np.abs(np.linalg.norm(f, axis=1) - GRAVITY_MPS2).max() < 3 * GRAVITY_MPS2
    rec = simulate(raw, seed=3)
    handling = rec.reference["handling"]
    assert handling["action"].tolist() == ["take_out", "put_away"]
    np.testing.assert_allclose(handling[["t_start_s", "t_end_s"]].to_numpy(), [[0.5, 2.3], [16.8, 18.6]])
    with pytest.raises(InputError, match="in_pocket_s"):
        ImuSpec(placement="waist", in_pocket_s=((0.0, 1.0),))
