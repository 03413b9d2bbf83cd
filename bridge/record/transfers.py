"""``summary.json["mission_transfer"]`` (``bsst sitl --await-mission``): the controller's downloads from the vehicle.

In:  what the controller said of its downloads (its ``stats``' or ``mission`` report's ``mission_transfer``: the
     mission's :class:`~bridge.mavlink.missionitems.TransferStats` fields, and those of the fence's and the rally
     points' under ``fence`` and ``rally``), the vehicle's start (its ``stats``' ``mission_start``: ``command``,
     ``by``)
Out: :class:`MissionTransfer` (:func:`mission_transfer`), or None when the controller said none

The mission's figures stay at the record's top level, as they were before the fence and the rally points were in
it (their downloads follow the mission's: bridge.nodes.offboard.mission); each of those is a
:class:`TypeTransfer` of its own under ``fence`` and ``rally``, None when the controller never began it.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class TypeTransfer:
    """One download's figures: its items, the requests sent (``attempts``: the first of each message and every one
    again), those sent again (``re_requests``), its wall time (s) and ``result`` (``accepted``, or why not)."""

    items: int
    attempts: int
    re_requests: int
    duration_s: float
    result: str

    def as_dict(self) -> dict[str, Any]:
        return {"items": self.items, "attempts": self.attempts, "re_requests": self.re_requests,
                "duration_s": self.duration_s, "result": self.result}

    @classmethod
    def of(cls, said: Any) -> TypeTransfer | None:
        """The figures of ``said`` (``TransferStats`` fields), or None when it is not all there."""
        if not isinstance(said, Mapping):
            return None
        try:
            return cls(int(said["items"]), int(said["requests"]), int(said["re_requests"]),
                       float(said["duration_s"]), str(said["result"]))
        except (KeyError, TypeError, ValueError):
            return None


@dataclass(frozen=True)
class MissionTransfer:
    """``summary.json["mission_transfer"]``: the mission's download (:class:`TypeTransfer`'s keys, at the top
    level), then the fence's and the rally points' (``fence``, ``rally``: each a :class:`TypeTransfer`, None if
    never begun); ``started_by``, as the vehicle said it: how the ground station started the mission (``command``:
    ``MISSION_START``, ``AUTO.MISSION, then arm`` or ``arm, then AUTO.MISSION``) and who (``by``:
    ``SYSID:COMPID HOST:PORT LINK``), None if the vehicle said no start."""

    mission: TypeTransfer
    started_by: Mapping[str, str] | None = None
    fence: TypeTransfer | None = None
    rally: TypeTransfer | None = None

    def as_dict(self) -> dict[str, Any]:
        zones = {k: None if z is None else z.as_dict() for k, z in (("fence", self.fence), ("rally", self.rally))}
        return {**self.mission.as_dict(),
                "started_by": dict(self.started_by) if self.started_by is not None else None, **zones}


def mission_transfer(said: Mapping[str, Any] | None, started: Any = None) -> MissionTransfer | None:
    """The :class:`MissionTransfer` of what the controller said and of the vehicle's start, or None when the
    controller said no mission download, or not all of it."""
    mission = TypeTransfer.of(said)
    if mission is None:
        return None
    assert isinstance(said, Mapping)
    start = ({"command": str(started["command"]), "by": str(started["by"])}
             if isinstance(started, Mapping) and {"command", "by"} <= started.keys() else None)
    return MissionTransfer(mission, start, TypeTransfer.of(said.get("fence")), TypeTransfer.of(said.get("rally")))
