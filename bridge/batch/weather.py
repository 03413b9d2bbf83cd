"""Each cell's air and timeline for the batch engine, as arrays: steady wind, gusts, turbulence and events.

In:  a batch's prepared flights (their ``wind``: :class:`plant.wind.WindConfig`, and ``timeline``:
     :class:`plant.events.TimedEvent` s) and its :class:`~bridge.link.plan.Clocks`
Out: :class:`Weather`: per cell whether it flies in air, its steady wind (m/s NWU), its gusts (t_s s, duration_s s,
     amplitude m/s, from_deg in rad), the turbulence it meets at each physics step (m/s NWU) and its events (the
     control step each acts at; a rotor's effectiveness 0..1, or the new steady wind m/s NWU), what
     :func:`bridge.batch.flight.fly_cells` flies through

One generator, not a twin: the turbulence's samples are those of the scalar plant's own :class:`plant.wind.Wind`
(:func:`plant.wind.turbulence_series`: the same configuration, seed and physics step), worked out before the
cells fly and read by the compiled flight at each physics step, where it adds them to the steady wind as
:meth:`plant.wind.Wind.now` does. An event acts at the control step :meth:`SimVehicle.advance
<bridge.autopilot.simvehicle.SimVehicle.advance>` acts on it (the same test on the same plant clock); a gust
event is a gust starting at that step's plant time, as :meth:`SimVehicle.inject
<bridge.autopilot.simvehicle.SimVehicle.inject>` adds it. The batch flies ``motor``, ``wind`` and ``gust``
events (:data:`bridge.batch.scope.BATCH_EVENT_KINDS`); the others are refused
(:func:`bridge.batch.scope.flights_problem`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from bridge.core.flight import Flight
from bridge.link.plan import Clocks
from plant.events import TimedEvent
from plant.wind import blowing, turbulence_series

EV_MOTOR, EV_WIND = 0.0, 1.0  # an event's kind in Weather.events[..., 0]
NO_STEP = np.iinfo(np.int64).max  # an event slot with nothing in it


class Weather(NamedTuple):
    """Every cell's air and events (the last fields of :class:`bridge.batch.flight.Cells`)."""

    windy: np.ndarray  # [n] bool: the cell flies in air (a [wind], or wind events)
    wind: np.ndarray  # [n, 3] its steady wind (m/s NWU), changed in flight by its wind events
    gusts: np.ndarray  # [n, G, 4] its gusts (t_s s, duration_s s, amplitude m/s, from_deg in rad)
    n_gusts: np.ndarray  # [n]
    turb_idx: np.ndarray  # [n] int64: its row of ``turb`` (-1: no turbulence)
    turb: np.ndarray  # [cells with turbulence, physics steps, 3] the turbulence at each physics step (m/s NWU)
    event_step: np.ndarray  # [n, E + 1] int64: the control step each event acts at, in order (NO_STEP: none)
    events: np.ndarray  # [n, E + 1, 4]: (EV_MOTOR, rotor index 0-3, effectiveness, 0) or (EV_WIND, wind m/s NWU)
    next_event: np.ndarray  # [n] int64: the cell's next event to act
    effectiveness: np.ndarray  # [n, 4] each rotor's, 0..1


def event_step(e: TimedEvent, clocks: Clocks) -> int:
    """The control step whose start acts on ``e``: the first whose plant time t satisfies SimVehicle.advance's
    ``ceil(t_s / period - 1e-9) * period <= t + h / 4`` (period = h * substeps, h the physics step)."""
    h = 1.0 / clocks.physics_hz
    period = h * clocks.substeps
    at = math.ceil(e.t_s / period - 1e-9) * period + 0.0
    starts = clocks.plant_t[:clocks.steps * clocks.substeps:clocks.substeps] + 0.25 * h
    return int(np.searchsorted(starts, at, side="left"))


def weather_arrays(flights: Sequence[Flight], clocks: Clocks) -> Weather:
    """The :class:`Weather` of a batch's flights (one mission and rate): zeros for a cell in still air."""
    n = len(flights)
    physics_steps = clocks.steps * clocks.substeps
    t_plant = clocks.plant_t
    gust_lists: list[list[tuple[float, float, float, float]]] = []
    timed: list[list[tuple[int, tuple[float, float, float, float]]]] = []
    for f in flights:
        gl = [(g.t_s, g.duration_s, g.amplitude_mps, math.radians(g.from_deg)) for g in f.wind.gusts] if f.wind else []
        ev: list[tuple[int, tuple[float, float, float, float]]] = []
        for e in f.timeline:
            k = event_step(e, clocks)
            if e.kind == "gust":  # a gust from the plant time of the step it acts at (SimVehicle.inject)
                gl.append((float(t_plant[min(k, clocks.steps) * clocks.substeps]), e.get("duration_s"),
                           e.get("amplitude_mps"), math.radians(e.get("from_deg"))))
            elif e.kind == "motor":
                ev.append((k, (EV_MOTOR, float(e.get("motor") - 1), float(e.get("effectiveness")), 0.0)))
            elif e.kind == "wind":
                ev.append((k, (EV_WIND, *blowing(e.get("speed_mps"), e.get("from_deg")))))
            else:
                raise ValueError(f"a {e.kind} event is not flown by the batch engine")
        gust_lists.append(gl)
        timed.append(ev)
    most_g = max([len(g) for g in gust_lists] + [1])
    most_e = max([len(e) for e in timed] + [1])
    wind, gusts, count = np.zeros((n, 3)), np.zeros((n, most_g, 4)), np.zeros(n, np.int64)
    # one slot more than the most events: a NO_STEP the compiled flight may always read at next_event
    steps, events = np.full((n, most_e + 1), NO_STEP, np.int64), np.zeros((n, most_e + 1, 4))
    turbulent = [i for i, f in enumerate(flights) if f.wind is not None and f.wind.turbulence != "none"]
    turb_idx = np.full(n, -1, np.int64)
    turb = np.zeros((max(len(turbulent), 1), physics_steps if turbulent else 1, 3))
    for r, i in enumerate(turbulent):
        f = flights[i]
        turb_idx[i] = r
        turb[r] = turbulence_series(f.wind, f.mission.seed, 1.0 / f.mission.physics_hz, physics_steps)
    for i, f in enumerate(flights):
        if f.wind is not None:
            wind[i] = blowing(f.wind.speed_mps, f.wind.from_deg)
        count[i] = len(gust_lists[i])
        for g, gust in enumerate(gust_lists[i]):
            gusts[i, g] = gust
        for s, (k, values) in enumerate(timed[i]):
            steps[i, s], events[i, s] = k, values
    return Weather(np.array([f.wind is not None for f in flights], bool), wind, gusts, count, turb_idx, turb, steps,
                   events, np.zeros(n, np.int64), np.ones((n, 4)))


def turbulent(flights: Sequence[Flight]) -> bool:
    """Whether any of the flights meets turbulence (its samples are held for the whole flight)."""
    return any(f.wind is not None and f.wind.turbulence != "none" for f in flights)


def faulty(flights: Sequence[Flight]) -> bool:
    """Whether any of the flights has a motor event (its rotors' speeds, not their wrench, are held)."""
    return any(e.kind == "motor" for f in flights for e in f.timeline)
