"""The grid of a campaign: its axes, their one range table, and the cells it makes.

In:  a mission and a :class:`Grid` (lists of values per axis: law, control rate Hz, one-way
     delay ms, jitter ms, loss %, mean loss-burst length in packets; seeds)
Out: the :class:`Cell` list in grid order, and for each cell the overrides that
     :func:`bridge.core.flight.prepare` (the one path from a mission to its parts) applies

Ranges: the link axes take :data:`bridge.core.link.NUMBER_RANGES`, the rate the mission
loader's, so a value a mission accepts is accepted here and the other way round.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields
from itertools import product
from typing import Any

from bridge.core.flight import Flight, prepare
from bridge.core.link import DIRECTIONS, NUMBER_RANGES
from missions import MISSION_RANGES, Mission
from missions.mission import law_spec_problem
from params import ConfigError

# Grid axes, in the order of the product (the last varies fastest; seeds vary faster still).
AXES = ("controller", "rate_hz", "delay_ms", "jitter_ms", "loss_pct", "burst_len")


LINK_AXES = ("delay_ms", "jitter_ms", "loss_pct", "burst_len")
# Short names: command-line flags (--delay ...) and heat-map file names (map_delay_loss.png).


SHORT = {"controller": "controller", "rate_hz": "rate", "delay_ms": "delay", "jitter_ms": "jitter",
         "loss_pct": "loss", "burst_len": "burst"}
# Value of a link axis when neither the sweep nor the mission's [link.up] sets it.


LINK_DEFAULTS = {"delay_ms": 0.0, "jitter_ms": 0.0, "loss_pct": 0.0, "burst_len": 0.0}
# (lo, hi) of every numeric axis, units in the names: ms, %, packets, Hz.


RANGES = {"rate_hz": MISSION_RANGES["rate_hz"], **{a: NUMBER_RANGES[a] for a in LINK_AXES}}


MODES = ("offline", "lockstep")


@dataclass(frozen=True)
class Grid:
    """The axes of a sweep. An empty axis is not swept: the mission's own value is flown.

    ``controller``: law names; ``rate_hz``: control rates (Hz); ``delay_ms``: fixed one-way
    delay (ms); ``jitter_ms``: jitter amplitude (ms); ``loss_pct``: packet loss (%);
    ``burst_len``: mean loss-burst length (packets, Gilbert-Elliott; 0 = independent losses).
    ``seeds``: how many seeds per grid point (mission seed, +1, ...) or the seeds themselves.
    """

    controller: tuple[str, ...] = ()
    rate_hz: tuple[float, ...] = ()
    delay_ms: tuple[float, ...] = ()
    jitter_ms: tuple[float, ...] = ()
    loss_pct: tuple[float, ...] = ()
    burst_len: tuple[float, ...] = ()
    seeds: int | tuple[int, ...] = 1

    def __post_init__(self) -> None:
        for name in AXES:
            values = getattr(self, name)
            if isinstance(values, (str, int, float)):
                values = (values,)
            values = tuple(values) if name == "controller" else tuple(float(v) for v in values)
            object.__setattr__(self, name, values)
            if len(set(values)) != len(values):
                raise ConfigError(f"grid.{name}: repeated value in {list(values)}")
            for v in values:
                if name == "controller":
                    why = law_spec_problem(v)
                    if why:
                        raise ConfigError(f"grid.controller: {why}")
                else:
                    lo, hi = RANGES[name]
                    if not (lo <= v <= hi):  # also rejects nan
                        raise ConfigError(f"grid.{name}: must be in [{lo:g}, {hi:g}], got {v:g}")
        s = self.seeds
        if isinstance(s, bool) or not isinstance(s, (int, tuple, list)):
            raise ConfigError(f"grid.seeds: expected a count or a list of seeds, got {s!r}")
        if isinstance(s, int):
            if not 1 <= s <= 10000:
                raise ConfigError(f"grid.seeds: must be in [1, 10000], got {s}")
        else:
            s = tuple(int(v) for v in s)
            object.__setattr__(self, "seeds", s)
            if not s or len(set(s)) != len(s) or not all(0 <= v <= 2**31 - 1 for v in s):
                raise ConfigError(f"grid.seeds: expected distinct seeds in [0, 2^31-1], got {list(s)}")

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


@dataclass(frozen=True)
class Cell:
    """One grid point flown with one seed: the effective values of every axis.

    ``link`` names the link axes that override the mission's ``[link.up]``/``[link.down]``.
    """

    controller: str
    rate_hz: float
    delay_ms: float
    jitter_ms: float
    loss_pct: float
    burst_len: float
    seed: int
    link: tuple[str, ...] = ()

    def key(self) -> tuple[Any, ...]:
        """What identifies the cell's row in ``cells.csv``."""
        return (self.controller, self.rate_hz, self.delay_ms, self.jitter_ms, self.loss_pct, self.burst_len,
                self.seed)

    def label(self) -> str:
        return " ".join(f"{a}={getattr(self, a):g}" if a != "controller" else f"{a}={self.controller}"
                        for a in (*AXES, "seed"))


def mission_value(mission: Mission, axis: str) -> Any:
    """The mission's own value of an axis (link axes: ``[link.up]``, else ``[link]``, else none)."""
    if axis == "controller":
        return mission.controller
    if axis == "rate_hz":
        return float(mission.rate_hz)
    up = mission.link.get("up")
    for table in (up if isinstance(up, Mapping) else {}, mission.link):
        v = table.get(axis)
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            return float(v)
    return LINK_DEFAULTS[axis]


def cells(mission: Mission, grid: Grid) -> list[Cell]:
    """Every cell of the sweep, in grid order (axes in :data:`AXES` order, seed fastest)."""
    given = set(grid.swept())
    lists = [getattr(grid, a) or (mission_value(mission, a),) for a in AXES]
    link = tuple(a for a in LINK_AXES if a in given)
    seeds = grid.seed_list(mission)
    return [Cell(*values, seed=s, link=link) for values in product(*lists) for s in seeds]


def cell_overrides(cell: Cell) -> dict[str, Any]:
    """What a cell changes in its mission, as :func:`bridge.core.flight.prepare`'s overrides:
    law, rate and seed, and the swept link axes in both directions."""
    link = {d: {a: getattr(cell, a) for a in cell.link} for d in DIRECTIONS} if cell.link else None
    return {"controller": cell.controller, "rate_hz": cell.rate_hz, "seed": cell.seed, "link": link}


def cell_flight(mission: Mission, cell: Cell) -> Flight:
    """The parts a cell flies, by the one path from a mission and its overrides."""
    return prepare(mission, **cell_overrides(cell))
