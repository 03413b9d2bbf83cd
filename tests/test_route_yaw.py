"""Covers missions.route and missions.minsnap: a plan's yaw reference as a PX4 user expects it (MPC_YAW_MODE 0,
towards the waypoint): the leg's heading held along a straight leg, turns at the corners that never swing past
their knots, within MPC_YAWRAUTO_MAX, a waypoint's given yaw reached and held; the positions timed as before, and
a plan flown offline to its landing on that yaw.

Until the third wave's forty-fourth session the yaw was the minimum-snap polynomial the positions are: on the box's
straight legs it swung 11.9 deg off their heading and back, 28.7 deg round an out-and-back waypoint (a user's tour).
"""

from __future__ import annotations

import copy
import math
from pathlib import Path

import pytest

from bridge import simulate
from missions.minsnap import Smooth
from missions.planfiles import read_plan_text
from missions.route import Limits, route_of
from tests.plans import BOX_PLAN, ITEMS_AND_FRAMES, M_PER_DEG, l_plan, write_plan


def out_and_back(data: dict) -> None:
    """The box plan's takeoff and speed, then 20 m north and back over the home (passed through), and out again."""
    items = data["mission"]["items"]
    there, home = copy.deepcopy(items[2]), copy.deepcopy(items[2])
    there["params"][4:6] = [47.397742 + 20.0 / M_PER_DEG, 8.545594]
    home["params"][4:6] = [47.397742, 8.545594]
    data["mission"]["items"] = [items[0], items[1], there, home, copy.deepcopy(there), items[7]]


def third_corner_east(data: dict) -> None:
    """The box with its third corner's yaw given: 90 deg, east."""
    data["mission"]["items"][4]["params"][3] = 90


def plan_route(tmp_path: Path, name: str):
    """(route, its trajectory) of the plan ``name``."""
    if name == "box":
        text = BOX_PLAN.read_text()
    elif name == "L":
        text = l_plan(tmp_path).read_text()
    elif name == "frames":
        text = ITEMS_AND_FRAMES
    else:
        text = write_plan(tmp_path, {"out-and-back": out_and_back, "east": third_corner_east}[name]).read_text()
    route = route_of(read_plan_text(text, name), Limits(), 100.0)
    return route, Smooth(route.knots, route.lands)


def yaws(ref: Smooth, a, b, n: int = 200) -> list[tuple[float, ...]]:
    """The yaw (value and derivatives) at n - 1 times strictly between knots a and b."""
    return [ref.sample(a.t + (b.t - a.t) * i / n)[3] for i in range(1, n)]


def test_the_yaw_holds_each_straight_legs_heading_on_the_box() -> None:
    """Between a leg's two guide knots (the straight 60 % of each 40 m side) the yaw is the leg's heading, to
    rounding, and still; it turns only near the corners. On the minimum-snap yaw: 0.208 rad (11.9 deg) off."""
    route, ref = plan_route(Path("."), "box")
    named = {k for _, k, _ in route.waypoints}
    ks = ref.knots
    legs = [j for j in range(len(ks) - 1) if j not in named and j + 1 not in named and j > 0
            and math.hypot(ks[j + 1].x - ks[j].x, ks[j + 1].y - ks[j].y) > 1.0]
    assert len(legs) == 6  # the five sides and the way back over the home
    worst = 0.0
    for j in legs:
        a, b = ks[j], ks[j + 1]
        heading = math.atan2(b.y - a.y, b.x - a.x)
        for p in yaws(ref, a, b):
            worst = max(worst, abs(math.remainder(p[0] - heading, 2 * math.pi)), abs(p[1]))
    assert worst <= 1e-9


@pytest.mark.parametrize("name", ["box", "L", "out-and-back", "east", "frames"])
def test_the_yaw_never_swings_past_its_knots_and_keeps_the_yaw_rate_limit(tmp_path: Path, name: str) -> None:
    """Every segment's yaw stays between its two knots' (monotone: a turn goes one way), and its rate within
    MPC_YAWRAUTO_MAX (45 deg/s) everywhere. The minimum-snap yaw went past them by 11.9 deg on the box, 8.5 on
    the L, 28.7 round the out-and-back waypoint, 35.9 before the box's corner given 90 deg, 17.6 on the items and
    frames plan; its rate kept the limit."""
    _, ref = plan_route(tmp_path, name)
    ks, limit = ref.knots, math.radians(Limits().MPC_YAWRAUTO_MAX)
    past = fastest = 0.0
    for a, b in zip(ks, ks[1:]):
        lo, hi = min(a.psi, b.psi), max(a.psi, b.psi)
        for p in yaws(ref, a, b):
            past, fastest = max(past, p[0] - hi, lo - p[0]), max(fastest, abs(p[1]))
    assert past <= 1e-12, f"{math.degrees(past):.2f} deg past a knot"
    assert fastest <= limit, f"{math.degrees(fastest):.3f} deg/s"


@pytest.mark.parametrize("name, end_s", [("box", 88.644), ("L", 19.389), ("out-and-back", 61.016), ("east", 94.918),
                                         ("frames", 57.706)])
def test_the_positions_keep_their_times(tmp_path: Path, name: str, end_s: float) -> None:
    """The yaw's change moves no position: every plan ends when it did (the legs are timed by the minimum-snap
    yaw's rate, as before), and a turn too quick for its corner at those times is spread along the legs beside it
    (the L, the out-and-back, the given yaws: their guide knots' yaws moved) rather than slowing the flight. A guard:
    passes on the old code too."""
    route, _ = plan_route(tmp_path, name)
    assert route.knots[-1].t == pytest.approx(end_s, abs=1e-9)


def test_a_given_yaw_is_reached_and_held() -> None:
    """The items and frames plan's waypoint given 90 deg (east, psi -pi/2) holding 2 s: the yaw is there on arrival
    and still for the hold; the leg before turns to it without passing it."""
    route, ref = plan_route(Path("."), "frames")
    k = next(k for label, k, _ in route.waypoints if label == "item 2")
    here, then = ref.knots[k], ref.knots[k + 1]
    assert here.psi == then.psi == pytest.approx(-math.pi / 2)
    assert all(p[0] == here.psi and p[1] == 0.0 for p in yaws(ref, here, then))
    before = yaws(ref, ref.knots[k - 1], here)
    assert all(-math.pi / 2 - 1e-12 <= p[0] <= 1e-12 for p in before)  # from north (0) to east, not past it


def test_the_l_plan_flies_to_its_landing_on_the_monotone_yaw(tmp_path: Path) -> None:
    """``bsst sim``'s flight (bridge.simulate) of the L: completed, landed and disarmed; its psi_ref is the yaw
    reference above (never past its knots) and the vehicle follows it (the law's psi, psi' and psi'' continuous)."""
    run = simulate(l_plan(tmp_path), plots=False)
    assert run.summary["outcome"] == "completed" and (run.summary.get("end") or {}).get("disarmed")
    tr = run.trace
    _, ref = plan_route(tmp_path, "L")
    lo, hi = min(k.psi for k in ref.knots), max(k.psi for k in ref.knots)
    assert lo == pytest.approx(-math.pi / 2) and hi == 0.0
    assert all(lo - 1e-12 <= p <= hi + 1e-12 for p in tr["psi_ref"])
    assert max(abs(ref.sample(t)[3][0] - p) for t, p in zip(tr["t"], tr["psi_ref"])) <= 1e-12
    assert max(abs(math.remainder(a - b, 2 * math.pi)) for a, b in zip(tr["psi"], tr["psi_ref"])) <= 0.01
