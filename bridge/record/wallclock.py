"""A lockstep SITL fleet's records as its separation judge takes them, and what it says of a vehicle that flew on.

In:  each vehicle's finished :class:`~bridge.record.runlog.Run` (its trace and end-landing rows at step j = row j,
     ``summary.json``'s ``sitl.gate.left``: the step it left the fleet's shared step clock and where it stayed,
     its ``outcome``, ``events``, ``lockstep``), its id, the control rate (Hz); the fleet's ``summary.json``
Out: :class:`FleetRecords`: each vehicle's end-landing rows to judge, where it stays after its rows (m, or
     :data:`~bridge.record.separation.NOWHERE`), the step after which its rows were flown on the wall clock;
     :func:`judged_on_wall_clock`: the fleet summary's ``separation.wall_clock`` (who flew on, from when to when,
     s, why, judged until when) and ``whole_flight``, and the ``separation`` policy not held when a vehicle was
     not judged over the whole flight; :func:`taken_over_records`: a real-time fleet's records, each vehicle a
     ground station took over and that flew on under it listed (its first intervention's step), for
     ``separation.taken_over``, and one disarmed in the air on the ground below its last row after it

A vehicle leaves the shared clock when its flight is over (its landing disarmed it, a disarm, a crash, a contact):
it stays where it left, as offline. It also leaves to fly on, on the wall clock: a ground station's mode (HOLD,
TAKEOFF, LAND, ...), or its controller silent (a failsafe landing still going at the mission's end). Those rows are
recorded, at the vehicle's own steps of 1 / rate s: they are judged against the others' rows of the same step (by
mission time, approximately, as a real-time fleet's; a contact there is found afterwards, not prevented). Where
such a record ends with the vehicle at rest (disarmed, crashed, its mission completed) it stays there; where it
ends in flight (its session stopped it still armed), its place after is not known: from then on it is not judged,
and the fleet summary says so, up to when, and why, and the ``separation`` policy does not hold.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from bridge.record.runlog import Run
from bridge.record.separation import NOWHERE

FLYING_ON = ("taken over by a ground station: the vehicle flies on under it, on the wall clock, recorded, until "
             "the rest of the fleet is done (docs/swarm.md)")  # (a fleet's session's event: bridge.session.fleet)
AT_REST = ("completed", "crashed", "diverged", "collision")  # outcomes after which the vehicle stays where it is
PLANT_ENDED = ("crashed", "diverged")  # its plant ended the flight (and disarmed it): it stays where it ended


@dataclass(frozen=True)
class Flown:
    """A vehicle that flew on, on the wall clock, after it left the shared clock at ``from_step``."""

    index: int  # in the fleet (from 0)
    id: int
    from_step: int
    last_step: int  # its record's last row
    why: str  # why it left (its session's ``lockstep.why``)
    at_rest: bool  # at rest where its record ends (else: its place after it is not known)


@dataclass(frozen=True)
class FleetRecords:
    """A lockstep fleet's records for :func:`~bridge.record.separation.judge_traces` (one entry a vehicle)."""

    afters: list[Sequence[Sequence[float]]]  # the end landing's rows to judge (m)
    finals: list[tuple[float, float, float] | None]  # where it stays after its rows (None: at its last row)
    walls: list[int | None]  # the step after which its rows were flown on the wall clock (None: none)
    ends: list[int]  # its record's last step
    flown: list[Flown]
    rate: float  # Hz

    def unjudged(self) -> list[tuple[Flown, int]]:
        """The vehicles whose record ended in flight while another's went on: each with the last step it is judged
        at (its record's last)."""
        out = []
        for f in self.flown:
            others = [e for j, e in enumerate(self.ends) if j != f.index]
            if not f.at_rest and f.last_step < max(others, default=0):
                out.append((f, f.last_step))
        return out


def _gate_left(run: Run) -> dict[str, Any] | None:
    return ((run.summary.get("sitl") or {}).get("gate") or {}).get("left")


def at_rest(summary: dict[str, Any]) -> bool:
    """Whether a session's vehicle was at rest when its record ended: its outcome one of :data:`AT_REST`, or its
    last word on arming ``disarmed``."""
    return summary.get("outcome") in AT_REST or _disarmed_last(summary)


def _disarmed_last(summary: dict[str, Any]) -> bool:
    said = [e["kind"] for e in summary.get("events") or () if e.get("source") == "vehicle"
            and e.get("kind") in ("armed", "disarmed")]
    return bool(said) and said[-1] == "disarmed"


def _disarmed_below(run: Run) -> tuple[float, float, float] | None:
    """Where a vehicle flown on the wall clock (real time, or a lockstep one that left the shared clock) and disarmed
    in the air stays after its record's last row (its last word on arming ``disarmed``, its plant not the one that
    ended it): on the ground below that row, as one on the shared clock stays
    (:func:`bridge.nodes.vehicle.gate.resting`; its rows end at the disarm, its fall is not recorded). None: at its
    last row (still armed, or ended by its plant: where it ended, in the air too, as offline)."""
    if run.summary.get("outcome") in PLANT_ENDED or not _disarmed_last(run.summary):
        return None
    if len(run.after):  # (its last row: the end action's after the trace's)
        x, y, z = run.after[-1]
    elif len(run.trace["t"]):
        x, y, z = run.trace["x"][-1], run.trace["y"][-1], run.trace["z"][-1]
    else:
        return None
    return float(x), float(y), min(float(z), 0.0)


def clocked_records(runs: Sequence[Run], ids: Sequence[int], rate: float) -> FleetRecords:
    """Each vehicle's record as the trace judge takes it (the module's docstring): on the shared clock to its end,
    its end landing up to the step it left and where it stayed (its gate's word), as offline; flown on after it,
    every row, and after them its last row (at rest; disarmed in the air, the ground below it: :func:`_disarmed_below`)
    or :data:`~bridge.record.separation.NOWHERE`."""
    afters: list[Sequence[Sequence[float]]] = []
    finals: list[tuple[float, float, float] | None] = []
    walls: list[int | None] = []
    ends: list[int] = []
    flown: list[Flown] = []
    for j, (r, i) in enumerate(zip(runs, ids)):
        left = _gate_left(r)
        rows = len(r.trace["t"]) + len(r.after)
        ends.append(rows - 1 if left is None else max(rows - 1, int(left["step"])))
        if left is None or rows - 1 <= int(left["step"]):  # on the shared clock to its end (as offline)
            cut = None if left is None else max(int(left["step"]) - len(r.trace["t"]), 0)
            afters.append(r.after if cut is None else r.after[:cut])
            finals.append(None if left is None else tuple(left["position"]))  # type: ignore[arg-type]
            walls.append(None)
            continue
        rest = at_rest(r.summary)
        why = (r.summary.get("lockstep") or {}).get("why") or "it left the shared clock"
        flown.append(Flown(j, i, int(left["step"]), rows - 1, why, rest))
        afters.append(r.after)
        finals.append(_disarmed_below(r) if rest else NOWHERE)
        walls.append(int(left["step"]))
    return FleetRecords(afters, finals, walls, ends, flown, rate)


def taken_over_records(runs: Sequence[Run], ids: Sequence[int], rate: float) -> FleetRecords:
    """A real-time fleet's records as the trace judge takes them: each on its own clock, to its end (its end
    action's rows after its trace's), staying at its last row after it; a vehicle a ground station took over that
    flew on under it (its session's ``sitl.flew_on``: :mod:`bridge.session.fleet`) is listed from its takeover (its
    first intervention's step) and, its record ended in flight, is :data:`~bridge.record.separation.NOWHERE` after
    it (its place not known); one disarmed in the air stays on the ground below its last row, as in lockstep."""
    finals: list[tuple[float, float, float] | None] = []
    ends: list[int] = []
    flown: list[Flown] = []
    for j, (r, i) in enumerate(zip(runs, ids)):
        last = len(r.trace["t"]) + len(r.after) - 1
        ends.append(last)
        on = bool((r.summary.get("sitl") or {}).get("flew_on"))
        rest = at_rest(r.summary)
        if on:
            first = (r.summary.get("interventions") or [{}])[0]
            flown.append(Flown(j, i, int(first.get("step", last)), last,
                               f"taken over by a ground station ({first.get('by', 'unknown')})", rest))
        finals.append(NOWHERE if on and not rest else _disarmed_below(r))
    return FleetRecords([r.after for r in runs], finals, [None] * len(runs), ends, flown, rate)


REALTIME = "approximately, as every vehicle of a real-time fleet: its rows matched to the others' by step"


def judged_on_wall_clock(summary: dict[str, Any], rec: FleetRecords, key: str = "wall_clock",
                         judged: str = "approximately: its rows matched to the others' by step (mission time)") -> None:
    """Say in the fleet's ``summary`` who flew on, on the wall clock (``key``: a lockstep fleet's ``wall_clock``, a
    real-time fleet's ``taken_over``), and how it was judged (``judged``; ``separation.whole_flight``); a vehicle not
    judged over the whole flight makes the ``separation`` policy not hold (``judged`` false, ``why``), unless it
    broke already (then ``judged`` false)."""
    rate = rec.rate
    short = dict((f.id, s) for f, s in rec.unjudged())
    sep = summary["separation"]
    sep[key] = [{"id": f.id, "from_step": f.from_step, "from_t": round(f.from_step / rate, 6),
                 "to_t": round(f.last_step / rate, 6), "why": f.why, "at_rest": f.at_rest, "judged": judged,
                 "judged_until_t": round(short[f.id] / rate, 6) if f.id in short else None}
                for f in rec.flown]
    sep["whole_flight"] = not short
    if not short:
        return
    last = max(rec.ends) / rate
    why = ("not judged over the whole flight: " + "; ".join(
        f"vehicle {f.id} only until t={s / rate:.3f} s, still flying when its record ended ({f.why}), while the "
        f"fleet's record goes on to t={last:.3f} s" for f, s in rec.unjudged()))
    policy = next(p for p in summary["policies"] if p["name"] == "separation")
    if policy["ok"]:
        policy.update(ok=False, t=round(min(short.values()) / rate, 6), why=why)
    policy.update(judged=False, not_judged=why)
