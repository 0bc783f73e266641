"""Physical constants and frame conventions, declared once.

Frames: local east-north-up (ENU); heading is yaw counter-clockwise from east, in radians.
Quaternions are named with their order (``q_wxyz``).
"""

GRAVITY_MPS2 = 9.80665  # standard gravity
EARTH_RADIUS_M = 6_378_137.0  # WGS-84 semi-major axis
REFERENCE_CADENCE_HZ = 110.0 / 60.0  # a normal adult cadence (100-120 steps/min)

# Gait from the trunk's vertical specific force (in g). Walking is an inverted pendulum: the trunk vaults over the
# stance leg and its vertical specific force bottoms out at g (1 - v^2 / (g L)), about 0.5 g at the walk-run
# transition (Froude number 0.5), a little less at the pelvis (its own excursion); a foot is always on the ground.
# Running is a bouncing spring-mass gait with a flight phase, where the body is in free fall and the specific force
# is near 0 g (soft tissue and low-pass filtering, or a 5th-order Fourier series, leave a trough of 0.1-0.3 g).
FLIGHT_MAX_SPECIFIC_FORCE_G = 0.25  # at or below: a flight phase (running)
WALK_MIN_SPECIFIC_FORCE_G = 0.40  # staying at or above over a step: walking
