"""A mission's air and its timeline of events, checked against the vehicle that flies them.

In:  a :class:`~missions.Mission` (its raw ``[wind]`` table and ``[[events]]``: times s, speeds m/s, heights m), the
     flight's :class:`~plant.Profile`, its sensors (:class:`~plant.sensors.SensorConfig`) and estimator kind, whether
     it flies the profile's battery; an event's kind (a ground station's injection)
Out: the :class:`~plant.wind.WindConfig` (None: still air) and the validated timeline
     (:class:`~plant.events.TimedEvent`, s); the timeline's ``link`` events as the link model's handovers
     (:class:`~bridge.link.model.LinkConfig` up and down from a step's time, s); why an event cannot act on this
     vehicle (a line, or None); a bad event as an :class:`~plant.events.EventError` naming where it was given; why a
     swept steady wind would not be flown as swept (a line, or None)

Split out of :mod:`bridge.core.flight` (:func:`~bridge.core.flight.prepare` calls these in its turn): what the plant
flies through, and what a timeline's event may do to this vehicle, is here.
"""

from __future__ import annotations

from dataclasses import replace

from bridge.link.model import LinkConfig, link_from_table, unmet_key
from missions import Mission
from params import ConfigError, Table
from plant import Profile
from plant.events import (
    SENSOR_EVENT_KINDS,
    EventError,
    TimedEvent,
    at_first_step,
    check_state_changes,
    table_where,
    timeline_from_tables,
)
from plant.sensors import SensorConfig
from plant.wind import WindConfig, wind_from_table


def swept_replaced_problem(m: Mission, kind: str, each: str = "cell") -> str | None:
    """Why a swept steady wind (``kind`` ``wind``: a sweep's ``--wind``, ``bsst margin --over wind_mps``) or link
    (``link``: ``--delay``, ``--loss``, ...) would not be flown as swept on ``m`` (a line naming the event, or None):
    an event of that kind in its timeline sets the steady wind, or hands both directions' link over, itself, so from
    its step every ``each`` (a sweep's cell, a margin's probe) flies the event's whatever its own (a gust adds to the
    wind, and is kept)."""
    for e in timeline_from_tables(m.events, m.source, m.duration_s):
        if e.kind == kind == "wind":
            return (f"{table_where(m.source, e)} sets the steady wind from {e.t_s:g} s, so every {each} would fly "
                    f"that event's {e.get('speed_mps'):g} m/s from then, not its own: sweep the steady wind of a "
                    "mission without wind events (gusts add to it and are kept)")
        if e.kind == kind == "link":
            return (f"{table_where(m.source, e)} hands the link over ({e.text()}) from {e.t_s:g} s, so every {each} "
                    "would fly that link from then, not its own: sweep the link of a mission without link events")
    return None


def event_problem(kind: str, prof: Profile, sensors: SensorConfig | None, estimator: str = "ekf",
                  battery: bool = False) -> str | None:
    """Why an event of ``kind`` cannot act on this vehicle (``sensors`` None: the truth estimator, no sensor
    to fail; ``battery``: it flies the profile's pack, ``[effects] battery``), or None: a motor event needs rotors,
    a sensor event the vehicle's sensors, a GPS event a gnss set, a compass event a heading sensor, and an
    ``estimator`` that reads that sensor (``raw`` reads no barometer, nor a compass when its set measures the
    attitude: docs/sensors.md), a battery event a battery. The timeline's check, and a ground station's
    injection's."""
    if kind == "battery" and not (battery and prof.battery is not None):
        if prof.battery is None:
            return f"profile {prof.name!r} has no battery ([battery] table): fly --profile x500, [effects] battery"
        return "the vehicle flies no battery: set the mission's [effects] battery = true"
    if kind == "motor" and prof.actuation != "motors":
        return (f"profile {prof.name!r} flies ideal wrench actuation: it has no rotors to fail (fly --profile x500, "
                "or set the mission's actuation = \"motors\")")
    if kind in SENSOR_EVENT_KINDS and sensors is None:
        return ("the truth estimator reads the true state, no sensor to fail: fly --estimator ekf (or raw), with "
                "--sensors gnss or mocap")
    if kind == "gps" and sensors is not None and sensors.position_class != "gnss":
        return f"sensor set {sensors.name!r} has no GPS (its position is {sensors.position_class}): fly --sensors gnss"
    if kind == "mag" and sensors is not None and sensors.heading_rate_hz <= 0.0:
        return f"sensor set {sensors.name!r} has no magnetometer (heading_rate_hz = 0)"
    if estimator == "raw" and sensors is not None and (kind == "baro" or (kind == "mag" and
                                                                          sensors.position_class == "mocap")):
        what = "barometer" if kind == "baro" else f"compass (set {sensors.name!r} measures the attitude)"
        return f"the raw estimator never reads the {what}, so the fault would change nothing: fly --estimator ekf"
    return None


def weather_of(m: Mission, prof: Profile, sensors: SensorConfig, estimator: str,
               battery: bool = False) -> tuple[WindConfig | None, tuple[TimedEvent, ...]]:
    """The mission's ``[wind]`` (its turbulence at the reference's mean height unless ``altitude_m``; None: still
    air) and ``[[events]]``, validated and checked against the flight (``battery``: it flies the profile's pack,
    ``[effects] battery``): a motor event needs rotors, a sensor event the vehicle's sensors (an estimator other
    than truth), a GPS event a gnss set, a compass event a heading sensor, a battery event a battery; a wind or
    gust event with no ``[wind]`` flies the plant in (still) air."""
    src = m.source
    timeline = timeline_from_tables(m.events, src, m.duration_s)
    for e in timeline:
        why = event_problem(e.kind, prof, None if estimator == "truth" else sensors, estimator, battery)
        if why is not None:
            raise EventError(e, why, table_where(src, e))
    check_state_changes(timeline, m.rate_hz, src)  # an event that changes nothing, or two at one step: refused
    if not m.wind and not any(e.kind in ("wind", "gust") for e in timeline):
        return None, timeline
    wind = wind_from_table(Table(m.wind, src, "wind"), m.duration_s)
    if wind.altitude_m is None:  # the flight's altitude: the reference's mean height over the mission
        n = 100
        heights = [m.trajectory.sample(m.duration_s * k / n)[2][0] for k in range(n + 1)]
        wind = wind.at_altitude(max(sum(heights) / len(heights), 0.0))
    first = at_first_step(timeline, m.rate_hz, "wind")  # its steady wind is the one flown from the start: said
    if first is not None:
        wind = replace(wind, start=(first.get("speed_mps"), first.get("from_deg"), table_where(src, first)))
    return wind, timeline


GUARD_KEYS = ("stale_ms", "stop_ms", "compensation", "command_lag_ms")  # the controller's: not the link's to hand over


def handovers_of(timeline: tuple[TimedEvent, ...], m: Mission) -> tuple[tuple[float, LinkConfig, LinkConfig], ...]:
    """The timeline's ``link`` events as the link model's handovers: (the time of the control step it acts at,
    s; the up and down links from then), each a ``[link]`` table of its own (a profile and/or keys, unset keys
    at their defaults, the mission's seed) validated as the mission's is. The controller's guard stays the
    flight's: guard keys in a handover are refused, a profile's are not used."""
    out = []
    for e in timeline:
        if e.kind != "link":
            continue
        where = table_where(m.source, e)
        table = dict(e.settings)
        guard = [k for k in GUARD_KEYS if k in table]
        if guard:
            raise EventError(e, f"{guard[0]} is the controller's guard, not the link's: it stays the flight's "
                             f"([link] {guard[0]}); a handover changes the two directions only", where)
        try:
            ls = link_from_table(table, m.source, seed=m.seed, duration_s=m.duration_s)
        except ConfigError as exc:  # a key of the handover's own table, in the event's place; another file's whole
            own = exc.source == m.source and exc.what is not None
            raise EventError(e, (f"{exc.key}: {exc.what}" if exc.key else exc.what) if own else str(exc), where) \
                from None
        unmet = unmet_key(table)  # a handover's table is its own: a key of it that needs what it never gives
        if unmet:
            raise EventError(e, f"link.{unmet[0]}: {unmet[1]}", where)
        out.append((e.step(m.rate_hz) / m.rate_hz, ls.up, ls.down))
    return tuple(out)
