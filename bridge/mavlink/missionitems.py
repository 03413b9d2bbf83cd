"""Mission items on the wire: MISSION_ITEM_INT / MISSION_ITEM to a typed :class:`MissionItem` and back,
checked as PX4's mission manager checks them (``parse_mavlink_mission_item``, mavlink_mission.cpp, PX4-Autopilot
main at 001bb4d7: its command lists).

In:  a MISSION_ITEM_INT (x, y: latitude, longitude in degE7; z m) or a legacy MISSION_ITEM (x, y in deg,
     float32) with its frame, command, param1..4 and autocontinue
Out: a :class:`MissionItem` (x, y as int degE7 in a global frame, the raw integers of param5 and param6 in
     ``MAV_FRAME_MISSION``; z m; params as sent) or the MAV_MISSION_RESULT PX4 answers the item with
     (:class:`ItemRefused`); the item as MISSION_ITEM_INT or MISSION_ITEM for a download; a held mission as
     a :class:`~missions.planfiles.PlanFile` (:func:`plan_of`, to be flown); a transfer's figures
     (:class:`TransferStats`: items, requests, requests again, wall time s, result)

What PX4 refuses, and with which result (its parser, then its mission-type check):

- a frame other than GLOBAL, GLOBAL_RELATIVE_ALT, their _INT forms (the _INT ones in a MISSION_ITEM_INT
  only) and MISSION: ``MAV_MISSION_UNSUPPORTED_FRAME``;
- a command PX4's parser does not know for the frame (:data:`GLOBAL_COMMANDS`, :data:`MISSION_COMMANDS`):
  ``MAV_MISSION_UNSUPPORTED``;
- NAV_ROI / DO_SET_ROI with a param1 (ROI mode) PX4 has no use for there: ``MAV_MISSION_INVALID_PARAM1``;
- a fence or rally command in a mission (PX4's "hardening against wrong client implementations"):
  ``MAV_MISSION_ERROR``.

Ours on top (PX4 leaves them to its feasibility checks at mission start): in a global frame a latitude
not finite or beyond +-90 deg is ``MAV_MISSION_INVALID_PARAM5_X``, a longitude beyond +-180 deg
``MAV_MISSION_INVALID_PARAM6_Y``, an altitude not finite ``MAV_MISSION_INVALID_PARAM7``; but a NAV_LAND's or
NAV_TAKEOFF's latitude and longitude both NaN (MISSION_ITEM) or both INT32_MAX (MISSION_ITEM_INT) are taken as not
given, land or take off where it is (PX4's parser keeps the NaN, its own land-here item is one, and its flight task
holds the position a setpoint without latitude and longitude finds), held as :data:`NOT_GIVEN` and sent back as
given. A NaN param1..4 is MAVLink's "use the default" (MAVSDK sends yaw NaN) and is kept.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

from missions.planfiles import PlanFile, plan_from_items

GLOBAL_FRAMES = frozenset({mavlink.MAV_FRAME_GLOBAL, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT})
GLOBAL_INT_FRAMES = frozenset({mavlink.MAV_FRAME_GLOBAL_INT, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT})
# a global frame's float form, for a legacy (float) download
FLOAT_FRAME = {mavlink.MAV_FRAME_GLOBAL_INT: mavlink.MAV_FRAME_GLOBAL,
               mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT: mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT}
_C = mavlink
# the commands PX4's parser takes in a global frame (they have a position) ...
GLOBAL_COMMANDS = frozenset({
    _C.MAV_CMD_NAV_WAYPOINT, _C.MAV_CMD_NAV_LOITER_UNLIM, _C.MAV_CMD_NAV_LOITER_TIME, _C.MAV_CMD_NAV_LAND,
    _C.MAV_CMD_NAV_TAKEOFF, _C.MAV_CMD_NAV_LOITER_TO_ALT, _C.MAV_CMD_NAV_ROI, _C.MAV_CMD_DO_SET_ROI,
    _C.MAV_CMD_DO_SET_ROI_LOCATION, _C.MAV_CMD_NAV_VTOL_TAKEOFF, _C.MAV_CMD_NAV_VTOL_LAND, _C.MAV_CMD_CONDITION_GATE,
    _C.MAV_CMD_NAV_FENCE_RETURN_POINT, _C.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION,
    _C.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION, _C.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION,
    _C.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION, _C.MAV_CMD_NAV_RALLY_POINT, _C.MAV_CMD_COMPONENT_ARM_DISARM,
    _C.MAV_CMD_DO_AUTOTUNE_ENABLE})
# ... and in MAV_FRAME_MISSION (no position: param5..7 are plain parameters)
MISSION_COMMANDS = frozenset({
    _C.MAV_CMD_DO_JUMP, _C.MAV_CMD_NAV_ROI, _C.MAV_CMD_DO_SET_ROI, _C.MAV_CMD_DO_CHANGE_SPEED, _C.MAV_CMD_DO_SET_HOME,
    _C.MAV_CMD_DO_LAND_START, _C.MAV_CMD_DO_TRIGGER_CONTROL, _C.MAV_CMD_DO_DIGICAM_CONTROL,
    _C.MAV_CMD_DO_MOUNT_CONFIGURE, _C.MAV_CMD_DO_MOUNT_CONTROL, _C.MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW,
    _C.MAV_CMD_SET_CAMERA_FOCUS, _C.MAV_CMD_DO_GIMBAL_MANAGER_CONFIGURE, _C.MAV_CMD_IMAGE_START_CAPTURE,
    _C.MAV_CMD_IMAGE_STOP_CAPTURE, _C.MAV_CMD_VIDEO_START_CAPTURE, _C.MAV_CMD_VIDEO_STOP_CAPTURE,
    _C.MAV_CMD_DO_CONTROL_VIDEO, _C.MAV_CMD_DO_SET_CAM_TRIGG_DIST, _C.MAV_CMD_OBLIQUE_SURVEY,
    _C.MAV_CMD_DO_SET_CAM_TRIGG_INTERVAL, _C.MAV_CMD_SET_CAMERA_MODE, _C.MAV_CMD_SET_CAMERA_SOURCE,
    _C.MAV_CMD_DO_VTOL_TRANSITION, _C.MAV_CMD_NAV_DELAY, _C.MAV_CMD_NAV_RETURN_TO_LAUNCH,
    _C.MAV_CMD_DO_SET_ROI_WPNEXT_OFFSET, _C.MAV_CMD_DO_SET_ROI_NONE, _C.MAV_CMD_CONDITION_DELAY,
    _C.MAV_CMD_CONDITION_DISTANCE, _C.MAV_CMD_DO_WINCH, _C.MAV_CMD_DO_GRIPPER, _C.MAV_CMD_DO_SET_ACTUATOR,
    _C.MAV_CMD_DO_AUTOTUNE_ENABLE, _C.MAV_CMD_COMPONENT_ARM_DISARM})
# PX4 refuses these in a mission (they are a fence's or rally points')
NOT_IN_MISSION = frozenset({
    _C.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION, _C.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION,
    _C.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, _C.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION, _C.MAV_CMD_NAV_RALLY_POINT})
_ROI = frozenset({_C.MAV_CMD_NAV_ROI, _C.MAV_CMD_DO_SET_ROI})
ROI_MODES_GLOBAL = frozenset({_C.MAV_ROI_LOCATION, _C.MAV_ROI_NONE})
ROI_MODES_MISSION = frozenset({_C.MAV_ROI_NONE, _C.MAV_ROI_WPNEXT, _C.MAV_ROI_WPINDEX})
DEG_E7 = 1e7
INT32_MAX = 2**31 - 1  # a MISSION_ITEM_INT's x or y not given (MAVLink: "optional"), a MISSION_ITEM's NaN
NOT_GIVEN = (INT32_MAX, INT32_MAX)  # a MissionItem's x, y of a NAV_LAND or NAV_TAKEOFF with no position: here
HERE_COMMANDS = frozenset({_C.MAV_CMD_NAV_LAND, _C.MAV_CMD_NAV_TAKEOFF})  # those that may have no position: here


def _roi_mode(p1: float) -> int:
    """NAV_ROI / DO_SET_ROI's param1 (a MAV_ROI) as PX4's ``(int)`` cast reads it; -1 when not a number."""
    return int(p1) if math.isfinite(p1) else -1


class ItemRefused(ValueError):
    """A mission item PX4 would refuse: its MAV_MISSION_RESULT and why, in words."""

    def __init__(self, result: int, why: str) -> None:
        super().__init__(why)
        self.result = result


@dataclass(frozen=True)
class MissionItem:
    """One accepted mission item. In a global frame x, y are latitude and longitude (degE7) and z the
    altitude (m, AMSL or above home by the frame); in MAV_FRAME_MISSION they are param5..7."""

    seq: int
    frame: int
    command: int
    param1: float
    param2: float
    param3: float
    param4: float
    x: int
    y: int
    z: float
    autocontinue: int

    @property
    def global_frame(self) -> bool:
        return self.frame != mavlink.MAV_FRAME_MISSION

    @property
    def lat_deg(self) -> float:
        return self.x / DEG_E7

    @property
    def lon_deg(self) -> float:
        return self.y / DEG_E7


def _whole(v: float, lo: int, hi: int, result: int, what: str) -> int:
    """A legacy item's float x or y as the int MISSION_ITEM_INT would carry, or refused with ``result``."""
    if not math.isfinite(v) or not lo <= round(v) <= hi:
        raise ItemRefused(result, f"{what} {v!r} is not a number in [{lo}, {hi}]")
    return round(v)


def item_position(m: Any, int_mode: bool) -> tuple[int, int]:
    """x, y of a global-frame item as degE7, checked (latitude within +-90, longitude within +-180 deg)."""
    if int_mode:
        x, y = int(m.x), int(m.y)
    else:  # legacy MISSION_ITEM: degrees as float32
        x = _whole(m.x * DEG_E7, -900_000_000, 900_000_000, mavlink.MAV_MISSION_INVALID_PARAM5_X, "latitude")
        y = _whole(m.y * DEG_E7, -1_800_000_000, 1_800_000_000, mavlink.MAV_MISSION_INVALID_PARAM6_Y, "longitude")
    if not -900_000_000 <= x <= 900_000_000:
        raise ItemRefused(mavlink.MAV_MISSION_INVALID_PARAM5_X, f"latitude {x / DEG_E7} deg beyond +-90")
    if not -1_800_000_000 <= y <= 1_800_000_000:
        raise ItemRefused(mavlink.MAV_MISSION_INVALID_PARAM6_Y, f"longitude {y / DEG_E7} deg beyond +-180")
    return x, y


def _here(m: Any, int_mode: bool) -> bool:
    """Whether ``m`` is a NAV_LAND or NAV_TAKEOFF with no latitude and longitude: both NaN (a MISSION_ITEM's, PX4's
    own land-here item, ``MissionBlock::set_land_item``: "descend at current position"; MAVSDK's and scripts'
    takeoffs, which PX4's ``FlightTaskAuto`` flies over the position it holds: "No position provided in xy. Lock
    position") or both INT32_MAX (a MISSION_ITEM_INT's: MAVLink's "optional" for an integer). One of the two alone
    is refused as any other bad position."""
    if m.command not in HERE_COMMANDS:
        return False
    if int_mode:
        return int(m.x) == int(m.y) == INT32_MAX
    return math.isnan(m.x) and math.isnan(m.y)


def parse_item(m: Any, int_mode: bool) -> MissionItem:
    """The :class:`MissionItem` of a MISSION_ITEM_INT (``int_mode``) or MISSION_ITEM, or :class:`ItemRefused`
    with PX4's result (module docstring)."""
    frame, command = m.frame, m.command
    if frame in GLOBAL_FRAMES or (int_mode and frame in GLOBAL_INT_FRAMES):
        if command not in GLOBAL_COMMANDS:
            raise ItemRefused(mavlink.MAV_MISSION_UNSUPPORTED, f"command {command} unsupported in frame {frame}")
        if command in _ROI and _roi_mode(m.param1) not in ROI_MODES_GLOBAL:
            raise ItemRefused(mavlink.MAV_MISSION_INVALID_PARAM1, f"ROI mode {m.param1} unsupported here")
        x, y = NOT_GIVEN if _here(m, int_mode) else item_position(m, int_mode)
        if not math.isfinite(m.z):
            raise ItemRefused(mavlink.MAV_MISSION_INVALID_PARAM7, f"altitude {m.z} is not a number")
    elif frame == mavlink.MAV_FRAME_MISSION:
        if command not in MISSION_COMMANDS:
            raise ItemRefused(mavlink.MAV_MISSION_UNSUPPORTED, f"command {command} unsupported in frame {frame}")
        if command in _ROI and _roi_mode(m.param1) not in ROI_MODES_MISSION:
            raise ItemRefused(mavlink.MAV_MISSION_INVALID_PARAM1, f"ROI mode {m.param1} unsupported here")
        big = 2**31 - 1
        x = int(m.x) if int_mode else _whole(m.x, -big, big, mavlink.MAV_MISSION_INVALID_PARAM5_X, "param5")
        y = int(m.y) if int_mode else _whole(m.y, -big, big, mavlink.MAV_MISSION_INVALID_PARAM6_Y, "param6")
    else:
        raise ItemRefused(mavlink.MAV_MISSION_UNSUPPORTED_FRAME, f"frame {frame} unsupported")
    if command in NOT_IN_MISSION:
        raise ItemRefused(mavlink.MAV_MISSION_ERROR, f"command {command} is a fence's or rally point's")
    return MissionItem(m.seq, frame, command, m.param1, m.param2, m.param3, m.param4, x, y, m.z, m.autocontinue)


def item_message(item: MissionItem, target: tuple[int, int], current: bool, int_mode: bool,
                 mission_type: int = mavlink.MAV_MISSION_TYPE_MISSION) -> Any:
    """``item`` as MISSION_ITEM_INT (``int_mode``) or MISSION_ITEM (x, y in deg, a global _INT frame as
    its float form) to ``target`` (sysid, compid), ``current`` set on the mission's current item; of
    ``mission_type`` (a mission's, a fence's or rally points')."""
    args = (*target, item.seq)
    params = (item.param1, item.param2, item.param3, item.param4)
    if int_mode:
        return mavlink.MAVLink_mission_item_int_message(*args, item.frame, item.command, int(current),
                                                        item.autocontinue, *params, item.x, item.y, item.z,
                                                        mission_type)
    x, y = _degrees(item)
    return mavlink.MAVLink_mission_item_message(*args, FLOAT_FRAME.get(item.frame, item.frame), item.command,
                                                int(current), item.autocontinue, *params, x, y, item.z, mission_type)


def _degrees(item: MissionItem) -> tuple[float, float]:
    """x, y as a MISSION_ITEM and a plan carry them: degrees in a global frame (NaN, NaN for a land-here's
    or take-off-here's :data:`NOT_GIVEN`), param5 and param6 as they are in MAV_FRAME_MISSION."""
    if not item.global_frame:
        return float(item.x), float(item.y)
    if (item.x, item.y) == NOT_GIVEN and item.command in HERE_COMMANDS:
        return math.nan, math.nan
    return item.x / DEG_E7, item.y / DEG_E7


@dataclass
class TransferStats:
    """One transfer's figures (an upload on the vehicle, a download by the controller): its items, the
    requests sent (first and again), the requests sent again, its wall time (s) and result (``accepted``,
    ``timeout``, ``refused item N``, ``cancelled``, ...; "" while it runs)."""

    items: int = 0
    requests: int = 0
    re_requests: int = 0
    duration_s: float = 0.0
    result: str = ""

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def plan_of(items: tuple[MissionItem, ...], home: tuple[float, float, float], source: str, geo_fence: Any = None,
            rally: Any = None) -> PlanFile:
    """A held mission as a plan to fly, about ``home`` (deg, deg, m AMSL): checked as a plan file's items
    are (:func:`missions.planfiles.plan_from_items`: a :class:`params.ConfigError` naming the item); with the
    held fence and rally points as a plan's ``geoFence`` and ``rallyPoints`` (bridge.mavlink.fenceitems)."""
    rows = []
    for it in items:
        rows.append((it.seq, it.command, it.frame, (it.param1, it.param2, it.param3, it.param4, *_degrees(it), it.z),
                     it.autocontinue))
    return plan_from_items(source, home, rows, geo_fence, rally)
