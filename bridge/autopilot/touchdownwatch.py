"""An armed vehicle that was airborne and comes down onto the ground in a landing nobody asked for: a ``touchdown``.

In:  after each control period, the plant (true state: height m above the ground plane, velocity m/s; time s),
     whether the vehicle is armed in OFFBOARD, and the mission's reference height (m) at the period's start
     (a function of mission time s; None: not known, e.g. real time before the mission starts)
Out: the ``touchdown`` event's text, once per touchdown (:meth:`TouchdownWatch.judge`); the run's ``touchdown``
     policy (:mod:`bridge.record.policies`) breaks on it: not flown as asked, exit 1 (docs/weather.md "Outcomes")

A touchdown softer than ``CRASH_SPEED_MPS`` is no crash (:mod:`bridge.autopilot.impactwatch`), and the flight
goes on; but a vehicle that sat down mid-mission under offboard control did not fly the mission. It is judged
only armed in OFFBOARD (the mission's end landing, LAND, RTL, TAKEOFF, HOLD and every failsafe fly in their
own modes: landings it was asked to make), only once it has been airborne (higher than :data:`AIRBORNE_M`
since it last rested: a takeoff from the ground that has not yet left it is none), and only while the
reference is above :data:`REF_GROUND_M` (a ground-hugging reference, or a trajectory that lands, asks for
the ground). Judged at the end of each control period (a vehicle resting on the ground then); the reference is
sampled only then, for a vehicle come to rest from the air. The batch engine does not judge it (its rows' policies
are not judged).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from plant import Quadrotor

AIRBORNE_M = 0.05  # m above the ground: higher, the vehicle has left it
REF_GROUND_M = 0.05  # m: a reference this low (or lower) asks for the ground: touching it is no touchdown


def touched(z: float, vz: float, airborne: bool, judged: bool) -> tuple[bool, bool]:
    """(come to rest from the air while judged, airborne after this period) from the true height ``z`` and ``vz``
    (resting: z <= 0 and vz <= 0, ``Quadrotor.on_ground``), whether the vehicle was ``airborne`` and whether it is
    ``judged`` (armed in OFFBOARD). A touchdown if, besides, the reference is up (:meth:`TouchdownWatch.judge`)."""
    if z > AIRBORNE_M:
        return False, True
    if z > 0.0 or vz > 0.0:
        return False, airborne
    return airborne and judged, False


@dataclass
class TouchdownWatch:
    """One vehicle's touchdowns: whether it is airborne now."""

    airborne: bool = False
    speed: float = 0.0  # m/s: the true speed at the last period's end (a touchdown's state rests: speed 0)

    def judge(self, plant: Quadrotor, judged: bool, reference_z: Callable[[float], float] | None,
              t0: float | None, period_s: float) -> str | None:
        """After a control period of ``period_s`` (s): the ``touchdown`` event's text, or None. ``judged``: armed in
        OFFBOARD; ``reference_z``: the reference height (m) at a mission time (s; None: unknown), read at the
        period's start; ``t0``: the plant time of the mission's time 0 (None: not started)."""
        t, X = plant.t, plant.state
        rested, self.airborne = touched(X[4], X[5], self.airborne, judged)
        before, self.speed = self.speed, math.sqrt(X[1] * X[1] + X[3] * X[3] + X[5] * X[5])
        if not rested or reference_z is None or t0 is None:
            return None
        ref_z = reference_z(t - period_s - t0)  # sampled only here: the controller samples it every step already
        if ref_z <= REF_GROUND_M:
            return None
        return (f"touched down armed in OFFBOARD by t={t:.3f} s at {before:.2f} m/s (a control period before), "
                f"x={X[0]:.3f} y={X[2]:.3f} m, the reference {ref_z:.3f} m up: not a landing it was asked to make")
