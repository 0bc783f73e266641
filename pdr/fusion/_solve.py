"""The factor graph of a walk, its Levenberg-Marquardt solve and the poses' marginal covariances (gtsam)."""

from __future__ import annotations

import threading
from typing import NamedTuple

import gtsam
import numpy as np

from pdr.errors import InputError, warn
from pdr.fusion import factors
from pdr.fusion._initial import interpolate_positions
from pdr.fusion._inputs import Problem
from pdr.fusion._linear import deviation_design


def named_blocks(sizes: dict[str, int]) -> dict[str, slice]:
    """Consecutive index ranges of the given sizes, by name, in the order given."""
    edges = np.cumsum([0, *sizes.values()])
    return {name: slice(int(a), int(b)) for name, a, b in zip(sizes, edges[:-1], edges[1:])}


class Measurements(NamedTuple):
    """What the calibrated parameters make of the measurements: per-step length and heading change, the magnetometer
    deviation curve's coefficients and the per-stride length."""

    step_length_m: np.ndarray
    dtheta_rad: np.ndarray
    mag_deviation_coef: np.ndarray
    stride_length_m: np.ndarray


def build_graph(problem: Problem, poses: np.ndarray, meas: Measurements, use: np.ndarray, absolute: bool, *,
                gnss_factor: str, huber_k: float, noise_length_m: np.ndarray | None = None
                ) -> tuple[gtsam.NonlinearFactorGraph, dict[str, slice]]:
    """The factor graph at the current ``poses`` (which set the magnetometer deviation at each heading and the shift of
    the ``"shifted"`` GNSS factors) with the fixes ``use``, and its rows (:func:`graph_rows`). ``noise_length_m``: the
    step lengths that set the step factors' noise (default: ``meas``'s own)."""
    noise_length = meas.step_length_m if noise_length_m is None else noise_length_m
    graph = gtsam.NonlinearFactorGraph()
    if absolute:
        graph.add(factors.start_prior(gtsam.Pose2(*poses[0]), anchored=False))
    else:
        graph.add(factors.start_prior(gtsam.Pose2(0.0, 0.0, problem.heading0_rad), anchored=True))
    for i in range(problem.n_steps):
        graph.add(factors.step_factor(i, meas.step_length_m[i], meas.dtheta_rad[i], problem.step_length_std_m[i],
                                      problem.dtheta_std_rad[i], problem.lateral_std_m[i], noise_length[i]))
    mag_idx = np.flatnonzero(np.isfinite(problem.mag_rad))
    mag = problem.mag_rad[mag_idx] - deviation_design(poses[mag_idx + 1, 2]) @ meas.mag_deviation_coef
    for i, m in zip(mag_idx, mag):
        graph.add(factors.heading_factor(i + 1, m, problem.mag_std_rad[i], huber_k))
    for (k0, k1), length_m, std in zip(problem.stride_k, meas.stride_length_m, problem.stride_std_m):
        graph.add(factors.stride_factor(k0, k1, length_m, std, huber_k))
    idx = np.flatnonzero(use)
    k, alpha = problem.gnss_k[idx], problem.gnss_alpha[idx]
    if gnss_factor == "interpolated" and problem.n_steps > 0:
        for j, kk, a in zip(idx, k, alpha):
            graph.add(factors.gnss_interpolated_factor(kk, a, problem.gnss_en_m[j],
                                                       factors.gnss_noise(float(problem.gnss_std_m[j]), huber_k)))
    else:
        nearest = np.where(alpha < 0.5, k, np.minimum(k + 1, problem.n_steps))
        shift = poses[nearest, :2] - interpolate_positions(poses, k, alpha)
        for j, m, s in zip(idx, nearest, shift):
            graph.add(factors.gnss_shifted_factor(m, problem.gnss_en_m[j], s,
                                                  factors.gnss_noise(float(problem.gnss_std_m[j]), huber_k)))
    return graph, graph_rows(problem, use)


def graph_rows(problem: Problem, use: np.ndarray) -> dict[str, slice]:
    """The rows of each factor kind in the linearised system of :func:`build_graph` (gtsam stacks the factors'
    whitened rows in the order they are added): Pose2 prior and between factors 3 rows each; rotation prior and
    range 1; GNSS position 2."""
    return named_blocks({"start": 3, "steps": 3 * problem.n_steps, "heading": int(np.isfinite(problem.mag_rad).sum()),
                         "strides": len(problem.stride_length_m), "gnss": 2 * int(np.sum(use))})


def initial_values(poses: np.ndarray) -> gtsam.Values:
    values = gtsam.Values()
    for i, p in enumerate(poses):
        values.insert(factors.pose_key(i), gtsam.Pose2(*p))
    return values


def solve(graph: gtsam.NonlinearFactorGraph, initial: gtsam.Values) -> tuple[gtsam.Values, int, float]:
    """Levenberg-Marquardt from ``initial``: the solution, the iterations and the final error."""
    params = gtsam.LevenbergMarquardtParams()
    params.setRelativeErrorTol(1e-5)
    params.setMaxIterations(100)
    params.setOrderingType("METIS")
    # a pose chain with unary fixes has little fill-in: the sequential factorisation needs less memory than the
    # multifrontal one (100,000 steps: 670 MB instead of 810 MB peak) and is faster, with the same solution
    params.setLinearSolverType("SEQUENTIAL_CHOLESKY")
    try:
        optimizer = gtsam.LevenbergMarquardtOptimizer(graph, initial, params)
        result = with_deep_stack(optimizer.optimize)
    except RuntimeError as exc:  # gtsam's "Indeterminant linear system" and friends never reach the user
        raise InputError(f"fusion: the factor graph could not be solved (expected every pose to be constrained "
                         f"by steps and an anchor; gtsam says: {str(exc).splitlines()[0]})") from None
    return result, optimizer.iterations(), optimizer.error()


def marginal_std(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, poses: np.ndarray) -> np.ndarray:
    """(N + 1, 2) east/north std of the poses (``gtsam.Marginals`` rotated to east-north); where gtsam cannot
    compute them, the upper bounds of :func:`chain_position_std`, with a warning."""
    try:
        marginals = with_deep_stack(gtsam.Marginals, graph, values)
    except RuntimeError as exc:
        reason = " ".join(str(exc).strip().split("\n\n")[0].split()) or type(exc).__name__
        warn(f"fusion: gtsam marginal covariances unavailable ({reason}); e_std_m/n_std_m propagated "
             "along the step chain from the start pose's prior instead (magnetometer, stride and GNSS "
             "factors ignored: upper bounds)")
        return chain_position_std(graph, poses)
    out = np.empty((len(poses), 2))
    for i, p in enumerate(poses):
        cov = factors.world_position_cov(marginals.marginalCovariance(factors.pose_key(i)), p[2])
        out[i] = np.sqrt(np.maximum(np.diag(cov), 0.0))
    return out


def fix_d2(problem: Problem, poses: np.ndarray) -> np.ndarray:
    """Squared whitened distance of each fix from the path at its time."""
    pos = interpolate_positions(poses, problem.gnss_k, problem.gnss_alpha)
    return np.sum(np.square(pos - problem.gnss_en_m), axis=1) / np.square(problem.gnss_std_m)


def gate(d2: np.ndarray, threshold: float, max_run: int) -> np.ndarray:
    """Chi-square gate of the fixes (in time order), except that a run of more than ``max_run`` consecutive rejected
    fixes is kept: outliers come alone, a long consistent run means the path, not the fixes, is wrong."""
    use = d2 <= threshold
    rejected = np.concatenate([[0], (~use).astype(np.int8), [0]])
    starts = np.flatnonzero(np.diff(rejected) == 1)
    ends = np.flatnonzero(np.diff(rejected) == -1)
    for a, b in zip(starts, ends):
        if b - a > max_run:
            use[a:b] = True
    return use


DEEP_STACK_BYTES = 1 << 30  # gtsam recurses along the elimination tree: a 100,000-pose chain overflows 8 MB


def with_deep_stack(fn, *args):
    """Run ``fn(*args)`` in a thread with a large stack (virtual memory only) and return its result or raise its error.

    gtsam's recursive elimination / marginalisation over a long chain (a walk of tens of thousands of steps) overflows
    the default 8 MB stack and crashes the interpreter."""
    out: dict = {}

    def target() -> None:
        try:
            out["value"] = fn(*args)
        except BaseException as exc:  # re-raised in the caller's thread
            out["error"] = exc

    previous = threading.stack_size(DEEP_STACK_BYTES)
    try:
        thread = threading.Thread(target=target, name="pdr-gtsam")
        thread.start()
    finally:
        threading.stack_size(previous)
    thread.join()
    if "error" in out:
        raise out["error"]
    return out["value"]


def chain_position_std(graph: gtsam.NonlinearFactorGraph, poses: np.ndarray) -> np.ndarray:
    """(N + 1, 2) east/north std of the poses from the start prior and the step factors alone (first-order
    propagation in the tangent space, ``P_k+1 = Ad(T^-1) P_k Ad(T^-1)^T + Q_k`` with ``T`` the measured step; Barfoot,
    *State Estimation for Robotics*, 2017, sec. 7.3): the exact marginals of the step chain, so upper bounds of those
    of a graph with further factors. A position is never farther from the start than the distance walked, so no std
    exceeds that distance (a linearised heading std of several radians says no more than that)."""
    prior, steps = None, {}
    for i in range(graph.size()):
        factor = graph.at(i)
        if isinstance(factor, gtsam.PriorFactorPose2) and factor.keys()[0] == factors.pose_key(0):
            prior = factor.noiseModel().covariance()
        elif isinstance(factor, gtsam.BetweenFactorPose2):
            steps[factor.keys()[0]] = factor
    cov = np.array(prior, float)
    out = np.empty((len(poses), 2))
    walked = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(poses[:, :2], axis=0), axis=1))])
    for k, pose in enumerate(poses):
        if k > 0:
            step = steps[factors.pose_key(k - 1)]
            adjoint = step.measured().inverse().AdjointMap()
            cov = adjoint @ cov @ adjoint.T + step.noiseModel().covariance()
        std = np.sqrt(np.maximum(np.diag(factors.world_position_cov(cov, pose[2])), 0.0))
        out[k] = np.minimum(std, max(walked[k], float(np.sqrt(prior[0, 0]))))
    return out
