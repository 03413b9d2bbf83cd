"""The suite's plan files: the shipped box, edited copies of it, and the box cut to an L.

In:  a temporary directory, an edit of the plan's JSON (a function that changes it in place)
Out: the path of a ``.plan`` file written there

Pure (files in the test's own directory only): both the pure plan tests and the ground-station tests
(MAVSDK's MissionRaw imports a ``.plan``) fly these.
"""

from __future__ import annotations

import copy
import json
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BOX_PLAN = ROOT / "examples" / "box.plan"
PLAN = json.loads(BOX_PLAN.read_text())


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
