"""A ground station's mission as flown: the one build and check that the vehicle's start (``bsst vehicle
--await-mission``) and the controller's download share, so the vehicle refuses at its start what the
controller and the session would refuse after (docs/missions.md, "From a ground station").

In:  the settings' :class:`~bridge.core.flight.Flight` (profile, law, rates, ``[link]``, ``--param-at``), the
     mission's items (:class:`~bridge.mavlink.missionitems.MissionItem`) and those of the fence and rally points
     the vehicle holds with it (as a ground station downloads them), the vehicle's home (deg, deg, m AMSL),
     the step cap of a command that keeps its trace in memory (``bsst sitl``: :func:`bridge.record.runlog.trace_cap`;
     None: none), the name its refusals give the mission
Out: the items' plan (:class:`~missions.planfiles.PlanFile`) and the :class:`~bridge.core.flight.Flight` flying
     them (the plan's smooth trajectory), or a :class:`params.ConfigError` saying why they cannot be flown: an
     item, a fence or rally points not read as a plan's (:mod:`bridge.mavlink.fenceitems`, about the home), the
     longest a mission may last, the step cap, a ``--param-at`` after its end, or a trajectory of more points than
     its ``mission.toml`` may hold

Its cost is the plan's timing: about 7 s for 1000 items (measured, one core), which is why the vehicle runs it on
a thread as the upload ends (:mod:`bridge.nodes.vehicle.startcheck`); a plan over the longest duration or the cap
even at its speed limits is refused in milliseconds, before it is timed.
"""

from __future__ import annotations

from collections.abc import Sequence

from bridge.core.flight import Flight, prepare
from bridge.mavlink.fenceitems import fence_plan, rally_plan
from bridge.mavlink.missionitems import MissionItem, plan_of
from missions.mission import with_plan
from missions.planfiles import MAX_ITEMS, PlanFile
from missions.steps import StepCap
from params import ConfigError


def uploaded_flight(flight: Flight, items: Sequence[MissionItem], home: tuple[float, float, float],
                    cap: StepCap | None = None, source: str = "the mission from the vehicle",
                    fence: Sequence[MissionItem] = (), rally: Sequence[MissionItem] = ()) -> tuple[PlanFile, Flight]:
    """``items``' plan about ``home`` (with the held ``fence``'s and ``rally`` points' items as its ``geoFence`` and
    ``rallyPoints``, :func:`~bridge.mavlink.missionitems.plan_of`), and ``flight``'s settings flying it (see the
    module docstring); ConfigError naming ``source`` when they cannot be flown."""
    try:
        geo_fence = fence_plan(tuple(fence))
    except ValueError as exc:  # a polygon's vertices not in a row
        raise ConfigError(f"{source}: {exc}") from None
    plan = plan_of(tuple(items), home, source, geo_fence, rally_plan(tuple(rally)))
    mission = with_plan(flight.mission, plan, flight.mission.name, cap)
    new = prepare(mission, param_at=flight.param_changes)  # --param-at: in this mission's time
    points = len(getattr(new.mission.trajectory, "knots", ()))
    if points > MAX_ITEMS:  # its mission.toml (kind = "smooth") is read back by the session and the children
        raise ConfigError(f"{source}: its trajectory has {points} points, more than the {MAX_ITEMS} a mission file "
                          "may hold (mission.toml, read back as flown)")
    why = cap.problem(new.mission.duration_s, new.mission.rate_hz) if cap is not None else None
    if why:
        raise ConfigError(f"{source}: {why}")
    return plan, new
