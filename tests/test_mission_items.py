"""Covers bridge.mavlink.missionitems: the commands PX4's mission item parser takes in each frame.

PX4's ``MavlinkMissionManager::parse_mavlink_mission_item`` (src/modules/mavlink/mavlink_mission.cpp, PX4-Autopilot
main at 001bb4d7) answers MAV_MISSION_UNSUPPORTED for a command it does not list in the item's frame; the vehicle's
parser answers the same (it once refused DO_WINCH, DO_GRIPPER, DO_SET_ACTUATOR, SET_CAMERA_SOURCE,
DO_AUTOTUNE_ENABLE and COMPONENT_ARM_DISARM, which PX4 takes, and took SET_CAMERA_ZOOM and DO_SET_SERVO, which it
refuses). Such an item is held as uploaded; whether it can be flown is the start's question (docs/missions.md).
"""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import common as M

from bridge.mavlink.missionitems import ItemRefused, parse_item

HOME = (473977420, 85455940)
MISSION_FRAME_TAKEN = ("DO_WINCH", "DO_GRIPPER", "DO_SET_ACTUATOR", "SET_CAMERA_SOURCE", "DO_AUTOTUNE_ENABLE",
                       "COMPONENT_ARM_DISARM", "DO_JUMP", "DO_CHANGE_SPEED", "NAV_RETURN_TO_LAUNCH")
GLOBAL_FRAME_TAKEN = ("COMPONENT_ARM_DISARM", "DO_AUTOTUNE_ENABLE", "NAV_WAYPOINT", "NAV_LOITER_UNLIM")


def _item(command: str, frame: int) -> object:
    x, y = (HOME if frame != M.MAV_FRAME_MISSION else (0, 0))
    return M.MAVLink_mission_item_int_message(1, 1, 1, frame, getattr(M, f"MAV_CMD_{command}"), 0, 1, 1.0, 0.0, 0.0,
                                              math.nan, x, y, 5.0, 0)


@pytest.mark.parametrize("command", MISSION_FRAME_TAKEN)
def test_px4s_mission_frame_commands_are_taken(command: str) -> None:
    assert parse_item(_item(command, M.MAV_FRAME_MISSION), True).command == getattr(M, f"MAV_CMD_{command}")


@pytest.mark.parametrize("command", GLOBAL_FRAME_TAKEN)
def test_px4s_global_frame_commands_are_taken(command: str) -> None:
    assert parse_item(_item(command, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT), True).x == HOME[0]


@pytest.mark.parametrize("command, frame", [("SET_CAMERA_ZOOM", M.MAV_FRAME_MISSION),
                                            ("DO_SET_SERVO", M.MAV_FRAME_MISSION),  # taken until 2026-12-06
                                            ("DO_WINCH", M.MAV_FRAME_GLOBAL_INT),
                                            ("NAV_SPLINE_WAYPOINT", M.MAV_FRAME_GLOBAL_INT)])
def test_what_px4s_parser_does_not_list_is_unsupported(command: str, frame: int) -> None:
    with pytest.raises(ItemRefused) as exc:
        parse_item(_item(command, frame), True)
    assert exc.value.result == M.MAV_MISSION_UNSUPPORTED
