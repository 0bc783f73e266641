"""Step length: per-step length and standard deviation from the steps table.

Models (all linear in their parameters, each with a population preset so an uncalibrated user works):
:class:`RegressionStepLength` (Ladetto et al. 2000, the default), :class:`WeinbergStepLength`, :class:`KimStepLength`,
:class:`ZijlstraStepLength`. Weinberg, Kim and Zijlstra need signal features beyond the steps table: add them with
``model.prepare(steps, rec)`` (or :func:`with_signal_features`). A calibrated model is its parameters as JSON
(:func:`save_model` / :func:`load_model`); :func:`model_from_config` reads the ``[step_length]`` section.
A person never calibrated gets a model from the body and the placement (:func:`body_model`; :func:`choose_model`
is the choice of ``pdr run``).

Example
-------
>>> from pdr.step_length import model_from_config
>>> model = model_from_config({"step_length": {"model": "regression"}})
>>> model.estimate(steps).step_length_m_  # doctest: +SKIP
"""

from pdr.step_length.body import body_model, choose_model
from pdr.step_length.features import step_signal_features, vertical_excursion_m, with_signal_features
from pdr.step_length.io import leg_camera_calibration, load_model, model_from_config, save_model
from pdr.step_length.models import (
    MODELS,
    KimStepLength,
    RegressionStepLength,
    StepLengthModel,
    WeinbergStepLength,
    ZijlstraStepLength,
)

__all__ = [
    "MODELS", "KimStepLength", "RegressionStepLength", "StepLengthModel", "WeinbergStepLength", "ZijlstraStepLength",
    "body_model", "choose_model", "leg_camera_calibration", "load_model", "model_from_config", "save_model", "step_signal_features", "vertical_excursion_m", "with_signal_features",
]
