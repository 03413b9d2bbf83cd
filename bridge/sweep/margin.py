"""``bsst margin``: how much of one link impairment, of sensor noise, or of steady wind a law takes
before it fails, found by bisection instead of a grid.

In: a mission, the swept axis (``delay_ms`` | ``loss_pct`` | ``jitter_ms`` | ``burst_len``,
applied to both directions as a sweep's axes are, or ``noise``: the scale of every sigma of the
mission's sensor set, flown with its estimator, or ``wind_mps``: the steady wind's speed, from the
mission's ``[wind] from_deg``, with its turbulence), the failure criterion (``rms=X``: the 3-D
RMS error passes X m; ``class=NAME``: the cell's class is NAME or worse, see
:mod:`bridge.sweep.classes`), the laws, the seeds and the band checked below the margin (axis unit).
Out: per law the margin (the largest value flown that did not fail, in the axis's unit), its bracket
``[margin, first failing value]``, ``monotone``, ``failed_below`` and ``holds_below`` (the check
below it), and every cell flown; ``margin.json`` when a directory is given (the search's fields, then one
entry per law under ``controllers``, whatever their number: docs/campaigns.md, "margin.json"). Stopped by
Ctrl-C: :class:`MarginInterrupted`, a KeyboardInterrupt that carries the same content for what was flown
(``interrupted`` true; each law's ``interrupted_in``, its bracket so far, no margin its bisection did not reach).

A law that could not be flown at a value (a cell ``law_failed``, or ``error``: e.g. its worker process died)
measured nothing there: not a boundary. Its search ends at that cell, its ``error`` says where and why, its
margin is None; the other laws' searches go on (``laws_failed`` names it; ``bsst margin`` exits 1). A cell
``denied`` (the mission's vehicle is not armed) is the mission's fault, at any value: ConfigError.

A value fails when any of its seeds fails. The search first doubles from ``start`` until it
finds a failing value (or reaches the axis's range), then halves the bracket until it is no
wider than ``resolution``. All laws' probes of one round fly together, with their seeds, as
one batch (:mod:`bridge.batch`) where it can fly them (a round of one cell too), one by one otherwise.

The bisection assumes that failure is monotonic in the axis (more delay is never better); it need
not be (the sine's delay fails at 34.25-35 ms, holds at 35.25-36 and fails from 36.25). So after it,
every value of ``[margin - below, margin)`` at ``resolution`` steps that was not flown yet is flown
(one more round, all laws and seeds together; ``below`` defaults to ``BELOW_STEPS`` x ``resolution``,
0 skips it): ``monotone`` says whether every value flown below the margin held, ``failed_below``
lists those that did not, and ``holds_below`` is the largest value flown such that every value
flown at or below it held (the margin when monotone). ``margin`` stays the bisection's answer.

Ctrl-C (SIGINT) stops the search only while a round flies (bridge.core.interrupt.sigint_deferred; one that
lands between rounds stops it before the next): a round on the process pool lets its cells in flight finish, a
second Ctrl-C ends them; a cell flown in this process stops at once and is not a result (its row ``aborted``);
the batch engine stops once its compiled call returns. The rows flown before it are kept: a value a seed failed
at is the bracket's top (a value fails when any seed fails), a value every seed held at its bottom, and a value
some seeds held at, with others not flown, is neither. The content then says ``interrupted``, each law's
``interrupted_in`` (``bisection``: no margin, the bracket so far; ``below``: the margin, its check not flown to
the end, ``monotone`` false if a value failed in the part flown, else null), and :class:`MarginInterrupted`
carries it.

Over ``noise`` the batch engine cannot fly the cells (it has no sensors): every probe is a
scalar flight on the process engine, one at a time for one law and seed (a pool costs more
than a few cells), so keep ``seeds`` and the laws few. Noise needs an estimator that reads
the sensors (``raw`` or ``ekf``; ``truth`` ignores them) and a set with noise to scale. Over
``wind_mps`` the batch engine flies the probes (steady wind, and the mission's turbulence if it has one) of a
mission that ends in a hold; one that ends in a landing flies them on the process engine, which judges a landing
in wind (:func:`bridge.batch.scope.air_at_end`).
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from numbers import Real
from operator import itemgetter
from pathlib import Path
from typing import Any

from bridge.core.flight import noise_problem, prepare
from bridge.core.interrupt import Deferred, sigint_deferred
from bridge.core.weather import swept_replaced_problem
from bridge.link.model import NEEDS, idle_problem
from bridge.record.runlog import run_dir, write_json_atomic
from bridge.sweep.cells import FAILED, broke_policy, seeds_alike
from bridge.sweep.classes import CLASSES, Classes, classify
from bridge.sweep.executors import Report, engine_for, run_batch, run_cell, run_local
from bridge.sweep.grid import LINK_AXES, RANGES, Cell, cell_flight, link_trace, mission_value
from bridge.sweep.spec import check_jobs
from controller.law import LawError, is_builtin
from missions import Mission, load_mission
from params import ConfigError
from params.text import number

OVER = (*LINK_AXES, "noise", "wind_mps")  # the axes a margin is searched over
# first value tried; noise: the set's own sigmas (1), so a set that holds them takes 1, 2, 4, ... up to the
# range's top (plant.profiles.NOISE_SCALE_RANGE, 100): at most 8 doublings and 8 halvings at 0.25 per law and seed
# wind: 4, 8, 16, 32, 50 m/s (the range's top), then halvings: about 12 probes per law and seed at 0.25 m/s
START = {"delay_ms": 16.0, "loss_pct": 10.0, "jitter_ms": 16.0, "burst_len": 4.0, "noise": 1.0, "wind_mps": 4.0}
MARGIN_JSON = "margin.json"
IN_PROCESS_CELLS = 2  # a round of at most this many process-engine cells flies in this process
MAX_HALVINGS = 24  # the finest --resolution is an axis's range / 2^24 (delay: 3.6 us, loss: 6e-6 %)
RESOLUTION_TOP = 1e6  # the coarsest (the flag's own top)
BELOW_STEPS = 16  # the monotonicity check's default band: the bisection's bracket four halvings before its end
MAX_BELOW = 1024  # the widest band, in resolution steps
MAX_SEEDS = 1000  # seeds per value (--seeds)


@dataclass(frozen=True)
class Until:
    """The failure criterion: ``rms`` (m) passed, or a class at least as bad as ``cls``."""

    rms: float | None = None
    cls: str | None = None

    def __post_init__(self) -> None:
        """One made in Python is checked as ``--until`` is (:func:`parse_until`): one of the two, a positive RMS, a
        class worse than clean. (Until(cls="foo") raised a bare ValueError after its first round had flown.)"""
        if (self.rms is None) == (self.cls is None):
            raise ConfigError(f"until: give one of rms=METRES or cls=NAME, got {self!r}")
        if self.rms is not None and (isinstance(self.rms, bool) or not isinstance(self.rms, Real)
                                     or not (math.isfinite(self.rms) and self.rms > 0)):
            raise ConfigError(f"until.rms: must be a positive number of metres, got {self.rms!r}"[:200])
        if self.cls is not None and (not isinstance(self.cls, str) or self.cls not in CLASSES[1:]):
            raise ConfigError(f"until.cls: must be one of {', '.join(CLASSES[1:])}, got {self.cls!r}"[:200])

    def failed(self, row: dict[str, Any], classes: Classes) -> bool:
        """Whether a probe's row fails: the criterion, or a safety policy its run broke (its ``policies``
        column names one: a probe that left its geofence does not hold, whatever its RMS)."""
        if row["outcome"] == "denied":  # its vehicle is not armed, at any value, for any law: the mission's fault
            raise ConfigError(f"margin: a cell could not be flown: {row.get('error')}")
        if row["outcome"] in FAILED:  # the law failed, or its worker died: Search.take ends that law's search
            return True
        if broke_policy(row):
            return True
        if self.rms is not None:
            rms = row["rms"]
            return rms is None or not math.isfinite(rms) or rms > self.rms or row["outcome"] != "completed"
        return CLASSES.index(classify(row, classes)) >= CLASSES.index(self.cls or "error")

    def text(self) -> str:
        return f"rms={self.rms:g}" if self.rms is not None else f"class={self.cls}"


def parse_until(text: str) -> Until:
    """``rms=0.1`` or ``class=limit-cycling`` (ConfigError naming ``--until`` otherwise)."""
    key, sep, value = text.partition("=")
    if sep and key.strip() == "rms":
        try:
            v = number(value)
        except ValueError:
            v = math.nan
        if not (math.isfinite(v) and v > 0):
            raise ConfigError(f"--until rms=X: X must be a positive number of metres, got {value!r}")
        return Until(rms=v)
    if sep and key.strip() == "class":
        name = value.strip()
        if name not in CLASSES or name == "clean":
            raise ConfigError(f"--until class=NAME: NAME must be one of {', '.join(CLASSES[1:])}, got {name!r}")
        return Until(cls=name)
    raise ConfigError(f"--until must be rms=METRES or class=NAME, got {text!r}")


@dataclass
class Search:
    """One law's bracket: ``lo`` flown and held (``held``; until then the range's low end, not flown),
    ``hi`` flown and failed (None: not found yet)."""

    controller: str
    lo: float
    hi: float | None = None
    cells: list[dict[str, Any]] = field(default_factory=list)
    held: bool = False
    error: dict[str, Any] | None = None  # the first cell that could not be flown: the search ended there
    bisecting: bool = True  # false once its bisection has ended (bracketed, at the range's top, or an error)

    def next_value(self, resolution: float, top: float) -> float | None:
        if self.hi is None:
            nxt = min(max(2.0 * self.lo, self.lo + resolution), top)
            return None if nxt <= self.lo else nxt
        mid = 0.5 * (self.lo + self.hi)
        if self.hi - self.lo <= resolution or not self.lo < mid < self.hi:  # no float left between: done too
            # every value flown failed: fly the range's low end itself (once) rather than claim that it holds
            return self.lo if not self.held and self.hi > self.lo else None
        return mid

    def record(self, value: float, failed: bool) -> None:
        """``value`` was flown: it failed (the bracket's new top) or held (its new bottom)."""
        if failed:
            self.hi = value
        else:
            self.lo, self.held = value, True

    def take(self, over: str, value: float, rows: list[dict[str, Any]], until: Until, classes: Classes,
             phase: str) -> bool:
        """Record this law's cells of ``value`` among ``rows`` (``phase``: bisection | below); whether it failed."""
        mine = [r for r in rows if r["controller"] == self.controller and r[over] == value]
        # (each cell says the wind, link and noise it flew, not the searched axis alone: forty-fifth session)
        cells = [{over: value, **{a: r[a] for a in OVER if a != over}, "seed": r["seed"], "rms": r["rms"],
                  "outcome": r["outcome"],
                  "class": classify(r, classes), "failed": until.failed(r, classes), "phase": phase,
                  "error": r.get("error") or "", "policies": r.get("policies") or "",
                  "jitter_capped": r.get("jitter_capped") or ""} for r in mine]
        self.cells += cells
        unflown = [c for c in cells if c["outcome"] in FAILED]
        if unflown and self.error is None:  # the law failed (or its worker died): it measured nothing there
            c = unflown[0]
            self.error = {over: value, "seed": c["seed"], "outcome": c["outcome"], "phase": phase,
                          "error": c["error"] or c["outcome"]}
        return any(c["failed"] for c in cells)

    def band(self, over: str, below: float, resolution: float, floor: float) -> list[float]:
        """The values of ``[margin - below, margin)`` at ``resolution`` steps (not under ``floor``) not flown yet."""
        if not self.held or below <= 0 or self.error is not None:
            return []
        flown = {c[over] for c in self.cells}
        steps = int(math.floor(below / resolution + 1e-9))
        values = (self.lo - k * resolution for k in range(1, steps + 1))
        return [v for v in values if v >= floor and v not in flown]

    def below(self, over: str, checked: list[float] | None) -> dict[str, Any]:
        """The monotonicity fields of ``margin.json``: ``monotone`` (None: not checked), ``failed_below``
        (the values under the margin that failed), ``holds_below``, ``checked_below`` (the band flown)."""
        if not self.held:
            return {"monotone": None, "failed_below": [], "holds_below": None, "checked_below": None}
        failed = {c[over] for c in self.cells if c["failed"]}
        flown = sorted({c[over] for c in self.cells if c[over] <= self.lo})
        holds = None
        for v in flown:
            if v in failed:
                break
            holds = v
        under = sorted(v for v in failed if v < self.lo)
        monotone = False if under else None if checked is None else True  # (a failure: also in a band cut short)
        return {"monotone": monotone, "failed_below": under, "holds_below": holds, "checked_below": checked}

    def short_of(self, over: str, values: list[float], seeds: int) -> list[float]:
        """The values of ``values`` that this law has flown with fewer than ``seeds`` seeds."""
        return [v for v in values if sum(1 for c in self.cells if c[over] == v) < seeds]


def resolution_range(over: str) -> tuple[float, float]:
    """The ``--resolution`` a search over ``over`` takes: at least its range / 2^MAX_HALVINGS, so that the
    bisection ends within MAX_HALVINGS rounds (and the doubling within log2(top / start) before it)."""
    lo, top = RANGES[over]
    return (top - lo) * 2.0 ** -MAX_HALVINGS, RESOLUTION_TOP


def _called_with(mission: Mission | str | Path, until: Until | str, controllers: object, seeds: object,
                 resolution: object, below: object) -> tuple[Mission, Until]:
    """The mission (a path is loaded, as :func:`bridge.sweep.sweep` takes one) and the criterion (a string is
    ``--until``'s) of a Python call, its other arguments checked as their flags are: a ConfigError or TypeError
    naming the argument. (``seeds=0`` flew nothing and claimed the axis's whole range; ``controllers="smc"`` flew
    law 's'; a string ``until`` raised an AttributeError after its first round.)"""
    if isinstance(mission, str | os.PathLike):
        mission = load_mission(mission)
    elif not isinstance(mission, Mission):
        raise TypeError(f"mission: expected a Mission or a path to its file, got {mission!r}"[:200])
    if isinstance(until, str):
        until = parse_until(until)
    elif not isinstance(until, Until):
        raise TypeError(f"until: expected an Until or 'rms=METRES' / 'class=NAME', got {until!r}"[:200])
    if controllers is not None and (isinstance(controllers, str) or not isinstance(controllers, Sequence)
                                    or not controllers or not all(isinstance(c, str) for c in controllers)):
        raise TypeError(f"controllers: expected a list of law names (['bsst', 'smc']), got {controllers!r}"[:200])
    if isinstance(seeds, bool) or not isinstance(seeds, int) or not 1 <= seeds <= MAX_SEEDS:
        raise ConfigError(f"seeds: must be a whole number in [1, {MAX_SEEDS}], got {seeds!r}"[:200])
    for name, value in (("resolution", resolution), ("below", below)):
        if (value is not None or name == "resolution") and (isinstance(value, bool) or not isinstance(value, Real)):
            raise TypeError(f"{name}: expected a number, got {value!r}"[:200])
    return mission, until


def margin(mission: Mission | str | Path, over: str, until: Until | str, *, controllers: Sequence[str] | None = None,
           seeds: int = 1, resolution: float = 0.25, classes: Classes | Mapping[str, float] | None = None,
           jobs: int | None = None, engine: str = "auto", progress: Callable[[str], None] | None = None,
           below: float | None = None) -> dict[str, Any]:
    """Search the margin of each law, then check the band ``below`` it (default ``BELOW_STEPS`` x
    ``resolution``, 0: no check; see the module docstring); the ``margin.json`` content. Ctrl-C:
    :class:`MarginInterrupted`, carrying the content of what was flown."""
    if over not in OVER:
        raise ConfigError(f"--over must be one of {', '.join(OVER)}, got {over!r}")
    mission, until = _called_with(mission, until, controllers, seeds, resolution, below)
    check_jobs(jobs)
    least, most = resolution_range(over)
    if not least <= resolution <= most:  # also refuses nan
        raise ConfigError(f"--resolution must be in [{least:.3g}, {most:g}] for --over {over} (its range "
                          f"[{RANGES[over][0]:g}, {RANGES[over][1]:g}] in at most {MAX_HALVINGS} halvings), "
                          f"got {resolution:g}")
    below = BELOW_STEPS * resolution if below is None else below
    if not (math.isfinite(below) and 0 <= below <= MAX_BELOW * resolution):
        raise ConfigError(f"--check-below must be in [0, {MAX_BELOW} x --resolution = {MAX_BELOW * resolution:g}] "
                          f"(at most {MAX_BELOW} values per law and seed), got {below:g}")
    classes = Classes.of(classes)
    lo_range, top = RANGES[over]
    laws = list(controllers or (mission.controller,))
    # the mission's own [link]: a profile's delay is searched over (the probe's value replaces it), a link event is
    # refused as such below
    base = {a: float(mission_value(mission, a, with_profile=False, events=False) or 0.0) for a in LINK_AXES}
    if over in LINK_AXES and base[over]:
        raise ConfigError(f"margin over {over}: the mission's [link] already sets {over} = {base[over]:g}; "
                          "search from a mission without it")
    own_wind = mission_value(mission, "wind_mps", events=False)  # [wind]'s own: a wind event is named below
    if over == "wind_mps" and own_wind:
        raise ConfigError(f"margin over wind_mps: the mission's [wind] already sets speed_mps = {own_wind:g}; "
                          "search from a mission without it")
    kind = "wind" if over == "wind_mps" else "link" if over in LINK_AXES else None
    why = swept_replaced_problem(mission, kind, "probe") if kind else None
    if why:  # every probe would fly the event's wind or link from its step: a margin of the event's, not the searched
        raise ConfigError(f"margin over {over}: {why}"[:400])
    flight = prepare(mission, axes=(over,))  # (a [link] key the searched value gives its need is not idle)
    trace = link_trace(flight) if over in LINK_AXES else None
    if trace:
        raise ConfigError(f"margin over {over}: {mission.source} replays the link trace {trace}, which gives the "
                          f"link's {', '.join(LINK_AXES)}: {over} cannot be searched over it; search from a mission "
                          "without the trace, or over noise or wind_mps")
    if over == "noise":
        why = noise_problem((flight.estimator,), prepare(mission, noise=1.0).sensors)  # the set's own sigmas
        if why:
            raise ConfigError(f"margin over noise: {why}")
    why = idle_problem(over, (flight.link.up, flight.link.down)) if over in NEEDS else None
    if why:  # every probe would fly the same flight: a margin of the whole range, measured of nothing
        raise ConfigError(f"margin over {over}: changes nothing: {why}; give the mission a {NEEDS[over][0]} (or "
                          f"--loss PCT)")
    # every column but the searched one as the probe flies it: the link laid over its profile and a t = 0 event's
    # wind or link (as a sweep's unswept columns; 0 m/s and no profile in every cell until the forty-fifth session)
    base = {a: float(mission_value(mission, a) or 0.0) for a in LINK_AXES}
    vehicle = {"estimator": flight.estimator, "noise": mission_value(mission, "noise"),
               "turbulence": mission_value(mission, "turbulence"), "wind_mps": mission_value(mission, "wind_mps")}
    seed_list = [mission.seed + i for i in range(seeds)]
    for c in laws:  # each law's file, module and class before any cell flies (as a sweep's validate does)
        try:
            cell_flight(mission, probe(mission, c, over, START[over], mission.seed, base, vehicle))
        except LawError:  # named where it was given: --controller, or the mission's controller key
            raise
        except ConfigError as exc:  # the probe's own values (the search's first) with the mission's
            raise ConfigError(f"margin over {over}: its first probe ({over} = {START[over]:g}) cannot be flown: "
                              f"{exc}") from None
    searches = [Search(c, lo_range) for c in laws]
    probes = Probes(mission, over, base, vehicle, seed_list, engine, jobs)
    with sigint_deferred() as deferred:  # Ctrl-C taken while a round flies, never in the bookkeeping between
        cells_flown, interrupted = bisect(searches, probes, until, classes, resolution, top, deferred, progress)
        bands = {s.controller: s.band(over, below, resolution, lo_range) for s in searches}
        if any(bands.values()) and not interrupted:
            if progress is not None:
                n = sum(map(len, bands.values()))
                each = f" ({n * len(seed_list)} cells: {len(seed_list)} seeds each)" if len(seed_list) > 1 else ""
                progress(f"checking {n} values below the margin{'s' if len(searches) > 1 else ''}{each}")
            rows, interrupted = probes.fly(bands, deferred)
            cells_flown += len(rows)
            for s in searches:
                for v in bands[s.controller]:
                    s.take(over, v, rows, until, classes, "below")
        stopped = {s.controller: "bisection" if s.bisecting else
                   "below" if interrupted and s.short_of(over, bands[s.controller], len(seed_list)) else None
                   for s in searches} if interrupted else {}
        checked = {s.controller: [max(s.lo - below, lo_range), s.lo] if s.held and below > 0 and s.error is None
                   and not stopped.get(s.controller) else None for s in searches}
        result = {"over": over, "until": until.text(), "resolution": resolution, "check_below": below,
                  "seeds": seed_list, "start_scatter_m": mission.start_scatter_m,  # 0: one start, every seed
                  "mission": mission.name, "cells_flown": cells_flown, "estimator": flight.estimator,
                  "sensors": flight.sensors.name, "interrupted": interrupted,
                  "laws_failed": [s.controller for s in searches if s.error is not None],
                  "controllers": [entry(s, over, checked[s.controller], stopped.get(s.controller))
                                  for s in searches]}
    if interrupted:
        raise MarginInterrupted(result)
    return result


class MarginInterrupted(KeyboardInterrupt):
    """Ctrl-C stopped :func:`margin`: ``result`` is the ``margin.json`` content of what it flew (``interrupted``
    true). A KeyboardInterrupt: a caller that does not catch it stops as before."""

    def __init__(self, result: dict[str, Any]) -> None:
        super().__init__(f"margin search interrupted after {result['cells_flown']} cells")
        self.result = result


@dataclass(frozen=True)
class Probes:
    """What every probe of one search shares (the mission, the axis, the other axes' values, the seeds) and how a
    round of them flies (``engine``, ``jobs``)."""

    mission: Mission
    over: str
    link: dict[str, float]
    vehicle: dict[str, Any]
    seeds: list[int]
    engine: str
    jobs: int | None

    def fly(self, values: dict[str, list[float]], deferred: Deferred) -> tuple[list[dict[str, Any]], bool]:
        """Fly each law's ``values`` with every seed, as one round; its rows, and whether Ctrl-C stopped it (the
        rows then those flown before it)."""
        cells = [probe(self.mission, c, self.over, v, s, self.link, self.vehicle)
                 for c, vs in values.items() for v in vs for s in self.seeds]
        rows: list[dict[str, Any]] = []
        try:
            with deferred.raising():
                fly_round(self.mission, cells, self.engine, self.jobs, rows.append)
        except KeyboardInterrupt:
            return rows, True
        return rows, False


def bisect(searches: list[Search], probes: Probes, until: Until, classes: Classes, resolution: float, top: float,
           deferred: Deferred, progress: Callable[[str], None] | None) -> tuple[int, bool]:
    """The bisection's rounds, all laws' probes of a round together, until every law's search has ended (or Ctrl-C:
    each law's bracket as far as the rows flown take it); (cells flown, interrupted)."""
    over, seeds = probes.over, len(probes.seeds)
    pending = {s.controller: START[over] for s in searches}
    cells_flown = 0
    while pending:
        rows, interrupted = probes.fly({c: [v] for c, v in pending.items()}, deferred)
        cells_flown += len(rows)
        for s in searches:
            if s.controller not in pending:
                continue
            v = pending.pop(s.controller)
            failed = s.take(over, v, rows, until, classes, "bisection")
            if s.error is not None:  # not a boundary: the law could not be flown there; its search ends
                s.bisecting = False
                continue
            if interrupted and not failed and s.short_of(over, [v], seeds):  # held by the seeds flown: not known
                continue
            s.record(v, failed)
            nxt = s.next_value(resolution, top)
            if nxt is None:  # bracketed to the resolution, or held up to the top of the axis's range
                s.bisecting = False
            elif not interrupted:
                pending[s.controller] = nxt
        if interrupted:
            return cells_flown, True
        if progress is not None:
            progress(f"{cells_flown} cell{'' if cells_flown == 1 else 's'} flown; " + ", ".join(
                f"{s.controller} [{s.lo:g}, {'-' if s.hi is None else f'{s.hi:g}'}]" for s in searches))
    return cells_flown, False


def entry(s: Search, over: str, checked: list[float] | None, stopped: str | None = None) -> dict[str, Any]:
    """One law's entry of ``margin.json``'s ``controllers`` (see docs/campaigns.md, "margin.json"); ``stopped``:
    the phase Ctrl-C stopped its search in (``bisection``: no margin, its bracket so far; ``below``)."""
    cut = s.error is not None and s.error["phase"] == "bisection" or stopped == "bisection"  # no margin found
    return {"controller": s.controller, "margin": s.lo if s.held and not cut else None,  # None: no value held
            "bracket": [s.lo if s.held else None, s.hi], **s.below(over, checked),
            "seeds_alike": seeds_alike(s.cells, itemgetter(over)), "error": s.error, "cells": s.cells,
            "held_to_range": s.hi is None and not cut and s.error is None, "interrupted_in": stopped}


def fly_round(mission: Mission, probes: list[Cell], engine: str, jobs: int | None, report: Report) -> None:
    """Fly one round's cells, each row to ``report``: as a batch where it can (even one cell: this process loads
    the kernels once), in this process for a cell or two of the built-in laws, in a process pool otherwise.
    KeyboardInterrupt for a Ctrl-C (a cell in this process that it stopped, ``aborted``, is not reported)."""
    used, _ = engine_for(mission, probes, "offline", engine, min_cells=1)
    if used == "batch":
        run_batch(mission, probes, report, jobs=jobs)
    elif len(probes) <= IN_PROCESS_CELLS and all(is_builtin(c.controller) for c in probes):  # a pool's start
        # costs more than a cell or two; a law of the user's own flies in a worker, whose death is a failed cell
        for c in probes:
            row = run_cell(mission, c)
            if row["outcome"] == "aborted":  # the flight took the Ctrl-C (bridge.loop): interrupted, not a result
                raise KeyboardInterrupt
            report(row)
    else:
        run_local(mission, probes, "offline", jobs or os.cpu_count() or 1, report, name="margin")


def probe(mission: Mission, law: str, over: str, value: float, seed: int, link: dict[str, float],
          vehicle: dict[str, Any]) -> Cell:
    """The cell that flies ``value`` of ``over`` for one law and seed: a link axis in both directions, the
    noise scale or the wind; the other axes at the mission's own values (``link``, ``vehicle``, its discretization)."""
    own = {"seed": seed, "discretization": mission.discretization}
    if over == "noise":
        return Cell(law, float(mission.rate_hz), **link, **own, estimator=vehicle["estimator"], noise=value,
                    sensing=("noise",), turbulence=vehicle["turbulence"], wind_mps=vehicle["wind_mps"])
    if over == "wind_mps":
        return Cell(law, float(mission.rate_hz), **link, **own, **{**vehicle, "wind_mps": value},
                    weather=("wind_mps",))
    return Cell(law, float(mission.rate_hz), **{**link, over: value}, **own, link=(over,), **vehicle)


def write_margin(result: dict[str, Any], out: str | Path | None, mission_name: str, overwrite: bool) -> Path:
    """``margin.json`` in ``out`` (or ``runs/<UTC time>-<mission>-margin``)."""
    path = run_dir(out, f"{mission_name}-margin", overwrite)
    write_json_atomic(path / MARGIN_JSON, result)
    return path
