"""Recursive step-length prediction when no GNSS is available (Ladetto et al. 2000, section 5)."""

from __future__ import annotations

import numpy as np
import pandas as pd

from pdr.base import Algorithm
from pdr.errors import InputError
from pdr.step_length.models import StepLengthModel


class RecursiveStepCalibration(Algorithm):
    """A constant step value S over windows of steps, moved by the mean residual of the model's predictions.

    Parameters
    ----------
    window_steps : steps per window (the paper's update period: 20).
    initial_step_m : S of the first window; None = the mean prediction of the first window.

    Attributes
    ----------
    step_length_m_ : per step, the S of its window.
    step_length_std_m_ : per step, the standard deviation of the residuals of its window about S (the spread of the
        "natural" step variability the paper models as Gaussian), floored at the model's per-step std of the mean.
    window_step_m_ : S per window; ``residual_mean_m_`` and ``residual_std_m_``: mu and sigma per window.

    Notes
    -----
    Ladetto et al. (2000), section 5: (1) take a constant step value S over an interval of t steps; (2) compute the
    residuals between S and the values predicted by the model (eq. 1); (3) estimate the mean mu and variance of their
    normal distribution; (4) the next constant is S = S + mu. Steps vary about a more stable value, so this smooths
    single-step outliers; it lags one window behind a change of pace (the paper's Figure 5 shows why the adaptive
    Kalman filter with GNSS is needed to re-parameterise the model).

    Example
    -------
    >>> from pdr.step_length import RegressionStepLength
    >>> rc = RecursiveStepCalibration(window_steps=20).estimate(steps, RegressionStepLength.population())  # doctest: +SKIP
    >>> rc.step_length_m_  # doctest: +SKIP
    """

    def __init__(self, *, window_steps: int = 20, initial_step_m: float | None = None):
        self.window_steps = window_steps
        self.initial_step_m = initial_step_m

    def estimate(self, steps: pd.DataFrame, model: StepLengthModel, subject: dict | None = None):
        if not isinstance(self.window_steps, int) or isinstance(self.window_steps, bool) or self.window_steps < 1:
            raise InputError(f"RecursiveStepCalibration: expected window_steps a positive integer, found {self.window_steps!r}")
        if self.initial_step_m is not None and not (isinstance(self.initial_step_m, (int, float)) and 0 < self.initial_step_m < 3):
            raise InputError(f"RecursiveStepCalibration: expected initial_step_m in metres (0-3) or None, found {self.initial_step_m!r}")
        model.estimate(steps, subject)
        pred = np.asarray(model.step_length_m_, float)
        n = len(pred)
        n_win = -(-n // self.window_steps)
        s_win = np.empty(n_win)
        mu = np.empty(n_win)
        sigma = np.empty(n_win)
        s = self.initial_step_m
        for j in range(n_win):
            window = pred[j * self.window_steps:(j + 1) * self.window_steps]
            if s is None:
                s = float(window.mean())
            s_win[j] = s
            resid = window - s
            mu[j] = resid.mean()
            sigma[j] = resid.std(ddof=1) if len(resid) > 1 else float(model.residual_std_m)
            s = s + mu[j]
        idx = np.arange(n) // self.window_steps
        self.step_length_m_ = s_win[idx] if n else np.empty(0)
        floor = np.asarray(model.step_length_std_m_, float) / np.sqrt(self.window_steps)
        self.step_length_std_m_ = np.maximum(np.sqrt(sigma[idx] ** 2 + mu[idx] ** 2), floor) if n else np.empty(0)
        self.window_step_m_ = s_win
        self.residual_mean_m_ = mu
        self.residual_std_m_ = sigma
        return self
