"""Step-length models: per-step length and its standard deviation from the features of the steps table.

Every model here is linear in its parameters, ``length = x(features) . theta``, which lets one least-squares fit
(:meth:`StepLengthModel.fit`) and one Bayesian update (the GNSS calibration in :mod:`pdr.calibration`) serve them all:

================================  ==========================================  =====================================
model                             length (m)                                  parameters (theta)
================================  ==========================================  =====================================
:class:`RegressionStepLength`     A + B * step_freq_hz + C * acc_var_m2ps4    a_m, b_m_per_hz, c_m_per_m2ps4
:class:`WeinbergStepLength`       K * (a_max - a_min) ** (1/4)                k_m_per_root4_mps2
:class:`KimStepLength`            K * mean(|a|) ** (1/3)                      k_m_per_root3_mps2
:class:`ZijlstraStepLength`       K * 2 * sqrt(2 l h - h^2)                   k_scale (l: sensor height, h: CoM
                                                                              vertical excursion over the step)
================================  ==========================================  =====================================

The standard deviation of a step is ``sqrt(residual_std_m^2 + x Sigma x^T)``: the model's per-step scatter plus the
uncertainty of its parameters (``covariance``, None = parameters taken as exact).
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
import pandas as pd

from pdr.base import Algorithm
from pdr.constants import REFERENCE_CADENCE_HZ
from pdr.errors import InputError, warn
from pdr.io.recording import Recording
from pdr.signals import ImuSignals
from pdr.step_length.features import with_signal_features

MAX_STEP_M = 2.0  # a longer "step" is a model blow-up (a sprint step is ~1.5 m): clipped, with a warning
LEG_LENGTH_PER_HEIGHT = 0.53  # greater-trochanter height / body height (Winter, Biomechanics of Human Movement, 2009)
MAX_FREQ_HZ = 6.0  # faster than any human cadence: the column is not a step frequency in Hz
POPULATION_HEIGHT_M = 1.70  # adult stature, both sexes (NCD-RisC 2016, Europe / North America: men ~1.77, women ~1.64)
HEIGHT_STEP_RATIO = 0.414  # step length / body height at a normal cadence (pedometer rule: 0.415 men, 0.413 women)
LEVEL_REL_STD = 0.08  # prior spread of a person's step length at a given height and cadence
SLOPE_REL_STD = 0.30  # prior spread of the cadence slope, relative to its value


class StepLengthModel(Algorithm):
    """Common mechanics of the linear-in-parameters step-length models (see the module docstring)."""

    name: ClassVar[str] = ""
    required_columns: ClassVar[tuple[str, ...]] = ()
    theta_names: ClassVar[tuple[str, ...]] = ()
    nonnegative: ClassVar[tuple[str, ...]] = ()  # parameters a calibration holds at >= 0
    preset: ClassVar[dict[str, Any]] = {}

    # ------------------------------------------------------------------ parameters
    @property
    def theta(self) -> np.ndarray:
        """The linear parameters, in the order of ``theta_names``."""
        return np.array([float(getattr(self, n)) for n in self.theta_names])

    @property
    def covariance_matrix(self) -> np.ndarray | None:
        """``covariance`` as a (p, p) array, or None."""
        return None if self.covariance is None else np.asarray(self.covariance, float).reshape(len(self.theta_names), -1)

    def with_theta(self, theta: np.ndarray, covariance: np.ndarray | None, residual_std_m: float | None = None):
        """A copy of this model with new linear parameters (and covariance, residual std)."""
        params = self.get_params()
        params.update({n: float(v) for n, v in zip(self.theta_names, theta)})
        params["covariance"] = None if covariance is None else np.asarray(covariance, float).tolist()
        if residual_std_m is not None:
            params["residual_std_m"] = float(residual_std_m)
        return type(self)(**params)

    @classmethod
    def population(cls, **overrides: Any):
        """The published / population preset (for a user never calibrated), with optional overrides."""
        return cls.from_config({**cls.preset, **overrides})

    def _check_params(self) -> None:
        for n in (*self.theta_names, "residual_std_m"):
            v = getattr(self, n)
            if not isinstance(v, (int, float)) or isinstance(v, bool) or not np.isfinite(v):
                raise InputError(f"{type(self).__name__}: expected a finite number for {n}, found {v!r}")
        if self.residual_std_m < 0:
            raise InputError(f"{type(self).__name__}: expected residual_std_m >= 0, found {self.residual_std_m}")
        if self.covariance is not None:
            p = len(self.theta_names)
            try:
                cov = np.asarray(self.covariance, float)
            except (TypeError, ValueError):
                raise InputError(f"{type(self).__name__}: expected covariance a {p}x{p} matrix of numbers, found {self.covariance!r}") from None
            if cov.shape != (p, p) or not np.isfinite(cov).all():
                raise InputError(f"{type(self).__name__}: expected covariance a finite {p}x{p} matrix "
                                 f"(order {', '.join(self.theta_names)}), found shape {cov.shape}")
            if not np.allclose(cov, cov.T, rtol=1e-6, atol=1e-12) or np.linalg.eigvalsh((cov + cov.T) / 2).min() < -1e-12:
                raise InputError(f"{type(self).__name__}: expected a symmetric positive semi-definite covariance, found {cov.tolist()}")

    # ------------------------------------------------------------------ features
    def prepare(self, steps: pd.DataFrame, rec: Recording | pd.DataFrame, signals: ImuSignals | None = None) -> pd.DataFrame:
        """``steps`` with the signal features this model needs added from the recording (a no-op when present);
        ``signals``: its main IMU's shared signals (default: computed here)."""
        if all(c in steps.columns for c in self.required_columns):
            return steps
        return with_signal_features(steps, rec, signals)

    def _features(self, steps: pd.DataFrame) -> dict[str, np.ndarray]:
        if not isinstance(steps, pd.DataFrame):
            raise InputError(f"{type(self).__name__}: expected the steps as a DataFrame, found {type(steps).__name__}")
        missing = [c for c in self.required_columns if c not in steps.columns]
        if missing:
            hint = " (add them with pdr.step_length.with_signal_features(steps, rec) or model.prepare)" \
                if set(missing) & {"acc_range_mps2", "acc_abs_mean_mps2", "vertical_excursion_m"} else ""
            raise InputError(f"{type(self).__name__}: expected steps columns {', '.join(self.required_columns)}, "
                             f"missing {', '.join(missing)}{hint}")
        out = {}
        for c in self.required_columns:
            x = pd.to_numeric(steps[c], errors="coerce").to_numpy(float)
            finite = np.isfinite(x)
            if (x[finite] < 0).any():
                raise InputError(f"{type(self).__name__}: expected {c} >= 0, found {x[finite].min():.4g}")
            if not finite.all() and len(x):
                fill = float(np.median(x[finite])) if finite.any() else float(self.typical_features[c])
                warn(f"{type(self).__name__}: {int((~finite).sum())} step(s) without a finite {c}; "
                     f"using {fill:.4g} for them")
                x = np.where(finite, x, fill)
            out[c] = x
        if "step_freq_hz" in out and (out["step_freq_hz"] > MAX_FREQ_HZ).any():
            raise InputError(f"{type(self).__name__}: expected step_freq_hz in Hz (< {MAX_FREQ_HZ:g}), "
                             f"found {out['step_freq_hz'].max():.4g}")
        return out

    typical_features: ClassVar[dict[str, float]] = {}

    def design(self, steps: pd.DataFrame, subject: dict | None = None) -> np.ndarray:
        """The (n_steps, p) matrix ``x`` with ``length = x @ theta``."""
        raise NotImplementedError

    # ------------------------------------------------------------------ verbs
    def estimate(self, steps: pd.DataFrame, subject: dict | None = None):
        """Per-step length and standard deviation into ``step_length_m_``, ``step_length_std_m_``; returns self."""
        self._check_params()
        x = self.design(steps, subject)
        length = x @ self.theta
        var = np.full(len(length), float(self.residual_std_m) ** 2)
        cov = self.covariance_matrix
        if cov is not None and len(x):
            var = var + np.einsum("ij,jk,ik->i", x, cov, x)
        bad = (length < 0) | (length > MAX_STEP_M)
        if bad.any():
            warn(f"{type(self).__name__}: {int(bad.sum())} step length(s) outside [0, {MAX_STEP_M:g}] m clipped "
                 "(features far from the model's range)")
            length = np.clip(length, 0.0, MAX_STEP_M)
        self.step_length_m_ = length
        self.step_length_std_m_ = np.sqrt(var)
        return self

    def fit(self, steps: pd.DataFrame, lengths, subject: dict | None = None):
        """Least-squares fit of the parameters to known step lengths (m); sets them, their covariance and the residual
        std on this model and returns self. Parameters the features cannot tell apart (e.g. B and C when only one
        walking frequency is seen) keep their values and only the first (A, or K) is fitted, with a warning."""
        x = self.design(steps, subject)
        y = np.asarray(lengths, float).ravel()
        if len(y) != len(x):
            raise InputError(f"{type(self).__name__}.fit: expected one length per step ({len(x)}), found {len(y)}")
        if not np.isfinite(y).all() or (y <= 0).any():
            raise InputError(f"{type(self).__name__}.fit: expected finite positive lengths (m), found "
                             f"{int((~np.isfinite(y)).sum())} non-finite and {int((y <= 0).sum())} non-positive")
        p = x.shape[1]
        cols = list(range(p))
        if len(y) <= p or np.linalg.matrix_rank(_standardised(x)) < p:
            if len(y) < 2:
                raise InputError(f"{type(self).__name__}.fit: expected at least 2 steps, found {len(y)}")
            warn(f"{type(self).__name__}.fit: the features do not separate the {p} parameters "
                 f"({len(y)} steps); fitting {self.theta_names[0]} only")
            cols = [0]
        theta = self.theta
        fixed = [j for j in range(p) if j not in cols]
        y_free = y - x[:, fixed] @ theta[fixed]
        xf = x[:, cols]
        sol, *_ = np.linalg.lstsq(xf, y_free, rcond=None)
        resid = y_free - xf @ sol
        dof = max(len(y) - len(cols), 1)
        s2 = float(resid @ resid) / dof
        cov = np.zeros((p, p))
        cov[np.ix_(cols, cols)] = s2 * np.linalg.inv(xf.T @ xf)
        theta[cols] = sol
        for n, v in zip(self.theta_names, theta):
            setattr(self, n, float(v))
        self.covariance = cov.tolist()
        self.residual_std_m = float(np.sqrt(s2))
        self.n_fit_steps_ = len(y)
        return self


def _standardised(x: np.ndarray) -> np.ndarray:
    """Columns scaled to unit norm, so the rank test does not depend on units."""
    norm = np.linalg.norm(x, axis=0)
    return x / np.where(norm > 0, norm, 1.0)


def height_cadence_params(height_m: float) -> dict[str, Any]:
    """Parameters and prior covariance of :class:`RegressionStepLength` for a person ``height_m`` tall: step length
    ``HEIGHT_STEP_RATIO * height`` at ``REFERENCE_CADENCE_HZ``, proportional to the cadence (constant walk ratio)."""
    level = HEIGHT_STEP_RATIO * float(height_m)
    f0 = REFERENCE_CADENCE_HZ
    b = level / f0
    s_level, s_b = LEVEL_REL_STD * level, SLOPE_REL_STD * b
    return {"a_m": 0.0, "b_m_per_hz": round(b, 6), "c_m_per_m2ps4": 0.0, "residual_std_m": 0.07,
            "covariance": [[s_level ** 2 + (f0 * s_b) ** 2, -f0 * s_b ** 2, 0.0],
                           [-f0 * s_b ** 2, s_b ** 2, 0.0],
                           [0.0, 0.0, 0.01 ** 2]]}


class RegressionStepLength(StepLengthModel):
    """Step length = A + B * step frequency + C * acceleration variance (Ladetto et al. 2000, eq. 1).

    Parameters
    ----------
    a_m : A, metres.
    b_m_per_hz : B, metres per Hz of step frequency (``step_freq_hz``).
    c_m_per_m2ps4 : C, metres per (m/s²)² of variance of the acceleration norm over the step (``acc_var_m2ps4``).
    residual_std_m : standard deviation of one step about the model (the paper's w ~ N(0, sigma)).
    covariance : 3x3 covariance of (A, B, C) in the units above, or None.

    Attributes
    ----------
    step_length_m_, step_length_std_m_ : per step (after :meth:`estimate`).
    n_fit_steps_ : steps used by the last :meth:`fit`.

    Notes
    -----
    Ladetto, Gabaglio, Merminod, Terrier, Schutz (2000), "Human walking analysis assisted by DGPS", eq. (1); A, B, C by
    linear least squares, with their covariance ``s^2 (X^T X)^-1``. For a user never calibrated, the length comes
    from the body height H and the cadence (:meth:`for_height`): a step of 0.414 H at 110 steps/min (the pedometer
    rule of 41.5% / 41.3% of the height for men / women, at a normal cadence in the middle of the adults' 100-120
    steps/min) and a walk ratio (step length / cadence) constant over walking speeds (Sekiya & Nagasaki 1998), i.e.
    A = 0, B = 0.414 H / 1.833 Hz = 0.226 H per Hz, C = 0. Its prior covariance: the level at 110 steps/min known to
    8% (people of one height differ), the slope B to 30% (a negative slope is 3.3 sigma away), C to 0.01 m/(m/s²)²;
    7 cm per-step scatter (Ladetto et al.: 3-11 cm depending on cadence). The population preset is that model at
    the population height (:data:`POPULATION_HEIGHT_M`, 1.70 m), B = 0.3839 m/Hz, which is also the walk ratio of Sekiya &
    Nagasaki's adults (0.0064 m per step/min = 0.384 m/Hz).

    Example
    -------
    >>> model = RegressionStepLength.population()
    >>> model.estimate(pd.DataFrame({"step_freq_hz": [1.8], "acc_var_m2ps4": [4.0]})).step_length_m_
    array([0.691...])
    """

    name = "regression"
    required_columns = ("step_freq_hz", "acc_var_m2ps4")
    theta_names = ("a_m", "b_m_per_hz", "c_m_per_m2ps4")
    typical_features = {"step_freq_hz": 1.8, "acc_var_m2ps4": 4.0}
    nonnegative = ("b_m_per_hz",)  # walking steps do not shorten as the cadence rises (Grieve & Gear 1966)
    preset = height_cadence_params(POPULATION_HEIGHT_M)

    @classmethod
    def for_height(cls, height_m: float, **overrides: Any) -> "RegressionStepLength":
        """The height-and-cadence model of a person ``height_m`` tall (see Notes)."""
        return cls.from_config({**height_cadence_params(height_m), **overrides})

    def __init__(self, *, a_m: float, b_m_per_hz: float, c_m_per_m2ps4: float, residual_std_m: float,
                 covariance: list | np.ndarray | None = None):
        self.a_m = a_m
        self.b_m_per_hz = b_m_per_hz
        self.c_m_per_m2ps4 = c_m_per_m2ps4
        self.residual_std_m = residual_std_m
        self.covariance = covariance

    def design(self, steps: pd.DataFrame, subject: dict | None = None) -> np.ndarray:
        f = self._features(steps)
        return np.column_stack([np.ones(len(steps)), f["step_freq_hz"], f["acc_var_m2ps4"]])


class WeinbergStepLength(StepLengthModel):
    """Step length = K * (a_max - a_min)^(1/4) over the step (Weinberg 2002).

    Parameters
    ----------
    k_m_per_root4_mps2 : K, metres per (m/s²)^(1/4).
    residual_std_m, covariance : as :class:`RegressionStepLength` (covariance 1x1).

    Attributes
    ----------
    step_length_m_, step_length_std_m_ : per step; n_fit_steps_ : steps used by the last :meth:`fit`.

    Notes
    -----
    H. Weinberg, "Using the ADXL202 in pedometer and personal navigation applications", Analog Devices AN-602 (2002):
    the bounce of the hips grows with the step. ``a`` is the vertical acceleration (``acc_range_mps2`` of
    :mod:`pdr.step_length.features`). K is per user in the source; values of 0.41-0.5 are reported for a waist
    sensor in m/s²; the preset takes 0.45.

    Example
    -------
    >>> WeinbergStepLength.population().estimate(pd.DataFrame({"acc_range_mps2": [6.0]})).step_length_m_
    array([0.70428...])
    """

    name = "weinberg"
    required_columns = ("acc_range_mps2",)
    theta_names = ("k_m_per_root4_mps2",)
    typical_features = {"acc_range_mps2": 6.0}
    preset = {"k_m_per_root4_mps2": 0.45, "residual_std_m": 0.08, "covariance": [[0.05 ** 2]]}

    def __init__(self, *, k_m_per_root4_mps2: float, residual_std_m: float, covariance: list | np.ndarray | None = None):
        self.k_m_per_root4_mps2 = k_m_per_root4_mps2
        self.residual_std_m = residual_std_m
        self.covariance = covariance

    def design(self, steps: pd.DataFrame, subject: dict | None = None) -> np.ndarray:
        return (self._features(steps)["acc_range_mps2"] ** 0.25)[:, None]


class KimStepLength(StepLengthModel):
    """Step length = K * (mean |a| over the step)^(1/3) (Kim et al. 2004).

    Parameters
    ----------
    k_m_per_root3_mps2 : K, metres per (m/s²)^(1/3).
    residual_std_m, covariance : as :class:`RegressionStepLength` (covariance 1x1).

    Attributes
    ----------
    step_length_m_, step_length_std_m_ : per step; n_fit_steps_ : steps used by the last :meth:`fit`.

    Notes
    -----
    J. W. Kim, H. J. Jang, D.-H. Hwang, C. Park, "A step, stride and heading determination for the pedestrian
    navigation system", J. Global Positioning Systems 3 (2004). ``|a|`` is the absolute vertical dynamic acceleration
    (``acc_abs_mean_mps2``). K is per user in the source; the preset (0.55) gives 0.70 m at a mean |a| of 2 m/s²,
    a typical waist walk at 1.8 Hz.

    Example
    -------
    >>> KimStepLength.population().estimate(pd.DataFrame({"acc_abs_mean_mps2": [2.0]})).step_length_m_
    array([0.69295...])
    """

    name = "kim"
    required_columns = ("acc_abs_mean_mps2",)
    theta_names = ("k_m_per_root3_mps2",)
    typical_features = {"acc_abs_mean_mps2": 2.0}
    preset = {"k_m_per_root3_mps2": 0.55, "residual_std_m": 0.08, "covariance": [[0.06 ** 2]]}

    def __init__(self, *, k_m_per_root3_mps2: float, residual_std_m: float, covariance: list | np.ndarray | None = None):
        self.k_m_per_root3_mps2 = k_m_per_root3_mps2
        self.residual_std_m = residual_std_m
        self.covariance = covariance

    def design(self, steps: pd.DataFrame, subject: dict | None = None) -> np.ndarray:
        return (self._features(steps)["acc_abs_mean_mps2"] ** (1.0 / 3.0))[:, None]


class ZijlstraStepLength(StepLengthModel):
    """Inverted pendulum: step length = K * 2 * sqrt(2 l h - h^2) (Zijlstra & Hof 2003).

    Parameters
    ----------
    k_scale : K, dimensionless correction of the pendulum model.
    sensor_height_m : l, pendulum length (sensor height above ground); None = from the subject: ``sensor_height_m``,
        else ``leg_length_m``, else 0.53 * ``height_m`` (greater-trochanter height, Winter 2009).
    residual_std_m, covariance : as :class:`RegressionStepLength` (covariance 1x1).

    Attributes
    ----------
    step_length_m_, step_length_std_m_ : per step; n_fit_steps_ : steps used by the last :meth:`fit`.

    Notes
    -----
    W. Zijlstra, A. L. Hof, "Assessment of spatio-temporal gait parameters from trunk accelerations during human
    walking", Gait & Posture 18(2), 2003: the centre of mass vaults over the stance leg; its vertical excursion h
    over a step (``vertical_excursion_m``, from double-integrating the vertical acceleration between contacts, see
    :func:`pdr.step_length.features.vertical_excursion_m`) gives the step length. Zijlstra & Hof's correction was
    1.25; mobgap's ``SlZijlstra`` (Soltani et al. 2021) uses 4.587/4 (MS patients) and 4.739/4 = 1.185 (all
    participants of the MsProject set); the preset takes 1.185.

    Example
    -------
    >>> m = ZijlstraStepLength.population(sensor_height_m=1.0)
    >>> m.estimate(pd.DataFrame({"vertical_excursion_m": [0.03]})).step_length_m_
    array([0.57...])
    """

    name = "zijlstra"
    required_columns = ("vertical_excursion_m",)
    theta_names = ("k_scale",)
    typical_features = {"vertical_excursion_m": 0.04}
    preset = {"k_scale": 4.739 / 4.0, "sensor_height_m": None, "residual_std_m": 0.07, "covariance": [[0.06 ** 2]]}

    def __init__(self, *, k_scale: float, sensor_height_m: float | None = None, residual_std_m: float,
                 covariance: list | np.ndarray | None = None):
        self.k_scale = k_scale
        self.sensor_height_m = sensor_height_m
        self.residual_std_m = residual_std_m
        self.covariance = covariance

    def pendulum_length_m(self, subject: dict | None) -> float:
        """l: this model's ``sensor_height_m`` or the subject's (see the class docstring)."""
        subject = subject or {}
        for value, what in ((self.sensor_height_m, "sensor_height_m"), (subject.get("sensor_height_m"), "subject.sensor_height_m"),
                            (subject.get("leg_length_m"), "subject.leg_length_m")):
            if value is not None:
                if not isinstance(value, (int, float)) or not 0.2 < value < 2.5:
                    raise InputError(f"ZijlstraStepLength: expected {what} in metres (0.2-2.5), found {value!r}")
                return float(value)
        if subject.get("height_m") is not None:
            return LEG_LENGTH_PER_HEIGHT * float(subject["height_m"])
        raise InputError("ZijlstraStepLength: expected the sensor height (sensor_height_m, or the subject's "
                         "sensor_height_m, leg_length_m or height_m in meta.toml [subject]), found none")

    def design(self, steps: pd.DataFrame, subject: dict | None = None) -> np.ndarray:
        h = self._features(steps)["vertical_excursion_m"]
        length = self.pendulum_length_m(subject)
        h = np.minimum(h, length)
        return (2.0 * np.sqrt(2.0 * length * h - h * h))[:, None]


MODELS: dict[str, type[StepLengthModel]] = {
    m.name: m for m in (RegressionStepLength, WeinbergStepLength, KimStepLength, ZijlstraStepLength)
}
