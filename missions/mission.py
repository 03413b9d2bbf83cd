"""Mission files: load, validate, and the :class:`Mission` they describe.

A mission names its trajectory, duration, vehicle profile, controller and gains, rates,
effects, link impairment and seed. The tables ``[gains]``, ``[effects]``, ``[link]`` and
``[failsafe]`` belong to other parts (controller, plant, bridge): they are kept here as raw
tables with their source and validated by the part that owns them when a run is built, so
errors still name the file and the key.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from missions.references import Reference, Setpoint, Sine, Step, Waypoints
from params import ConfigError, Table, load_toml

CONTROLLERS = ("bsst", "smc", "pid")
TRAJECTORIES = ("step", "sine", "waypoints")


@dataclass(frozen=True)
class Mission:
    """One flight: a reference to follow for ``duration_s`` and how to fly it."""

    trajectory: Reference
    duration_s: float
    name: str = "mission"
    profile: str = "paper"
    actuation: str | None = None  # None: the profile's own
    controller: str = "bsst"
    rate_hz: float = 250.0
    physics_hz: float = 1000.0
    seed: int = 0
    start: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)  # x, y, z, psi at rest
    gains: Mapping[str, Any] = field(default_factory=dict)
    effects: Mapping[str, Any] = field(default_factory=dict)
    link: Mapping[str, Any] = field(default_factory=dict)
    failsafe: Mapping[str, Any] = field(default_factory=dict)
    source: str = "<python>"

    def __post_init__(self) -> None:
        check_timing(self.duration_s, self.rate_hz, self.physics_hz, self.source)
        if self.controller not in CONTROLLERS:
            raise ConfigError(f"{self.source}: controller: must be one of {', '.join(CONTROLLERS)}")

    def with_overrides(self, **kw: Any) -> Mission:
        """A copy with some fields replaced (None values are ignored), validated again."""
        return replace(self, **{k: v for k, v in kw.items() if v is not None})

    def to_dict(self) -> dict[str, Any]:
        """The mission as a TOML-ready table (what ``mission.toml`` of a run holds)."""
        d: dict[str, Any] = {
            "name": self.name,
            "duration_s": self.duration_s,
            "profile": self.profile,
            "controller": self.controller,
            "rate_hz": self.rate_hz,
            "physics_hz": self.physics_hz,
            "seed": self.seed,
        }
        if self.actuation:
            d["actuation"] = self.actuation
        d["start"] = {"position": list(self.start[:3]), "psi": self.start[3]}
        d["trajectory"] = self.trajectory.to_dict()
        for k in ("gains", "effects", "link", "failsafe"):
            if getattr(self, k):
                d[k] = dict(getattr(self, k))
        return d

    @property
    def steps(self) -> int:
        """Number of control steps in the mission."""
        return int(round(self.duration_s * self.rate_hz))


def check_timing(duration_s: float, rate_hz: float, physics_hz: float, source: str = "<python>") -> None:
    """Rates and duration must be positive and the physics rate a multiple of the control rate."""
    if not (math.isfinite(duration_s) and 0.0 < duration_s <= 86400.0):
        raise ConfigError(f"{source}: duration_s: must be in (0, 86400], got {duration_s:g}")
    if not 50.0 <= rate_hz <= 1000.0:
        raise ConfigError(f"{source}: rate_hz: must be in [50, 1000], got {rate_hz:g}")
    if not 100.0 <= physics_hz <= 10000.0:
        raise ConfigError(f"{source}: physics_hz: must be in [100, 10000], got {physics_hz:g}")
    ratio = physics_hz / rate_hz
    if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
        raise ConfigError(
            f"{source}: rate_hz: the physics rate {physics_hz:g} Hz must be a whole multiple of it, got {rate_hz:g}"
        )


def load_mission(path: str | Path) -> Mission:
    """Read and validate a mission TOML file."""
    p = Path(path)
    return mission_from_table(load_toml(p), str(p), default_name=p.stem)


def mission_from_table(data: Mapping[str, Any], source: str, default_name: str = "mission") -> Mission:
    t = Table(data, source)
    name = t.string("name", default_name)
    duration = t.number("duration_s", lo=0.0, lo_open=True, hi=86400.0)
    profile = t.string("profile", "paper")
    actuation = t.string("actuation", "", choices=("", "wrench", "motors")) or None
    controller = t.string("controller", "bsst", choices=CONTROLLERS)
    rate = t.number("rate_hz", 250.0, lo=50.0, hi=1000.0)
    physics = t.number("physics_hz", 1000.0, lo=100.0, hi=10000.0)
    seed = t.integer("seed", 0, lo=0, hi=2**31 - 1)
    st = t.table("start")
    start = st.vector("position", 3, (0.0, 0.0, 0.0), lo=-1e4, hi=1e4) + (st.number("psi", 0.0, lo=-10, hi=10),)
    st.done()
    trajectory = _trajectory(t.table("trajectory", required=True), duration)
    raw = {k: _table(t, k) for k in ("gains", "effects", "link", "failsafe")}
    t.done()
    return Mission(
        trajectory=trajectory,
        duration_s=duration,
        name=name,
        profile=profile,
        actuation=actuation,
        controller=controller,
        rate_hz=rate,
        physics_hz=physics,
        seed=seed,
        start=start,  # type: ignore[arg-type]
        source=source,
        **raw,
    )


def _table(t: Table, name: str) -> Mapping[str, Any]:
    v = t.raw(name, {})
    if not isinstance(v, Mapping):
        raise t.error(name, "expected a table")
    return v


def _setpoints(t: Table, key: str, duration: float) -> tuple[Setpoint, ...]:
    items = t.raw(key)
    if not isinstance(items, list) or not items:
        raise t.error(key, "expected a non-empty list of tables {t, x, y, z, psi}")
    out = []
    for i, item in enumerate(items):
        s = Table(item, t._source, f"{t.key(key)}[{i}]")
        sp = Setpoint(
            s.number("t", lo=0.0, hi=duration),
            s.number("x", lo=-1e4, hi=1e4),
            s.number("y", lo=-1e4, hi=1e4),
            s.number("z", lo=-1e4, hi=1e4),
            s.number("psi", 0.0, lo=-100.0, hi=100.0),
        )
        s.done()
        if out and sp.t <= out[-1].t:
            raise s.error("t", f"must be later than the previous one ({out[-1].t:g})")
        out.append(sp)
    return tuple(out)


def _trajectory(t: Table, duration: float) -> Reference:
    kind = t.string("kind", choices=TRAJECTORIES)
    if kind == "sine":
        ref: Reference = Sine(
            amplitude=t.number("amplitude", 1.0, lo=0.0, hi=1e4),
            omega=t.number("omega", 0.5, lo=0.0, hi=100.0),
            climb=t.number("climb", 0.1, lo=-100.0, hi=100.0),
            z0=t.number("z0", 0.0, lo=-1e4, hi=1e4),
            psi=t.number("psi", 0.0, lo=-100.0, hi=100.0),
        )
    elif kind == "step":
        ref = Step(_setpoints(t, "setpoints", duration))
    else:
        ref = Waypoints(_setpoints(t, "points", duration))
    t.done()
    return ref
