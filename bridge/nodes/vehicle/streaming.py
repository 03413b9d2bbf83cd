"""What the vehicle streams: the vehicle as its messages read it, each link's stream table sent when due, its load.

In:  the simulated vehicle, its flight (the profile's omega_max, rad/s), its config (home, sysid), the mission it
     holds (:mod:`.mission`), its step clock (halted or not), the simulation time of its step (s), wall times (s,
     ``time.monotonic``) and CPU times (s, ``time.process_time``)
Out: :class:`~bridge.nodes.vehicle.streams.VehicleView` (about the vehicle's local origin, or the mission's frame for
     the controller), HEARTBEAT and any message by id (:func:`~bridge.nodes.vehicle.streams.message`), the GCS link's
     and the controller link's streams sent when due (their stream tables: intervals s), the wall time the next is
     due (s), and the load (per mille of one core since the last heartbeat) that SYS_STATUS says
"""

from __future__ import annotations

import time
from collections.abc import Callable
from contextlib import AbstractContextManager
from typing import Any

from bridge.autopilot.simvehicle import OFFBOARD, SimVehicle
from bridge.core.flight import Flight
from bridge.mavlink import telemetry as tm
from bridge.mavlink.endpoint import Endpoint
from bridge.mavlink.modes import MISSION
from bridge.nodes.vehicle.clock import Clock
from bridge.nodes.vehicle.config import VehicleConfig
from bridge.nodes.vehicle.mission import MissionManager
from bridge.nodes.vehicle.streams import (
    DEFAULT_STREAMS,
    StreamTable,
    VehicleView,
    battery_streams,
    estimator_streams,
    health_of,
    heartbeat,
    message,
)


class Streaming:
    """The vehicle's view, messages and streams, for one vehicle."""

    def __init__(self, sim: SimVehicle, flight: Flight, cfg: VehicleConfig, missions: MissionManager, clock: Clock,
                 t: Callable[[], float], now: float, load_at: tuple[float, float]) -> None:
        self.sim, self.flight, self.cfg, self.missions, self.clock, self.t = sim, flight, cfg, missions, clock, t
        plant = sim.plant
        # the GCS link's: the defaults, and with sensors (not truth) HIGHRES_IMU and, for GNSS, GPS_RAW_INT
        sensors = sim.sensors.config if sim.sensors is not None else None
        self.streams = StreamTable({**DEFAULT_STREAMS, **tm.sensor_streams(sensors), **estimator_streams(
            sim.sensors), **battery_streams(plant.battery)}, now)
        self.ctl_streams = StreamTable(dict.fromkeys(self.streams, 0.0), now)  # the controller link's: none
        self._load_at, self.load = load_at, 0

    def view(self, own: bool = True) -> VehicleView:
        """The vehicle now, as its telemetry reads it; ``own``: about its local origin (VehicleView.origin)."""
        sim, plant, cfg = self.sim, self.sim.plant, self.cfg
        mode = MISSION if self.missions.shows_mission(sim.armed, sim.mode == OFFBOARD) else sim.mode
        return VehicleView(sim.published(), self.t(), mode, sim.onboard.target, sim.armed, self.clock.halted,
                           plant.on_ground, plant.omega, self.flight.profile.omega_max, self.load, sim.sensors,
                           cfg.home, cfg.sysid, self.missions.current_fields(),
                           plant.battery, sim.battery_watch.level(plant.battery.remaining) if plant.battery else 0,
                           sim.prearm_refusal, sim.position.ekf_valid, lambda: health_of(sim),
                           (sim.home[0], sim.home[1]) if own else (0.0, 0.0))

    def heartbeat(self) -> Any:
        return heartbeat(self.view())

    def message(self, mid: int, own: bool = True) -> list[Any]:
        """The message(s) with id ``mid`` for a stream or a REQUEST_MESSAGE ([] if none; ``own``: :meth:`view`'s)."""
        return message(mid, self.view(own))

    def measure_load(self, now: float) -> None:
        """The load since the last measure (per mille of one core), for SYS_STATUS."""
        cpu = time.process_time()
        w0, c0 = self._load_at
        self.load = int(1000 * (cpu - c0) / max(now - w0, 1e-6))
        self._load_at = (now, cpu)

    def send_due(self, now: float, nxt: float, gcs: Endpoint | None, link: Endpoint,
                 charged: Callable[[], AbstractContextManager[Any]]) -> float:
        """Each link's streams due by ``now`` sent, to whoever is on it (the controller link's within a would-be
        controller's credit, ``charged``); the wall time (s) the next is due, at most ``nxt``."""
        if gcs is not None and gcs.peer is not None:
            self.streams.send_due(now, lambda mid: gcs.send_many(self.message(mid)))
            nxt = min(nxt, *self.streams.due.values())
        if link.peer is not None and self.ctl_streams.due:
            with charged():
                self.ctl_streams.send_due(now, lambda mid: link.send_many(self.message(mid, False)))
            nxt = min(nxt, *self.ctl_streams.due.values())
        return nxt
