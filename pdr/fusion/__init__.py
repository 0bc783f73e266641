"""Fusion of steps, strides, heading and GNSS into a trajectory (all gtsam code of `pdr` lives here).

:class:`FactorGraphFusion` (batch smoothing, Levenberg-Marquardt), :class:`IncrementalFusion` (iSAM2, causal, step by
step) and :class:`EkfFusion` (forward extended Kalman filter baseline) share one ``fuse`` signature and one set of
results (``trajectory_``, ``step_model_``, ``step_length_m_``, ``gnss_used_``, ``solver_``).
"""

from pdr.fusion.ekf import EkfFusion
from pdr.fusion.graph import FactorGraphFusion
from pdr.fusion.incremental import IncrementalFusion

__all__ = ["EkfFusion", "FactorGraphFusion", "IncrementalFusion"]
