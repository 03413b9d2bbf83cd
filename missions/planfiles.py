"""Mission files of the ground stations: QGroundControl ``.plan`` (JSON) and ``QGC WPL 110`` text.

In:  a file's text and its name (for messages); the file is read by :mod:`params` (missions are pure)
Out: a :class:`PlanFile`: the home (lat, lon deg, alt m AMSL), the multicopter cruise speed (m/s) the
     file gives, and its :class:`Item` s (MAVLink MAV_CMD, MAV_FRAME, param1..4, lat, lon deg, alt m);
     anything we do not fly raises :class:`params.ConfigError` naming the file, the item's index and its
     command (name and number)

``.plan`` follows QGroundControl's documented schema (docs.qgroundcontrol.com, "Plan File Format"):
``fileType`` "Plan", ``version`` 1, ``mission`` {``version`` 2, ``firmwareType``, ``vehicleType``,
``cruiseSpeed``, ``hoverSpeed``, ``plannedHomePosition`` [lat, lon, alt AMSL], ``items``}, ``geoFence``,
``rallyPoints``. An item is a ``SimpleItem`` {``command``, ``frame``, ``params`` [7], ``autoContinue``,
``doJumpId``, ...} (QGC writes NaN as null) or a ``ComplexItem`` (survey, corridor scan, structure scan),
which is refused. A ``QGC WPL 110`` file (mavlink.io, "File Formats") is a header line, then one line per
item: index, current, frame, command, param1..4, x/lat, y/lon, z/alt, autocontinue; line 0 is the home,
as QGroundControl and MAVProxy write it. A ``.plan``'s geofence is read (:mod:`missions.geofence`: checked over
the run, held by the vehicle, which acts on a breach by GF_ACTION); its rally points are where Return may land
(:mod:`missions.rally`).
"""

from __future__ import annotations

import difflib
import json
import math
from dataclasses import dataclass
from typing import Any

from missions.geodetic import Home
from missions.geofence import geofence_from_plan
from params import ConfigError, finite_float, json_show, show, too_many_digits
from params.text import number

NAV_WAYPOINT, NAV_LOITER_TIME, NAV_RETURN_TO_LAUNCH, NAV_LAND, NAV_TAKEOFF, DO_CHANGE_SPEED = 16, 19, 20, 21, 22, 178
SUPPORTED = {NAV_WAYPOINT: "NAV_WAYPOINT", NAV_LOITER_TIME: "NAV_LOITER_TIME", NAV_RETURN_TO_LAUNCH:
             "NAV_RETURN_TO_LAUNCH", NAV_LAND: "NAV_LAND", NAV_TAKEOFF: "NAV_TAKEOFF",
             DO_CHANGE_SPEED: "DO_CHANGE_SPEED"}
# names of commands a plan often holds that we do not fly (MAVLink common.xml MAV_CMD), for the refusal's text
OTHER_NAMES = {17: "NAV_LOITER_UNLIM", 18: "NAV_LOITER_TURNS", 31: "NAV_LOITER_TO_ALT", 82: "NAV_SPLINE_WAYPOINT",
               84: "NAV_VTOL_TAKEOFF", 85: "NAV_VTOL_LAND", 92: "NAV_GUIDED_ENABLE", 93: "NAV_DELAY",
               94: "NAV_PAYLOAD_PLACE", 112: "CONDITION_DELAY", 114: "CONDITION_DISTANCE", 115: "CONDITION_YAW",
               177: "DO_JUMP", 179: "DO_SET_HOME", 181: "DO_SET_RELAY", 183: "DO_SET_SERVO", 189: "DO_LAND_START",
               195: "DO_SET_ROI_LOCATION", 197: "DO_SET_ROI_NONE", 201: "DO_SET_ROI", 202: "DO_DIGICAM_CONFIGURE",
               203: "DO_DIGICAM_CONTROL", 205: "DO_MOUNT_CONTROL", 206: "DO_SET_CAM_TRIGG_DIST",
               530: "SET_CAMERA_MODE", 2000: "IMAGE_START_CAPTURE", 2001: "IMAGE_STOP_CAPTURE",
               2003: "DO_TRIGGER_CONTROL", 2500: "VIDEO_START_CAPTURE", 3000: "DO_VTOL_TRANSITION"}
FRAMES = {0: "GLOBAL", 3: "GLOBAL_RELATIVE_ALT", 5: "GLOBAL_INT", 6: "GLOBAL_RELATIVE_ALT_INT"}
MISSION_FRAME = 2  # MAV_FRAME_MISSION: no position
RELATIVE_FRAMES = (3, 6)  # altitude above the home; the others: AMSL
OTHER_FRAMES = {1: "LOCAL_NED", 2: "MISSION", 4: "LOCAL_ENU", 7: "LOCAL_OFFSET_NED", 8: "BODY_NED",
                9: "BODY_OFFSET_NED", 10: "GLOBAL_TERRAIN_ALT", 11: "GLOBAL_TERRAIN_ALT_INT"}
PARAM_NAMES = ("param1", "param2", "param3", "param4", "x/lat", "y/lon", "z/alt")  # an item's 7 numbers
MAX_HOLD_S = 3600.0  # s: the longest hold time (param1) of NAV_WAYPOINT and NAV_LOITER_TIME flown
MAX_COMMAND, MAX_FRAME = 65535, 255  # MISSION_ITEM_INT's command is a uint16, its frame a uint8
MAX_ITEMS = 10_000  # PX4 keeps at most a few thousand (its dataman); a file with more is not a mission


def command_name(cmd: int) -> str:
    """``NAV_WAYPOINT (16)``: a command as the refusals name it."""
    return f"{SUPPORTED.get(cmd) or OTHER_NAMES.get(cmd) or 'MAV_CMD'} ({cmd})"


@dataclass(frozen=True)
class Item:
    """One mission item: where it is in its file (``mission.items[0]``; ``item 1``: a waypoint file's index,
    the home 0), MAV_CMD, MAV_FRAME, param1..4 (NaN: not given) and position (deg, deg, m in its frame)."""

    label: str
    command: int
    frame: int
    p1: float
    p2: float
    p3: float
    p4: float
    lat: float
    lon: float
    alt: float

    @property
    def name(self) -> str:
        return command_name(self.command)


@dataclass(frozen=True)
class PlanFile:
    """A ground station's mission: home (deg, deg, m AMSL), cruise speed (m/s, None: not given), items."""

    source: str
    home: tuple[float, float, float]
    items: tuple[Item, ...]
    cruise_m_s: float | None = None
    fence: Any = None  # missions.geofence.Geofence of a .plan's geoFence (None: none drawn)
    rally: Any = None  # a .plan's rallyPoints object, as read (missions.rally.rally_from_plan reads it)
    nan_word: str = "nan"  # how the file writes a value not given: a .plan's JSON null, a waypoint file's nan
    geo_fence: Any = None  # the geoFence object ``fence`` was read from (plan_text writes it back; None: none)

    def shown(self, v: float) -> str:
        """A value of an item as its file writes it (NaN as ``nan_word``)."""
        return self.nan_word if math.isnan(v) else str(v)

    def refuse(self, item: Item, why: str) -> ConfigError:
        """The refusal of ``item``: file, index, command, why."""
        return ConfigError(f"{self.source}: {item.label} ({item.name}): {why}")


def _number(v: Any) -> float:
    """A number as JSON holds it: a finite number, or null for NaN (QGroundControl writes NaN, a value not given,
    as null); ValueError if it is neither (Infinity, -Infinity and NaN, which Python's json reads, included)."""
    if v is None:
        return math.nan
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ValueError(f"expected a number or null, got {v!r}"[:80])
    f = finite_float(v)
    if f is None:
        raise ValueError(f"must be a finite number or null, got {json_show(v)}")
    return f


_PLAN_KEYS = ("fileType", "version", "groundStation", "mission", "geoFence", "rallyPoints")
_MISSION_KEYS = ("version", "firmwareType", "vehicleType", "cruiseSpeed", "hoverSpeed", "plannedHomePosition", "items",
                 "globalPlanAltitudeMode")


def _near_misses(source: str, obj: dict[str, Any], keys: tuple[str, ...], prefix: str) -> None:
    """Refuse a key of ``obj`` that is not one of ``keys`` but close to one (``geofence``, ``hoverspeed``): the one
    meant was read as not given (no fence, the default speed). Other keys are a tool's own, left alone as
    QGroundControl leaves them."""
    for k in obj:
        if isinstance(k, str) and k not in keys:
            near = difflib.get_close_matches(k.lower(), [c.lower() for c in keys], n=1, cutoff=0.8)
            if near:
                meant = next(c for c in keys if c.lower() == near[0])
                raise ConfigError(f"{source}: {prefix}{k[:40]}: unknown key; did you mean {meant!r}?")


def _version(source: str, key: str, v: Any, want: int) -> None:
    """Refuse a file format version (``version``, ``mission.version``) other than the number ``want``."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        got = "nothing" if v is None else f"the {_json_kind(v)} {json.dumps(v)[:40]}"
        raise ConfigError(f"{source}: {key}: expected the number {want}, got {got}")
    if v != want:
        raise ConfigError(f"{source}: {key}: version {show(v)} not supported ({want} is)")


def _json_kind(v: Any) -> str:
    """What a JSON value is, in JSON's words (``string``, ``array``)."""
    kinds = ((bool, "boolean"), (str, "string"), (list, "array"), (dict, "object"))
    return next((name for t, name in kinds if isinstance(v, t)), type(v).__name__)


def _check_item(source: str, item: Item, auto_continue: bool, null: str | None = None) -> Item:
    """``item`` if we fly it, else the refusal naming file, index and command. ``null``: how the file writes NaN
    (``null``, ``nan``), which a hold time (param1 of NAV_WAYPOINT, NAV_LOITER_TIME) must not be: QGroundControl
    writes 0 for no hold, NaN only where a value is not used or left to the vehicle (the yaw, param4). None: an
    item uploaded over MAVLink, where NaN is MAVLink's "the default" (no hold)."""
    where = f"{source}: {item.label} ({item.name})"
    if item.command not in SUPPORTED:
        raise ConfigError(f"{where}: not supported; supported: "
                          f"{', '.join(command_name(c) for c in SUPPORTED)}")
    if null and item.command in (NAV_WAYPOINT, NAV_LOITER_TIME) and math.isnan(item.p1):
        raise ConfigError(f"{where}: hold time (param1) {null}: expected a number of seconds in "
                          f"[0, {MAX_HOLD_S:g}] (0: no hold)")
    if not auto_continue:
        raise ConfigError(f"{where}: autoContinue false (the mission would wait there for a ground station)")
    # (QGroundControl writes RTL in frame MISSION, PX4 takes it only so: it names no position)
    if item.command != DO_CHANGE_SPEED and item.frame not in FRAMES and not (
            item.command == NAV_RETURN_TO_LAUNCH and item.frame == MISSION_FRAME):
        name = OTHER_FRAMES.get(item.frame, "unknown")
        raise ConfigError(f"{where}: frame {name} ({item.frame}) not supported; supported: "
                          f"{', '.join(f'{n} ({f})' for f, n in FRAMES.items())}")
    return item


class _DuplicateKey(Exception):
    """A JSON object that names a key twice (json keeps the last one, silently)."""


def _unique_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    """A JSON object's pairs as a dict, refusing a key given twice (a hand edit: QGroundControl writes each once)."""
    out: dict[str, Any] = {}
    for k, v in pairs:
        if k in out:
            raise _DuplicateKey(k)
        out[k] = v
    return out


def read_qgc_plan(text: str, source: str) -> PlanFile:
    """A QGroundControl ``.plan`` file's text: its home, cruise speed and items (refusals named)."""
    try:
        data = json.loads(text, object_pairs_hook=_unique_keys)
    except _DuplicateKey as exc:
        raise ConfigError(f"{source}: not a QGroundControl plan (key {show(exc.args[0])} given twice in one object; "
                          "JSON would keep the last)"[:300]) from None
    except (json.JSONDecodeError, RecursionError) as exc:
        raise ConfigError(f"{source}: not a QGroundControl plan (not valid JSON: {exc})"[:300]) from None
    except ValueError as exc:  # an integer over Python's limit of digits (json converts with int())
        why = too_many_digits(text, exc)
        raise ConfigError(f"{source}: not a QGroundControl plan (not valid JSON: {why})") from None
    if not isinstance(data, dict) or data.get("fileType") != "Plan":
        raise ConfigError(f"{source}: not a QGroundControl plan (fileType must be \"Plan\")")
    _version(source, "version", data.get("version"), 1)
    _near_misses(source, data, _PLAN_KEYS, "")
    mission = data.get("mission")
    if not isinstance(mission, dict):
        raise ConfigError(f"{source}: mission: expected an object")
    _version(source, "mission.version", mission.get("version"), 2)
    _near_misses(source, mission, _MISSION_KEYS, "mission.")
    home = mission.get("plannedHomePosition")
    try:
        lat, lon, alt = (_number(v) for v in home)  # type: ignore[union-attr]
    except (TypeError, ValueError):
        raise ConfigError(f"{source}: mission.plannedHomePosition: expected [lat, lon, alt] of finite numbers, "
                          f"got {json_show(home)}") from None
    check_home(source, lat, lon, alt, "mission.plannedHomePosition")
    speeds = {}
    for key in ("hoverSpeed", "cruiseSpeed"):  # the multicopter's, flown; the fixed wing's, checked only
        try:
            speeds[key] = _number(mission.get(key))
        except ValueError as exc:
            raise ConfigError(f"{source}: mission.{key}: {exc}") from None
    hover = speeds["hoverSpeed"]
    raw = mission.get("items")
    if not isinstance(raw, list) or not raw:
        raise ConfigError(f"{source}: mission.items: expected a non-empty list")
    if len(raw) > MAX_ITEMS:
        raise ConfigError(f"{source}: mission.items: {len(raw)} items, more than {MAX_ITEMS}")
    items = tuple(_plan_item(source, i, x) for i, x in enumerate(raw))
    fence = geofence_from_plan(data.get("geoFence"), Home(lat, lon, alt), source)
    return PlanFile(source, (lat, lon, alt), items, hover if math.isfinite(hover) else None, fence,
                    data.get("rallyPoints"), "null", data.get("geoFence"))


def _plan_item(source: str, index: int, x: Any) -> Item:
    label = f"mission.items[{index}]"
    if not isinstance(x, dict):
        raise ConfigError(f"{source}: {label}: expected an object")
    if x.get("type") == "ComplexItem":
        kind = x.get("complexItemType", "unknown")
        raise ConfigError(f"{source}: {label} (ComplexItem {str(kind)[:40]!r}): complex items (survey, corridor "
                          f"scan, structure scan) are not supported; fly their waypoints as simple items")
    if x.get("type") != "SimpleItem":
        raise ConfigError(f"{source}: {label}: type {str(x.get('type'))[:40]!r} not supported (SimpleItem is)")
    cmd, frame, params = x.get("command"), x.get("frame"), x.get("params")
    if not all(isinstance(v, int) and not isinstance(v, bool) and 0 <= v <= top
               for v, top in ((cmd, MAX_COMMAND), (frame, MAX_FRAME))):
        raise ConfigError(f"{source}: {label}: command and frame must be integers in [0, {MAX_COMMAND}] and "
                          f"[0, {MAX_FRAME}], got {json_show(cmd)} and {json_show(frame)}")
    try:
        if not isinstance(params, list) or len(params) != 7:
            raise ValueError("params: expected a list of 7")
        p = []
        for k, v in enumerate(params):
            try:
                p.append(_number(v))
            except ValueError as exc:
                raise ValueError(f"params[{k}] ({PARAM_NAMES[k]}): {exc}") from None
    except ValueError as exc:
        raise ConfigError(f"{source}: {label} ({command_name(cmd)}): {exc}") from None
    item = Item(label, cmd, frame, *p)
    if "autoContinue" not in x:  # QGroundControl's own loader requires it (MissionItem::load): never taken as true
        raise ConfigError(f"{source}: {label} ({command_name(cmd)}): autoContinue: missing; expected true or false "
                          "(QGroundControl writes it in every SimpleItem, and its loader refuses an item without it)")
    auto = x["autoContinue"]
    if not isinstance(auto, bool):
        raise ConfigError(f"{source}: {label} ({command_name(cmd)}): autoContinue: expected true or false, "
                          f"got {json_show(auto)}")
    return _check_item(source, item, auto, "null")


def read_wpl(text: str, source: str) -> PlanFile:
    """A ``QGC WPL 110`` file's text: line 0 the home, then the items (refusals named, by the file's own line
    numbers: blank lines are skipped, not renumbered)."""
    lines = [(n, ln) for n, ln in enumerate(text.splitlines(), start=1) if ln.strip()]
    if not lines or lines[0][1].split() != ["QGC", "WPL", "110"]:
        raise ConfigError(f"{source}: not a waypoint file (the first line must be \"QGC WPL 110\")")
    if len(lines) < 3:
        raise ConfigError(f"{source}: expected the home (line 0) and at least one item")
    if len(lines) > MAX_ITEMS + 2:
        raise ConfigError(f"{source}: {len(lines) - 2} items, more than {MAX_ITEMS}")
    rows = [_wpl_row(source, index, line, ln) for index, (line, ln) in enumerate(lines[1:])]
    line, frame, cmd, vals, _auto = rows[0]
    where = f"{source}: line {line} (the home)"
    if cmd != NAV_WAYPOINT:  # QGroundControl, MAVProxy and ArduPilot write the home as a NAV_WAYPOINT
        raise ConfigError(f"{where}: command {command_name(cmd)}, expected {command_name(NAV_WAYPOINT)}")
    if frame not in (0, 5):
        raise ConfigError(f"{where}: frame {frame}, expected GLOBAL (0): altitude AMSL")
    check_home(source, vals[4], vals[5], vals[6], f"the home (line {line})")
    items = tuple(_check_item(source, Item(f"item {i}", cmd, fr, *v), auto == 1, "nan")
                  for i, (_line, fr, cmd, v, auto) in enumerate(rows[1:], start=1))
    return PlanFile(source, (vals[4], vals[5], vals[6]), items)




def _wpl_row(source: str, index: int, line: int, text: str) -> tuple[int, int, int, list[float], int]:
    """(line, frame, command, [param1..4, lat, lon, alt], autocontinue) of the waypoint file's item ``index``,
    on the file's line ``line``; a value may be nan (not given: QGroundControl's NaN), never infinite."""
    f = text.split()
    try:
        if len(f) != 12:
            raise ValueError(f"expected 12 fields, got {len(f)}")
        idx, _cur, frame, cmd, auto = (_wpl_int(f[k]) for k in (0, 1, 2, 3, 11))  # (current: not flown)
        vals = [_wpl_number(name, word) for name, word in zip(PARAM_NAMES, f[4:11], strict=True)]
    except ValueError as exc:
        raise ConfigError(f"{source}: line {line}: {exc}"[:300]) from None
    if idx != index:
        raise ConfigError(f"{source}: line {line}: index {idx}, expected {index} (items are numbered from 0)")
    return line, frame, cmd, vals, auto


def _wpl_number(name: str, word: str) -> float:
    """A number field of a waypoint file (param1..4, latitude, longitude, altitude): a number or nan (not given:
    QGroundControl's NaN), never infinite; its name in the error."""
    try:
        v = number(word)
    except ValueError:
        raise ValueError(f"{name} {show(word)}: expected a number (or nan: not given)") from None
    if math.isinf(v):
        raise ValueError(f"{name} {show(word)}: must be a finite number or nan")
    return v


def _wpl_int(word: str) -> int:
    """A whole-number field of a waypoint file (index, current, frame, command, autocontinue)."""
    if not (word.lstrip("+-").isdigit() and len(word) <= 10):
        raise ValueError(f"expected an integer of at most 10 digits, got {show(word)}")
    return int(word)


def check_home(source: str, lat: float, lon: float, alt: float, key: str) -> None:
    """Refuse a home that is not a place on the earth."""
    if not (math.isfinite(lat) and math.isfinite(lon) and math.isfinite(alt)):
        raise ConfigError(f"{source}: {key}: not a position ({lat}, {lon}, {alt})")
    if not (-90.0 < lat < 90.0 and -180.0 <= lon <= 180.0 and -1000.0 <= alt <= 10000.0):
        raise ConfigError(f"{source}: {key}: latitude must be in (-90, 90) deg, longitude in [-180, 180] deg, "
                          f"altitude in [-1000, 10000] m; got ({lat:g}, {lon:g}, {alt:g})")


def plan_from_items(source: str, home: tuple[float, float, float],
                    items: list[tuple[int, int, int, tuple[float, ...], int]], geo_fence: Any = None,
                    rally: Any = None) -> PlanFile:
    """A mission that came over MAVLink as a plan: ``home`` (deg, deg, m AMSL) and per item (seq, MAV_CMD,
    MAV_FRAME, (param1..4, lat deg, lon deg, alt m), autocontinue); checked as a file's items are (the
    refusal names ``item SEQ`` and its command); with the fence and rally points that came with it, as a
    ``.plan``'s ``geoFence`` and ``rallyPoints`` objects (read as a file's are)."""
    check_home(source, *home, "the vehicle's home")
    if not items:
        raise ConfigError(f"{source}: the mission has no items")
    fence = geofence_from_plan(geo_fence, Home(*home), source)
    return PlanFile(source, home, tuple(_check_item(source, Item(f"item {seq}", cmd, frame, *vals), auto == 1)
                                        for seq, cmd, frame, vals, auto in items), fence=fence, rally=rally,
                    geo_fence=geo_fence)


def _json_number(v: float) -> float | int | None:
    """A number as QGroundControl writes it: NaN as null, whole numbers without a fraction."""
    if not math.isfinite(v):
        return None
    return int(v) if v == int(v) and abs(v) < 2**53 else v


def plan_text(plan: PlanFile) -> str:
    """``plan`` as a QGroundControl ``.plan`` file's text (its documented schema; read back by
    :func:`read_qgc_plan` to the same items, fence and rally points): every item a SimpleItem, altitude mode by
    its frame."""
    def item(n: int, it: Item) -> dict[str, Any]:
        params = [_json_number(v) for v in (it.p1, it.p2, it.p3, it.p4, it.lat, it.lon, it.alt)]
        out: dict[str, Any] = {"autoContinue": True, "command": it.command, "doJumpId": n + 1, "frame": it.frame,
                               "params": params, "type": "SimpleItem"}
        if it.command != DO_CHANGE_SPEED:
            out.update({"AMSLAltAboveTerrain": None, "Altitude": params[6],
                        "AltitudeMode": 1 if it.frame in RELATIVE_FRAMES else 2})
        return out

    mission = {"cruiseSpeed": 15, "firmwareType": 12, "globalPlanAltitudeMode": 1,
               "hoverSpeed": _json_number(plan.cruise_m_s) if plan.cruise_m_s is not None else 5,
               "items": [item(n, it) for n, it in enumerate(plan.items)],
               "plannedHomePosition": [_json_number(v) for v in plan.home], "vehicleType": 2, "version": 2}
    zones = plan.geo_fence if isinstance(plan.geo_fence, dict) else {}  # (read: checked by geofence_from_plan)
    fence = {key: [{**{k: z[k] for k in ("inclusion", shape)}, "version": 1} for z in zones.get(key, [])]
             for key, shape in (("circles", "circle"), ("polygons", "polygon"))}
    points = plan.rally.get("points", []) if isinstance(plan.rally, dict) else []
    data = {"fileType": "Plan", "geoFence": {**fence, "version": 2},
            "groundStation": "bsst", "mission": mission, "rallyPoints": {"points": points, "version": 2},
            "version": 1}
    return json.dumps(data, indent=4, sort_keys=True) + "\n"


def read_plan_text(text: str, source: str) -> PlanFile:
    """A ``.plan`` or ``QGC WPL 110`` file's text, told apart by its content; a ``.waypoints`` or ``.txt`` file that
    is not JSON is read as a waypoint file (so one without its header line is told that, not that it is bad JSON)."""
    head = text.lstrip()
    if not head:
        raise ConfigError(f"{source}: empty (a QGroundControl .plan or a QGC WPL 110 waypoint file)")
    wpl = head.startswith("QGC WPL") or (source.lower().endswith((".waypoints", ".txt")) and not head.startswith("{"))
    return read_wpl(text, source) if wpl else read_qgc_plan(text, source)
