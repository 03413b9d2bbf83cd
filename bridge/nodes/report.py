"""What a child process (vehicle, controller, relay) reports to the session: one JSON object a line.

In:  a report (one frozen dataclass per :class:`Kind`) to write; a line read back from a child's stdout
Out: :func:`to_line`: ``{"report": KIND, ...fields}`` on one line (no newline); :func:`parse_line`: the
     report again, or None for a line that is not one (not JSON, an unknown kind, a missing field)

The kinds, and their fields (times in s of the flight's clock, to the millisecond):

- ``ready``: the child is up, bound, its clock chosen (:class:`Ready`: which node, its addresses);
- ``event``: something happened (:class:`Event`: ``t`` s, ``kind``, ``text``, ``by`` the
  :class:`~bridge.autopilot.vehicleevents.Sender` that caused it, as an object, or null; a vehicle's
  ``param`` event its change, ``param`` (``{name, old, new}``), a ``mode`` event its ``mode`` and ``armed``,
  else null);
- ``statustext``: a STATUSTEXT the controller received (:class:`StatusText`: MAV_SEVERITY, text);
- ``warning``: what the receive path refused lately (:class:`Warning`,
  :meth:`bridge.mavlink.receive.Rejections.report`);
- ``refused``: a command or parameter the vehicle refused, and why (:class:`Refused`);
- ``stats``: the child's counts on exit (:class:`Stats`, a JSON object; the keys per child are
  :func:`bridge.nodes.offboard.run_controller`'s and the vehicle's);
- ``mission``: the controller has a ground station's mission (``bsst controller --await-mission``) and wrote it
  as flown into its directory (:class:`MissionLoaded`: its name, items, the download's figures);
- ``done``: the controller's outcome (:class:`Done`: ``completed``, ``failsafe``, ``diverged`` or
  ``aborted``; whether the vehicle left lockstep; why it gave up; the mode a ground station took it into; whether
  it heard nothing from the vehicle at the end);
- ``bad_input``: the child's command refused its input, exit 2 (:class:`BadInput`: the refusal, ``text``, and the
  typed fields of its :class:`params.ConfigError`, ``source``, ``key``, ``what``): written by :func:`bridge.cli.main`
  beside the line on stderr, which stays the person's (the session raises it again from these fields, never from
  that line's text).

This module is the one place that reads them: the session never looks inside a report's text.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field, fields
from enum import StrEnum
from typing import Any

from bridge.autopilot.vehicleevents import Event as VehicleEvent
from bridge.autopilot.vehicleevents import ParamChanged, Sender, typed_fields
from params import ConfigError


class Kind(StrEnum):
    READY = "ready"
    EVENT = "event"
    STATUSTEXT = "statustext"
    WARNING = "warning"
    REFUSED = "refused"
    STATS = "stats"
    DONE = "done"
    MISSION = "mission"
    BAD_INPUT = "bad_input"


@dataclass(frozen=True)
class Ready:
    """A child is up. ``node``: ``vehicle``, ``controller`` or ``relay``; the rest as the node has them:

    - vehicle: ``listen`` (HOST:PORT of its controller link), ``gcs`` (HOST:PORT of its GCS link, or None) and
      ``gcs_mode`` (``udpout``: it sends its telemetry there; ``udpin``: it is bound there, the port it got, and a
      ground station sends to it first), ``sysid``, ``clock`` (``lockstep``/``realtime``), ``profile``,
      ``controller_from`` (the one address it hears its controller from, or None);
    - controller: ``vehicle`` (HOST:PORT it sends to), ``local`` (its own), ``clock``;
    - relay: ``listen`` (its front), ``to`` (where it forwards), ``back`` (the port it forwards from),
      ``client`` (the controller side, or None: the first sender), ``up`` and ``down`` (each direction's
      link model, described).
    """

    node: str
    listen: str | None = None
    gcs: str | None = None
    gcs_mode: str | None = None
    sysid: int | None = None
    clock: str | None = None
    profile: str | None = None
    controller_from: str | None = None
    vehicle: str | None = None
    local: str | None = None
    to: str | None = None
    back: str | None = None
    client: str | None = None
    up: str | None = None
    down: str | None = None

    def describe(self) -> str:
        """One line for a person (the session's ``started`` event): the relay's as it says it,
        the others' as ``key=value`` pairs of what they have."""
        if self.node == "relay":
            ends = f"client {self.client}" if self.client else "client: the first sender"
            return (f"listening on {self.listen} -> {self.to} from {self.back} ({ends}); "
                    f"up: {self.up}; down: {self.down}")
        return " ".join(f"{f.name}={v}" for f in fields(self)[1:] if (v := getattr(self, f.name)) is not None)


@dataclass(frozen=True)
class Event:
    """An event at ``t`` (s, to the millisecond: :meth:`at`) of ``kind``, its ``text``, who caused it, and
    the typed fields of the vehicle's events (:class:`bridge.autopilot.vehicleevents.Event`: a parameter
    event's change, ``param``; a mode event's ``mode`` and ``armed``; an arm's ``pre_start``; a fault's ``gps``).
    ``answers``: a
    controller's event said in answer to the vehicle's own events of these kinds (its arming, its end action, its
    crash): the session never puts it before its cause, whatever the two clocks say
    (:meth:`bridge.session.session.Session._handle`). ``result``: the controller's ``end`` event that says how the
    vehicle answered its end-action command, that answer (``accepted``, ``no answer``, ``MAV_RESULT 4``:
    :func:`bridge.record.ending.end_not_taken` reads it); None on every other event."""

    t: float
    kind: str
    text: str
    by: Sender | None = None
    param: ParamChanged | None = None
    mode: str | None = None
    armed: bool | None = None
    pre_start: bool | None = None
    gps: bool | None = None
    answers: tuple[str, ...] | None = None
    result: str | None = None

    @classmethod
    def at(cls, t: float, kind: str, text: str, by: Sender | None = None, **fields: Any) -> Event:
        """The event at ``t`` rounded to the millisecond: the resolution every child reports at."""
        return cls(float(f"{t:.3f}"), kind, text, by, **fields)

    @classmethod
    def of(cls, e: VehicleEvent) -> Event:
        """The report of one of the vehicle's events (at the millisecond, with its fields)."""
        return cls.at(e.t, e.kind, e.text, e.by, **typed_fields(e))


@dataclass(frozen=True)
class StatusText:
    """A STATUSTEXT received from the vehicle: its MAV_SEVERITY and text."""

    severity: int
    text: str


@dataclass(frozen=True)
class Warning:  # noqa: A001 - the report's name; the builtin is not used here
    """What the receive path refused since the last warning (one line, counts by reason)."""

    text: str


@dataclass(frozen=True)
class Refused:
    """A command or parameter refused, and why."""

    text: str


@dataclass(frozen=True)
class Stats:
    """A child's counts on exit (a JSON object; the keys are the child's)."""

    values: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class Done:
    """The controller's outcome; ``left_lockstep``: the vehicle left lockstep during the flight;
    ``reason``: why it ended other than completed (None: it completed, or said nothing); ``taken_over``:
    the mode a ground station switched the armed vehicle to, when that ended the flight (else None); ``silent``: it
    ended hearing nothing from the vehicle for its vehicle timeout (a lockstep fleet's vehicle is then frozen:
    :mod:`bridge.session.alone`)."""

    outcome: str
    left_lockstep: bool = False
    reason: str | None = None
    taken_over: str | None = None
    silent: bool = False


@dataclass(frozen=True)
class MissionLoaded:
    """The controller downloaded a ground station's mission and wrote ``mission.plan`` and ``mission.toml``
    (``name``: the mission's, ``items``: its items, ``transfer``: the download's figures, as
    :class:`~bridge.mavlink.missionitems.TransferStats` holds them)."""

    name: str
    items: int
    transfer: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class BadInput:
    """The child's command refused its input (exit 2): the refusal as :class:`params.ConfigError` says it
    (``text``: its ``str()``, without the ``bsst: `` a person's line opens with) and its typed fields (``source``:
    what the text opens with, a file, a flag or a command, ``bsst relay``; ``key``; ``what``: the bare reason; None
    where the refusal did not set them). :meth:`error` is that refusal again, in the session's process."""

    text: str
    source: str | None = None
    key: str | None = None
    what: str | None = None

    @classmethod
    def of(cls, exc: ConfigError) -> BadInput:
        return cls(str(exc), exc.source, exc.key, exc.what)

    def error(self) -> ConfigError:
        return ConfigError(self.text, source=self.source, key=self.key, what=self.what)


Report = Ready | Event | StatusText | Warning | Refused | Stats | Done | MissionLoaded | BadInput
KIND_OF: dict[type, Kind] = {Ready: Kind.READY, Event: Kind.EVENT, StatusText: Kind.STATUSTEXT,
                             Warning: Kind.WARNING, Refused: Kind.REFUSED, Stats: Kind.STATS, Done: Kind.DONE,
                             MissionLoaded: Kind.MISSION, BadInput: Kind.BAD_INPUT}
_CLASS_OF = {k: c for c, k in KIND_OF.items()}


def to_line(report: Report) -> str:
    """The report as one JSON object on one line (no newline): ``{"report": KIND, ...fields}``."""
    body: dict[str, Any] = {"report": KIND_OF[type(report)].value}
    for f in fields(report):
        v = getattr(report, f.name)
        body[f.name] = v.as_dict() if isinstance(v, (Sender, ParamChanged)) else v
    return json.dumps(body, separators=(",", ":"))


def parse_line(line: str) -> Report | None:
    """The report a line holds, or None when it holds none (not JSON, an unknown kind, a missing or
    mistyped field)."""
    text = line.strip()
    if not text.startswith("{"):
        return None
    try:
        body = json.loads(text)
        cls = _CLASS_OF[Kind(body.pop("report"))]
        if cls is Event and body.get("by") is not None:
            body["by"] = Sender.from_dict(body["by"])
        if cls is Event and body.get("param") is not None:
            body["param"] = ParamChanged.from_dict(body["param"])
        if cls is Event and isinstance(body.get("answers"), list):
            body["answers"] = tuple(body["answers"])
        report = cls(**body)
    except (ValueError, KeyError, TypeError, AttributeError):
        return None
    return report if _well_typed(report) else None


def _well_typed(report: Report) -> bool:
    """Whether the fields a reader relies on have their types (a JSON line is anyone's to write)."""
    if isinstance(report, Event):
        return (_number(report.t) and isinstance(report.kind, str) and isinstance(report.text, str)
                and (report.mode is None or isinstance(report.mode, str))
                and (report.armed is None or isinstance(report.armed, bool))
                and (report.pre_start is None or isinstance(report.pre_start, bool))
                and (report.gps is None or isinstance(report.gps, bool))
                and (report.result is None or isinstance(report.result, str))
                and (report.answers is None or (isinstance(report.answers, tuple)
                                                and all(isinstance(k, str) for k in report.answers))))
    if isinstance(report, Stats):
        return isinstance(report.values, dict)
    if isinstance(report, Done):
        return (isinstance(report.outcome, str) and (report.reason is None or isinstance(report.reason, str))
                and isinstance(report.silent, bool))
    if isinstance(report, StatusText):
        return isinstance(report.severity, int) and isinstance(report.text, str)
    if isinstance(report, Ready):
        return isinstance(report.node, str)
    if isinstance(report, MissionLoaded):
        return isinstance(report.name, str) and isinstance(report.items, int) and isinstance(report.transfer, dict)
    if isinstance(report, BadInput):
        return isinstance(report.text, str) and all(v is None or isinstance(v, str)
                                                    for v in (report.source, report.key, report.what))
    return isinstance(report.text, str)


def _number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)
