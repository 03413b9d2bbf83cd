"""The vehicle's watch over a mission in flight: which item is current and when each is reached.

In:  the held mission's items (:class:`~bridge.mavlink.missionitems.MissionItem`) and the vehicle's home
     (deg, deg, m AMSL), at the start; then at each control step its time (s) and the plant's true state
     (paper frame: x, y, z m at indices 0, 2, 4)
Out: the items reached at that step (their seq, in order) and the current item; a mission that cannot be
     flown is a :class:`params.ConfigError` naming the item (the start is refused with it)

Where each item is: the route the controller flies (:func:`missions.route.stops_of`, the same code, about
the same home), the last point of the route an item names (the top of a takeoff, the ground under a
landing). An item is reached, as PX4's navigator has it, when the vehicle is within its acceptance radius
(NAV_WAYPOINT's param2 when > 0, else :data:`ACCEPTANCE_M`; a landing or return: :data:`LANDED_M` of the
ground point, on the ground) and has held there for the item's hold time; an item without a position
(DO_CHANGE_SPEED) is reached as soon as it is the current one. Items are reached in order.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from bridge.mavlink.missionitems import MissionItem, plan_of
from missions.envelope import ENVELOPE_RADIUS_M
from missions.planfiles import NAV_LAND, NAV_RETURN_TO_LAUNCH, NAV_WAYPOINT
from missions.route import Limits, stops_of

ACCEPTANCE_M = 1.0  # m: a position item's acceptance radius when it gives none (ours; PX4's NAV_ACC_RAD is wider)
LANDED_M = 0.1  # m: a landing or return is reached on the ground under it


@dataclass(frozen=True)
class Goal:
    """One item: its seq, its point (paper frame, m; None: no position), acceptance radius (m), hold (s)."""

    seq: int
    point: tuple[float, float, float] | None
    radius_m: float
    hold_s: float


def goals_of(items: tuple[MissionItem, ...], home: tuple[float, float, float]) -> tuple[Goal, ...]:
    """Each item's goal, from the route flown (ConfigError when the mission cannot be flown)."""
    plan = plan_of(items, home, "the vehicle's mission")
    stops, _ = stops_of(plan, Limits(), ENVELOPE_RADIUS_M)
    last = {label: s for s in stops for label in s.items}  # each item's last point
    goals = []
    for it in items:
        s = last.get(f"item {it.seq}")
        if s is None:
            goals.append(Goal(it.seq, None, 0.0, 0.0))
            continue
        if it.command in (NAV_LAND, NAV_RETURN_TO_LAUNCH):
            radius = LANDED_M
        elif it.command == NAV_WAYPOINT and math.isfinite(it.param2) and it.param2 > 0:
            radius = it.param2
        else:
            radius = ACCEPTANCE_M
        goals.append(Goal(it.seq, (s.x, s.y, s.z), radius, s.hold_s))
    return tuple(goals)


class ItemWatch:
    """The items of a mission in flight, reached in order (:meth:`step`)."""

    def __init__(self, goals: tuple[Goal, ...]) -> None:
        self.goals = goals
        self.i = 0  # the current goal
        self._inside_at: float | None = None  # when the vehicle came within the current goal's radius (s)

    @property
    def current(self) -> int:
        """The current item's seq (the last one once all are reached)."""
        return self.goals[min(self.i, len(self.goals) - 1)].seq

    @property
    def done(self) -> bool:
        return self.i >= len(self.goals)

    def step(self, t: float, X: tuple[float, ...]) -> list[int]:
        """The items reached at time ``t`` (s) with the vehicle at ``X`` (paper frame), in order."""
        out = []
        while self.i < len(self.goals):
            g = self.goals[self.i]
            if g.point is not None:
                dx, dy, dz = X[0] - g.point[0], X[2] - g.point[1], X[4] - g.point[2]
                if dx * dx + dy * dy + dz * dz > g.radius_m * g.radius_m:
                    self._inside_at = None
                    return out
                if self._inside_at is None:
                    self._inside_at = t
                if t - self._inside_at < g.hold_s:
                    return out
            out.append(g.seq)
            self.i += 1
            self._inside_at = None
        return out
