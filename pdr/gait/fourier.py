"""Fourier representation of a cyclic gait parameter (Watanabe et al., eq. 2).

A gait parameter sampled over one cycle (phase 0..2*pi) is represented by its Fourier expansion to order K
(the paper: K = 5). The paper writes it in amplitude-phase form,

    z(eta) = sum_{n=0..K} A_n sin(n eta + B_n)                                      (eq. 2)

which is the same function as the linear form used here for the fit,

    z(eta) = a_0 + sum_{k=1..K} (a_k cos(k eta) + b_k sin(k eta)),

with A_k = hypot(a_k, b_k), B_k = atan2(a_k, b_k) and A_0 sin(B_0) = a_0. The linear form makes the fit an
ordinary least-squares problem (unique when the samples cover at least 2K+1 distinct phases); the
amplitude-phase form is available through :func:`amplitude_phase`.

Coefficient layout (stable, relied on by the camera gait estimator): ``[a_0, a_1, b_1, a_2, b_2, ..., a_K, b_K]``,
length ``2K + 1``. Values may carry several parameters as columns: ``values`` of shape (n,) gives coefficients of
shape (2K+1,), ``values`` of shape (n, m) gives (2K+1, m).

Example
-------
>>> import numpy as np
>>> phi = np.linspace(0, 2 * np.pi, 50, endpoint=False)
>>> c = fourier_coefficients(phi, 1.0 + 0.5 * np.cos(phi) - 0.2 * np.sin(3 * phi))
>>> (np.round(c[:7], 6) + 0.0).tolist()
[1.0, 0.5, 0.0, 0.0, 0.0, 0.0, -0.2]
"""

from __future__ import annotations

import numpy as np

from pdr.errors import InputError

DEFAULT_ORDER = 5  # Watanabe et al.: "a Fourier expansion of up to fifth order"


def n_coefficients(order: int = DEFAULT_ORDER) -> int:
    """Number of coefficients of an expansion to ``order``: 2*order + 1."""
    return 2 * int(order) + 1


def coefficient_names(order: int = DEFAULT_ORDER) -> list[str]:
    """Names of the coefficients in layout order: ``a0, a1, b1, ..., aK, bK``."""
    names = ["a0"]
    for k in range(1, int(order) + 1):
        names += [f"a{k}", f"b{k}"]
    return names


def fourier_design_matrix(phase_rad, order: int = DEFAULT_ORDER) -> np.ndarray:
    """Matrix (n, 2K+1) whose columns are 1, cos(phi), sin(phi), ..., cos(K phi), sin(K phi)."""
    if int(order) < 0:
        raise InputError(f"Fourier order must be >= 0, found {order}")
    phi = np.asarray(phase_rad, dtype=float).reshape(-1)
    k = np.arange(1, int(order) + 1)
    arg = phi[:, None] * k[None, :]
    out = np.empty((len(phi), n_coefficients(order)))
    out[:, 0] = 1.0
    out[:, 1::2] = np.cos(arg)
    out[:, 2::2] = np.sin(arg)
    return out


def fourier_coefficients(phase_rad, values, order: int = DEFAULT_ORDER) -> np.ndarray:
    """Least-squares Fourier coefficients of ``values`` sampled at ``phase_rad`` (eq. 2, linear form).

    Parameters
    ----------
    phase_rad : array (n,)
        Gait phase of each sample, radians (any real value; 0..2*pi is one cycle).
    values : array (n,) or (n, m)
        The parameter(s) sampled at those phases.
    order : int
        Highest harmonic K (default 5).

    Returns
    -------
    array (2K+1,) or (2K+1, m): ``[a0, a1, b1, ..., aK, bK]`` per parameter.

    Raises
    ------
    InputError
        Mismatched lengths, non-finite samples, or fewer than 2K+1 samples (the fit would be underdetermined).
    """
    phi = np.asarray(phase_rad, dtype=float).reshape(-1)
    y = np.asarray(values, dtype=float)
    if y.ndim not in (1, 2) or y.shape[0] != len(phi):
        raise InputError(f"values must have shape ({len(phi)},) or ({len(phi)}, m) to match phase_rad, found {y.shape}")
    n_coef = n_coefficients(order)
    if len(phi) < n_coef:
        raise InputError(f"a Fourier fit of order {order} needs at least {n_coef} samples, found {len(phi)}")
    if not (np.all(np.isfinite(phi)) and np.all(np.isfinite(y))):
        raise InputError("phase_rad and values must be finite (found NaN or inf)")
    design = fourier_design_matrix(phi, order)
    coef, *_ = np.linalg.lstsq(design, y, rcond=None)
    return coef


def fourier_series(coeffs, phase_rad) -> np.ndarray:
    """Evaluate an expansion with coefficients ``[a0, a1, b1, ...]`` at ``phase_rad``.

    ``coeffs`` of shape (2K+1,) gives shape (n,); (2K+1, m) gives (n, m). Phase may be a scalar.
    """
    c = np.asarray(coeffs, dtype=float)
    if c.ndim not in (1, 2) or c.shape[0] % 2 != 1:
        raise InputError(f"Fourier coefficients must have an odd length 2K+1 along axis 0, found shape {c.shape}")
    order = (c.shape[0] - 1) // 2
    scalar = np.ndim(phase_rad) == 0
    out = fourier_design_matrix(phase_rad, order) @ c
    return out[0] if scalar else out


def fourier_derivative(coeffs) -> np.ndarray:
    """Coefficients of d/dphi of an expansion (same layout; a0 becomes 0)."""
    c = np.asarray(coeffs, dtype=float)
    order = (c.shape[0] - 1) // 2
    d = np.zeros_like(c)
    for k in range(1, order + 1):
        a, b = c[2 * k - 1], c[2 * k]
        d[2 * k - 1] = k * b  # d/dphi (a cos + b sin) = -k a sin + k b cos
        d[2 * k] = -k * a
    return d


def amplitude_phase(coeffs) -> tuple[np.ndarray, np.ndarray]:
    """The paper's amplitude-phase form (eq. 2): ``(A_n, B_n)`` for n = 0..K with z = sum A_n sin(n eta + B_n).

    For n = 0 the term is the constant a0, written as A_0 = a0, B_0 = pi/2.
    """
    c = np.asarray(coeffs, dtype=float)
    a = c[1::2]
    b = c[2::2]
    amp = np.concatenate([c[:1], np.hypot(a, b)], axis=0)
    ph = np.concatenate([np.full_like(c[:1], np.pi / 2), np.arctan2(a, b)], axis=0)
    return amp, ph


def from_amplitude_phase(amp, ph) -> np.ndarray:
    """Inverse of :func:`amplitude_phase`: A sin(k eta + B) = A sin B cos(k eta) + A cos B sin(k eta)."""
    amp = np.asarray(amp, dtype=float)
    ph = np.asarray(ph, dtype=float)
    order = amp.shape[0] - 1
    c = np.empty((n_coefficients(order),) + amp.shape[1:])
    c[0] = amp[0] * np.sin(ph[0])
    c[1::2] = amp[1:] * np.sin(ph[1:])
    c[2::2] = amp[1:] * np.cos(ph[1:])
    return c
