"""The walking simulator: body kinematics (``gait``), the route, sensors (IMU, magnetometer, barometer, GNSS) and
``simulate`` / ``simulate_to_disk`` (scenario files in ``configs/sim/``; keys in :mod:`pdr.sim.simulator`)."""

from pdr.sim.gait import WalkKinematics
from pdr.sim.people import Body, GaitUser, plan_walk
from pdr.sim.route import Route
from pdr.sim.simulator import build_walk, parse_scenario, simulate, simulate_to_disk

__all__ = ["Body", "GaitUser", "Route", "WalkKinematics", "build_walk", "parse_scenario", "plan_walk", "simulate",
           "simulate_to_disk"]
