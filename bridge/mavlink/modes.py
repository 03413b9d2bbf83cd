"""Flight modes and parameter values in PX4's encoding (docs/ground-station.md): bytes, no sockets.

In:  the vehicle's mode (:mod:`bridge.autopilot.simvehicle`: offboard, hold, land, takeoff, failsafe, landed) and
     the target its on-board controller flies; DO_SET_MODE's parameters and SET_MODE's ``base_mode`` and
     ``custom_mode``; a parameter's value and MAVLink type
Out: HEARTBEAT's ``base_mode`` and ``custom_mode`` (PX4's: main mode in bits 16-23, sub mode in
     bits 24-31, px4_custom_mode.h), the mode a ground station asked for (or why not, or none), PARAM_VALUE's
     ``param_value`` float for a value and the value a PARAM_SET's float carries

With ``MAV_AUTOPILOT_PX4`` in the heartbeat, MAVProxy, MAVSDK and QGroundControl read
``custom_mode`` as PX4's and name the modes (OFFBOARD, HOLD — pymavlink calls it LOITER —, LAND,
TAKEOFF), and they encode INT32 parameters as PX4 does, byte for byte in the float
(``MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE``).
"""

from __future__ import annotations

import math
import struct
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

from bridge.autopilot.failsafe import Land, Level, PositionHold, ReturnHome, Takeoff, Target
from bridge.autopilot.modes import TERMINATION
from bridge.autopilot.simvehicle import FAILSAFE, HOLD, LAND, LANDED, OFFBOARD, RTL, TAKEOFF

MAIN_MANUAL = 1  # PX4_CUSTOM_MAIN_MODE_MANUAL: what PX4's get_px4_custom_mode gives NAVIGATION_STATE_TERMINATION
MAIN_POSCTL = 3  # PX4_CUSTOM_MAIN_MODE_POSCTL (not flown here: named when refused)
MAIN_AUTO = 4  # PX4_CUSTOM_MAIN_MODE_AUTO
MAIN_OFFBOARD = 6  # PX4_CUSTOM_MAIN_MODE_OFFBOARD
MAIN_STABILIZED = 7  # PX4_CUSTOM_MAIN_MODE_STABILIZED (not flown here: named when refused)
SUB_TAKEOFF, SUB_LOITER, SUB_MISSION, SUB_RTL, SUB_LAND = 2, 3, 4, 5, 6  # PX4_CUSTOM_SUB_MODE_AUTO_*
# AUTO.MISSION: a ground station's mission, flown by the offboard controller (bsst sitl --await-mission); shown,
# selected and started here, never a SimVehicle mode (bridge/nodes/vehicle/mission.py)
MISSION = "mission"
PX4_MODES = {  # the modes the vehicle flies: its name -> (main, sub) and the name a ground station shows
    OFFBOARD: (MAIN_OFFBOARD, 0),
    HOLD: (MAIN_AUTO, SUB_LOITER),
    LAND: (MAIN_AUTO, SUB_LAND),
    TAKEOFF: (MAIN_AUTO, SUB_TAKEOFF),
    MISSION: (MAIN_AUTO, SUB_MISSION),
    RTL: (MAIN_AUTO, SUB_RTL),
}
_BY_CODE = {code: mode for mode, code in PX4_MODES.items()}
# PX4's other modes by (main, sub), to name the one refused: px4_custom_mode.h
_PX4_NAMES = {(1, 0): "MANUAL", (2, 0): "ALTCTL", (3, 0): "POSCTL", (4, 1): "AUTO READY", (4, 4): "MISSION",
              (4, 7): "RTGS", (4, 8): "FOLLOW_TARGET", (4, 9): "PRECLAND", (5, 0): "ACRO",
              (7, 0): "STABILIZED", (8, 0): "RATTITUDE"}
# base_mode as PX4 sends it in these modes: custom mode, auto, guided, stabilized (29), and armed
BASE_MODE = (mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | mavlink.MAV_MODE_FLAG_AUTO_ENABLED
             | mavlink.MAV_MODE_FLAG_GUIDED_ENABLED | mavlink.MAV_MODE_FLAG_STABILIZE_ENABLED)


PARAM_TYPES = {"REAL32": mavlink.MAV_PARAM_TYPE_REAL32, "INT32": mavlink.MAV_PARAM_TYPE_INT32}  # ParamSpec.kind


def custom_mode(main: int, sub: int = 0) -> int:
    """PX4's ``custom_mode`` of a main and sub mode."""
    return (main << 16) | (sub << 24)


def shown_mode(mode: str, target: Target | None) -> str:
    """The mode a ground station is shown for the vehicle's ``mode`` and on-board ``target``: the
    failsafe flies as HOLD (a hold), RTL (a return) or LAND (land, descend), a landed vehicle shows LAND."""
    if mode in PX4_MODES:
        return mode
    if mode == FAILSAFE and isinstance(target, PositionHold):
        return HOLD
    if mode == FAILSAFE and isinstance(target, Takeoff):
        return TAKEOFF
    if mode == FAILSAFE and isinstance(target, ReturnHome):
        return RTL
    assert mode in (FAILSAFE, LANDED) and (target is None or isinstance(target, (Land, Level)))
    return LAND


def heartbeat_mode(mode: str, target: Target | None, armed: bool) -> tuple[int, int]:
    """HEARTBEAT's (``base_mode``, ``custom_mode``). In flight termination PX4 enables no controller (only
    CUSTOM_MODE_ENABLED in ``base_mode``) and names main mode MANUAL (mavlink streams/HEARTBEAT.hpp)."""
    armed_flag = mavlink.MAV_MODE_FLAG_SAFETY_ARMED if armed else 0
    if mode == TERMINATION:
        return mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | armed_flag, custom_mode(MAIN_MANUAL)
    return BASE_MODE | armed_flag, custom_mode(*PX4_MODES[shown_mode(mode, target)])


def mode_name(mode: str) -> str:
    """A vehicle mode's name as a ground station shows it."""
    return mode.upper()


def requested_mode(base: float, main: float, sub: float) -> tuple[str | None, str]:
    """The mode DO_SET_MODE asks for, read as PX4's commander reads it (Commander.cpp, handle_command's
    VEHICLE_CMD_DO_SET_MODE): with MAV_MODE_FLAG_CUSTOM_MODE_ENABLED in param1 (the base mode), param2 PX4's main mode
    and param3 its sub mode (AUTO with sub mode 0 is MISSION); without it, the base mode's flags
    (:func:`_base_mode_code`). Whole numbers. (mode, ""), (None, why not), or (None, ""): no mode asked (PX4
    answers ACCEPTED and changes nothing)."""
    nums = (base, main, sub)
    if not all(math.isfinite(v) and v == int(v) and 0 <= v <= 255 for v in nums):
        return None, "DO_SET_MODE: base, main and sub mode must be whole numbers in [0, 255]"
    if int(base) & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
        code: tuple[int, int] | None = (int(main), int(sub) if int(main) == MAIN_AUTO else 0)
    else:
        code = _base_mode_code(int(base))
    if code is None:
        return None, ""
    if code == (MAIN_AUTO, 0):  # PX4: AUTO without a sub mode is Mission
        code = (MAIN_AUTO, SUB_MISSION)
    mode = _BY_CODE.get(code)
    if mode is None:
        name = _PX4_NAMES.get(code, f"main {code[0]} sub {code[1]}")
        return None, f"mode {name}: not flown here; {', '.join(map(mode_name, PX4_MODES))} are flown here"
    return mode, ""


def _base_mode_code(base: int) -> tuple[int, int] | None:
    """The (main, sub) mode PX4 takes for a base mode without CUSTOM_MODE_ENABLED (its "use base mode" branch):
    AUTO_ENABLED, MISSION; else MANUAL_INPUT_ENABLED, POSCTL with GUIDED_ENABLED, STABILIZED with STABILIZE_ENABLED,
    else MANUAL; neither flag, None (no mode)."""
    if base & mavlink.MAV_MODE_FLAG_AUTO_ENABLED:
        return MAIN_AUTO, SUB_MISSION
    if not base & mavlink.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED:
        return None
    if base & mavlink.MAV_MODE_FLAG_GUIDED_ENABLED:
        return MAIN_POSCTL, 0
    return (MAIN_STABILIZED, 0) if base & mavlink.MAV_MODE_FLAG_STABILIZE_ENABLED else (MAIN_MANUAL, 0)


def requested_custom_mode(base: int, custom: int) -> tuple[str | None, str]:
    """The mode SET_MODE asks for (``base_mode``, ``custom_mode`` in PX4's encoding)."""
    return requested_mode(float(base), float((custom >> 16) & 0xFF), float((custom >> 24) & 0xFF))


def main_mode(custom: int) -> int:
    """PX4's main mode in a ``custom_mode``."""
    return (custom >> 16) & 0xFF


def shown_name(custom: int) -> str:
    """The name a ground station shows for a PX4 ``custom_mode``."""
    code = (main_mode(custom), (custom >> 24) & 0xFF if main_mode(custom) == MAIN_AUTO else 0)
    mode = _BY_CODE.get(code)
    return mode_name(mode) if mode else _PX4_NAMES.get(code, f"main {code[0]} sub {code[1]}")


def param_name(m: Any) -> str:
    """The parameter a PARAM_REQUEST_READ or PARAM_SET names (its ``param_id``, NULs stripped)."""
    return m.param_id.rstrip("\x00") if isinstance(m.param_id, str) else m.param_id.decode(errors="replace")


def param_to_wire(value: float, kind: int) -> float:
    """PARAM_VALUE's float for ``value`` of MAVLink type ``kind``: an INT32's bytes as they are
    (PX4's bytewise encoding), a REAL32 itself."""
    if kind == mavlink.MAV_PARAM_TYPE_INT32:
        return struct.unpack("<f", struct.pack("<i", int(value)))[0]
    return value


def param_from_wire(value: float, kind: int) -> float:
    """The value a PARAM_SET's float carries for MAVLink type ``kind``: an INT32 bytewise (PX4), or,
    when the float is a whole number itself (not a denormal or NaN pattern), cast (ArduPilot's way;
    the two never collide for the vehicle's INT32 ranges, -1..10 000 000: below 2^24, a value's bytes are
    a denormal or the least normal floats, never whole)."""
    if kind != mavlink.MAV_PARAM_TYPE_INT32:
        return value
    if math.isfinite(value) and value == int(value) and (abs(value) >= 1 or math.copysign(1.0, value) > 0):
        return float(value)  # (-0.0 is bytewise: INT32's -2147483648, 0x80000000)
    return float(struct.unpack("<i", struct.pack("<f", value))[0])
