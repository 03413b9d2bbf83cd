"""MAV_CMD_DO_SET_MISSION_CURRENT (224), the command form of the deprecated MISSION_SET_CURRENT message, as PX4
answers it since its pull request 28105 (its navigator's ``VEHICLE_CMD_DO_SET_MISSION_CURRENT``, with
``Mission::set_current_mission_index``: docs/ground-station.md, "Missions", says which copies were read), for what
this vehicle flies.

In:  the command's param1 (the item's seq; -1: the current one) and param2 (MAV_BOOL: 1 resets the mission), from a
     sender with authority (:class:`~bridge.autopilot.vehicleevents.Sender`); the vehicle's mission
     (:class:`~bridge.nodes.vehicle.mission.MissionManager`)
Out: the MAV_RESULT and why it was refused (the commander's STATUSTEXT); when ACCEPTED the new current item (a
     ``mission`` event naming the sender) and MISSION_CURRENT, after the COMMAND_ACK in its datagram (MAVLink:
     "emit MISSION_CURRENT whether or not the mission number changed")

PX4: param1 not finite or below -1, or param2 other than 0 or 1: DENIED; an item not in the mission (none held, or
-1 with no current item): FAILED; else ACCEPTED, the item current (-1: unchanged) and, with param2 = 1, the DO_JUMP
counters and the mission's "finished" reset. Here as there, and as the vehicle answers MISSION_SET_CURRENT
(:mod:`.missiontransfer`): before the start (or once the mission's flight is over) the item is held and MISSION_CURRENT
says it (MISSION_START and AUTO.MISSION then start only from item 0: :meth:`MissionManager.start`); while the mission
is flown (started, or armed in OFFBOARD flying it) it is DENIED saying why, where PX4 jumps there: the offboard
controller flies the trajectory it planned from the whole mission. Ours too: a param1 that is not a whole number is
DENIED (PX4 truncates it), the offboard controller's (a reader of the mission, never its writer) is DENIED, and a
reset clears a COMPLETE mission state (MISSION_CURRENT says NOT_STARTED: nothing flies it until it is started again;
the vehicle keeps no DO_JUMP counters: a mission with DO_JUMP is not flown here).
"""

from __future__ import annotations

import math
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

from bridge.autopilot.vehicleevents import Sender
from bridge.nodes.vehicle.mission import MissionManager

NAME = "DO_SET_MISSION_CURRENT"
Result = tuple[int, str | None]  # (MAV_RESULT, why it was refused: a STATUSTEXT; None: not refused)


def bad_numbers(p1: float, p2: float) -> str | None:
    """Why param1 / param2 are not a DO_SET_MISSION_CURRENT's (None: they are)."""
    if not (math.isfinite(p1) and p1 >= -1 and p1 == int(p1)):
        return f"{NAME}: param1 (the item) must be a whole number, -1 (the current item) or more; got {p1:g}"
    if p2 not in (0.0, 1.0):
        return f"{NAME}: param2 (reset the mission) must be 0 or 1; got {p2:g}"
    return None


def set_current(missions: MissionManager, m: Any, by: Sender, reject: Any) -> tuple[Result, tuple[Any, ...]]:
    """DO_SET_MISSION_CURRENT ``m`` from ``by`` (module docstring): ((MAV_RESULT, why refused), MISSION_CURRENT when
    ACCEPTED). ``reject`` counts a bad number (``bad_number``)."""
    why = bad_numbers(m.param1, m.param2)
    if why is not None:
        reject("bad_number")
        return (mavlink.MAV_RESULT_DENIED, why), ()
    if by.link == "controller":
        return (mavlink.MAV_RESULT_DENIED, f"{NAME}: the controller reads the mission; a ground station sets it"), ()
    flown = missions.flown()
    if flown is not None:
        return (mavlink.MAV_RESULT_DENIED, f"{NAME}: {flown}"), ()
    mission = missions.mission
    n = len(mission.items)
    seq = mission.current if m.param1 == -1 else int(m.param1)
    if not 0 <= seq < n:
        return (mavlink.MAV_RESULT_FAILED, f"{NAME}: no mission held" if n == 0 else
                f"{NAME}: item {seq} is not in the mission (items 0 to {n - 1})"), ()
    missions.choose(by, seq, reset=m.param2 == 1.0, what=NAME)
    return (mavlink.MAV_RESULT_ACCEPTED, None), tuple(missions.current_message())
