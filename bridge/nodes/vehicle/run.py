"""``bsst vehicle``: one :class:`~bridge.nodes.vehicle.node.Vehicle` served until SIGTERM or SIGINT.

In:  the flight (mission, profile, parameters), the vehicle's configuration, a run directory (or none)
Out: its reports on stdout (JSON lines, :mod:`bridge.nodes.report`); on stderr, one line each for a flight that did
     not end well, for a timeline event it never flew and for a started mission no controller flew (:mod:`.verdict`),
     and for a controller refused for flying the other actuation mode; the exit status, 0 or 1 (a flight that did
     not end well, an event not flown, a started mission not flown)
"""

from __future__ import annotations

import sys
from pathlib import Path

from bridge.core.flight import Flight
from bridge.nodes.process import on_stop_signals, report_printer
from bridge.nodes.vehicle.config import VehicleConfig
from bridge.nodes.vehicle.node import Vehicle
from bridge.nodes.vehicle.verdict import flights_not_ended_well, start_not_flown, timeline_not_reached
from bridge.record.runlog import side_dir


def run_vehicle(flight: Flight, cfg: VehicleConfig, out: str | Path | None = None, overwrite: bool = False) -> int:
    """``bsst vehicle``: serve until SIGTERM or SIGINT; its reports on stdout (JSON lines); exit status 0, or 1 for
    a flight that did not end well, each said on stderr (:mod:`bridge.nodes.vehicle.verdict`), with why the
    controller's targets were refused when it flew the other actuation mode (a --profile that differs)."""
    path = side_dir(out, ("vehicle.tlog", "vehicle.bin"), overwrite) if out is not None else None
    v = Vehicle(flight, cfg, path, report_printer())
    on_stop_signals(v.stop)
    v.run()
    v.report_stats()
    said = (flights_not_ended_well(v.sim.events) + timeline_not_reached(v.sim)
            + start_not_flown(v.missions.start_requested, v.missions.started,
                              v.sim.events[v.missions.started_n0:]))
    mismatch = v.targets.mismatch
    sys.stderr.writelines(f"bsst vehicle: {why}\n" for why in said)
    if mismatch.refused:
        sys.stderr.write(f"bsst vehicle: {mismatch.text} ({mismatch.refused} refused)\n")
    return 1 if said else 0
