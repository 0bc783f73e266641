"""Base class of the algorithm objects (the gaitmap / scikit-learn way).

``__init__`` takes keyword-only parameters with units in their names and stores them; one action verb
returns ``self``; results are attributes ending in ``_``. A configuration section or a calibrated model
is the algorithm's parameters as a dict; :meth:`Algorithm.params_to_json` / :meth:`Algorithm.from_json` write and
read it as JSON (a parameter that is itself an object, such as a camera model or a fitted template set, is stored
through its ``to_dict`` / ``from_dict``, or an algorithm through its parameters, with its class name).
"""

from __future__ import annotations

import copy
import importlib
import inspect
from typing import Any

import numpy as np

from pdr.errors import InputError


class Algorithm:
    """Parameters in, results out; see the module docstring."""

    @classmethod
    def param_names(cls) -> list[str]:
        sig = inspect.signature(cls.__init__)
        return [p.name for p in sig.parameters.values() if p.kind is inspect.Parameter.KEYWORD_ONLY]

    def get_params(self) -> dict[str, Any]:
        return {name: getattr(self, name) for name in self.param_names()}

    def set_params(self, **params: Any):
        """Change parameters in place (unknown names are an InputError naming the valid ones); returns ``self``."""
        _check_names(type(self), params)
        for name, value in params.items():
            setattr(self, name, value)
        return self

    def clone(self):
        """A new, unrun algorithm with deep copies of the parameters (no results)."""
        return type(self)(**copy.deepcopy(self.get_params()))

    def params_to_json(self) -> dict[str, Any]:
        """The parameters as JSON data (see the module docstring); :meth:`from_json` rebuilds the algorithm."""
        return {name: _to_json(value, f"{type(self).__name__} {name}") for name, value in self.get_params().items()}

    @classmethod
    def from_json(cls, params: dict[str, Any]):
        """The algorithm of :meth:`params_to_json` data."""
        return cls.from_config({name: _from_json(value) for name, value in params.items()})

    @classmethod
    def from_config(cls, section: dict[str, Any] | None, **overrides: Any):
        """Build from a configuration section; unknown keys are an InputError naming the valid ones."""
        section = dict(section or {})
        section.update(overrides)
        _check_names(cls, section)
        return cls(**section)

    def __repr__(self) -> str:
        params = ", ".join(f"{k}={v!r}" for k, v in self.get_params().items())
        return f"{type(self).__name__}({params})"


def _check_names(cls: type[Algorithm], params: dict[str, Any]) -> None:
    names = cls.param_names()
    unknown = sorted(set(params) - set(names))
    if unknown:
        raise InputError(
            f"unknown parameter(s) {', '.join(unknown)} for {cls.__name__}; expected some of: {', '.join(names)}"
        )


_OBJECT = "__object__"  # key of a JSON object that stands for a Python object: its "module:Class"


def _to_json(value: Any, what: str) -> Any:
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_to_json(v, what) for v in value]
    if isinstance(value, dict):
        if not all(isinstance(k, str) for k in value) or _OBJECT in value:
            raise InputError(f"{what}: expected a table with text keys, found keys {list(value)!r}")
        return {k: _to_json(v, what) for k, v in value.items()}
    cls = type(value)
    name = f"{cls.__module__}:{cls.__qualname__}"
    # a model's own dict first: it holds what was fitted, not only the parameters
    if callable(getattr(value, "to_dict", None)) and callable(getattr(cls, "from_dict", None)):
        return {_OBJECT: name, "dict": _to_json(value.to_dict(), what)}
    if isinstance(value, Algorithm):
        return {_OBJECT: name, "params": value.params_to_json()}
    raise InputError(f"{what}: expected numbers, text, lists, tables or pdr objects, found {cls.__name__}")


def _from_json(value: Any) -> Any:
    if isinstance(value, list):
        return [_from_json(v) for v in value]
    if not isinstance(value, dict):
        return value
    if _OBJECT not in value:
        return {k: _from_json(v) for k, v in value.items()}
    module, _, qualname = str(value[_OBJECT]).partition(":")
    if module.split(".")[0] != "pdr":
        raise InputError(f"parameters: expected a pdr object, found {value[_OBJECT]!r}")
    cls = importlib.import_module(module)
    for part in qualname.split("."):
        cls = getattr(cls, part)
    if "params" in value:
        return cls.from_json(value["params"])
    return cls.from_dict(_from_json(value["dict"]))
