"""The in-process closed loop (``bsst sim``): the truth every networked run is checked against.

In:  a mission (a :class:`~missions.Mission` or a TOML path) and overrides (profile, controller,
     ``rate_hz`` Hz, seed, a ``[link]`` table), or a prepared :class:`~bridge.core.flight.Flight`
Out: a :class:`~bridge.record.runlog.Run`: trace arrays (:data:`~bridge.record.columns.TRACE_COLUMNS`,
     SI units) and ``summary.json`` as a dict (``clock = "offline"``); with a directory also
     ``mission.toml``, ``trace.csv``, ``events.log``, ``summary.json`` and ``plots/``

One control step at time t_k = k / rate_hz: the law reads the state, its command goes to
the vehicle, which holds it over ``physics_hz / rate_hz`` RK4 steps. The vehicle is the same
:class:`~bridge.core.simvehicle.SimVehicle` (timeout, failsafe) as the MAVLink vehicle uses.

Both messages cross the mission's link model (:mod:`bridge.core.link`) in simulation time, as
they would cross the sockets: the state at t_k goes down to the controller's
:class:`~controller.link_guard.LinkGuard`, which controls on the newest state delivered
(``state_age_s`` in the trace is its age); the command goes up and acts at the physics
step the model delivers it in (:mod:`bridge.core.linkends`). A perfect link (the default)
delivers both at once, which is exactly the loop without a link.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from bridge.core.flight import Flight, prepare
from bridge.core.linkends import ControllerEnd, VehicleEnd
from bridge.core.simvehicle import FAILSAFE, LANDED, OFFBOARD
from bridge.core.wire import command_to_wire
from bridge.record.columns import TRACE_COLUMNS, state_columns, trace_row
from bridge.record.metrics import summarise
from bridge.record.runlog import Run, RunRecord, run_dir, trace_arrays
from controller.link_guard import LinkGuard
from missions import Mission

Progress = Callable[[float, float, float], None]  # (t, duration, current 3-D error)


def simulate(
    mission: Mission | str | Path,
    *,
    out: str | Path | None = None,
    write: bool = False,
    overwrite: bool = False,
    plots: bool = True,
    profile: str | None = None,
    controller: str | None = None,
    rate_hz: float | None = None,
    seed: int | None = None,
    progress: Progress | None = None,
    link: Mapping[str, Any] | None = None,
) -> Run:
    """Fly a mission offline. Returns a :class:`Run` (trace as arrays, summary as a dict).

    The run directory is written only when ``out`` is given or ``write`` is true (then under
    ``runs/``). Overrides replace the mission's own values, as the CLI flags do; ``link`` is
    laid over the mission's ``[link]`` table (e.g. ``{"up": {"loss_pct": 20}}``).
    """
    flight = prepare(mission, profile=profile, controller=controller, rate_hz=rate_hz, seed=seed, link=link)
    path = run_dir(out, flight.mission.name, overwrite) if (out is not None or write) else None
    return fly(flight, path, plots=plots, progress=progress)


def fly(flight: Flight, path: Path | None = None, *, plots: bool = True, progress: Progress | None = None) -> Run:
    """Fly a prepared :class:`Flight`; write its run directory into ``path`` if given."""
    m = flight.mission
    vehicle = flight.make_vehicle(armed=True)
    ctl = flight.make_controller()
    law = ctl.law
    plant = vehicle.plant
    actuation = flight.profile.actuation
    sample = m.trajectory.sample
    rate = m.rate_hz
    up, down = flight.link.make()
    guard = LinkGuard(ctl, flight.guard)
    vend = VehicleEnd(vehicle, up, actuation)
    cend = ControllerEnd(guard, down)
    blackouts = flight.blackout_notes()
    rows: list[tuple[float, ...]] = []
    record = RunRecord(path, m) if path is not None else None
    trace = record.trace if record is not None else None
    events = record.events if record is not None else None
    outcome = "completed"
    failsafe_seen = False
    logged = 0
    noted = 0
    demanded = wire = (0.0, 0.0, 0.0, 0.0)
    try:
        for k in range(m.steps):
            t = k / rate
            X = plant.state
            ref = sample(t)
            while blackouts and blackouts[0][0] <= t:
                vehicle.event("blackout", blackouts.pop(0)[1])
            cend.receive_state(t, X, vehicle.armed and vehicle.mode == OFFBOARD)
            dec = cend.step(t, sample)
            for e in guard.events[noted:]:
                vehicle.event(e[1], e[2])
            noted = len(guard.events)
            if dec.arm:
                vend.receive_arm(t)
            cmd = dec.command
            if cmd is not None:
                vend.receive_command(t, cmd.normalised, dec.state_t)
                demanded = cmd.demanded
                wire = command_to_wire(actuation, cmd.normalised)
            vend.deliver(t)
            row = trace_row(t, state_columns(X), ref, demanded, wire, plant.realised,
                            dec.state_age_s if cmd is not None else math.nan, law.desired)
            rows.append(row)
            if trace is not None:
                trace.row(row)
            vend.advance()
            while logged < len(vehicle.events):
                e = vehicle.events[logged]
                logged += 1
                if events is not None:
                    events.event(e.t, e.kind, e.text)
            why = plant.diverged()
            if why:
                outcome = "diverged"
                vehicle.event("diverged", why)
                break
            if vehicle.mode in (FAILSAFE, LANDED):
                failsafe_seen = True
                outcome = "failsafe"
            elif failsafe_seen and flight.failsafe.resume and vehicle.armed:
                outcome = "completed"  # resumed after a failsafe (the events say so)
            if progress is not None and k % int(rate) == 0:
                progress(t, m.duration_s, sum((X[i] - ref[j][0]) ** 2 for i, j in ((0, 0), (2, 1), (4, 2))) ** 0.5)
    except KeyboardInterrupt:
        outcome = "aborted"
        vehicle.event("aborted", "interrupted")
    finally:
        if record is not None:
            for e in vehicle.events[logged:]:
                record.events.event(e.t, e.kind, e.text)
            record.close()
    arrays = trace_arrays(rows, TRACE_COLUMNS)
    ev = [{"t": round(e.t, 6), "kind": e.kind, "text": e.text} for e in vehicle.events]
    link = {"up": up.stats.summary(), "down": down.stats.summary(), "rejected": dict(vend.rejected)}
    summary = summarise(arrays, m, flight.gains, clock="offline", outcome=outcome, events=ev, link=link)
    if record is not None:
        record.finish(arrays, summary, f"{m.name} ({m.controller}, {flight.profile.name})", plots)
    return Run(arrays, summary, path)
