"""How the vehicle is reached and clocked: :class:`VehicleConfig`, shared by all its parts, and its two links.

In:  the ``bsst vehicle`` options (addresses, MAVLink ids, clock, speed, timeouts, home, signing key, a fleet's gate)
Out: one frozen :class:`VehicleConfig` (wall times in s, ``speed`` in x real time); :func:`open_links`: its
     controller link and GCS link, bound
"""

from __future__ import annotations

from dataclasses import dataclass, field

from bridge.mavlink import telemetry as tm
from bridge.mavlink.endpoint import CONTROLLER_COMPID, CONTROLLER_SYSID, VEHICLE_COMPID, Address, Endpoint, Tlog
from bridge.mavlink.receive import Rejections
from bridge.mavlink.signing import Signing
from bridge.nodes.vehicle.gate import GateConfig
from missions.steps import StepCap

CLOCKS = ("lockstep", "realtime")


@dataclass(frozen=True)
class VehicleConfig:
    """How the vehicle is reached and clocked (see :mod:`bridge.nodes.vehicle`)."""

    listen: Address
    gcs: Address | None
    sysid: int = 1
    compid: int = VEHICLE_COMPID
    controller_sysid: int = CONTROLLER_SYSID
    controller_compid: int = CONTROLLER_COMPID
    clock: str = "lockstep"
    speed: float | None = None  # x real time: lockstep cap, and pace after losing the controller
    lost_after_s: float = 0.5  # s of wall time
    spin_s: float = 0.0002  # s polled (yielding) before sleeping while a lockstep answer is due: ~4x the
    # peer's median work; longer only burns a core that a busy machine needs for that peer
    home: tm.Home = field(default_factory=tm.Home)
    key: bytes | None = field(default=None, repr=False)  # MAVLink 2 signing key (never shown)
    # the only address the controller's ids are heard from on the controller link (bsst sitl pins the
    # controller's source port); None: learned from its first message, as docs/design.md says
    controller_from: tuple[str, int] | None = None
    # a ground station's mission is flown (bsst sitl --await-mission): MISSION_START and AUTO.MISSION are taken,
    # and the offboard controller, which downloads the mission, flies it (docs/missions.md, "From a ground station")
    await_mission: bool = False
    # the step cap of a session that keeps the mission's trace in memory (bsst sitl's: bsst vehicle --trace-cap):
    # a ground station's mission over it is refused at its start (None: none, the rows stream to disk)
    trace_cap: StepCap | None = None
    # a lockstep fleet's shared step clock (bsst sitl --vehicles, :mod:`bridge.nodes.vehicle.gate`); None: alone
    gate: GateConfig | None = None


def open_links(cfg: VehicleConfig, tlog: Tlog | None, rejected: Rejections) -> tuple[Endpoint, Endpoint | None]:
    """The controller link (``--listen``) and the GCS link (``--gcs``, if any), signed with ``cfg.key``."""
    # one replay table for both links: a signed frame replayed from one link onto the other is refused
    replay: dict[tuple[int, int, int], int] = {}
    sign = ((lambda link_id: Signing(cfg.key, link_id, replay)) if cfg.key is not None
            else (lambda link_id: None))
    link = Endpoint(cfg.listen, sysid=cfg.sysid, compid=cfg.compid, tlog=tlog, name="--listen",
                    signing=sign(0), rejected=rejected, priority=True)
    link.follow = False  # ODOMETRY goes to the flight's controller only (see Receiver.handle)
    # a ground station is charged like any source, and its refusals are not the controller's
    gcs = (Endpoint(cfg.gcs, sysid=cfg.sysid, compid=cfg.compid, tlog=tlog, name="--gcs",
                    signing=sign(1), rejected=rejected, exempt_peer=False)
           if cfg.gcs is not None else None)
    return link, gcs
