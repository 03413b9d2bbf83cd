"""What the batch engine can fly, without numba: the check every ``--engine auto`` sweep makes, most of them small.

In:  a mission (a :class:`~missions.Mission` or a TOML path) and, per cell, its
     :class:`~bridge.core.overrides.Overrides` (``controller``, ``discretization``, ``rate_hz`` Hz, ``seed``, a
     ``link`` table: what :func:`bridge.sweep.grid.cell_overrides` gives; or those fields as a mapping), or prepared
     :class:`~bridge.core.flight.Flight` s
Out: :func:`batch_problem` (:func:`flights_problem` for prepared flights): in one line why a set of cells cannot be
     flown in the batch engine, or None; each cell's Flight as :func:`bridge.core.flight.prepare` builds it
     (:func:`_prepare_all`, which the engine flies)

Why apart from :mod:`bridge.batch.engine`: a sweep under ``--engine auto`` asks this before it counts its cells
(the reason it gives is what the batch cannot fly, ahead of "fewer than 32 cells"), and importing the engine
imports numba (~0.25 CPU-s), which a small grid, flown on the process engine, never uses. Nothing here imports it
(tests/test_sweep_engines.py checks a small sweep's process).

Cells may differ in law (``bsst``, ``smc``, ``pid``), seed, control rate (flown as separate batches) and every
link setting but the bandwidth queue; they must share everything else (profile, effects, gains, trajectory,
duration, the battery too; each cell may have its own wind, turbulence, gusts and ``motor``, ``wind`` and
``gust`` events, or none: bridge.batch.weather). Not flown there: a user's own law, the bandwidth queue
(``rate_bps``), a measured link ``trace``, ``[failsafe] resume``, any failsafe ``action`` but ``descend``,
parameters changed in flight (``--param-at``), ``link`` events (a handover), and a mission ending in a landing at a
descent rate (MPC_LAND_SPEED) that may touch down hard, or after a motor fault (a landing on a weak rotor: the x500
at 60 % crashed in it at 3.35 m/s): the scalar loop then flies its end landing and judges it (a crash), which the
batch engine, flying the mission's time only, cannot.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

from bridge.core.flight import Flight, idle_link_key, prepare
from bridge.core.overrides import Overrides
from bridge.link.model import NEEDS, link_from_table, merge_link_tables
from missions import Mission, load_mission
from params import ConfigError
from plant.quadrotor import CRASH_SPEED_MPS

BACKSTEPPING = ("bsst", "smc")  # the laws of controller.bsst (super-twisting or sign reaching)
BATCH_LAWS = (*BACKSTEPPING, "pid")  # the built-in laws the batch flies (bridge.batch.control)
BATCH_EVENT_KINDS = ("motor", "wind", "gust")  # the timeline's kinds the batch engine flies (bridge.batch.weather)
CELL_STEPS = 8_000_000  # cells x control steps in one batch: bounds its memory (1000 x 7500: 457 MiB peak RSS)
# m/s: the fastest descent whose end landing cannot crash: the on-board landing touches down up to ~1.13 times
# faster than it sinks (docs/weather.md, "Outcomes"), a margin kept
END_LANDING_SAFE_MPS = CRASH_SPEED_MPS / 1.25


def batch_problem(mission: Mission | str | Path, cells: Sequence[Overrides | Mapping[str, Any]]) -> str | None:
    """Why these cells cannot fly in the batch engine, in one line; None if they can.

    ``cells``: per cell the overrides of :func:`bridge.core.flight.prepare` (a cell whose overrides are
    bad input is no reason: it becomes an ``error`` row, as in the process engine)."""
    m = mission if isinstance(mission, Mission) else load_mission(mission)
    return flights_problem([f for f in _prepare_all(m, cells) if isinstance(f, Flight)])


def flights_problem(flights: Sequence[Flight]) -> str | None:
    """:func:`batch_problem` for prepared flights."""
    first: Flight | None = None
    for f in flights:
        m = f.mission
        if m.controller not in BATCH_LAWS:
            return (f"controller {m.controller!r}: the batch engine flies only the built-in laws "
                    f"({', '.join(BATCH_LAWS)}); a law of your own needs the process engine")
        for d, cfg in (("up", f.link.up), ("down", f.link.down)):
            if cfg.rate_bps:
                return f"link {d}.rate_bps = {cfg.rate_bps:g}: the bandwidth queue is not in the batch engine"
            if cfg.trace is not None:
                return f"link {d}.trace: replaying a measured trace is not in the batch engine"
        if f.estimator != "truth":  # the batch plant has no sensors: it would fly the truth and say otherwise
            return (f"[estimator] kind = {f.estimator!r}: sensors and the on-board estimator are not in the batch "
                    f"engine; it flies only 'truth'")
        if f.param_changes:
            return ("--param-at: parameters changed during the flight are not in the batch engine")
        other = [e.kind for e in f.timeline if e.kind not in BATCH_EVENT_KINDS]
        if other:
            return (f"a {other[0]} event ([[events]] or --at): the batch engine flies the timeline's "
                    f"{', '.join(BATCH_EVENT_KINDS)} events only")
        if f.failsafe.resume:
            return "[failsafe] resume = true: re-arming after a failsafe is not in the batch engine"
        if f.failsafe.action != "descend":
            return f"[failsafe] action = {f.failsafe.action!r}: the batch engine flies only the default, 'descend'"
        if m.geofence is not None or f.params.max_hor_m > 0.0 or f.params.max_ver_m > 0.0:
            return ("a geofence ([geofence], a plan's geoFence, GF_MAX_HOR_DIST or GF_MAX_VER_DIST): the batch engine "
                    "keeps no trace to judge a cell's policies by, so a cell that left it would read as flown")
        if f.effects.battery and (f.effects.battery_start_pct < 100.0 or f.params.low_battery_action):
            return ("the battery's levels ([effects] battery_start_pct below 100, or COM_LOW_BAT_ACT > 0): the "
                    "vehicle's battery failsafe is not in the batch engine")
        if m.end_action == "land" and f.failsafe.descent_rate > END_LANDING_SAFE_MPS:
            return (f"[failsafe] descent_rate (MPC_LAND_SPEED) {f.failsafe.descent_rate:g} m/s: the mission's end "
                    f"landing may touch down faster than {CRASH_SPEED_MPS:g} m/s, a crash the process engine judges "
                    "and the batch engine (no end action) cannot")
        if m.end_action == "land" and any(e.kind == "motor" and e.get("effectiveness") < 1.0 for e in f.timeline):
            return ("a motor fault ([[events]] or --at) before the mission's end landing: a landing on a weak rotor "
                    "may touch down hard, a crash the process engine judges and the batch engine (no end action) "
                    "cannot")
        air = air_at_end(f) if m.end_action == "land" else None
        if air:
            return (f"{air} at the mission's end: its end landing in wind may touch down hard or tilted, a crash the "
                    "process engine judges and the batch engine (no end action) cannot (a mission that ends "
                    "in a hold, [end] action = \"hold\", flies in the batch)")
        if m.steps > CELL_STEPS:
            return f"the mission has {m.steps} control steps: more than the batch engine holds ({CELL_STEPS})"
        if first is None:
            first = f
            continue
        why = _differs(first, f)
        if why:
            return f"the cells differ in {why}: a batch flies one mission with per-cell law, seed, rate and link"
    return None


def air_at_end(f: Flight) -> str | None:
    """What of the air still blows as the flight's mission time ends (its end landing flies in it): turbulence, a
    steady wind (the ``[wind]`` speed or the last ``wind`` event's, m/s), or a gust not over by then (of ``[wind]``
    or an event); None in still air there."""
    w, end = f.wind, f.mission.duration_s
    if w is not None and w.turbulence != "none":
        return f"{w.turbulence} turbulence"
    steady = w.speed_mps if w is not None else 0.0
    gusts = [(g.t_s, g.duration_s) for g in w.gusts] if w is not None else []
    for e in f.timeline:  # (in time order)
        if e.kind == "wind":
            steady = e.get("speed_mps")
        elif e.kind == "gust":
            gusts.append((e.t_s, e.get("duration_s")))
    if steady > 0.0:
        return f"a steady wind of {steady:g} m/s"
    late = sorted(t for t, d in gusts if t + d > end)
    return f"a gust from t = {late[0]:g} s not over" if late else None


def _differs(a: Flight, b: Flight) -> str | None:
    ma, mb = a.mission, b.mission
    for what, x, y in (("trajectory", ma.trajectory, mb.trajectory), ("duration_s", ma.duration_s, mb.duration_s),
                       ("physics_hz", ma.physics_hz, mb.physics_hz), ("start", ma.start, mb.start),
                       ("start_scatter_m", ma.start_scatter_m, mb.start_scatter_m),
                       ("profile", a.profile, b.profile), ("effects", a.effects, b.effects),
                       ("gains", a.gains, b.gains), ("failsafe", a.failsafe, b.failsafe)):
        if x != y:
            return what
    return None


_PER_CELL = frozenset({"seed", "link"})  # what a cell may change without its own prepare()
# a base is prepared as if every need of a mission's [link] key were met: each cell's is checked on its own, as
# prepare() checks it (idle_link_key), since the cells' link tables give them
_ALL_NEEDS = tuple(need for need, *_ in NEEDS.values())


def _prepare_all(mission: Mission, cells: Sequence[Overrides | Mapping[str, Any]]) -> list[Flight | str]:
    """Each cell's Flight, as :func:`prepare` builds it; a cell that cannot be built gives its error's text.

    prepare() parses the profile and builds the law (milliseconds each), so it runs once per distinct
    law, rate and discretization; each cell then gets what prepare() does with a seed and a ``link`` table: the mission
    with that seed and the table laid over ``[link]``, and that ``[link]`` validated (tests/test_batch.py
    checks the result equals prepare()'s, cell by cell)."""
    bases: dict[tuple[Any, ...], Flight | str] = {}
    out: list[Flight | str] = []
    for given in cells:
        try:
            over = Overrides.of(given)
            if not set(over.given()) <= _PER_CELL | {"controller", "rate_hz", "discretization"}:
                out.append(prepare(mission, over))
                continue
            key = (over.controller, over.rate_hz, over.discretization)
            if key not in bases:
                try:
                    bases[key] = prepare(mission, Overrides(controller=key[0], rate_hz=key[1], discretization=key[2]),
                                         axes=_ALL_NEEDS)
                except Exception as exc:  # the cell's law or rate is bad input: every such cell says so
                    bases[key] = f"{type(exc).__name__}: {exc}"
            base = bases[key]
            if isinstance(base, str):
                out.append(base)
                continue
            unmet = idle_link_key(mission, over.link)
            if unmet:
                raise ConfigError(unmet)
            out.append(_with_seed_and_link(base, mission, over.seed, over.link))
        except Exception as exc:  # a cell that cannot be built is an error row, never the end of the batch
            out.append(f"{type(exc).__name__}: {exc}")
    return out


def _with_seed_and_link(base: Flight, mission: Mission, seed: int | None, link: Mapping[str, Any] | None) -> Flight:
    """``prepare(mission, controller=…, rate_hz=…, seed=seed, link=link)`` from that prepare() without them."""
    if seed is None and not link:
        return base
    merged = merge_link_tables(mission.link, link) if link else None
    m = base.mission.with_overrides(seed=seed, link=merged)
    return replace(base, mission=m, link=link_from_table(m.link, m.source, seed=m.seed, duration_s=m.duration_s))


__all__ = ["BATCH_EVENT_KINDS", "BATCH_LAWS", "CELL_STEPS", "air_at_end", "batch_problem", "flights_problem"]
