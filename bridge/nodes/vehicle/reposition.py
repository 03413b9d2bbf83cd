"""A ground station's MAV_CMD_DO_REPOSITION as the point HOLD flies to (pure; docs/ground-station.md).

In:  the command (COMMAND_LONG: param5/param6 latitude/longitude in degrees, param7 altitude in m AMSL;
     COMMAND_INT: x/y in degE7 and z in m, AMSL in frame GLOBAL(_INT), above home in GLOBAL_RELATIVE_ALT(_INT));
     param2 its flags, param4 the heading (rad, clockwise from north, as PX4 reads it; NaN: as now); the home
     (deg, deg, m AMSL: the paper frame's origin); the vehicle's published state X (eq. 7, paper frame)
Out: :class:`Reposition`: the MAV_RESULT PX4 answers, the point (x, y, z m, paper frame: NWU about home),
     heading psi (rad, paper frame; None: keep turning as now) and ground speed (m/s; None: the on-board
     controller's) to hold, and why not (a STATUSTEXT's text)

As PX4 (``Commander::handle_command``, then its navigator): the command asks for AUTO.LOITER (HOLD) and only
that (param2 must be MAV_DO_REPOSITION_FLAGS_CHANGE_MODE, 1: anything else is UNSUPPORTED); a latitude and
longitude not given (NaN, or INT32_MAX in COMMAND_INT) keep the position now, an altitude not given the height
now, a heading not given the heading. HOLD flies there within the on-board controller's limits (2 m/s across,
1.5 m/s up, 1 m/s down; bridge.autopilot.failsafe.OnboardGains); a ground speed in param1 (> 0; -1: the
default) lowers the first, as PX4's cruise speed (a faster one is held to 2 m/s: the gains are tuned for it).
A point this plant cannot fly to is DENIED, saying why: below :data:`LOWEST_M` above home, or farther than
:data:`FARTHEST_M` from it (the plant's envelope is 100 m, plant.quadrotor.ENVELOPE_M).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

from controller.bsst import wrap_angle
from missions.geodetic import Home
from plant.quadrotor import ENVELOPE_M

LOWEST_M = 0.5  # m above home: the least height HOLD is sent to (MIS_TAKEOFF_ALT's least)
FARTHEST_M = ENVELOPE_M - 5.0  # m from home: room for HOLD's approach inside the plant's envelope
UNSET_INT = 2**31 - 1  # COMMAND_INT's x or y not given (MAVLink: INT32_MAX)
_AMSL = (mavlink.MAV_FRAME_GLOBAL, mavlink.MAV_FRAME_GLOBAL_INT)
_ABOVE_HOME = (mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT)


@dataclass(frozen=True)
class Reposition:
    """What a DO_REPOSITION comes to: its MAV_RESULT, the point and heading to hold, and why not."""

    result: int
    to: tuple[float, float, float] | None = None  # m, paper frame (x north, y west, z up about home)
    psi: float | None = None  # rad, paper frame (counter-clockwise from north); None: as now
    speed: float | None = None  # m/s across (param1 > 0: PX4's ground speed); None: the on-board controller's
    why: str | None = None


def _refused(result: int, why: str) -> Reposition:
    return Reposition(result, why=f"DO_REPOSITION: {why}")


def reposition(m: Any, home: Home, X: tuple[float, ...]) -> Reposition:
    """The point and heading ``m`` (a COMMAND_LONG or COMMAND_INT DO_REPOSITION) asks HOLD to fly to, from
    state X about ``home`` (the module's docstring), or why not."""
    if m.param2 != mavlink.MAV_DO_REPOSITION_FLAGS_CHANGE_MODE:
        return _refused(mavlink.MAV_RESULT_UNSUPPORTED, f"param2 (flags) must be "
                                                        f"{mavlink.MAV_DO_REPOSITION_FLAGS_CHANGE_MODE} "
                                                        f"(change mode), as PX4 takes it; got {m.param2:g}")
    up = 0.0  # the altitude's datum above home's (m)
    if m._type == "COMMAND_INT":
        if m.frame not in _AMSL + _ABOVE_HOME:
            return _refused(mavlink.MAV_RESULT_UNSUPPORTED, f"frame {m.frame}: only GLOBAL(_INT) (altitude AMSL) "
                                                            "and GLOBAL_RELATIVE_ALT(_INT) (above home)")
        given = m.x != UNSET_INT and m.y != UNSET_INT
        lat, lon, alt = m.x * 1e-7, m.y * 1e-7, m.z
        up = home.alt if m.frame in _ABOVE_HOME else 0.0
    else:
        lat, lon, alt = m.param5, m.param6, m.param7
        given = math.isfinite(lat) and math.isfinite(lon)
    if any(math.isinf(v) for v in (lat, lon, alt, m.param4)):
        return _refused(mavlink.MAV_RESULT_DENIED, "an infinite latitude, longitude, altitude or heading "
                                                   "(NaN leaves one as it is)")
    if given and not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
        return _refused(mavlink.MAV_RESULT_DENIED, f"latitude {lat:g}, longitude {lon:g}: not a place on earth")
    x, y, _ = home.paper(lat, lon, home.alt) if given else (X[0], X[2], 0.0)
    z = alt + up - home.alt if math.isfinite(alt) else X[4]
    if z < LOWEST_M:
        return _refused(mavlink.MAV_RESULT_DENIED, f"{z:.2f} m above home: must be at least {LOWEST_M:g} m")
    far = math.sqrt(x * x + y * y + z * z)
    if far > FARTHEST_M:
        return _refused(mavlink.MAV_RESULT_DENIED, f"{far:.1f} m from home: must be within {FARTHEST_M:g} m "
                                                   f"(the plant's envelope is {ENVELOPE_M:g} m)")
    psi = wrap_angle(-m.param4) if math.isfinite(m.param4) else None
    speed = float(m.param1) if math.isfinite(m.param1) and m.param1 > 0.0 else None
    return Reposition(mavlink.MAV_RESULT_ACCEPTED, (x, y, z), psi, speed)
