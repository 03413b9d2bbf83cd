"""Mission files: load, validate, and the :class:`Mission` they describe.

In:  a mission TOML file's path (read by :func:`params.load_toml`), a ground station's plan (``.plan``,
     ``.waypoints``, ``.txt``: read by :func:`params.read_text_file`), or a TOML's parsed table, or the
     fields given in Python: a trajectory, ``duration_s`` (s), ``rate_hz`` and ``physics_hz`` (Hz),
     ``start`` (x, y, z in m, psi in rad; paper frame NWU, z up) and its ``scatter_m`` (m), the profile, law
     and seed names, and the raw tables of the other parts
Out: a frozen, validated :class:`Mission` (its trajectory a :class:`~missions.references.Reference`; its
     ``flight_start``, where its seed's flight begins: :mod:`missions.scatter`);
     a bad value as a :class:`params.ConfigError` naming the file and the key; ``to_dict`` the
     TOML-ready table a run's ``mission.toml`` holds

A mission names its trajectory, duration, vehicle profile, controller and gains, rates,
effects, link impairment, wind, timeline of events and seed. The tables ``[gains]``, ``[effects]``, ``[link]``,
``[failsafe]``, ``[sensors]``, ``[estimator]``, ``[params]``, ``[wind]`` and ``[[events]]`` belong to other parts
(controller, plant, bridge):
they are kept here as raw tables with their source and validated by the part that owns them when a run is built, so
errors still name the file and the key.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from numbers import Integral, Real
from pathlib import Path, PurePath
from typing import Any

from missions.envelope import ENVELOPE_RADIUS_M, envelope_problem, ground_problem
from missions.fleet import Separation, VehicleSpec, fleet_from_table, four_of
from missions.geodetic import Home as GeoHome
from missions.geofence import Geofence, geofence_from_table
from missions.planfiles import PlanFile, read_plan_text
from missions.rally import rally_dict, rally_from_plan, rally_from_table
from missions.references import Reference, Sine, Step, Waypoints
from missions.scatter import fleet_scatter_problem, scattered_start
from missions.steps import PlanBudget, StepCap
from missions.trajectories import END_REST_S, PLAN_MAX_BYTES, PSI_RANGE, plan_of, plan_smooth, psi_of, trajectory_of
from params import ConfigError, Table, load_toml, read_text_file, show, unreachable

CONTROLLERS = ("bsst", "smc", "pid")
# how the super-twisting step of ``bsst`` is stepped over the control period (controller.supertwisting):
# forward Euler as the paper prints it, or backward Euler solved in closed form (docs/law.md, "Discretization")
DISCRETIZATIONS = ("explicit", "implicit")
# the one default of the whole tree (mission key, flags, Python API, batch engine): implicit keeps every
# acceptance figure of the paper without the explicit step's period-2 chattering (issue 24's rule; docs/law.md,
# "Which is the default"); ``explicit`` flies the paper as printed, bit for bit
DEFAULT_DISCRETIZATION = "implicit"
# the allowed range [lo, hi] of each top-level number of a mission (duration_s: lo excluded), shared by
# the loader, the command-line flags (--rate, --seed) and the sweep axes: one range per key
MISSION_RANGES: dict[str, tuple[float, float]] = {
    "duration_s": (0.0, 86400.0),
    "rate_hz": (50.0, 1000.0),
    "physics_hz": (100.0, 10000.0),
    "seed": (0, 2**31 - 1),
    "start_scatter_m": (0.0, 100.0),  # [start] scatter_m, --scatter: missions.scatter
    "psi": PSI_RANGE,  # rad: [start] psi, a sine's, a first point's (missions.trajectories.psi_of)
}
PLAN_SUFFIXES = (".plan", ".waypoints", ".txt")  # QGroundControl's JSON plan; QGC WPL 110 text
DEFAULT_RATE_HZ = 250.0  # Hz: a mission's control rate unless it gives one (a plan's, always)
DEFAULT_PHYSICS_HZ = 1000.0  # Hz: a mission's physics rate unless it gives one
# what the vehicle does once the mission's time is flown (``[end] action``): land where it is with its on-board
# landing and disarm on the ground, or hold its position until the session ends; never motors off in the air
END_ACTIONS = ("land", "hold")
DEFAULT_END_ACTION = "land"
NAME_MAX_BYTES = 100  # a run directory is runs/<UTC time>-<name>[-N]: well under a file system's 255 bytes


@dataclass(frozen=True)
class Mission:
    """One flight: a reference to follow for ``duration_s`` and how to fly it."""

    trajectory: Reference
    duration_s: float
    name: str = "mission"
    profile: str = "paper"
    actuation: str | None = None  # None: the profile's own
    controller: str = "bsst"
    discretization: str = DEFAULT_DISCRETIZATION  # DISCRETIZATIONS; only ``bsst`` has a step it changes
    rate_hz: float = DEFAULT_RATE_HZ
    physics_hz: float = DEFAULT_PHYSICS_HZ
    seed: int = 0
    start: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)  # x, y, z, psi at rest
    start_scatter_m: float = 0.0  # [start] scatter_m: each seed starts in a disc this wide around it (flight_start)
    gains: Mapping[str, Any] = field(default_factory=dict)
    effects: Mapping[str, Any] = field(default_factory=dict)
    link: Mapping[str, Any] = field(default_factory=dict)
    failsafe: Mapping[str, Any] = field(default_factory=dict)
    sensors: Mapping[str, Any] = field(default_factory=dict)  # raw: plant.profiles.sensors_from_table
    estimator: Mapping[str, Any] = field(default_factory=dict)  # raw: bridge.core.flight validates kind
    params: Mapping[str, Any] = field(default_factory=dict)  # raw: bridge.autopilot.params.params_from_table
    source: str = "<python>"
    wind: Mapping[str, Any] = field(default_factory=dict)  # raw: plant.wind.wind_from_table
    events: tuple[Mapping[str, Any], ...] = ()  # raw [[events]]: plant.events.timeline_from_tables
    end_action: str = DEFAULT_END_ACTION  # END_ACTIONS: ``[end] action``
    vehicles: tuple[Any, ...] = ()  # [[vehicles]]: missions.fleet.VehicleSpec, validated; () one vehicle
    separation: Any = None  # [separation]: missions.fleet.Separation; None: its defaults
    geofence: Any = None  # [geofence], or a plan's geoFence: missions.geofence.Geofence; None: none
    rally: tuple[tuple[float, float], ...] = ()  # [rally] points (x, y m), or a plan's rallyPoints: missions.rally

    def __post_init__(self) -> None:
        check_fields(self)  # first: its source, which every error names
        why = name_problem(self.name)
        if why:
            raise ConfigError(f"{self.source}: name: {why}")
        check_timing(self.duration_s, self.rate_hz, self.physics_hz, self.source)
        object.__setattr__(self, "start", tuple(map(float, self.start)))  # an array's, numpy's numbers: a file's
        why = law_spec_problem(self.controller)
        if why:
            raise ConfigError(f"{self.source}: controller: {why}")
        if self.discretization not in DISCRETIZATIONS:
            raise ConfigError(f"{self.source}: discretization: must be one of {', '.join(DISCRETIZATIONS)}; "
                              f"got {self.discretization!r}"[:300])
        if self.end_action not in END_ACTIONS:
            raise ConfigError(f"{self.source}: end.action: must be one of {', '.join(END_ACTIONS)}; "
                              f"got {self.end_action!r}"[:300])
        lo, hi = MISSION_RANGES["start_scatter_m"]
        if isinstance(self.start_scatter_m, bool) or not isinstance(self.start_scatter_m, Real):
            raise ConfigError(f"{self.source}: start.scatter_m: expected a number (m), "
                              f"got {show(self.start_scatter_m)}")
        if not lo <= self.start_scatter_m <= hi:  # also refuses nan
            raise ConfigError(f"{self.source}: start.scatter_m: must be in [{lo:g}, {hi:g}] m; "
                              f"got {self.start_scatter_m!r}"[:300])
        why = fleet_scatter_problem(self.start_scatter_m, "[[vehicles]], --vehicles" if self.vehicles else "")
        if why is not None:
            raise ConfigError(f"{self.source}: start.scatter_m: {why}")
        outside = (envelope_problem(self.trajectory, self.start, self.duration_s, self.start_scatter_m)
                   or ground_problem(self.trajectory, self.start, self.duration_s))
        if outside:
            raise ConfigError(f"{self.source}: {outside[0]}: {outside[1]}")

    @property
    def flight_start(self) -> tuple[float, float, float, float]:
        """Where this flight begins (x, y, z m, psi rad): ``start``, or with ``start_scatter_m`` a point drawn
        around it from the seed (:func:`missions.scatter.scattered_start`)."""
        return scattered_start(self.start, self.start_scatter_m, self.seed)

    def with_overrides(self, **kw: Any) -> Mission:
        """A copy with some fields replaced (None values are ignored), validated again."""
        return replace(self, **{k: v for k, v in kw.items() if v is not None})

    def to_dict(self) -> dict[str, Any]:
        """The mission as a TOML-ready table (what ``mission.toml`` of a run holds)."""
        d: dict[str, Any] = {"name": self.name, "duration_s": self.duration_s, "profile": self.profile,
                             "controller": self.controller, "discretization": self.discretization,
                             "rate_hz": self.rate_hz, "physics_hz": self.physics_hz, "seed": self.seed}
        if self.actuation:
            d["actuation"] = self.actuation
        d["start"] = {"position": list(self.start[:3]), "psi": self.start[3]}
        if self.start_scatter_m:  # (none: mission.toml as before)
            d["start"]["scatter_m"] = self.start_scatter_m
        d["trajectory"] = self.trajectory.to_dict()
        for k in ("gains", "effects", "link", "failsafe", "sensors", "estimator", "params", "wind"):
            if getattr(self, k):
                d[k] = dict(getattr(self, k))
        if self.events:
            d["events"] = [dict(e) for e in self.events]
        if self.end_action != DEFAULT_END_ACTION:  # (the default unwritten: mission.toml as before)
            d["end"] = {"action": self.end_action}
        if self.vehicles:  # (a mission of one vehicle writes neither)
            d["vehicles"] = [v.to_dict() for v in self.vehicles]
        if self.separation is not None:
            d["separation"] = self.separation.to_dict()
        if self.geofence is not None:
            d["geofence"] = self.geofence.to_dict()
        if self.rally:
            d["rally"] = rally_dict(self.rally)
        return d

    @property
    def steps(self) -> int:
        """Number of control steps in the mission."""
        return int(round(self.duration_s * self.rate_hz))


def name_problem(name: object) -> str | None:
    """Why ``name`` cannot name a mission, or None. It names the run directory,
    ``runs/<UTC time>-<name>``, so it must be one safe path component: not blank, no ``/`` or ``\\``,
    printable (no newline, tab or other control character), at most :data:`NAME_MAX_BYTES` bytes of
    UTF-8. Refused, never rewritten: the name in ``summary.json`` is the directory's."""
    if not isinstance(name, str):
        return f"expected a string, got {name!r}"[:200]
    if not name.strip():
        return "must not be blank (it names the run directory runs/<UTC time>-<name>)"
    if "/" in name or "\\" in name:
        return f"must not contain / or \\ (it names the run directory runs/<UTC time>-<name>); got {name!r}"[:200]
    if not name.isprintable():
        return f"must be printable, without newlines, tabs or other control characters; got {name!r}"[:200]
    if len(name.encode()) > NAME_MAX_BYTES:
        return f"must be at most {NAME_MAX_BYTES} bytes of UTF-8 (it names the run directory), got {len(name.encode())}"
    return None


def law_spec_problem(spec: object) -> str | None:
    """Why ``spec`` cannot name a law, or None: a built-in name, or ``path/to/file.py:ClassName``
    or ``package.module:ClassName`` (whether that file, module and class exist, and fit the
    law interface, is checked when the flight is built: controller.law.resolve_law)."""
    if not isinstance(spec, str):
        return f"must be a string, got {spec!r}"
    if spec in CONTROLLERS:
        return None
    where, sep, cls = spec.rpartition(":")
    if sep and where.strip() and cls.isidentifier() and "\n" not in spec:
        return None
    return (f"must be one of {', '.join(CONTROLLERS)}, or path/to/file.py:ClassName, or package.module:ClassName; "
            f"got {spec!r}")


def law_spec_from(spec: str, base: Path) -> str:
    """``spec`` with a relative law file made absolute against ``base`` (a mission file's folder;
    the working directory for a command-line flag), so that every process that reads the flown
    ``mission.toml`` finds the same file."""
    where, sep, cls = spec.rpartition(":")
    if not sep or not (where.endswith(".py") or "/" in where or "\\" in where):
        return spec
    p = Path(where).expanduser()
    return f"{p if p.is_absolute() else (base / p).absolute()}:{cls}"


def check_timing(duration_s: float, rate_hz: float, physics_hz: float, source: str = "<python>") -> None:
    """Rates and duration must be numbers (a Python caller's text or bool is named) in their ranges, and the physics
    rate a multiple of the control rate (named where not the default: it, not the rate, may be what was set)."""
    for key, v in (("duration_s", duration_s), ("rate_hz", rate_hz), ("physics_hz", physics_hz)):
        if isinstance(v, bool) or not isinstance(v, Real):
            raise ConfigError(f"{source}: {key}: expected a number ({'s' if key == 'duration_s' else 'Hz'}), got {v!r}"
                              [:300])
        (lo, hi), left = MISSION_RANGES[key], "(" if key == "duration_s" else "["  # (a duration of 0 s is none)
        if not (lo < v if left == "(" else lo <= v) or not v <= hi:  # also refuses nan
            raise ConfigError(f"{source}: {key}: must be in {left}{lo:g}, {hi:g}], got {v:g}")
    why = rate_problem(rate_hz, physics_hz, " (physics_hz)" if physics_hz != DEFAULT_PHYSICS_HZ else "")
    if why is not None:
        raise ConfigError(f"{source}: rate_hz: {why}, got {rate_hz:g}")


def rate_problem(rate_hz: float, physics_hz: float, physics_from: str = "") -> str | None:
    """Why ``rate_hz`` (Hz) cannot be flown at ``physics_hz`` (Hz; set where ``physics_from`` says), or None: the one
    rule, for the loader (``rate_hz``) and ``--rate`` (named as the flag: bridge.cli.options.checked_mission)."""
    ratio = physics_hz / rate_hz
    if abs(ratio - round(ratio)) <= 1e-9 and round(ratio) >= 1:
        return None
    lo, hi = MISSION_RANGES["rate_hz"]
    whole = [r for k in range(1, int(physics_hz // lo) + 1) if lo <= (r := physics_hz / k) <= hi and r == int(r)]
    shown = f"; the whole ones {', '.join(f'{r:g}' for r in sorted(whole))}" if whole else ""
    return (f"the physics rate {physics_hz:g} Hz{physics_from} must be a whole multiple of it (allowed: "
            f"{physics_hz:g} Hz divided by a whole number, {lo:g}-{hi:g} Hz{shown})")


SHIPPED_DIR = Path(__file__).parent  # the missions that come with the package


def mission_path(path: str | Path) -> Path:
    """``path``, or the shipped mission it names when there is no such file here: a bare name
    (``sine``) or ``missions/<name>.toml``, so that an installed ``bsst`` flies the paper's
    missions from any directory. A file of that name in the working directory always wins."""
    p = Path(path)
    if unreachable(p) or p.exists():  # (one that cannot be looked up: its reader names it)
        return p
    named = (len(p.parts) == 1 and p.suffix == "") or (len(p.parts) == 2 and p.parts[0] == "missions")
    shipped = SHIPPED_DIR / (p.name if p.suffix == ".toml" else f"{p.name}.toml")
    return shipped if named and shipped.is_file() else p


def is_plan_file(path: str | Path) -> bool:
    """Whether ``path`` names a ground station's mission (by its suffix: :data:`PLAN_SUFFIXES`)."""
    return Path(path).suffix.lower() in PLAN_SUFFIXES


def load_mission(path: str | Path, cap: StepCap | None = None, table: Mapping[str, Any] | None = None) -> Mission:
    """Read and validate a mission TOML file (a shipped one by name: :func:`mission_path`; ``table``: its TOML, read
    already), or a ground station's plan (:func:`is_plan_file`: flown with every other setting at its default). ``cap``:
    the control steps the command keeps (:class:`missions.steps.StepCap`): a mission over it is refused as soon as
    its length is known, a plan's before its trajectory is timed when even its least length is over."""
    if not isinstance(path, str | PurePath):  # simulate(5), sweep(None): named, not os.fspath's bare TypeError
        raise TypeError(f"mission: expected a Mission or a path to its file, got {path!r}"[:200])
    p = mission_path(path)
    if is_plan_file(p):
        return mission_from_plan(read_text_file(p, "a mission plan", PLAN_MAX_BYTES), str(p), p.stem, cap)
    return mission_from_table(load_toml(p) if table is None else table, str(p), default_name=p.stem, cap=cap)


def _budget(rate_hz: float, cap: StepCap | None = None) -> PlanBudget:
    """What a plan's mission may last: the longest ``duration_s``, and ``cap`` at ``rate_hz``."""
    return PlanBudget(MISSION_RANGES["duration_s"][1], rate_hz, cap)


def with_plan(base: Mission, plan: PlanFile, name: str, cap: StepCap | None = None) -> Mission:
    """``base`` (its settings: profile, law, rates, link, ...) flying ``plan``: its trajectory, then
    :data:`END_REST_S` at rest, named ``name`` (``cap``: as :func:`load_mission`'s, a plan too long for it
    refused before it is timed)."""
    smooth = plan_smooth(plan, budget=_budget(base.rate_hz, cap))
    return replace(base, trajectory=smooth, duration_s=smooth.end_s + END_REST_S, name=name, geofence=plan.fence,
                   rally=_plan_rally(plan))


def mission_from_plan(text: str, source: str, name: str = "mission", cap: StepCap | None = None) -> Mission:
    """The mission of a plan's text: its trajectory, then :data:`END_REST_S` at rest; defaults otherwise
    (``cap``: :func:`load_mission`)."""
    plan = read_plan_text(text, source)
    smooth = plan_smooth(plan, budget=_budget(DEFAULT_RATE_HZ, cap))
    return Mission(trajectory=smooth, duration_s=smooth.end_s + END_REST_S, name=name, source=source,
                   geofence=plan.fence, rally=_plan_rally(plan))


def _plan_rally(plan: PlanFile) -> tuple[tuple[float, float], ...]:
    """A plan's rally points in the paper frame about its home (within the plant's envelope)."""
    return rally_from_plan(plan.rally, GeoHome(*plan.home), plan.source, ENVELOPE_RADIUS_M)


def mission_from_table(data: Mapping[str, Any], source: str, default_name: str = "mission",
                       cap: StepCap | None = None) -> Mission:
    t = Table(data, source)
    name = t.string("name", default_name)
    trajectory_table = t.table("trajectory", required=True)
    derived = trajectory_table.raw("kind") == "plan" and not t.has("duration_s")  # the plan's own length
    duration = 0.0 if derived else t.number("duration_s", lo=MISSION_RANGES["duration_s"][0], lo_open=True,
                                            hi=MISSION_RANGES["duration_s"][1])
    profile, actuation = _vehicle_of(t)
    controller = _law(t, "controller") or "bsst"
    discretization = t.string("discretization", DEFAULT_DISCRETIZATION, choices=DISCRETIZATIONS)
    r = MISSION_RANGES
    rate = t.number("rate_hz", DEFAULT_RATE_HZ, lo=r["rate_hz"][0], hi=r["rate_hz"][1])
    physics = t.number("physics_hz", DEFAULT_PHYSICS_HZ, lo=r["physics_hz"][0], hi=r["physics_hz"][1])
    if not t.has("rate_hz") and (why := rate_problem(rate, physics, " (physics_hz)")):  # the default's, not the file's
        raise ConfigError(f"{source}: rate_hz: not given, so {rate:g} Hz (the default), and {why}; give rate_hz "
                          f"(in the file: --rate lays a rate over it, but the file's own must fit too)")
    seed = _seed_of(t)
    st = t.table("start")
    start = _start_of(st)
    scatter = st.number("scatter_m", 0.0, lo=r["start_scatter_m"][0], hi=r["start_scatter_m"][1])
    st.done()
    too_long = cap.problem(duration, rate) if cap is not None and not derived else None  # before the trajectory
    if too_long:
        raise ConfigError(f"{source}: {too_long}")
    budget = _budget(rate, cap) if derived else None  # a plan's own length: checked before it is timed
    plan = plan_of(trajectory_table)  # its plan file, read once (None: no plan, or no file named)
    trajectory = trajectory_of(trajectory_table, duration if not derived else MISSION_RANGES["duration_s"][1], budget,
                               plan)
    if derived:
        duration = trajectory.end_s + END_REST_S  # type: ignore[attr-defined]
    raw = {k: _table(t, k) for k in ("gains", "effects", "link", "failsafe", "sensors", "estimator", "params", "wind")}
    end = t.table("end")
    end_action = end.string("action", DEFAULT_END_ACTION, choices=END_ACTIONS)
    end.done()
    events = t.raw("events", [])
    if not isinstance(events, list) or not all(isinstance(e, Mapping) for e in events):
        raise t.error("events", "expected an array of tables [[events]] (t_s, kind and its settings)")
    span = duration if not derived else MISSION_RANGES["duration_s"][1]
    vehicles, separation = fleet_from_table(t, lambda tt: trajectory_of(tt, span, budget), _law)
    fence, rally = (plan.fence, _plan_rally(plan)) if plan is not None else (None, ())  # a plan's, unless its own
    fence = geofence_from_table(t.table("geofence")) if t.has("geofence") else fence
    rally = rally_from_table(t.table("rally"), ENVELOPE_RADIUS_M) if t.has("rally") else rally
    t.done()
    return Mission(
        trajectory=trajectory,
        duration_s=duration,
        name=name,
        profile=profile,
        actuation=actuation,
        controller=controller,
        discretization=discretization,
        rate_hz=rate,
        physics_hz=physics,
        seed=seed,
        start=start,  # type: ignore[arg-type]
        start_scatter_m=scatter,
        source=source,
        events=tuple(events),
        end_action=end_action,
        vehicles=vehicles,
        separation=separation,
        geofence=fence,
        rally=rally,
        **raw,
    )


def _seed_of(t: Table) -> int:
    """Key ``seed`` of ``t``: an integer in its one range (:data:`MISSION_RANGES`); 0 if not given."""
    lo, hi = MISSION_RANGES["seed"]
    return t.integer("seed", 0, lo=int(lo), hi=int(hi))


def _vehicle_of(t: Table) -> tuple[str, str | None]:
    """Keys ``profile`` (a name or a profile file's path, found when the flight is built) and ``actuation`` (None:
    the profile's own) of ``t``."""
    return t.string("profile", "paper"), t.string("actuation", "", choices=("", "wrench", "motors")) or None


def _start_of(st: Table) -> tuple[float, float, float, float]:
    """A ``[start]`` table's ``position`` (x, y, z m) and ``psi`` (rad: :func:`psi_of`), as the start's 4-tuple."""
    return st.vector("position", 3, (0.0, 0.0, 0.0), lo=-1e4, hi=1e4) + (psi_of(st),)  # type: ignore[return-value]


def check_fields(m: Mission) -> None:
    """The fields of a :class:`Mission` built in Python that a mission file's loader reads, read as it reads them
    (one reader and one range per key: :data:`MISSION_RANGES`, :data:`missions.trajectories.PSI_RANGE`,
    :func:`missions.trajectories.trajectory_of`), so that ``Mission(seed="x")`` or ``Mission(Sine(psi=90), ...)`` is
    refused as a file's ``seed = "x"`` or ``psi = 90`` is, the field named as the file's key (``seed``,
    ``start.psi``, ``trajectory.psi``, ``trajectory.setpoints[0].t``; a point's time may be past ``duration_s``, never
    past the longest mission's): a trajectory of the kinds a file writes
    (:class:`Sine`, :class:`Step`, :class:`Waypoints`), the raw tables (a mapping each) and ``events``. A smooth
    trajectory (a plan's, checked as it is planned) and a caller's own reference are taken as given. ``source``
    first: every error names it (a string: the file, or ``<python>``)."""
    if not isinstance(m.source, str):
        raise ConfigError(f"<python>: source: expected a string (the mission's file, or '<python>': its errors name "
                          f"it), got {show(m.source)}")
    top = Table(_plain({"seed": m.seed, "profile": m.profile, "actuation": "" if m.actuation is None else m.actuation}),
                m.source)
    _seed_of(top)
    _vehicle_of(top)
    start = m.start
    if four_of(start) is None:
        raise ConfigError(f"{m.source}: start: expected (x, y, z, psi): 4 numbers (m, m, m, rad), got {show(start)}")
    _start_of(Table(_plain({"position": list(start[:3]), "psi": start[3]}), m.source, "start"))
    ref = m.trajectory
    if not all(callable(getattr(ref, a, None)) for a in ("sample", "change_times", "to_dict")):
        raise ConfigError(f"{m.source}: trajectory: expected a reference (Sine, Step, Waypoints, or an object with "
                          f"sample, change_times and to_dict: missions.references.Reference), got {show(ref)}")
    if isinstance(ref, _READ_AGAIN):  # (each value read as the file's: a new reference, thrown away)
        # a point's time up to the longest mission's, not this one's: a file's mission flown shorter from Python
        # (``replace(step, duration_s=12.0)``, its first 12 s) keeps the points it does not reach
        trajectory_of(Table(_plain(ref.to_dict()), m.source, "trajectory"), MISSION_RANGES["duration_s"][1])
    for k in ("gains", "effects", "link", "failsafe", "sensors", "estimator", "params", "wind"):
        if not isinstance(getattr(m, k), Mapping):
            raise ConfigError(f"{m.source}: {k}: expected a table (a mapping), got {show(getattr(m, k))}")
    if not isinstance(m.events, (tuple, list)) or not all(isinstance(e, Mapping) for e in m.events):
        raise ConfigError(f"{m.source}: events: expected a tuple of tables (t_s, kind and its settings), "
                          f"got {show(m.events)}")
    for k, what in (("vehicles", "missions.fleet.VehicleSpec"), ("rally", "(x, y) points (m)")):
        if not isinstance(getattr(m, k), (tuple, list)):
            raise ConfigError(f"{m.source}: {k}: expected a tuple of {what}, got {show(getattr(m, k))}")
    if m.geofence is not None and not isinstance(m.geofence, Geofence):
        raise ConfigError(f"{m.source}: geofence: expected a missions.geofence.Geofence, got {show(m.geofence)}")
    if m.rally:  # read as a file's [rally] points (x, y m within the envelope)
        rally_from_table(Table(_plain({"points": m.rally}), m.source, "rally"), ENVELOPE_RADIUS_M)
    if m.vehicles or m.separation is not None:
        _check_fleet(m)


_READ_AGAIN = (Sine, Step, Waypoints)  # the trajectories check_fields reads again (a smooth one: as given)


def _check_fleet(m: Mission) -> None:
    """A Python mission's ``vehicles`` and ``separation`` read as a file's ``[[vehicles]]`` and ``[separation]``
    (:func:`missions.fleet.fleet_from_table`: ids 1..N, offsets, starts, their trajectories and laws, the ranges)."""
    for i, v in enumerate(m.vehicles):
        if not isinstance(v, VehicleSpec):
            raise ConfigError(f"{m.source}: vehicles[{i}]: expected a missions.fleet.VehicleSpec, got {show(v)}")
        if v.start is not None and four_of(v.start) is None:
            raise ConfigError(f"{m.source}: vehicles[{i}].start: expected (x, y, z, psi): 4 numbers (m, m, m, rad), "
                              f"got {show(v.start)}")
        if v.trajectory is not None and not callable(getattr(v.trajectory, "to_dict", None)):
            raise ConfigError(f"{m.source}: vehicles[{i}].trajectory: expected a reference, got {show(v.trajectory)}")
    if m.separation is not None and not isinstance(m.separation, Separation):
        raise ConfigError(f"{m.source}: separation: expected a missions.fleet.Separation, got {show(m.separation)}")
    table = {"vehicles": [v.to_dict() for v in m.vehicles]} if m.vehicles else {}
    if m.separation is not None:
        table["separation"] = m.separation.to_dict()
    t = Table(_plain(table), m.source)
    longest = MISSION_RANGES["duration_s"][1]
    fleet_from_table(t, lambda tt: trajectory_of(tt, longest) if tt.raw("kind") in ("sine", "step", "waypoints")
                     else Sine(), _law)


def _plain(v: Any) -> Any:
    """A Python caller's value as a TOML file's: numpy's and other numbers as int or float (a bool stays one), lists
    and tuples as lists, mappings as dicts; anything else as it is (its reader names it)."""
    if isinstance(v, bool) or isinstance(v, (str, int, float)):
        return v
    if isinstance(v, Integral):
        return int(v)
    if isinstance(v, Real):
        return float(v)
    if isinstance(v, Mapping):
        return {k: _plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    return v


def _law(t: Table, key: str) -> str | None:
    """A law's name under ``key`` (None if absent), checked, a relative law file made absolute (law_spec_from)."""
    if t.raw(key) is None:  # (asked for all the same: a misspelled key is named with this one)
        return None
    spec = t.string(key)
    why = law_spec_problem(spec)
    if why:
        raise t.error(key, why)
    return law_spec_from(spec, Path(t._source).parent)


def _table(t: Table, name: str) -> Mapping[str, Any]:
    v = t.raw(name, {})
    if not isinstance(v, Mapping):
        raise t.error(name, "expected a table")
    return v
