"""Geodetic conversions: WGS-84 latitude/longitude <-> the local east-north frame of a recording's [geo] origin.

Through pymap3d's exact geodetic <-> ENU transforms about the origin (no flat-Earth shortcut), so long walks keep
centimetre consistency.
"""

from __future__ import annotations

import numpy as np
import pymap3d


def latlon_to_en(lat_deg, lon_deg, origin: tuple[float, float], alt_m=0.0) -> tuple[np.ndarray, np.ndarray]:
    """East and north (m) of points relative to ``origin = (lat_deg, lon_deg)`` (at altitude 0)."""
    lat_deg, lon_deg = np.asarray(lat_deg, float), np.asarray(lon_deg, float)
    alt_m = np.broadcast_to(np.asarray(alt_m, float), lat_deg.shape)
    e, n, _ = pymap3d.geodetic2enu(lat_deg, lon_deg, alt_m, origin[0], origin[1], 0.0)
    return np.asarray(e, float), np.asarray(n, float)


def en_to_latlon(e_m, n_m, origin: tuple[float, float], u_m=0.0) -> tuple[np.ndarray, np.ndarray]:
    """Latitude and longitude (deg) of local east/north points (inverse of :func:`latlon_to_en`)."""
    e_m, n_m = np.asarray(e_m, float), np.asarray(n_m, float)
    u_m = np.broadcast_to(np.asarray(u_m, float), e_m.shape)
    lat, lon, _ = pymap3d.enu2geodetic(e_m, n_m, u_m, origin[0], origin[1], 0.0)
    return np.asarray(lat, float), np.asarray(lon, float)
