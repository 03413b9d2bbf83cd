"""The batch engine's flight: many cells of one mission flown at once, over a cell axis (numpy and numba).

In:  a mission (a :class:`~missions.Mission` or a TOML path) and, per cell, its
     :class:`~bridge.core.overrides.Overrides` (``controller``, ``discretization``, ``rate_hz`` Hz, ``seed``, a
     ``link`` table: what :func:`bridge.sweep.grid.cell_overrides` gives; or those fields as a mapping), or prepared
     :class:`~bridge.core.flight.Flight` s
Out: per cell the measured columns of a ``cells.csv`` row (:data:`MEASURES`: ``rms``/``max`` m,
     ``settling_s``/``flown_s`` s, ``tv_u2`` N/s, ``ripple_u2`` N, ``outcome``, packet counts, ``error``),
     the same numbers :func:`bridge.sweep.cells.row_from_run` takes from the scalar loop's run;
     :func:`batch_problem` says in one line why a set of cells cannot be flown here

The scalar loop (:func:`bridge.loop.fly`) stays the reference; this engine flies the same parts cell by
cell: the link model, the guard and the vehicle's timeout first, as a plan of the whole flight
(:func:`bridge.link.plan.plan_links`: with no bandwidth queue and no re-arming nothing of it depends
on the flight), then each cell's whole flight along it in one compiled call (:mod:`bridge.batch.flight`:
the wire, the prediction, the law and actuation, the physics steps, the failsafe landing, the running
figures), blocks of cells on ``jobs`` threads. The metrics are accumulated as the flight goes (running
sums and maxima, the last step outside the settling band), with one column kept whole, u2, for the
ripple of each cell's own second half; no trace is held.

Cells may differ in law (``bsst``, ``smc``, ``pid``), seed, control rate (flown as separate batches) and every
link setting but the bandwidth queue; they must share everything else (profile, effects, gains, trajectory,
duration, the battery too; each cell may have its own wind, turbulence, gusts and ``motor``, ``wind`` and
``gust`` events, or none: bridge.batch.weather). Not flown here (:func:`batch_problem`): a user's own law, the
bandwidth queue (``rate_bps``), a measured link ``trace``, ``[failsafe] resume``, any failsafe ``action`` but
``descend``, parameters changed in flight (``--param-at``), ``link`` events (a handover), and a mission ending in
a landing at a descent rate (MPC_LAND_SPEED) that may touch down hard, or after a motor fault (a landing on a weak
rotor: the x500 at 60 % crashed in it at 3.35 m/s): the scalar loop then flies its end landing and judges it (a
crash), which this engine, flying the mission's time only, cannot.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from bridge.batch.control import BATCH_LAWS
from bridge.batch.flight import Cells, Constants, batch_arrays, fly_cells
from bridge.batch.metrics import Metrics, measured_rows
from bridge.batch.weather import BATCH_EVENT_KINDS, turbulent
from bridge.core.flight import Flight, idle_link_key, prepare
from bridge.core.interrupt import sigint_futures, wait_or_interrupt
from bridge.core.overrides import Overrides
from bridge.link.model import NEEDS, jitter_cell, link_from_table, merge_link_tables
from bridge.link.plan import Clocks, plan_links
from bridge.record.metrics import RMS_FROM_S
from missions import MISSION_DIR, Mission, Sine, load_mission
from params import ConfigError
from params.text import one_line
from plant.quadrotor import CRASH_SPEED_MPS

# the columns of a cells.csv row this engine measures (the cell's own axes and seed come from the cell)
MEASURES = ("rms", "max", "settling_s", "tv_u2", "ripple_u2", "outcome", "up_sent", "up_lost", "down_sent",
            "down_lost", "flown_s", "error", "policies", "jitter_capped")
CELL_STEPS = 8_000_000  # cells x control steps in one batch: bounds its memory (1000 x 7500: 457 MiB peak RSS)
# cells x physics steps of a batch that meets turbulence (its samples, 3 floats a physics step, are held for the
# whole flight: bridge.batch.weather): 120 MiB of them (the 30 s sine at 1 kHz: 166 cells a batch)
TURBULENCE_STEPS = 5_000_000
# m/s: the fastest descent whose end landing cannot crash: the on-board landing touches down up to ~1.13 times
# faster than it sinks (docs/weather.md, "Outcomes"), a margin kept
END_LANDING_SAFE_MPS = CRASH_SPEED_MPS / 1.25
BLOCK_CELLS = 8  # cells a thread flies in one compiled call (~0.1 s of the 30 s sine): small enough to share out evenly
Progress = Callable[[int, int], None]  # (cells done, cells in all), now and then


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


def fly_batch(mission: Mission | str | Path, cells: Sequence[Overrides | Mapping[str, Any]], *,
              progress: Progress | None = None, jobs: int | None = None) -> list[dict[str, Any]]:
    """Fly every cell (the overrides of :func:`bridge.core.flight.prepare`) and return, in order, the
    measured columns (:data:`MEASURES`) of each one's ``cells.csv`` row; a cell that cannot be built gets
    outcome ``error`` and its message. ValueError (:func:`batch_problem`'s line) if the batch cannot fly them.
    ``jobs``: threads flying cells (default: every core); the rows do not depend on it."""
    m = mission if isinstance(mission, Mission) else load_mission(mission)
    built = _prepare_all(m, cells)
    flights = [f for f in built if isinstance(f, Flight)]
    results = iter(fly_flights(flights, progress=progress, total=len(built), jobs=jobs))
    return [{**next(results), "jitter_capped": jitter_cell(f.link.jitter_capped())} if isinstance(f, Flight)
            else error_measures(f) for f in built]


def compile_batch() -> None:
    """Compile, or load from numba's on-disk cache, this engine's kernels in this process, by flying a
    few steps of every kind of cell: each law, wrench (paper) and motors (x500), plant effects, a lossy
    delayed link with prediction. A first batch on a machine compiles them (~23 s of CPU here: the whole
    flight's kernel inlines its helpers); after it, ~1 s."""
    cells = [{"controller": law} for law in ("bsst", "smc", "pid")]
    cells.append({"link": {"delay_ms": 8.0, "loss_pct": 10.0, "compensation": "predict"}})
    x500 = load_mission(MISSION_DIR / "robust-x500.toml")
    for m in (Mission(Sine(), duration_s=0.1), replace(x500, duration_s=0.1)):
        fly_batch(m, cells)


def error_measures(why: str) -> dict[str, Any]:
    """The measured columns of a cell that could not be flown (outcome ``error``)."""
    out: dict[str, Any] = {c: None for c in MEASURES}
    out.update(outcome="error", error=one_line(why), policies="", jitter_capped="")
    return out


def fly_flights(flights: Sequence[Flight], *, progress: Progress | None = None,
                total: int | None = None, jobs: int | None = None) -> list[dict[str, Any]]:
    """Fly prepared flights (of one mission, see :func:`flights_problem`) on ``jobs`` threads (default: every
    core); the measured columns of each."""
    why = flights_problem(flights)
    if why:
        raise ValueError(why)
    out: list[dict[str, Any] | None] = [None] * len(flights)
    by_rate: dict[float, list[int]] = {}
    for i, f in enumerate(flights):
        by_rate.setdefault(f.mission.rate_hz, []).append(i)
    total = len(flights) if total is None else total
    done = total - len(flights)
    for idx in by_rate.values():
        f0 = flights[idx[0]]
        most = 1024
        if turbulent([flights[i] for i in idx]):
            most = TURBULENCE_STEPS // max(1, f0.mission.steps * f0.substeps)
        size = max(1, min(len(idx), CELL_STEPS // max(1, f0.mission.steps), most))
        for a in range(0, len(idx), size):
            part = idx[a:a + size]

            def report(k: int, of: int, base: int = done, n: int = len(part)) -> None:
                if progress is not None:
                    progress(base + n * k // max(of, 1), total)

            rows = _Batch([flights[i] for i in part]).fly(report, jobs or os.cpu_count() or 1)
            for i, r in zip(part, rows, strict=True):
                out[i] = r
            done += len(part)
            if progress is not None:
                progress(done, total)
    return [r for r in out if r is not None]


class _Batch:
    """One batch: flights of one mission and one control rate."""

    def __init__(self, flights: Sequence[Flight]) -> None:
        self.flights = list(flights)
        f0 = self.flights[0]
        m = f0.mission
        self.mission = m
        self.n = len(self.flights)
        self.clocks = Clocks(m.rate_hz, m.physics_hz, f0.substeps, m.steps)

    def fly(self, report: Callable[[int, int], None], jobs: int) -> list[dict[str, Any]]:
        fl = self.flights
        m = self.mission
        clocks = self.clocks
        steps = clocks.steps
        plan = plan_links([f.link for f in fl], [f.guard for f in fl], fl[0].failsafe.timeout_s, clocks, jobs)
        t_all = clocks.step_t
        c, a = batch_arrays(fl, plan, clocks, _references(m, t_all), lambda lag: _references(m, t_all + lag))
        _fly_blocks(c, a, steps, jobs, report)
        flown = a.flown
        outcome = np.where(a.diverged, "diverged", np.where(a.crashed, "crashed", np.where(
            plan.failsafe_step < flown, "failsafe", "completed")))
        met = Metrics(a.sq_sum, a.sq_max, a.last_out, a.tv, a.u2.T)  # u2 as the ripple reads it, [steps, n]
        rms_from = min(RMS_FROM_S, 0.5 * m.duration_s)
        return measured_rows(met, flown, outcome, plan.counts(flown), list(m.trajectory.change_times()), rms_from,
                             t_all, clocks.rate_hz)


def _fly_blocks(c: Constants, a: Cells, steps: int, jobs: int, report: Callable[[int, int], None]) -> None:
    """Fly every cell's whole flight, :data:`BLOCK_CELLS` at a time, on ``jobs`` threads (the kernel runs
    without the GIL); report (cells done, cells) as blocks end. Blocks are handed out as threads come
    free, so a core slowed by other work takes fewer; each cell flies alone, so the rows are the same."""
    n = a.X.shape[0]
    blocks = [(lo, min(n, lo + BLOCK_CELLS)) for lo in range(0, n, BLOCK_CELLS)]
    done = 0
    if jobs <= 1 or len(blocks) == 1:
        for lo, hi in blocks:
            fly_cells(lo, hi, 0, steps, c, a)
            done += hi - lo
            report(done, n)
        return
    # Ctrl-C raises between waits, never inside the pool's locks (bridge.core.interrupt)
    with sigint_futures() as sigint, ThreadPoolExecutor(min(jobs, len(blocks))) as pool:
        running = {pool.submit(fly_cells, lo, hi, 0, steps, c, a): hi - lo for lo, hi in blocks}
        try:
            while running:
                for f in wait_or_interrupt(running, sigint.first):
                    f.result()
                    done += running.pop(f)
                    report(done, n)
        finally:
            for f in running:
                f.cancel()


def _references(m: Mission, times: np.ndarray) -> np.ndarray:
    """[len(times), 4, 5]: the reference sample (x, y, z, psi; value and 4 derivatives) at each time."""
    sample = m.trajectory.sample
    return np.array([sample(float(t)) for t in times])


__all__ = ["CELL_STEPS", "MEASURES", "batch_problem", "error_measures", "flights_problem", "fly_batch",
           "fly_flights"]

