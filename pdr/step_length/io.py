"""A per-user step model as JSON (what ``pdr calibrate`` writes and ``pdr run --model`` reads), and the ``[step_length]``
configuration section.

The file::

    {"pdr_model_version": 1, "model": "regression",
     "params": {"a_m": ..., "b_m_per_hz": ..., "c_m_per_m2ps4": ..., "residual_std_m": ..., "covariance": [[...]]},
     "info": {"n_steps": ..., "distance_m": ..., ...},
     "leg_camera": {"method": "odometry", "length_scale": ..., "length_scale_std": ..., ...}}

``leg_camera`` (optional, from a calibration walk filmed by a leg camera) holds the camera strides' length scale and
the stride method it was calibrated for, which ``pdr run --model`` gives that method's estimator
(:func:`leg_camera_calibration`; a file without ``method`` was written for "slip_of").

Example
-------
>>> from pdr.step_length import RegressionStepLength, save_model, load_model
>>> save_model(RegressionStepLength.population(), "model.json", n_steps=0)  # doctest: +SKIP
>>> load_model("model.json").b_m_per_hz  # doctest: +SKIP
0.384
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from pdr import __version__
from pdr.errors import InputError
from pdr.io.atomic import write_text
from pdr.io.tomlio import jsonable, read_json
from pdr.step_length.models import MODELS, RegressionStepLength, StepLengthModel

MODEL_VERSION = 1


def model_to_dict(model: StepLengthModel, leg_camera: dict[str, Any] | None = None, **info: Any) -> dict[str, Any]:
    """The JSON document of a model (see the module docstring)."""
    if not isinstance(model, StepLengthModel):
        raise InputError(f"save_model: expected a step-length model, found {type(model).__name__}")
    model._check_params()
    doc = {"pdr_model_version": MODEL_VERSION, "model": model.name, "params": jsonable(model.get_params(), float_digits=None),
           "info": jsonable({"pdr_version": __version__, **info}, float_digits=None)}
    if leg_camera is not None:
        doc["leg_camera"] = jsonable(leg_camera, float_digits=None)
    return doc


def save_model(model: StepLengthModel, path: str | Path, leg_camera: dict[str, Any] | None = None, **info: Any) -> Path:
    """Write ``model`` (with the leg camera's calibration, if any, and free-form ``info``: steps and metres seen,
    recordings, ...) as JSON, atomically."""
    path = Path(path)
    write_text(path, json.dumps(model_to_dict(model, leg_camera, **info), indent=2, sort_keys=True) + "\n")
    return path


def model_from_dict(doc: Any, what: str = "model") -> StepLengthModel:
    """Rebuild a model from its JSON document; every deviation from the expected shape is an InputError."""
    if not isinstance(doc, dict):
        raise InputError(f"{what}: expected a JSON object with pdr_model_version, model, params; found {type(doc).__name__}")
    version = doc.get("pdr_model_version")
    if version != MODEL_VERSION:
        raise InputError(f"{what}: expected pdr_model_version {MODEL_VERSION} (a model written by `pdr calibrate`), "
                         f"found {version!r}")
    name = doc.get("model")
    if name not in MODELS:
        raise InputError(f"{what}: expected model one of {', '.join(MODELS)}, found {name!r}")
    params = doc.get("params")
    if not isinstance(params, dict):
        raise InputError(f"{what}: expected params to be an object of {MODELS[name].__name__} parameters, found {params!r}")
    cls = MODELS[name]
    missing = [p for p in cls.param_names() if p not in params and p not in ("covariance", "sensor_height_m")]
    if missing:
        raise InputError(f"{what}: expected params {', '.join(cls.param_names())}, missing {', '.join(missing)}")
    model = cls.from_config(params)
    model._check_params()
    return model


def _model_document(path: str | Path, what: str) -> Any:
    """The JSON document of a model file (what ``pdr calibrate`` writes)."""
    return read_json(path, what=what, missing="expected a JSON file from `pdr calibrate`, found nothing there")


LEG_CAMERA_SCALE_RANGE = (2.0 / 3.0, 1.5)  # a factor 1.5 either way: beyond any body model's error, a wrong mount


def leg_camera_calibration(path: str | Path) -> dict[str, Any] | None:
    """The leg camera's per-user calibration of a model file (its ``leg_camera`` object): ``method``,
    ``length_scale`` and, if stored, ``length_scale_std``; None when it has none."""
    what = f"model file {path}"
    doc = _model_document(path, what)
    section = doc.get("leg_camera") if isinstance(doc, dict) else None
    if section is None:
        return None
    section = section if isinstance(section, dict) else {}
    scale, std = section.get("length_scale"), section.get("length_scale_std")
    method = section.get("method", "slip_of")
    lo, hi = LEG_CAMERA_SCALE_RANGE
    if isinstance(scale, bool) or not isinstance(scale, (int, float)) or not lo <= scale <= hi:
        raise InputError(f"{what}: expected leg_camera.length_scale a number in [{lo:.3g}, {hi:.3g}], found {scale!r}")
    if std is not None and (isinstance(std, bool) or not isinstance(std, (int, float)) or not 0 <= std < 1):
        raise InputError(f"{what}: expected leg_camera.length_scale_std a number in [0, 1), found {std!r}")
    if method not in ("odometry", "slip_of"):
        raise InputError(f"{what}: expected leg_camera.method 'odometry' or 'slip_of', found {method!r}")
    out = {"method": method, "length_scale": float(scale)}
    if std is not None:
        out["length_scale_std"] = float(std)
    return out


def load_model(path: str | Path) -> StepLengthModel:
    """Read a model file written by :func:`save_model`."""
    what = f"model file {path}"
    doc = _model_document(path, what)
    return model_from_dict(doc, what)


def model_from_config(config: dict[str, Any] | None) -> StepLengthModel:
    """The model of the ``[step_length]`` section: ``model = "regression" | "weinberg" | "kim" | "zijlstra"`` (default
    regression) and any of its parameters, which override the population preset."""
    section = dict((config or {}).get("step_length") or {})
    name = section.pop("model", RegressionStepLength.name)
    if name not in MODELS:
        raise InputError(f"configuration [step_length]: expected model one of {', '.join(MODELS)}, found {name!r}")
    model = MODELS[name].population(**section)
    model._check_params()
    return model
