"""The step model of a person never calibrated, from the body (``meta.toml`` ``[subject]``) and the sensor placement.

=========================================  ====================================================================
what is known                              model
=========================================  ====================================================================
trunk sensor (``waist``, ``trunk``)        :class:`ZijlstraStepLength`, the inverted pendulum, with the pendulum
                                           length from ``sensor_height_m``, else ``leg_length_m``, else
                                           0.53 ``height_m`` (greater-trochanter height, Winter 2009)
any other placement                        :class:`RegressionStepLength` from ``height_m`` and the cadence
                                           (:meth:`RegressionStepLength.for_height`); without a height, from
                                           ``leg_length_m`` / 0.53
nothing about the person                   the same models at the population height (1.70 m), with a warning
=========================================  ====================================================================

:func:`choose_model` also honours an explicit choice (``--model`` file, a ``[step_length]`` section) and returns the
reason with the model; ``pdr run`` records both in ``summary.json`` (``step_model.choice``).

Example
-------
>>> model, choice = choose_model({}, {"height_m": 1.62, "sensor_height_m": 0.98}, "waist")
>>> type(model).__name__, choice["source"]
('ZijlstraStepLength', 'subject.sensor_height_m')
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from pdr.errors import warn
from pdr.io.recording import TRUNK_PLACEMENTS, check_subject
from pdr.step_length.io import load_model, model_from_config
from pdr.step_length.models import (
    LEG_LENGTH_PER_HEIGHT,
    POPULATION_HEIGHT_M,
    RegressionStepLength,
    StepLengthModel,
    ZijlstraStepLength,
)



def body_model(subject: dict[str, Any] | None, placement: str) -> tuple[StepLengthModel, dict[str, Any]]:
    """The model for a person never calibrated (see the module table) and why: ``{"model", "source", "reason"}``."""
    subject = dict(subject or {})
    check_subject(subject)
    height, leg, sensor = subject.get("height_m"), subject.get("leg_length_m"), subject.get("sensor_height_m")
    if placement in TRUNK_PLACEMENTS:
        for value, source in ((sensor, "subject.sensor_height_m"), (leg, "subject.leg_length_m")):
            if value is not None:
                model = ZijlstraStepLength.population(sensor_height_m=float(value))
                return model, _choice(model, source, f"{placement} sensor: inverted pendulum (Zijlstra & Hof 2003) "
                                                     f"of length {value:g} m ({source})")
        known = height is not None
        h = float(height) if known else POPULATION_HEIGHT_M
        length = round(LEG_LENGTH_PER_HEIGHT * h, 4)
        model = ZijlstraStepLength.population(sensor_height_m=length)
        source = "subject.height_m" if known else "population"
        reason = (f"{placement} sensor: inverted pendulum (Zijlstra & Hof 2003) of length {LEG_LENGTH_PER_HEIGHT:g} x "
                  f"{'height' if known else 'the population height'} {h:g} m = {length:g} m (Winter 2009)")
    else:
        known = height is not None or leg is not None
        h = float(height) if height is not None else (float(leg) / LEG_LENGTH_PER_HEIGHT if leg is not None
                                                       else POPULATION_HEIGHT_M)
        model = RegressionStepLength.for_height(round(h, 4))
        source = "subject.height_m" if height is not None else ("subject.leg_length_m" if leg is not None else "population")
        what = {"subject.height_m": "height", "subject.leg_length_m": "height from the leg length / 0.53",
                "population": "the population height"}[source]
        reason = (f"{placement} sensor: height-and-cadence model, 0.414 x {what} {h:.3g} m at 110 steps/min, "
                  f"proportional to the cadence (pedometer rule; Sekiya & Nagasaki 1998)")
    if not known:
        warn(f"step length: nothing known about the person (meta.toml [subject] has no height_m, leg_length_m "
             f"or sensor_height_m); using the population model ({reason})")
    return model, _choice(model, source, reason)


def _choice(model: StepLengthModel, source: str, reason: str) -> dict[str, Any]:
    return {"model": model.name, "source": source, "reason": reason}


def choose_model(config: dict[str, Any], subject: dict[str, Any] | None, placement: str,
                 model_path: str | Path | None = None) -> tuple[StepLengthModel, dict[str, Any]]:
    """The step model of a run and why: the ``--model`` file, else the ``[step_length]`` section when it names a
    model, else :func:`body_model`."""
    if model_path is not None:
        model = load_model(model_path)
        return model, _choice(model, "model file", f"calibrated model from {Path(model_path).name}")
    section = (config or {}).get("step_length") or {}
    if section:
        model = model_from_config(config)
        return model, _choice(model, "configuration", f"configuration [step_length] ({model.name})")
    return body_model(subject, placement)
