"""Simulated thigh-camera observations of a chessboard floor, from the simulator's walking kinematics.

The walk is :class:`pdr.sim.gait.WalkKinematics` (Fourier hip/knee/ankle curves blended by speed, speed-dependent
stride and stance, per-step variability, pelvic rotation/obliquity/sway, rocker-sole stance feet, two-link leg
inverse kinematics) with speed segments labelled as walking forms (slow walk, walk, fast walk, run) that change
during the walk, on a route with turns. A camera (:class:`pdr.gait.camera_estimator.ThighCameraModel`) rides on
the thigh frame of the kinematics; the floor is a chessboard whose inner corners are the known ground points (the
paper's experiment). Each frame projects the corners in view with OpenCV (``cv2.projectPoints``, an implementation
independent of the estimator's), adds pixel noise, drops missed detections and mislabels a few corners (a
neighbouring corner's label, or a spurious detection anywhere in the image).

Ground truth per frame: the walking state (path point ``e_m, n_m``, path heading, phase = 2 pi x strides since
the first left heel strike, phase rate), the form of the speed segment, and the world positions of the pelvis,
hips, knees and ankles (``<joint>_{e,n,u}_m``, the motion-capture table the form templates are learnt from).
"""

from __future__ import annotations

import dataclasses
from typing import Sequence

import cv2
import numpy as np
import pandas as pd
from scipy.spatial import cKDTree

from pdr.errors import InputError
from pdr.gait.camera_estimator import JOINTS, ThighCameraModel, joint_columns
from pdr.sim.gait import WalkKinematics
from pdr.sim.people import Body, GaitUser, plan_walk
from pdr.sim.route import Route

# Nominal speeds of the walking forms (m/s): slow, natural and fast walking (Bohannon 1997: comfortable 1.3-1.4,
# maximum ~2.0-2.5 m/s for adults) and running (the simulator's curves are fully running above 2.6 m/s).
FORM_SPEEDS_MPS = {"slow_walk": 0.8, "walk": 1.3, "fast_walk": 1.8, "run": 2.9}
# A rectangular loop (m): the walk turns by 90 deg every 30 or 12 m.
LOOP_WAYPOINTS_M = [[0.0, 0.0], [30.0, 0.0], [30.0, 12.0], [0.0, 12.0]]
_RNG_SUBJECT, _RNG_STEPS, _RNG_CAMERA = 71, 72, 73


@dataclasses.dataclass
class FormWalk:
    """A walk of labelled speed segments: the kinematics, the segments (``form, t_start_s, t_end_s, speed_mps``)
    and the walking interval (``t_walk_s``: without the start-up steps and the steps slowing to the stop)."""

    kin: WalkKinematics
    segments: pd.DataFrame
    t_walk_s: tuple[float, float]

    def form_at(self, t_s: np.ndarray) -> np.ndarray:
        seg = self.segments
        i = np.clip(np.searchsorted(seg["t_start_s"].to_numpy(), t_s, side="right") - 1, 0, len(seg) - 1)
        return seg["form"].to_numpy()[i]

    def truth(self, t_s: np.ndarray) -> pd.DataFrame:
        """Motion-capture-like truth at times ``t_s``: state, form and joint positions (columns of
        :data:`pdr.gait.camera_estimator.MOCAP_COLUMNS`)."""
        t = np.asarray(t_s, float)
        kin = self.kin
        ps = kin.pelvis_state(t)
        h = 5e-4
        rate = (kin.pelvis_state(t + h)["phase"] - kin.pelvis_state(t - h)["phase"]) / (2 * h)
        path = kin.route.to_world(ps["s_m"], np.zeros_like(t), np.zeros_like(t))
        out = {"t_s": t, "e_m": path[:, 0], "n_m": path[:, 1], "heading_rad": kin.route.heading_rad(ps["s_m"]),
               "phase_rad": 2 * np.pi * ps["phase"], "phase_rate_radps": 2 * np.pi * rate, "form": self.form_at(t)}
        jp = kin.joint_positions_m(t)
        for j in JOINTS:
            for k, c in enumerate(joint_columns(j)):
                out[c] = jp[j][:, k]
        return pd.DataFrame(out)

    def cycles(self) -> pd.DataFrame:
        """True gait cycles (left heel strike to the next, within the walking interval) with the form of the
        segment at the middle of the cycle: ``t_start_s, t_end_s, form``."""
        hs = self.kin.heel_strikes
        t = hs.loc[hs["foot"] == "left", "t_s"].to_numpy()
        t = t[(t >= self.t_walk_s[0]) & (t <= self.t_walk_s[1])]
        mid = 0.5 * (t[:-1] + t[1:])
        return pd.DataFrame({"t_start_s": t[:-1], "t_end_s": t[1:], "form": self.form_at(mid)})


def form_walk(plan: Sequence[tuple[str, float, float]], *, subject_seed: int = 0, walk_seed: int = 0,
              height_m: float = 1.75, waypoints_m=None, standing_s: float = 1.0) -> FormWalk:
    """A walk of consecutive segments ``(form, duration_s, speed_mps)`` by the subject ``subject_seed`` (drawn
    gait coefficients; same seed = same person), steps drawn from ``walk_seed``, on a loop route with turns."""
    if not plan:
        raise InputError("form walk: expected at least one (form, duration_s, speed_mps) segment, found none")
    body = Body(height_m)
    user = GaitUser.draw(np.random.default_rng([subject_seed, _RNG_SUBJECT]))
    segs = [(standing_s, 0.0)] + [(float(d), float(v)) for _, d, v in plan] + [(standing_s, 0.0)]
    if any(v <= 0 for _, _, v in plan):
        raise InputError("form walk: expected positive speeds in every segment, found a stop")
    bouts = plan_walk(segs, user, body, np.random.default_rng([walk_seed, _RNG_STEPS]))
    if len(bouts) != 1:
        raise InputError(f"form walk: expected one walking bout, found {len(bouts)}")
    need = float(bouts[0].target_length_m.sum()) + 10.0
    route = Route(waypoints_m if waypoints_m is not None else LOOP_WAYPOINTS_M, loop=True, min_length_m=need)
    kin = WalkKinematics(body, user, bouts, route)
    starts = standing_s + np.concatenate([[0.0], np.cumsum([d for _, d, _ in plan])[:-1]])
    segments = pd.DataFrame({"form": [f for f, _, _ in plan], "t_start_s": starts,
                             "t_end_s": starts + np.array([d for _, d, _ in plan]), "speed_mps": [v for _, _, v in plan]})
    b = bouts[0].t_s
    return FormWalk(kin, segments, (float(b[2]), float(b[-4])))  # off the start-up and stopping steps


@dataclasses.dataclass
class ThighCameraWalk:
    """Observations of a thigh camera and their truth.

    ``frames``: ``t_s`` per frame; ``observations``: ``frame, point_id, u_px, v_px, outlier`` (``outlier``: a
    mislabelled corner, truth only); ``points``: ``point_id, e_m, n_m, u_m`` (the chessboard corners);
    ``truth``: per frame, :meth:`FormWalk.truth`; ``cycles``: true cycles and forms; ``camera``.
    """

    frames: pd.DataFrame
    observations: pd.DataFrame
    points: pd.DataFrame
    truth: pd.DataFrame
    cycles: pd.DataFrame
    segments: pd.DataFrame
    camera: ThighCameraModel


def chessboard_points(walk: FormWalk, *, square_m: float = 0.1, half_width_m: float = 1.5) -> pd.DataFrame:
    """Inner corners of a chessboard of ``square_m`` squares laid on the floor along the walked path, up to
    ``half_width_m`` either side of it: ``point_id, e_m, n_m, u_m``."""
    kin = walk.kin
    s_end = float(kin.pelvis_state(np.array([kin.duration_s]))["s_m"][0])
    s = np.arange(-1.0, min(s_end + 2.0, kin.route.length_m), 0.25)
    path = kin.route.to_world(s, np.zeros_like(s), np.zeros_like(s))[:, :2]
    lo = np.floor((path.min(0) - half_width_m) / square_m) * square_m
    hi = path.max(0) + half_width_m
    ge, gn = np.meshgrid(np.arange(lo[0], hi[0], square_m), np.arange(lo[1], hi[1], square_m), indexing="ij")
    grid = np.stack([ge.ravel(), gn.ravel()], -1)
    d, _ = cKDTree(path).query(grid)
    grid = grid[d <= half_width_m]
    return pd.DataFrame({"point_id": np.arange(len(grid)), "e_m": grid[:, 0], "n_m": grid[:, 1], "u_m": 0.0})


def camera_poses(walk: FormWalk, camera: ThighCameraModel, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World position (N, 3) of the optical centre and rotation camera -> world (N, 3, 3), from the thigh frame
    of the kinematics."""
    joints, r_wt = walk.kin.segment_pose(np.asarray(t_s, float), f"thigh_{camera.side}")
    centre = joints[f"hip_{camera.side}"] + r_wt @ camera.offset_thigh_m
    return centre, r_wt @ camera.rotation_thigh


def simulate_thigh_camera(walk: FormWalk, camera: ThighCameraModel | None = None, *, t_start_s: float | None = None,
                          t_end_s: float | None = None, square_m: float = 0.1, pixel_noise_px: float = 1.0,
                          detection_prob: float = 0.85, outlier_fraction: float = 0.05, seed: int = 0) -> ThighCameraWalk:
    """Frames of the thigh camera over ``[t_start_s, t_end_s]`` (default: the walking interval of ``walk``).

    Every chessboard corner in front of the camera and inside the image is detected with probability
    ``detection_prob``, with Gaussian pixel noise ``pixel_noise_px`` (1-sigma per axis); a fraction
    ``outlier_fraction`` of the detections are wrong: half carry a neighbouring corner's label (the image point of
    the corner one square away), half are spurious points anywhere in the image.
    """
    camera = camera or ThighCameraModel()
    t0 = walk.t_walk_s[0] if t_start_s is None else float(t_start_s)
    t1 = walk.t_walk_s[1] if t_end_s is None else float(t_end_s)
    if not t1 > t0:
        raise InputError(f"thigh camera: expected t_end_s > t_start_s, found {t0} .. {t1}")
    t = t0 + np.arange(int(np.floor((t1 - t0) * camera.fps)) + 1) / camera.fps
    rng = np.random.default_rng([seed, _RNG_CAMERA])
    points = chessboard_points(walk, square_m=square_m)
    xyz = points[["e_m", "n_m", "u_m"]].to_numpy(float)
    tree = cKDTree(xyz[:, :2])
    centre, r_wc = camera_poses(walk, camera, t)
    k = camera.intrinsics
    reach = 4.0 * centre[:, 2] + 0.5  # ground within view: far enough for a 76 deg wide view tilted 20-30 deg
    near = tree.query_ball_point(centre[:, :2], reach)
    rows = []
    for i in range(len(t)):
        idx = np.asarray(near[i], int)
        if idx.size == 0:
            continue
        r_cw = r_wc[i].T
        p_cam = (xyz[idx] - centre[i]) @ r_cw.T
        front = p_cam[:, 2] > 0.05
        idx = idx[front]
        if idx.size == 0:
            continue
        rvec, _ = cv2.Rodrigues(r_cw)
        tvec = -r_cw @ centre[i]
        uv = cv2.projectPoints(xyz[idx].reshape(-1, 1, 3), rvec, tvec, k, None)[0].reshape(-1, 2)
        inside = (uv[:, 0] >= 0) & (uv[:, 0] <= camera.width_px - 1) & (uv[:, 1] >= 0) & (uv[:, 1] <= camera.height_px - 1)
        inside &= rng.random(len(uv)) < detection_prob
        idx, uv = idx[inside], uv[inside]
        if idx.size == 0:
            continue
        uv = uv + pixel_noise_px * rng.standard_normal(uv.shape)
        bad = rng.random(len(idx)) < outlier_fraction
        kind = rng.random(len(idx)) < 0.5
        neigh = bad & kind
        if neigh.any():  # the image point of the corner one square away in a random direction
            step = square_m * np.array([[1, 0], [-1, 0], [0, 1], [0, -1]], float)[rng.integers(0, 4, neigh.sum())]
            other = xyz[idx[neigh]] + np.column_stack([step, np.zeros(len(step))])
            uv[neigh] = cv2.projectPoints(other.reshape(-1, 1, 3), rvec, tvec, k, None)[0].reshape(-1, 2)
        spur = bad & ~kind
        uv[spur] = rng.uniform([0, 0], [camera.width_px - 1, camera.height_px - 1], (spur.sum(), 2))
        rows.append(pd.DataFrame({"frame": i, "point_id": idx, "u_px": uv[:, 0], "v_px": uv[:, 1], "outlier": bad}))
    obs = pd.concat(rows, ignore_index=True) if rows else pd.DataFrame(
        {"frame": pd.Series(dtype=int), "point_id": pd.Series(dtype=int), "u_px": [], "v_px": [], "outlier": []})
    cyc = walk.cycles()
    cyc = cyc[(cyc["t_start_s"] >= t[0]) & (cyc["t_end_s"] <= t[-1])].reset_index(drop=True)
    return ThighCameraWalk(pd.DataFrame({"t_s": t}), obs, points, walk.truth(t), cyc, walk.segments, camera)


def training_table(plans: Sequence[Sequence[tuple[str, float, float]]], *, subject_seed: int, walk_seeds: Sequence[int],
                   rate_hz: float = 100.0, **walk_kwargs) -> pd.DataFrame:
    """Motion-capture truth of training walks (one per plan and walk seed) over their walking intervals,
    concatenated with a ``walk`` column: what :class:`pdr.gait.camera_estimator.FourierFormTemplates` learns from."""
    tables = []
    for w, (plan, seed) in enumerate(zip(plans, walk_seeds)):
        walk = form_walk(plan, subject_seed=subject_seed, walk_seed=seed, **walk_kwargs)
        t = np.arange(walk.t_walk_s[0], walk.t_walk_s[1], 1.0 / rate_hz)
        tables.append(walk.truth(t).assign(walk=w))
    return pd.concat(tables, ignore_index=True)
