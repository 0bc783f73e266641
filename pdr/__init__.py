"""pdr: pedestrian dead reckoning by sensor fusion (steps, step length, strides, GTSAM factor graph).

The Python API (imported on first use, so ``import pdr`` stays light)::

    import pdr
    rec = pdr.load_recording("path/to/recording")
    res = pdr.Pipeline().run(rec)          # or pdr.Pipeline.from_config("run.toml")
    res.trajectory_, res.steps_, res.summary_
"""

import importlib

__version__ = "0.1.0"

_API = {"Pipeline": "pdr.pipelines.pipeline", "load_recording": "pdr.io.recording"}  # name -> module defining it
__all__ = ["Pipeline", "__version__", "load_recording"]


def __getattr__(name: str):
    if name in _API:
        return getattr(importlib.import_module(_API[name]), name)
    raise AttributeError(f"module 'pdr' has no attribute {name!r}")
