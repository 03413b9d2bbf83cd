"""The children's reports of one read, put in the order things happened on the flight's clock.

In:  reports read together from a session's children (the controller's pipe read before the vehicle's; an event's
     ``answers`` and, the vehicle's, its sender ``by``: its controller's link or not), the time
     of each on the events' clock (s; -inf for a report that is not a timed event), and the vehicle's latest
     event of each kind in earlier reads (s, by kind: updated here)
Out: the reports in that order, each with the time it is recorded at (s)

Each child's pipe is read in turn, so the order read is not the order things happened: events go in the order of
their times. A controller's event said in answer to the vehicle's own (its ``answers``: it armed it, took the end
action, saw it crash, its parameter set was echoed) is never put before its cause, the latest of them read before
it or the earliest read with it: the controller stamps its word at the last state it answered, and in real time the
two clocks are mapped onto the flight's only to within a few ms. Its cause is never read after it: the controller's
pipe is read first, and the vehicle says each event before the answer to whoever caused it goes out (a command's
before its COMMAND_ACK, a parameter's change before its PARAM_VALUE echo); a controller says its own act before it
sends it (a PARAM_SET).

Events of one time go by cause (:func:`_rank`): the vehicle's own first (what the controller stamped at that time
came after the state that showed them), then the others' (the controller's acts, the relay's), then the vehicle's
events caused by its controller (the change its PARAM_SET made, in lockstep at the step the controller stamped its
PARAM_SET at), then the controller's answers; the vehicle's own events keep the order it said them in (one said
after a caused one goes after it: a ground station's fence upload after the controller's ARM, both stamped at the
step the flight waits at). Until the forty-first session the vehicle's came first on every tie: its change before
the controller's PARAM_SET that made it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from bridge.autopilot.vehicleevents import CONTROLLER_LINK
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
    caused_at: set[float] = set()  # the times of this read at which the vehicle said an event its controller caused
    for (child, r), t in zip(reports, times):
        if isinstance(r, Event) and child.name != "vehicle" and r.answers:
            t = max(t, *(max(vehicle_said.get(k, -math.inf), first.get(k, -math.inf)) for k in r.answers))
        rank = _rank(child, r)
        if rank == 2:
            caused_at.add(t)
        elif rank == 0 and t in caused_at:  # (said after one its controller caused: after it still)
            rank = 2
        timed.append((t, rank, child, r))
    for kind, t in last.items():
        vehicle_said[kind] = max(t, vehicle_said.get(kind, -math.inf))
    return [(child, report, t) for t, _, child, report in sorted(timed, key=lambda x: x[:2])]


def _rank(child: Child, report: Report) -> int:
    """Where ``report`` goes among its read's reports of its time (module docstring): 0 the vehicle's own, 1 the
    others' (the controller's acts), 2 the vehicle's caused by its controller (``by`` its link), 3 the controller's
    answers. The vehicle's events keep the order it said them in (:func:`in_cause_order` ranks one said after a
    caused one 2 too: the vehicle's pipe is in the order things happened on it)."""
    if child.name == "vehicle":
        return 2 if isinstance(report, Event) and report.by is not None and report.by.link == CONTROLLER_LINK else 0
    return 3 if isinstance(report, Event) and report.answers else 1
