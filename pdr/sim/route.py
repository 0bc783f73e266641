"""The walked route: a polyline with smoothed turns and optional slopes, as a curve parameterised by path length.

Every body point is placed in *path coordinates* ``(s, d, h)``: distance along the route, lateral offset to the
left, height above the local ground; :meth:`Route.to_world` maps them to the local east-north-up frame. A foot
planted at fixed ``(s, d)`` therefore stays fixed in the world, also in a turn.
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.ndimage import gaussian_filter1d

from pdr.errors import InputError

GRID_M = 0.05  # path-length grid of the curve


class Route:
    """A smooth planar curve with a ground altitude profile.

    Parameters
    ----------
    waypoints_m : (K, 2) east/north vertices of the polyline (K >= 2), walked in order.
    grades : one slope (rise / run) per polyline leg, or None (flat).
    turn_smoothing_m : heading changes at vertices are spread over about this path length (Gaussian sigma).
    min_length_m : the route is extended (repeating the polyline as a loop if ``loop``, else straight on) until
        it is at least this long.
    loop : repeat the polyline (closed back to its first vertex) instead of walking straight on.

    Notes
    -----
    The heading is a step function of the polyline's path length smoothed by a Gaussian, and the curve is its
    integral, so turns keep their exact angles and the curve is smooth (continuous curvature).
    """

    def __init__(self, waypoints_m, *, grades=None, turn_smoothing_m: float = 0.8, min_length_m: float = 0.0,
                 loop: bool = False):
        wp = np.asarray(waypoints_m, float)
        if wp.ndim != 2 or wp.shape[1] != 2 or len(wp) < 2 or not np.isfinite(wp).all():
            raise InputError(f"route.waypoints_m: expected a list of at least 2 [east, north] pairs, found shape {wp.shape}")
        seg = np.diff(wp, axis=0)
        seg_len = np.hypot(seg[:, 0], seg[:, 1])
        if (seg_len < 1e-6).any():
            raise InputError("route.waypoints_m: expected distinct consecutive waypoints, found a repeated one")
        grades = np.zeros(len(seg)) if grades is None else np.asarray(grades, float)
        if grades.shape != (len(seg),) or (np.abs(grades) > 0.5).any():
            raise InputError(f"route.grades: expected {len(seg)} slopes (one per leg, |grade| <= 0.5), found {grades.tolist()}")
        if loop and np.hypot(*(wp[-1] - wp[0])) > 1e-6:
            closing = wp[0] - wp[-1]
            seg = np.vstack([seg, closing])
            seg_len = np.append(seg_len, np.hypot(*closing))
            grades = np.append(grades, 0.0)
        total = float(seg_len.sum())
        reps = int(np.ceil(min_length_m / total)) if loop and total < min_length_m else 1
        seg, seg_len, grades = np.tile(seg, (reps, 1)), np.tile(seg_len, reps), np.tile(grades, reps)
        heading = np.unwrap(np.arctan2(seg[:, 1], seg[:, 0]))  # turns keep their sign and size (< 180 deg)
        ends = np.cumsum(seg_len)
        extra = max(min_length_m - ends[-1], 0.0) + 20.0  # walk straight on past the last vertex
        ends[-1] += extra
        length = float(ends[-1])
        s = np.arange(0.0, length + GRID_M, GRID_M)
        idx = np.minimum(np.searchsorted(ends, s, side="right"), len(ends) - 1)
        psi = gaussian_filter1d(heading[idx], max(turn_smoothing_m, GRID_M) / GRID_M, mode="nearest")
        grade = gaussian_filter1d(grades[idx], max(turn_smoothing_m, GRID_M) / GRID_M, mode="nearest")
        de, dn = np.cos(psi), np.sin(psi)
        e = np.concatenate([[0.0], np.cumsum(0.5 * (de[1:] + de[:-1]) * GRID_M)]) + wp[0, 0]
        n = np.concatenate([[0.0], np.cumsum(0.5 * (dn[1:] + dn[:-1]) * GRID_M)]) + wp[0, 1]
        u = np.concatenate([[0.0], np.cumsum(0.5 * (grade[1:] + grade[:-1]) * GRID_M)])
        self.length_m = length
        self._s = s
        self._e = CubicSpline(s, e)
        self._n = CubicSpline(s, n)
        self._u = CubicSpline(s, u)
        self._psi = CubicSpline(s, psi)

    @classmethod
    def straight(cls, length_m: float = 1000.0, heading_rad: float = 0.0) -> "Route":
        """A straight flat route from the origin."""
        end = [length_m * np.cos(heading_rad), length_m * np.sin(heading_rad)]
        return cls([[0.0, 0.0], end])

    def heading_rad(self, s_m: np.ndarray) -> np.ndarray:
        """Direction of the route (CCW from east) at path length ``s_m``."""
        return self._psi(np.clip(s_m, 0.0, self.length_m))

    def ground_u_m(self, s_m: np.ndarray) -> np.ndarray:
        return self._u(np.clip(s_m, 0.0, self.length_m))

    def to_world(self, s_m: np.ndarray, d_m: np.ndarray, h_m: np.ndarray) -> np.ndarray:
        """(N, 3) east, north, up of path points: ``s`` along, ``d`` to the left, ``h`` above the ground."""
        s = np.asarray(s_m, float)
        if s.size and (s.min() < -1.0 or s.max() > self.length_m):
            raise InputError(f"route: expected path lengths within 0..{self.length_m:.0f} m, found {s.min():.1f}..{s.max():.1f}")
        sc = np.clip(s, 0.0, self.length_m)
        psi = self._psi(sc)
        # before the start (a heel behind the first footprint) continue the first direction straight back
        before = np.minimum(s, 0.0)
        e = self._e(sc) + before * np.cos(psi) - d_m * np.sin(psi)
        n = self._n(sc) + before * np.sin(psi) + d_m * np.cos(psi)
        u = self._u(sc) + h_m
        return np.stack([e, n, u], axis=-1)
