"""The fence and rally points a ground station uploads over the mission protocol (MAV_MISSION_TYPE_FENCE, _RALLY):
held, read as a plan file's are, the rally points given to the vehicle's Return, the fence watched in flight.

In:  an accepted upload's or a clear's items (:mod:`bridge.nodes.vehicle.missiontransfer`), the home (deg, deg,
     m AMSL), what the controller's download of the fence or the rally points sends
Out: the items held of each type (a download sends them; before any upload, the mission's own fence and rally
     points); the vehicle's rally points (``SimVehicle.rally``, m,
     the paper frame: an upload or a clear replaces the mission's own) and the fence it watches
     (:meth:`SimVehicle.watch_fence`: its first breach a ``geofence`` event, which fails the run's ``geofence``
     policy, bridge.record.policies); why an upload cannot be read as a fence or rally points (None: held);
     those the run's record holds (:attr:`HeldZones.recorded`) and whether it holds the fence watched
     (``SimVehicle.fence_recorded``: decided here alone, the vehicle's checks read it)

As PX4's navigator judges a position against its stored fence (missions.geofence: inside an inclusion zone if
there is one, outside every exclusion zone); the vehicle acts on a breach by GF_ACTION (bridge.autopilot.fencewatch:
Hold, PX4's default) and says where it left the fence, as it does for a plan's fence (docs/missions.md).
"""

from __future__ import annotations

from pymavlink.dialects.v20 import common as mavlink

from bridge.autopilot.simvehicle import SimVehicle
from bridge.mavlink.fenceitems import fence_items, fence_plan, rally_items, rally_plan
from bridge.nodes.vehicle.missiontransfer import Mission
from missions.envelope import ENVELOPE_RADIUS_M
from missions.geodetic import Home
from missions.geofence import geofence_from_plan
from missions.rally import rally_from_plan
from params import ConfigError

FENCE, RALLY = mavlink.MAV_MISSION_TYPE_FENCE, mavlink.MAV_MISSION_TYPE_RALLY


class HeldZones:
    """One vehicle's uploaded fence and rally points."""

    def __init__(self, sim: SimVehicle, home: tuple[float, float, float]) -> None:
        self.sim = sim
        self.home = Home(*home)
        # what it holds from the start: the mission's own fence and rally points, as a ground station downloads them
        self.items = {FENCE: Mission(fence_items(sim.fence, self.home)),
                      RALLY: Mission(rally_items(sim.rally, self.home))}
        # those the run's record (its mission.toml) holds: the mission's own, or the controller's download's
        # (--await-mission); those flown are said at a flight's arm if not these (MissionManager.flight_armed)
        self.recorded = dict(self.items)

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
            self.sim.watch_fence(fence)  # (None: no zones, or only a return point)
            self._fence_recorded()
        else:
            self.sim.rally = rally
        return None

    def downloaded(self, mission_type: int, sending: Mission) -> None:
        """The controller's download of the fence or the rally points (begun, or begun again) sends ``sending``:
        what its mission.toml holds, the record's."""
        self.recorded[mission_type] = sending
        self._fence_recorded()

    def _fence_recorded(self) -> None:
        """The one place that says whether the run's record holds the fence the vehicle watches: while it is the
        one held (an upload after the controller's download is not; GF_ACTION 0 still judges that one)."""
        self.sim.fence_recorded = self.recorded[FENCE] is self.items[FENCE]
