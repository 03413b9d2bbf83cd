"""A run's events as the record keeps them: typed, with their sender as a field.

In:  an event's time (s, the flight's clock: negative before its time 0), kind, text, who reported it
     (``source``: in a session the vehicle, the controller, the relay or the session; offline none), who caused
     it (``by``, a :class:`~bridge.autopilot.vehicleevents.Sender`, or None) and a parameter event's change
     (``param``, a :class:`~bridge.autopilot.vehicleevents.ParamChanged`: name, old and new value, or None)
Out: :class:`RunEvent`; its dict for ``summary.json["events"]`` (:meth:`RunEvent.as_dict`: ``t`` s rounded
     to 1 us or null, ``kind``, ``text`` with the sender shown as `` [by ...]``, ``source`` when there is one,
     ``param`` (``{name, old, new}``), ``mode``, ``armed``, ``pre_start`` and ``gps`` when the event has them);
     whether it came before the mission's time 0 (:attr:`RunEvent.before_start`); a run's events split there, into
     the mission's and those before it (:func:`split_at_start`: the one place a run's readers are told which is
     which); :func:`in_time_order`: events as recorded, in the order of their times

The written `` [by ...]`` is for people (events.log, summary.json); everything that judges a run reads
``by`` (:mod:`bridge.record.policies`), never the text.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from bridge.autopilot.vehicleevents import ParamChanged, Sender, typed_fields


@dataclass(frozen=True)
class RunEvent:
    """One event of a run: ``t`` (s, rounded to 1 us; None when it has no time on the flight's clock)."""

    t: float | None
    kind: str
    text: str
    source: str | None = None
    by: Sender | None = None
    param: ParamChanged | None = None  # the typed fields of the vehicle's events (bridge.autopilot.vehicleevents.Event)
    mode: str | None = None
    armed: bool | None = None
    pre_start: bool | None = None
    gps: bool | None = None  # a fault event's: the GPS it leaves on or off (a gps event's state)
    result: str | None = None  # a controller's ``end`` event's: its end-action command's answer (Event.result)

    @classmethod
    def at(cls, t: float, kind: str, text: str, source: str | None = None, by: Sender | None = None,
           **fields: Any) -> RunEvent:
        """The event at ``t`` (s): rounded to 1 us, None if not finite; ``fields``: its typed fields."""
        return cls(round(t, 6) if math.isfinite(t) else None, kind, text, source, by, **fields)

    @property
    def before_start(self) -> bool:
        """At a negative time: before the mission's time 0 (a session's events before an awaited mission's start,
        a ground station's flight among them: :mod:`bridge.record.missionclock`); not the mission's to judge."""
        return self.t is not None and self.t < 0.0

    @property
    def shown(self) -> str:
        """The text as written: with its sender's `` [by ...]`` when it names one."""
        return self.text + (self.by.suffix if self.by is not None else "")

    def as_dict(self) -> dict[str, Any]:
        """``summary.json["events"]``'s entry: ``t``, ``kind``, ``text`` (as shown) and ``source`` if any."""
        d: dict[str, Any] = {"t": self.t, "kind": self.kind, "text": self.shown}
        if self.source is not None:
            d["source"] = self.source
        d.update((k, v.as_dict() if isinstance(v, ParamChanged) else v)
                 for k, v in typed_fields(self).items() if v is not None)
        if self.result is not None:
            d["result"] = self.result
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> RunEvent:
        """An event as :meth:`as_dict` gave it (``by`` read only when given as an object: a written
        `` [by ...]`` stays text)."""
        by, param = d.get("by"), d.get("param")
        return cls(d.get("t"), d["kind"], d.get("text", ""), d.get("source"),
                   Sender.from_dict(by) if isinstance(by, Mapping) else None,
                   ParamChanged.from_dict(param) if isinstance(param, Mapping) else None,
                   mode=d.get("mode"), armed=d.get("armed"), pre_start=d.get("pre_start"), gps=d.get("gps"),
                   result=d.get("result"))


def split_at_start(events: Iterable[RunEvent]) -> tuple[list[RunEvent], list[RunEvent]]:
    """``events`` (in the order recorded) split at the mission's time 0: (the mission's: at or after it, or with no
    time; the hop's: before it, :attr:`RunEvent.before_start`: a ground station's own flight before an awaited
    mission's start, and in real time the mission's own arm, which may come just before its 0)."""
    mission: list[RunEvent] = []
    hop: list[RunEvent] = []
    for e in events:
        (hop if e.before_start else mission).append(e)
    return mission, hop


def in_time_order(events: Iterable[RunEvent]) -> list[RunEvent]:
    """``events`` (in the order recorded) sorted by their times, stably: events of one time keep the order recorded,
    so a cause recorded before its answer stays before it (a session never stamps an answer before its cause:
    :meth:`bridge.session.session.Session._handle`). An event with no time keeps its place after the one recorded
    before it. A session records its closing notes (``ended``, ``policy``, ...) last, at the trace's last row (with no
    row, at the latest event's: :func:`bridge.record.summary.notes_time`), which may come before the vehicle's end
    action (its landing, its disarm): here they take their place in time, as in events.log
    (:class:`bridge.record.runlog.EventLog`)."""
    timed, t = [], -math.inf
    for e in events:
        t = e.t if e.t is not None else t
        timed.append((t, e))
    return [e for _, e in sorted(timed, key=lambda x: x[0])]
