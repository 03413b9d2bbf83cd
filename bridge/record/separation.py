"""A fleet's separation policy: every pair's closest approach, and the contacts, judged on the vehicles' positions.

In:  the vehicles' ids, their rotor discs' radii (m), the policy's minimum clearance (m); each step, the mission time
     (s) and the vehicles' true centres (m, NWU x, y, z); for SITL, the finished traces (rows at t = j / rate s,
     columns ``x``, ``y``, ``z`` m), where each stayed after its last row, each one's start (m) and the step after
     which each one's rows were flown on the wall clock
Out: :class:`Watch`: the pairs that touch at a step (indices, why), ``summary.json["separation"]`` (every pair's
     closest approach: clearance m, at t s) and the ``separation`` policy's verdict (ok, or t s and why);
     :class:`Untold`: the offline fleet's vehicles judged but told nothing (a failsafe's landing after the
     mission: from, to s) and their contacts (step, t s, the other's id, why, ``continued``);
     :func:`judge_traces`: each vehicle's first contact on finished traces (step, t s, the other's id, why, and
     ``continued`` when nothing stopped the flights at it)

The offline fleet (:mod:`bridge.swarm`) judges its world after every step with a :class:`Watch`; a SITL fleet's
is judged on its sessions' traces afterwards, by the same :class:`Watch` (:func:`judge_traces`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from missions.fleet import clearance

DEFINITION = ("distance between the vehicles' centres less each one's disc radius (its arm plus its rotor "
              "radius: rotor_radius_m, by default half the arm)")
CONTINUED = ("the flights continued past the contact: in real time each vehicle keeps its own wall clock, the "
             "vehicles share no clock, so nothing stopped them at it (docs/swarm.md)")
WALL_CLOCK = ("the flights continued past the contact: found afterwards on the records, at a step one of the two flew "
              "on the wall clock after it left the fleet's shared step clock, matched to the other's by mission time "
              "(approximate); nothing stopped them at it (docs/swarm.md)")
ALONE = ("the flights continued past the contact: found at a step one of the two flew its failsafe's landing alone "
         "after the mission (offline it is flown alone, told nothing, as a lockstep fleet flies it on the wall clock "
         "and judges it on its record), so nothing stopped them at it (docs/swarm.md)")
NOWHERE = (math.nan, math.nan, math.nan)  # a vehicle whose place is not known: never closer, never touching


class Watch:
    """The shared world's separation policy over a flight: every pair's closest approach (clearance m, at t s),
    the first time the policy broke, and the pairs in contact now."""

    def __init__(self, ids: Sequence[int], radii: Sequence[float], min_m: float) -> None:
        self.ids, self.radii, self.min_m = list(ids), list(radii), min_m
        n = len(ids)
        self.pairs = [(a, b) for a in range(n) for b in range(a + 1, n)]
        self.closest = {p: (math.inf, 0.0) for p in self.pairs}  # (clearance m, t s)
        self.broken: tuple[float, str] | None = None

    def check(self, t: float, positions: Sequence[Sequence[float]]) -> list[tuple[int, int, str]]:
        """Judge the world at time ``t`` (s) with these centres (m): the pairs (indices) that touch, and why."""
        touching = []
        for a, b in self.pairs:
            d, c = clearance(positions[a], positions[b], self.radii[a], self.radii[b])
            if c < self.closest[(a, b)][0]:
                self.closest[(a, b)] = (c, t)
            if c < self.min_m and self.broken is None:
                self.broken = (t, f"vehicles {self.ids[a]} and {self.ids[b]} {c:.3f} m apart (rotor discs), "
                                  f"under the minimum of {self.min_m:g} m")
            if c <= 0.0:
                touching.append((a, b, f"vehicles {self.ids[a]} and {self.ids[b]} touched at t={t:.3f} s "
                                       f"(centres {d:.3f} m apart, rotor discs {c:.3f} m)"))
        return touching

    def summary(self) -> dict[str, Any]:
        """``summary.json["separation"]``: the policy, and every pair's closest approach."""
        pairs = [{"ids": [self.ids[a], self.ids[b]], "closest_m": _num(c), "t": round(t, 6),
                  "ok": c >= self.min_m} for (a, b), (c, t) in self.closest.items()]
        least = min((p["closest_m"] for p in pairs if p["closest_m"] is not None), default=None)
        return {"min_m": self.min_m, "definition": DEFINITION, "disc_radius_m": dict(zip(map(str, self.ids),
                self.radii)), "closest_m": least, "pairs": pairs}

    def verdict(self) -> dict[str, Any]:
        """The ``separation`` policy's verdict, as the other policies' (:class:`bridge.record.policies.Verdict`)."""
        if self.broken is None:
            return {"name": "separation", "ok": True}
        return {"name": "separation", "ok": False, "t": round(self.broken[0], 6), "why": self.broken[1]}


class Untold:
    """The vehicles an offline fleet judges without telling them anything: each flies its failsafe's landing after the
    mission alone (:class:`bridge.loop.Alone`), as flown by itself, and stays untold where it ends. When each flew so
    (steps), and each vehicle's first contact with one of them, found, not prevented (``continued``: :data:`ALONE`)."""

    def __init__(self, ids: Sequence[int], rate: float) -> None:
        self.ids, self.rate = list(ids), rate
        self.first: dict[int, int] = {}  # vehicle index -> the first period it flew alone (0: the fleet's first step)
        self.last: dict[int, int] = {}
        self.found: dict[int, dict[str, Any]] = {}

    def flew(self, i: int, k: int) -> None:
        """Vehicle ``i`` (index) flew period ``k`` alone."""
        self.first.setdefault(i, k)
        self.last[i] = k

    def told(self, k: int, touching: list[tuple[int, int, str]]) -> list[tuple[int, int, str]]:
        """Of the pairs touching in the world after period ``k - 1`` (step ``k``), those to tell (neither untold);
        the others' contacts are kept as found (each vehicle's first)."""
        tell = []
        for a, b, why in touching:
            if a not in self.first and b not in self.first:
                tell.append((a, b, why))
                continue
            for i, other in ((a, b), (b, a)):
                self.found.setdefault(i, {"step": k, "t": round(k / self.rate, 6), "with": self.ids[other],
                                          "why": why, "continued": ALONE})
        return tell

    def summary(self) -> list[dict[str, Any]]:
        """``summary.json["separation"]["alone"]``: who flew alone after the mission, from when to when (s)."""
        return [{"id": self.ids[i], "from_t": round(self.first[i] / self.rate, 6),
                 "to_t": round((self.last[i] + 1) / self.rate, 6),
                 "why": "its failsafe's landing, still going at the mission's end",
                 "judged": "at every step, as the mission's; told nothing: a contact found, not prevented"}
                for i in sorted(self.first)]


def _num(v: float) -> float | None:  # (m, 9 digits; None: never judged)
    return round(v, 9) if math.isfinite(v) else None


def judge_traces(watch: Watch, traces: Sequence[dict[str, Any]], rate: float,
                 finals: Sequence[tuple[float, float, float] | None] | None = None,
                 starts: Sequence[Sequence[float]] | None = None,
                 afters: Sequence[Sequence[Sequence[float]]] | None = None,
                 walls: Sequence[int | None] | None = None, own_clocks: bool = False) -> dict[int, dict[str, Any]]:
    """Judge the shared world on finished traces, with the offline loop's :class:`Watch`: row j of every trace
    (the true positions at t = j / rate; row 0 the start) is the world after step j - 1, as the loop judges it,
    and after a trace's rows, its vehicle's ``afters`` (m: its end landing's, flown on after the mission, as the
    loop flies and judges them); a path that ended early stays at its last row, or with ``finals`` (a lockstep
    fleet's shared clock: where each vehicle stayed, m, after its last row's step) there, as the loop keeps it; an
    empty one (a vehicle that flew no step) is at its start with ``starts`` (m: one never armed stands there, as
    the loop keeps it), else nowhere, and touches no one (a final :data:`NOWHERE`: not known after its rows).
    ``walls``: the step after which each vehicle's rows were flown on the wall clock (None: none), judged by their
    index as the rest. On a shared clock (``finals``, not ``own_clocks``) a vehicle whose flight was over (past its
    rows) is an obstacle only, its outcome its own, as the offline loop tells a contact to live flights only.
    The first contact of each vehicle (by index): its step, time, the other's id and why (without
    ``finals``, or with ``own_clocks`` (a real-time fleet's: each vehicle on its own clock), that the flights went
    on: :data:`CONTINUED`; at a step one of the two flew on the wall clock: :data:`WALL_CLOCK`)."""
    last = [finals[i] if finals is not None else None for i in range(len(traces))]
    paths = [[(float(x), float(y), float(z)) for x, y, z in zip(tr["x"], tr["y"], tr["z"])] for tr in traces]
    for path, more_rows in zip(paths, afters or ()):
        path.extend((float(p[0]), float(p[1]), float(p[2])) for p in more_rows)
    n = max((len(path) + (p is not None) for path, p in zip(paths, last)), default=0)
    first: dict[int, dict[str, Any]] = {}
    unflown = [tuple(s[:3]) for s in starts] if starts is not None else [NOWHERE] * len(traces)
    wall = list(walls) if walls is not None else [None] * len(traces)
    shared = finals is not None and not own_clocks  # a lockstep fleet's shared clock
    for j in range(n):
        positions = []
        for path, p, home in zip(paths, last, unflown):
            r = min(j, len(path) - 1)
            positions.append(p if p is not None and j > r else path[r] if r >= 0 else home)
        for a, b, why in watch.check(j / rate, positions):
            off = any(w is not None and j > w for w in (wall[a], wall[b]))
            more = ({"continued": CONTINUED} if finals is None or own_clocks else
                    {"continued": WALL_CLOCK} if off else {})
            for i, other in ((a, b), (b, a)):
                if shared and j > len(paths[i]):  # its flight was over (row len: where it stayed): an obstacle only
                    continue
                first.setdefault(i, {"step": j, "t": round(j / rate, 6), "with": watch.ids[other], "why": why, **more})
    return first
