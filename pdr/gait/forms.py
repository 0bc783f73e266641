"""Walking forms: PCA of the cycles' Fourier features to three dimensions, k-means, a transition diagram (Watanabe et
al., section 4, eq. 3), and the classification of new cycles.

A forms model is data only (JSON): the feature layout, the standardisation, the PCA basis, the centroids, the
transition diagram and a description of each form; see :meth:`FourierGaitForms.to_dict`.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from scipy.cluster.vq import kmeans2

from pdr.base import Algorithm
from pdr.constants import FLIGHT_MAX_SPECIFIC_FORCE_G, GRAVITY_MPS2
from pdr.errors import InputError, collect_warnings
from pdr.gait.fourier import DEFAULT_ORDER
from pdr.io.tomlio import read_json

FORMS_FORMAT = "pdr-gait-forms"
FORMS_VERSION = 1
LEG_LENGTH_PER_HEIGHT = 0.53  # greater-trochanter height / body height (Winter 2009), as in pdr.step_length
DEFAULT_LEG_LENGTH_M = LEG_LENGTH_PER_HEIGHT * 1.75
# Names of forms from the physics of gait. Speeds as Froude numbers Fr = v^2 / (g * leg length), so the names hold
# for any body size: humans change from walking to running near Fr = 0.5 (Alexander 1989, "Optimization and gaits in
# the locomotion of vertebrates"); comfortable walking lies near Fr = 0.2 (1.3 m/s for a 0.9 m leg); below 0.1
# (about 0.95 m/s) the walk is slow, above 0.3 (1.6 m/s) it is fast.
FROUDE_SLOW = 0.1
FROUDE_FAST = 0.3
FROUDE_RUN = 0.5
# Stairs climb at about 30-35 degrees, ramps at most ~5 (1:12): a path steeper than 15 degrees is stairs.
STAIRS_MIN_SLOPE = np.tan(np.radians(15.0))
# A stride that turns more than 30 degrees is a turn (a corner walked in one or two strides turns 45-90 per stride).
TURN_MIN_RAD_PER_CYCLE = np.radians(30.0)
# The trunk vaults over the stance leg (inverted pendulum): a vertical excursion h over a step of a leg l gives the
# step length 2 sqrt(2 l h - h^2), times Zijlstra & Hof's (2003) correction for the pelvis's own motion (1.25).
# Unlike the step model's speed (population coefficients), it needs only the leg length, so it holds across people.
PENDULUM_K = 1.25
WALK_KINDS = ("slow_walk", "walk", "fast_walk")
MIN_VAR_FRACTION = 0.05  # floor of a form's variance, as a fraction of the pooled one (a form of a few cycles)
FORM_KINDS = ("slow_walk", "walk", "fast_walk", "run", "turning", "stairs_up", "stairs_down")
FORMS_COLUMNS = ["t_start_s", "t_end_s", "form", "form_id", "kind", "distance", "source"]


def speed_kind(speed_mps, leg_length_m) -> np.ndarray:
    """The speed name of each speed (slow_walk, walk, fast_walk, run) from its Froude number (``leg_length_m``: one
    leg length, or one per speed)."""
    v = np.asarray(speed_mps, float)
    fr = v ** 2 / (GRAVITY_MPS2 * leg_length_m)
    return np.where(fr < FROUDE_SLOW, "slow_walk", np.where(fr < FROUDE_FAST, "walk",
                    np.where(fr < FROUDE_RUN, "fast_walk", "run"))).astype(object)


def min_vertical_acc_mps2(cycles: pd.DataFrame, channel: str = "acc_v_mps2") -> np.ndarray:
    """Lowest vertical acceleration (gravity removed) over each cycle, from its Fourier series; NaN without the
    channel (shoe IMU cycles)."""
    from pdr.gait.fourier import coefficient_names, fourier_design_matrix

    cols = [f"{channel}_{c}" for c in coefficient_names(DEFAULT_ORDER)]
    if not all(c in cycles.columns for c in cols):
        return np.full(len(cycles), np.nan)
    phase = np.linspace(0.0, 2.0 * np.pi, 4 * len(cols), endpoint=False)
    return (cycles[cols].to_numpy(float) @ fourier_design_matrix(phase, DEFAULT_ORDER).T).min(axis=1)


def pendulum_speed_mps(cycles: pd.DataFrame, leg_length_m, channel: str = "acc_v_mps2") -> np.ndarray:
    """Walking speed of each cycle by the inverted pendulum (Zijlstra & Hof 2003) from its Fourier series: the
    vertical excursion h of the trunk (the series of the vertical acceleration integrated twice, harmonic k divided by
    -(2 pi k / T)^2; its peak to peak over the stride), the step length ``PENDULUM_K`` * 2 sqrt(2 l h - h^2) with the
    leg length l, and two steps per cycle duration T. NaN without the channel (shoe IMU cycles) or a leg length."""
    from pdr.gait.fourier import fourier_design_matrix

    n = len(cycles)
    cols = [f"{channel}_{c}" for k in range(1, DEFAULT_ORDER + 1) for c in (f"a{k}", f"b{k}")]
    if n == 0 or not all(c in cycles.columns for c in cols) or "duration_s" not in cycles.columns:
        return np.full(n, np.nan)
    dur = cycles["duration_s"].to_numpy(float)
    harmonic = np.repeat(np.arange(1, DEFAULT_ORDER + 1), 2)
    omega = 2.0 * np.pi * harmonic[None, :] / dur[:, None]
    coef = np.c_[np.zeros(n), -cycles[cols].to_numpy(float) / omega ** 2]  # displacement series (no mean)
    phase = np.linspace(0.0, 2.0 * np.pi, 8 * (DEFAULT_ORDER + 1), endpoint=False)
    z = coef @ fourier_design_matrix(phase, DEFAULT_ORDER).T
    leg = np.broadcast_to(np.asarray(leg_length_m, float), (n,))
    h = np.minimum(z.max(axis=1) - z.min(axis=1), leg)
    with np.errstate(invalid="ignore"):
        step = PENDULUM_K * 2.0 * np.sqrt(2.0 * leg * h - h * h)
    return np.where((leg > 0) & (dur > 0), 2.0 * step / dur, np.nan)


def form_kind(speed_mps: float, turn_rad_per_cycle: float, climb_rate_mps: float, leg_length_m: float,
              min_acc_v_mps2: float = float("nan")) -> str:
    """The name of a form from its speed, turn per cycle, climb rate and lowest vertical acceleration (see the
    constants). Running is told by its flight phase where the trunk's vertical acceleration is known (it falls
    freely, near -g, in flight: specific force at most ``pdr.constants.FLIGHT_MAX_SPECIFIC_FORCE_G``; a walking
    trunk vaults over the stance leg and stays well above that), else by the Froude number; the walking speeds by
    the Froude number."""
    if np.isfinite(climb_rate_mps) and np.isfinite(speed_mps) and speed_mps > 0:
        slope = climb_rate_mps / speed_mps
        if slope > STAIRS_MIN_SLOPE:
            return "stairs_up"
        if slope < -STAIRS_MIN_SLOPE:
            return "stairs_down"
    if np.isfinite(turn_rad_per_cycle) and abs(turn_rad_per_cycle) > TURN_MIN_RAD_PER_CYCLE:
        return "turning"
    if np.isfinite(min_acc_v_mps2):
        if min_acc_v_mps2 + GRAVITY_MPS2 <= FLIGHT_MAX_SPECIFIC_FORCE_G * GRAVITY_MPS2:  # a flight phase
            return "run"
        if not np.isfinite(speed_mps):
            return "walk"
        kind = str(speed_kind([speed_mps], leg_length_m)[0])
        return "fast_walk" if kind == "run" else kind
    if not np.isfinite(speed_mps):
        return "walk"
    return str(speed_kind([speed_mps], leg_length_m)[0])


def _viterbi(log_emit: np.ndarray, log_trans: np.ndarray, log_prior: np.ndarray) -> np.ndarray:
    """Most likely state sequence (n,) of an HMM."""
    n, k = log_emit.shape
    back = np.zeros((n, k), int)
    score = log_prior + log_emit[0]
    for i in range(1, n):
        cand = score[:, None] + log_trans
        back[i] = np.argmax(cand, axis=0)
        score = cand[back[i], np.arange(k)] + log_emit[i]
    path = np.empty(n, int)
    path[-1] = int(np.argmax(score))
    for i in range(n - 1, 0, -1):
        path[i - 1] = back[i, path[i]]
    return path


def feature_groups(layout: list[str]) -> list[str]:
    """The gait parameter of each feature: ``acc_v_mps2_b3`` -> ``acc_v_mps2``; a scalar is its own group."""
    return [re.sub(r"_[ab]\d+$", "", name) for name in layout]


def parameter_scales(layout: list[str], x: np.ndarray) -> np.ndarray:
    """Scale of each feature: the root of the total variance of its gait parameter's coefficients, so every
    parameter (and every scalar) weighs the same in the PCA whatever its unit, while the harmonics of one parameter
    keep their relative sizes (a per-coefficient z-score would blow the noise of weak harmonics up to the size of
    the gait's own). A parameter that does not vary gets scale 1 (it stays at zero after centring)."""
    groups = np.array(feature_groups(layout), dtype=object)
    var = x.var(axis=0)
    scale = np.ones(len(layout))
    tiny = 1e-18 * max(float(np.max(x ** 2)) if x.size else 1.0, 1.0)
    for grp in dict.fromkeys(groups):
        sel = groups == grp
        total = float(var[sel].sum())
        if total > tiny:
            scale[sel] = np.sqrt(total)
    return scale


def similarity_factors(layout: list[str], leg_length_m: np.ndarray) -> np.ndarray:
    """Factors (n, n_features) making each feature dimensionless with gravity and the leg length (dynamic similarity,
    Alexander & Jayes 1983: people of different sizes moving at the same Froude number have the same dimensionless
    speeds, frequencies and accelerations): m/s^2 / g, rad/s and Hz * sqrt(L / g), m/s / sqrt(g L)."""
    leg = np.asarray(leg_length_m, float).reshape(-1, 1)
    per_unit = {"mps2": 1.0 / GRAVITY_MPS2 + 0.0 * leg, "radps": np.sqrt(leg / GRAVITY_MPS2),
                "hz": np.sqrt(leg / GRAVITY_MPS2), "mps": 1.0 / np.sqrt(GRAVITY_MPS2 * leg)}
    out = np.ones((len(leg), len(layout)))
    for j, group in enumerate(feature_groups(layout)):
        unit = group.rsplit("_", 1)[-1]
        if unit in per_unit:
            out[:, j] = per_unit[unit][:, 0]
    return out


def sequence_breaks(cycles: pd.DataFrame) -> np.ndarray:
    """True where a cycle does not directly follow the previous one (other source or bout, or a gap of more than
    half a cycle): the transition diagram only counts direct successions."""
    n = len(cycles)
    if n == 0:
        return np.zeros(0, bool)
    src = cycles["source"].to_numpy(object)
    bout = cycles["bout_id"].to_numpy()
    t0 = cycles["t_start_s"].to_numpy(float)
    t1 = cycles["t_end_s"].to_numpy(float)
    gap = np.r_[np.inf, t0[1:] - t1[:-1]]
    dur = t1 - t0
    brk = np.r_[True, (src[1:] != src[:-1]) | (bout[1:] != bout[:-1])] | (np.abs(gap) > 0.5 * dur)
    if "recording" in cycles.columns:
        rec = cycles["recording"].to_numpy(object)
        brk |= np.r_[True, rec[1:] != rec[:-1]]
    return brk


class FourierGaitForms(Algorithm):
    """Walking forms learnt from the Fourier features of gait cycles, and their transition diagram.

    Parameters
    ----------
    n_forms : number of k-means clusters (forms). The paper asks for "a sufficient number of forms": more forms than
        names (a name may cover several forms, e.g. running at 2.6 and at 3.4 m/s), so k-means is not forced to merge
        two kinds of gait while it spends clusters on wide ones (turns at every speed).
    n_components : dimension of the PCA space (the paper: 3).
    seed : seed of the k-means++ initialisation (k-means is run ``n_init`` times, the lowest within-cluster sum of
        squares is kept), so a fit is reproducible.
    n_init : number of k-means runs.
    smoothing : classify a sequence of cycles with the transition diagram (Viterbi over the forms, emission an
        isotropic Gaussian around each centroid with the form's own variance); False (default): nearest centroid.
        On the simulated mixed walks and the gaitmap data the smoothing did not raise the per-cycle accuracy (it
        holds a form a few cycles too long after a change), so it is an option.
    leg_length_m : leg length used to name the forms by Froude number; None: from the cycles' ``leg_length_m`` column
        if any, else 0.53 x 1.75 m.
    dynamic_similarity : make the features dimensionless with each cycle's leg length (``leg_length_m`` column;
        :func:`similarity_factors`) before the PCA, so the forms of a tall and a short person walking at the same
        Froude number coincide. Off by default: on the simulated benchmark (heights 1.74-1.81 m) it did not raise the
        accuracy (0.865 against 0.895 with 10 forms), the errors there come from the people's own step-length laws.
    cycle_speed_check : name the speed of each walking cycle by its own Froude number (default True): a cycle of a
        level walking form (slow_walk, walk, fast_walk) takes the speed name of its inverted-pendulum speed
        (:func:`pendulum_speed_mps`, trunk IMUs with the vertical acceleration; the form's name otherwise). k-means
        boundaries do not follow the Froude bands across people (a person with longer steps at a lower cadence lands
        in the next slower form), while the pendulum speed needs only the leg length: on the simulated benchmark the
        held-out accuracy rose from 0.855 to 0.962 (and, leaving one of the training people 0-5 out at a time, from
        0.944 to 0.961 on average, the worst person from 0.816 to 0.951). Running, turns and stairs keep their form's
        name (renaming cycles by their own flight phase too lowered the accuracy, 0.949). The pendulum is the
        trunk's: for an IMU in a pocket or a hand, turn the check off.
    cycle_turn_check : a cycle that itself turns more than ``TURN_MIN_RAD_PER_CYCLE`` (its ``turn_rate_radps`` x
        ``duration_s``, from the gyro) is named turning whatever its form, stairs excepted (default True). k-means
        places a corner stride by the shape of its signals, which a turn changes little: on the simulated benchmark
        the turning cycles found rose from 0.849 to 0.930 and the accuracy per cycle from 0.962 to 0.965.

    Attributes
    ----------
    layout_ : the feature columns (the layout of :mod:`pdr.gait.cycles`).
    mean_, scale_ : standardisation of the features.
    components_ : (n_components, n_features) orthonormal PCA basis U of eq. 3; ``explained_variance_ratio_``.
    centroids_ : (n_forms, n_components) k-means centroids in the PCA space; ``within_var_`` pooled variance per axis,
        ``form_var_`` each form's own (floored at 5% of the pooled).
    forms_ : DataFrame, one row per form: ``form_id, form, kind, n_cycles, speed_mps, turn_rate_radps, climb_rate_mps,
        step_freq_hz, duration_s, min_acc_v_mps2`` (medians over the form's training cycles).
    transition_counts_, transition_ : (n_forms, n_forms) counts and row probabilities of form j following form i.
    labels_ : form id of each training cycle (after :meth:`fit`) or of each classified cycle (after :meth:`classify`).
    distance_ : after :meth:`classify`: each cycle's distance to its form's centroid (the ``distance`` below).
    leg_length_used_m_ : the leg length the form kinds were named with (``leg_length_m``, the cycles' or the default).
    cycles_forms_ : after :meth:`classify`: ``t_start_s, t_end_s, form, form_id, kind, distance, source``
        (``distance``: to the nearest centroid in the standardised PCA space; ``kind``: the form's, or the cycle's own
        speed name with ``cycle_speed_check``, or turning with ``cycle_turn_check``).

    Notes
    -----
    Watanabe et al. (section 4): the feature vectors f_k of many cycles are compressed to three dimensions by PCA,
    g_k = U (f_k - f_mean) (eq. 3), and clustered by k-means; each cluster is a walking form, and a transition diagram
    is built from the order in which the forms follow each other. Here the features are scaled first, one scale per
    gait parameter (:func:`parameter_scales`: their units differ, m/s^2, rad/s, m/s, Hz), and each form is named
    from the medians of its cycles: speed (Froude number), turn per cycle, climb slope and, for a trunk IMU, the
    lowest vertical acceleration (a flight phase: running) (:func:`form_kind`).

    Examples
    --------
    >>> forms = FourierGaitForms(n_forms=4).fit(cycles)           # doctest: +SKIP
    >>> forms.classify(new_cycles).cycles_forms_.head()           # doctest: +SKIP
    """

    def __init__(self, *, n_forms: int = 10, n_components: int = 3, seed: int = 0, n_init: int = 10,
                 smoothing: bool = False, leg_length_m: float | None = None, dynamic_similarity: bool = False,
                 cycle_speed_check: bool = True, cycle_turn_check: bool = True) -> None:
        self.n_forms = n_forms
        self.n_components = n_components
        self.seed = seed
        self.n_init = n_init
        self.smoothing = smoothing
        self.leg_length_m = leg_length_m
        self.dynamic_similarity = dynamic_similarity
        self.cycle_speed_check = cycle_speed_check
        self.cycle_turn_check = cycle_turn_check

    # ------------------------------------------------------------------ helpers
    def _check_params(self) -> None:
        for name in ("n_forms", "n_components", "n_init"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
                raise InputError(f"{type(self).__name__}: expected {name} an integer >= 1, found {v!r}")

    @staticmethod
    def _layout_of(cycles: pd.DataFrame) -> list[str]:
        from pdr.gait.cycles import FOOT_CHANNELS, IMU_CHANNELS, foot_layout, imu_layout

        if "source" not in cycles.columns:
            raise InputError("gait forms: expected a cycles table with a source column (pdr.gait.cycles)")
        cols = set(cycles.columns)
        for channels, layout in ((IMU_CHANNELS, imu_layout), (FOOT_CHANNELS, foot_layout)):
            if f"{channels[0]}_a0" in cols:
                order = sum(1 for c in cols if c.startswith(f"{channels[0]}_a")) - 1
                return layout(order)
        raise InputError("gait forms: expected the Fourier feature columns of pdr.gait.cycles, found none")

    def _dimensionless(self, cycles: pd.DataFrame) -> np.ndarray:
        """The layout's features, made dimensionless by dynamic similarity when ``dynamic_similarity``."""
        x = cycles[self.layout_].to_numpy(float)
        if not self.dynamic_similarity:
            return x
        leg = cycles["leg_length_m"].to_numpy(float) if "leg_length_m" in cycles.columns else np.full(len(x), np.nan)
        default = self.leg_length_m if self.leg_length_m is not None else DEFAULT_LEG_LENGTH_M
        leg = np.where(np.isfinite(leg) & (leg > 0), leg, default)
        return x * similarity_factors(self.layout_, leg)

    def _matrix(self, cycles: pd.DataFrame) -> np.ndarray:
        missing = [c for c in self.layout_ if c not in cycles.columns]
        if missing:
            raise InputError(f"gait forms: the cycles lack {len(missing)} feature column(s) of the forms' layout "
                             f"(first: {missing[0]})")
        x = self._dimensionless(cycles)
        # a feature the recording cannot give (speed without a step model): the training mean, i.e. no information
        bad = ~np.isfinite(x)
        if bad.any():
            x = np.where(bad, self.mean_[None, :], x)
        return x

    def project(self, cycles: pd.DataFrame) -> np.ndarray:
        """The compressed features g (n, n_components) of eq. 3."""
        z = (self._matrix(cycles) - self.mean_) / self.scale_
        return z @ self.components_.T

    # ------------------------------------------------------------------ verbs
    def fit(self, cycles: pd.DataFrame) -> FourierGaitForms:
        """Learn the forms from a cycles table (the rows in time order within each source)."""
        self._check_params()
        if not isinstance(cycles, pd.DataFrame):
            raise InputError(f"gait forms: expected a cycles DataFrame, found {type(cycles).__name__}")
        self.layout_ = self._layout_of(cycles)
        n = len(cycles)
        p = len(self.layout_)
        if n < max(self.n_forms, self.n_components + 1) * 2:
            raise InputError(f"gait forms: expected at least {max(self.n_forms, self.n_components + 1) * 2} gait cycles "
                             f"to learn {self.n_forms} forms, found {n}")
        if self.n_components > p:
            raise InputError(f"gait forms: n_components {self.n_components} exceeds the {p} features")
        raw = self._dimensionless(cycles)
        self.mean_ = np.nanmean(raw, axis=0)
        self.mean_ = np.where(np.isfinite(self.mean_), self.mean_, 0.0)
        x = np.where(np.isfinite(raw), raw, self.mean_[None, :])
        self.scale_ = parameter_scales(self.layout_, x)
        z = (x - self.mean_) / self.scale_
        _, s, vt = np.linalg.svd(z, full_matrices=False)
        self.components_ = vt[: self.n_components]
        self.explained_variance_ratio_ = (s[: self.n_components] ** 2) / max(float((s ** 2).sum()), 1e-300)
        g = z @ self.components_.T
        best = None
        rng = np.random.default_rng(self.seed)
        for _ in range(self.n_init):
            with collect_warnings():
                cent, lab = kmeans2(g, self.n_forms, minit="++", seed=rng)
            if len(np.unique(lab)) < self.n_forms:
                continue
            sse = float(((g - cent[lab]) ** 2).sum())
            if best is None or sse < best[0]:
                best = (sse, cent, lab)
        if best is None:
            raise InputError(f"gait forms: k-means found fewer than {self.n_forms} distinct forms in {n} cycles; "
                             "ask for fewer forms")
        _, cent, lab = best
        # order the forms by speed (then by the first PCA axis) so form ids are stable and readable
        speed = cycles["speed_mps"].to_numpy(float) if "speed_mps" in cycles else np.full(n, np.nan)
        key = [(np.nanmean(speed[lab == j]) if np.isfinite(speed[lab == j]).any() else 0.0, cent[j, 0])
               for j in range(self.n_forms)]
        order = sorted(range(self.n_forms), key=lambda j: key[j])
        remap = np.empty(self.n_forms, int)
        remap[order] = np.arange(self.n_forms)
        self.centroids_ = cent[order]
        self.labels_ = remap[lab]
        self.within_var_ = float(((g - self.centroids_[self.labels_]) ** 2).sum() / max(n * self.n_components, 1))
        # per-form spread (isotropic): a form of wide variety (turns at any speed) must not swallow compact ones
        var = np.array([((g[self.labels_ == j] - self.centroids_[j]) ** 2).sum()
                        / max(int((self.labels_ == j).sum()) * self.n_components, 1) for j in range(self.n_forms)])
        self.form_var_ = np.maximum(var, MIN_VAR_FRACTION * self.within_var_)
        leg = self.leg_length_m
        if leg is None:
            leg = float(np.nanmean(cycles["leg_length_m"])) if "leg_length_m" in cycles and \
                np.isfinite(cycles["leg_length_m"]).any() else DEFAULT_LEG_LENGTH_M
        self.leg_length_used_m_ = float(leg)
        self.forms_ = self._describe(cycles, self.labels_)
        brk = sequence_breaks(cycles)
        counts = np.zeros((self.n_forms, self.n_forms))
        follow = np.flatnonzero(~brk)
        np.add.at(counts, (self.labels_[follow - 1], self.labels_[follow]), 1.0)
        self.transition_counts_ = counts
        self.transition_ = self._probabilities(counts)
        return self

    @staticmethod
    def _probabilities(counts: np.ndarray) -> np.ndarray:
        # add-one (Laplace) smoothing: a transition never seen in training stays possible, only unlikely
        c = counts + 1.0
        return c / c.sum(axis=1, keepdims=True)

    def _describe(self, cycles: pd.DataFrame, labels: np.ndarray) -> pd.DataFrame:
        rows, seen = [], {}
        min_acc = min_vertical_acc_mps2(cycles)
        for j in range(self.n_forms):
            sel = cycles[labels == j]

            def mean(col):  # the median: a form's name should not follow its few odd cycles
                if col not in sel or not len(sel):
                    return float("nan")
                v = sel[col].to_numpy(float)
                return float(np.nanmedian(v)) if np.isfinite(v).any() else float("nan")

            turn_per_cycle = float(np.nanmedian(np.abs(sel["turn_rate_radps"] * sel["duration_s"]))) if len(sel) else np.nan
            low = min_acc[labels == j]
            low = float(np.nanmedian(low)) if np.isfinite(low).any() else float("nan")
            kind = form_kind(mean("speed_mps"), turn_per_cycle, mean("climb_rate_mps"), self.leg_length_used_m_, low)
            seen[kind] = seen.get(kind, 0) + 1
            name = kind if seen[kind] == 1 else f"{kind}_{seen[kind]}"
            rows.append({"form_id": j, "form": name, "kind": kind, "n_cycles": int(len(sel)),
                         "speed_mps": mean("speed_mps"), "turn_rate_radps": mean("turn_rate_radps"),
                         "turn_per_cycle_rad": turn_per_cycle, "climb_rate_mps": mean("climb_rate_mps"),
                         "step_freq_hz": mean("step_freq_hz"), "duration_s": mean("duration_s"),
                         "min_acc_v_mps2": low})
        return pd.DataFrame(rows)

    def classify(self, cycles: pd.DataFrame) -> FourierGaitForms:
        """Label cycles with the learnt forms (nearest centroid, smoothed along each sequence of directly following
        cycles by the transition diagram when ``smoothing``); results in ``labels_`` and ``cycles_forms_``."""
        if not hasattr(self, "centroids_"):
            raise InputError("gait forms: classify needs learnt forms (fit, or load a forms file)")
        if not isinstance(cycles, pd.DataFrame):
            raise InputError(f"gait forms: expected a cycles DataFrame, found {type(cycles).__name__}")
        n = len(cycles)
        if n == 0:
            self.labels_ = np.zeros(0, int)
            self.distance_ = np.zeros(0)
            self.cycles_forms_ = pd.DataFrame({c: pd.Series(dtype=float if c in ("t_start_s", "t_end_s", "distance")
                                                            else int if c == "form_id" else object)
                                               for c in FORMS_COLUMNS})
            return self
        layout = self._layout_of(cycles)
        if layout != self.layout_:
            raise InputError(f"gait forms: the forms were learnt on another feature layout ({len(self.layout_)} features, "
                             f"first {self.layout_[0]}) than these cycles give ({len(layout)} features, first {layout[0]})")
        g = self.project(cycles)
        d2 = ((g[:, None, :] - self.centroids_[None, :, :]) ** 2).sum(axis=2)
        labels = np.argmin(d2, axis=1)
        if self.smoothing and self.n_forms > 1:
            var = np.maximum(self.form_var_, 1e-12)
            log_emit = -0.5 * d2 / var[None, :] - 0.5 * self.n_components * np.log(var)[None, :]
            log_trans = np.log(self.transition_)
            prior = self.forms_["n_cycles"].to_numpy(float) + 1.0
            log_prior = np.log(prior / prior.sum())
            brk = np.flatnonzero(sequence_breaks(cycles))
            ends = np.r_[brk[1:], n]
            for a, b in zip(brk, ends):
                labels[a:b] = _viterbi(log_emit[a:b], log_trans, log_prior)
        self.labels_ = labels
        self.distance_ = np.sqrt(d2[np.arange(n), labels])
        names = self.forms_["form"].to_numpy(object)
        kinds = self.forms_["kind"].to_numpy(object)[labels]
        if self.cycle_speed_check:
            kinds = self._cycle_speed_kinds(cycles, kinds)
        if self.cycle_turn_check and "turn_rate_radps" in cycles.columns:
            turn = np.abs(cycles["turn_rate_radps"].to_numpy(float) * cycles["duration_s"].to_numpy(float))
            own_turn = np.isfinite(turn) & (turn > TURN_MIN_RAD_PER_CYCLE) & ~np.isin(kinds, ["stairs_up", "stairs_down"])
            kinds = np.where(own_turn, "turning", kinds)
        self.cycles_forms_ = pd.DataFrame({
            "t_start_s": cycles["t_start_s"].to_numpy(float), "t_end_s": cycles["t_end_s"].to_numpy(float),
            "form": names[labels], "form_id": labels.astype(int), "kind": kinds, "distance": self.distance_,
            "source": cycles["source"].to_numpy(object)})
        return self

    def _cycle_speed_kinds(self, cycles: pd.DataFrame, kinds: np.ndarray) -> np.ndarray:
        """The kinds with each level walking cycle renamed by the Froude number of its pendulum speed (see
        ``cycle_speed_check``); a cycle without a pendulum speed keeps its form's kind. Running is told by the flight
        phase, so the fastest name a walking cycle gets is fast_walk."""
        leg = cycles["leg_length_m"].to_numpy(float) if "leg_length_m" in cycles.columns else np.full(len(cycles), np.nan)
        leg = np.where(np.isfinite(leg) & (leg > 0), leg, self.leg_length_used_m_)
        speed = pendulum_speed_mps(cycles, leg)
        ok = np.isin(kinds, WALK_KINDS) & np.isfinite(speed)
        if "trunk_sensor" in cycles.columns:  # a phone in a hand or pocket does not follow the trunk's rise and fall
            ok &= cycles["trunk_sensor"].to_numpy(bool)
        if not ok.any():
            return kinds
        own = speed_kind(speed[ok], leg[ok])
        out = kinds.copy()
        out[ok] = np.where(own == "run", "fast_walk", own)
        return out

    # ------------------------------------------------------------------ data only (JSON)
    def to_dict(self, **info: Any) -> dict[str, Any]:
        """The learnt forms as plain data (lists, numbers, strings)."""
        if not hasattr(self, "centroids_"):
            raise InputError("gait forms: nothing to save before fit")
        return {
            "format": FORMS_FORMAT, "version": FORMS_VERSION, "algorithm": type(self).__name__,
            "params": self.get_params(), "layout": list(self.layout_),
            "mean": self.mean_.tolist(), "scale": self.scale_.tolist(), "components": self.components_.tolist(),
            "explained_variance_ratio": self.explained_variance_ratio_.tolist(),
            "centroids": self.centroids_.tolist(), "within_var": self.within_var_, "form_var": self.form_var_.tolist(),
            "leg_length_used_m": self.leg_length_used_m_,
            "forms": json.loads(self.forms_.to_json(orient="records")),
            "transition_counts": self.transition_counts_.tolist(), **info,
        }

    @classmethod
    def from_dict(cls, doc: Any, what: str = "forms") -> FourierGaitForms:
        """Rebuild learnt forms from :meth:`to_dict` data; anything malformed is an InputError naming it."""
        if not isinstance(doc, dict) or doc.get("format") != FORMS_FORMAT:
            found = doc.get("format") if isinstance(doc, dict) else type(doc).__name__
            raise InputError(f"{what}: expected a {FORMS_FORMAT} file (pdr gait-forms fit), found {found!r}")
        if doc.get("version") != FORMS_VERSION:
            raise InputError(f"{what}: expected version {FORMS_VERSION}, found {doc.get('version')!r}")
        try:
            self = cls.from_config(doc["params"])
            self._check_params()
            self.layout_ = [str(c) for c in doc["layout"]]
            p, k, m = len(self.layout_), self.n_forms, self.n_components
            self.mean_ = np.asarray(doc["mean"], float).reshape(p)
            self.scale_ = np.asarray(doc["scale"], float).reshape(p)
            self.components_ = np.asarray(doc["components"], float).reshape(m, p)
            self.explained_variance_ratio_ = np.asarray(doc["explained_variance_ratio"], float).reshape(m)
            self.centroids_ = np.asarray(doc["centroids"], float).reshape(k, m)
            self.within_var_ = float(doc["within_var"])
            self.form_var_ = np.asarray(doc["form_var"], float).reshape(k)
            self.leg_length_used_m_ = float(doc["leg_length_used_m"])
            self.forms_ = pd.DataFrame(doc["forms"])
            self.transition_counts_ = np.asarray(doc["transition_counts"], float).reshape(k, k)
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f"{what}: malformed forms file ({type(exc).__name__}: {exc})") from None
        if len(self.forms_) != k or not {"form", "kind", "n_cycles"} <= set(self.forms_.columns):
            raise InputError(f"{what}: expected {k} forms with form, kind, n_cycles, found {len(self.forms_)}")
        arrays = (self.mean_, self.scale_, self.components_, self.centroids_, self.transition_counts_)
        if not all(np.isfinite(a).all() for a in arrays) or (self.scale_ <= 0).any():
            raise InputError(f"{what}: expected finite numbers and positive scales in the forms file")
        self.transition_ = self._probabilities(self.transition_counts_)
        return self


def load_forms(path: str | Path) -> tuple[FourierGaitForms, dict[str, Any]]:
    """Read a forms JSON file: the forms and the whole document (for extra sections such as step models)."""
    what = f"forms {path}"
    doc = read_json(path, what=what, missing="expected a forms JSON file, found none")
    return FourierGaitForms.from_dict(doc, what), doc
