"""The children's reports of one read, put in the order things happened on the flight's clock.

In:  reports read together from a session's children (the controller's pipe read before the vehicle's), the time
     of each on the events' clock (s; -inf for a report that is not a timed event), and the vehicle's latest
     event of each kind in earlier reads (s, by kind: updated here)
Out: the reports in that order, each with the time it is recorded at (s)

Each child's pipe is read in turn, so the order read is not the order things happened: events go in the order of
their times (the vehicle's first on a tie: the controller's events about the vehicle are its answers). A
controller's event said in answer to the vehicle's own (its ``answers``: it armed it, took the end action, saw it
crash) is never put before its cause, the latest of them read before it or the earliest read with it: the
controller stamps its word at the last state it answered, and in real time the two clocks are mapped onto the
flight's only to within a few ms.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from bridge.nodes.report import Event, Report
from bridge.session.children import Child


def in_cause_order(reports: Sequence[tuple[Child, Report]], times: Sequence[float],
                   vehicle_said: dict[str, float]) -> list[tuple[Child, Report, float]]:
    """``reports`` (with their ``times``, s) in the order they happened (module docstring), each with the time it
    is recorded at (s); ``vehicle_said`` (the vehicle's latest event of each kind in earlier reads, s) takes this
    read's."""
    # the vehicle's events of this read, each kind's earliest and latest: the controller's pipe is read first, so an
    # answer's cause is read with it or before it
    first: dict[str, float] = {}
    last: dict[str, float] = {}
    for (child, r), t in zip(reports, times):
        if isinstance(r, Event) and child.name == "vehicle":
            first[r.kind], last[r.kind] = min(t, first.get(r.kind, math.inf)), max(t, last.get(r.kind, -math.inf))
    timed = []
    for (child, r), t in zip(reports, times):
        if isinstance(r, Event) and child.name != "vehicle" and r.answers:
            t = max(t, *(max(vehicle_said.get(k, -math.inf), first.get(k, -math.inf)) for k in r.answers))
        timed.append((t, child.name != "vehicle", child, r))
    for kind, t in last.items():
        vehicle_said[kind] = max(t, vehicle_said.get(kind, -math.inf))
    return [(child, report, t) for t, _, child, report in sorted(timed, key=lambda x: x[:2])]
