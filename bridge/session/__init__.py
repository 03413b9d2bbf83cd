"""The SITL session: ``bsst sitl`` and :func:`sitl` (docs/design.md, "The MAVLink contract" to "Link model").

In:  a mission (a :class:`~missions.Mission` or a TOML path) and options: overrides (profile, controller,
     ``rate_hz`` Hz, seed, a ``[link]`` table), ``realtime``, ``instance`` (0-9, or None: a free port),
     ``gcs``, ``speed`` (x real time), a signing key file
Out: a :class:`~bridge.record.runlog.Run` (trace arrays, ``summary.json`` as a dict with its ``link``,
     ``timing`` and ``sitl`` blocks) and its run directory (below); progress on stderr with ``live``

Starts the vehicle (``python -m bridge vehicle``) and the offboard controller
(``python -m bridge controller``) as two child processes talking MAVLink 2 over UDP on
127.0.0.1, waits for each to say ``ready`` (deadlines, no fixed sleeps), supervises them,
and leaves the run directory of docs/design.md, "Files of a run":

- ``mission.toml`` (as flown, overrides applied: both children read this file),
- ``vehicle.tlog``, ``controller.tlog`` (both directions of each side),
- ``vehicle.bin``, ``controller.bin``: each side's half of the trace, appended as it flies,
- ``trace.csv``: the two halves joined (appended live in real time; in lockstep written once the controller
  is done, the halves being the flight's live record), one row per control step, the same columns and meaning
  as the offline loop's (:data:`bridge.record.columns.TRACE_COLUMNS`),
- ``summary.json`` (with the ``link`` block and a ``timing`` block), ``events.log``,
  ``plots/``, and ``vehicle.log`` / ``controller.log`` (each child's stderr).

The mission's ``[link]`` impairment (docs/design.md, "Link model"): in lockstep both children apply
it in simulation time to what crossed the socket (the offline loop's ends,
:mod:`bridge.link.ends`), and ``summary.json["link"]`` gives the model's exact statistics; in
real time, when the link is impaired, a third child, ``bsst relay`` (``relay.log``,
``relay.json``), sits between controller and vehicle and applies it on the wall clock.

Each half is written by the process that owns it, whole records at a time, so any process
killed with SIGKILL leaves every file readable up to its last complete record; the join
only ever appends rows whose two halves are both on disk. A child that dies is reported
by name and the session ends in exit status 1; Ctrl-C or SIGTERM stops both children
(SIGTERM; SIGKILL for one not gone within ``STOP_DEADLINE_S``, 8 s: under load a child may need seconds to
close its records) and still writes the summary (outcome ``aborted``).

Every session says honestly how it flew (docs/sitl.md, "Outcomes, exit statuses and safety
policies"): ``summary.json["ended_by"]`` names who ended the flight (the mission, the sender the
vehicle names for a disarm by command, the vehicle's failsafe, a child that died, the user), a
lockstep session has ``summary.json["lockstep"]`` (held, or when and why the vehicle left it),
and the safety policies of :mod:`bridge.record.policies` are checked over its trace and events
(``summary.json["policies"]``); ``events.log`` says the same, in time order among the flight's events
(docs/design.md).

The parts: :class:`~bridge.session.session.Session` starts, supervises and stops the children
(:mod:`bridge.session.children`) and reads their reports (:mod:`bridge.nodes.report`), acted on in the order things
happened (:mod:`bridge.session.eventorder`) and recorded on the mission's clock (:mod:`bridge.record.missionclock`);
the summary is :func:`bridge.record.summary.session_summary`'s, a pure function of what the session saw.

Ports, as PX4 numbers its instances: the vehicle binds 14560 + N for the controller link
and sends GCS telemetry to 14550 + N, with sysid N + 1, holding instance N's lock for its life
(:func:`~bridge.session.children.hold_instances`: one another session holds is refused before anything is
written). ``instance=None`` (for campaigns running many sessions at once) binds a free port instead and sends no
GCS telemetry.
"""

from __future__ import annotations

import math
import shutil
import tempfile
from pathlib import Path
from typing import Any

from bridge.autopilot.estimator import compile_estimator
from bridge.core.clock import lockstep_pace, realtime_speed_problem, speed_problem
from bridge.core.flight import Flight, Progress, laid_sensing_refusal, prepare
from bridge.core.overrides import Overrides, check_switches
from bridge.core.scalar import kernel_cache_on
from bridge.mavlink.endpoint import GCS_PORT, LINK_PORT, parse_address
from bridge.mavlink.signing import key_from_file
from bridge.nodes.forkserver import warm
from bridge.record.outlock import check_out_free, out_held
from bridge.record.runlog import Run, check_trace_steps, run_dir, trace_cap
from bridge.session.children import ChildError, check_port_free, hold_instances, instance_slot
from bridge.session.session import Session
from missions import Mission, Setpoint, Step, load_mission
from params import ConfigError, reads_inputs

__all__ = ["ChildError", "Session", "check_options", "hold_instances", "instance_slot", "sitl"]


AWAIT_DURATION_S = 600.0  # s: --await-mission's settings' duration (the ground station's mission has its own)


def awaiting() -> Mission:
    """``bsst sitl --await-mission``'s settings before a ground station's mission: at rest at the home, the
    defaults; the command line's overrides are laid over it, and the mission flown replaces its trajectory."""
    return Mission(Step((Setpoint(0.0, 0.0, 0.0, 0.0, 0.0),)), duration_s=AWAIT_DURATION_S, name="await-mission",
                   source="--await-mission")


def check_options(*, realtime: bool, instance: int | None, gcs: str | None, speed: float | None) -> str | None:
    """Check a session's clock, instance and pace (ConfigError naming the flag, before anything starts); the
    ground-station address its vehicles send to: ``gcs``, else 127.0.0.1:14550 + instance (None: no GCS link)."""
    if instance is not None and not (isinstance(instance, int) and 0 <= instance <= 9):
        raise ConfigError(f"--instance must be in [0, 9], got {instance!r}")
    if speed is not None:
        number = isinstance(speed, (int, float)) and not isinstance(speed, bool)
        why = speed_problem(speed) if number else f"expected a number, got {speed!r}"[:200]
        if why:
            raise ConfigError(f"--speed {why}")
    if realtime and (why := realtime_speed_problem(speed)):
        raise ConfigError(why)
    gcs_text = gcs if gcs is not None else (None if instance is None else f"127.0.0.1:{GCS_PORT + instance}")
    if gcs_text is not None and gcs_text.strip().lower() == "none":
        gcs_text = None
    if gcs_text is not None:
        parse_address(gcs_text, "udpout", "--gcs")  # bad input fails here, before anything starts
    return gcs_text


def fill_kernel_cache(flight: Flight, forked: bool) -> None:
    """Compile the kernels a session's children will fly into numba's cache on disk (or find them there), before
    they start: a first EKF (~7 s) or a first compiled law and plant (~4 s) on a machine compiles once, here, and
    the two children load them instead of compiling them at once in their start-up. Nothing where the children are
    ``forked`` by a fork server: it loads them before it forks them, from the cache or compiled (the session tells
    it what they fly: bridge.core.kernelpreload), and the launcher, which flies nothing, need not (it loaded them,
    ~0.5-0.7 s of CPU, with a warm cache too). Where numba has no cache (no writable place:
    bridge.autopilot.kernelcache) nothing: each process that flies a kernel compiles it itself, and a compile here
    would only be one more (docs/sitl.md, "Without a writable home")."""
    if forked:
        return
    compile_estimator(flight.estimator)  # nothing where numba has no cache (bridge.autopilot.estimator)
    if flight.compiled and kernel_cache_on():
        flight.make_controller()
        flight.make_plant()


@reads_inputs
def sitl(
    mission: Mission | str | Path | None,
    *,
    out: str | Path | None = None,
    write: bool = False,
    overwrite: bool = False,
    plots: bool = True,
    realtime: bool = False,
    instance: int | None = 0,
    gcs: str | None = None,
    speed: float | None = None,
    progress: Progress | None = None,
    live: bool = False,
    key: str | Path | None = None,
    overrides: Overrides | None = None,
    await_mission: bool = False,
    **keywords: Any,
) -> Run:
    """Fly a mission as a SITL session (vehicle and controller processes over UDP).

    Returns a :class:`~bridge.record.runlog.Run`, as :func:`bridge.loop.simulate` does. The run
    directory is kept when ``out`` is given or ``write`` is true (then under ``runs/``);
    otherwise the session works in a temporary directory and returns only the arrays.
    ``instance`` N (0-9) picks ports 14560 + N / 14550 + N and sysid N + 1; ``None`` picks
    a free port and no GCS link. ``gcs`` (``HOST:PORT`` or ``"none"``) overrides the GCS
    address. ``speed`` caps lockstep at that many times real time (0: as fast as it goes; not given, as fast as it
    goes, and 1 with ``await_mission``: :func:`lockstep_pace`). ``live`` prints on stderr, once the
    vehicle is up, where a ground station connects (:mod:`bridge.session.announce`), and a progress line (when
    stderr is a terminal). ``overrides`` (an
    :class:`~bridge.core.overrides.Overrides`), or its fields as keywords, are laid over the mission as for
    :func:`bridge.loop.simulate` (``param_at``: the controller sends each change as PARAM_SET before the
    answer of its step: in lockstep the same step as offline).
    ``key`` is a MAVLink 2 signing key file (:func:`bridge.mavlink.signing.key_from_file`): both
    sides sign everything they send and accept only what is signed with it; only the file's path
    is passed on.
    ``await_mission`` (``mission`` None): no mission file; a ground station uploads one to the vehicle and starts
    it, the controller downloads it and flies it (docs/missions.md, "From a ground station").
    """
    check_switches(write=write, overwrite=overwrite, plots=plots, realtime=realtime, live=live,
                   await_mission=await_mission)
    if await_mission:
        if mission is not None:
            raise ConfigError("--await-mission: give no mission file (a ground station uploads the mission)")
        mission = awaiting()
        for c in Overrides.of(overrides, **keywords).param_at or ():  # checked again against the mission flown
            if not (math.isfinite(c.t_s) and 0.0 <= c.t_s < AWAIT_DURATION_S):
                raise ConfigError(f"--param-at {c.t_s:g}:{c.name}={c.value!r}: with --await-mission the time is "
                                  f"mission time, in [0, {AWAIT_DURATION_S:g}) s; the ground station's mission, once "
                                  "downloaded, must last longer than it")
    elif mission is None:
        raise ConfigError.at("bsst sitl", None, "give a mission file (or --await-mission)")
    if key is not None:
        key_from_file(key)  # a missing, empty or world-readable key file is bad input, before anything starts
    over = Overrides.of(overrides, **keywords)
    m = mission if isinstance(mission, Mission) else load_mission(mission, trace_cap(over.rate_hz))  # capped early
    flight = prepare(m, over)
    refused = laid_sensing_refusal(over, flight)  # noise= or sensors= that a truth flight does not read
    if refused:
        raise ConfigError(refused)
    check_trace_steps(flight.mission)  # the session keeps every trace row for its summary: a cap, said up front
    gcs_text = check_options(realtime=realtime, instance=instance, gcs=gcs, speed=speed)
    speed = lockstep_pace(speed, realtime=realtime, await_mission=await_mission)
    n = instance or 0
    if gcs_text is None and await_mission:
        raise ConfigError("--await-mission: the vehicle needs a GCS link for the ground station's mission "
                          "(an --instance, or --gcs HOST:PORT)")
    keep = out is not None or write
    if keep:  # a refused run directory is named before a busy port (both before anything starts)
        run_dir(out, flight.mission.name, overwrite, create=False)
        check_out_free(out)  # another run writing it now
    # the instance held for the session's life (another session's is refused here, before anything is written)
    with hold_instances(() if instance is None else (n,), lambda k: f"--instance {k}"):
        if instance is not None:
            check_port_free(LINK_PORT + n, f"--instance {n}")
        forked = warm()  # the fork server's imports (bridge.nodes.forkserver) overlap what follows
        fill_kernel_cache(flight, forked)
        with out_held(out):  # for the session's life
            path = run_dir(out, flight.mission.name, overwrite) if keep else Path(tempfile.mkdtemp(prefix="bsst-sitl-"))
            try:
                s = Session(flight, path, realtime=realtime, instance=instance, gcs=gcs_text, speed=speed,
                            progress=progress, live=live, key=Path(key) if key is not None else None,
                            await_mission=await_mission, announce=live)
                return s.run(plots=plots and keep, keep=keep)
            finally:
                if not keep:
                    shutil.rmtree(path, ignore_errors=True)
