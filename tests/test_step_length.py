"""Step-length models: least-squares fit and covariance, presets, features, model files, bad input."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pdr.constants import GRAVITY_MPS2
from pdr.errors import InputError, collect_warnings
from pdr.step_length import (
    KimStepLength,
    RegressionStepLength,
    WeinbergStepLength,
    ZijlstraStepLength,
    load_model,
    model_from_config,
    save_model,
    vertical_excursion_m,
    with_signal_features,
)
from conftest import warns


def walk_features(n: int, rng: np.random.Generator) -> pd.DataFrame:
    """Features of a walk at changing speeds: cadence from speed (Grieve & Gear style power law), variance growing
    with speed; richer than the linear model (the truth below is not A + B f + C v)."""
    speed = rng.uniform(0.8, 1.8, n)
    freq = 1.05 * speed ** 0.55 + 0.05 * rng.standard_normal(n)
    var = 1.5 * speed ** 2 + 0.3 * rng.standard_normal(n) ** 2
    return pd.DataFrame({"step_freq_hz": freq, "acc_var_m2ps4": var, "speed_mps": speed})


def test_fit_recovers_coefficients_and_covariance():
    rng = np.random.default_rng(1)
    true = np.array([0.15, 0.28, 0.012])
    sigma = 0.04
    thetas, covs = [], []
    for _ in range(300):
        steps = walk_features(150, rng)
        y = true[0] + true[1] * steps.step_freq_hz + true[2] * steps.acc_var_m2ps4 + sigma * rng.standard_normal(150)
        m = RegressionStepLength.population().fit(steps, y)
        thetas.append(m.theta)
        covs.append(np.asarray(m.covariance))
    thetas = np.array(thetas)
    mean_cov = np.mean(covs, axis=0)
    se = np.sqrt(np.diag(mean_cov) / len(thetas))
    assert np.all(np.abs(thetas.mean(axis=0) - true) < 4 * se)
    # the reported covariance matches the spread of the estimates over noise draws
    emp = np.cov(thetas.T)
    ratio = np.diag(emp) / np.diag(mean_cov)
    assert np.all((ratio > 0.75) & (ratio < 1.33)), ratio
    corr_emp = emp[0, 1] / np.sqrt(emp[0, 0] * emp[1, 1])
    corr_rep = mean_cov[0, 1] / np.sqrt(mean_cov[0, 0] * mean_cov[1, 1])
    assert abs(corr_emp - corr_rep) < 0.1
    assert m.residual_std_m == pytest.approx(sigma, rel=0.2)


def test_fit_on_a_richer_truth_predicts_distance():
    rng = np.random.default_rng(2)
    steps = walk_features(400, rng)
    truth = steps.speed_mps / steps.step_freq_hz.clip(lower=0.8)  # length = speed / cadence, not linear in the features
    truth = truth + 0.03 * rng.standard_normal(len(truth))
    m = RegressionStepLength.population().fit(steps[:200], truth[:200])
    est = m.estimate(steps[200:]).step_length_m_
    assert abs(est.sum() / truth[200:].sum() - 1) < 0.02
    # the stated per-step std is honest: about 68% of the errors within one sigma
    inside = np.abs(est - truth[200:]) < m.step_length_std_m_
    assert 0.55 < inside.mean() < 0.85


def test_single_frequency_fits_a_only():
    rng = np.random.default_rng(3)
    steps = pd.DataFrame({"step_freq_hz": np.full(50, 1.8), "acc_var_m2ps4": np.full(50, 3.0)})
    m = RegressionStepLength.population()
    with warns(match="a_m only"):
        m.fit(steps, 0.75 + 0.02 * rng.standard_normal(50))
    assert m.b_m_per_hz == RegressionStepLength.preset["b_m_per_hz"] and m.c_m_per_m2ps4 == 0.0
    assert m.estimate(steps).step_length_m_.mean() == pytest.approx(0.75, abs=0.01)


@settings(max_examples=40, deadline=None)
@given(scale=st.floats(0.2, 5.0), c=st.floats(-0.05, 0.05))
def test_scaling_a_feature_and_its_coefficient_is_invariant(scale, c):
    rng = np.random.default_rng(4)
    steps = walk_features(30, rng)
    m = RegressionStepLength(a_m=0.2, b_m_per_hz=0.25, c_m_per_m2ps4=c, residual_std_m=0.05,
                             covariance=np.diag([0.01, 0.004, 1e-4]).tolist())
    scaled = steps.assign(acc_var_m2ps4=steps.acc_var_m2ps4 * scale)
    cov = np.diag([0.01, 0.004, 1e-4 / scale ** 2]).tolist()
    m2 = RegressionStepLength(a_m=0.2, b_m_per_hz=0.25, c_m_per_m2ps4=c / scale, residual_std_m=0.05, covariance=cov)
    with collect_warnings():
        a, b = m.estimate(steps), m2.estimate(scaled)
    np.testing.assert_allclose(a.step_length_m_, b.step_length_m_, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(a.step_length_std_m_, b.step_length_std_m_, rtol=1e-9)


@settings(max_examples=30, deadline=None)
@given(scale=st.floats(0.3, 3.0))
def test_scaling_the_lengths_scales_the_coefficients(scale):
    rng = np.random.default_rng(5)
    steps = walk_features(60, rng)
    y = 0.1 + 0.3 * steps.step_freq_hz + 0.01 * steps.acc_var_m2ps4 + 0.03 * rng.standard_normal(60)
    m1 = RegressionStepLength.population().fit(steps, y)
    m2 = RegressionStepLength.population().fit(steps, scale * y)
    np.testing.assert_allclose(m2.theta, scale * m1.theta, rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(m2.covariance, scale ** 2 * np.asarray(m1.covariance), rtol=1e-8, atol=1e-14)


def test_presets_give_plausible_steps_for_an_uncalibrated_user():
    steps = pd.DataFrame({"step_freq_hz": [1.8], "acc_var_m2ps4": [4.0], "acc_range_mps2": [6.0],
                          "acc_abs_mean_mps2": [2.0], "vertical_excursion_m": [0.035]})
    for model in (RegressionStepLength.population(), WeinbergStepLength.population(), KimStepLength.population(),
                  ZijlstraStepLength.population()):
        length = model.estimate(steps, subject={"sensor_height_m": 1.0}).step_length_m_[0]
        assert 0.55 < length < 0.85, (model, length)
        assert 0.05 < model.step_length_std_m_[0] < 0.2


def test_vertical_excursion_of_a_known_bounce():
    rate, f, h = 100.0, 1.9, 0.045
    t = np.arange(0, 30, 1 / rate)
    # pelvis height: a bounce with a harmonic (not a pure sinusoid), excursion h per step
    z = h / 2 * np.cos(2 * np.pi * f * t) + 0.004 * np.cos(4 * np.pi * f * t)
    acc = -(h / 2) * (2 * np.pi * f) ** 2 * np.cos(2 * np.pi * f * t) - 0.004 * (4 * np.pi * f) ** 2 * np.cos(4 * np.pi * f * t)
    contacts = t[0] + np.arange(3, 27, 1 / f)
    exc = vertical_excursion_m(acc, rate, t[0], contacts[:-1], contacts[1:])
    per_step = np.array([np.ptp(z[(t >= a) & (t <= b)]) for a, b in zip(contacts[:-1], contacts[1:])])
    np.testing.assert_allclose(exc, per_step, rtol=0.08)


def test_signal_features_are_orientation_free():
    rate, f = 100.0, 1.8
    t = np.arange(0, 20, 1 / rate)
    up_acc = 2.5 * np.cos(2 * np.pi * f * t) + 0.8 * np.cos(4 * np.pi * f * t + 0.3)
    tilt = np.radians(35.0)
    vec = np.stack([np.zeros_like(t), np.zeros_like(t), GRAVITY_MPS2 + up_acc], axis=1)
    rot = np.array([[1, 0, 0], [0, np.cos(tilt), -np.sin(tilt)], [0, np.sin(tilt), np.cos(tilt)]])
    steps = pd.DataFrame({"t_s": np.arange(2, 18, 1 / f), "bout_id": 0})
    frames = []
    for r in (np.eye(3), rot):
        a = vec @ r.T
        imu = pd.DataFrame({"t_s": t, "acc_x_mps2": a[:, 0], "acc_y_mps2": a[:, 1], "acc_z_mps2": a[:, 2]})
        frames.append(with_signal_features(steps, imu))
    for col in ("acc_range_mps2", "acc_abs_mean_mps2", "vertical_excursion_m"):
        np.testing.assert_allclose(frames[0][col], frames[1][col], rtol=0.02)


@pytest.mark.parametrize("cls", [RegressionStepLength, WeinbergStepLength, KimStepLength, ZijlstraStepLength])
def test_model_file_round_trip(tmp_path, cls):
    model = cls.population()
    path = save_model(model, tmp_path / "m.json", n_steps=12, distance_m=8.5)
    loaded = load_model(path)
    assert type(loaded) is cls
    assert loaded.get_params() == json.loads(json.dumps(model.get_params()))
    doc = json.loads(path.read_text())
    assert doc["pdr_model_version"] == 1 and doc["info"]["n_steps"] == 12


@pytest.mark.parametrize("mutate, match", [
    (lambda d: d.update(pdr_model_version=2), "pdr_model_version 1"),
    (lambda d: d.pop("pdr_model_version"), "pdr_model_version 1"),
    (lambda d: d.update(model="magic"), "model one of"),
    (lambda d: d["params"].pop("a_m"), "missing a_m"),
    (lambda d: d["params"].update(a_m="x"), "finite number for a_m"),
    (lambda d: d["params"].update(covariance=[[1.0, 0.0], [0.0, 1.0]]), "3x3"),
    (lambda d: d["params"].update(covariance=[[1.0, 2.0, 0], [2.0, 1.0, 0], [0, 0, 1]]), "positive semi-definite"),
    (lambda d: d["params"].update(gain=3.0), "unknown parameter"),
    (lambda d: d.update(params=[1, 2, 3]), "params to be an object"),
])
def test_bad_model_files_are_clear_errors(tmp_path, mutate, match):
    path = save_model(RegressionStepLength.population(), tmp_path / "m.json")
    doc = json.loads(path.read_text())
    mutate(doc)
    path.write_text(json.dumps(doc))
    with pytest.raises(InputError, match=match):
        load_model(path)


def test_unreadable_and_missing_model_files(tmp_path):
    (tmp_path / "bad.json").write_text("{not json")
    with pytest.raises(InputError, match="expected JSON"):
        load_model(tmp_path / "bad.json")
    (tmp_path / "list.json").write_text("[1, 2]")
    with pytest.raises(InputError, match="JSON object"):
        load_model(tmp_path / "list.json")
    with pytest.raises(InputError, match="found nothing"):
        load_model(tmp_path / "absent.json")


def test_model_from_config():
    assert model_from_config({}).get_params() == RegressionStepLength.population().get_params()
    m = model_from_config({"step_length": {"model": "zijlstra", "k_scale": 1.25}})
    assert isinstance(m, ZijlstraStepLength) and m.k_scale == 1.25
    with pytest.raises(InputError, match="model one of"):
        model_from_config({"step_length": {"model": "nope"}})
    with pytest.raises(InputError, match="unknown parameter"):
        model_from_config({"step_length": {"a": 1.0}})


def test_bad_steps_input():
    m = RegressionStepLength.population()
    with pytest.raises(InputError, match="missing acc_var_m2ps4"):
        m.estimate(pd.DataFrame({"step_freq_hz": [1.8]}))
    with pytest.raises(InputError, match="in Hz"):
        m.estimate(pd.DataFrame({"step_freq_hz": [108.0], "acc_var_m2ps4": [3.0]}))  # steps/min, not Hz
    with pytest.raises(InputError, match=">= 0"):
        m.estimate(pd.DataFrame({"step_freq_hz": [-1.8], "acc_var_m2ps4": [3.0]}))
    with warns(match="without a finite step_freq_hz"):
        est = m.estimate(pd.DataFrame({"step_freq_hz": [1.8, np.nan, 2.0], "acc_var_m2ps4": [3.0, 3.0, 3.0]}))
    assert np.isfinite(est.step_length_m_).all()
    empty = m.estimate(pd.DataFrame({"step_freq_hz": [], "acc_var_m2ps4": []}))
    assert empty.step_length_m_.shape == (0,) and empty.step_length_std_m_.shape == (0,)
    with pytest.raises(InputError, match="sensor height"):
        ZijlstraStepLength.population().estimate(pd.DataFrame({"vertical_excursion_m": [0.03]}), subject={})
    with pytest.raises(InputError, match="with_signal_features"):
        WeinbergStepLength.population().estimate(pd.DataFrame({"t_s": [1.0]}))
    with pytest.raises(InputError, match="one length per step"):
        m.fit(pd.DataFrame({"step_freq_hz": [1.8, 1.9], "acc_var_m2ps4": [3.0, 3.1]}), [0.7])
    with pytest.raises(InputError, match="positive lengths"):
        m.fit(pd.DataFrame({"step_freq_hz": [1.8, 1.9], "acc_var_m2ps4": [3.0, 3.1]}), [0.7, np.nan])


def test_signal_features_bad_input():
    imu = pd.DataFrame({"t_s": np.arange(0, 5, 0.01), "acc_x_mps2": 0.0, "acc_y_mps2": 0.0, "acc_z_mps2": GRAVITY_MPS2})
    with pytest.raises(InputError, match="unsorted"):
        with_signal_features(pd.DataFrame({"t_s": [2.0, 1.0]}), imu)
    with pytest.raises(InputError, match="at least 10 Hz"):
        with_signal_features(pd.DataFrame({"t_s": [2.0]}), imu.iloc[::20])
    out = with_signal_features(pd.DataFrame({"t_s": []}), imu)
    assert list(out.columns) == ["t_s", "acc_range_mps2", "acc_abs_mean_mps2", "vertical_excursion_m"] and len(out) == 0
    with warns(match="outside the IMU record"):
        out = with_signal_features(pd.DataFrame({"t_s": [2.0, 30.0]}), imu)
    assert np.isnan(out.acc_range_mps2.iloc[1])
