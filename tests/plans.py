"""The suite's plan files: the shipped box, edited copies of it, and the box cut to an L.

In:  a temporary directory, an edit of the plan's JSON (a function that changes it in place)
Out: the path of a ``.plan`` file written there

Pure (files in the test's own directory only): both the pure plan tests and the ground-station tests
(MAVSDK's MissionRaw imports a ``.plan``) fly these.
"""

from __future__ import annotations

import copy
import json
import math
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BOX_PLAN = ROOT / "examples" / "box.plan"
PLAN = json.loads(BOX_PLAN.read_text())

# a plan of the other items and frames (tests/test_plan.py, tests/test_route_yaw.py): a waypoint held 2 s with its yaw
# given (90 deg, east), a loiter, a pass-through, return to launch
ITEMS_AND_FRAMES = """QGC WPL 110
0\t1\t0\t16\t0\t0\t0\t0\t47.397742\t8.545594\t488.0\t1
1\t0\t3\t22\t0\t0\t0\tnan\t47.397742\t8.545594\t10\t1
2\t0\t0\t16\t2\t0\t0\t90\t47.3978319\t8.545594\t498.0\t1
3\t0\t6\t19\t3\t0\t0\tnan\t47.3978319\t8.5457268\t10\t1
4\t0\t5\t16\t0\t0\t0\tnan\t47.397742\t8.5457268\t498.0\t1
5\t0\t2\t20\t0\t0\t0\t0\t0\t0\t0\t1
"""


def write_plan(tmp_path: Path, edit: Callable[[dict], None], name: str = "p.plan") -> Path:
    """A copy of the box plan, changed by ``edit``, written as ``tmp_path / name``."""
    data = copy.deepcopy(PLAN)
    edit(data)
    p = tmp_path / name
    p.write_text(json.dumps(data))
    return p


def l_plan(tmp_path: Path) -> Path:
    """The box plan cut to an L (takeoff to 3 m, a speed change, 10 m north, a pass-through corner, 10 m east,
    land): 5 items and 20 s of flight where the box has 8 and 90, with every kind of item the box has (its
    figures: tests/test_plan.py, offline)."""
    def cut(data: dict) -> None:
        items = data["mission"]["items"]
        takeoff, speed, corner, land = (copy.deepcopy(items[i]) for i in (0, 1, 2, 7))
        north, east = corner, copy.deepcopy(corner)
        for item, (lat, lon) in ((takeoff, (47.397742, 8.545594)), (north, (47.397832, 8.545594)),
                                 (east, (47.397832, 8.545727)), (land, (47.397832, 8.545727))):
            item["params"][4:6] = [lat, lon]
            if item is not land:
                item["params"][6] = item["Altitude"] = 3
        data["mission"]["items"] = [takeoff, speed, north, east, land]
        for k, item in enumerate(data["mission"]["items"]):
            item["doJumpId"] = k + 1
    return write_plan(tmp_path, cut, "l.plan")


def box_repeated(tmp_path: Path, items: int, name: str = "long.plan") -> Path:
    """The box plan with its five corners flown round and round: takeoff, speed change, corners, land; ``items``
    items in all (3 000: 7.5 hours of flight, docs/missions.md "Loading a long plan")."""
    def repeat(data: dict) -> None:
        box = data["mission"]["items"]
        laps = [copy.deepcopy(box[2 + k % 5]) for k in range(items - 3)]
        data["mission"]["items"] = [box[0], box[1], *laps, box[7]]
        for k, item in enumerate(data["mission"]["items"]):
            item["doJumpId"] = k + 1
    return write_plan(tmp_path, repeat, name)


M_PER_DEG = 6_371_000.0 * math.pi / 180.0  # the projection's sphere: metres per degree of latitude
L_HOME = (47.397742, 8.545594)  # the L plan's home and start
# why a vehicle at the start of outside_fence_plan is not armed (PX4's pre-arm geofence check)
OUTSIDE_WHY = "arming denied: outside its fence: at x=0.000 y=0.000 m, outside every inclusion zone of the geofence"


def l_latlon(north: float, east: float) -> list[float]:
    """[lat, lon] of the point ``north`` m north and ``east`` m east of the L plan's home."""
    return [L_HOME[0] + north / M_PER_DEG, L_HOME[1] + east / (M_PER_DEG * math.cos(math.radians(L_HOME[0])))]


def l_rectangle(south: float, north: float, west: float, east: float) -> list[list[float]]:
    """The corners of a rectangle in metres north and east of the L's home, as a plan's [lat, lon] polygon."""
    return [l_latlon(south, -west), l_latlon(north, -west), l_latlon(north, east), l_latlon(south, east)]


def fenced_l(tmp_path: Path, fence: dict, name: str) -> Path:
    """The L plan (10 m north, then 10 m east, at 3 m) with ``fence`` as its geoFence."""
    p = l_plan(tmp_path)
    data = json.loads(p.read_text())
    data["geoFence"] = {"version": 2, "polygons": [], "circles": [], **fence}
    out = tmp_path / name
    out.write_text(json.dumps(data))
    return out


def outside_fence_plan(tmp_path: Path) -> Path:
    """The L plan fenced from 2 m north of its start: the vehicle starts outside the fence."""
    fence = {"polygons": [{"inclusion": True, "version": 1, "polygon": l_rectangle(2, 13, 3, 13)}]}
    return fenced_l(tmp_path, fence, "outside.plan")


def battery_mission(tmp_path: Path, start_pct: float, duration_s: float = 15.0, up: tuple[float, float] = (5.0, 3.0),
                    north: tuple[float, float] = (12.0, 5.0), name: str = "battery") -> Path:
    """The x500 with its battery from ``start_pct`` % of its charge: climbing to ``up`` = (by t s, height m), then
    ``north`` = (by t s, x m) north at that height, held there; ``duration_s``. By default: 3 m in 5 s, 5 m north
    by 12 s, 15 s."""
    p = tmp_path / f"{name}-{start_pct:g}.toml"
    p.write_text(f"""name = "{name}"
duration_s = {duration_s}
profile = "x500"

[trajectory]
kind = "waypoints"
points = [{{ t = 0.0, x = 0.0, y = 0.0, z = 0.0 }}, {{ t = {up[0]}, x = 0.0, y = 0.0, z = {up[1]} }},
          {{ t = {north[0]}, x = {north[1]}, y = 0.0, z = {up[1]} }}]

[effects]
battery = true
battery_start_pct = {start_pct}
""")
    return p
