"""The SITL session: ``bsst sitl`` and :func:`sitl` (DESIGN.md sections 4-7).

Starts the vehicle (``python -m bridge vehicle``) and the offboard controller
(``python -m bridge controller``) as two child processes talking MAVLink 2 over UDP on
127.0.0.1, waits for each to say ``ready`` (deadlines, no fixed sleeps), supervises them,
and leaves the run directory of DESIGN.md section 6:

- ``mission.toml`` (as flown, overrides applied: both children read this file),
- ``vehicle.tlog``, ``controller.tlog`` (both directions of each side),
- ``vehicle.csv``, ``controller.csv``: each side's half of the trace, appended as it flies,
- ``trace.csv``: the two halves joined live, one row per control step, the same columns
  and meaning as the offline loop's (:data:`bridge.runlog.TRACE_COLUMNS`),
- ``summary.json`` (with the ``link`` block and a ``timing`` block), ``events.log``,
  ``plots/``, and ``vehicle.log`` / ``controller.log`` (each child's stderr).

The mission's ``[link]`` impairment (DESIGN.md section 5): in lockstep both children apply
it in simulation time to what crossed the socket (the offline loop's ends,
:mod:`bridge.linkends`), and ``summary.json["link"]`` gives the model's exact statistics; in
real time, when the link is impaired, a third child, ``bsst relay`` (``relay.log``,
``relay.json``), sits between controller and vehicle and applies it on the wall clock.

Each half is written by the process that owns it, whole lines at a time, so any process
killed with SIGKILL leaves every file readable up to its last complete row; the join
only ever appends rows whose two halves are both on disk. A child that dies is reported
by name and the session ends in exit status 1; Ctrl-C or SIGTERM stops both children
within 2 s (SIGTERM, then SIGKILL) and still writes the summary (outcome ``aborted``).

Ports, as PX4 numbers its instances: the vehicle binds 14560 + N for the controller link
and sends GCS telemetry to 14550 + N, with sysid N + 1. ``instance=None`` (for campaigns
running many sessions at once) binds a free port instead and sends no GCS telemetry.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import math
import os
import selectors
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any

from bridge.endpoint import CONTROLLER_COMPID, CONTROLLER_SYSID, GCS_PORT, LINK_PORT, parse_address
from bridge.flight import Flight, prepare
from bridge.metrics import percentiles, summarise
from bridge.process import die_with_parent, parse_status
from bridge.runlog import (
    TRACE_COLUMNS,
    EventLog,
    Run,
    TraceWriter,
    finish_run,
    run_dir,
    trace_arrays,
    write_text_atomic,
)
from bridge.signing import key_from_file
from missions import Mission, Setpoint, Step
from params import ConfigError, dump_toml

Progress = Callable[[float, float, float], None]  # (t, duration, current 3-D error), as bridge.loop
READY_TIMEOUT_S = 30.0  # s for a child to start (Python, imports, bind) on a loaded machine
STOP_GRACE_S = 1.5  # s between SIGTERM and SIGKILL: both children gone within 2 s
# column positions in vehicle.csv / controller.csv (bridge.vehicle.VEHICLE_COLUMNS, bridge.offboard.CONTROLLER_COLUMNS)
V_K, V_STATE, V_MODE, V_KEY, V_C, V_U, V_ACT, V_AGE, V_RTT, V_SENT, V_RECV = 0, 2, 14, 15, 16, 20, 24, 28, 29, 30, 31
C_K, C_U, C_C, C_PHI_D, C_RECV, C_SENT, C_S2C, C_LATE, C_AGE = 0, 6, 10, 14, 16, 17, 18, 19, 20


class ChildError(Exception):
    """A child process failed to start or died; the message names it."""


def sitl(
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
    realtime: bool = False,
    instance: int | None = 0,
    gcs: str | None = None,
    speed: float | None = None,
    progress: Progress | None = None,
    live: bool = False,
    link: Mapping[str, Any] | None = None,
    key: str | Path | None = None,
) -> Run:
    """Fly a mission as a SITL session (vehicle and controller processes over UDP).

    Returns a :class:`~bridge.runlog.Run`, as :func:`bridge.loop.simulate` does. The run
    directory is kept when ``out`` is given or ``write`` is true (then under ``runs/``);
    otherwise the session works in a temporary directory and returns only the arrays.
    ``instance`` N (0-9) picks ports 14560 + N / 14550 + N and sysid N + 1; ``None`` picks
    a free port and no GCS link. ``gcs`` (``HOST:PORT`` or ``"none"``) overrides the GCS
    address. ``speed`` caps lockstep at that many times real time. ``live`` prints a
    progress line on stderr (when it is a terminal). ``link`` is laid over the mission's
    ``[link]`` table, as for :func:`bridge.loop.simulate`. ``key`` is a MAVLink 2 signing key
    file (:func:`bridge.signing.key_from_file`): both sides sign everything they send and
    accept only what is signed with it; only the file's path is passed on.
    """
    if key is not None:
        key_from_file(key)  # a missing, empty or world-readable key file is bad input, before anything starts
    flight = prepare(mission, profile=profile, controller=controller, rate_hz=rate_hz, seed=seed, link=link)
    if instance is not None and not (isinstance(instance, int) and 0 <= instance <= 9):
        raise ConfigError(f"--instance must be in [0, 9], got {instance!r}")
    if speed is not None and not (math.isfinite(speed) and speed > 0):
        raise ConfigError(f"--speed must be a positive number, got {speed!r}")
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
        _check_port_free(LINK_PORT + n, f"--instance {n}")
    path = run_dir(out, flight.mission.name, overwrite) if keep else Path(tempfile.mkdtemp(prefix="bsst-sitl-"))
    try:
        s = Session(flight, path, realtime=realtime, instance=instance, gcs=gcs_text, speed=speed,
                    progress=progress, live=live, key=Path(key) if key is not None else None)
        return s.run(plots=plots and keep, keep=keep)
    finally:
        if not keep:
            shutil.rmtree(path, ignore_errors=True)


def _check_port_free(port: int, flag: str) -> None:
    """ConfigError naming ``flag`` if UDP 127.0.0.1:``port`` is taken: a vehicle already runs
    there, so this session's could not start (said before any file is written)."""
    import socket

    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        s.bind(("127.0.0.1", port))
    except OSError as exc:
        raise ConfigError(f"{flag}: UDP 127.0.0.1:{port} is in use ({exc.strerror}); pick another instance") from None
    finally:
        s.close()


class Child:
    """One child process: its status lines (stdout, read without blocking) and its exit."""

    def __init__(self, name: str, argv: list[str], log: Path) -> None:
        self.name = name
        with open(log, "wb") as err:
            self.proc = subprocess.Popen(
                [sys.executable, "-m", "bridge", *argv], stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                stderr=err, start_new_session=True, preexec_fn=die_with_parent)
        self.log = log
        self.fd = self.proc.stdout.fileno()  # type: ignore[union-attr]
        os.set_blocking(self.fd, False)
        self._buf = b""
        self.eof = False
        self.stats: dict[str, Any] = {}
        self.done: str | None = None  # the controller's "done outcome=..." line

    @property
    def pid(self) -> int:
        return self.proc.pid

    def lines(self) -> list[str]:
        """Complete lines written since the last call."""
        out = []
        while True:
            try:
                data = os.read(self.fd, 65536)
            except BlockingIOError:
                break
            if not data:
                self.eof = True
                break
            self._buf += data
        *full, self._buf = self._buf.split(b"\n")
        for raw in full:
            line = raw.decode(errors="replace")
            word, rest = parse_status(line)
            if word == "stats":
                try:
                    self.stats = json.loads(rest)
                except ValueError:
                    pass
            elif word == "done":
                self.done = rest
            out.append(line)
        return out

    def exit_text(self) -> str:
        rc = self.proc.returncode
        if rc is None:
            return "still running"
        if rc < 0:
            try:
                return f"killed by {signal.Signals(-rc).name}"
            except ValueError:
                return f"killed by signal {-rc}"
        return f"exited with status {rc}"

    def last_error(self) -> str:
        """The last line of the child's stderr (its one-line error, or a traceback's end)."""
        try:
            lines = [ln for ln in self.log.read_text(errors="replace").splitlines() if ln.strip()]
        except OSError:
            return ""
        return lines[-1].strip() if lines else ""


class PartReader:
    """Reads the complete new lines of a part file (``vehicle.csv``, ``controller.csv``)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._fd = -1
        self._buf = b""
        self._header = True

    def read(self) -> list[list[float]]:
        if self._fd < 0:
            try:
                self._fd = os.open(self.path, os.O_RDONLY)
            except FileNotFoundError:
                return []
        chunks = []
        while True:
            data = os.read(self._fd, 1 << 20)
            if not data:
                break
            chunks.append(data)
        if not chunks:
            return []
        *full, self._buf = (self._buf + b"".join(chunks)).split(b"\n")
        if self._header and full:
            full = full[1:]
            self._header = False
        return [[float(x) for x in line.split(b",")] for line in full if line]

    def close(self) -> None:
        if self._fd >= 0:
            os.close(self._fd)
            self._fd = -1


class TraceJoiner:
    """Joins the vehicle's and the controller's halves into trace rows (live, append-only).

    Vehicle row k holds the true state at t_k, the command in force (the target answering
    state ``cmd_k``, as it arrived on the wire) and what the plant realised; the controller's
    row for ``cmd_k`` holds what the law demanded (u1..u4, phi_d, theta_d). A vehicle row
    waits for its other half (the controller writes it just after sending the command);
    once the controller is gone, a row whose half never came is left out (``missing``).
    Rows flown by the vehicle's own failsafe (no controller command) take the landing
    loop's demand, and its desired attitude (level). ``t`` counts from the first state the
    controller answered. In ``lockstep`` a step the controller answered (``cmd_k`` = k) takes
    ``c1..c4`` and ``state_age_s`` from the controller's row, as the offline loop writes them:
    the last command sent, and the age of the state this step's command was computed from
    (nan when the guard sent none).
    """

    def __init__(self, path: Path, flight: Flight, trace: TraceWriter | None, lockstep: bool = False) -> None:
        self.v = PartReader(path / "vehicle.csv")
        self.c = PartReader(path / "controller.csv")
        self.lockstep = lockstep
        self.trace = trace
        self.rate = flight.mission.rate_hz
        self.steps = flight.mission.steps
        self.sample = flight.mission.trajectory.sample
        self.ctl: dict[int, list[float]] = {}
        self.pending: deque[list[float]] = deque()
        self.k0: int | None = None
        self.rows: list[tuple[float, ...]] = []
        self.controller_done = False
        self.up_ms: list[float] = []
        self.down_ms: list[float] = []
        self.rtt_ms: list[float] = []
        self.s2c_ms: list[float] = []
        self.late_ms: list[float] = []
        self._up_seen: set[int] = set()
        self.missing = 0  # vehicle rows left out: their controller half was never written
        self.first_sent: float | None = None  # wall time the first / last joined state was sent
        self.last_sent = math.nan

    def update(self) -> int:
        """Join what both files hold now; returns the number of new trace rows."""
        vrows = self.v.read()  # first: see the class docstring
        for c in self.c.read():
            k = int(c[C_K])
            self.ctl[k] = c
            if self.k0 is None:
                self.k0 = k
            if math.isfinite(c[C_S2C]):
                self.s2c_ms.append(1e3 * c[C_S2C])
            if math.isfinite(c[C_LATE]):
                self.late_ms.append(1e3 * c[C_LATE])
        self.pending.extend(vrows)
        n0 = len(self.rows)
        while self.pending:
            v = self.pending[0]
            key = int(v[V_KEY])
            c = self.ctl.get(key) if key >= 0 else None
            if key >= 0 and c is None and not self.controller_done:
                break  # its row is on its way (written just after the send)
            self.pending.popleft()
            self._join(v, key, c)
        if self.trace is not None and len(self.rows) > n0:
            self.trace.flush()
        return len(self.rows) - n0

    def _join(self, v: list[float], key: int, c: list[float] | None) -> None:
        k = int(v[V_K])
        mode = int(v[V_MODE])
        if self.k0 is None or k < self.k0 or (key < 0 and mode == 0):
            return  # not flying the mission yet (armed, no target)
        if key >= 0 and c is None:
            self.missing += 1  # a controller killed between its send and its row: no half to join
            return
        if mode == 0 and k - self.k0 >= self.steps:
            return  # realtime: the state that ended the mission, flown while the disarm was on its way
        t = (k - self.k0) / self.rate
        ref = self.sample(t)
        if c is not None:
            u = tuple(c[C_U:C_U + 4])
            desired = tuple(c[C_PHI_D:C_PHI_D + 2])
            if key not in self._up_seen and math.isfinite(v[V_RECV]):
                self._up_seen.add(key)
                self.up_ms.append(1e3 * (v[V_RECV] - c[C_SENT]))
                if math.isfinite(v[V_RTT]):
                    self.rtt_ms.append(1e3 * v[V_RTT])
        else:
            u = tuple(v[V_U:V_U + 4])
            desired = (0.0, 0.0)  # the landing loop holds the vehicle level
        own = self.ctl.get(k)
        if own is not None:
            self.down_ms.append(1e3 * (own[C_RECV] - v[V_SENT]))
        if self.first_sent is None:
            self.first_sent = v[V_SENT]
        self.last_sent = v[V_SENT]
        wire, age = v[V_C:V_C + 4], v[V_AGE]
        if self.lockstep and c is not None and key == k:
            wire, age = c[C_C:C_C + 4], c[C_AGE]
        row = (t, *v[V_STATE:V_STATE + 12], ref[0][0], ref[1][0], ref[2][0], ref[3][0], *u,
               *wire, *v[V_ACT:V_ACT + 4], age, *desired)
        self.rows.append(row)
        if self.trace is not None:
            self.trace.row(row)

    def close(self) -> None:
        self.v.close()
        self.c.close()


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
        self.sysid = (instance or 0) + 1
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
        write_text_atomic(self.path / "mission.toml", dump_toml(m.to_dict()))
        self._event_log = EventLog(self.path / "events.log")
        trace = TraceWriter(self.path / "trace.csv")
        self.joiner = TraceJoiner(self.path, self.flight, trace, lockstep=not self.realtime)
        self.t_wall0 = time.monotonic()
        restore = _catch_stop_signals(self)
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
                trace.close()
                self._event_log.close()
        wall = time.monotonic() - self.t_wall0
        outcome = self._outcome()
        rows = self.joiner.rows
        arrays = trace_arrays(rows, TRACE_COLUMNS)
        summary = summarise(arrays, m, self.flight.gains, clock="realtime" if self.realtime else "lockstep",
                            outcome=outcome, events=self.events, link=self._link_block())
        summary["timing"] = self._timing_block(wall)
        summary["sitl"] = {
            "instance": self.instance, "listen": self.listen, "gcs": self.gcs, "sysid": self.sysid,
            "speed": self.speed, "died": self.died, "signed": self.key is not None,
            "vehicle_exit": self.vehicle.exit_text() if self.vehicle else None,
            "controller_exit": self.controller.exit_text() if self.controller else None,
        }
        if keep:
            title = f"{m.name} ({m.controller}, {self.flight.profile.name}, SITL {summary['clock']})"
            finish_run(self.path, arrays, summary, title, plots and not self.aborted)
        if self.live:
            sys.stderr.write("\n")
        return Run(arrays, summary, self.path if keep else None)

    def _outcome(self) -> str:
        ctl = self.controller
        completed = ctl is not None and ctl.proc.returncode == 0 and not (self.aborted or self.died)
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
        mission = str(self.path / "mission.toml")
        argv = ["vehicle", mission, "--listen", self.listen, "--gcs", self.gcs or "none",
                "--sysid", str(self.sysid), "--realtime" if self.realtime else "--lockstep",
                "--out", str(self.path), "--overwrite"]
        if self.speed is not None:
            argv += ["--speed", repr(self.speed)]
        keyarg = ["--key", str(self.key)] if self.key is not None else []
        self.vehicle = Child("vehicle", argv + keyarg, self.path / "vehicle.log")
        ready = self._wait_ready(self.vehicle)
        port = ready.get("listen", self.listen).rpartition(":")[2]
        self.listen = f"127.0.0.1:{port}"  # the port bound, also when it was chosen free
        self._note("started", f"vehicle pid {self.vehicle.pid}: {ready.get('_line', '')}", "session")
        if self.realtime and self.flight.link.impaired:  # the link model on the wall clock, between the two
            self.relay = Child("relay", ["relay", "--listen", "127.0.0.1:0", "--to", f"127.0.0.1:{port}",
                                         "--mission", mission, "--mission-clock",
                                         "--stats", str(self.path / "relay.json")], self.path / "relay.log")
            line = self._wait_ready(self.relay, "relay:")["_line"]
            port = line.split(" -> ")[0].rpartition(":")[2]  # "listening on HOST:PORT -> ..."
            self._note("started", f"relay pid {self.relay.pid}: {line}", "session")
        argv = ["controller", mission, "--vehicle", f"127.0.0.1:{port}", "--target-sysid", str(self.sysid),
                "--out", str(self.path), "--overwrite"]
        if self.realtime:
            argv.append("--realtime")
        self.controller = Child("controller", argv + keyarg, self.path / "controller.log")
        self._wait_ready(self.controller)
        self._note("started", f"controller pid {self.controller.pid}", "session")

    def _wait_ready(self, child: Child, ready: str = "ready") -> dict[str, str]:
        """Block until ``child`` says ``ready`` (the first word of a status line; its
        ``key=value`` fields, and the rest of the line as ``_line``), or raise :class:`ChildError`."""
        deadline = time.monotonic() + READY_TIMEOUT_S
        sel = selectors.DefaultSelector()
        sel.register(child.fd, selectors.EVENT_READ)
        try:
            while True:
                for line in child.lines():
                    word, rest = parse_status(line)
                    self._status(child, line)
                    if word == ready:
                        fields = dict(f.partition("=")[::2] for f in rest.split())
                        fields["_line"] = rest
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
                    veh.lines()
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
                    if ctl.proc.returncode == 0 or not self.vehicle_armed:
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
        return 5.0 + (1.0 + fs.timeout_s + max(z, 0.0) / fs.descent_rate) / pace

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
        """``summary.json["link"]`` (DESIGN.md section 6), per direction:

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
        # what each side's receive path refused (bridge.guard), and all of it by reason
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
            elif model[d]:
                out[d] = {**model[d], "socket_ms": measured[d]}
            else:
                out[d] = {**sides[d], "delay_ms": measured[d]}
        out["rejected"] = rejected
        out["rejected_by"] = by
        # of those, how many came from the other side itself (not from third parties on the link)
        out["rejected_from_peer"] = {"vehicle": own, "controller": sum(by["controller"].values())}
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
        }


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


@contextlib.contextmanager
def instance_slot(timeout_s: float = 600.0) -> Iterator[int]:
    """Hold instance number N (0-9) of this machine exclusively while the block runs.

    An advisory ``flock`` on ``<tmp>/bsst-instance-N.lock`` (the convention ``bsst sweep``
    uses too), so sessions started by tests, sweeps or scripts side by side never share
    ports 14550 + N / 14560 + N. Raises TimeoutError when all ten stay taken.
    """
    deadline = time.monotonic() + timeout_s
    while True:
        for n in range(10):
            fd = os.open(os.path.join(tempfile.gettempdir(), f"bsst-instance-{n}.lock"), os.O_RDWR | os.O_CREAT,
                         0o644)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                os.close(fd)
                continue
            try:
                yield n
            finally:
                os.close(fd)  # closing releases the lock
            return
        if time.monotonic() > deadline:
            raise TimeoutError(f"no free SITL instance (0-9) within {timeout_s:g} s")
        time.sleep(0.05)  # all ten held by other sessions: look again shortly


# -- the two sides alone (bsst vehicle, bsst controller) -------------------------------------------------
def rest_mission() -> Mission:
    """What a bare ``bsst vehicle`` simulates: the paper profile at rest at the origin."""
    return Mission(Step((Setpoint(0.0, 0.0, 0.0, 0.0, 0.0),)), duration_s=86400.0, name="vehicle")


def vehicle_from_args(args: Any) -> int:
    """``bsst vehicle`` from its parsed arguments."""
    from bridge.telemetry import Home
    from bridge.vehicle import VehicleConfig, run_vehicle

    flight = prepare(args.mission or rest_mission(), profile=args.profile, rate_hz=args.rate, seed=args.seed)
    n = args.instance
    listen = parse_address(args.listen or f"127.0.0.1:{LINK_PORT + n}", "udpin", "--listen")
    if listen.mode != "udpin":
        raise ConfigError(f"--listen {args.listen!r}: the controller link is bound (udpin), not udpout")
    gcs_text = args.gcs or f"127.0.0.1:{GCS_PORT + n}"
    gcs = None if gcs_text.strip().lower() == "none" else parse_address(gcs_text, "udpout", "--gcs")
    sysid, compid = args.controller_id or (CONTROLLER_SYSID, CONTROLLER_COMPID)
    cfg = VehicleConfig(listen, gcs, sysid=args.sysid or n + 1, controller_sysid=sysid, controller_compid=compid,
                        clock="realtime" if args.realtime else "lockstep", speed=args.speed,
                        home=Home(*args.home) if args.home else Home(), key=_key(args))
    return run_vehicle(flight, cfg, args.out, args.overwrite)


def controller_from_args(args: Any) -> int:
    """``bsst controller`` from its parsed arguments."""
    from bridge.offboard import OffboardConfig, run_controller

    flight = prepare(args.mission, profile=args.profile, controller=args.controller, rate_hz=args.rate,
                     seed=args.seed)
    vehicle = parse_address(args.vehicle or f"127.0.0.1:{LINK_PORT + args.instance}", "udpout", "--vehicle")
    if vehicle.mode != "udpout":
        raise ConfigError(f"--vehicle {args.vehicle!r}: the controller sends to the vehicle (udpout)")
    cfg = OffboardConfig(vehicle, sysid=args.sysid, clock="realtime" if args.realtime else "lockstep",
                         target_sysid=args.target_sysid, connect_timeout_s=args.timeout, key=_key(args))
    return run_controller(flight, cfg, args.out, args.overwrite)


def _key(args: Any) -> bytes | None:
    """The signing key of ``--key FILE``, if given (ConfigError: exit 2, naming the file)."""
    return key_from_file(args.key) if getattr(args, "key", None) else None
