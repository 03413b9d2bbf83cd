"""The vehicle's parameters, by PX4's names (docs/ground-station.md, "Parameters").

In:  a parameter's name and value (a float: MAVLink's PARAM_VALUE carries every value as one; an
     INT32's as the integer), the settings they act on (:class:`VehicleParams`: the ``[failsafe]``
     table's numbers, s and m/s, the takeoff altitude m, the MAVLink system id), a mission's
     ``[params]`` table (NAME = value) and ``--param NAME=VALUE`` flags
Out: the parameter list (:data:`PARAMS`: name, type, unit, range, meaning), a value read
     (:func:`read_param`), a change checked and made (:func:`change_param`, or :class:`ParamRefused`
     saying why, and what kind of refusal it is: :class:`Refusal`), the ``[failsafe]`` keys a ``[params]``
     table stands for (:func:`params_as_failsafe`), a value as MAVLink's float32 carries it (:func:`float32`),
     scheduled changes as the ``--param-at`` flags that give them to a child process (:func:`param_at_args`)

Each parameter is one of the vehicle's settings under PX4's name where PX4 has that setting, with
the one range the setting has everywhere (``[failsafe]``'s :data:`~bridge.autopilot.failsafe.FAILSAFE_RANGES`
for the failsafe's numbers), so a mission file, a flag and a ground station's PARAM_SET are checked
alike. The two offboard-loss action parameters are one setting, ``[failsafe] action``, under PX4's
old name (``COM_OBL_ACT``, PX4 1.13 and earlier: 0 Land, 1 Hold, 3 Terminate) and its current one
(``COM_OBL_RC_ACT``, PX4 1.14 on: 4 Land, 5 Hold, 7 Disarm); ``descend``, which PX4 does not have,
is -1 in both. PX4's values that the vehicle cannot fly (Return, Position, ...) are refused; two entries naming that
one setting with different actions, in one ``[params]`` table or in the flags, are refused too.
``MAV_SYS_ID`` takes effect when the vehicle starts (``--param``, ``[params]``); a ground station's
PARAM_SET of it is refused, as it could not act until a restart that SITL does not do.

An INT32 is an integer however it is written: a finite whole float (``1e6``, ``1000000.0``, a PARAM_SET's C cast)
is taken as it, from a file, a flag, Python or the wire alike (:func:`typed_value`, :func:`value_problem`).

A value that came over MAVLink is a float32: the documented minimum COM_OF_LOSS_T, 0.01 s, arrives as
0.0099999998. The range check (:func:`in_range`) therefore takes a value that rounds to a bound in
float32 as that bound, and the change sets the bound itself.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, replace
from enum import Enum
from typing import Any

from bridge.autopilot.failsafe import FAILSAFE_RANGES, FailsafeConfig
from bridge.autopilot.positionloss import NOAID_TIMEOUT_RANGE_US, NOAID_TIMEOUT_US
from bridge.autopilot.returnland import LAND_RANGES, RETURN_RANGES, ReturnConfig
from params import ConfigError, Table, finite_float, show
from params.text import meant_hint, number, quoted, shown_name, whole

REAL32 = "REAL32"
INT32 = "INT32"
PREFLIGHT_DISARM_RANGE_S = (-1.0, 600.0)  # COM_DISARM_PRFLT: PX4 gives no bounds; -1 (any value <= 0) is off
LAND_DISARM_RANGE_S = (-1.0, 20.0)  # COM_DISARM_LAND: PX4 1.14 gives no bounds (<= 0 is off), earlier ones -1..20 s
TAKEOFF_ALT_RANGE_M = (0.5, 50.0)  # MIS_TAKEOFF_ALT: inside the plant's 100 m envelope; PX4: 0..80 m
GF_MAX_HOR_RANGE_M = (0.0, 10000.0)  # GF_MAX_HOR_DIST: PX4's range; 0 is off
GF_MAX_VER_RANGE_M = (0.0, 1000.0)  # GF_MAX_VER_DIST: PX4's range; 0 is off
# PX4's battery levels (fractions of the charge) and their ranges: BAT_LOW_THR, BAT_CRIT_THR, BAT_EMERGEN_THR
BAT_LOW_RANGE, BAT_CRIT_RANGE, BAT_EMERGEN_RANGE = (0.12, 0.5), (0.05, 0.25), (0.03, 0.1)
SYSID_RANGE = (1, 254)  # MAV_SYS_ID and --sysid (0 is broadcast, 255 a ground station's by custom)


@dataclass(frozen=True)
class VehicleParams:
    """The settings the parameters read and change."""

    failsafe: FailsafeConfig = FailsafeConfig()
    takeoff_alt_m: float = 2.5  # m above home: NAV_TAKEOFF's altitude when it gives none (PX4's default)
    sysid: int = 1
    failure_injection: int = 0  # SYS_FAILURE_EN: 1 acts on MAV_CMD_INJECT_FAILURE, 0 denies it (PX4's default)
    rtl: ReturnConfig = ReturnConfig()  # RTL_*, NAV_ACC_RAD: Return mode's heights above home (m) and its cone
    preflight_disarm_s: float = 10.0  # COM_DISARM_PRFLT: armed on the ground, disarmed if not started by then (s)
    max_hor_m: float = 0.0  # GF_MAX_HOR_DIST: the farthest from home (m, horizontally) the vehicle may fly; 0: any
    max_ver_m: float = 0.0  # GF_MAX_VER_DIST: the highest above home (m) it may fly; 0: any
    fence_action: int = 2  # GF_ACTION: what the vehicle does beyond a limit or outside a fence (PX4's default: Hold)
    battery_low: float = 0.15  # BAT_LOW_THR: the charge left (0..1) below which the battery is low (a warning)
    battery_critical: float = 0.07  # BAT_CRIT_THR: critical (COM_LOW_BAT_ACT acts; arming denied below it)
    battery_emergency: float = 0.05  # BAT_EMERGEN_THR: emergency (COM_LOW_BAT_ACT 3 lands)
    low_battery_action: int = 0  # COM_LOW_BAT_ACT: 0 warning (PX4's default), 2 land, 3 return then land
    noaid_timeout_us: int = NOAID_TIMEOUT_US  # EKF2_NOAID_TOUT: unaided this long (us), the position is invalid
    land_disarm_s: float = 2.0  # COM_DISARM_LAND: landed this long (s) after an auto landing, it disarms; <= 0 never


@dataclass(frozen=True)
class ParamSpec:
    """One parameter: its name (at most 16 characters: PARAM_VALUE's ``param_id``), MAVLink type,
    unit, range [lo, hi] (an INT32's ``choices``: the values allowed and what each means), what it
    is, and the ``[failsafe]`` key it stands for (None: another setting)."""

    name: str
    kind: str
    unit: str
    lo: float
    hi: float
    meaning: str
    failsafe_key: str | None = None
    choices: Mapping[int, str] | None = None
    at_start_only: bool = False


# GF_ACTION's values (PX4's geofence_result GF_ACTION_*): what the vehicle does at a breach
FENCE_ACTIONS = {0: "none", 1: "warning", 2: "hold", 3: "return", 4: "terminate", 5: "land"}
# COM_LOW_BAT_ACT's values (PX4 1.14's): what the vehicle does at the battery's critical and emergency levels
LOW_BATTERY_ACTIONS = {0: "warning", 2: "land", 3: "return at critical, land at emergency"}
# PX4's offboard-loss action values, old and new, of the actions the vehicle flies
_OBL_ACT = {-1: "descend", 0: "land", 1: "hold", 2: "return", 3: "disarm"}
_OBL_RC_ACT = {-1: "descend", 3: "return", 4: "land", 5: "hold", 7: "disarm"}
_fr, _lr = FAILSAFE_RANGES, LAND_RANGES
PARAMS: tuple[ParamSpec, ...] = (
    ParamSpec("COM_OF_LOSS_T", REAL32, "s", *_fr["timeout_s"],
              "offboard loss timeout: no actuator target for this long and the failsafe acts "
              "([failsafe] timeout_s)", failsafe_key="timeout_s"),
    ParamSpec("COM_OBL_ACT", INT32, "", -1, 3,
              "offboard loss action, PX4 1.13 values: -1 descend, 0 land, 1 hold, 2 return, 3 terminate (disarm) "
              "([failsafe] action)", failsafe_key="action", choices=_OBL_ACT),
    ParamSpec("COM_OBL_RC_ACT", INT32, "", -1, 7,
              "offboard loss action, PX4 1.14 values: -1 descend, 3 return, 4 land, 5 hold, 7 disarm "
              "([failsafe] action)", failsafe_key="action", choices=_OBL_RC_ACT),
    ParamSpec("COM_FAIL_ACT_T", REAL32, "s", *_fr["hold_s"],
              "hold failsafe: how long it holds before it lands ([failsafe] hold_s)", failsafe_key="hold_s"),
    ParamSpec("MPC_LAND_SPEED", REAL32, "m/s", *_fr["descent_rate"],
              "descent speed of the failsafe's landing and of LAND ([failsafe] descent_rate); below MPC_LAND_ALT2 "
              "the auto landing's (LAND, Return, the failsafe's land, hold and return)", failsafe_key="descent_rate"),
    ParamSpec("MPC_Z_V_AUTO_DN", REAL32, "m/s", *_lr["auto_down_mps"],
              "the auto landing's descent speed above MPC_LAND_ALT1 (blending to MPC_LAND_SPEED at MPC_LAND_ALT2)"),
    ParamSpec("MPC_LAND_ALT1", REAL32, "m", *_lr["alt1_m"],
              "the auto landing slows from MPC_Z_V_AUTO_DN below this height above home (taken as at least "
              "MPC_LAND_ALT2)"),
    ParamSpec("MPC_LAND_ALT2", REAL32, "m", *_lr["alt2_m"],
              "the auto landing comes down at MPC_LAND_SPEED below this height above home"),
    ParamSpec("MIS_TAKEOFF_ALT", REAL32, "m", *TAKEOFF_ALT_RANGE_M,
              "takeoff altitude above home when NAV_TAKEOFF gives none, and the least it climbs to"),
    ParamSpec("MAV_SYS_ID", INT32, "", *SYSID_RANGE, "the vehicle's MAVLink system id (at start only)",
              at_start_only=True),
    ParamSpec("RTL_RETURN_ALT", REAL32, "m", *RETURN_RANGES["return_alt_m"],
              "Return mode: the height above home it climbs to (if lower) before it flies home"),
    ParamSpec("RTL_DESCEND_ALT", REAL32, "m", *RETURN_RANGES["descend_alt_m"],
              "Return mode: the height above home it comes down to over home before it lands"),
    ParamSpec("RTL_CONE_ANG", INT32, "deg", *RETURN_RANGES["cone_deg"],
              "Return mode: half-angle of the cone over home within RTL_MIN_DIST of which it returns lower than "
              "RTL_RETURN_ALT (0: no cone)"),
    ParamSpec("RTL_MIN_DIST", REAL32, "m", *RETURN_RANGES["min_dist_m"],
              "Return mode: within this horizontal distance of home the cone sets the return height"),
    ParamSpec("NAV_ACC_RAD", REAL32, "m", *RETURN_RANGES["acc_rad_m"],
              "acceptance radius: Return within it of home returns at most 2 x the distance up, beyond it at least "
              "2 x NAV_ACC_RAD (with the cone)"),
    ParamSpec("SYS_FAILURE_EN", INT32, "", 0, 1,
              "failure injection: 1 acts on a ground station's MAV_CMD_INJECT_FAILURE, 0 denies it (docs/weather.md)",
              choices={0: "disabled", 1: "enabled"}),
    ParamSpec("COM_DISARM_PRFLT", REAL32, "s", *PREFLIGHT_DISARM_RANGE_S,
              "armed on the ground by a ground station and not started within this time, the vehicle disarms "
              "itself (PX4's pre-takeoff timeout, default 10 s; 0 or less: never; docs/missions.md)"),
    ParamSpec("GF_MAX_HOR_DIST", REAL32, "m", *GF_MAX_HOR_RANGE_M,
              "geofence: the farthest from home the vehicle may fly, horizontally (0: no limit); beyond it the vehicle "
              "acts by GF_ACTION and the run's geofence policy fails"),
    ParamSpec("GF_MAX_VER_DIST", REAL32, "m", *GF_MAX_VER_RANGE_M,
              "geofence: the highest above home the vehicle may fly (0: no limit); above it the vehicle acts by "
              "GF_ACTION and the run's geofence policy fails"),
    ParamSpec("GF_ACTION", INT32, "", 0, 5,
              "geofence action, PX4's values: 0 none (not watched), 1 warning, 2 hold (PX4's default), 3 return, "
              "4 terminate (motors off), 5 land; 2-5 are the vehicle's failsafe (docs/missions.md)",
              choices=FENCE_ACTIONS),
    ParamSpec("BAT_LOW_THR", REAL32, "", *BAT_LOW_RANGE,
              "battery low level: below this share of its charge a warning (a battery event; docs/weather.md)"),
    ParamSpec("BAT_CRIT_THR", REAL32, "", *BAT_CRIT_RANGE,
              "battery critical level: below it COM_LOW_BAT_ACT acts, and arming is denied"),
    ParamSpec("BAT_EMERGEN_THR", REAL32, "", *BAT_EMERGEN_RANGE,
              "battery emergency level: below it COM_LOW_BAT_ACT 3 lands"),
    ParamSpec("COM_LOW_BAT_ACT", INT32, "", 0, 3,
              "low battery action, PX4's values: 0 warning (PX4's default), 2 land at critical, 3 return at critical "
              "and land at emergency; 2 and 3 are the vehicle's failsafe (docs/weather.md)",
              choices=LOW_BATTERY_ACTIONS),
    ParamSpec("EKF2_NOAID_TOUT", INT32, "us", *NOAID_TIMEOUT_RANGE_US,
              "maximum inertial dead-reckoning time: no position fix fused for this long, the estimate's horizontal "
              "position is invalid and the vehicle's failsafe descends (PX4's; docs/sensors.md)"),
    ParamSpec("COM_DISARM_LAND", REAL32, "s", *LAND_DISARM_RANGE_S,
              "auto-disarm after landing: on the ground this long after the vehicle's own landing (LAND, Return, the "
              "mission's end, a failsafe's), motors idle, it disarms (PX4's default 2 s; 0 or less: never)"),
)
BY_NAME = {p.name: p for p in PARAMS}
_RTL_FIELDS = {"RTL_RETURN_ALT": "return_alt_m", "RTL_DESCEND_ALT": "descend_alt_m",  # -> ReturnConfig's field
               "RTL_CONE_ANG": "cone_deg", "RTL_MIN_DIST": "min_dist_m", "NAV_ACC_RAD": "acc_rad_m"}
_LAND_FIELDS = {"MPC_Z_V_AUTO_DN": "auto_down_mps", "MPC_LAND_ALT1": "alt1_m",  # -> FailsafeConfig.slowdown's field
                "MPC_LAND_ALT2": "alt2_m"}
# the REAL32 parameters that are one field of VehicleParams each
_FIELDS = {"COM_DISARM_PRFLT": "preflight_disarm_s", "GF_MAX_HOR_DIST": "max_hor_m", "GF_MAX_VER_DIST": "max_ver_m",
           "MIS_TAKEOFF_ALT": "takeoff_alt_m", "BAT_LOW_THR": "battery_low", "BAT_CRIT_THR": "battery_critical",
           "BAT_EMERGEN_THR": "battery_emergency", "COM_DISARM_LAND": "land_disarm_s"}
_INT_FIELDS = {"SYS_FAILURE_EN": "failure_injection", "GF_ACTION": "fence_action",  # the INT32s that are one field
               "COM_LOW_BAT_ACT": "low_battery_action", "EKF2_NOAID_TOUT": "noaid_timeout_us"}


class Refusal(Enum):
    """Why a parameter change is not made, as a ground station is told it (PARAM_ERROR's code:
    :mod:`bridge.nodes.vehicle.paramservice`)."""

    VALUE = "value"  # out of the parameter's range, not one of its choices, not a number of its type
    READ_ONLY = "read_only"  # acts at start only (MAV_SYS_ID)
    UNKNOWN = "unknown"  # no such parameter
    TYPE = "type"  # the set says another MAVLink type than the parameter's
    TYPE_UNSUPPORTED = "type_unsupported"  # the set says a MAVLink type no parameter here has (not INT32, REAL32)


class ParamRefused(ValueError):
    """A parameter change that is not made; the message, ``NAME: what``, says why (it goes out in a STATUSTEXT),
    ``what`` the reason alone, ``why`` what kind of refusal it is (:class:`Refusal`)."""

    def __init__(self, name: str, what: str, why: Refusal = Refusal.VALUE) -> None:
        super().__init__(f"{name}: {what}")
        self.name, self.what, self.why = name, what, why


def read_param(p: VehicleParams, name: str) -> float:
    """The value of parameter ``name`` (a float; an INT32's integer value)."""
    spec = BY_NAME[name]
    if spec.failsafe_key == "action":
        return float(next(v for v, a in (spec.choices or {}).items() if a == p.failsafe.action))
    if spec.failsafe_key is not None:
        return float(getattr(p.failsafe, spec.failsafe_key))
    if name in _INT_FIELDS:
        return float(getattr(p, _INT_FIELDS[name]))
    if name in _FIELDS:
        return float(getattr(p, _FIELDS[name]))
    if name in _RTL_FIELDS:
        return float(getattr(p.rtl, _RTL_FIELDS[name]))
    if name in _LAND_FIELDS:
        return float(getattr(p.failsafe.slowdown, _LAND_FIELDS[name]))
    return float(p.sysid)


def float32(x: float) -> float | None:
    """``x`` rounded to float32 (what a MAVLink float carries: PARAM_SET's and PARAM_VALUE's ``param_value``), or
    None if it is beyond float32's range. The one such rounding of the scalar code (the batch engine's compiled
    twin: ``bridge.batch.wire``)."""
    try:  # (an int is made a float first: struct refuses a big int with its own error, not OverflowError)
        return struct.unpack("<f", struct.pack("<f", float(x)))[0]
    except OverflowError:
        return None


def in_range(value: float, lo: float, hi: float) -> bool:
    """Whether ``value`` is in [lo, hi], counting one that rounds to a bound in float32 as that bound (a
    value that crossed MAVLink: 0.01 arrives as 0.0099999998)."""
    if lo <= value <= hi:
        return True
    f = float32(value)
    return f is not None and f in (float32(lo), float32(hi))


def typed_value(spec: ParamSpec, value: Any) -> float:
    """``value`` as ``spec``'s type, checked (:func:`value_problem`): an INT32's an ``int`` (a finite whole float is
    taken as that integer: PARAM_VALUE, Python callers, ``1e6`` in a TOML file or a flag), a REAL32's a number;
    :class:`ParamRefused` if it is not one, or not one the parameter takes."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ParamRefused(spec.name, f"expected a number, got {value!r}"[:198 - len(spec.name)])
    why = _value_why(spec, value)
    if why:
        raise ParamRefused(spec.name, why)
    return int(value) if spec.kind == INT32 else value


def value_problem(spec: ParamSpec, value: float) -> str | None:
    """Why ``value`` cannot be ``spec``'s, or None (type, range, choices; :func:`in_range`): the one check of a
    value, from a file, a flag, Python or the wire: ``NAME: why``."""
    why = _value_why(spec, value)
    return None if why is None else f"{spec.name}: {why}"


def _value_why(spec: ParamSpec, value: float) -> str | None:
    """:func:`value_problem`'s reason alone."""
    if isinstance(value, int) and finite_float(value) is None:  # past the float range: isfinite would raise
        return f"{_range_text(spec)}, got {show(value)}"
    if spec.kind == INT32 and not (math.isfinite(value) and value == int(value)):  # 1.5, nan, inf
        return f"an INT32, expected an integer {_allowed(spec)}, got {shown_value(value)}"
    if not math.isfinite(value):
        return f"must be finite, got {value}"
    if spec.choices is not None and int(value) not in spec.choices:
        return f"{shown_value(value)} is not one the vehicle flies; allowed: {_choices(spec.choices)}"
    if not in_range(value, spec.lo, spec.hi):
        return f"{_range_text(spec)}, got {shown_value(value)}"
    return None


def shown_value(value: float) -> str:
    """``value`` in a refusal or a ``param`` event: an integer whole, else in as few digits as tell it apart in float32
    (a bound's neighbour as 10000001 or 20.000001, never 1e+07 or 20; a wire value as 25.3, not 25.2999992371)."""
    if isinstance(value, int) or (math.isfinite(value) and value == int(value) and abs(value) < 1e16):
        return str(int(value))
    for digits in (6, 9):
        text = f"{value:.{digits}g}"
        if float32(float(text)) == float32(value):
            return text
    return f"{value:.17g}"


def _range_text(spec: ParamSpec) -> str:
    """``must be in [0.01, 60] s``: the parameter's range, as every refusal of a value out of it says."""
    return f"must be in {_bounds(spec)}"


def _bounds(spec: ParamSpec) -> str:
    """``[0.01, 60] s``: the parameter's range and unit."""
    return f"[{spec.lo:.12g}, {spec.hi:.12g}]" + (f" {spec.unit}" if spec.unit else "")  # (not 1e+07)


def _choices(choices: Mapping[int, str]) -> str:
    """``-1 descend, 0 land, ...``: an INT32's values and what each means."""
    return ", ".join(f"{v} {a}" for v, a in choices.items())


def _allowed(spec: ParamSpec) -> str:
    """What an INT32 takes, after "an integer": ``in [1, 254]``, or its choices in brackets."""
    return f"({_choices(spec.choices)})" if spec.choices is not None else f"in {_bounds(spec)}"


def change_param(p: VehicleParams, name: str, value: float, running: bool = True) -> VehicleParams:
    """``p`` with parameter ``name`` set to ``value``; :class:`ParamRefused` if it cannot be (an
    unknown name, a value out of range or of the wrong type, or, ``running``, one that acts only at start)."""
    spec = BY_NAME.get(name)
    if spec is None:
        raise ParamRefused(name, "no such parameter", Refusal.UNKNOWN)
    why = _value_why(spec, value)
    if why:
        raise ParamRefused(name, why)
    if running and spec.at_start_only:
        raise ParamRefused(name, f"takes effect at start only (--param {name}=N)", Refusal.READ_ONLY)
    value = min(max(value, spec.lo), spec.hi)  # one that rounds to a bound in float32 is that bound (in_range)
    if spec.failsafe_key == "action":
        return replace(p, failsafe=replace(p.failsafe, action=(spec.choices or {})[int(value)]))
    if spec.failsafe_key is not None:
        return replace(p, failsafe=replace(p.failsafe, **{spec.failsafe_key: float(value)}))
    if name in _FIELDS:
        return replace(p, **{_FIELDS[name]: float(value)})
    if name in _INT_FIELDS:
        return replace(p, **{_INT_FIELDS[name]: int(value)})
    if name in _RTL_FIELDS:
        typed = int(value) if spec.kind == INT32 else float(value)
        return replace(p, rtl=replace(p.rtl, **{_RTL_FIELDS[name]: typed}))
    if name in _LAND_FIELDS:
        slowdown = replace(p.failsafe.slowdown, **{_LAND_FIELDS[name]: float(value)})
        return replace(p, failsafe=replace(p.failsafe, slowdown=slowdown))
    return replace(p, sysid=int(value))


def no_such_param(name: object) -> str:
    """Why ``name`` is refused at start (``[params]``, ``--param``, ``Mission(params=...)``, ``params=``): no such
    parameter, and what it likely meant, as an unknown key of a table says (:func:`params.text.meant_hint`): the
    vehicle's parameter in another case or one slip away (``com_of_loss_t``: did you mean 'COM_OF_LOSS_T'?), or
    where a PX4 name that is no vehicle parameter goes (a plan's ``MPC_XY_CRUISE``); else every parameter the vehicle
    has. (A ground station's PARAM_SET is told no such parameter alone: :func:`change_param`.)"""
    return f"no such parameter{meant_hint(str(name), BY_NAME) or '; the vehicle has ' + ', '.join(BY_NAME)}"


def params_from_table(data: Mapping[str, Any], source: str, start: VehicleParams) -> VehicleParams:
    """A ``[params]`` table (NAME = value) applied over ``start``, each value checked with its
    parameter's one range; names the file and the key (``params.NAME``) of a bad one, and both keys of
    two that set one setting to different values."""
    t = Table(data, source, "params")
    entries = []
    for name in data:
        spec = BY_NAME.get(name)
        if spec is None:
            raise t.error(name, no_such_param(name))
        v = data[name]  # an integer past the float range goes on as it is: apply_params names the range
        huge = isinstance(v, int) and not isinstance(v, bool) and finite_float(v) is None
        if spec.kind == INT32 and isinstance(v, float):  # 1e6 or 1000000.0: typed_value takes a finite whole one
            entries.append((name, t.raw(name)))
        else:
            entries.append((name, t.number(name) if spec.kind == REAL32 and not huge else t.integer(name)))
    t.done()
    return apply_params(start, entries, f"{source}: ", lambda name, value: f"params.{name}")


def apply_params(start: VehicleParams, entries: Iterable[tuple[str, Any]], prefix: str,
                 where: Callable[[str, Any], str]) -> VehicleParams:
    """Parameters at start (``[params]``, ``--param``), in order, over ``start``: each a known name with a
    value of its type in its range, and no two naming one setting (COM_OBL_ACT, COM_OBL_RC_ACT) with
    different values. ConfigError ``prefix`` + ``where(name, value)`` (the entry: a file's key, a flag)
    + why; a clash names both entries."""
    p = start
    by_setting: dict[str, tuple[str, Any]] = {}  # [failsafe] key -> the entry that set it
    for name, value in entries:
        spec = BY_NAME.get(name)
        try:
            if spec is None:
                raise ParamRefused(name, no_such_param(name), Refusal.UNKNOWN)
            after = change_param(p, name, typed_value(spec, value), running=False)
        except ParamRefused as exc:
            raise ConfigError(f"{prefix}{where(name, value)}: {exc.what}") from None
        key = spec.failsafe_key
        if key is not None:
            other = by_setting.get(key)
            was, now = getattr(p.failsafe, key), getattr(after.failsafe, key)
            if other is not None and other[0] != name and was != now:
                raise ConfigError(f"{prefix}{where(name, value)} and {where(*other)} set one setting, [failsafe] "
                                  f"{key}, two ways ({now}, {was}): give one of them")
            by_setting[key] = (name, value)
        p = after
    return p


def params_as_failsafe(data: Mapping[str, Any]) -> dict[str, str]:
    """The ``[failsafe]`` keys the parameters of a ``[params]`` table stand for: key -> parameter name."""
    return {BY_NAME[n].failsafe_key: n for n in data if n in BY_NAME and BY_NAME[n].failsafe_key}  # type: ignore[misc]


def parse_assignment(text: str) -> tuple[str, float]:
    """``NAME=VALUE`` (``--param``) as (name, value), the value parsed as the parameter's type (an INT32's
    as an integer, or as a number, ``1e6``, that :func:`value_problem` then takes only if it is a finite whole one;
    a REAL32's as a number); ConfigError saying what is wrong."""
    name, sep, value = text.partition("=")
    name = name.strip()
    if not sep or not name:
        raise ConfigError(f"expected NAME=VALUE, got {quoted(text)}")
    spec = BY_NAME.get(name)
    if spec is None:
        raise ConfigError(f"{shown_name(name)}: {no_such_param(name)}")
    for parse in ((whole, number) if spec.kind == INT32 else (number,)):
        try:
            got = parse(value)
        except ValueError:
            continue
        if isinstance(got, float) and math.isinf(got) and value.strip().lstrip("+-").lower() not in ("inf", "infinity"):
            raise ConfigError(f"{name}: {_range_text(spec)}, got {_past_float(value)}")  # so past float32's too
        return name, got
    what = f"an INT32, expected an integer {_allowed(spec)}" if spec.kind == INT32 else "a REAL32, expected a number"
    raise ConfigError(f"{name}: {what}, got {value.strip()!r}"[:300])


def _past_float(text: str) -> str:
    """A number's text that ``float()`` took past its range (``inf``): ``an integer of 4400 digits`` (over Python's
    limit of digits for ``int()``, or an INT32 no float holds: as :func:`params.show` says a shorter one), or the text
    as given (``1e400``: a number ``float()`` read), cut to 40 characters."""
    digits = text.strip().lstrip("+-").replace("_", "")
    return f"an integer of {len(digits)} digits" if digits.isdigit() else text.strip()[:40]


@dataclass(frozen=True, order=True)
class ParamChange:
    """A parameter set at a mission time (``--param-at T:NAME=VALUE``): it takes effect at the start of
    the control step that begins at or after ``t_s`` (s), in every clock the same step."""

    t_s: float
    name: str
    value: float

    def step(self, rate_hz: float) -> int:
        """The control step it takes effect at."""
        return math.ceil(self.t_s * rate_hz - 1e-9)


def check_param_changes(changes: Any, duration_s: float) -> tuple[ParamChange, ...]:
    """Scheduled changes, checked (a known parameter that may change while running, its value of its type
    and in range, a time inside the mission), each value as its parameter's type (:func:`typed_value`),
    in time order: two at one time in the order given (the last given wins); ConfigError naming the bad one."""
    out = []
    for c in changes:
        where = f"--param-at {c.t_s:g}:{c.name}={c.value!r}"
        if not (math.isfinite(c.t_s) and 0.0 <= c.t_s < duration_s):
            raise ConfigError(f"{where}: the time must be in [0, {duration_s:g}) s (the mission's duration)")
        try:
            spec = BY_NAME.get(c.name)
            value = c.value if spec is None else typed_value(spec, c.value)
            change_param(VehicleParams(), c.name, value)
        except ParamRefused as exc:
            raise ConfigError(f"{where}: {exc}") from None
        out.append(replace(c, value=value))
    return tuple(sorted(out, key=lambda c: c.t_s))  # stable: one time's changes keep the order given


def parse_change(text: str) -> ParamChange:
    """``T:NAME=VALUE`` (``--param-at``) as a :class:`ParamChange`; ConfigError saying what is wrong."""
    t, sep, rest = text.partition(":")
    if not sep:
        raise ConfigError(f"expected T:NAME=VALUE (T in s of mission time), got {quoted(text)}")
    try:
        t_s = float(t)
    except ValueError:
        raise ConfigError(f"expected T:NAME=VALUE, T a number of seconds, got {quoted(t.strip())}") from None
    name, value = parse_assignment(rest)
    return ParamChange(t_s, name, value)


def param_at_args(changes: tuple[ParamChange, ...]) -> list[str]:
    """``changes`` as ``--param-at T:NAME=VALUE`` flags, each read back by :func:`parse_change` to itself (repr:
    exact)."""
    return [a for c in changes for a in ("--param-at", f"{c.t_s!r}:{c.name}={c.value!r}")]
