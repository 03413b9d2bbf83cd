"""A flight's timeline of events: faults and weather changes at mission times (pure; validated here).

In:  a mission's ``[[events]]`` tables (``t_s`` s, ``kind`` and its settings; a flag's also ``at``, the flag as
     typed, and a Python caller's ``at=`` table its place there, ``at[0]``) or ``--at T:KIND[:ARGS]`` flags
Out: frozen :class:`TimedEvent` s in time order, each with its TOML table (what ``mission.toml`` holds), the
     one-line text its ``events.log`` line carries and the ``--at`` flag or the ``at[i]`` that laid it (None: the
     mission's own)

The kinds, as a table and as a flag (units: s, m, m/s, rad/s; rotors numbered as eq. 4):

=========  ==============================================  =========================================
kind       table keys                                      flag ARGS
=========  ==============================================  =========================================
motor      ``motor`` 1-4, ``effectiveness`` 0..1 (0: off)  ``N=EFFECTIVENESS``
gps        ``state`` off|on, or ``jump`` [dx, dy, dz] m    ``off``, ``on``, ``jump=DX,DY,DZ``
baro       ``drift_mps`` (m/s of altitude error)           ``drift=M_PER_S``
mag        ``state`` off|on                                ``off``, ``on``
battery    ``state`` empty|ok: the pack reads empty (its       ``empty``, ``ok``
           voltage and charge as measured; the rotors still
           draw its real power), or as it is
gyro       ``bias`` [x, y, z] rad/s (added)                ``bias=X,Y,Z``
wind       ``speed_mps``, ``from_deg``                     ``SPEED[:FROM_DEG]``
gust       ``duration_s``, ``amplitude_mps``, ``from_deg``  ``DURATION,AMPLITUDE[,FROM_DEG]``
link       ``profile`` and/or ``[link]``'s per-direction    ``PROFILE``, ``KEY=VALUE,...`` or both
           keys: the link handed over to (checked by
           :func:`bridge.core.flight.prepare`)
=========  ==============================================  =========================================

An event acts at the start of the control step that begins at or after ``t_s``: the same step in every clock.
An event that could change nothing (a device set to the state it is already in, two setting one device at one
step) is refused: :func:`check_state_changes`.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

from params import ConfigError, Table, finite_float, show
from params.text import number

EVENT_KINDS = ("motor", "gps", "baro", "mag", "gyro", "battery", "wind", "gust", "link")
# the allowed range [lo, hi] of each number of an event's table (and of its --at flag, of [wind] and of a [wind]
# gust), one per key, and its unit (said with the range: range_problem); a vector key's range is each element's. A
# gust's key (GUST_AT_NOTHING) excludes its low end; a fault vector (FAULT_VECTORS) is not all 0
EVENT_RANGES: dict[str, tuple[float, float, str]] = {
    "motor": (1, 4, ""),
    "effectiveness": (0.0, 1.0, ""),
    "jump": (-1e4, 1e4, "m"),
    "drift_mps": (-100.0, 100.0, "m/s"),
    "bias": (-10.0, 10.0, "rad/s"),
    "speed_mps": (0.0, 50.0, "m/s"),
    "from_deg": (-360.0, 360.0, "deg"),
    "duration_s": (0.0, 600.0, "s"),
    "amplitude_mps": (0.0, 50.0, "m/s"),
    "altitude_m": (0.0, 1000.0, "m"),  # [wind]'s own (the height its turbulence is taken at; plant.wind.WIND_RANGES)
}
# the faults given as a vector that adds to what is there: (0, 0, 0) would inject nothing (a user's slip)
FAULT_VECTORS = {"jump": "a GPS jump", "bias": "a gyro bias"}
# a gust's keys whose low end (0) would inject nothing (a user's slip): what the key is, for the refusal
GUST_AT_NOTHING = {"duration_s": "duration", "amplitude_mps": "amplitude"}
SENSOR_EVENT_KINDS = ("gps", "baro", "mag", "gyro")
BATTERY_STATES = ("empty", "ok")  # a battery event's: the pack reads empty (PX4's injected failure), or as it is
LINK_SCALARS = (str, int, float)  # a handover's keys: a profile name and [link]'s per-direction scalars
# an event table's key for the --at flag that laid it ("T:KIND[:ARGS]", as typed): a run's mission.toml keeps it, so
# that the flight flown from that file (bsst sitl's children, a ground station's mission in its place) names the flag
AT_KEY = "at"
# ... or, for a table a Python caller laid (``at=({...},)``: bridge.core.overrides), its place there, as its refusals
# name it: ``at[0]`` (never a flag's text, which begins with a time); ASCII digits, no leading zero, as overrides
# writes it (``\d`` would take any script's digits)
CALLER_AT = re.compile(r"at\[(?:0|[1-9][0-9]*)\]")
LAID_FROM_PYTHON = "laid from Python"  # said beside a file's table whose at is a caller's place (CALLER_AT)


@dataclass(frozen=True, slots=True)
class TimedEvent:
    """One event of the timeline: at ``t_s`` (s), ``kind`` with its ``settings`` (key, value) pairs."""

    t_s: float
    kind: str
    settings: tuple[tuple[str, Any], ...]
    # the --at flag's T:KIND[:ARGS] that laid it, or a Python caller's table's place in at= (CALLER_AT); None: the
    # mission's own table
    at: str | None = field(default=None, compare=False)

    def get(self, key: str, default: Any = None) -> Any:
        return dict(self.settings).get(key, default)

    def step(self, rate_hz: float) -> int:
        """The control step it acts at (the first that begins at or after t_s)."""
        return math.ceil(self.t_s * rate_hz - 1e-9)

    def table(self) -> dict[str, Any]:
        """As a ``[[events]]`` table."""
        return {"t_s": self.t_s, "kind": self.kind, **{k: list(v) if isinstance(v, tuple) else v
                                                       for k, v in self.settings},
                **({AT_KEY: self.at} if self.at is not None else {})}

    def text(self) -> str:
        """What it does, for ``events.log``."""
        s = dict(self.settings)
        k = self.kind
        if k == "motor":
            e = s["effectiveness"]
            return f"motor {s['motor']}: {'off' if e == 0.0 else f'{e:g} of its thrust'}"
        if k in ("gps", "mag", "battery") and "state" in s:
            return f"{k} {s['state']}"
        if k == "gps":
            return "gps jump by ({:g}, {:g}, {:g}) m".format(*s["jump"])
        if k == "baro":
            return f"baro drifts {s['drift_mps']:g} m/s"
        if k == "gyro":
            return "gyro bias +({:g}, {:g}, {:g}) rad/s".format(*s["bias"])
        if k == "wind":
            return f"steady wind {s['speed_mps']:g} m/s from {s['from_deg']:g} deg"
        if k == "link":
            return "link handover to " + ", ".join(str(v) if n == "profile" else f"{n}={v:g}"
                                                   if isinstance(v, float) else f"{n}={v}" for n, v in self.settings)
        return f"gust {s['amplitude_mps']:g} m/s from {s['from_deg']:g} deg over {s['duration_s']:g} s"


class EventError(ConfigError):
    """An event that cannot be flown (bad input, one line): ``where`` it was given (the mission's ``events (t_s =
    T, kind = K)``, or the flag ``--at T:KIND[:ARGS]``: :func:`bridge.core.flight.prepare` names it, as it names
    a law's ``--controller``) and ``what`` is wrong with it."""

    def __init__(self, event: TimedEvent, what: str, where: str) -> None:
        self.event = event
        self.where = where
        super().__init__(f"{where}: {what}", what=what)


def ranged_number(t: Table, key: str, default: Any = ...) -> float:
    """``t``'s number ``key`` in its :data:`EVENT_RANGES` range, refused naming its unit (:func:`range_problem`): the
    one way an event's number, and ``[wind]``'s, is read."""
    big = t.raw(key) if t.has(key) else None
    if isinstance(big, int) and finite_float(big) is None and not isinstance(big, bool):  # past the float range
        raise t.error(key, range_problem(key, big) or "")  # (~1e308): out of the key's range, said as such
    v = t.number(key, default)  # a finite number; its range, with its unit, from the one table
    why = range_problem(key, v)
    if why:
        raise t.error(key, why)
    return v


def range_problem(key: str, v: float) -> str | None:
    """Why ``v`` is no value of ``key`` (its :data:`EVENT_RANGES` entry and unit; the low end of
    :data:`GUST_AT_NOTHING`'s excluded: a gust of no length or no amplitude injects nothing), or None: one text for
    an event's table, its ``--at`` flag and a ``[wind]`` gust, each naming the key before it."""
    lo, hi, unit = EVENT_RANGES[key]
    u = f" {unit}" if unit else ""
    got = f"{v:g}" if finite_float(v) is not None or isinstance(v, float) else show(v)  # an int past ~1e308: digits
    if key in GUST_AT_NOTHING:
        if v == lo:
            return f"a gust of {GUST_AT_NOTHING[key]} {lo:g}{u} injects nothing: {key} in ({lo:g}, {hi:g}]{u}"
        return None if lo < v <= hi else f"must be in ({lo:g}, {hi:g}]{u}, got {got}"
    return None if lo <= v <= hi else f"must be in [{lo:g}, {hi:g}]{u}, got {got}"


def start_problem(t_s: float, duration_s: float) -> str | None:
    """Why an event (or a ``[wind]`` gust) cannot start at ``t_s`` (s): [0, the mission's end), since one at the end
    would never act; or None."""
    return None if 0.0 <= t_s < duration_s else f"must be in [0, {duration_s:g}) s (before the mission's end), " \
                                                 f"got {t_s:g}"


def _fault_vector(t: Table, key: str) -> tuple[float, float, float]:
    """A fault's [x, y, z] (:data:`FAULT_VECTORS`), each element in its range, not all 0: a fault that injects
    nothing is refused, naming the key, its range and its unit."""
    lo, hi, unit = EVENT_RANGES[key]
    v = t.vector(key, 3)
    for i, x in enumerate(v):
        why = range_problem(key, x)
        if why:
            raise t.error(key, f"element {i} {why}")
    if not any(v):
        raise t.error(key, f"{FAULT_VECTORS[key]} of (0, 0, 0) {unit} injects nothing: x, y, z each "
                           f"in [{lo:g}, {hi:g}] {unit}, at least one not 0")
    return v  # type: ignore[return-value]


def event_from_table(t: Table, duration_s: float) -> TimedEvent:
    """Validate one ``[[events]]`` table; errors name the file and key."""
    t_s = t.number("t_s")
    why = start_problem(t_s, duration_s)
    if why:
        raise t.error("t_s", why)
    kind = t.string("kind", choices=EVENT_KINDS)
    s: dict[str, Any] = {}
    if kind == "link":  # the keys of the [link] table handed over to: the link model checks them (prepare)
        for key in sorted(k for k in t._data if k not in ("t_s", "kind")):
            v = t.raw(key)
            if isinstance(v, bool) or not isinstance(v, LINK_SCALARS):
                raise t.error(key, f"a link handover takes a profile and [link]'s scalar keys, got {v!r}"[:200])
            s[key] = v
        if not s:
            raise t.error("kind", "a link handover needs a profile or [link] keys (delay_ms, loss_pct, ...)")
    elif kind == "motor":
        lo, hi, _ = EVENT_RANGES["motor"]
        s["motor"] = t.integer("motor", lo=int(lo), hi=int(hi))
        s["effectiveness"] = ranged_number(t, "effectiveness")
    elif kind in ("gps", "mag"):
        if kind == "gps" and t.has("jump"):
            s["jump"] = _fault_vector(t, "jump")
        else:
            s["state"] = t.string("state", choices=("off", "on"))
    elif kind == "battery":
        s["state"] = t.string("state", choices=BATTERY_STATES)
    elif kind == "baro":
        s["drift_mps"] = ranged_number(t, "drift_mps")
    elif kind == "gyro":
        s["bias"] = _fault_vector(t, "bias")
    elif kind == "wind":
        s["speed_mps"] = ranged_number(t, "speed_mps")
        s["from_deg"] = ranged_number(t, "from_deg", 0.0)
    else:
        s["duration_s"] = ranged_number(t, "duration_s")
        s["amplitude_mps"] = ranged_number(t, "amplitude_mps")
        s["from_deg"] = ranged_number(t, "from_deg", 0.0)
    t.done()
    return TimedEvent(t_s, kind, tuple(s.items()))


def timeline_from_tables(tables: Sequence[Mapping[str, Any]], source: str, duration_s: float) -> tuple[TimedEvent, ...]:
    """Every ``[[events]]`` table validated, in time order (two at one time in the order given)."""
    out = []
    for i, raw in enumerate(tables):
        if not isinstance(raw, Mapping):
            raise ConfigError(f"{source}: events[{i}]: expected a table {{t_s, kind, ...}}, got {raw!r}"[:200])
        out.append(event_given(raw, source, f"events[{i}]", duration_s))
    return tuple(sorted(out, key=lambda e: e.t_s))


def event_given(raw: Mapping[str, Any], source: str, prefix: str, duration_s: float) -> TimedEvent:
    """One event's table validated (:func:`event_from_table`), its errors named where it was given: the ``--at``
    flag that laid it when it holds one (:data:`AT_KEY`, refused unless the table is that flag's event), else
    ``source: prefix``, with a Python caller's place in ``at=`` when it holds one (:data:`CALLER_AT`:
    ``m.toml: events[1] (at[0], laid from Python)``; ``source`` alone when ``prefix`` is empty, the caller's own
    ``at[0]``)."""
    if AT_KEY not in raw:
        return event_from_table(Table(raw, source, prefix), duration_s)
    t = Table(raw, source, prefix)
    text = t.string(AT_KEY)
    own = {k: v for k, v in raw.items() if k != AT_KEY}
    if CALLER_AT.fullmatch(text):  # a Python caller's table: named by its place in at=; read from a file (prefix),
        # by the file's table too, which a hand edit may have changed (nothing to check it against, as a flag's is)
        where = f"{source}: {prefix} ({text}, {LAID_FROM_PYTHON})" if prefix else source
        return replace(event_from_table(Table(own, where), duration_s), at=text)
    try:
        flagged = event_table_from_flag(text)
    except ValueError as exc:
        raise t.error(AT_KEY, f"not an --at flag's T:KIND[:ARGS] nor a place in at= (at[0]): {exc}"[:300]) from None
    if own.keys() != flagged.keys() or not all(_same(own[k], v) for k, v in flagged.items()):  # (a hand-edited
        # table: what it flies is not what the flag it names would)
        raise t.error(AT_KEY, f"the table is not the event --at {text} lays "
                              f"({', '.join(f'{k} = {v!r}' for k, v in flagged.items())}): give the flag's "
                              f"values, or drop {AT_KEY} (the table is then the mission's own)"[:300])
    return replace(event_from_table(Table(own, f"--at {text}"), duration_s), at=text)


def _same(a: Any, b: Any) -> bool:
    """``a == b``, a NaN the same as a NaN (a flag's ``nan``, refused by the ranges, not as a hand edit)."""
    return a == b or (isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b))


def table_where(source: str, e: TimedEvent) -> str:
    """Where a mission's event was given, as a refusal names it: the flag that laid it (``--at 10:gps:off``), else
    its table (``m.toml: events (t_s = 10, kind = gps)``), with a Python caller's place in ``at=`` when it holds one
    (``m.toml: events (t_s = 10, kind = gps; at[0], laid from Python)``)."""
    if e.at is not None and not CALLER_AT.fullmatch(e.at):
        return f"--at {e.at}"
    laid = f"; {e.at}, {LAID_FROM_PYTHON}" if e.at is not None else ""
    return f"{source}: events (t_s = {e.t_s:g}, kind = {e.kind}{laid})"


# the devices the timeline sets to a state, each with the state it starts every flight in: the GPS and the compass
# on, each rotor whole (effectiveness 1), the barometer not drifting (0 m/s)
_DEVICE_START = {"gps": "on", "mag": "on", "battery": "ok", "motor": 1.0, "baro": 0.0}
_DEVICE_NAMES = {"gps": "the GPS", "mag": "the compass", "battery": "the battery", "baro": "the barometer",
                 "wind": "the steady wind", "link": "the link"}
# the devices an event switches off or on: one that leaves it as it is was meant the other way (a rotor's or the
# barometer's value is a level: its baseline, 1 or 0, is a value a scripted series of flights gives too)
_SWITCHES = ("gps", "mag", "battery")


def at_first_step(timeline: Sequence[TimedEvent], rate_hz: float, kind: str) -> TimedEvent | None:
    """The first event of ``kind`` that acts at the flight's first control step (``t_s = 0``, step 0 at
    ``rate_hz``): what it sets (a steady wind, a link) is flown from the start, in place of the flight's own; None."""
    return next((e for e in timeline if e.kind == kind and e.step(rate_hz) == 0), None)


def device_set(e: TimedEvent) -> tuple[tuple[Any, ...], Any] | None:
    """(the device ``e`` sets, the state it sets it to), or None for an event that adds to what is there (a GPS jump,
    a gyro bias) or changes the air or the link."""
    if e.kind in ("gps", "mag", "battery") and e.get("state") is not None:
        return (e.kind,), e.get("state")
    if e.kind == "motor":
        return ("motor", e.get("motor")), e.get("effectiveness")
    if e.kind == "baro":
        return ("baro",), e.get("drift_mps")
    return None


def _already(device: tuple[Any, ...], state: Any) -> str:
    """``the GPS is already on``: a switched device already in a state."""
    return f"{_DEVICE_NAMES[device[0]]} is already {state}"


def _device_name(device: tuple[Any, ...]) -> str:
    return f"motor {device[1]}" if device[0] == "motor" else _DEVICE_NAMES[device[0]]


def check_state_changes(timeline: Sequence[TimedEvent], rate_hz: float, source: str) -> None:
    """EventError (named as :func:`table_where`, which :func:`bridge.core.flight.prepare` turns into the ``--at``
    flag that gave it) for an event of ``timeline`` (in time order) that switches the GPS, the compass or the
    battery to the state it is already in at that time, from the start or from the event before (``gps:on`` with
    no ``gps:off`` before it, two ``gps:off`` with no ``gps:on`` between), or one that sets a device (those, a rotor's
    effectiveness, the barometer's drift, the steady wind, the link) another event sets at the same control step of
    ``rate_hz`` (Hz), where only the order given would say which one holds."""
    last: dict[tuple[Any, ...], TimedEvent] = {}  # device -> the event that last set it
    for e in timeline:
        sets = device_set(e)
        if sets is None and e.kind in ("wind", "link"):  # the steady wind, the link: replaced whole, so two at one
            sets = (e.kind,), None                        # step race (never "already": not a switch)
        if sets is None:
            continue
        device, state = sets
        before = last.get(device)
        if before is not None and before.step(rate_hz) == e.step(rate_hz):
            raise EventError(e, f"{before.text()} at {before.t_s:g} s and {e.text()} at {e.t_s:g} s both set "
                                f"{_device_name(device)} at the control step at {e.step(rate_hz) / rate_hz:g} s "
                                f"({rate_hz:g} Hz), so which one holds is ambiguous: give one, or times a step "
                                f"({1.0 / rate_hz:g} s) apart", table_where(source, e))
        if device[0] in _SWITCHES:  # (a switch only: a level, the wind, the link may be set again as it is)
            was = _DEVICE_START[device[0]] if before is None else device_set(before)[1]  # type: ignore[index]
            if state == was:
                since = "as every flight starts" if before is None else f"since {before.text()} at {before.t_s:g} s"
                raise EventError(e, f"{_already(device, state)} at {e.t_s:g} s ({since}): the event would change "
                                    "nothing", table_where(source, e))
        last[device] = e


def _numbers(text: str, n: tuple[int, ...], what: str, shown: str | None = None) -> list[float]:
    """``text``'s comma-separated numbers, ``n`` of them, finite; ValueError naming ``shown`` (as typed: ``text``)."""
    parts = text.split(",")
    try:
        values = [number(p) for p in parts]
    except ValueError:
        values = []
    if len(values) not in n or not all(math.isfinite(v) for v in values):
        raise ValueError(f"expected {what}, got {text if shown is None else shown!r}")
    return values


def _scalar(text: str) -> int | float | str:
    """A flag's value as TOML would read it: an integer, a number, else the text."""
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def _link_args(args: str, text: str) -> dict[str, Any]:
    """``link:PROFILE``, ``link:KEY=VALUE,...`` or ``link:PROFILE,KEY=VALUE,...`` as a handover's keys."""
    out: dict[str, Any] = {}
    for part in (p.strip() for p in args.split(",") if p.strip()):
        key, eq, value = part.partition("=")
        if not eq:
            if "profile" in out:
                raise ValueError(f"expected link:PROFILE[,KEY=VALUE,...] with one profile, got {text!r}")
            out["profile"] = key
            continue
        out[key.strip()] = _scalar(value.strip())
    if not out:
        raise ValueError(f"expected link:PROFILE or link:KEY=VALUE,... (a link profile or [link] keys), got {text!r}")
    return out


def event_table_from_flag(text: str) -> dict[str, Any]:
    """``T:KIND[:ARGS]`` (``--at``) as an ``[[events]]`` table; ValueError saying what is wrong (ranges are
    checked by :func:`event_from_table`)."""
    t_text, _, rest = text.partition(":")
    kind, _, args = rest.partition(":")
    try:
        t_s = number(t_text)
    except ValueError:
        raise ValueError(f"expected T:KIND[:ARGS] with T in seconds, got {text!r}") from None
    if kind not in EVENT_KINDS:
        raise ValueError(f"unknown event kind {kind!r} in {text!r}; the kinds are {', '.join(EVENT_KINDS)}")
    out: dict[str, Any] = {"t_s": t_s, "kind": kind}
    key, eq, value = args.partition("=")
    if kind == "link":
        out.update(_link_args(args, text))
    elif kind == "motor":
        if not eq or not key.strip().isdigit():
            raise ValueError(f"expected motor:N=EFFECTIVENESS (N 1-4, 0..1), got {text!r}")
        out.update(motor=int(key), effectiveness=_numbers(value, (1,), "an effectiveness 0..1")[0])
    elif kind in ("gps", "mag") and args in ("off", "on"):
        out["state"] = args
    elif kind == "battery" and args in BATTERY_STATES:
        out["state"] = args
    elif kind == "gps" and key == "jump" and eq:
        out["jump"] = _numbers(value, (3,), "jump=DX,DY,DZ in m")
    elif kind == "baro" and key == "drift" and eq:
        out["drift_mps"] = _numbers(value, (1,), "drift=M_PER_S")[0]
    elif kind == "gyro" and key == "bias" and eq:
        out["bias"] = _numbers(value, (3,), "bias=X,Y,Z in rad/s")
    elif kind == "wind" and args:
        v = _numbers(args.replace(":", ","), (1, 2), "wind:SPEED[:FROM_DEG]", shown=args)
        out.update(speed_mps=v[0], from_deg=v[1] if len(v) > 1 else 0.0)
    elif kind == "gust" and args:
        v = _numbers(args, (2, 3), "gust:DURATION,AMPLITUDE[,FROM_DEG]")
        out.update(duration_s=v[0], amplitude_mps=v[1], from_deg=v[2] if len(v) > 2 else 0.0)
    else:
        forms = {"gps": "gps:off|on|jump=DX,DY,DZ", "baro": "baro:drift=M_PER_S", "mag": "mag:off|on",
                 "battery": "battery:empty|ok",
                 "gyro": "gyro:bias=X,Y,Z", "wind": "wind:SPEED[:FROM_DEG]",
                 "gust": "gust:DURATION,AMPLITUDE[,FROM_DEG]"}
        raise ValueError(f"expected {forms[kind]}, got {text!r}")
    return out
