"""Walking forms: Fourier fit, gait cycles, forms on simulated walks and shoe IMUs, CLI, bad input."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pdr.cli.main import main
from pdr.errors import InputError, collect_warnings
from pdr.gait import amplitude_phase, fourier_coefficients, fourier_derivative, fourier_series, from_amplitude_phase
from pdr.gait.cycles import MAX_CYCLE_S, foot_cycles, foot_layout, imu_cycles, imu_layout, side_convention
from pdr.gait.forms import PENDULUM_K, TURN_MIN_RAD_PER_CYCLE, FourierGaitForms, load_forms, pendulum_speed_mps, speed_kind
from pdr.io.recording import load_recording, save_recording
from pdr.pipelines.gait_forms import classify_forms, recording_cycles
from pdr.sim.simulator import simulate
from pdr.signals import estimate_attitude, uniform_imu

from conftest import DATASETS, warns

ROOT = Path(__file__).resolve().parents[1]
GAITMAP = DATASETS / "gaitmap_foot_imu_mocap"

# a short mix of the four speed kinds (inside their Froude bands for any simulated height) on a route with corners
SCENARIO = {
    "route": {"waypoints_m": [[0, 0], [40, 0], [40, 30], [0, 30]], "loop": True},
    "segment": [{"duration_s": 3, "speed_mps": 0}, {"duration_s": 30, "speed_mps": 0.85},
                {"duration_s": 30, "speed_mps": 1.25}, {"duration_s": 25, "speed_mps": 1.9},
                {"duration_s": 20, "speed_mps": 3.0}, {"duration_s": 25, "speed_mps": 1.25},
                {"duration_s": 3, "speed_mps": 0}],
    "gnss": {"enabled": False},
}


# ---------------------------------------------------------------------------------------------------- Fourier (eq. 2)
def test_fourier_fit_is_exact_for_a_5th_order_series():
    rng = np.random.default_rng(1)
    coef = rng.standard_normal((11, 3))
    phi = np.sort(rng.uniform(0, 2 * np.pi, 40))  # irregular phases, as on a real cycle
    values = fourier_series(coef, phi)
    np.testing.assert_allclose(fourier_coefficients(phi, values, order=5), coef, atol=1e-10)
    # the paper's amplitude-phase form z = sum A_n sin(n eta + B_n) is the same function
    amp, ph = amplitude_phase(coef[:, 0])
    z = sum(amp[n] * np.sin(n * phi + ph[n]) for n in range(6))
    np.testing.assert_allclose(z, values[:, 0], atol=1e-10)
    np.testing.assert_allclose(from_amplitude_phase(amp, ph), coef[:, 0], atol=1e-12)
    # derivative coefficients against a central difference
    h = 1e-6
    num = (fourier_series(coef[:, 1], phi + h) - fourier_series(coef[:, 1], phi - h)) / (2 * h)
    np.testing.assert_allclose(fourier_series(fourier_derivative(coef[:, 1]), phi), num, atol=1e-6)


def test_fourier_fit_least_squares_and_bad_input():
    phi = np.linspace(0, 2 * np.pi, 200, endpoint=False)
    # a 7th harmonic is orthogonal to the 5th-order basis on a uniform grid: the fit ignores it
    c = fourier_coefficients(phi, 2.0 + np.sin(2 * phi) + 0.5 * np.cos(7 * phi))
    np.testing.assert_allclose(c, [2.0, 0, 0, 0, 1.0, 0, 0, 0, 0, 0, 0], atol=1e-12)
    with pytest.raises(InputError, match="at least 11 samples"):
        fourier_coefficients(phi[:10], phi[:10])
    with pytest.raises(InputError, match="shape"):
        fourier_coefficients(phi, phi[:-1])
    with pytest.raises(InputError, match="finite"):
        fourier_coefficients(phi, np.where(phi > 1, np.nan, 0.0))


def test_side_convention_puts_phase_shifted_cycles_together():
    rng = np.random.default_rng(0)
    c1 = (1.0 - 2.0j) * np.exp(1j * rng.normal(0, 0.2, 50))
    shifted = rng.random(50) < 0.5
    flip = side_convention(np.where(shifted, -c1, c1))
    assert np.array_equal(flip, shifted) or np.array_equal(flip, ~shifted)
    assert (np.where(flip, c1 * np.where(shifted, -1, 1) * -1, c1 * np.where(shifted, -1, 1)).imag < 0).all()


# ---------------------------------------------------------------------------------------------------- cycles
@pytest.fixture(scope="module")
def sim_recs(tmp_path_factory) -> list[Path]:
    base = tmp_path_factory.mktemp("gait_forms")
    out = []
    with collect_warnings():
        for seed in (0, 1):
            out.append(save_recording(simulate(SCENARIO, seed), base / f"mix{seed}"))
    return out


def _truth_kind(rec, cycles: pd.DataFrame) -> np.ndarray:
    ref = rec.reference["steps"]
    mid = 0.5 * (cycles["t_start_s"] + cycles["t_end_s"]).to_numpy()
    j = np.clip(np.searchsorted(ref["t_s"].to_numpy(), mid), 0, len(ref) - 1)
    return speed_kind(ref["speed_mps"].to_numpy()[j], 0.53 * rec.subject["height_m"])


def test_imu_cycles_are_strides_with_the_layout(sim_recs):
    rec = load_recording(sim_recs[0])
    with collect_warnings():
        cyc = recording_cycles(rec, {})
    assert set(imu_layout()) <= set(cyc.columns)
    assert len(cyc) > 50
    ref = rec.reference["steps"]
    walking = ref.groupby("bout_id")["t_s"].agg(["min", "max"])
    # a stride is two steps: its duration is two reference step durations, within the sampling
    assert np.median(cyc["duration_s"]) == pytest.approx(2 * np.median(ref["step_duration_s"]), rel=0.1)
    assert ((cyc["t_start_s"] >= walking["min"].min() - 0.2) & (cyc["t_end_s"] <= walking["max"].max() + 0.2)).all()
    # the vertical acceleration of a trunk IMU repeats every step: its 2nd stride harmonic dominates the 1st
    amp2 = np.hypot(cyc["acc_v_mps2_a2"], cyc["acc_v_mps2_b2"])
    amp1 = np.hypot(cyc["acc_v_mps2_a1"], cyc["acc_v_mps2_b1"])
    assert np.median(amp2) > 3 * np.median(amp1)
    # running is faster than slow walking in the speed column
    kind = _truth_kind(rec, cyc)
    assert cyc.loc[kind == "run", "speed_mps"].median() > 2 * cyc.loc[kind == "slow_walk", "speed_mps"].median()


def test_cycles_too_short_or_too_long_are_dropped_with_a_warning(sim_recs):
    rec = load_recording(sim_recs[0])
    u = uniform_imu(rec.imu)
    att = estimate_attitude(u)
    t = np.array([10.0, 10.5, 11.0, 11.1, 11.2, 11.3, 20.0, 20.5, 21.0])  # good, too short, too long (one bout)
    steps = pd.DataFrame({"t_s": t, "bout_id": 0, "heading_rad": 0.0})
    with warns(match="dropped as not gait"):
        cyc = imu_cycles(u, att, steps)
    assert len(cyc) == 2 and (cyc["duration_s"] <= MAX_CYCLE_S).all() and (cyc["duration_s"] >= 0.5).all()
    with warns(match="no gait cycle"):
        empty = imu_cycles(u, att, steps.iloc[:2])
    assert len(empty) == 0 and set(imu_layout()) <= set(empty.columns)


# ---------------------------------------------------------------------------------------------------- forms
def test_forms_learnt_on_one_walk_name_the_cycles_of_another(sim_recs):
    with collect_warnings():
        train, test = (recording_cycles(load_recording(p), {}) for p in sim_recs)
    forms = FourierGaitForms().fit(train)
    assert forms.components_.shape == (3, len(imu_layout()))
    np.testing.assert_allclose(forms.components_ @ forms.components_.T, np.eye(3), atol=1e-9)  # U orthonormal
    assert {"slow_walk", "walk", "run"} <= set(forms.forms_["kind"])
    # the transition diagram: rows are probabilities, and staying in a form is the most common transition
    np.testing.assert_allclose(forms.transition_.sum(axis=1), 1.0)
    assert np.trace(forms.transition_counts_) > 0.7 * forms.transition_counts_.sum()
    rec = load_recording(sim_recs[1])
    truth = _truth_kind(rec, test)
    got = forms.classify(test).cycles_forms_
    straight = got["kind"] != "turning"
    accuracy = float((got["kind"][straight] == truth[straight]).mean())
    # one short walk of another person to learn from (the benchmark learns from four): well above chance (1/4)
    assert accuracy > 0.7, pd.crosstab(truth, got["kind"].to_numpy())
    # the data-only JSON round trip classifies identically
    again = FourierGaitForms.from_dict(json.loads(json.dumps(forms.to_dict())))
    assert np.array_equal(again.classify(test).labels_, got["form_id"].to_numpy())
    # smoothing by the transition diagram gives a valid labelling too
    forms.smoothing = True
    assert set(forms.classify(test).labels_) <= set(range(forms.n_forms))


def test_pendulum_speed_of_a_compass_gait_cycle():
    # a trunk that rises and falls by h once per step (the 2nd stride harmonic): z = -h/2 cos(2 phi), so the
    # vertical acceleration is h/2 (4 pi / T)^2 cos(2 phi); the pendulum gives K 2 sqrt(2 l h - h^2) per step
    leg, h, dur = np.array([0.9, 0.9, 1.0]), np.array([0.03, 0.05, 0.05]), np.array([1.1, 1.0, 1.2])
    cyc = pd.DataFrame({c: 0.0 for c in imu_layout() if c.startswith("acc_v_mps2_")}, index=range(3))
    cyc["acc_v_mps2_a2"] = 0.5 * h * (4 * np.pi / dur) ** 2
    cyc["duration_s"] = dur
    want = 2 * PENDULUM_K * 2 * np.sqrt(2 * leg * h - h * h) / dur
    np.testing.assert_allclose(pendulum_speed_mps(cyc, leg), want, rtol=1e-3)
    # no vertical acceleration channel (shoe IMU cycles): no speed
    assert np.isnan(pendulum_speed_mps(cyc.drop(columns="acc_v_mps2_a2"), leg)).all()


def test_each_walking_cycle_is_named_by_its_own_froude_number(sim_recs):
    # k-means boundaries alone do not follow the Froude bands for people unseen in training (a fast walk with longer
    # steps at a lower cadence falls into the walk form); a level walking cycle is named by the Froude number of its
    # inverted-pendulum speed, which needs only the leg length
    with collect_warnings():
        train, test = (recording_cycles(load_recording(p), {}) for p in sim_recs)
    forms = FourierGaitForms().fit(train)
    got = forms.classify(test).cycles_forms_
    own_turn = np.abs(test["turn_rate_radps"] * test["duration_s"]).to_numpy() > TURN_MIN_RAD_PER_CYCLE
    walking = np.isin(forms.forms_["kind"].to_numpy(object)[got["form_id"]], ["slow_walk", "walk", "fast_walk"]) & ~own_turn
    own = speed_kind(pendulum_speed_mps(test, test["leg_length_m"]), test["leg_length_m"].to_numpy())
    assert walking.sum() > 50
    assert np.array_equal(got["kind"][walking], np.where(own == "run", "fast_walk", own)[walking])
    # the pendulum speed of the simulated person is within 10% of the planned speed while walking (no per-person fit)
    rec = load_recording(sim_recs[1])
    ref = rec.reference["steps"]
    mid = 0.5 * (test["t_start_s"] + test["t_end_s"]).to_numpy()
    planned = ref["speed_mps"].to_numpy()[np.clip(np.searchsorted(ref["t_s"].to_numpy(), mid), 0, len(ref) - 1)]
    slow = (planned < 2.0) & walking
    ratio = np.median(pendulum_speed_mps(test, test["leg_length_m"])[slow] / planned[slow])
    assert ratio == pytest.approx(1.0, abs=0.1)
    # per-cycle speed names are at least as accurate as the forms' own names on the straight cycles
    truth = _truth_kind(rec, test)
    plain = FourierGaitForms.from_dict({**forms.to_dict(), "params": {**forms.get_params(), "cycle_speed_check": False}})
    base = plain.classify(test).cycles_forms_["kind"].to_numpy()
    straight = got["kind"].to_numpy() != "turning"
    assert (got["kind"].to_numpy() == truth)[straight].mean() >= (base == truth)[straight].mean()
    # a sensor off the trunk (a phone in a hand or pocket) does not rise and fall with it: the forms' names stay
    assert test["trunk_sensor"].all()
    hand = forms.classify(test.assign(trunk_sensor=False)).cycles_forms_["kind"].to_numpy()
    np.testing.assert_array_equal(hand, base)
    # a cycle that itself turns more than 30 degrees is turning, whatever its form; more true turns are found so
    assert own_turn.sum() >= 5 and (got["kind"].to_numpy()[own_turn] == "turning").all()
    no_turn = FourierGaitForms.from_dict({**forms.to_dict(), "params": {**forms.get_params(), "cycle_turn_check": False}})
    formwise = no_turn.classify(test).cycles_forms_["kind"].to_numpy()
    np.testing.assert_array_equal(formwise[~own_turn], got["kind"].to_numpy()[~own_turn])
    tr = rec.reference["trajectory"]
    h = np.unwrap(tr["heading_rad"].to_numpy())
    turns = np.abs(np.interp(test["t_end_s"], tr["t_s"], h) - np.interp(test["t_start_s"], tr["t_s"], h)) > TURN_MIN_RAD_PER_CYCLE
    assert turns.sum() >= 5
    assert (got["kind"].to_numpy()[turns] == "turning").mean() >= (formwise[turns] == "turning").mean()


def test_cli_round_trip_and_forms_file_errors(sim_recs, tmp_path, capsys):
    forms_path = tmp_path / "forms.json"
    with collect_warnings():
        assert main(["gait-forms", "fit", str(sim_recs[0]), "-o", str(forms_path)]) == 0
        assert main(["gait-forms", "classify", str(sim_recs[1]), "--forms", str(forms_path),
                     "-o", str(tmp_path / "forms.csv")]) == 0
    assert capsys.readouterr().out.split() == [str(forms_path), str(tmp_path / "forms.csv")]
    table = pd.read_csv(tmp_path / "forms.csv")
    assert list(table.columns[:3]) == ["t_start_s", "t_end_s", "form"] and len(table) > 50
    assert (table["t_end_s"] > table["t_start_s"]).all()
    doc = json.loads(forms_path.read_text())
    assert doc["layout"] == imu_layout() and "all" in doc["step_models"]
    # another feature layout: a clear InputError
    doc["layout"] = foot_layout()
    doc["mean"] = doc["scale"] = [1.0] * len(foot_layout())
    doc["components"] = [[0.0] * len(foot_layout())] * 3
    bad = tmp_path / "foot_forms.json"
    bad.write_text(json.dumps(doc))
    with pytest.raises(InputError, match="another feature layout"):
        classify_forms(sim_recs[1], bad, tmp_path / "x.csv")
    assert main(["gait-forms", "classify", str(sim_recs[1]), "--forms", str(bad), "-o", str(tmp_path / "x.csv")]) == 1
    assert "another feature layout" in capsys.readouterr().err
    (tmp_path / "junk.json").write_text('{"format": "something"}')
    with pytest.raises(InputError, match="pdr-gait-forms"):
        load_forms(tmp_path / "junk.json")
    assert not (tmp_path / "x.csv").exists()


def test_recording_without_cycles_gives_an_empty_table(sim_recs, tmp_path, small_recording):
    forms_path = tmp_path / "forms.json"
    with collect_warnings():
        main(["gait-forms", "fit", str(sim_recs[0]), "-o", str(forms_path)])
    still = load_recording(small_recording)
    still.imu[[c for c in still.imu.columns if c.startswith("acc_")]] = [0.0, 0.0, 9.80665]
    still_path = save_recording(still, tmp_path / "still")
    with warns(match="no gait cycle|no walking"):
        out = classify_forms(still_path, forms_path, tmp_path / "still.csv")
    table = pd.read_csv(out)
    assert len(table) == 0 and list(table.columns[:3]) == ["t_start_s", "t_end_s", "form"]


@pytest.mark.real_data("gaitmap_foot_imu_mocap")
def test_shoe_imu_cycles_climb_on_stairs(tmp_path):
    with collect_warnings():
        main(["import", "gaitmap", str(GAITMAP), str(tmp_path), "--rate-hz", "204.8"])
    slope = {}
    for name in ("walk_2x20m", "stairs_up", "stairs_down"):
        rec = load_recording(tmp_path / name)
        with collect_warnings():
            cyc = recording_cycles(rec, {})
        assert set(cyc["source"]) == {"foot_left", "foot_right"}
        assert set(foot_layout()) <= set(cyc.columns)
        slope[name] = np.degrees(np.arctan2(cyc["climb_rate_mps"], cyc["speed_mps"])).median()
    # stairs climb at about 30 degrees, the lab floor is level
    assert abs(slope["walk_2x20m"]) < 5 and slope["stairs_up"] > 15 and slope["stairs_down"] < -15
    with pytest.raises(InputError, match="left' or 'right"):
        foot_cycles(load_recording(tmp_path / "stairs_up").imu, "middle")


def test_run_uses_per_form_step_models(sim_recs, tmp_path):
    from pdr.pipelines.run import run_recording

    forms_path = tmp_path / "forms.json"
    with collect_warnings():
        main(["gait-forms", "fit", str(sim_recs[0]), "-o", str(forms_path)])
        cfg = tmp_path / "run.toml"
        cfg.write_text('[gait_forms]\nforms = "forms.json"\n')  # relative to the configuration file
        with_forms = run_recording(sim_recs[1], tmp_path / "out_forms", config_path=cfg)
        population = tmp_path / "population.toml"
        population.write_text('[step_length]\nmodel = "regression"\n')  # the height-free population regression
        plain = run_recording(sim_recs[1], tmp_path / "out_plain", config_path=population)
    info = with_forms["gait_forms"]
    # the per-form models keep their relative lengths: the fusion that ran calibrates one scale; the pipeline's own
    # fusion parameters (run.json "pipeline") stay as configured
    run_json = json.loads((tmp_path / "out_forms" / "run.json").read_text())
    ran = run_json["config"]["fusion"]["params"]
    assert (ran["calibrate_step_model"], ran["calibrate_step_scale"]) == (False, True)
    assert (run_json["pipeline"]["fusion"]["calibrate_step_model"], run_json["pipeline"]["fusion"]["calibrate_step_scale"]) == (True, False)
    assert info["n_cycles"] > 50 and sum(info["steps_per_form_model"].values()) > 100
    steps = pd.read_csv(tmp_path / "out_forms" / "steps.csv")
    assert len(steps) == plain["n_steps"]
    # per-form models learnt on another simulated person's true step lengths: used, and within 20% of the truth (the
    # simulated people differ in leg proportion and step-length law, so another person's models carry over only so
    # far: 14% here against 11% for the population regression)
    truth = load_recording(sim_recs[1]).reference["summary"]["distance_m"]
    assert with_forms["distance_m"] != pytest.approx(plain["distance_m"], rel=0.01)
    assert abs(with_forms["distance_m"] / truth - 1) < 0.2
    cfg.write_text('[gait_forms]\nforms = "missing.json"\n')
    with pytest.raises(InputError, match="forms JSON file"):
        run_recording(sim_recs[1], tmp_path / "out_bad", config_path=cfg)
    cfg.write_text('[gait_forms]\nforms = "forms.json"\ncycle_speed_chek = false\n')
    with pytest.raises(InputError, match="cycle_speed_chek"):
        run_recording(sim_recs[1], tmp_path / "out_bad", config_path=cfg)


def test_classification_settings_from_the_configuration(sim_recs, tmp_path):
    cfg = tmp_path / "fit.toml"
    cfg.write_text("[gait_forms]\ncycle_speed_check = false\nsmoothing = true\n")
    with collect_warnings():
        assert main(["gait-forms", "fit", str(sim_recs[0]), "-o", str(tmp_path / "forms.json"), "--config", str(cfg)]) == 0
    forms, _ = load_forms(tmp_path / "forms.json")
    assert forms.cycle_speed_check is False and forms.smoothing is True  # kept in the forms file


def test_dynamic_similarity_makes_features_dimensionless():
    from pdr.gait.forms import similarity_factors

    layout = ["acc_v_mps2_a0", "gyr_yaw_radps_b1", "speed_mps", "step_freq_hz", "climb_rate_mps"]
    f = similarity_factors(layout, np.array([1.0, 0.81]))
    g = 9.80665
    np.testing.assert_allclose(f[0], [1 / g, np.sqrt(1 / g), 1 / np.sqrt(g), np.sqrt(1 / g), 1 / np.sqrt(g)])
    # Froude number v^2 / (g L) = (dimensionless speed)^2
    assert (1.2 * f[1, 2]) ** 2 == pytest.approx(1.2 ** 2 / (g * 0.81))
