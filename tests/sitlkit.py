"""Helpers for the tests that start real processes: read their status lines with deadlines.

No sleeps to hope something happened: every wait is on an event (a line, a file row, a
process exit) with a deadline, and fails with what was seen so far.
"""

from __future__ import annotations

import contextlib
import json
import os
import select
import selectors
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, Literal, TypeVar

import numpy as np
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from bridge.nodes.forkserver import ForkedChild, start_child
from bridge.nodes.process import die_with_parent
from bridge.nodes.report import Event, Report, parse_line
from bridge.record.policies import stalls_of
from tests.gcsfork import start_script
from tests.waiting import wait_for

ROOT = Path(__file__).resolve().parent.parent
ENV = {**os.environ, "MAVLINK20": "1"}
BSST = [sys.executable, "-m", "bridge"]  # the command line of `bsst` that the forked children show
R = TypeVar("R")


def run_bsst(*args: str | Path, cwd: Path = ROOT, env: dict[str, str] | None = None, timeout: float = 300.0,
             input: str | None = None) -> subprocess.CompletedProcess[str]:
    """``bsst ARGS`` (``python -m bridge ARGS``) run to its end in ``cwd``, as ``subprocess.run(...,
    capture_output=True, text=True)`` gives it; forked warm by the fork server, as a session's children are
    (docs/testing.md). ``input``: its stdin (default: empty)."""
    return _run_to_end(Bsst(*args, cwd=cwd, env=env, input=input), timeout)


def _run_to_end(p: Bsst, timeout: float) -> subprocess.CompletedProcess[str]:
    """``p`` (a :class:`Bsst` or :class:`Script`) waited for, its output read, as ``subprocess.run`` gives it;
    ``subprocess.TimeoutExpired`` after ``timeout`` s, ``p`` killed."""
    try:
        out, err = p.communicate(timeout)
    except subprocess.TimeoutExpired:
        p.kill()
        p.wait()
        raise
    return subprocess.CompletedProcess(p.args, p.returncode, out, err)


class Bsst:
    """``bsst ARGS`` started and left running, forked warm by the fork server: the ``subprocess.Popen`` calls
    the tests make of it (``pid``, ``poll``, ``wait``, ``send_signal``, ``kill``, ``returncode``,
    ``communicate``), its stdout and stderr each a text pipe (``stdout``, ``stderr``), discarded (``False``), or
    stderr into stdout's pipe (``stderr="stdout"``, as ``subprocess.STDOUT``); ``env``: this process's environment
    unless given; ``input``: its stdin (default: empty), or ``stdin``, a descriptor. It is its own process group
    (``os.killpg(p.pid, ...)``)."""

    PREFIX = BSST  # what the command line shows before ARGS

    def __init__(self, *args: str | Path, cwd: Path = ROOT, env: dict[str, str] | None = None,
                 stdout: bool = True, stderr: bool | Literal["stdout"] = True, input: str | None = None,
                 stdin: int | None = None) -> None:
        self.args = [*self.PREFIX, *map(str, args)]
        out = os.pipe() if stdout else None
        err = os.pipe() if stderr is True else None
        with open(os.devnull, "wb") as null, tempfile.TemporaryFile() as given:
            given.write((input or "").encode())
            given.seek(0)
            out_fd = null.fileno() if out is None else out[1]
            err_fd = out_fd if stderr == "stdout" else null.fileno() if err is None else err[1]
            try:
                self.p = self._start(self.args[len(self.PREFIX):], out_fd, err_fd,
                                     given.fileno() if stdin is None else stdin, str(cwd), env)
            finally:
                for e in (out, err):
                    if e is not None:
                        os.close(e[1])
        self.stdout, self.stderr = (None if e is None else open(e[0], encoding="utf-8", errors="replace")
                                    for e in (out, err))
        self.pid = self.p.pid

    def _start(self, args: list[str], out: int, err: int, given: int, cwd: str,
               env: dict[str, str] | None) -> ForkedChild | subprocess.Popen[bytes]:
        return start_child(args, out, err, stdin=given, cwd=cwd, env=env)

    @property
    def returncode(self) -> int | None:
        return self.p.returncode

    def poll(self) -> int | None:
        return self.p.poll()

    def wait(self, timeout: float | None = None) -> int:
        return self.p.wait(timeout)  # type: ignore[return-value]

    def send_signal(self, sig: int) -> None:
        self.p.send_signal(sig)

    def kill(self) -> None:
        self.p.kill()

    def communicate(self, timeout: float | None = None) -> tuple[str, str]:
        """What is left on stdout and stderr (each read to its end by a thread of its own, "" for one
        discarded) and the exit, within ``timeout`` s (``subprocess.TimeoutExpired`` if not; the reading goes on
        for the next call)."""
        deadline = None if timeout is None else time.monotonic() + timeout
        if not hasattr(self, "_readers"):
            self._texts: dict[int, str] = {}

            def drain(i: int, f: Any) -> None:
                self._texts[i] = f.read()

            self._readers = [threading.Thread(target=drain, args=(i, f), daemon=True)
                             for i, f in enumerate((self.stdout, self.stderr)) if f is not None]
            for t in self._readers:
                t.start()
        for t in self._readers:
            t.join(None if deadline is None else max(0.0, deadline - time.monotonic()))
            if t.is_alive():
                raise subprocess.TimeoutExpired(self.args, timeout or 0.0)
        try:
            self.wait(None if deadline is None else max(0.0, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            raise subprocess.TimeoutExpired(self.args, timeout or 0.0) from None
        for f in (self.stdout, self.stderr):
            if f is not None:
                f.close()
        return self._texts.get(0, ""), self._texts.get(1, "")


class Script(Bsst):
    """``python ARGS`` (a ground station: ``-c SCRIPT ...`` or ``FILE ...``) as :class:`Bsst` runs ``bsst``, forked
    warm by the test kit's own fork server (tests/gcsfork.py: pymavlink, MAVProxy and MAVSDK imported once); ``cwd``:
    this process's unless given, as ``subprocess`` has it."""

    PREFIX = [sys.executable]

    def __init__(self, *args: str | Path, cwd: Path | None = None, **kw: Any) -> None:
        super().__init__(*args, cwd=Path.cwd() if cwd is None else cwd, **kw)

    def _start(self, args: list[str], out: int, err: int, given: int, cwd: str,
               env: dict[str, str] | None) -> ForkedChild | subprocess.Popen[bytes]:
        return start_script(args, out, err, stdin=given, cwd=cwd, env=env)


def run_script(*args: str | Path, cwd: Path | None = None, env: dict[str, str] | None = None, timeout: float = 300.0,
               input: str | None = None) -> subprocess.CompletedProcess[str]:
    """``python ARGS`` run to its end, as ``subprocess.run([sys.executable, *ARGS], capture_output=True, text=True,
    ...)`` gives it: forked warm (:class:`Script`); ``subprocess.TimeoutExpired`` after ``timeout`` s, the script
    killed."""
    return _run_to_end(Script(*args, cwd=cwd, env=env, input=input), timeout)


def pool_workers(group: int) -> list[int]:
    """A ``bsst sweep``'s or ``bsst margin``'s pool workers: the processes of its process group two generations below
    its leader (the leader starts multiprocessing's fork server, which forks the workers). While the leader runs they
    are its children's children (a few reads of /proc/PID/task/TID/children: a test polls this every 10 ms, and a
    scan of /proc reads every process's stat, ~4 ms a call with 80 processes on the machine, more in a loaded suite);
    once it has ended, those left in its group (a dying sweep's orphans) are found by that scan."""
    if process_state(group) not in (None, "Z"):
        return [w for child in _children(group) for w in _children(child) if _stat(w)[2:3] == [str(group)]]
    parents = {}
    for entry in Path("/proc").iterdir():
        fields = _stat(entry.name)
        if fields[2:3] == [str(group)]:  # pgrp
            parents[int(entry.name)] = int(fields[1])  # ppid
    return [pid for pid, ppid in parents.items() if ppid in parents and ppid != group]


def _stat(pid: int | str) -> list[str]:
    """The fields of /proc/PID/stat after the command's name (state, ppid, pgrp, ...); [] if it is not a process, or
    gone."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return []


def process_state(pid: int) -> str | None:
    """Process ``pid``'s state letter (``Z``: ended, not reaped), None if it is gone."""
    return (_stat(pid) or [None])[0]


def _children(pid: int) -> list[int]:
    """The children of process ``pid`` (forked by any of its threads); [] if it is gone."""
    try:
        tasks = os.listdir(f"/proc/{pid}/task")
    except OSError:
        return []
    kids = []
    for tid in tasks:
        try:
            kids += map(int, Path(f"/proc/{pid}/task/{tid}/children").read_text().split())
        except OSError:
            continue  # the thread has ended
    return kids


def shown(e: Event) -> str:
    """A child's event as a person reads it: ``kind: text`` and its sender's `` [by ...]``."""
    return f"{e.kind}: {e.text}" + (e.by.suffix if e.by is not None else "")


class Proc:
    """A child process whose stdout is read line by line without blocking."""

    def __init__(self, argv: list[str], cwd: Path | None = None, stdin: int | None = subprocess.DEVNULL,
                 bsst: bool = False, warm: bool = False) -> None:
        """``bsst``: ``argv`` is ``bsst``'s (:data:`BSST` ...), forked warm as a session's children are; ``warm``:
        ``argv`` is a ground station's (``sys.executable`` ...), forked warm too (:class:`Script`), its stdin a pipe
        of its own (``self.stdin``) with ``stdin=subprocess.PIPE``; else exec'd (docs/testing.md)."""
        self.argv = argv
        self.p: subprocess.Popen[bytes] | ForkedChild
        self.stdin: Any = None
        if bsst or warm:
            piped = os.pipe() if warm and stdin == subprocess.PIPE else None
            if bsst:
                forked: Bsst = Bsst(*argv[len(BSST):], cwd=cwd or Path.cwd(), env=ENV, stderr="stdout")
            else:
                forked = Script(*argv[1:], cwd=cwd, env=ENV, stderr="stdout", stdin=piped and piped[0])
            if piped is not None:
                os.close(piped[0])
                self.stdin = open(piped[1], "wb")  # noqa: SIM115  (held as Popen's stdin is)
            self.p = forked.p
            self._out = forked.stdout  # (held: closing it would close the pipe)
            self.fd = forked.stdout.fileno()  # type: ignore[union-attr]
        else:
            # its own session (a test signals its group), and SIGTERM if the test process dies: a bare vehicle
            # runs until stopped, so one left by a killed pytest would hold its instance's ports for the next run
            self.p = subprocess.Popen(argv, cwd=cwd, stdin=stdin, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                      env=ENV, start_new_session=True, preexec_fn=die_with_parent)
            self.fd = self.p.stdout.fileno()  # type: ignore[union-attr]
            self.stdin = self.p.stdin
        os.set_blocking(self.fd, False)
        self._buf = b""
        self.lines: list[str] = []

    @classmethod
    def bsst(cls, *args: str, cwd: Path | None = None) -> Proc:
        """``bsst ARGS`` (``python -m bridge ARGS``), its stdout and stderr read as one."""
        return cls([*BSST, *args], cwd=cwd, bsst=True)

    def _read(self) -> None:
        while True:
            try:
                data = os.read(self.fd, 65536)
            except BlockingIOError:
                return
            if not data:
                return
            self._buf += data
            *full, self._buf = self._buf.split(b"\n")
            self.lines += [ln.decode(errors="replace") for ln in full]

    def wait_line(self, pred: Callable[[str], bool], timeout: float = 20.0, start: int = 0) -> str:
        """The first line (seen so far from index ``start`` on, or to come) that satisfies ``pred``."""
        deadline = time.monotonic() + timeout
        sel = selectors.DefaultSelector()
        sel.register(self.fd, selectors.EVENT_READ)
        seen = start
        try:
            while True:
                self._read()
                for line in self.lines[seen:]:
                    if pred(line):
                        return line
                seen = len(self.lines)
                left = deadline - time.monotonic()
                if left <= 0 or (self.p.poll() is not None and not sel.select(0)):
                    raise AssertionError(f"no such line within {timeout} s from {self.argv[-3:]}; "
                                         f"exit {self.p.poll()}; got:\n" + "\n".join(self.lines[-30:]))
                sel.select(min(left, 0.2))
        finally:
            sel.close()

    def reports(self) -> list[Report]:
        """The reports read so far (:func:`bridge.nodes.report.parse_line`; other lines left out)."""
        self._read()
        return [r for r in map(parse_line, self.lines) if r is not None]

    def wait_report(self, kind: type[R], pred: Callable[[R], Any] = lambda r: True, timeout: float = 20.0) -> R:
        """The first report of ``kind`` (seen so far or to come) that satisfies ``pred``."""
        line = self.wait_line(lambda s: isinstance(r := parse_line(s), kind) and bool(pred(r)), timeout)
        return parse_line(line)  # type: ignore[return-value]

    def events(self) -> list[str]:
        """The events reported so far, as :func:`shown`, in order."""
        return [shown(r) for r in self.reports() if isinstance(r, Event)]

    def wait_event(self, pred: Callable[[str], Any], timeout: float = 20.0) -> Event:
        """The first event whose :func:`shown` text satisfies ``pred``."""
        return self.wait_report(Event, lambda e: pred(shown(e)), timeout)

    def ended(self, timeout: float = 30.0) -> int:
        """The exit status of a process that ends itself (a refusal said, its exit under way): waited for, and only
        after ``timeout`` stopped. :meth:`stop` at once could SIGTERM it between its last line and its exit (-15)."""
        try:
            self.p.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            pass
        return self.stop()

    def stop(self, timeout: float = 5.0) -> int:
        """SIGTERM, wait (SIGKILL after ``timeout``), read what is left; the exit status."""
        if self.p.poll() is None:
            self.p.send_signal(signal.SIGTERM)
        try:
            self.p.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.p.kill()
            self.p.wait()
        self._read()
        return self.p.returncode


class MavProxy(Proc):
    """MAVProxy, unmodified, as a user runs it: ``mavproxy.py --master=MASTER --nowait`` in ``cwd`` (where its
    ``wp load`` / ``wp list`` files are), typed to through its stdin."""

    def __init__(self, master: str, cwd: Path) -> None:
        mavproxy = os.path.join(os.path.dirname(sys.executable), "mavproxy.py")
        super().__init__([sys.executable, mavproxy, f"--master={master}", "--nowait"], cwd=cwd, stdin=subprocess.PIPE,
                         warm=True)

    def say(self, cmd: str) -> int:
        """Type ``cmd``; the index of the first line that can answer it."""
        mark = len(self.lines)
        self.stdin.write(cmd.encode() + b"\n")
        self.stdin.flush()
        return mark

    def wait_online(self, timeout: float = 30.0) -> str:
        """MAVProxy has heard the vehicle (its ``online system`` line, or ``Detected vehicle``)."""
        return self.wait_line(lambda s: "online system" in s or "Detected vehicle" in s, timeout)

    def stop(self, timeout: float = 5.0) -> int:
        """End MAVProxy as a user at its prompt does, Ctrl-D: its stdin closed, its input loop reads EOF, unloads
        its modules and exits 1 (MAVProxy 1.8's end, whatever ended it); else (not within ``timeout``) as
        :meth:`Proc.stop`. ``exit`` is not a command unless ``set requireexit True``, and then, as SIGTERM, only
        sets the flag its main thread reads between lines of stdin: blocked reading the next, it never looked (a
        SIGTERM within ~50 ms of a typed line, before the line was read, ended it; one later, 5 s to the SIGKILL)."""
        with contextlib.suppress(OSError):  # (BrokenPipeError: it has ended already)
            self.stdin.close()
        with contextlib.suppress(subprocess.TimeoutExpired):
            self.p.wait(timeout=timeout)
        return super().stop(timeout)


def csv_rows(path: Path) -> int:
    """Complete data rows of a CSV (``trace.csv``) so far (0 if it does not exist yet)."""
    try:
        return max(path.read_bytes().count(b"\n") - 1, 0)
    except FileNotFoundError:
        return 0


class GcsSocket:
    """A ground station's UDP socket on 127.0.0.1 (system 255, component 190) for a vehicle built in this process
    (``bridge.nodes.vehicle.Vehicle`` with ``gcs=`` :attr:`url`): it sends a frame to the vehicle's GCS link, lets
    the vehicle take in what came, and reads the answers; no processes, no sleeps. ``link="link"`` with the
    controller's ids is the controller on the vehicle's own link (its ``--listen``) instead."""

    def __init__(self, sysid: int = 255, compid: int = 190, link: str = "gcs") -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.setblocking(False)
        self.mav = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)
        self.link = link  # the vehicle's attribute of the link it sends to

    @property
    def url(self) -> str:
        """The vehicle's ``--gcs``: where its GCS link sends."""
        return f"udpout:127.0.0.1:{self.sock.getsockname()[1]}"

    def received(self) -> list[Any]:
        """The messages waiting on the socket now (none: an empty list)."""
        got: list[Any] = []
        with contextlib.suppress(BlockingIOError):
            while True:
                got.extend(self.mav.parse_buffer(self.sock.recv(65535)) or [])
        return got

    def exchange(self, vehicle: Any, msg: Any | None, want: str) -> Any:
        """Send ``msg`` (if any) to ``vehicle``'s link and let it take in what came, until a ``want`` message
        is back (5 s deadline): the first one; what came with it is dropped."""
        seen = self.exchange_until(vehicle, msg, lambda m: m.get_type() == want, f"the vehicle's {want}")
        return next(m for m in seen if m.get_type() == want)

    def exchange_until(self, vehicle: Any, msg: Any | None, last: Callable[[Any], bool], what: str) -> list[Any]:
        """Send ``msg`` (if any) to ``vehicle``'s link and let it take in what came, until a message for which
        ``last`` is true is back (5 s deadline, ``what`` named if it is missed): every message back so far."""
        link = getattr(vehicle, self.link)
        if msg is not None:
            self.sock.sendto(msg.pack(self.mav), link.local)
        seen: list[Any] = []

        def answered() -> bool:
            for m, addr in link.poll():
                vehicle._handle(link, m, addr)
            seen.extend(self.received())
            return any(last(m) for m in seen)

        wait_for(answered, 5.0, what, poll_s=0.001)
        return seen

    def close(self) -> None:
        self.sock.close()


def unexplained_outages(trace: dict[str, Any], stalls: dict[str, Any], over_s: float = 0.03) -> dict[str, list]:
    """A real-time run on a perfect link against its ``timing.stalls``: ``rows``, the trace's times (s) whose
    command in force answered a state more than ``over_s`` old outside every listed stall (its t - 10 ms to its
    end + 20 ms: the catch-up after it); ``stalls``, the listed stalls of 2 ``over_s`` or more, ending inside the
    trace, with no such row in their window. Both empty: the stalls explain every outage the trace shows."""
    t, age = trace["t"], trace["state_age_s"]
    windows = [(s["t"] - 0.01, s["t"] + s["ms"] / 1e3 + 0.02, s) for s in stalls["at"]]
    old = [float(x) for x, a in zip(t, age) if a > over_s]
    rows = [x for x in old if not any(lo <= x <= hi for lo, hi, _ in windows)]
    end = float(t[-1]) if len(t) else 0.0
    missed = [s for lo, hi, s in windows if s["ms"] >= 2e3 * over_s and hi <= end
              and not any(lo <= x <= hi for x in old)]
    return {"rows": rows, "stalls": missed}


CONTROLLER_STALLED = "bsst controller: not flown as asked: the machine stalled the real-time loop"


def clean_exit(summary: dict[str, Any]) -> int:
    """The exit status of a run that flew as asked but for the machine's stalls: 0, or 1 if it stalled (a host
    that takes its cores back stalls the suite's real-time runs: ``timing.stalls``)."""
    return 0 if stalls_of(summary) is None else 1


def controller_exit(lines: list[str]) -> int:
    """The exit status of a real-time ``bsst controller`` alone that flew as asked but for the machine's stalls of its
    ticks (its stderr's lines, or its stdout's and stderr's as one): 0, or 1 if it said it stalled (:func:`clean_exit`
    for a session) and nothing else: a stall beside another reason (``bsst controller: failsafe: ...``, an end action
    unanswered) is 0, so that the caller's ``rc == controller_exit(...)`` fails on that exit 1 (a stall line alone
    accepted then any exit 1: the flight's own failure hidden behind the machine's stall)."""
    said = [ln for ln in lines if ln.startswith("bsst controller:")]
    return 1 if said and all(ln.startswith(CONTROLLER_STALLED) for ln in said) else 0


def controller_exit_text(summary: dict[str, Any]) -> str:
    """``sitl.controller_exit`` of a real-time session's controller that flew as asked but for the machine's stalls
    of its ticks: status 1 if ``timing.stalls`` lists one on its side (it says so as it would alone), else 0."""
    stalls = (summary.get("timing") or {}).get("stalls") or {}
    return f"exited with status {int(any(s['side'] == 'controller' for s in stalls.get('at', ())))}"


def stall_blackouts(stalls: dict[str, Any], duration_s: float) -> list[list[float]]:
    """A real-time run's stalls as the ``[link] blackouts`` (``[[t_s, duration_s], ...]``, both directions) that
    fly the same outages offline: a stalled process neither reads nor sends, and the vehicle holds its target
    (docs/sitl.md, "Stalls"). Overlapping stalls (both sides at once, as a host stops both cores) are one."""
    merged: list[list[float]] = []
    for lo, hi in sorted((s["t"], s["t"] + s["ms"] / 1e3) for s in stalls["at"]):
        if merged and lo <= merged[-1][1]:
            merged[-1][1] = max(merged[-1][1], hi)
        else:
            merged.append([lo, hi])
    return [[round(lo, 3), round(min(hi, duration_s) - lo, 3)] for lo, hi in merged if lo < duration_s]


def trace_blackouts(trace: dict[str, Any], rate_hz: float) -> list[list[float]]:
    """The outages a real-time run flew, from its trace, as ``[link] blackouts`` (``[[t_s, duration_s], ...]``) that
    fly them offline: each control tick whose state no command in force ever answered (a row's ``t -
    state_age_s``), lost. It takes what :func:`stall_blackouts` models (a stall's outage) at the length the run had
    it (a catch-up the loaded machine slowed; a tick the controller skipped for waking late) and nothing else: a
    command the vehicle flew that its controller never sent shows in the RMS, not here."""
    period = 1.0 / rate_hz
    t = np.asarray(trace["t"], dtype=float)
    answered = set(np.rint((t - np.asarray(trace["state_age_s"], dtype=float)) * rate_hz).astype(int).tolist())
    out: list[list[float]] = []
    for j in range(int(round(t[-1] * rate_hz)) - 1 if len(t) else 0):
        if j in answered:
            continue
        if out and abs(out[-1][0] + out[-1][1] - (j - 0.5) * period) < 1e-9:
            out[-1][1] += period
        else:  # (the first tick's from the flight's start: a blackout starts at 0 s or later)
            start = max((j - 0.5) * period, 0.0)
            out.append([start, (j + 0.5) * period - start])
    return [[round(a, 6), round(d, 6)] for a, d in out]


def child_pids(run: Path) -> dict[str, int]:
    """A session's children's pids by name (``vehicle``, ``controller``, ``relay``), as its launcher logged them
    in ``events.log`` (``started: NAME pid N...``): those started so far, read while it flies."""
    pids = {}
    path = run / "events.log"
    for line in (path.read_text() if path.is_file() else "").splitlines():
        if "started:" in line and " pid " in line:
            name, pid = line.split("started: ")[1].split(" pid ")
            pids[name] = int(pid.split(":")[0].split()[0])
    return pids


class HeldEcho(threading.Thread):
    """The control of a relay's hold: a datagram held ``hold_s`` by a timed sleep and sent back, in this process, by
    a thread of its own (a context manager: started on entry, stopped on exit). A relayed datagram wakes three
    threads on its way (the relay's on its arrival, the relay's again at its due time, the receiver's); so does one
    sent here. On an oversubscribed machine the scheduler makes each wake-up late whatever the relay does (a full
    suite beside two busy loops: ~1 ms each, against 0.1 ms for a lone timer's), and this measures how late, in the
    same seconds (:meth:`round`, :meth:`median_late_ms`)."""

    def __init__(self, hold_s: float) -> None:
        super().__init__(daemon=True)
        self.hold_s = hold_s
        self.late_ms: list[float] = []  # each round's
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self._stop_r, self._stop_w = os.pipe()

    def run(self) -> None:
        while True:
            ready = select.select([self.sock, self._stop_r], [], [])[0]
            if self._stop_r in ready:
                return
            data, back = self.sock.recvfrom(2048)
            select.select([self._stop_r], [], [], self.hold_s)
            self.sock.sendto(data, back)

    def __enter__(self) -> HeldEcho:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        os.write(self._stop_w, b"x")
        self.join(5.0)
        for fd in (self._stop_r, self._stop_w):
            os.close(fd)
        self.sock.close()

    def round(self, client: socket.socket, size: int) -> None:
        """A datagram of ``size`` bytes from ``client`` (a socket with a timeout) held and back: how late (ms),
        its time out and back less the hold, kept."""
        t0 = time.perf_counter()
        client.sendto(bytes(size), self.sock.getsockname())
        client.recvfrom(2048)
        self.late_ms.append((time.perf_counter() - t0 - self.hold_s) * 1000.0)

    def median_late_ms(self) -> float:
        """The rounds' median lateness (ms), never below 0."""
        assert self.late_ms, "no round of the control was sent"
        return max(0.0, statistics.median(self.late_ms))


def tlog_messages(path: Path, sysid: int, kinds: str | list[str]) -> list[Any]:
    """The messages of ``kinds`` that system ``sysid`` sent, in the order a tlog (``vehicle.tlog``) holds them."""
    log = mavutil.mavlink_connection(str(path), dialect="common")
    out = []
    while (m := log.recv_match(type=kinds)) is not None:
        if m.get_srcSystem() == sysid:
            out.append(m)
    return out


def script_result(r: subprocess.CompletedProcess[str]) -> dict[str, Any]:
    """The ``out`` a ground-station script run to its end printed as ``RESULT <json>`` (:data:`MAVSDK_GROUND_STATION`);
    a script that printed none fails the test with its exit status and the tails of its output."""
    lines = [ln for ln in r.stdout.splitlines() if ln.startswith("RESULT ")]
    assert lines, f"MAVSDK script failed (exit {r.returncode}):\n{r.stdout[-3000:]}\n{r.stderr[-3000:]}"
    return json.loads(lines[0][len("RESULT "):])


# The opening of a MAVSDK script run as ``python -c SCRIPT CONNECTION`` (a ground station on CONNECTION): ``sdk``,
# ``out`` (printed as ``RESULT <json>`` at the end by the script) and ``until(pred, timeout)``, polling ``pred``.
MAVSDK_GROUND_STATION = r"""
import json, sys, time
from mavsdk import Mavsdk, Configuration, ComponentType

sdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
sdk.add_any_connection(sys.argv[1])
out = {}
def until(pred, timeout):
    deadline = time.monotonic() + timeout
    while not pred():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.02)
    return True
"""
