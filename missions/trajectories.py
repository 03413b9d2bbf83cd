"""A mission's trajectory from its ``[trajectory]`` table, and a ground station's plan as a smooth trajectory.

In:  a ``[trajectory]`` table (:class:`params.Table`: ``kind`` and its keys; times s, positions m, angles rad),
     the mission's duration (s), a plan file (``.plan``, ``QGC WPL 110``: read by :func:`params.read_text_file`) or
     a read :class:`~missions.planfiles.PlanFile`, PX4's speed and acceleration limits by name, and the
     :class:`~missions.steps.PlanBudget` a plan's mission may last
Out: a :class:`~missions.references.Reference` (step, sine, waypoints, smooth, a plan's smooth); a bad value as a
     :class:`params.ConfigError` naming the file and the key

Split out of :mod:`missions.mission` (which reads the rest of a mission file and builds the :class:`Mission`):
this module is what a trajectory's table and a plan become.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path

from missions.envelope import ENVELOPE_RADIUS_M
from missions.minsnap import Knot, Smooth
from missions.planfiles import MAX_ITEMS, PlanFile, read_plan_text
from missions.references import Reference, Setpoint, Sine, Step, Waypoints
from missions.route import LIMIT_RANGES, Limits, least_duration_s, smooth_from_plan
from missions.steps import PlanBudget
from params import ConfigError, Table, path_problem, read_text_file

TRAJECTORIES = ("step", "sine", "waypoints", "smooth", "plan")
PLAN_MAX_BYTES = 16 << 20  # a plan of MAX_ITEMS items is about 5 MB of JSON
END_REST_S = 1.0  # s: a plan's mission lasts this long after its trajectory ends (at rest, or on the ground)
PSI_RANGE = (-2 * math.pi, 2 * math.pi)  # rad: a yaw of one turn either way (a start's, a sine's, a first point's)
MAX_STRETCH = 4.0  # the most a trajectory is slowed (``stretched_by``; missions.airframe fits a plan's with it)


def plan_smooth(plan: PlanFile, limits: Mapping[str, float] | None = None, budget: PlanBudget | None = None) -> Smooth:
    """The smooth trajectory of a read plan (a file's, or one a ground station uploaded): its cruise speed is
    MPC_XY_CRUISE unless ``limits`` give it. With a ``budget`` (how long the mission it makes may last), a plan
    whose least length (:func:`missions.route.least_duration_s`, then :data:`END_REST_S`) is over it is refused
    before the trajectory is timed (milliseconds, where the timing takes seconds a thousand items)."""
    given = dict(limits or {})
    if plan.cruise_m_s is not None and "MPC_XY_CRUISE" not in given:
        lo, hi = LIMIT_RANGES["MPC_XY_CRUISE"]
        if not lo <= plan.cruise_m_s <= hi:
            raise ConfigError(f"{plan.source}: mission.hoverSpeed: {plan.cruise_m_s:g} m/s, must be in "
                              f"[{lo:g}, {hi:g}]")
        given["MPC_XY_CRUISE"] = plan.cruise_m_s
    limited = Limits(**given)
    if budget is not None:
        budget.check(plan.source, len(plan.items), least_duration_s(plan, limited, ENVELOPE_RADIUS_M) + END_REST_S)
    smooth, _ = smooth_from_plan(plan, limited, ENVELOPE_RADIUS_M)
    return smooth


def _setpoints(t: Table, key: str, duration: float, stops: list[bool] | None = None) -> tuple[Setpoint, ...]:
    """The list of points {t, x, y, z, psi} under ``key``; with ``stops``, each may say ``stop`` (appended)."""
    items = t.raw(key)
    if not isinstance(items, list) or not items:
        raise t.error(key, "expected a non-empty list of tables {t, x, y, z, psi}")
    if len(items) > MAX_ITEMS:  # as a plan's items: checked before any is read (19 000 smooth knots: 39 s to refuse)
        raise t.error(key, f"{len(items)} points, more than {MAX_ITEMS}")
    out = []
    for i, item in enumerate(items):
        s = Table(item, t._source, f"{t.key(key)}[{i}]")
        sp = Setpoint(
            s.number("t", lo=0.0, hi=duration),
            s.number("x", lo=-1e4, hi=1e4),
            s.number("y", lo=-1e4, hi=1e4),
            s.number("z", lo=-1e4, hi=1e4),
            psi_of(s, out[-1].psi if out else None),
        )
        if stops is not None:
            stops.append(s.boolean("stop", False))
        s.done()
        if out and sp.t <= out[-1].t:
            raise s.error("t", f"must be later than the previous one ({out[-1].t:g})")
        out.append(sp)
    return tuple(out)


def psi_of(t: Table, previous: float | None = None) -> float:
    """Key ``psi`` of ``t`` (rad; 0 if not given): in :data:`PSI_RANGE`, or with ``previous`` (the point before's)
    within one turn of it, so a list of points may turn on (a plan's knots are unwrapped along its route, and a
    run's mission.toml holds them so). A yaw in degrees (``psi = 90``: 14 turns) is refused, saying so."""
    v = t.number("psi", 0.0)
    unit = "radians; a QGC plan's yaw, param4, is degrees"
    if previous is None and not PSI_RANGE[0] <= v <= PSI_RANGE[1]:
        raise t.error("psi", f"must be in [-2π, 2π] = [{PSI_RANGE[0]:.5g}, {PSI_RANGE[1]:.5g}] ({unit}), got {v:g}")
    if previous is not None and abs(v - previous) > PSI_RANGE[1]:
        raise t.error("psi", f"must be within 2π = {PSI_RANGE[1]:.5g} (one turn) of the point before's {previous:g} "
                             f"({unit}), got {v:g}")
    return v


def trajectory_of(t: Table, duration: float, budget: PlanBudget | None = None,
                  plan: PlanFile | None = None) -> Reference:
    """The trajectory of a ``[trajectory]`` table; a plan's (``kind = "plan"``) with ``budget`` (:func:`plan_smooth`),
    ``plan`` its file if read already."""
    kind = t.string("kind", choices=TRAJECTORIES)
    if kind == "sine":
        ref: Reference = Sine(
            amplitude=t.number("amplitude", 1.0, lo=0.0, hi=1e4),
            omega=t.number("omega", 0.5, lo=0.0, hi=100.0),
            climb=t.number("climb", 0.1, lo=-100.0, hi=100.0),
            z0=t.number("z0", 0.0, lo=-1e4, hi=1e4),
            psi=psi_of(t),
            x0=t.number("x0", 0.0, lo=-1e4, hi=1e4),
            y0=t.number("y0", 0.0, lo=-1e4, hi=1e4),
        )
    elif kind == "step":
        ref = Step(_setpoints(t, "setpoints", duration))
    elif kind == "waypoints":
        ref = Waypoints(_setpoints(t, "points", duration))
    elif kind == "smooth":
        ref = _smooth(t, duration)
    else:
        ref = _plan(t, budget, plan)
        if ref.end_s > duration:  # its knots past duration_s, as a step's point past it: refused, not cut
            least = f"at least {ref.end_s:g} s"
            own = t.key("file") == "trajectory.file"  # (a fleet's vehicle's: duration_s is the mission's trajectory's)
            fix = f"drop duration_s to fly the plan's own length (or give {least})" if own else \
                f"give a duration_s of {least}"
            raise t.error("file", f"{t.raw('file')} flies {ref.end_s:g} s, then {END_REST_S:g} s at rest ("
                                  f"{ref.end_s + END_REST_S:g} s flown whole), longer than the mission's duration_s = "
                                  f"{duration:g} s, which would end the flight inside the plan; {fix}")
    t.done()
    return ref


def _smooth(t: Table, duration: float) -> Smooth:
    """``kind = "smooth"``: knots {t, x, y, z, psi, stop} (the times from 0), ``lands``, ``stretched_by``."""
    lands = t.boolean("lands", False)
    factor = t.number("stretched_by", 1.0, lo=1.0, hi=MAX_STRETCH)
    stops: list[bool] = []
    points = _setpoints(t, "points", duration, stops)
    if len(points) < 2:
        raise t.error("points", "a smooth trajectory needs at least two points")
    return Smooth(tuple(Knot(p.t, p.x, p.y, p.z, p.psi, s) for p, s in zip(points, stops)), lands, factor)


def _plan(t: Table, budget: PlanBudget | None = None, plan: PlanFile | None = None) -> Smooth:
    """``kind = "plan"``: ``file`` (a ``.plan`` or ``QGC WPL 110`` file, relative to the mission's folder; ``plan``,
    if read already) and PX4's speed and acceleration limits by name (:class:`missions.route.Limits`)."""
    p = _plan_path(t, t.string("file"))
    limits = {k: t.number(k, lo=lo, hi=hi) for k, (lo, hi) in LIMIT_RANGES.items() if t.has(k)}
    return plan_smooth(plan if plan is not None else _read_plan(t, p), limits, budget)


def _plan_path(t: Table, name: str) -> Path:
    """A ``kind = "plan"`` trajectory's ``file``: relative to the mission's folder (an empty one is refused as an
    empty flag path is: not the mission's folder)."""
    why = path_problem(name, "give the plan's file, relative to the mission's folder")
    if why:
        raise t.error("file", why)
    p = Path(name).expanduser()
    return p if p.is_absolute() else Path(t._source).parent / p


def plan_of(t: Table) -> PlanFile | None:
    """A ``kind = "plan"`` trajectory's plan file, read (its route, geofence and rally points: read once), or
    None (another kind, or no ``file`` named: :func:`_plan` names the key)."""
    if t.raw("kind") != "plan" or not isinstance(t.raw("file"), str):
        return None
    return _read_plan(t, _plan_path(t, t.raw("file")))


def _read_plan(t: Table, p: Path) -> PlanFile:
    """The plan file ``p`` that ``t``'s ``file`` names, read; one that cannot be read (not there, a folder, not
    text) is named as the key too (``m.toml: trajectory.file: m/box.plan: no such file``), a bad plan by its item."""
    try:
        text = read_text_file(p, "a mission plan", PLAN_MAX_BYTES)
    except ConfigError as exc:
        raise t.error("file", str(exc)) from None
    return read_plan_text(text, str(p))
