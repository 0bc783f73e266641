"""Stride sources calibrated by GNSS inside the fusion: a length scale per source (prior 1)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from benchmarks.bench_fusion import synthetic_strides, synthetic_walk
from pdr.errors import InputError
from pdr.fusion import FactorGraphFusion, IncrementalFusion
from pdr.fusion._linear import solve_stride_scales


def biased_strides(w: dict, bias: float, source: str = "leg_camera", seed: int = 0, std_m: float = 0.08) -> pd.DataFrame:
    return synthetic_strides(w, bias, source, seed, std_m)


def path_m(fusion) -> float:
    return float(fusion.step_length_m_.sum())


@pytest.fixture(scope="module")
def walk():
    return synthetic_walk(duration_s=400.0, seed=0)


def test_a_short_stride_source_is_scaled_back_with_gnss(walk):
    strides = biased_strides(walk, 0.9)
    truth = float(np.sum(walk["true_length_m"]))
    plain = FactorGraphFusion(calibrate_stride_scales=False).fuse(walk["steps"], gnss=walk["gnss"], strides=strides)
    fused = FactorGraphFusion().fuse(walk["steps"], gnss=walk["gnss"], strides=strides)
    scale = fused.stride_scales_["leg_camera"]
    assert scale["calibrated"] and scale["n_strides"] == len(strides)
    # 1 / 0.9 = 1.111; GNSS with correlated errors knows the scale of a 400 s walk to ~1.5% (the reported std)
    assert scale["scale"] == pytest.approx(1 / 0.9, abs=0.03)
    assert 0.005 < scale["std"] < 0.03
    assert abs(path_m(fused) / truth - 1) < 0.02
    assert abs(path_m(fused) / truth - 1) < 0.3 * abs(path_m(plain) / truth - 1)
    # whatever GNSS says (on some walks GNSS and steps are off by a few %), the scaled strides agree with it
    gnss_only = FactorGraphFusion().fuse(walk["steps"], gnss=walk["gnss"])
    assert path_m(fused) == pytest.approx(path_m(gnss_only), rel=0.015)
    assert fused.solver_["stride_scales_calibrated"]


def test_without_gnss_the_scale_stays_at_its_prior(walk):
    strides = biased_strides(walk, 0.9)
    fused = FactorGraphFusion().fuse(walk["steps"], strides=strides)
    off = FactorGraphFusion(calibrate_stride_scales=False).fuse(walk["steps"], strides=strides)
    scale = fused.stride_scales_["leg_camera"]
    assert scale == {"scale": 1.0, "std": 0.07, "prior_std": 0.07, "n_strides": len(strides), "calibrated": False}
    np.testing.assert_array_equal(fused.trajectory_.e_m, off.trajectory_.e_m)
    # a single fix does not tell a scale either
    one_fix = FactorGraphFusion().fuse(walk["steps"], gnss=walk["gnss"].iloc[:1], strides=strides)
    assert one_fix.stride_scales_["leg_camera"]["scale"] == 1.0


def test_sources_get_their_own_scales_and_priors(walk):
    strides = pd.concat([biased_strides(walk, 0.9, "leg_camera", seed=1),
                         biased_strides(walk, 1.0, "foot_imu", seed=2, std_m=0.03)]).sort_values("t_end_s")
    fused = FactorGraphFusion(stride_scale_prior_std_by_source={"foot_imu": 0.02}).fuse(
        walk["steps"], gnss=walk["gnss"], strides=strides)
    cam, foot = fused.stride_scales_["leg_camera"], fused.stride_scales_["foot_imu"]
    assert foot["prior_std"] == 0.02 and cam["prior_std"] == 0.07
    # the unbiased, trusted foot IMU holds the path; the camera is scaled onto it
    assert foot["scale"] == pytest.approx(1.0, abs=0.015)
    assert cam["scale"] == pytest.approx(1 / 0.9, abs=0.03)
    # a table without a source column is one source, "stride"
    anonymous = FactorGraphFusion().fuse(walk["steps"], gnss=walk["gnss"], strides=strides.drop(columns="source"))
    assert list(anonymous.stride_scales_) == ["stride"]


def test_incremental_uses_given_scales(walk):
    strides = biased_strides(walk, 0.9)
    n = 200
    steps = walk["steps"].iloc[:n]
    strides = strides[strides.t_end_s <= steps.t_s.iloc[-1]]
    plain = IncrementalFusion().fuse(steps, strides=strides)
    scaled = IncrementalFusion(stride_scales={"leg_camera": 1 / 0.9}).fuse(steps, strides=strides)
    assert plain.stride_scales_["leg_camera"]["scale"] == 1.0
    assert scaled.stride_scales_["leg_camera"] == pytest.approx(
        {"scale": 1 / 0.9, "std": 0.07, "prior_std": 0.07, "n_strides": len(strides), "calibrated": False})
    assert path_m(scaled) > 1.03 * path_m(plain)


def test_closed_form_scale_is_the_weighted_ratio():
    length = np.array([1.0, 1.2, 1.4, 1.3])
    scale, std = solve_stride_scales(1.1 * length, length, np.full(4, 0.01), np.zeros(4, int), np.array([1e6]),
                                     np.ones(1), 1.345 * 1e6)
    assert scale[0] == pytest.approx(1.1) and std[0] < 0.01


@pytest.mark.parametrize("params", [{"stride_scale_prior_std": 0.0}, {"stride_scale_prior_std_by_source": {"x": -1}},
                                    {"stride_scale_prior_std_by_source": [0.1]}, {"gnss_correlated_std_m": np.nan}])
def test_bad_scale_params_are_input_errors(walk, params):
    with pytest.raises(InputError):
        FactorGraphFusion(**params).fuse(walk["steps"].iloc[:20])


def test_bad_given_scales_are_input_errors(walk):
    with pytest.raises(InputError, match="stride_scales"):
        IncrementalFusion(stride_scales={"leg_camera": 0}).fuse(walk["steps"].iloc[:20])
