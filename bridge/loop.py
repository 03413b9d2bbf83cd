"""The in-process closed loop (``bsst sim``): the truth every networked run is checked against.

One control step at time t_k = k / rate_hz: the law reads the state, its command goes to
the vehicle, which holds it over ``physics_hz / rate_hz`` RK4 steps. The vehicle is the same
:class:`~bridge.simvehicle.SimVehicle` (timeout, failsafe) as the MAVLink vehicle uses.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from bridge.flight import Flight, prepare
from bridge.metrics import summarise
from bridge.runlog import (
    TRACE_COLUMNS,
    EventLog,
    Run,
    TraceWriter,
    finish_run,
    run_dir,
    state_columns,
    trace_arrays,
)
from bridge.simvehicle import FAILSAFE, LANDED
from bridge.wire import command_to_wire
from missions import Mission
from params import dump_toml

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
) -> Run:
    """Fly a mission offline. Returns a :class:`Run` (trace as arrays, summary as a dict).

    The run directory is written only when ``out`` is given or ``write`` is true (then under
    ``runs/``). Overrides replace the mission's own values, as the CLI flags do.
    """
    flight = prepare(mission, profile=profile, controller=controller, rate_hz=rate_hz, seed=seed)
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
    rows: list[tuple[float, ...]] = []
    trace = events = None
    if path is not None:
        (path / "mission.toml").write_text(dump_toml(m.to_dict()))
        trace = TraceWriter(path / "trace.csv")
        events = EventLog(path / "events.log")
    outcome = "completed"
    logged = 0
    try:
        for k in range(m.steps):
            t = k / rate
            X = plant.state
            ref = sample(t)
            cmd = ctl.step(t, X, ref)
            vehicle.command(cmd.normalised)
            wire = command_to_wire(actuation, cmd.normalised)
            row = (t, *state_columns(X), ref[0][0], ref[1][0], ref[2][0], ref[3][0], *cmd.demanded, *wire,
                   *plant.realised, 0.0, *law.desired)
            rows.append(row)
            if trace is not None:
                trace.row(row)
            vehicle.advance()
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
                outcome = "failsafe"
            if progress is not None and k % int(rate) == 0:
                progress(t, m.duration_s, sum((X[i] - ref[j][0]) ** 2 for i, j in ((0, 0), (2, 1), (4, 2))) ** 0.5)
    except KeyboardInterrupt:
        outcome = "aborted"
        vehicle.event("aborted", "interrupted")
    finally:
        if trace is not None:
            trace.close()
        if events is not None:
            for e in vehicle.events[logged:]:
                events.event(e.t, e.kind, e.text)
            events.close()
    arrays = trace_arrays(rows, TRACE_COLUMNS)
    ev = [{"t": round(e.t, 6), "kind": e.kind, "text": e.text} for e in vehicle.events]
    summary = summarise(arrays, m, flight.gains, clock="offline", outcome=outcome, events=ev)
    if path is not None:
        finish_run(path, arrays, summary, f"{m.name} ({m.controller}, {flight.profile.name})", plots)
    return Run(arrays, summary, path)
