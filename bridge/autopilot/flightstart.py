"""Whether a flight flown by the vehicle's own controller (a ground station's modes) has begun: the real-time
mission clock's start when no controller's target starts it (docs/weather.md, "A flight flown by a ground station
alone").

In:  the simulated vehicle (armed, its mode, its on-board controller's target: m, paper frame; its published
     height, its true height and its start's, m)
Out: :func:`flight_begun`: True once the vehicle, armed in a mode its own controller flies (HOLD, LAND, TAKEOFF,
     RTL), is sent up or is up: TAKEOFF; with ``engaged`` (just as a ground station's command gave the mode its
     target) HOLD or RTL to a point more than :data:`CLIMB_M` above where it knows itself to be (a DO_REPOSITION, a
     return's climb); in any of them, more than :data:`AIRBORNE_M` above its start. False for an arm that leaves it
     on the ground (HOLD where it stands, LAND), or disarmed

As PX4: an arm is not a flight. PX4 stamps a flight's takeoff (vehicle_status.takeoff_time) when its land detector
sees it leave the ground, and disarms a vehicle armed and left on the ground (COM_DISARM_PRFLT) as one that never
flew; the flight starts here at the command that sends it up rather than at the lift-off it causes, as a
controller's flight starts at its first target (the spool-up and the climb are the flight's, as offline's).
"""

from __future__ import annotations

from bridge.autopilot.failsafe import PositionHold, ReturnHome
from bridge.autopilot.modes import GROUND_MODES, TAKEOFF
from bridge.autopilot.simvehicle import SimVehicle

CLIMB_M = 0.3  # m: a target this far above the vehicle's published height sends it up (DO_REPOSITION: >= 0.5 m)
# m above the start: off the ground for good. A HOLD armed on the ground idles there (a landed HOLD,
# failsafe.LandedHold): an EKF's start height estimate above the ground (gnss set: up to 0.3 m) lifts it no more
AIRBORNE_M = 0.3


def flight_begun(sim: SimVehicle, engaged: bool = False) -> bool:
    """Whether ``sim`` flies a flight of its own controller now (the module docstring); ``engaged``: its mode's
    target was given just now (compared with the estimate then: an estimate on the ground drifts from a HOLD's
    target later, an EKF's settling from its start height, and a landed HOLD flies none of it)."""
    if not sim.armed or sim.mode not in GROUND_MODES:
        return False
    if sim.mode == TAKEOFF:
        return True
    target = sim.onboard.target
    up = target.z if isinstance(target, PositionHold) else target.z_return if isinstance(target, ReturnHome) else None
    if engaged and up is not None and up - sim.published()[4] > CLIMB_M:
        return True
    return sim.plant.state[4] - sim.home[2] > AIRBORNE_M  # (home: the start, m)
