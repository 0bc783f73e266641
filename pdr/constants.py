"""Physical constants and frame conventions, declared once.

Frames: local east-north-up (ENU); heading is yaw counter-clockwise from east, in radians.
Quaternions are named with their order (``q_wxyz``).
"""

GRAVITY_MPS2 = 9.80665  # standard gravity
EARTH_RADIUS_M = 6_378_137.0  # WGS-84 semi-major axis
