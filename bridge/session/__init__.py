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
- ``vehicle.csv``, ``controller.csv``: each side's half of the trace, appended as it flies,
- ``trace.csv``: the two halves joined live, one row per control step, the same columns
  and meaning as the offline loop's (:data:`bridge.record.columns.TRACE_COLUMNS`),
- ``summary.json`` (with the ``link`` block and a ``timing`` block), ``events.log``,
  ``plots/``, and ``vehicle.log`` / ``controller.log`` (each child's stderr).

The mission's ``[link]`` impairment (docs/design.md, "Link model"): in lockstep both children apply
it in simulation time to what crossed the socket (the offline loop's ends,
:mod:`bridge.link.ends`), and ``summary.json["link"]`` gives the model's exact statistics; in
real time, when the link is impaired, a third child, ``bsst relay`` (``relay.log``,
``relay.json``), sits between controller and vehicle and applies it on the wall clock.

Each half is written by the process that owns it, whole lines at a time, so any process
killed with SIGKILL leaves every file readable up to its last complete row; the join
only ever appends rows whose two halves are both on disk. A child that dies is reported
by name and the session ends in exit status 1; Ctrl-C or SIGTERM stops both children
within 2 s (SIGTERM, then SIGKILL) and still writes the summary (outcome ``aborted``).

Every session says honestly how it flew (docs/sitl.md, "Outcomes, exit statuses and safety
policies"): ``summary.json["ended_by"]`` names who ended the flight (the mission, the sender the
vehicle names for a disarm by command, the vehicle's failsafe, a child that died, the user), a
lockstep session has ``summary.json["lockstep"]`` (held, or when and why the vehicle left it),
and the safety policies of :mod:`bridge.record.policies` are checked over its trace and events
(``summary.json["policies"]``); ``events.log`` ends with the same.

Ports, as PX4 numbers its instances: the vehicle binds 14560 + N for the controller link
and sends GCS telemetry to 14550 + N, with sysid N + 1. ``instance=None`` (for campaigns
running many sessions at once) binds a free port instead and sends no GCS telemetry.
"""

from __future__ import annotations

import json
import math
import selectors
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from bridge.autopilot.estimator import compile_estimator
from bridge.core.flight import Flight, Overrides, Progress, prepare
from bridge.mavlink.endpoint import CONTROLLER_COMPID, CONTROLLER_SYSID, GCS_PORT, LINK_PORT, parse_address
from bridge.mavlink.signing import key_from_file
from bridge.nodes.process import parse_status
from bridge.record.columns import TRACE_COLUMNS
from bridge.record.joiner import TraceJoiner
from bridge.record.metrics import percentiles, summarise
from bridge.record.policies import (
    ended_by_command,
    ended_by_outcome,
    judge,
    lockstep_record,
    rules_for,
    violation_text,
    without_sender,
)
from bridge.record.runlog import EventLog, Run, RunRecord, check_trace_steps, run_dir, trace_arrays
from bridge.session.children import (
    READY_TIMEOUT_S,
    STOP_GRACE_S,
    Child,
    ChildError,
    check_port_free,
    free_udp_port,
    instance_slot,
)
from missions import Mission
from params import ConfigError

__all__ = ["ChildError", "Session", "instance_slot", "sitl"]



def sitl(
    mission: Mission | str | Path,
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
    **keywords: Any,
) -> Run:
    """Fly a mission as a SITL session (vehicle and controller processes over UDP).

    Returns a :class:`~bridge.record.runlog.Run`, as :func:`bridge.loop.simulate` does. The run
    directory is kept when ``out`` is given or ``write`` is true (then under ``runs/``);
    otherwise the session works in a temporary directory and returns only the arrays.
    ``instance`` N (0-9) picks ports 14560 + N / 14550 + N and sysid N + 1; ``None`` picks
    a free port and no GCS link. ``gcs`` (``HOST:PORT`` or ``"none"``) overrides the GCS
    address. ``speed`` caps lockstep at that many times real time. ``live`` prints a
    progress line on stderr (when it is a terminal). ``overrides`` (an
    :class:`~bridge.core.flight.Overrides`), or its fields as keywords, are laid over the mission as for
    :func:`bridge.loop.simulate` (``param_at``: the controller sends each change as PARAM_SET before the
    answer of its step: in lockstep the same step as offline).
    ``key`` is a MAVLink 2 signing key file (:func:`bridge.mavlink.signing.key_from_file`): both
    sides sign everything they send and accept only what is signed with it; only the file's path
    is passed on.
    """
    if key is not None:
        key_from_file(key)  # a missing, empty or world-readable key file is bad input, before anything starts
    flight = prepare(mission, overrides, **keywords)
    check_trace_steps(flight.mission)  # the session keeps every trace row for its summary: a cap, said up front
    if instance is not None and not (isinstance(instance, int) and 0 <= instance <= 9):
        raise ConfigError(f"--instance must be in [0, 9], got {instance!r}")
    if speed is not None and not (math.isfinite(speed) and speed > 0):
        raise ConfigError(f"--speed must be a positive number, got {speed!r}")
    if realtime and speed is not None and speed != 1.0:  # the controller's schedule is the wall clock's
        raise ConfigError(f"--speed {speed:g} with --realtime: a real-time flight runs at the wall clock's pace "
                          "(the controller keeps its rate on it, the plant would outrun it); --speed paces lockstep")
    n = instance or 0
    gcs_text = gcs if gcs is not None else (None if instance is None else f"127.0.0.1:{GCS_PORT + n}")
    if gcs_text is not None and gcs_text.strip().lower() == "none":
        gcs_text = None
    if gcs_text is not None:
        parse_address(gcs_text, "udpout", "--gcs")  # bad input fails here, before anything starts
    keep = out is not None or write
    if keep:  # a refused run directory is named before a busy port (both before anything starts)
        run_dir(out, flight.mission.name, overwrite, create=False)
    if instance is not None:
        check_port_free(LINK_PORT + n, f"--instance {n}")
    compile_estimator(flight.estimator)  # a first EKF on this machine compiles here, not in the vehicle's start-up
    path = run_dir(out, flight.mission.name, overwrite) if keep else Path(tempfile.mkdtemp(prefix="bsst-sitl-"))
    try:
        s = Session(flight, path, realtime=realtime, instance=instance, gcs=gcs_text, speed=speed,
                    progress=progress, live=live, key=Path(key) if key is not None else None)
        return s.run(plots=plots and keep, keep=keep)
    finally:
        if not keep:
            shutil.rmtree(path, ignore_errors=True)


class Session:
    """One SITL session in a run directory; :meth:`run` flies it."""

    def __init__(self, flight: Flight, path: Path, *, realtime: bool, instance: int | None, gcs: str | None,
                 speed: float | None, progress: Progress | None, live: bool, key: Path | None = None) -> None:
        self.flight = flight
        self.key = key  # the signing key file (its path only) both children get as --key
        self.path = path
        self.realtime = realtime
        self.instance = instance
        self.gcs = gcs
        self.speed = speed
        self.progress = progress
        self.live = live and sys.stderr.isatty()
        # a mission's MAV_SYS_ID is the vehicle's system id; else the instance's, as PX4 SITL's
        self.sysid = flight.params.sysid if "MAV_SYS_ID" in flight.mission.params else (instance or 0) + 1
        self.listen = f"127.0.0.1:{LINK_PORT + instance}" if instance is not None else "127.0.0.1:0"
        self.events: list[dict[str, Any]] = []
        self.vehicle: Child | None = None
        self.controller: Child | None = None
        self.relay: Child | None = None  # real time with an impaired link: bsst relay between the two
        self.vehicle_armed = False
        self.failsafe_seen = False
        self.diverged = False
        self.died: str | None = None
        self.aborted = False
        self.interrupted = False  # set by Ctrl-C / SIGTERM (see _catch_stop_signals)
        self._event_log: EventLog | None = None

    # -- the whole session ---------------------------------------------------------------------
    def run(self, plots: bool, keep: bool) -> Run:
        m = self.flight.mission
        record = RunRecord(self.path, m)
        self._event_log = record.events
        self.joiner = TraceJoiner(self.path, self.flight, record.trace, lockstep=not self.realtime)
        self.t_wall0 = time.monotonic()
        restore = _catch_stop_signals(self)
        try:
            try:
                self._start()
                self._supervise()
            except KeyboardInterrupt:
                self.aborted = True
                self._note("aborted", "interrupted (Ctrl-C or SIGTERM): stopping both processes", "session")
            except ChildError:
                pass  # already said by name (_died); the outcome is "aborted", the files are kept
            finally:
                try:
                    self._stop_children()
                finally:
                    restore()
                    self.joiner.controller_done = True
                    self.joiner.update()
                    self.joiner.close()
            arrays, summary = self._summary(time.monotonic() - self.t_wall0)
        finally:
            record.close()  # after the summary: events.log ends with how the run ended and its verdicts
        if keep:
            title = f"{m.name} ({m.controller}, {self.flight.profile.name}, SITL {summary['clock']})"
            record.finish(arrays, summary, title, plots and not self.aborted)
        if self.live:
            sys.stderr.write("\n")
        return Run(arrays, summary, self.path if keep else None)

    def _summary(self, wall: float) -> tuple[dict[str, Any], dict[str, Any]]:
        """The trace arrays and ``summary.json``: the figures, the ``timing`` and ``sitl`` blocks, the
        lockstep record (lockstep), who ended the flight (``ended_by``, which may turn a completion
        into ``aborted``) and the policies' verdicts; the last three also go to ``events.log``."""
        m = self.flight.mission
        clock = "realtime" if self.realtime else "lockstep"
        arrays = trace_arrays(self.joiner.rows, TRACE_COLUMNS)
        link = self._link_block()
        summary = summarise(arrays, m, self.flight.gains, clock=clock, outcome=self._outcome(), events=self.events,
                            link=link, estimator=self.flight.estimator, sensors=self.flight.sensors.name)
        summary["timing"] = self._timing_block(wall)
        summary["sitl"] = {
            "instance": self.instance, "listen": self.listen, "gcs": self.gcs, "sysid": self.sysid,
            "speed": self.speed, "died": self.died, "signed": self.key is not None,
            "vehicle_exit": self.vehicle.exit_text() if self.vehicle else None,
            "controller_exit": self.controller.exit_text() if self.controller else None,
        }
        judged, lockstep, off_clock = arrays, None, None
        if not self.realtime:
            # lockstep events keep the vehicle's clock (step k at k / rate_hz); the trace counts from the
            # controller's first answered step k0: the policies see both on the vehicle's clock
            k0 = self.joiner.k0 or 0
            judged = {**arrays, "t": arrays["t"] + k0 / m.rate_hz}
            off_clock = self._off_clock_t()
            summary["lockstep"] = lockstep = lockstep_record(self.events, off_clock)
        summary["outcome"], summary["ended_by"] = self._ended_by(summary["outcome"], arrays)
        rules = rules_for(self.flight, clock, link, (CONTROLLER_SYSID, CONTROLLER_COMPID))
        violated = judge(summary, judged, self.events, rules, lockstep, off_clock)
        end = summary["ended_by"]
        self._note("ended", f"{summary['outcome']}: by {end['who']}: {end['how']}", "session")
        if lockstep is not None and not lockstep["held"]:
            self._note("lockstep", f"not a lockstep run: the vehicle left lockstep at t={lockstep['left_at_s']:.3f} s "
                                   f"({lockstep['why']}) and flew on the wall clock", "session")
        for v in violated:
            self._note("policy", violation_text(v), "session")
        return arrays, summary

    def _ended_by(self, outcome: str, trace: Mapping[str, Any]) -> tuple[str, dict[str, Any]]:
        """The outcome and ``summary.json["ended_by"]``: who ended the flight, and how. A disarm or
        mode change by command from anyone but the configured controller, before the mission's
        end, ended it (named by the vehicle's event, `` [by ...]``), as does a controller that
        reports a completed mission whose trace stops short of the mission's end: both are
        ``aborted``, never ``completed``."""
        m = self.flight.mission
        ctl = self.controller
        if self.aborted:
            return "aborted", {"who": "user", "how": "interrupted (Ctrl-C or SIGTERM)"}
        if self.died:
            child = next((c for c in (self.vehicle, self.controller, self.relay) if c and c.name == self.died), None)
            how = f"died ({child.exit_text() if child else 'gone'})"
            if outcome == "failsafe":
                how += "; the vehicle's failsafe took over"
            return outcome, {"who": self.died, "how": how}
        if outcome == "diverged":
            return outcome, ended_by_outcome(outcome, self.events)
        ctl_completed = self._controller_completed()
        hit = ended_by_command(self.events, (CONTROLLER_SYSID, CONTROLLER_COMPID), before_s=m.duration_s)
        if hit is not None and not (ctl_completed and hit[1] is None):  # unattributed: the controller's own
            e, who = hit
            if e["kind"] == "mode":
                how = f"mode changed at t={e['t']:.3f} s: {without_sender(e['text'])}"
            else:
                where = "in flight" if _airborne(trace, e["t"] - (self.joiner.k0 or 0) / m.rate_hz
                                                 if not self.realtime else e["t"]) else "on the ground"
                how = f"disarmed {where} by command at t={e['t']:.3f} s"
            named = str(who) if who is not None else "someone (the vehicle's event names no sender)"
            return ("aborted" if outcome == "completed" else outcome), {"who": named, "how": how}
        t = trace["t"]
        if outcome == "completed" and (not len(t) or t[-1] < m.duration_s - 1.5 / m.rate_hz):
            flown = float(t[-1]) + 1.0 / m.rate_hz if len(t) else 0.0
            return "aborted", {"who": "controller", "how": f"ended the mission after {flown:.3f} s of its "
                                                           f"{m.duration_s:g} s"}
        if outcome == "aborted" and ctl is not None and ctl.done and "reason=" in ctl.done:
            return outcome, {"who": "controller", "how": ctl.done.split("reason=", 1)[1]}
        return outcome, ended_by_outcome(outcome, self.events)

    def _off_clock_t(self) -> float | None:
        """Lockstep: the vehicle's time (s) of its first row of ``vehicle.csv`` not flown on the step
        clock (the command in force answers another step, or none), or None; read as a stream."""
        try:
            with open(self.path / "vehicle.csv") as f:
                header = f.readline().strip().split(",")
                ik, ic = header.index("k"), header.index("cmd_k")
                for line in f:
                    parts = line.split(",")
                    if not line.endswith("\n") or len(parts) != len(header):
                        break  # a torn last line
                    if parts[ik] != parts[ic] and float(parts[ik]) != float(parts[ic]):
                        return float(parts[ik]) / self.flight.mission.rate_hz
        except (OSError, ValueError):
            return None
        return None

    def _controller_completed(self) -> bool:
        """Whether the controller flew its mission to the end: exit 0, or exit 1 with outcome completed
        (in lockstep, a vehicle that left lockstep: ``done outcome=completed lockstep=left``)."""
        ctl = self.controller
        if ctl is None or ctl.proc.returncode not in (0, 1):
            return False
        return ctl.proc.returncode == 0 or (ctl.done or "").startswith("outcome=completed ")

    def _outcome(self) -> str:
        ctl = self.controller
        completed = self._controller_completed() and not (self.aborted or self.died)
        if self.diverged:
            return "diverged"
        if self.failsafe_seen and not completed:  # completed after a failsafe: resumed ([failsafe] resume)
            return "failsafe"
        if self.aborted or self.died:
            return "aborted"
        if completed:
            return "completed"
        if ctl is not None and ctl.done and ctl.done.startswith("outcome="):
            word = ctl.done.split()[0].partition("=")[2]
            return word if word in ("failsafe", "diverged", "aborted") else "aborted"
        return "aborted"

    # -- children ----------------------------------------------------------------------------------
    def _start(self) -> None:
        """Start the children at once (each one's start-up, ~0.5 s of Python and imports, overlaps the
        others'), every port they need chosen first, then wait until each is ready."""
        mission = str(self.path / "mission.toml")
        # the controller's source port, named to the vehicle before either starts: the vehicle hears the
        # controller's ids from that address only (through a relay, from the relay's back port), so no
        # other process can claim them, not even before the controller's first message
        source = free_udp_port()
        relayed = self.realtime and self.flight.link.impaired
        back = free_udp_port() if relayed else source
        if self.listen.endswith(":0"):
            self.listen = f"127.0.0.1:{free_udp_port()}"
        port = self.listen.rpartition(":")[2]
        argv = ["vehicle", mission, "--listen", self.listen, "--gcs", self.gcs or "none",
                "--sysid", str(self.sysid), "--realtime" if self.realtime else "--lockstep",
                "--controller-from", f"127.0.0.1:{back}", "--out", str(self.path), "--overwrite"]
        if self.speed is not None:
            argv += ["--speed", repr(self.speed)]
        keyarg = ["--key", str(self.key)] if self.key is not None else []
        self.vehicle = Child("vehicle", argv + keyarg, self.path / "vehicle.log")
        to = port
        if relayed:  # the link model on the wall clock, between the two
            to = str(free_udp_port())
            self.relay = Child("relay", ["relay", "--listen", f"127.0.0.1:{to}", "--to", f"127.0.0.1:{port}",
                                         "--back-port", str(back), "--client", f"127.0.0.1:{source}",
                                         "--mission", mission, "--mission-clock",
                                         "--stats", str(self.path / "relay.json")], self.path / "relay.log")
        # its wait for the vehicle's heartbeat now includes the vehicle's start-up: the session's budget for it
        argv = ["controller", mission, "--vehicle", f"127.0.0.1:{to}", "--target-sysid", str(self.sysid),
                "--source-port", str(source), "--timeout", f"{READY_TIMEOUT_S:g}", "--out", str(self.path),
                "--overwrite"]
        if self.realtime:
            argv.append("--realtime")
        for c in self.flight.param_changes:
            argv += ["--param-at", f"{c.t_s!r}:{c.name}={c.value!r}"]
        self.controller = Child("controller", argv + keyarg, self.path / "controller.log")
        ready = self._wait_ready(self.vehicle)
        self._note("started", f"vehicle pid {self.vehicle.pid}: {ready.get('_line', '')}", "session")
        if self.relay is not None:
            line = self._wait_ready(self.relay, "relay:")["_line"]
            self._note("started", f"relay pid {self.relay.pid}: {line}", "session")
        self._wait_ready(self.controller)
        self._note("started", f"controller pid {self.controller.pid}", "session")

    def _wait_ready(self, child: Child, ready: str = "ready") -> dict[str, str]:
        """Block until ``child`` says ``ready`` (the first word of a status line; its
        ``key=value`` fields, and the rest of the line as ``_line``), or raise :class:`ChildError`."""
        deadline = time.monotonic() + READY_TIMEOUT_S
        sel = selectors.DefaultSelector()
        sel.register(child.fd, selectors.EVENT_READ)
        try:
            fields: dict[str, str] | None = None
            while True:
                # every line read is handled, the ones after "ready" too: the children start at once, so the
                # controller may arm the vehicle before its "ready" is read, and its "event ... armed" line
                # then comes in the same read (dropped, the session saw a flight never armed)
                for line in child.lines():
                    word, rest = parse_status(line)
                    self._status(child, line)
                    if word == ready and fields is None:
                        fields = dict(f.partition("=")[::2] for f in rest.split())
                        fields["_line"] = rest
                if fields is not None:
                    return fields
                if child.eof or child.proc.poll() is not None:
                    child.proc.wait()
                    self._died(child, starting=True)
                if self.interrupted:
                    raise KeyboardInterrupt
                left = deadline - time.monotonic()
                if left <= 0:
                    self.died = child.name
                    self._note("died", f"{child.name} (pid {child.pid}) not ready within {READY_TIMEOUT_S:g} s",
                               "session")
                    raise ChildError(child.name)
                sel.select(min(left, 0.5))
        finally:
            sel.close()

    def _died(self, child: Child, starting: bool = False) -> None:
        """A child is gone: say so by name; bad input (exit 2) is the user's, anything else ours."""
        err = child.last_error()
        if starting and child.proc.returncode == 2:
            raise ConfigError(err.removeprefix("bsst: ") or f"{child.name}: bad input")
        self.died = child.name
        self._note("died", f"{child.name} (pid {child.pid}) {child.exit_text()}" + (f": {err}" if err else ""),
                   "session")
        if starting:
            raise ChildError(f"{child.name} (pid {child.pid}) {child.exit_text()}" + (f": {err}" if err else ""))

    def _supervise(self) -> None:
        veh, ctl = self.vehicle, self.controller
        assert veh is not None and ctl is not None
        sel = selectors.DefaultSelector()
        sel.register(veh.fd, selectors.EVENT_READ, veh)
        sel.register(ctl.fd, selectors.EVENT_READ, ctl)
        landing_deadline: float | None = None
        try:
            while True:
                sel.select(0.1)
                if self.interrupted:
                    raise KeyboardInterrupt
                for child in (veh, ctl):
                    for line in child.lines():
                        self._status(child, line)
                self.joiner.update()
                self._show_progress()
                if veh.proc.poll() is not None:
                    for line in veh.lines():  # its last words: events it said before it went
                        self._status(veh, line)
                    self._died(veh)
                    return
                if self.relay is not None and self.relay.proc.poll() is not None:
                    self._died(self.relay)
                    return
                if ctl.proc.poll() is not None and landing_deadline is None:
                    for line in ctl.lines():
                        self._status(ctl, line)
                    self.joiner.controller_done = True
                    if ctl.done and "reason=" in ctl.done:  # a controller that gave up says why
                        reason = ctl.done.split("reason=", 1)[1]
                        sys.stderr.write(("\n" if self.live else "") + f"bsst sitl: controller: {reason}\n")
                    taken = ctl.done is not None and "reason=the vehicle was switched to " in ctl.done
                    if self._controller_completed() or not self.vehicle_armed or taken:
                        # taken: a ground station flies it now (HOLD, LAND, ...): nothing of the mission to wait for
                        if ctl.proc.returncode not in (0, 1):
                            self._died(ctl)
                        return
                    if ctl.done is None:  # killed or crashed: a death, not an outcome
                        self._died(ctl)
                    # the vehicle is on its own: let it finish its failsafe (land and disarm)
                    landing_deadline = time.monotonic() + self._landing_time()
                    self._note("waiting", f"vehicle on its own: waiting up to {self._landing_time():.0f} s "
                                          "for it to land and disarm", "session")
                if landing_deadline is not None and (not self.vehicle_armed or time.monotonic() > landing_deadline):
                    return
        finally:
            sel.close()

    def _landing_time(self) -> float:
        """Wall time allowed to a vehicle flying its failsafe alone: lockstep loss, timeout,
        descent from the highest point the trace reached, with a margin."""
        z = max((r[3] for r in self.joiner.rows[-2000:]), default=0.0)
        fs = self.flight.failsafe
        pace = self.speed or 1.0
        return 5.0 + (1.0 + fs.timeout_s + fs.time_to_land_s(z)) / pace

    def _stop_children(self) -> None:
        """SIGTERM the controller, the relay, the vehicle; SIGKILL whatever is left after the grace."""
        children = [c for c in (self.controller, self.relay, self.vehicle) if c is not None]
        for c in children:
            if c.proc.poll() is None:
                try:
                    c.proc.send_signal(signal.SIGTERM)
                except ProcessLookupError:
                    pass
        deadline = time.monotonic() + STOP_GRACE_S
        for c in children:
            try:
                c.proc.wait(timeout=max(deadline - time.monotonic(), 0.01))
            except subprocess.TimeoutExpired:
                c.proc.kill()
                c.proc.wait()
                self._note("killed", f"{c.name} (pid {c.pid}) did not stop within {STOP_GRACE_S:g} s: SIGKILL",
                           "session")
            for line in c.lines():
                self._status(c, line)
            c.proc.stdout.close()  # type: ignore[union-attr]

    # -- status lines, events, progress -------------------------------------------------------------
    def _status(self, child: Child, line: str) -> None:
        word, rest = parse_status(line)
        if word != "event":
            return
        t_text, _, what = rest.partition(" ")
        kind, _, text = what.partition(": ")
        try:
            t = float(t_text.removeprefix("t="))
        except ValueError:
            t = math.nan
        if child.name == "vehicle":
            if self.realtime and math.isfinite(t):
                t = self._flight_time(t)
            if kind == "armed":
                self.vehicle_armed = True
            elif kind == "disarmed":
                self.vehicle_armed = False
            elif kind == "failsafe":
                self.failsafe_seen = True
            elif kind == "diverged":
                self.diverged = True
        self._note(kind, text, child.name, t)

    def _flight_time(self, t_vehicle: float) -> float:
        """Real time: the vehicle's clock runs from its start; the flight's (the trace's and
        the controller's) time 0 is the vehicle's step k0, the first state the controller
        answered. Events before it is known (arming) are at 0."""
        joiner = getattr(self, "joiner", None)
        if joiner is not None:
            joiner.update()  # k0 may be in a row not joined yet
        if joiner is None or joiner.k0 is None:
            return 0.0
        return t_vehicle - joiner.k0 / self.flight.mission.rate_hz

    def _note(self, kind: str, text: str, source: str, t: float | None = None) -> None:
        if t is None:
            t = self.joiner.rows[-1][0] if getattr(self, "joiner", None) and self.joiner.rows else 0.0
        self.events.append({"t": round(t, 6) if math.isfinite(t) else None, "kind": kind, "text": text,
                            "source": source})
        if self._event_log is not None:
            self._event_log.event(t if math.isfinite(t) else 0.0, kind, f"{text} [{source}]")
        if source == "session" and kind in ("died", "killed"):
            sys.stderr.write(("\n" if self.live else "") + f"bsst sitl: {text}\n")

    def _show_progress(self) -> None:
        rows = self.joiner.rows
        if not rows or not (self.live or self.progress):
            return
        r = rows[-1]
        t = r[0]
        err = math.sqrt((r[1] - r[13]) ** 2 + (r[2] - r[14]) ** 2 + (r[3] - r[15]) ** 2)
        if self.progress is not None:
            self.progress(t, self.flight.mission.duration_s, err)
        if self.live:
            first = self.joiner.first_sent
            wall = time.monotonic() - (first if first is not None else self.t_wall0)
            sys.stderr.write(f"\rsitl t {t:7.2f} / {self.flight.mission.duration_s:.2f} s   "
                             f"real-time factor {t / max(wall, 1e-9):6.1f}x   3-D error {err:.2e} m   ")
            sys.stderr.flush()

    # -- summary blocks --------------------------------------------------------------------------------
    def _link_block(self) -> dict[str, Any]:
        """``summary.json["link"]`` (docs/design.md, "Files of a run"), per direction:

        - lockstep: the link model's exact statistics, from the end that applies it (the
          vehicle: ``up``, the controller: ``down``), ``delay_ms`` in simulation time; plus
          ``socket_ms``, the wall-clock one-way time of the per-step messages over the socket;
        - real time through the relay: the relay's counts (every datagram), ``delay_ms``
          measured end to end on the per-step messages (ODOMETRY down, the target up) from
          both sides' stamps (one host: one monotonic clock, no offset to estimate), the
          model's schedule (``model_delay_ms``) and the delay the relay added (``relay_added_ms``);
        - otherwise (real time, perfect link; a side that left no statistics): counts from
          both sides, ``delay_ms`` from their stamps.
        """
        j = self.joiner
        vs = self.vehicle.stats if self.vehicle else {}
        cs = self.controller.stats if self.controller else {}
        # what each side's receive path refused (bridge.mavlink.receive), and all of it by reason
        by = {"vehicle": dict(vs.get("rejected", {})), "controller": dict(cs.get("rejected", {}))}
        rejected = {r: by["vehicle"].get(r, 0) + by["controller"].get(r, 0)
                    for r in sorted(set(by["vehicle"]) | set(by["controller"]))}
        own = int(vs.get("rejected_from_controller", sum(by["vehicle"].values())))  # of the controller's datagrams
        measured = {"up": percentiles(j.up_ms), "down": percentiles(j.down_ms)}
        relay = self._relay_stats()
        model = {"up": vs.get("up"), "down": cs.get("down")}
        up_sent = int(cs.get("commands", len(j.ctl)))
        up_delivered = int(vs.get("accepted", 0))
        down_sent = int(vs.get("odometry_sent", 0))
        down_delivered = int(cs.get("states", len(j.ctl)))  # a killed controller left no stats: its rows
        sides = {
            "up": {"sent": up_sent, "delivered": up_delivered,
                   "lost": max(0, up_sent - up_delivered - own), "duplicated": 0,
                   "reordered": int(rejected.get("reordered", 0))},
            "down": {"sent": down_sent, "delivered": down_delivered, "lost": max(0, down_sent - down_delivered),
                     "duplicated": 0, "reordered": 0},
        }
        out: dict[str, Any] = {}
        for d in ("up", "down"):
            if relay is not None:
                r = relay[d]
                out[d] = {**{k: r[k] for k in ("sent", "delivered", "lost", "duplicated", "reordered", "in_flight",
                                               "lost_by")},
                          "delay_ms": measured[d], "model_delay_ms": r["delay_ms"], "relay_added_ms": r["measured_ms"]}
                if "trace" in r:  # a replayed link trace: its own delays and losses, as offline
                    out[d]["trace"] = r["trace"]
            elif model[d]:
                out[d] = {**model[d], "socket_ms": measured[d]}
            else:
                out[d] = {**sides[d], "delay_ms": measured[d]}
        out["rejected"] = rejected
        out["rejected_by"] = by
        # of those, how many came from the other side itself, and how many from anyone else on the link (a
        # ground station's, a stranger's): the vehicle counts its controller's apart from the GCS link's
        ctl_own = int(cs.get("rejected_from_vehicle", sum(by["controller"].values())))
        out["rejected_from_peer"] = {"vehicle": own, "controller": ctl_own}
        out["rejected_from_others"] = {"vehicle": max(0, sum(by["vehicle"].values()) - own),
                                       "controller": max(0, sum(by["controller"].values()) - ctl_own)}
        if relay is not None:  # datagrams the relay refused, from neither of its two ends, by reason
            out["relay_refused"] = relay.get("refused", {})
        return out

    def _relay_stats(self) -> dict[str, Any] | None:
        """What ``bsst relay --stats`` wrote on exit (None without a relay or a readable file)."""
        if self.relay is None:
            return None
        try:
            return json.loads((self.path / "relay.json").read_text())
        except (OSError, ValueError):
            return None

    def _timing_block(self, wall: float) -> dict[str, Any]:
        j = self.joiner
        sim = len(j.rows) / self.flight.mission.rate_hz
        cs = self.controller.stats if self.controller else {}
        vs = self.vehicle.stats if self.vehicle else {}
        n = len(j.rows)
        flight_s = j.last_sent - j.first_sent if j.first_sent is not None and n > 1 else math.nan
        rate = (n - 1) / flight_s if flight_s > 0 else None
        return {
            "wall_s": wall,  # the whole session: start, fly, stop
            "sim_s": sim,
            "flight_wall_s": flight_s if math.isfinite(flight_s) else None,
            "step_rate_hz": rate,  # control steps per wall second while flying
            "real_time_factor": rate / self.flight.mission.rate_hz if rate else None,
            "missing_rows": j.missing,
            "state_to_command_ms": percentiles(j.rtt_ms),
            "state_to_command_timesync_ms": percentiles(j.s2c_ms),
            "period_error_ms": percentiles(j.late_ms),
            "stale_ticks": int(cs.get("stale_ticks", 0)),
            "overruns": int(cs.get("overruns", 0)),
            # lockstep: states resent after RESEND_S of wall time unanswered, and the second answers to them
            "lockstep_resends": int(vs.get("resends", 0)),
            "answered_again": int(vs.get("answered_again", 0)),
        }


def _airborne(trace: Mapping[str, Any], t: float) -> bool:
    """Whether the trace's last row at or before ``t`` (s) is off the ground (z above it, or moving)."""
    ts = trace["t"]
    i = int(np.searchsorted(ts, t + 1e-9, side="right")) - 1
    return i >= 0 and (trace["z"][i] > 1e-6 or abs(trace["vz"][i]) > 1e-6)


def _catch_stop_signals(session: Session) -> Callable[[], None]:
    """While a session runs, Ctrl-C (SIGINT) and SIGTERM only set ``session.interrupted``;
    the session checks it between whole steps, so no file is left half-written by an
    exception raised in the middle of a write. Main thread only (signals go there)."""
    if threading.current_thread() is not threading.main_thread():
        return lambda: None

    def handler(signum: int, frame: Any) -> None:
        session.interrupted = True

    old = {sig: signal.signal(sig, handler) for sig in (signal.SIGINT, signal.SIGTERM)}

    def restore() -> None:
        for sig, h in old.items():
            signal.signal(sig, h)

    return restore


