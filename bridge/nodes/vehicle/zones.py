"""The fence and rally points a ground station uploads over the mission protocol (MAV_MISSION_TYPE_FENCE, _RALLY):
held, read as a plan file's are, the rally points given to the vehicle's Return, the fence watched in flight.

In:  an accepted upload's or a clear's items (:mod:`bridge.nodes.vehicle.missiontransfer`), the home (deg, deg,
     m AMSL); the plant's time (s) and state (paper frame: x, y m at indices 0 and 2) after each control step
Out: the items held of each type (a download sends them); the vehicle's rally points (``SimVehicle.rally``, m,
     the paper frame: an upload or a clear replaces the mission's own); a ``geofence`` event the first time the
     vehicle is outside an uploaded fence (the run's ``geofence`` policy then fails, bridge.record.policies);
     why an upload cannot be read as a fence or rally points (None: held)

As PX4's navigator judges a position against its stored fence (missions.geofence: inside an inclusion zone if
there is one, outside every exclusion zone), checked here, not enforced: PX4 would act on a breach (GF_ACTION),
this vehicle flies on and says where it left the fence, as it does for a plan's fence (docs/missions.md).
"""

from __future__ import annotations

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

from bridge.autopilot.simvehicle import SimVehicle
from bridge.mavlink.fenceitems import fence_plan, rally_plan
from bridge.nodes.vehicle.missiontransfer import Mission
from missions.envelope import ENVELOPE_RADIUS_M
from missions.geodetic import Home
from missions.geofence import Geofence, geofence_from_plan
from missions.rally import rally_from_plan
from params import ConfigError

FENCE, RALLY = mavlink.MAV_MISSION_TYPE_FENCE, mavlink.MAV_MISSION_TYPE_RALLY


class HeldZones:
    """One vehicle's uploaded fence and rally points."""

    def __init__(self, sim: SimVehicle, home: tuple[float, float, float]) -> None:
        self.sim = sim
        self.home = Home(*home)
        self.items = {FENCE: Mission(), RALLY: Mission()}
        self.fence: Geofence | None = None  # the uploaded fence read (None: none, or only a return point)
        self._left = False  # the vehicle was outside the fence held now (said once per fence)

    def accept(self, mission: Mission, mission_type: int) -> str | None:
        """Hold an upload's (or a clear's: no items) fence or rally points, read as a plan's are; why they cannot
        be read (nothing held then: the vehicle keeps what it had), or None."""
        try:
            if mission_type == FENCE:
                fence = geofence_from_plan(fence_plan(mission.items), self.home, "the uploaded fence")
            else:
                rally = rally_from_plan(rally_plan(mission.items), self.home, "the uploaded rally points",
                                        ENVELOPE_RADIUS_M)
        except (ValueError, ConfigError) as exc:
            return str(exc)
        self.items[mission_type] = mission
        if mission_type == FENCE:
            self.fence, self._left = fence, False
        else:
            self.sim.rally = rally
        return None

    def step(self, t: float, X: tuple[float, ...]) -> None:
        """After a control step at plant time ``t`` (s) in state ``X``: the first time the vehicle is outside the
        fence held, a ``geofence`` event says where."""
        if self.fence is None or self._left:
            return
        breach = self.fence.first_breach(np.array((t,)), np.array((X[0],)), np.array((X[2],)))
        if breach is not None:
            self._left = True
            self.sim.event("geofence", f"outside the uploaded fence: {breach[1]} (checked, not enforced: PX4 "
                                       "would act on it, GF_ACTION)")
