"""Geodetic conversions: WGS-84 latitude/longitude <-> the local east-north frame of a recording's [geo] origin.

Exact ECEF -> ENU rotation about the origin (no flat-Earth shortcut), so long walks keep centimetre consistency.
"""

from __future__ import annotations

import numpy as np

_A_M = 6_378_137.0  # WGS-84 semi-major axis
_F = 1.0 / 298.257223563
_E2 = _F * (2.0 - _F)


def _ecef(lat_deg: np.ndarray, lon_deg: np.ndarray, alt_m: np.ndarray) -> np.ndarray:
    lat, lon = np.radians(lat_deg), np.radians(lon_deg)
    n = _A_M / np.sqrt(1.0 - _E2 * np.sin(lat) ** 2)
    return np.stack([(n + alt_m) * np.cos(lat) * np.cos(lon), (n + alt_m) * np.cos(lat) * np.sin(lon),
                     (n * (1.0 - _E2) + alt_m) * np.sin(lat)], axis=-1)


def _rotation_ecef_to_enu(lat0_deg: float, lon0_deg: float) -> np.ndarray:
    lat, lon = np.radians(lat0_deg), np.radians(lon0_deg)
    return np.array([
        [-np.sin(lon), np.cos(lon), 0.0],
        [-np.sin(lat) * np.cos(lon), -np.sin(lat) * np.sin(lon), np.cos(lat)],
        [np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)],
    ])


def latlon_to_en(lat_deg, lon_deg, origin: tuple[float, float], alt_m=0.0) -> tuple[np.ndarray, np.ndarray]:
    """East and north (m) of points relative to ``origin = (lat_deg, lon_deg)`` (at altitude 0)."""
    lat_deg, lon_deg = np.asarray(lat_deg, float), np.asarray(lon_deg, float)
    p = _ecef(lat_deg, lon_deg, np.broadcast_to(np.asarray(alt_m, float), lat_deg.shape))
    p0 = _ecef(np.array(origin[0]), np.array(origin[1]), np.array(0.0))
    enu = (p - p0) @ _rotation_ecef_to_enu(*origin).T
    return enu[..., 0], enu[..., 1]


def en_to_latlon(e_m, n_m, origin: tuple[float, float], u_m=0.0) -> tuple[np.ndarray, np.ndarray]:
    """Latitude and longitude (deg) of local east/north points (inverse of :func:`latlon_to_en`)."""
    e_m, n_m = np.asarray(e_m, float), np.asarray(n_m, float)
    enu = np.stack([e_m, n_m, np.broadcast_to(np.asarray(u_m, float), e_m.shape)], axis=-1)
    p = _ecef(np.array(origin[0]), np.array(origin[1]), np.array(0.0)) + enu @ _rotation_ecef_to_enu(*origin)
    x, y, z = p[..., 0], p[..., 1], p[..., 2]
    lon = np.arctan2(y, x)
    r = np.hypot(x, y)
    lat = np.arctan2(z, r * (1.0 - _E2))
    for _ in range(5):  # Bowring-style fixed point; converges to < 1e-12 rad in a few iterations
        n = _A_M / np.sqrt(1.0 - _E2 * np.sin(lat) ** 2)
        h = r / np.cos(lat) - n
        lat = np.arctan2(z, r * (1.0 - _E2 * n / (n + h)))
    return np.degrees(lat), np.degrees(lon)
