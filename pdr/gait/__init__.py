"""Gait cycles, their Fourier representation (Watanabe et al., eq. 2) and walking forms (PCA + k-means, eq. 3)."""

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

__all__ = [
    "DEFAULT_ORDER",
    "amplitude_phase",
    "coefficient_names",
    "fourier_coefficients",
    "fourier_derivative",
    "fourier_design_matrix",
    "fourier_series",
    "from_amplitude_phase",
    "n_coefficients",
]
