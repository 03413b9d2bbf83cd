"""The in-process closed loop (``bsst sim``): the truth every networked run is checked against.

In:  a mission (a :class:`~missions.Mission` or a TOML path) and its overrides (an
     :class:`~bridge.core.overrides.Overrides`, or its fields as keywords: profile, controller, ``rate_hz``
     Hz, seed, a ``[link]`` table, ...), or a prepared :class:`~bridge.core.flight.Flight`
Out: a :class:`~bridge.record.runlog.Run`: trace arrays (:data:`~bridge.record.columns.TRACE_COLUMNS`,
     SI units) and ``summary.json`` as a dict (``clock = "offline"``); with a directory also
     ``mission.toml``, ``trace.csv``, ``events.log``, ``summary.json`` and ``plots/``

One control step at time t_k = k / rate_hz: the law reads the state the vehicle publishes (its
on-board estimate: :meth:`~bridge.autopilot.simvehicle.SimVehicle.published`; the true state under the
``truth`` estimator), its command goes to
the vehicle, which holds it over ``physics_hz / rate_hz`` RK4 steps. The vehicle is the same
:class:`~bridge.autopilot.simvehicle.SimVehicle` (timeout, failsafe) as the MAVLink vehicle uses.

Both messages cross the mission's link model (:mod:`bridge.link.model`) in simulation time, as
they would cross the sockets: the state at t_k goes down to the controller's
:class:`~controller.link_guard.LinkGuard`, which controls on the newest state delivered
(``state_age_s`` in the trace is its age); the command goes up and acts at the physics
step the model delivers it in (:mod:`bridge.link.ends`). A perfect link (the default)
delivers both at once, which is exactly the loop without a link.

The plant flies through the mission's wind and its timeline of faults (docs/weather.md): the vehicle acts on
each event at the start of its control step. A touchdown too fast or too tilted while armed ends the flight
``crashed`` (the plant's impact speed in the event); ``summary.json`` carries the ``wind`` and ``battery`` blocks.
"""

from __future__ import annotations

import inspect
import math
from array import array
from collections.abc import Generator
from contextlib import nullcontext
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bridge.autopilot.intention import FAILSAFE_MODES, UserModeIntention
from bridge.autopilot.simvehicle import FAILSAFE, LAND, OFFBOARD, SimVehicle
from bridge.autopilot.vehicleevents import typed_fields
from bridge.core.flight import Flight, Progress, laid_sensing_refusal, prepare
from bridge.core.interrupt import Held, sigint_held
from bridge.core.overrides import Overrides, check_switches
from bridge.core.wire import command_over_wire, state_over_wire
from bridge.link.ends import ControllerEnd, VehicleEnd
from bridge.link.radio import Radio
from bridge.record.columns import TRACE_COLUMNS, state_columns, trace_row
from bridge.record.endedby import ended_by_outcome
from bridge.record.ending import end_block
from bridge.record.events import RunEvent
from bridge.record.metrics import after_faults, not_reached, plant_blocks, plant_summary, summarise
from bridge.record.outlock import out_held
from bridge.record.policies import judge, rules_for, violation_text
from bridge.record.runlog import Run, RunRecord, check_trace_steps, run_dir, trace_arrays, trace_cap
from controller.law import LawFailed
from controller.link_guard import LinkGuard
from missions import Mission, load_mission
from missions.minsnap import Smooth
from missions.references import Prefetched
from params import ConfigError, reads_inputs

TOUCHDOWN_M = 0.05  # m above the ground, and m/s: a landing trajectory's end finds the vehicle down, and disarms it


class StopAfterRecord(KeyboardInterrupt):
    """A stop held while a flight was judged (:func:`flying`), raised once its record is written: ``run`` is what the
    flight returns (a fleet keeps it in its record: :func:`bridge.swarm.fly_fleet`)."""

    def __init__(self, run: Run) -> None:
        super().__init__()
        self.run = run


def recorded_run(stop: KeyboardInterrupt) -> Run | None:
    """The run a stop carries: its flight's, recorded whole (:class:`StopAfterRecord`), or None (a plain stop: its
    flight not started yet, or stopped within its first step, nothing recorded)."""
    return stop.run if isinstance(stop, StopAfterRecord) else None


@dataclass(frozen=True)
class Alone:
    """A period the vehicle flew alone, told nothing: a failsafe's landing still going at the mission's end
    (:func:`land_failsafe`). ``state``: the plant's true state after it (eq. 7 order), for a fleet to judge its
    world on, without telling anyone (a contact sent back is not heeded)."""

    state: tuple[float, ...]


Step = tuple[float, ...] | Alone  # what :func:`flying` yields a control period


@reads_inputs
def simulate(
    mission: Mission | str | Path,
    *,
    out: str | Path | None = None,
    write: bool = False,
    overwrite: bool = False,
    plots: bool = True,
    progress: Progress | None = None,
    overrides: Overrides | None = None,
    **keywords: Any,
) -> Run:
    """Fly a mission offline. Returns a :class:`Run` (trace as arrays, summary as a dict).

    The run directory is written only when ``out`` is given or ``write`` is true (then under
    ``runs/``). ``overrides`` (an :class:`~bridge.core.overrides.Overrides`), or its fields as keywords,
    replace the mission's own values, as the CLI flags do: ``profile``, ``controller``, ``rate_hz``,
    ``seed``; ``link`` is laid over the mission's ``[link]`` table (e.g. ``{"up": {"loss_pct": 20}}``),
    ``failsafe`` over its ``[failsafe]`` table (e.g. ``{"action": "hold"}``), ``sensors`` over its
    ``[sensors]`` table (``{"set": "mocap"}``); ``estimator`` (truth, raw, ekf) and ``noise`` (every σ
    times it) replace ``[estimator] kind`` and ``[sensors] noise_scale``. ``params`` over its ``[params]``
    table (PX4 names, ``{"COM_OF_LOSS_T": 1.0}``); ``param_at``: parameter changes at mission times
    (``[ParamChange(10.0, "COM_OBL_ACT", 1)]``), made at the start of their control step.
    """
    check_switches(write=write, overwrite=overwrite, plots=plots)
    over = Overrides.of(overrides, **keywords)
    m = mission if isinstance(mission, Mission) else load_mission(mission, trace_cap(over.rate_hz))  # capped early
    flight = prepare(m, over)
    refused = laid_sensing_refusal(over, flight)  # (a sweep's truth cells of a noise axis fly by fly(), not here)
    if refused:
        raise ConfigError(refused)
    check_trace_steps(flight.mission)  # before the run directory is made: a refused mission writes nothing
    with out_held(out):  # (another run writing this --out: refused before its files are touched)
        path = run_dir(out, flight.mission.name, overwrite) if (out is not None or write) else None
        return fly(flight, path, plots=plots, progress=progress)


def fly(flight: Flight, path: Path | None = None, *, plots: bool = True, progress: Progress | None = None) -> Run:
    """Fly a prepared :class:`Flight`; write its run directory into ``path`` if given. A Ctrl-C (SIGINT, or SIGTERM
    taken as one) raised here, between two steps, is thrown into the flight, which ends ``aborted``, recorded, as on
    one raised within a step. Before, it left the flight unrecorded (no summary.json): Python raises it wherever the
    main thread next looks, and that is here for a signal landing as a step ends (at its yield)."""
    steps = flying(flight, path, plots=plots, progress=progress)
    stop = False
    while True:  # (its jump back comes only after a stop thrown in: the steps' loop is within the try)
        try:
            while True:
                if stop:
                    stop = False
                    steps.throw(KeyboardInterrupt)
                else:
                    next(steps)
        except StopIteration as done:
            return done.value
        except KeyboardInterrupt:
            if inspect.getgeneratorstate(steps) != inspect.GEN_SUSPENDED:
                raise  # the flight's own: not started, or let through (a second stop, one held: flying)
            stop = True


def flying(flight: Flight, path: Path | None = None, *, plots: bool = True, progress: Progress | None = None,
           radios: tuple[Radio, Radio] | None = None, user: int = 0) -> Generator[Step, str | None, Run]:
    """:func:`fly` one step at a time, for a loop that flies several vehicles in one world (:mod:`bridge.swarm`):
    after each step (the mission's, its end landing's: :func:`fly_end`) it yields the plant's true state (eq. 7
    order); sent a text, it ends the flight there ``collision`` (that text its event); a failsafe's landing after the
    mission yields :class:`Alone` (:func:`land_failsafe`). Returns the :class:`Run`; thrown a KeyboardInterrupt, it
    ends ``aborted``, recorded. ``radios``: the (up, down) radios the flight's links share, as their ``user``."""
    m = flight.mission
    check_trace_steps(m)
    w = _Wiring(flight, radios, user)
    vehicle, plant, intention, rate = w.vehicle, w.plant, w.intention, m.rate_hz
    rows = array("d")  # the trace, row after row, 8 bytes a value: 0.6 KB a step (a tuple of floats took 1.6 KB)
    record = RunRecord(path, m) if path is not None else None
    trace, events = (record.trace, record.events) if record is not None else (None, None)
    outcome = "completed" if vehicle.armed else "denied"  # denied: its pre-arm check refused (a preflight event)
    failsafe_seen = False
    logged = 0
    k = 0
    try:
        for k in range(m.steps if vehicle.armed else 0):
            t = k / rate
            X, ref, row = w.period(k, t)
            rows.extend(row)
            if trace is not None:
                trace.row(row)
            w.vend.advance()
            flown = intention.after_period()  # the period's mode (a disarm then takes the user's, as in a session)
            logged = _log_new_events(vehicle, events, logged)
            contact = yield plant.state
            if contact is not None:  # another vehicle touched this one (the caller judged the shared world)
                vehicle.event("collision", contact)
                outcome = "collision"
                break
            verdict = vehicle.plant_verdict()
            if verdict:
                outcome = verdict
                break
            if flown in FAILSAFE_MODES:
                failsafe_seen = True
                outcome = "failsafe"
            elif failsafe_seen and flight.failsafe.resume and vehicle.armed:
                outcome = "completed"  # resumed after a failsafe (the events say so)
            if progress is not None and k % int(rate) == 0:
                progress(t, m.duration_s, sum((X[i] - ref[j][0]) ** 2 for i, j in ((0, 0), (2, 1), (4, 2))) ** 0.5)
        if outcome == "completed" and isinstance(m.trajectory, Smooth) and m.trajectory.lands and \
                m.end_action == "hold":  # (with LAND the end action lands it, as a session's vehicle: fly_end)
            _disarm_landed(vehicle)
    except (KeyboardInterrupt, LawFailed) as exc:  # interrupted, or a user's law failed: the flight ends, recorded
        outcome = stopped(vehicle, exc, k, rate)
    except BaseException:
        _close_record(record, vehicle.events[logged:])
        raise
    # its last step flown: a stop while it is judged and written is held (its record is never cut), taken by its end
    # landing if it has one to fly (aborted there), else raised once the record is on disk (at the landing's yields
    # the previous handler is back: a fleet's other flights, and this one's caller, meet it as before)
    with sigint_held() as held:
        try:  # the record stays open for the verdicts' lines, and is closed whatever happens
            arrays = trace_arrays(rows, TRACE_COLUMNS)
            link = {"up": w.up.stats.summary(), "down": w.down.stats.summary(), "rejected": dict(w.vend.rejected)}
            summary = yield from _judged(flight, vehicle, intention, arrays, outcome, link, held)
        finally:
            _close_record(record, vehicle.events[logged:])
        if record is not None:
            record.finish(arrays, summary, f"{m.name} ({m.controller}, {flight.profile.name})", plots)
    if held.pending:
        raise StopAfterRecord(Run(arrays, summary, path))  # (held: the record is whole, as the flight ended)
    return Run(arrays, summary, path)


class _Wiring:
    """One flight's parts wired as a session wires them (the vehicle and its user's mode, the controller behind its
    link guard, the two links and their ends), and one control period of them (:meth:`period`). What carries from
    period to period is held here: the parameter changes and blackout notes not yet due, how many of the guard's
    events the vehicle was told, and the last command demanded and sent (the trace repeats them until the next)."""

    def __init__(self, flight: Flight, radios: tuple[Radio, Radio] | None, user: int) -> None:
        m = flight.mission
        self.vehicle = vehicle = flight.make_vehicle(armed=True)
        self.intention = UserModeIntention(vehicle)  # the mode a disarm in LAND or the failsafe leaves, as a session's
        ctl = flight.make_controller()
        self.law = ctl.law
        self.plant = vehicle.plant
        self.actuation = flight.profile.actuation
        self.sample = Prefetched(m.trajectory.sample)  # the row's sample at t is the law's (aim = t): once a step
        self.up, self.down = flight.link.make(radios, user)
        self.guard = LinkGuard(ctl, flight.guard)
        self.vend = VehicleEnd(vehicle, self.up, self.actuation)
        self.cend = ControllerEnd(self.guard, self.down)
        self.blackouts = flight.blackout_notes()
        self.changes = list(flight.param_changes)  # scheduled parameter changes: at the start of their step, as in SITL
        self.rate = m.rate_hz
        self.noted = 0
        self.demanded = self.wire = (0.0, 0.0, 0.0, 0.0)

    def period(self, k: int, t: float) -> tuple[tuple[float, ...], Any, tuple[float, ...]]:
        """The control period ``k`` (at ``t`` s) up to the vehicle's step: its due changes and notes made, the state
        sent down, the law's decision, the command sent up and delivered. Returns the plant's true state at its
        start (eq. 7 order), the reference sampled at ``t`` and the trace's row (:func:`trace_row`)."""
        vehicle, changes, blackouts, guard, vend, cend = (self.vehicle, self.changes, self.blackouts, self.guard,
                                                          self.vend, self.cend)
        while changes and changes[0].step(self.rate) <= k:
            c = changes.pop(0)
            vehicle.change_param(c.name, c.value)
        X = self.plant.state
        E = vehicle.published()  # what the vehicle knows, and sends down the link
        ref = self.sample(t)
        while blackouts and blackouts[0][0] <= t:
            vehicle.event("blackout", blackouts.pop(0)[1])
        # the law reads the state as ODOMETRY carries it (float32), as in SITL
        cend.receive_state(t, state_over_wire(E), vehicle.armed and vehicle.mode == OFFBOARD)
        dec = cend.step(t, self.sample)
        for e in guard.events[self.noted:]:
            vehicle.event(e[1], e[2])
        self.noted = len(guard.events)
        if dec.arm:
            vend.receive_arm(t)
        cmd = dec.command
        if cmd is not None:
            received, self.wire = command_over_wire(self.actuation, cmd.normalised)  # the float32 target, as in SITL
            vend.receive_command(t, received, dec.state_t)
            self.demanded = cmd.demanded
        vend.deliver(t)
        truth = state_columns(X)
        row = trace_row(t, truth, ref, self.demanded, self.wire, self.plant.realised,
                        dec.state_age_s if cmd is not None else math.nan, self.law.desired,
                        truth if E is X else state_columns(E), vehicle.nees(E))  # truth: E is X
        return X, ref, row


def _judged(flight: Flight, vehicle: SimVehicle, intention: UserModeIntention, arrays: dict[str, Any], outcome: str,
            link: dict[str, Any], held: Held) -> Generator[Step, str | None, dict[str, Any]]:
    """The flight's summary: its figures, plant blocks, who ended it, the policies' verdicts (each violation
    an event), and when it completed, its end action flown (:func:`fly_end`: its steps yielded, as the mission's).
    A stop while it judges is ``held`` (:func:`flying`), and taken by the landing, if one is flown."""
    summary = _verdicts(flight, vehicle, arrays, outcome, link)
    verdict = None
    if outcome == "completed":  # after the mission's figures: nothing of them changes
        summary["end"], verdict = yield from fly_end(flight, vehicle, intention, summary["events"], held)
    elif outcome == "failsafe":
        verdict = yield from land_failsafe(flight, vehicle, intention, summary["events"], held)
    if verdict is not None:  # its landing touched down hard (or the plant diverged): the plant ended the flight
        summary["outcome"] = verdict
        summary["ended_by"] = ended_by_outcome(verdict, [RunEvent(round(e.t, 6), e.kind, e.text, by=e.by)
                                                         for e in vehicle.events])
        summary.update({k: v for k, v in plant_blocks(vehicle.plant).items() if k == "impact"})
    return summary


def _verdicts(flight: Flight, vehicle: SimVehicle, arrays: dict[str, Any], outcome: str,
              link: dict[str, Any]) -> dict[str, Any]:
    """The flight's summary before its end action: figures, plant blocks, who ended it, the policies' verdicts (each
    violation an event)."""
    m, plant = flight.mission, vehicle.plant
    if caps := flight.link.jitter_capped():  # the delay capped a jitter (docs/links.md): said
        link["jitter_capped"] = caps
    ev = [RunEvent(round(e.t, 6), e.kind, e.text, by=e.by, **typed_fields(e)) for e in vehicle.events]
    shown = [e.as_dict() for e in ev]
    summary = summarise(arrays, m, flight.gains, clock="offline", outcome=outcome, events=shown, link=link,
                        estimator=flight.estimator, sensors=flight.sensors.name)
    summary.update(plant_summary(plant_blocks(plant), arrays, shown))
    summary["ended_by"] = {**ended_by_outcome(outcome, ev), **after_faults(outcome, shown),
                           **not_reached(outcome, flight.timeline, arrays["t"], flight.wind)}
    for v in judge(summary, arrays, ev, rules_for(flight, "offline", link)):
        vehicle.event("policy", violation_text(v))
        shown.append({"t": round(vehicle.t, 6), "kind": "policy", "text": violation_text(v)})
    return summary


def fly_end(flight: Flight, vehicle: SimVehicle, intention: UserModeIntention, shown: list[dict[str, Any]],
            held: Held | None = None) -> Generator[Step, str | None, tuple[dict[str, Any], str | None]]:
    """The mission's end action offline (``[end] action``, :meth:`SimVehicle.end_mission`), as the vehicle flies
    it in a session: ``land`` steps the vehicle's own landing (nothing from the controller; the mission's link
    is done with, its statistics the mission's) until it disarms on the ground, bounded by the descent at the
    failsafe's rate, COM_DISARM_LAND and 10 s, the plant's verdict judged after each period as a session's vehicle
    judges it (a touchdown faster than CRASH_SPEED_MPS is ``crashed``); ``hold`` is engaged and the flight ends with the
    mission (no session to hold through). Its events are added to ``shown``; returns ``summary.json["end"]``
    (:func:`bridge.record.ending.end_block`) and the plant's verdict (None: none). Each landing period yields the
    plant's state and may be sent a contact, as the mission's steps (:func:`flying`): a fleet judges its landings
    in its shared world, as a lockstep session's gate does (docs/swarm.md)."""
    n0 = len(vehicle.events)
    vehicle.end_mission(flight.mission.end_action)
    rows, verdict = yield from _fly_alone(flight, vehicle, intention, LAND, shown, n0, heeds=True, held=held)
    return end_block(flight.mission.end_action, rows, vehicle.events[n0:]), verdict


def land_failsafe(flight: Flight, vehicle: SimVehicle, intention: UserModeIntention, shown: list[dict[str, Any]],
                  held: Held | None = None) -> Generator[Step, str | None, str | None]:
    """A failsafe's landing still going at the mission's end goes on to the ground, as a session's vehicle flies it
    (on the wall clock: it leaves lockstep for it), stepped as :func:`fly_end` steps the end landing; the plant's
    verdict (None: none). Each period yields :class:`Alone`: a fleet judges its world on it but tells it nothing, as
    a lockstep fleet judges such a landing on its record (docs/swarm.md), so every flight stays as flown alone. A
    failsafe that holds, or is done, flies nothing more here."""
    target = vehicle.onboard.target
    if not (vehicle.armed and vehicle.mode == FAILSAFE and target is not None and target.lands):
        return None
    _, verdict = yield from _fly_alone(flight, vehicle, intention, FAILSAFE, shown, len(vehicle.events), heeds=False,
                                       held=held)
    return verdict


def _fly_alone(flight: Flight, vehicle: SimVehicle, intention: UserModeIntention, mode: str,
               shown: list[dict[str, Any]], n0: int, *, heeds: bool, held: Held | None = None
               ) -> Generator[Step, str | None, tuple[list[tuple[float, float, float]], str | None]]:
    """Step the vehicle alone (nothing from the controller; the mission's link is done with, its statistics the
    mission's) while it is armed in ``mode`` (or a failsafe's, taken meanwhile), until it disarms on the ground,
    bounded by the descent at the failsafe's rate, COM_DISARM_LAND and 10 s, its plant judged after each period;
    the events since the ``n0``-th added to ``shown``. After each period it yields the plant's state (a fleet's world
    judged on it). ``heeds``: a contact sent back ends it there, armed and not ended by its plant: ``collision``,
    disarmed, as a lockstep session's vehicle (its plant's verdict comes first there too); else the state is yielded
    as :class:`Alone` and what is sent back is not heeded. Interrupted (Ctrl-C),
    it ends ``aborted``, recorded, as on a stop ``held`` while the flight was judged. Returns the rows (t s, z m,
    vz m/s) and the verdict (None: none)."""
    m, plant = flight.mission, vehicle.plant
    rows: list[tuple[float, float, float]] = []
    k, rate = m.steps, m.rate_hz
    bound = k + math.ceil((10.0 + flight.failsafe.time_to_land_s(plant.state[4] - m.start[2])
                           + vehicle.land_disarm.wait_s()) * rate)
    verdict = None
    try:
        while verdict is None and vehicle.armed and vehicle.mode in (mode, FAILSAFE) and k < bound:
            if held is not None and held.pending:  # a stop held while the flight was judged: the landing takes it
                held.pending = False
                raise KeyboardInterrupt
            X = plant.state
            vehicle.advance()  # the vehicle alone: what the up link still holds stays in flight (its statistics too)
            intention.after_period()  # disarmed: the mode it takes (as a session's vehicle, before the plant's verdict)
            verdict = vehicle.plant_verdict()
            rows.append((k / rate, X[4], X[5]))
            k += 1
            if verdict is not None:
                vehicle.disarm(f"{verdict}: {vehicle.events[-1].text}")  # (as a session's: its landing's came first)
            with held.released() if held is not None else nullcontext():
                contact = (yield Alone(plant.state)) if not heeds else (yield plant.state)
            if heeds:
                if contact is not None and verdict is None and vehicle.armed:
                    vehicle.event("collision", contact)
                    vehicle.disarm(f"collision: {contact}")
                    verdict = "collision"
    except KeyboardInterrupt:
        vehicle.event("aborted", "interrupted")
        verdict = "aborted"
    shown.extend(RunEvent(round(e.t, 6), e.kind, e.text, by=e.by, **typed_fields(e)).as_dict()
                 for e in vehicle.events[n0:])
    return rows, verdict


def stopped(vehicle: SimVehicle, exc: BaseException, k: int, rate: float) -> str:
    """The outcome of a flight stopped at step ``k`` by ``exc``, its event logged: ``aborted`` (Ctrl-C), or
    ``law_failed`` (:class:`~controller.law.LawFailed`: a user's law raised, exited or gave no four finite inputs)."""
    if isinstance(exc, LawFailed):
        vehicle.event("law_failed", f"{exc} at step {k} (t={k / rate:.3f} s)")
        return "law_failed"
    vehicle.event("aborted", "interrupted")
    return "aborted"


def _log_new_events(vehicle: SimVehicle, events: Any, logged: int) -> int:
    """Write the vehicle's events after the first ``logged`` to ``events.log`` (if any); how many are logged now."""
    for e in vehicle.events[logged:]:
        if events is not None:
            events.event(e.t, e.kind, e.text)
    return len(vehicle.events)


def _disarm_landed(vehicle: Any) -> None:
    """A mission that ends with a landing (NAV_LAND, NAV_RETURN_TO_LAUNCH) ends disarmed on the ground, as
    PX4's land detector ends it: the vehicle, within :data:`TOUCHDOWN_M` of the ground and at rest, disarms."""
    X = vehicle.published()
    if vehicle.armed and X[4] <= TOUCHDOWN_M and abs(X[5]) <= TOUCHDOWN_M:
        vehicle.disarm("landed: the mission's landing touched down")
    else:
        vehicle.event("land", f"not on the ground at the mission's end (z = {X[4]:.3f} m): left armed")


def _close_record(record: RunRecord | None, unlogged: list[Any]) -> None:
    """Write the events not in ``events.log`` yet, then close the run's files."""
    if record is not None:
        for e in unlogged:
            record.events.event(e.t, e.kind, e.text)
        record.close()
