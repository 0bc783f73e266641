"""Base class of the algorithm objects (the gaitmap / scikit-learn way).

``__init__`` takes keyword-only parameters with units in their names and stores them; one action verb
returns ``self``; results are attributes ending in ``_``. A configuration section or a calibrated model
is the algorithm's parameters as a dict.
"""

from __future__ import annotations

import inspect
from typing import Any

from pdr.errors import InputError


class Algorithm:
    """Parameters in, results out; see the module docstring."""

    @classmethod
    def param_names(cls) -> list[str]:
        sig = inspect.signature(cls.__init__)
        return [p.name for p in sig.parameters.values() if p.kind is inspect.Parameter.KEYWORD_ONLY]

    def get_params(self) -> dict[str, Any]:
        return {name: getattr(self, name) for name in self.param_names()}

    @classmethod
    def from_config(cls, section: dict[str, Any] | None, **overrides: Any):
        """Build from a configuration section; unknown keys are an InputError naming the valid ones."""
        section = dict(section or {})
        section.update(overrides)
        names = cls.param_names()
        unknown = sorted(set(section) - set(names))
        if unknown:
            raise InputError(
                f"unknown parameter(s) {', '.join(unknown)} for {cls.__name__}; expected some of: {', '.join(names)}"
            )
        return cls(**section)

    def __repr__(self) -> str:
        params = ", ".join(f"{k}={v!r}" for k, v in self.get_params().items())
        return f"{type(self).__name__}({params})"
