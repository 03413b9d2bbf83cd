"""A ground station's MAV_CMD_INJECT_FAILURE as the events of the timeline it stands for (pure; docs/weather.md).

In:  the command's param1 (failure unit, MAVLink's FAILURE_UNIT), param2 (FAILURE_TYPE) and param3 (instance:
     a motor's number 1-4, 0 for all; a sensor's 0 or 1), floats as they came; the plant time now (s); why an
     event of a kind cannot act on this vehicle (:func:`bridge.core.weather.event_problem`, bound to it)
Out: :class:`Injection`: the MAV_RESULT PX4 answers, the :class:`~plant.events.TimedEvent` s to act on
     (ACCEPTED), and why it was not (a STATUSTEXT's text; None when accepted)

What maps: a motor OFF is ``motor:N=0``, OK ``motor:N=1``; GPS and compass OFF/OK are ``gps:off``/``gps:on``,
``mag:off``/``mag:on``; the battery's (instance 0) ``battery:empty``/``battery:ok``, as PX4's BatterySimulator
reads its pack empty. Any other type of those units is UNSUPPORTED (PX4 takes some of them, which change only
telemetry not simulated here: docs/weather.md). The barometer's and gyro's faults here are a drift and a bias
whose size the command has no field for (the mission's events, ``--at T:baro:drift=R``, ``gyro:bias=X,Y,Z``):
UNSUPPORTED, as is every other unit. An OK of a unit that works is acted on as nothing
(bridge.autopilot.timeline.changes_nothing). A number that is not a whole one in range (a motor the vehicle does
not have) is DENIED.
SYS_FAILURE_EN = 0 (the default) is the handler's own DENIED, before any of this.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from pymavlink.dialects.v20 import common as mavlink

from bridge.mavlink.receive import whole
from plant.events import TimedEvent

MOTORS = 4
_TYPES = {mavlink.FAILURE_TYPE_OK: "OK", mavlink.FAILURE_TYPE_OFF: "OFF"}
_SENSORS = {mavlink.FAILURE_UNIT_SENSOR_GPS: "gps", mavlink.FAILURE_UNIT_SENSOR_MAG: "mag"}
_SIZED = {mavlink.FAILURE_UNIT_SENSOR_BARO: "baro:drift=M_PER_S", mavlink.FAILURE_UNIT_SENSOR_GYRO: "gyro:bias=X,Y,Z"}


@dataclass(frozen=True)
class Injection:
    """What an INJECT_FAILURE comes to: its MAV_RESULT, the events it acts on, and why not (None: accepted)."""

    result: int
    events: tuple[TimedEvent, ...] = ()
    why: str | None = None


def _name(enum: str, value: int) -> str:
    entry = mavlink.enums[enum].get(value)
    return entry.name if entry is not None else f"{enum} {value}"


def injection(p1: float, p2: float, p3: float, t_s: float, problem: Callable[[str], str | None]) -> Injection:
    """The events ``INJECT_FAILURE(p1 unit, p2 type, p3 instance)`` acts on at ``t_s``, or why not;
    ``problem(kind)`` says why an event of ``kind`` cannot act on this vehicle (None: it can)."""
    unit, ftype, instance = whole(p1, 0, 255), whole(p2, 0, 255), whole(p3, 0, 255)
    if unit is None or ftype is None or instance is None:
        return Injection(mavlink.MAV_RESULT_DENIED, why=f"INJECT_FAILURE: unit, type and instance must be whole "
                                                        f"numbers, got {p1:g}, {p2:g}, {p3:g}")
    what = f"INJECT_FAILURE {_name('FAILURE_UNIT', unit)} {_name('FAILURE_TYPE', ftype)}"
    if unit == mavlink.FAILURE_UNIT_SYSTEM_MOTOR:
        kind, lo_hi = "motor", (0, MOTORS)
    elif unit in _SENSORS:
        kind, lo_hi = _SENSORS[unit], (0, 1)
    elif unit == mavlink.FAILURE_UNIT_SYSTEM_BATTERY:
        kind, lo_hi = "battery", (0, 0)
    elif unit in _SIZED:
        return Injection(mavlink.MAV_RESULT_UNSUPPORTED, why=f"{what}: its fault here has a size this command has "
                                                             f"no field for: give it in the mission's [[events]] "
                                                             f"(bsst sim/sitl: --at T:{_SIZED[unit]})")
    else:
        return Injection(mavlink.MAV_RESULT_UNSUPPORTED, why=f"{what}: not a unit the vehicle simulates")
    if ftype not in _TYPES:
        return Injection(mavlink.MAV_RESULT_UNSUPPORTED, why=f"{what}: only OK and OFF are supported")
    if kind == "battery" and instance != 0:  # PX4's BatterySimulator: UNSUPPORTED
        return Injection(mavlink.MAV_RESULT_UNSUPPORTED, why=f"{what}: instance {instance}: the vehicle has one "
                                                             "pack, instance 0")
    if not lo_hi[0] <= instance <= lo_hi[1]:
        has = "motors 1-4 (0: all)" if kind == "motor" else "one (0 or 1)"
        return Injection(mavlink.MAV_RESULT_DENIED, why=f"{what}: instance {instance}: the vehicle has {has}")
    why = problem(kind)
    if why is not None:
        return Injection(mavlink.MAV_RESULT_UNSUPPORTED, why=f"{what}: {why}")
    off = ftype == mavlink.FAILURE_TYPE_OFF
    if kind == "motor":
        motors = range(1, MOTORS + 1) if instance == 0 else (instance,)
        events = tuple(TimedEvent(t_s, "motor", (("motor", n), ("effectiveness", 0.0 if off else 1.0)))
                       for n in motors)
    elif kind == "battery":  # PX4's BatterySimulator: OFF reads the pack empty, OK as it is
        events = (TimedEvent(t_s, kind, (("state", "empty" if off else "ok"),)),)
    else:
        events = (TimedEvent(t_s, kind, (("state", "off" if off else "on"),)),)
    return Injection(mavlink.MAV_RESULT_ACCEPTED, events)
