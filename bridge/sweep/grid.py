"""The grid of a campaign: its axes, their one range table, and the cells it makes.

In:  a mission and a :class:`Grid` (lists of values per axis: law, control rate Hz, one-way
     delay ms, jitter ms, loss %, mean loss-burst length in packets, the vehicle's estimator kind,
     the noise scale of its sensor set (x every sigma), the steady wind m/s, the turbulence level, how ``bsst``
     steps its super-twisting step (explicit or implicit), the number of vehicles flown together (a fleet in a
     ``line:2`` formation, docs/swarm.md); seeds)
Out: the :class:`Cell` list in grid order, and for each cell the overrides that
     :func:`bridge.core.flight.prepare` (the one path from a mission to its parts) applies

Ranges: the link axes take :data:`bridge.link.model.NUMBER_RANGES`, the rate the mission
loader's, the noise scale the ``[sensors] noise_scale`` one (:data:`plant.profiles.NOISE_SCALE_RANGE`), the wind
``[wind] speed_mps``'s (:data:`plant.wind.WIND_RANGES`) and the turbulence its levels (:data:`plant.wind.TURBULENCE`),
so a value a mission accepts is accepted here and the other way round. The wind blows from the mission's
``[wind] from_deg`` (0, from the north, without one).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, fields
from itertools import product
from numbers import Real
from pathlib import Path
from typing import Any

from bridge.autopilot.estimator import ESTIMATOR_KINDS
from bridge.core.flight import Flight, prepare
from bridge.core.overrides import Overrides
from bridge.link.model import DIRECTIONS, NUMBER_RANGES, TRACE_EXCLUSIVE, merge_link_tables
from bridge.link.profile import load_link_profile
from controller.law import DISCRETIZED, LawError
from missions import MISSION_RANGES, Mission
from missions.fleet import FLEET_RANGES
from missions.mission import DEFAULT_DISCRETIZATION, DISCRETIZATIONS, law_spec_from, law_spec_problem
from params import ConfigError
from plant.events import TimedEvent, at_first_step, timeline_from_tables
from plant.profiles import NOISE_SCALE_RANGE
from plant.wind import TURBULENCE, WIND_RANGES

# Grid axes, in the order of the product (the last varies fastest; seeds vary faster still). The vehicle's
# axes come last, so that a grid without them keeps the order (and cells.csv its first columns) it had.
AXES = ("controller", "rate_hz", "delay_ms", "jitter_ms", "loss_pct", "burst_len", "estimator", "noise", "wind_mps",
        "turbulence", "discretization", "vehicles")
INT_AXES = ("vehicles",)  # whole numbers: a fleet's size (1: the mission's one vehicle, as without the axis)
FLEET_FORMATION = "line:2"  # how a cell of several vehicles lays them out (bridge.swarm; docs/campaigns.md)


LINK_AXES = ("delay_ms", "jitter_ms", "loss_pct", "burst_len")
assert set(LINK_AXES) == set(TRACE_EXCLUSIVE)  # what a link trace gives: link.trace refuses a swept link axis
SENSING_AXES = ("estimator", "noise")  # the vehicle's: prepare()'s estimator and noise overrides
WEATHER_AXES = ("wind_mps", "turbulence")  # the air's: prepare()'s wind (its speed) and turbulence overrides
NAME_AXES = ("controller", "estimator", "turbulence", "discretization")  # axes of names; the others are numbers
# Short names: command-line flags (--delay ...) and heat-map file names (map_delay_loss.png).


SHORT = {"controller": "controller", "rate_hz": "rate", "delay_ms": "delay", "jitter_ms": "jitter",
         "loss_pct": "loss", "burst_len": "burst", "estimator": "estimator", "noise": "noise", "wind_mps": "wind",
         "turbulence": "turbulence", "discretization": "discretization", "vehicles": "vehicles"}
# Value of a link axis when neither the sweep nor the mission's [link.up] sets it.


LINK_DEFAULTS = {"delay_ms": 0.0, "jitter_ms": 0.0, "loss_pct": 0.0, "burst_len": 0.0}
# (lo, hi) of every numeric axis, units in the names: ms, %, packets, Hz.


RANGES = {"rate_hz": MISSION_RANGES["rate_hz"], **{a: NUMBER_RANGES[a] for a in LINK_AXES}, "noise": NOISE_SCALE_RANGE,
          "wind_mps": WIND_RANGES["speed_mps"], "vehicles": FLEET_RANGES["vehicles"]}


NAME_CHOICES = {"estimator": ESTIMATOR_KINDS, "turbulence": TURBULENCE, "discretization": DISCRETIZATIONS}


MODES = ("offline", "lockstep")


NO_SCHEME = ""  # the discretization of a cell whose law has no super-twisting step (cells.csv: an empty field)


@dataclass(frozen=True)
class Grid:
    """The axes of a sweep. An empty axis is not swept: the mission's own value is flown.

    ``controller``: law names; ``rate_hz``: control rates (Hz); ``delay_ms``: fixed one-way
    delay (ms); ``jitter_ms``: jitter amplitude (ms); ``loss_pct``: packet loss (%);
    ``burst_len``: mean loss-burst length (packets, Gilbert-Elliott; 0 = independent losses).
    ``estimator``: the vehicle's estimator kinds (``truth``, ``ekf``, ``raw``); ``noise``: noise scales
    of the mission's sensor set (every sigma times it; 0 = exact sensors, still sampled and late).
    ``wind_mps``: steady wind speeds (m/s, from the mission's ``[wind] from_deg``); ``turbulence``: Dryden
    levels (``none``, ``light``, ``moderate``, ``severe``). ``discretization``: how ``bsst`` steps its
    super-twisting step (``explicit``, ``implicit``; docs/law.md; a law without one flies one cell per point, its
    discretization :data:`NO_SCHEME`).
    ``vehicles``: fleet sizes (whole numbers, 1-64), each flown offline in a ``line:2`` formation
    (:data:`FLEET_FORMATION`; 1: the mission as it flies alone).
    ``seeds``: how many seeds per grid point (mission seed, +1, ...) or the seeds themselves.
    """

    controller: tuple[str, ...] = ()
    rate_hz: tuple[float, ...] = ()
    delay_ms: tuple[float, ...] = ()
    jitter_ms: tuple[float, ...] = ()
    loss_pct: tuple[float, ...] = ()
    burst_len: tuple[float, ...] = ()
    estimator: tuple[str, ...] = ()
    noise: tuple[float, ...] = ()
    wind_mps: tuple[float, ...] = ()
    turbulence: tuple[str, ...] = ()
    discretization: tuple[str, ...] = ()
    vehicles: tuple[int, ...] = ()
    seeds: int | tuple[int, ...] = 1

    def __post_init__(self) -> None:
        for name in AXES:
            object.__setattr__(self, name, axis_values(name, getattr(self, name)))
        object.__setattr__(self, "seeds", seed_values(self.seeds))

    @classmethod
    def of(cls, grid: Grid | Mapping[str, Any]) -> Grid:
        """A :class:`Grid`, or one from a mapping of axis name -> list (and ``seeds``)."""
        if isinstance(grid, Grid):
            return grid
        unknown = sorted(set(grid) - {f.name for f in fields(cls)})
        if unknown:
            raise ConfigError(f"grid.{unknown[0]}: unknown axis (axes: {', '.join(AXES)}, seeds)")
        return cls(**dict(grid))

    def swept(self) -> tuple[str, ...]:
        """The axes given (even with one value)."""
        return tuple(a for a in AXES if getattr(self, a))

    def seed_list(self, mission: Mission) -> tuple[int, ...]:
        """The seeds each grid point is flown with: a count counts up from the mission's seed."""
        if isinstance(self.seeds, int):
            return tuple(mission.seed + i for i in range(self.seeds))
        return tuple(self.seeds)

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {a: list(getattr(self, a)) for a in AXES if getattr(self, a)}
        d["seeds"] = self.seeds if isinstance(self.seeds, int) else list(self.seeds)
        return d


def _whole(v: Any) -> bool:
    """A number with no fraction (2 and 2.0; not 1.5, nan, inf, True or '2'): a fleet's size, a seed."""
    return isinstance(v, Real) and not isinstance(v, bool) and float(v).is_integer()


def axis_values(name: str, given: Any) -> tuple[Any, ...]:
    """An axis's values as its :class:`Grid` field holds them, or a ConfigError naming the axis and quoting what
    was given (never one value silently changed into another): names among the axis's choices, numbers in its range
    (:data:`RANGES`), whole numbers on :data:`INT_AXES`, none repeated."""
    values = (given,) if isinstance(given, (str, Real)) else given
    if isinstance(values, Mapping) or not isinstance(values, Iterable):
        raise ConfigError(f"grid.{name}: expected a list of {'names' if name in NAME_AXES else 'numbers'}, "
                          f"got {given!r}")
    values = tuple(values)
    kind, ok = (("names", lambda v: isinstance(v, str)) if name in NAME_AXES else
                ("whole numbers", _whole) if name in INT_AXES else
                ("numbers", lambda v: isinstance(v, Real) and not isinstance(v, bool)))
    if not all(ok(v) for v in values):
        allowed = (f" among {', '.join(NAME_CHOICES[name])}" if name in NAME_CHOICES else "" if name in NAME_AXES
                   else " in [{:g}, {:g}]".format(*RANGES[name]))
        raise ConfigError(f"grid.{name}: must be {kind}{allowed}, got {list(values)!r}")
    kept = values if name in NAME_AXES else tuple((int if name in INT_AXES else float)(v) for v in values)
    if len(set(kept)) != len(kept):
        raise ConfigError(f"grid.{name}: repeated value in {list(values)!r}")
    for v in kept:
        if name == "controller":
            why = law_spec_problem(v)
            if why:
                raise ConfigError(f"grid.controller: {why}")
        elif name in NAME_AXES:
            if v not in NAME_CHOICES[name]:
                raise ConfigError(f"grid.{name}: must be among {', '.join(NAME_CHOICES[name])}, got {v!r}")
        else:
            lo, hi = RANGES[name]
            if not (lo <= v <= hi):  # also rejects nan
                raise ConfigError(f"grid.{name}: must be in [{lo:g}, {hi:g}], got {v:g}")
    return kept


def seed_values(given: Any) -> int | tuple[int, ...]:
    """A grid's seeds: a count, or distinct whole numbers in the seed range (2.0 is 2; 1.5 is refused, as a
    fleet's size is, never truncated); a ConfigError quoting what was given otherwise."""
    if isinstance(given, int) and not isinstance(given, bool):
        if not 1 <= given <= 10000:
            raise ConfigError(f"grid.seeds: must be in [1, 10000], got {given}")
        return given
    if not isinstance(given, (tuple, list)):
        raise ConfigError(f"grid.seeds: expected a count or a list of seeds, got {given!r}")
    if not all(_whole(v) for v in given):
        raise ConfigError(f"grid.seeds: must be whole numbers in [0, 2^31-1], got {list(given)!r}")
    s = tuple(int(v) for v in given)
    if not s or len(set(s)) != len(s) or not all(0 <= v <= 2**31 - 1 for v in s):
        raise ConfigError(f"grid.seeds: expected distinct seeds in [0, 2^31-1], got {list(given)!r}")
    return s


@dataclass(frozen=True)
class Cell:
    """One grid point flown with one seed: the effective values of every axis.

    ``link`` names the link axes that override the mission's ``[link.up]``/``[link.down]``;
    ``sensing`` the vehicle's axes (estimator kind, noise scale) that override its ``[estimator] kind``
    and ``[sensors] noise_scale``, ``weather`` the air's (wind speed, turbulence) that override its ``[wind]``
    (those where the cell's value is not the mission's own: a still-air cell of a still-air mission flies it).
    """

    controller: str
    rate_hz: float
    delay_ms: float
    jitter_ms: float
    loss_pct: float
    burst_len: float
    seed: int
    link: tuple[str, ...] = ()
    estimator: str = "truth"
    noise: float = 1.0
    sensing: tuple[str, ...] = ()
    wind_mps: float = 0.0
    turbulence: str = "none"
    weather: tuple[str, ...] = ()
    discretization: str = DEFAULT_DISCRETIZATION  # laid over the mission, as the law and the rate are; NO_SCHEME for
    # a law without a super-twisting step (set so below, whatever was given: it has none to step)
    vehicles: int = 1  # how many vehicles fly the cell together (more than 1: a fleet, FLEET_FORMATION)
    # the law as the cell flies it: a relative law file made absolute against the working directory where the cell is
    # made (the caller's, in the sweep's own process), never a worker's (a Dask cluster's started elsewhere); the
    # rows and the key keep ``controller`` as given
    law: str = field(init=False, compare=False, repr=False)

    def __post_init__(self) -> None:
        if self.controller not in DISCRETIZED:  # (smc, pid, a law of one's own: one cell, not one per scheme)
            object.__setattr__(self, "discretization", NO_SCHEME)
        try:
            law = law_spec_from(self.controller, Path("."))
        except OSError:  # no working directory (removed): a relative file is no one's; the flight names it missing
            law = self.controller
        object.__setattr__(self, "law", law)

    def key(self) -> tuple[Any, ...]:
        """What identifies the cell's row in ``cells.csv``."""
        return tuple(getattr(self, a) for a in (*AXES, "seed"))

    def label(self) -> str:
        return " ".join(f"{a}={getattr(self, a)}" if a in NAME_AXES + INT_AXES else f"{a}={getattr(self, a):g}"
                        for a in (*AXES, "seed"))


def mission_value(mission: Mission, axis: str, with_profile: bool = True, events: bool = True) -> Any:
    """The mission's own value of an axis, as its flight flies it from the start (link axes: ``[link.up]``, else
    ``[link]``, laid over its link profile's as the flight lays them (``with_profile``), else none; the vehicle's:
    ``[estimator] kind`` and ``[sensors] noise_scale``, else their defaults). With ``events``, an ``[[events]]`` table
    that sets the steady wind or hands the link over at the first control step (``t_s = 0``) gives the wind speed,
    or the link axes (from its own table: a handover replaces the link whole), in place of ``[wind]`` and ``[link]``;
    without (``bsst margin``'s "the mission already sets it"), the tables alone. (A sweep over loss on
    ``--link-profile lte`` wrote delay_ms 0, jitter_ms 0 and burst_len 0 in every row and report.md, of flights at
    35 ms, sigma 6, bursts of 5, until the third wave's forty-third session; a mission's ``[wind] speed_mps`` 5 under
    a t = 0 wind event of 1 m/s, 5 in every row's wind_mps, of flights at 1, until the forty-fifth session's.)"""
    if axis == "controller":
        return mission.controller
    if axis == "rate_hz":
        return float(mission.rate_hz)
    if axis == "discretization":
        return mission.discretization
    if axis == "vehicles":
        return len(mission.vehicles) or 1  # (a mission with [[vehicles]] is refused where a cell is built)
    if axis == "estimator":
        kind = mission.estimator.get("kind", "truth")
        return kind if isinstance(kind, str) else "truth"  # a bad kind: prepare() names it when the cell is built
    if axis == "noise":
        scale = mission.sensors.get("noise_scale", 1.0)
        return float(scale) if isinstance(scale, (int, float)) and not isinstance(scale, bool) else 1.0
    if axis == "turbulence":
        level = mission.wind.get("turbulence", "none")
        return level if isinstance(level, str) else "none"  # a bad level: prepare() names it
    first = _first_step_event(mission, "wind" if axis == "wind_mps" else "link") if events else None
    if axis == "wind_mps":
        speed = first.get("speed_mps") if first is not None else mission.wind.get("speed_mps", 0.0)
        return float(speed) if isinstance(speed, (int, float)) and not isinstance(speed, bool) else 0.0
    link = dict(first.settings) if first is not None else mission.link  # (a handover's table: scalar keys only)
    profile = link.get("profile")
    if with_profile and isinstance(profile, str) and profile:
        try:
            link = merge_link_tables(load_link_profile(profile).link, {k: v for k, v in link.items() if k != "profile"})
        except ConfigError:  # (named where the cell's flight is prepared)
            pass
    up = link.get("up")
    for table in (up if isinstance(up, Mapping) else {}, link):
        v = table.get(axis)
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            return float(v)
    return LINK_DEFAULTS[axis]


def _first_step_event(mission: Mission, kind: str) -> TimedEvent | None:
    """The mission's ``[[events]]`` table of ``kind`` (``wind``, ``link``) acting at its first control step: what it
    sets is flown from the start in place of the mission's own; None (also for a bad timeline: prepare() names it)."""
    if not mission.events:
        return None
    try:
        timeline = timeline_from_tables(mission.events, mission.source, mission.duration_s)
    except ConfigError:
        return None
    return at_first_step(timeline, mission.rate_hz, kind)


def cells(mission: Mission, grid: Grid) -> list[Cell]:
    """Every cell of the sweep, in grid order (axes in :data:`AXES` order, seed fastest); a law without a
    super-twisting step once per point of the other axes, not once per discretization (its cells' :data:`NO_SCHEME`)."""
    given = set(grid.swept())
    own = {a: mission_value(mission, a) for a in AXES}
    lists = [getattr(grid, a) or (own[a],) for a in AXES]
    link = tuple(a for a in LINK_AXES if a in given)
    seeds = grid.seed_list(mission)
    # a [wind] turbulence_scaling with no turbulence of its own: every cell lays its turbulence (none too: the same
    # air), so the scaling's need is given where the grid sweeps one (bridge.core.flight.scaling_refusal)
    stated = {"turbulence"} if "turbulence_scaling" in mission.wind and "turbulence" not in mission.wind else set()
    out: dict[tuple[Any, ...], Cell] = {}  # by key: smc's explicit and implicit points are one cell
    for values in product(*lists):
        v = dict(zip(AXES, values, strict=True))
        # a vehicle axis overrides only where it differs from the mission's own value: the same flight, and
        # a grid of 'truth' cells stays one the batch engine builds from one prepare() per law and rate
        sensing = tuple(a for a in SENSING_AXES if a in given and v[a] != own[a])
        weather = tuple(a for a in WEATHER_AXES if a in given and (v[a] != own[a] or a in stated))
        for s in seeds:
            c = Cell(**v, seed=s, link=link, sensing=sensing, weather=weather)
            out.setdefault(c.key(), c)
    return list(out.values())


def grid_size(values: Mapping[str, Sequence[Any]]) -> int:
    """How many cells a grid of these values per axis (and ``seed``: the seeds) makes, without making them (a
    ``Sweep``'s, or its ``sweep.json``'s ``axes``): the product of their lengths, where a law without a super-twisting
    step counts once whatever the discretizations (:func:`cells`)."""
    n = 1
    for a, v in values.items():
        n *= len(v) if a not in ("controller", "discretization") else 1
    laws, schemes = values.get("controller") or ("bsst",), len(values.get("discretization") or ()) or 1
    return n * sum(schemes if law in DISCRETIZED else 1 for law in laws)


def cell_overrides(cell: Cell) -> Overrides:
    """What a cell changes in its mission, as :func:`bridge.core.flight.prepare`'s overrides:
    law, discretization (a law without a super-twisting step has none to lay: prepare refuses one), rate and seed,
    the swept link axes in both directions, the vehicle's swept axes and the air's."""
    link = {d: {a: getattr(cell, a) for a in cell.link} for d in DIRECTIONS} if cell.link else None
    weather: dict[str, Any] = {}
    if "wind_mps" in cell.weather:
        weather["wind"] = {"speed_mps": cell.wind_mps}  # over [wind]: its direction (from_deg) stays
    if "turbulence" in cell.weather:
        weather["turbulence"] = cell.turbulence
    scheme = cell.discretization or None  # (NO_SCHEME: a law without a super-twisting step)
    return Overrides(controller=cell.law, discretization=scheme, rate_hz=cell.rate_hz, seed=cell.seed, link=link,
                     **{a: getattr(cell, a) for a in cell.sensing}, **weather)  # estimator, noise; wind, turbulence


def cell_flight(mission: Mission, cell: Cell) -> Flight:
    """The parts a cell flies, by the one path from a mission and its overrides (its link values named as the
    grid's axes where one changes nothing: bridge.sweep.spec); a law that cannot be built named as it was given."""
    try:
        return prepare(mission, cell_overrides(cell), laid_named=True)
    except LawError as exc:  # prepare names the override it was handed (the cell's law overrides the mission's key):
        if exc.spec != cell.law or cell.law == cell.controller:  # the law made absolute (Cell.law)
            raise
        raise LawError(exc.spec, exc.what, f"--controller {cell.controller}") from None


def link_trace(flight: Flight) -> str | None:
    """The link trace file a flight replays in either direction, from its start or a handover (None: none). A
    trace gives the link's delays and losses, every link axis (:data:`TRACE_EXCLUSIVE`): none can be swept or
    searched over it."""
    L = flight.link
    configs = (L.up, L.down, *(c for _, u, d in L.handovers for c in (u, d)))
    return next((c.trace.path for c in configs if c.trace is not None), None)
