"""Every ``Algorithm`` subclass keeps the house rules of the algorithm objects (DESIGN.md; the checks of tpcp's
``TestAlgorithmMixin``, written for this project): ``__init__`` takes keyword-only parameters and only stores them,
the docstring lists every parameter and every result, the action returns ``self`` and leaves ``get_params()``
unchanged, and the parameters survive a JSON round trip and ``clone``.

The subclasses are found by importing every module of the ``pdr`` package, so a new algorithm is checked without
editing this file; the action check needs an example run of it in ``ACTIONS`` and fails until it has one.
"""

from __future__ import annotations

import ast
import importlib
import inspect
import json
import pkgutil
import re
import textwrap

import numpy as np
import pandas as pd
import pytest

import pdr
from pdr.base import Algorithm
from pdr.errors import InputError, collect_warnings


def _all_algorithms() -> list[type[Algorithm]]:
    for info in pkgutil.walk_packages(pdr.__path__, "pdr."):
        if not info.name.endswith("__main__"):
            importlib.import_module(info.name)
    found, todo = set(), [Algorithm]
    while todo:
        for sub in todo.pop().__subclasses__():
            if sub.__module__.startswith("pdr.") and sub not in found:
                found.add(sub)
                todo.append(sub)
    # a base without an __init__ of its own (StepLengthModel, the frame-flow base) has no parameters and never runs
    return sorted((c for c in found if c.__init__ is not object.__init__), key=lambda c: (c.__module__, c.__name__))


ALGORITHMS = _all_algorithms()
IDS = [c.__name__ for c in ALGORITHMS]

# Subclasses that fail a check and live in files another change owns: (class name, check) -> why. None today.
KNOWN_FAILURES: dict[tuple[str, str], str] = {}


def _xfail_known(cls: type, check: str) -> None:
    reason = KNOWN_FAILURES.get((cls.__name__, check))
    if reason:
        pytest.xfail(reason)


@pytest.fixture(scope="module")
def templates():
    """Fitted thigh-camera templates (a parameter of the thigh-camera estimator): two forms of simulated person 1."""
    from pdr.gait.camera_templates import FourierFormTemplates
    from pdr.sim.thigh_camera import training_table

    plan = [("walk", 6.0, 1.3), ("fast_walk", 6.0, 1.8), ("walk", 6.0, 1.3)]
    return FourierFormTemplates().fit(training_table([plan], subject_seed=1, walk_seeds=[21]))


# Values of parameters without a default (an algorithm built with these and its defaults is valid).
def _required(name: str, templates_factory):
    from pdr.gait.camera_model import ThighCameraModel

    values = {"camera": ThighCameraModel, "templates": templates_factory, "k_m_per_root3_mps2": lambda: 0.55,
              "k_m_per_root4_mps2": lambda: 0.48, "k_scale": lambda: 1.0, "residual_std_m": lambda: 0.05,
              "a_m": lambda: 0.3, "b_m_per_hz": lambda: 0.2, "c_m_per_m2ps4": lambda: 0.01,
              "focal_px": lambda: 120.0, "cx_px": lambda: 79.5, "cy_px": lambda: 59.5}
    if name not in values:
        raise AssertionError(f"parameter {name!r} has no default: add an example value to _required in {__file__}")
    return values[name]()


def _build(cls: type[Algorithm], request) -> tuple[Algorithm, dict]:
    kwargs = {}
    for p in inspect.signature(cls.__init__).parameters.values():
        if p.name != "self" and p.default is inspect.Parameter.empty:
            kwargs[p.name] = _required(p.name, lambda: request.getfixturevalue("templates"))
    return cls(**kwargs), kwargs


@pytest.mark.parametrize("cls", ALGORITHMS, ids=IDS)
def test_init_takes_keyword_only_parameters_and_only_stores_them(cls, request):
    _xfail_known(cls, "init")
    params = [p for name, p in inspect.signature(cls.__init__).parameters.items() if name != "self"]
    not_keyword = [p.name for p in params if p.kind is not inspect.Parameter.KEYWORD_ONLY]
    assert not not_keyword, f"{cls.__name__}: parameters must be keyword-only and named, found {not_keyword}"
    algo, given = _build(cls, request)
    assert sorted(vars(algo)) == sorted(p.name for p in params), f"{cls.__name__}.__init__ sets more than its parameters"
    for p in params:
        expected = given[p.name] if p.name in given else p.default
        assert getattr(algo, p.name) is expected, f"{cls.__name__}.__init__ changes {p.name} instead of storing it"
    assert algo.param_names() == [p.name for p in params]


def _section(doc: str, title: str) -> str:
    """The text of a numpydoc section (``title`` over a line of dashes) up to the next section."""
    doc = inspect.cleandoc(doc or "")
    m = re.search(rf"^{title}\n-+\n(.*?)(?=^\w[\w ]*\n-+\n|\Z)", doc, flags=re.S | re.M)
    return m.group(1) if m else ""


def _results_set(cls: type) -> set[str]:
    """Public attributes ending in ``_`` that the methods ``cls`` has (its own and the inherited ones) assign."""
    names = set()
    for attr in dir(cls):
        fn = inspect.getattr_static(cls, attr)
        fn = getattr(fn, "__func__", fn)
        if not inspect.isfunction(fn) or not fn.__module__.startswith("pdr."):
            continue
        for node in ast.walk(ast.parse(textwrap.dedent(inspect.getsource(fn)))):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target] if isinstance(node, ast.AnnAssign) else []
            for t in targets:
                for e in ast.walk(t):
                    if (isinstance(e, ast.Attribute) and isinstance(e.value, ast.Name) and e.value.id == "self"
                            and e.attr.endswith("_") and not e.attr.startswith("_")):
                        names.add(e.attr)
    return names


@pytest.mark.parametrize("cls", ALGORITHMS, ids=IDS)
def test_docstring_lists_every_parameter_and_result(cls):
    _xfail_known(cls, "docstring")
    doc = cls.__doc__ or ""
    params, attributes = _section(doc, "Parameters"), _section(doc, "Attributes")
    missing = [n for n in cls.param_names() if not re.search(rf"\b{n}\b", params)]
    assert not missing, f"{cls.__name__}: the docstring's Parameters section lacks {', '.join(missing)}"
    results = sorted(_results_set(cls))
    assert results, f"{cls.__name__}: no result attributes (ending in _) found"
    missing = [n for n in results if not re.search(rf"\b{n}(?!\w)", attributes)]
    assert not missing, f"{cls.__name__}: the docstring's Attributes section lacks {', '.join(missing)}"


@pytest.mark.parametrize("cls", ALGORITHMS, ids=IDS)
def test_parameters_survive_json_clone_and_set_params(cls, request):
    _xfail_known(cls, "json")
    algo, _ = _build(cls, request)
    data = algo.params_to_json()
    back = cls.from_json(json.loads(json.dumps(data, allow_nan=False)))
    assert type(back) is cls and back.params_to_json() == data
    twin = algo.clone()
    assert type(twin) is cls and twin is not algo and twin.params_to_json() == data
    assert not [k for k in vars(twin) if k.endswith("_")], "clone copies parameters, not results"
    name = algo.param_names()[0]
    assert twin.set_params(**{name: getattr(algo, name)}) is twin
    with pytest.raises(InputError, match="unknown parameter"):
        twin.set_params(not_a_parameter=1)


def test_json_round_trip_keeps_a_fitted_model_parameter(templates):
    from pdr.gait.camera_estimator import WearableCameraGaitEstimation
    from pdr.gait.camera_model import ThighCameraModel

    est = WearableCameraGaitEstimation(templates=templates, camera=ThighCameraModel(side="left"), n_candidates=5)
    back = WearableCameraGaitEstimation.from_json(json.loads(json.dumps(est.params_to_json())))
    np.testing.assert_array_equal(back.templates.coefficients_, templates.coefficients_)
    assert back.templates.forms_ == templates.forms_ and back.camera == est.camera and back.n_candidates == 5
    with pytest.raises(InputError, match="expected numbers, text"):
        WearableCameraGaitEstimation(templates=templates, camera=object()).params_to_json()
    with pytest.raises(InputError, match="expected a pdr object"):
        Algorithm.from_json.__func__(WearableCameraGaitEstimation, {"camera": {"__object__": "os:system"}})


# ----------------------------------------------------------------------------------------------------------------
# The action: returns self, leaves the parameters as they were
# ----------------------------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def walk():
    """A simulated 30 s walk with a turn (waist IMU, both foot IMUs, GNSS) and what the earlier stages make of it."""
    from pdr.pipelines.steps import detect_steps
    from pdr.signals.attitude import estimate_attitude
    from pdr.signals.resample import uniform_imu
    from pdr.sim.simulator import simulate
    from pdr.step_length.features import with_signal_features
    from pdr.step_length.models import RegressionStepLength

    with collect_warnings():
        rec = simulate({"route": {"waypoints_m": [[0, 0], [40, 0], [40, 40]], "loop": False},
                        "segment": [{"duration_s": 2, "speed_mps": 0}, {"duration_s": 30, "speed_mps": 1.3}],
                        "imu": [{"placement": "waist"}, {"placement": "foot_left", "rate_hz": 200}]}, seed=3)
        steps = detect_steps(rec, {})
    model = RegressionStepLength(a_m=0.3, b_m_per_hz=0.2, c_m_per_m2ps4=0.01, residual_std_m=0.05).estimate(steps)
    steps = steps.assign(step_length_m=model.step_length_m_, step_length_std_m=model.step_length_std_m_)
    g = rec.gnss.dropna(subset=["lat_deg", "lon_deg"])
    r_m = 6_371_000.0  # a local tangent plane is enough for a test walk of 80 m
    lat0, lon0 = np.radians(g["lat_deg"].iloc[0]), np.radians(g["lon_deg"].iloc[0])
    gnss = pd.DataFrame({"t_s": g["t_s"], "e_m": r_m * np.cos(lat0) * (np.radians(g["lon_deg"]) - lon0),
                         "n_m": r_m * (np.radians(g["lat_deg"]) - lat0), "h_acc_m": g.get("h_acc_m", 5.0)})
    u = uniform_imu(rec.imu)
    return {"rec": rec, "steps": steps, "signal_steps": with_signal_features(steps, rec), "gnss": gnss, "u": u, "attitude": estimate_attitude(u), "model": model,
            "foot": rec.extra_imus["foot_left"]}


def _frames(n: int = 12, shift_px: int = 2) -> tuple[np.ndarray, np.ndarray]:
    texture = (np.random.default_rng(0).random((120, 160 + n * shift_px)) * 255).astype(np.uint8)
    return np.stack([texture[:, i * shift_px:i * shift_px + 160] for i in range(n)]), np.arange(n) / 30.0


def _cycles(w):
    from pdr.gait.cycles import imu_cycles

    return imu_cycles(w["u"], w["attitude"], w["steps"])


def _flow(n: int = 600, rate_hz: float = 100.0):
    t = np.arange(n) / rate_hz  # swing bursts at a 1 Hz stride
    return t, 400.0 * np.clip(np.sin(2 * np.pi * t), 0.0, None) ** 2 - 20.0


def _motion_and_segments():
    from pdr.flow import HomographyCameraMotion
    from pdr.pipelines.leg_camera import cut_strides

    motion = HomographyCameraMotion(focal_px=120.0, cx_px=79.5, cy_px=59.5).estimate(*_frames()).motion_
    return motion, cut_strides(motion)


# class name -> (inputs from the fixtures) -> (the action's name, its arguments, its keyword arguments). The step
# length models' ``fit`` is their calibration, which by design changes the parameters (DESIGN.md: a calibrated model
# is the parameters); their action here is ``estimate``.
ACTIONS = {
    "AdaptiveKalmanCalibration": lambda w, r: ("fit", (w["steps"], w["gnss"], w["model"]), {}),
    "RecursiveStepCalibration": lambda w, r: ("estimate", (w["steps"], w["model"]), {}),
    "PhaseCorrelationOpticalFlow": lambda w, r: ("estimate", _frames(), {}),
    "CorrelationOpticalFlow": lambda w, r: ("estimate", _frames(), {}),
    "InterpolationOpticalFlow": lambda w, r: ("estimate", _frames(), {}),
    "ZeroVelocityDetection": lambda w, r: ("detect", (w["foot"],), {}),
    "ZuptInsStride": lambda w, r: ("estimate", (w["foot"],), {}),
    "FootStepTrackerStride": lambda w, r: ("estimate", (w["foot"],), {}),
    "DoubleFeetCalibration": lambda w, r: ("estimate", (_foot_strides(w),), {}),
    "EkfFusion": lambda w, r: ("fuse", (w["steps"],), {"gnss": w["gnss"]}),
    "FactorGraphFusion": lambda w, r: ("fuse", (w["steps"],), {"gnss": w["gnss"]}),
    "IncrementalFusion": lambda w, r: ("fuse", (w["steps"],), {"gnss": w["gnss"]}),
    "FourierFormTemplates": lambda w, r: ("fit", (_training_table(),), {}),
    "WearableCameraGaitEstimation": lambda w, r: ("estimate", *_thigh_camera_walk()),
    "FourierGaitForms": lambda w, r: ("fit", (_cycles(w),), {}),
    "AttitudeStepHeading": lambda w, r: ("estimate", (w["u"], w["attitude"], w["steps"]), {}),
    "SensorFaultDetection": lambda w, r: ("detect", (w["rec"].imu,), {}),
    "SlipOpticalFlowStride": lambda w, r: ("estimate", _flow(), {}),
    "HomographyCameraMotion": lambda w, r: ("estimate", _frames(), {}),
    "FloorOdometryStride": lambda w, r: ("estimate", _motion_and_segments(), {}),
    "RegressionStepLength": lambda w, r: ("estimate", (w["signal_steps"],), {}),
    "WeinbergStepLength": lambda w, r: ("estimate", (w["signal_steps"],), {}),
    "KimStepLength": lambda w, r: ("estimate", (w["signal_steps"],), {}),
    "ZijlstraStepLength": lambda w, r: ("estimate", (w["signal_steps"],), {"subject": {"height_m": 1.75}}),
    "PeakStepDetection": lambda w, r: ("detect", (w["u"],), {}),
    "WaveletStepDetection": lambda w, r: ("detect", (w["u"],), {}),
    "AttitudeHandlingDetection": lambda w, r: ("detect", (w["u"],), {}),
    "Pipeline": lambda w, r: ("run", (w["rec"],), {}),
}


def _foot_strides(w):
    from pdr.foot.zupt_ins import ZuptInsStride

    strides = ZuptInsStride().estimate(w["foot"]).strides_
    right = strides.assign(foot="right", t_start_s=strides["t_start_s"] + 0.55, t_end_s=strides["t_end_s"] + 0.55)
    return pd.concat([strides.assign(foot="left"), right], ignore_index=True)


def _training_table():
    from pdr.sim.thigh_camera import training_table

    return training_table([[("walk", 6.0, 1.3), ("fast_walk", 6.0, 1.8), ("walk", 6.0, 1.3)]], subject_seed=1,
                          walk_seeds=[21])


def _thigh_camera_walk():
    from pdr.sim.thigh_camera import form_walk, simulate_thigh_camera

    sim = simulate_thigh_camera(form_walk([("walk", 5.0, 1.3)], subject_seed=1, walk_seed=5), seed=5)
    start = sim.truth.iloc[0]
    return (sim.frames, sim.observations, sim.points), {"initial_e_m": start["e_m"], "initial_n_m": start["n_m"],
                                                        "initial_heading_rad": start["heading_rad"]}


def test_every_algorithm_has_an_example_action():
    missing = [c.__name__ for c in ALGORITHMS if c.__name__ not in ACTIONS]
    assert not missing, f"add an example run of {', '.join(missing)} to ACTIONS in {__file__}"


@pytest.mark.parametrize("cls", ALGORITHMS, ids=IDS)
def test_action_returns_self_and_keeps_the_parameters(cls, walk, request):
    _xfail_known(cls, "action")
    if cls.__name__ not in ACTIONS:
        pytest.fail(f"no example run of {cls.__name__} in ACTIONS")
    algo, _ = _build(cls, request)
    before = json.dumps(algo.params_to_json(), sort_keys=True)
    verb, args, kwargs = ACTIONS[cls.__name__](walk, request)
    with collect_warnings():
        out = getattr(algo, verb)(*args, **kwargs)
    assert out is algo, f"{cls.__name__}.{verb} returns {type(out).__name__}, not self"
    assert json.dumps(algo.params_to_json(), sort_keys=True) == before, f"{cls.__name__}.{verb} changed its parameters"
    assert [k for k in vars(algo) if k.endswith("_") and not k.startswith("_")], f"{cls.__name__}.{verb} set no results"
