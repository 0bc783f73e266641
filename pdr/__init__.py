"""pdr: pedestrian dead reckoning by sensor fusion (steps, step length, strides, GTSAM factor graph)."""

__version__ = "0.1.0"
