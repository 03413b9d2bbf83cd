"""Whether a flight flown by the vehicle's own controller (a ground station's modes) has begun: the real-time
mission clock's start when no controller's target starts it (docs/weather.md, "A flight flown by a ground station
alone").

In:  the simulated vehicle (armed, its mode, its on-board controller's target: m, paper frame; its true height and
     its start's, m)
Out: :func:`flight_begun`: True once the vehicle, armed in a mode its own controller flies (HOLD, LAND, TAKEOFF,
     RTL), is sent up or is up: TAKEOFF; HOLD or RTL to a point more than :data:`AIRBORNE_M` above its start (a
     DO_REPOSITION, a return's climb); or more than :data:`AIRBORNE_M` above its start (any of them, in the air).
     False for an arm that leaves it on the ground (HOLD where it stands, LAND), or disarmed

As PX4: an arm is not a flight. PX4 stamps a flight's takeoff (vehicle_status.takeoff_time) when its land detector
sees it leave the ground, and disarms a vehicle armed and left on the ground (COM_DISARM_PRFLT) as one that never
flew; the flight starts here at the command that sends it up rather than at the lift-off it causes, as a
controller's flight starts at its first target (the spool-up and the climb are the flight's, as offline's).
"""

from __future__ import annotations

from bridge.autopilot.failsafe import PositionHold, ReturnHome
from bridge.autopilot.modes import GROUND_MODES, TAKEOFF
from bridge.autopilot.simvehicle import SimVehicle

# m above the start: off the ground for good, not the creep of a HOLD on the ground that holds an estimate's
# height (the EKF's start, gnss set: up to ~0.19 m)
AIRBORNE_M = 0.3


def flight_begun(sim: SimVehicle) -> bool:
    """Whether ``sim`` flies a flight of its own controller now (the module docstring)."""
    if not sim.armed or sim.mode not in GROUND_MODES:
        return False
    if sim.mode == TAKEOFF:
        return True
    ground = sim.home[2]  # the start's height (m)
    target = sim.onboard.target
    up = target.z if isinstance(target, PositionHold) else target.z_return if isinstance(target, ReturnHome) else None
    return sim.plant.state[4] - ground > AIRBORNE_M or (up is not None and up - ground > AIRBORNE_M)
