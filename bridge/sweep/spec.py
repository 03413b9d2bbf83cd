"""A whole campaign as one value (:class:`Sweep`), and the sweep TOML file that describes it.

In:  a sweep file (``mission = ...``, ``[grid]``, ``[classes]``, ``mode``, ``jobs``) or a
     mission and a grid
Out: a validated :class:`Sweep`, and its identity (what ``sweep.json`` holds)

Every law, rate and combination of link values is built once through
:func:`bridge.core.flight.prepare` before any cell flies.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from itertools import product
from pathlib import Path
from typing import Any

from bridge.core.flight import FLEETS_ELSEWHERE, noise_problem, prepare
from bridge.core.weather import swept_replaced_problem
from bridge.link.model import NEEDS, idle_problem, swept_links
from bridge.record.runlog import check_trace_steps
from bridge.swarm import check_fleet_steps, fleet_flights, fleet_mission
from bridge.sweep.cells import COLUMNS
from bridge.sweep.classes import Classes
from bridge.sweep.grid import (
    AXES,
    FLEET_FORMATION,
    INT_AXES,
    LINK_AXES,
    MODES,
    NAME_CHOICES,
    RANGES,
    SENSING_AXES,
    SHORT,
    WEATHER_AXES,
    Cell,
    Grid,
    cell_flight,
    cell_overrides,
    cells,
    grid_size,
    link_trace,
    mission_value,
)
from controller.law import discretization_problem
from missions import Mission, load_mission
from missions.mission import is_plan_file, law_spec_from, law_spec_problem, mission_path
from params import ConfigError, Table, finite_float, load_toml, show

JOBS_RANGE = (1, 1024)  # cores a sweep or a margin flies on: a sweep file's jobs and the --jobs flag alike


def check_jobs(jobs: object) -> None:
    """ConfigError unless ``jobs`` (a Python call's ``jobs=``) is None (every core) or a whole number in
    :data:`JOBS_RANGE`, as the sweep file's key and ``--jobs`` are (0 meant every core, -1 a ValueError of the
    process pool's)."""
    lo, hi = JOBS_RANGE
    if jobs is not None and (isinstance(jobs, bool) or not isinstance(jobs, int) or not lo <= jobs <= hi):
        raise ConfigError(f"jobs: must be a whole number in [{lo}, {hi}] (None: every core), got {jobs!r}"[:200])


MAX_CELLS = 10_000  # cells a sweep flies unless told more (max_cells): 48 cells of the 30 s sine take 15 s on 2
# cores, so 10^4 take about an hour; 10^6 would take days, which is a typo far more often than a plan


@dataclass(frozen=True)
class Sweep:
    """A whole campaign: the mission, its grid, how to fly the cells and how to class them."""

    mission: Mission
    grid: Grid
    mode: str = "offline"
    classes: Classes = field(default_factory=Classes)
    jobs: int | None = None  # default worker count (a sweep file may set it)
    max_cells: int | None = None  # the most cells it may fly (None: MAX_CELLS); not part of its identity

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise ConfigError(f"mode: must be one of {', '.join(MODES)}; got {self.mode!r}")
        if self.mode == "lockstep" and any(n > 1 for n in self.grid.vehicles):
            raise ConfigError("grid.vehicles (--vehicles): cells of several vehicles fly offline only for now; "
                              "a lockstep fleet (bsst sitl --vehicles) is not a sweep's cell yet: drop --lockstep")
        if self.max_cells is not None and (isinstance(self.max_cells, bool) or not isinstance(self.max_cells, int)
                                           or self.max_cells < 1):
            raise ConfigError(f"max_cells: must be a positive integer, got {self.max_cells!r}")

    def cell_count(self) -> int:
        """How many cells the grid makes (without making them): the product of the axes' lengths and the seeds, a
        law without a super-twisting step once whatever the discretizations (bridge.sweep.grid.grid_size)."""
        return grid_size({**{a: _axis_values(self, a) for a in AXES}, "seed": self.grid.seed_list(self.mission)})

    def check_size(self) -> None:
        """Refuse a grid of more than ``max_cells`` (default :data:`MAX_CELLS`) cells, saying how many and why."""
        n, cap = self.cell_count(), self.max_cells or MAX_CELLS
        if n > cap:
            raise ConfigError(f"grid: {n} cells ({self._sizes()}), over the cap of {cap} a sweep flies "
                              f"(about {n * self.mission.duration_s / 3600:.3g} h of flight time); "
                              f"raise it with --max-cells {n} (max_cells in a sweep file) if that is meant")

    def _sizes(self) -> str:
        """:meth:`cell_count`'s factors in words, which multiply to it: each swept axis's length and the seeds; the
        laws and the discretizations as one factor, spelt out, where a law without a super-twisting step makes
        their plain product overcount (it is one cell per point)."""
        laws, schemes = _axis_values(self, "controller"), _axis_values(self, "discretization")
        pairs = grid_size({"controller": laws, "discretization": schemes})  # (the one counting rule)
        plain = pairs == len(laws) * len(schemes)
        sizes = [f"{len(getattr(self.grid, a))} {a}" for a in AXES if len(getattr(self.grid, a)) > 1
                 and (plain or a not in ("controller", "discretization"))]
        seeds = f"{len(self.grid.seed_list(self.mission))} seeds"
        if plain:
            return " x ".join([*sizes, seeds])
        each = [f"{law} x {len(schemes)} discretization"
                if grid_size({"controller": [law], "discretization": schemes}) > 1 else law for law in laws]
        return (f"{' x '.join([f'{pairs} law-schemes', *sizes, seeds])}; the {pairs} law-schemes: "
                f"{' + '.join(each)}, a law without a super-twisting step being one cell whatever the discretization")

    def cells(self) -> list[Cell]:
        return cells(self.mission, self.grid)

    def identity(self) -> dict[str, Any]:
        """What ``sweep.json`` records, and what ``--resume`` must find unchanged."""
        return json.loads(json.dumps({
            "mission": self.mission.to_dict(),
            "mode": self.mode,
            "grid": self.grid.to_dict(),
            "seeds": list(self.grid.seed_list(self.mission)),
            "axes": {a: _axis_values(self, a) for a in AXES},
            "swept": list(self.grid.swept()),
            "classes": asdict(self.classes),
            "columns": list(COLUMNS),
        }))

    def validate(self) -> None:
        """Build the flight of every law, every rate, every discretization, every estimator kind, every noise scale,
        every wind and turbulence and every combination of link values once (not every cell), so that a bad value
        fails before any cell runs; first the grid's size and that no link axis is swept over a link trace; then that
        a swept burst length, noise scale and discretization axis change something."""
        self.check_size()
        self.check_link_trace()
        if self.mission.vehicles:  # (said once, not as every cell's: the cells would lay it out again)
            raise ConfigError(f"{self.mission.source}: vehicles: a mission of several vehicles ([[vehicles]]) is "
                              f"not a sweep's cell: {FLEETS_ELSEWHERE}")
        for axis, kind in (("wind_mps", "wind"), *((a, "link") for a in LINK_AXES)):
            values = getattr(self.grid, axis)
            why = swept_replaced_problem(self.mission, kind) if values else None
            if why:  # (each cell would fly the event's wind or link from its step: a row's value not what it flew)
                raise ConfigError(f"grid.{axis} (--{SHORT[axis]}): {why}"[:400])
        base = self.cells()[0]
        probes = [_replace_cell(base, **{a: v}) for a in ("controller", "rate_hz", "discretization")
                  for v in getattr(self.grid, a)]
        probes += [_replace_cell(base, **{a: v, "sensing": tuple({*base.sensing, a})}) for a in SENSING_AXES
                   for v in getattr(self.grid, a)]
        probes += [_replace_cell(base, **{a: v, "weather": tuple({*base.weather, a})}) for a in WEATHER_AXES
                   for v in getattr(self.grid, a)]
        lists = [getattr(self.grid, a) or (getattr(base, a),) for a in LINK_AXES]
        probes += [_replace_cell(base, **dict(zip(LINK_AXES, vs, strict=True))) for vs in product(*lists)]
        own = None  # the base cell's flight: the first link probe is the base cell itself
        for c in probes:
            try:
                flight = cell_flight(self.mission, c)
                check_trace_steps(flight.mission)  # each rate: its steps within the cap
            except ConfigError as exc:
                raise ConfigError(f"sweep cell ({c.label()}): {exc}") from None
            if c == base:
                own = flight
        if any(n > 1 for n in self.grid.vehicles):  # the largest fleet laid out: each vehicle inside the envelope
            n = max(self.grid.vehicles)
            try:
                fleet = fleet_mission(self.mission, n, FLEET_FORMATION)
                assert fleet is not None
                check_fleet_steps(fleet, fleet_flights(fleet, cell_overrides(_replace_cell(base, vehicles=n))))
            except ConfigError as exc:
                raise ConfigError(f"grid.vehicles (--vehicles {n}): {exc}") from None
        why = self.noise_problem()
        if why:
            raise ConfigError(f"grid.noise (--noise): {why}")
        swept = {a: getattr(self.grid, a) for a in LINK_AXES if getattr(self.grid, a)}
        for a in (a for a in swept if a in NEEDS):  # burst_len: its cells need a loss, swept or the mission's
            assert own is not None
            why = idle_problem(a, [v for pair in swept_links([own.link], swept) for v in pair])
            if why:
                need = NEEDS[a][0]
                raise ConfigError(f"grid.{a} (--{SHORT[a]}): changes nothing in any cell: {why}; sweep --{SHORT[need]} "
                                  f"too, or give the mission's [link] {need}")
        why = discretization_problem(self.grid.controller or (self.mission.controller,))
        if self.grid.discretization and why:  # (a cell of each scheme would fly one flight twice)
            raise ConfigError(f"grid.discretization (--discretization): {why}; add bsst to the laws (--controller), "
                              "or drop the axis")

    def check_link_trace(self) -> None:
        """A swept link axis over the mission's link trace (its ``[link]`` trace, or its link profile's): refused,
        since the trace gives the delays and losses (bridge.sweep.grid.link_trace)."""
        swept = [a for a in LINK_AXES if getattr(self.grid, a)]
        if not swept:
            return
        try:
            trace = link_trace(prepare(self.mission))
        except ConfigError:  # the mission cannot be flown as it is: the probes name why, cell by cell
            return
        if trace:
            a = swept[0]
            raise ConfigError(f"grid.{a} (--{SHORT[a]}): {self.mission.source} replays the link trace {trace}, which "
                              f"gives the link's {', '.join(LINK_AXES)}: {a} cannot be swept over it; sweep a mission "
                              "without the trace, or the other axes")

    def noise_problem(self) -> str | None:
        """Why the noise axis (one value or more: one is every cell's, as ``bsst sim --noise``) would change
        nothing, or None."""
        if not self.grid.noise:
            return None
        kinds = self.grid.estimator or (mission_value(self.mission, "estimator"),)
        first = self.cells()[0]
        unscaled = _replace_cell(first, noise=1.0, sensing=tuple({*first.sensing, "noise"}))  # the set's own sigmas
        return noise_problem(kinds, cell_flight(self.mission, unscaled).sensors)


def _axis_values(s: Sweep, axis: str) -> list[Any]:
    return list(getattr(s.grid, axis) or (mission_value(s.mission, axis),))


def _replace_cell(c: Cell, **kw: Any) -> Cell:
    d = asdict(c)
    d.pop("law")  # (made again from the controller: Cell.__post_init__)
    d.update(kw)
    d["link"] = tuple(d["link"])
    d["sensing"] = tuple(d["sensing"])
    d["weather"] = tuple(d["weather"])
    return Cell(**d)


def load_sweep(path: str | Path) -> Sweep:
    """Read a sweep file (TOML): ``mission`` (path relative to the file), ``mode``, ``seeds``,
    ``jobs``, ``[grid]`` (axis = [values]) and ``[classes]`` (thresholds). Errors name file and key."""
    p = Path(path)
    src = str(p)
    t = Table(load_toml(p), src)
    mpath = Path(t.string("mission"))
    if not mpath.is_absolute():
        mpath = p.parent / mpath
    if not mpath.exists():
        raise t.error("mission", f"no such file {mpath}")
    mission = load_mission(mpath)
    mode = t.string("mode", "offline", choices=MODES)
    jobs = t.integer("jobs", lo=JOBS_RANGE[0], hi=JOBS_RANGE[1]) if t.has("jobs") else None  # absent: all cores
    max_cells = t.integer("max_cells", MAX_CELLS, lo=1, hi=10**9)
    seeds_raw = t.raw("seeds", 1)
    if isinstance(seeds_raw, list):
        seeds: int | tuple[int, ...] = tuple(_int_list(t, "seeds", 0, 2**31 - 1))
    else:
        seeds = t.integer("seeds", 1, lo=1, hi=10000)
    g = t.table("grid")
    axes: dict[str, Any] = {}
    for a in AXES:
        if g.has(a):
            if a in INT_AXES:
                lo, hi = RANGES[a]
                axes[a] = tuple(int(v) for v in _int_list(g, a, int(lo), int(hi)))
            elif a in NAME_CHOICES:  # estimator, turbulence, discretization
                axes[a] = tuple(_name_list(g, a, NAME_CHOICES[a]))
            elif a == "controller":
                v = g.raw(a)
                if isinstance(v, str):
                    v = [v]
                if not isinstance(v, list) or not v or not all(isinstance(x, str) for x in v):
                    raise g.error(a, "expected a list of law names")
                for x in v:
                    why = law_spec_problem(x)
                    if why:
                        raise g.error(a, why)
                axes[a] = tuple(law_spec_from(x, Path(path).parent) for x in v)
            else:
                lo, hi = RANGES[a]
                axes[a] = tuple(_number_list(g, a, lo, hi))
    g.done()
    classes = Classes.from_table(t.table("classes"))
    t.done()
    try:
        grid = Grid(seeds=seeds, **axes)
    except ConfigError as exc:
        raise ConfigError(f"{src}: {exc}") from None
    return Sweep(mission, grid, mode, classes, jobs, max_cells)


def _number_list(t: Table, key: str, lo: float, hi: float) -> list[float]:
    v = t.raw(key)
    if isinstance(v, (int, float)) and not isinstance(v, bool):
        v = [v]
    if not isinstance(v, list) or not v:
        raise t.error(key, f"expected a non-empty list of numbers, got {v!r}")
    out = []
    for i, x in enumerate(v):
        if finite_float(x) is None:
            raise t.error(key, f"element {i} must be a finite number, got {show(x)}")
        if not lo <= x <= hi:
            raise t.error(key, f"element {i} must be in [{lo:g}, {hi:g}], got {x:g}")
        out.append(float(x))
    if len(set(out)) != len(out):
        raise t.error(key, "repeated value")
    return out


def _name_list(t: Table, key: str, choices: tuple[str, ...]) -> list[str]:
    v = t.raw(key)
    if isinstance(v, str):
        v = [v]
    if not isinstance(v, list) or not v or not all(isinstance(x, str) for x in v):
        raise t.error(key, f"expected a non-empty list of names among {', '.join(choices)}, got {v!r}")
    for i, x in enumerate(v):
        if x not in choices:
            raise t.error(key, f"element {i} must be one of {', '.join(choices)}, got {x!r}")
    if len(set(v)) != len(v):
        raise t.error(key, "repeated value")
    return list(v)


def _int_list(t: Table, key: str, lo: int, hi: int) -> list[int]:
    v = t.raw(key)
    if not isinstance(v, list) or not v or not all(isinstance(x, int) and not isinstance(x, bool) for x in v):
        raise t.error(key, f"expected {'a count or ' if key == 'seeds' else ''}a non-empty list of integers, got {v!r}")
    if not all(lo <= x <= hi for x in v) or len(set(v)) != len(v):
        raise t.error(key, f"{'seeds' if key == 'seeds' else 'the values'} must be distinct and in [{lo}, {hi}]")
    return list(v)


def is_sweep_file(path: str | Path) -> bool:
    """Whether a TOML file declares a sweep (it has a ``[grid]`` table or a ``mission`` key); a ground
    station's plan never does."""
    if is_plan_file(path):
        return False
    data = load_toml(mission_path(path))
    return "grid" in data or isinstance(data.get("mission"), str)
