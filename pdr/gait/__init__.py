"""Gait cycles, their Fourier representation (Watanabe et al., eq. 2) and walking forms (PCA + k-means, eq. 3).

- :mod:`pdr.gait.fourier`: least-squares Fourier expansion of a cyclic parameter (stable API);
- :mod:`pdr.gait.cycles`: gait cycles (strides) of a body-worn IMU or a shoe IMU with their Fourier features;
- :mod:`pdr.gait.forms`: :class:`FourierGaitForms` (PCA, k-means, transition diagram, named forms; JSON data only);
- :mod:`pdr.gait.camera_estimator`: :class:`WearableCameraGaitEstimation` (walking state, form and body pose from a
  thigh camera), with its :class:`ThighCameraModel` and :class:`FourierFormTemplates`.
"""

from pdr.gait.camera_estimator import FourierFormTemplates, ThighCameraModel, WearableCameraGaitEstimation
from pdr.gait.fourier import (
    DEFAULT_ORDER,
    amplitude_phase,
    coefficient_names,
    fourier_coefficients,
    fourier_derivative,
    fourier_design_matrix,
    fourier_series,
    from_amplitude_phase,
    n_coefficients,
)
from pdr.gait.forms import FourierGaitForms, load_forms

__all__ = [
    "DEFAULT_ORDER",
    "FourierFormTemplates",
    "FourierGaitForms",
    "ThighCameraModel",
    "WearableCameraGaitEstimation",
    "amplitude_phase",
    "coefficient_names",
    "fourier_coefficients",
    "fourier_derivative",
    "fourier_design_matrix",
    "fourier_series",
    "from_amplitude_phase",
    "load_forms",
    "n_coefficients",
]
