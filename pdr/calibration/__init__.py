"""Per-user step-length calibration (Ladetto et al. 2000, section 5).

:class:`RecursiveStepCalibration`: without GNSS, a constant step value over windows of 20 steps moved by the mean
residual of the model. :class:`AdaptiveKalmanCalibration`: with GNSS, an adaptive Kalman filter on the step length
from "GPS distance / number of steps" segments (:func:`gnss_segments`), and the model's parameters re-estimated
(a Bayesian update with the model's covariance as prior: one walking frequency fixes mainly the level). ``pdr calibrate`` (pdr.pipelines.calibrate) writes the result.
"""

from pdr.calibration.akf import AdaptiveKalmanCalibration
from pdr.calibration.recursive import RecursiveStepCalibration
from pdr.calibration.segments import gnss_segments

__all__ = ["AdaptiveKalmanCalibration", "RecursiveStepCalibration", "gnss_segments"]
