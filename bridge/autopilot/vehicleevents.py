"""The vehicle's events and who caused them: the typed record every clock and process shares.

In:  what the vehicle did or was told to do (kind, text, plant time s) and its sender's ids and address
Out: :class:`Event` (t s, kind, text, :class:`Sender`, and its typed fields: a :class:`ParamChanged`, the mode,
     whether it acted on an armed vehicle, whether it was the ground-side arm before a mission's start);
     :func:`typed_fields`, those fields by name as they travel (JSON lines, summary.json); :func:`impact_text`, a
     hard touchdown's words
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class Sender:
    """Who caused an event: the sysid and compid of a command's sender, the address (``host``,
    ``port``) it came from and the link it came in on (``controller`` or ``gcs``); or the vehicle
    itself (:data:`ITSELF`: its own disarm after a failsafe landing, a divergence), with no ids."""

    sysid: int | None
    compid: int | None
    host: str | None
    port: int | None
    link: str

    @property
    def is_vehicle(self) -> bool:
        """Whether the vehicle decided it itself (no command, no sender on any link)."""
        return self.link == VEHICLE_LINK

    def __str__(self) -> str:
        """``SYSID:COMPID HOST:PORT LINK``, or ``vehicle``: as events.log and summary.json name it."""
        if self.is_vehicle:
            return VEHICLE_LINK
        return f"{self.sysid}:{self.compid} {self.host}:{self.port} {self.link}"

    @property
    def addr(self) -> tuple[str, int]:
        """(host, port) it sent from: where its answers go."""
        return (str(self.host), int(self.port or 0))

    @property
    def suffix(self) -> str:
        """`` [by ...]``: how a written event (events.log, summary.json) names its sender; never parsed back."""
        return f" [by {self}]"

    def as_dict(self) -> dict[str, int | str | None]:
        return {"sysid": self.sysid, "compid": self.compid, "host": self.host, "port": self.port, "link": self.link}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Sender:
        """The inverse of :meth:`as_dict`; ValueError (or KeyError, TypeError) for anything else."""
        link = str(d["link"])
        if link == VEHICLE_LINK:
            return ITSELF
        return cls(int(d["sysid"]), int(d["compid"]), str(d["host"]), int(d["port"]), link)


VEHICLE_LINK = "vehicle"
CONTROLLER_LINK = "controller"  # the link of a sender on the vehicle's own link (its controller's); else "gcs"
ITSELF = Sender(None, None, None, None, VEHICLE_LINK)  # the vehicle's own decision
TYPED_FIELDS = ("param", "mode", "armed", "pre_start", "gps")  # an event's typed fields (:class:`Event`), as it travels


def typed_fields(event: Any) -> dict[str, Any]:
    """The typed fields of an event (this :class:`Event`, a report's, a run's: each carries them), by name."""
    return {k: getattr(event, k) for k in TYPED_FIELDS}


@dataclass(frozen=True)
class ParamChanged:
    """A parameter the vehicle changed: its PX4 ``name``, the value it had (``old``) and has (``new``), as
    PARAM_VALUE reads them (an INT32's as a float)."""

    name: str
    old: float
    new: float

    def as_dict(self) -> dict[str, str | float]:
        return {"name": self.name, "old": self.old, "new": self.new}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> ParamChanged:
        """The inverse of :meth:`as_dict`; ValueError (or KeyError, TypeError) for anything else."""
        return cls(str(d["name"]), float(d["old"]), float(d["new"]))


@dataclass
class Event:
    """Something the vehicle did (or was told to do) at plant time ``t`` (s): its ``kind``
    (``armed``, ``disarmed``, ``mode``, ``failsafe``, ...), a human ``text``, and who caused it
    (``by``; None: not said, e.g. offline, where only the flight's own controller commands).

    What a reader judges by is in fields, never in the text: a ``param`` event's change (``param``:
    name, old and new value); a ``mode`` event's ``mode`` (the mode it is in after, or will arm in)
    and ``armed`` (it acted on an armed vehicle now; False: a selection for the next arm); an ``armed`` or
    ``disarmed`` event's ``pre_start`` (True: a ground station's arm in HOLD on the ground, awaiting a
    mission's start, or the vehicle's disarm when none came: nothing flown, part of the start, docs/missions.md); a
    ``fault`` event's ``gps`` (the GPS it leaves on, True, or off, False: a ``gps`` event's ``state``; None for any
    other fault: :func:`bridge.record.metrics.gps_outages` reads it)."""

    t: float
    kind: str
    text: str
    by: Sender | None = None
    param: ParamChanged | None = None
    mode: str | None = None
    armed: bool | None = None
    pre_start: bool | None = None
    gps: bool | None = None

    @property
    def shown(self) -> str:
        """The text as written to events.log and summary.json: with its sender's `` [by ...]``."""
        return self.text + (self.by.suffix if self.by is not None else "")


def impact_text(impact: tuple[float, float, float], armed: bool = True) -> str:
    """A hard touchdown (t s, speed m/s, tilt rad) as the ``crashed`` (or, disarmed, ``impact``) event's text."""
    text = f"hit the ground at {impact[1]:.2f} m/s, tilted {math.degrees(impact[2]):.1f} deg"
    return text if armed else f"{text} (disarmed, motors off)"
