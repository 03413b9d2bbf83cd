"""Hostile input for the tests and benchmarks of issues 7 and 11: a seeded fuzzer of datagrams
that a vehicle must refuse, the kernel's view of a UDP socket, a paced sender, a flood (of
fuzz, or of packed requests: :func:`packed_requests`) that counts what comes back, and a
scripted MAVLink speaker (:class:`Station`: a ground station, a controller, a stranger), and what an in-process
vehicle's state is for a property test (:func:`vehicle_state`, :func:`drop_held_answer`).

Every datagram :class:`Fuzzer` makes must be refused by the vehicle while it flies a
lockstep mission (armed, at a step k >= :data:`MIN_STEP`), and each kind says which reason
it must be counted under (None: any reason, e.g. random bytes):

- ``random``: random bytes, 1-300 long;
- ``truncated``: a valid frame cut short (0 to len - 1 bytes);
- ``bitflip``: a valid frame with one bit flipped (CRC-16 catches every single-bit error);
- ``sender``: a valid actuator target from another system or component than the controller;
- ``target``: a valid ARM/DISARM addressed to another system;
- ``unknown_id``: a MAVLink 2 frame of a message id not in the dialect;
- ``not_finite`` / ``out_of_range``: targets with the controller's ids carrying NaN/inf, or
  values outside their range;
- ``stale`` / ``future``: valid targets with the controller's ids for step 0 or for a step
  far past the mission's end;

  (these four claim the controller's ids from other addresses during its flight: each is
  refused as a ``stranger``'s before its numbers are looked at; docs/design.md, "Authority")
- ``mavlink1``: valid MAVLink 1 frames;
- ``empty``: zero-length datagrams; ``huge``: 65507-byte (the largest UDP) datagrams.

Nothing it makes is ever a valid target for the step being flown, so a fuzzed lockstep
run must give the undisturbed run's ``trace.csv``.
"""

from __future__ import annotations

import contextlib
import itertools
import json
import math
import os
import random
import re
import selectors
import signal
import socket
import sys
import threading
import time
from collections import Counter
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

from bridge.mavlink.endpoint import CONTROLLER_COMPID, CONTROLLER_SYSID
from bridge.mavlink.kerneldrops import udp_table_row
from bridge.record.halves import count_records, read_half
from bridge.session import instance_slot
from tests.sitlkit import Proc, run_script
from tests.waiting import wait_for

MIN_STEP = 10  # the stale targets are for step 0: fuzz only once the vehicle is past this step
KINDS: dict[str, str | None] = {
    "random": None, "truncated": "truncated", "bitflip": None, "sender": "sender", "target": "target",
    "unknown_id": "unknown_id", "not_finite": "stranger", "out_of_range": "stranger", "stale": "stranger",
    "future": "stranger", "mavlink1": "mavlink1", "empty": "truncated", "huge": "oversized",
}
HUGE = 65507  # bytes: the largest UDP payload over IPv4
FUTURE_USEC = 10**12  # a step no mission reaches (11.6 days)


def vehicle_state(v: Any) -> tuple:
    """What an in-process :class:`~bridge.nodes.vehicle.Vehicle` is now, as its parts hold it: the plant, arming,
    mode and step, the clock's held answer and state, the target in force, the streams and the controller's
    address, the up link's newest send (a refused datagram must change none of it)."""
    s, clock = v.sim, v.clock
    return (v.plant.state, s.armed, s.mode, v.k, clock.answer, v.targets.applied, clock.state, clock.on_wall_clock,
            tuple(sorted(v.streaming.streams.items())), tuple(sorted(v.streaming.ctl_streams.items())), v.link.peer,
            v.vend.newest_sent_t, v.vend.up.stats.sent)


def drop_held_answer(v: Any) -> None:
    """The answer of step k held by a vehicle's clock, thrown away unflown (a test taking a step back)."""
    from bridge.nodes.vehicle.clock import ClockState, Trigger

    if v.clock.state is ClockState.ANSWERED:
        v.clock.fire(Trigger.DROP)


class Fuzzer:
    """Seeded hostile datagrams for a vehicle of system ``sysid`` flying ``actuation``
    (``wrench``: SET_ACTUATOR_CONTROL_TARGET, ``motors``: HIL_ACTUATOR_CONTROLS)."""

    def __init__(self, seed: int, sysid: int, actuation: str = "wrench", huge_every: int = 2000) -> None:
        self.rng = random.Random(seed)
        self.sysid = sysid
        self.actuation = actuation
        self.huge_every = huge_every
        self.ctl = mavlink.MAVLink(None, srcSystem=CONTROLLER_SYSID, srcComponent=CONTROLLER_COMPID)
        self.sent: Counter[str] = Counter()
        self._kinds = [k for k in KINDS if k != "huge"]

    def _pack(self, msg: object, mav: mavlink.MAVLink | None = None, v1: bool = False) -> bytes:
        mav = mav or self.ctl
        buf = msg.pack(mav, force_mavlink1=v1)  # type: ignore[attr-defined]
        mav.seq = (mav.seq + 1) & 0xFF
        return bytes(buf)

    def target(self, usec: int, values: tuple[float, float, float, float], src: tuple[int, int] | None = None
               ) -> bytes:
        """An actuator target of the vehicle's actuation, from ``src`` (default: the controller's ids)."""
        mav = self.ctl if src is None else mavlink.MAVLink(None, srcSystem=src[0], srcComponent=src[1])
        if self.actuation == "wrench":
            msg: object = mavlink.MAVLink_set_actuator_control_target_message(usec, 0, self.sysid, 1,
                                                                              list(values) + [0.0] * 4)
        else:
            msg = mavlink.MAVLink_hil_actuator_controls_message(usec, list(values) + [0.0] * 12,
                                                                mavlink.MAV_MODE_FLAG_SAFETY_ARMED, 1)
        return self._pack(msg, mav)

    def _valid(self) -> bytes:
        """A valid frame of some kind (only ever sent damaged)."""
        r = self.rng
        choice = r.randrange(4)
        if choice == 0:
            return self.target(r.randrange(10**9), (0.0, 0.0, 0.0, 0.3))
        if choice == 1:
            return self._pack(mavlink.MAVLink_command_long_message(self.sysid, 1, 400, 0, 0.0, 21196.0,
                                                                   0, 0, 0, 0, 0))  # a forced DISARM
        if choice == 2:
            return self._pack(mavlink.MAVLink_heartbeat_message(18, 8, 0, 0, 4, 3))
        return self._pack(mavlink.MAVLink_timesync_message(0, r.randrange(2**62)))

    def make(self, kind: str) -> bytes:
        r = self.rng
        self.sent[kind] += 1
        if kind == "random":
            return r.randbytes(r.randint(1, 300))
        if kind == "truncated":
            f = self._valid()
            return f[:r.randrange(len(f))]
        if kind == "bitflip":
            f = bytearray(self._valid())
            f[r.randrange(len(f))] ^= 1 << r.randrange(8)
            return bytes(f)
        if kind == "sender":
            other = (r.choice([s for s in range(1, 255) if s != CONTROLLER_SYSID]), CONTROLLER_COMPID) \
                if r.random() < 0.5 else (CONTROLLER_SYSID, r.choice([c for c in range(256) if c != CONTROLLER_COMPID]))
            return self.target(r.randrange(10**9), (0.0, 0.0, 0.0, 0.3), other)
        if kind == "target":
            return self._pack(mavlink.MAVLink_command_long_message(
                r.choice([s for s in range(1, 255) if s != self.sysid]), 1, 400, 0, float(r.randrange(2)), 21196.0,
                0, 0, 0, 0, 0))
        if kind == "unknown_id":
            n = r.randint(1, 40)
            mid = r.choice([42000, 50001, 0xFFFFFF, 12345])
            head = bytes((0xFD, n, 0, 0, r.randrange(256), 1, 1, mid & 0xFF, (mid >> 8) & 0xFF, mid >> 16))
            return head + r.randbytes(n + 2)
        if kind == "not_finite":
            bad = r.choice([math.nan, math.inf, -math.inf])
            v = [0.0, 0.0, 0.0, 0.3]
            v[r.randrange(4)] = bad
            return self.target(r.randrange(10**9), tuple(v))  # type: ignore[arg-type]
        if kind == "out_of_range":
            v = [0.0, 0.0, 0.0, 0.3]
            i = r.randrange(4)
            if self.actuation == "wrench" and i < 3:  # roll, pitch, yaw in [-1, 1]
                v[i] = r.choice([-1.5, 1.5, 7.0])
            else:  # thrust, motors in [0, 1]
                v[i] = r.choice([-0.1, 1.2, 7.0])
            return self.target(r.randrange(10**9), tuple(v))  # type: ignore[arg-type]
        if kind == "stale":
            return self.target(0, (0.0, 0.0, 0.0, 0.3))
        if kind == "future":
            return self.target(FUTURE_USEC + r.randrange(10**6), (0.0, 0.0, 0.0, 0.3))
        if kind == "mavlink1":
            mav = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
            return self._pack(mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3), mav, v1=True)
        if kind == "empty":
            return b""
        if kind == "huge":
            return r.randbytes(HUGE)
        raise ValueError(kind)

    def next(self, i: int) -> bytes:
        """The i-th datagram of a burst: a 64 KiB one every ``huge_every``, else a random kind."""
        if self.huge_every and i % self.huge_every == self.huge_every - 1:
            return self.make("huge")
        return self.make(self.rng.choice(self._kinds))

    def expected(self) -> Counter[str]:
        """The least count of each reason the refusals must show (kinds with a known reason)."""
        out: Counter[str] = Counter()
        for kind, n in self.sent.items():
            reason = KINDS[kind]
            if reason is not None:
                out[reason] += n
        return out


def udp_queue(port: int) -> tuple[int, int] | None:
    """The kernel's receive queue (bytes) and drop count of the (unconnected) UDP socket
    bound to 127.0.0.1:``port`` (``/proc/net/udp``), or None when there is none. The vehicle's
    controller gets a connected socket on the same port (Endpoint.prioritise): not that one."""
    want = f"0100007F:{port:04X}"
    row = udp_table_row(lambda cols: cols[1] == want and cols[2] == "00000000:0000")
    return (int(row[4].split(":")[1], 16), int(row[-1])) if row is not None else None


class Sender:
    """Sends datagrams to 127.0.0.1:``port`` from ``sources`` sockets in turn (each its own
    source address, so none exceeds the vehicle's per-source rate), pacing on the kernel's
    receive queue of the target so that nothing is dropped before the vehicle reads it."""

    def __init__(self, port: int, sources: int = 64, queue_bytes: int = 256 * 1024,
                 rate_hz: float | None = None) -> None:
        self.rate_hz = rate_hz  # datagrams/s at most, all sources together (None: as fast as read)
        self.dest = ("127.0.0.1", port)
        self.port = port
        self.queue_bytes = queue_bytes
        self.socks = []
        for _ in range(sources):
            s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            s.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 1 << 20)
            s.bind(("127.0.0.1", 0))
            self.socks.append(s)
        self.sent = 0

    def _room(self, need: int) -> bool:
        q = udp_queue(self.port)
        if q is None:
            raise AssertionError(f"nothing bound on 127.0.0.1:{self.port} any more")
        return q[0] + need <= self.queue_bytes or q[0] == 0

    def send(self, datagrams: Iterable[bytes], timeout: float = 30.0) -> None:
        """Send them all (paced), then return; fails if the receiver stops reading."""
        t0 = time.monotonic()
        for d in datagrams:
            if self.rate_hz and self.sent % 64 == 0:
                due = t0 + self.sent / self.rate_hz
                wait_for(lambda due=due: time.monotonic() >= due, timeout, "the rate's schedule", poll_s=0.0005)
            if self.sent % 64 == 0 or len(d) > 4096:
                wait_for(lambda d=d: self._room(2 * len(d) + 2048), timeout, "the vehicle reading its socket",
                         poll_s=0.001)
            self.socks[self.sent % len(self.socks)].sendto(d, self.dest)
            self.sent += 1

    def drained(self, timeout: float = 30.0) -> int:
        """Wait until the receiver has read everything; its kernel drop count."""
        wait_for(lambda: (udp_queue(self.port) or (0, 0))[0] == 0, timeout, "the vehicle draining its socket",
                 poll_s=0.001)
        q = udp_queue(self.port)
        return q[1] if q else 0

    def close(self) -> None:
        for s in self.socks:
            s.close()


# -- crash safety: what a run directory must look like whatever was killed, whenever ----------
MAVLOGDUMP = Path(sys.executable).with_name("mavlogdump.py")
PID = re.compile(r"started: (vehicle|controller|relay) pid (\d+)")


def check_trace(path: Path) -> int:
    """``path`` (a CSV with a header) is whole up to its last complete row: every line that
    ends in a newline has the header's number of fields, all numbers; only a last line
    without its newline (a write cut by SIGKILL) may be partial. Returns the complete rows."""
    data = path.read_bytes()
    lines = data.split(b"\n")
    header, *rows, tail = lines if len(lines) > 1 else [*lines, b""]
    width = len(header.split(b","))
    assert width > 1, f"{path}: no header"
    for i, line in enumerate(rows):
        fields = line.split(b",")
        assert len(fields) == width, f"{path}: row {i + 1} has {len(fields)} fields, not {width}"
        for f in fields:
            float(f)  # raises on a torn or garbled field
    assert len(tail) < len(header) + 64 * width, f"{path}: an impossibly long unfinished last line"
    return len(rows)


def check_half(path: Path) -> int:
    """``path`` (a trace half, bridge.record.halves) is whole up to its last complete record: its header parses,
    only a last record (a write cut by SIGKILL) may be short, and every record's step ``k`` is a whole number
    >= 0 (a record out of alignment would read as garbage). Returns the complete records."""
    half = read_half(path)
    k = half["k"]
    assert np.all((k >= 0) & (k == np.floor(k))), f"{path}: a record whose k is not a step number"
    head = path.read_bytes().index(b"\n") + 1
    assert (path.stat().st_size - head) // (8 * len(half)) == len(k)
    return len(k)


# pymavlink's mavlogdump.py run on each tlog named, in turn, in one process (its own script, as its command line
# runs it: ``runpy``): the start of Python and pymavlink (~0.25 CPU-s) paid once for a run's tlogs, not once each
_DUMP_EACH = """
import runpy, sys
script, mark, *logs = sys.argv[1:]
for log in logs:
    sys.argv = [script, log]
    runpy.run_path(script, run_name="__main__")
    print(mark, flush=True)
"""
_DUMPED = "-- mavlogdump done --"  # (no line of mavlogdump's: each starts with a time)


def check_tlogs(paths: list[Path]) -> list[int]:
    """Each of ``paths`` opens with pymavlink's ``mavlogdump.py`` (exit 0: each run in turn, in one process that
    stops at the first that fails); the messages it printed of each."""
    if not paths:
        return []
    r = run_script("-c", _DUMP_EACH, str(MAVLOGDUMP), _DUMPED, *map(str, paths), timeout=120,
                   env={**os.environ, "MAVLINK20": "1"})  # forked warm (tests/gcsfork.py)
    assert r.returncode == 0, f"mavlogdump {paths}: {r.stderr[-500:]}"
    *each, rest = r.stdout.split(_DUMPED + "\n")
    assert len(each) == len(paths) and rest == "", f"mavlogdump {paths}: {r.stdout[-500:]}"
    return [out.count("\n") for out in each]


def check_summary(path: Path) -> str | None:
    """``summary.json`` complete (valid JSON with its outcome) or absent: the outcome, or None."""
    if not path.exists():
        return None
    s = json.loads(path.read_text())
    assert s["outcome"] in ("completed", "failsafe", "diverged", "aborted") and "link" in s and "axes" in s
    return s["outcome"]


def check_run_dir(run: Path) -> dict[str, Any]:
    """Every file a SIGKILL may have cut, checked: the trace and its halves, tlogs, summary; no
    temporary file of an atomic write left beside a summary."""
    out: dict[str, Any] = {"summary": check_summary(run / "summary.json")}
    if (run / "trace.csv").exists():
        out["trace.csv"] = check_trace(run / "trace.csv")
    for name in ("vehicle.bin", "controller.bin"):
        if (run / name).exists():
            out[name] = check_half(run / name)
    tlogs = [name for name in ("vehicle.tlog", "controller.tlog") if (run / name).exists()]
    out.update(zip(tlogs, check_tlogs([run / name for name in tlogs]), strict=True))
    return out


def session_pids(run: Path) -> dict[str, int]:
    """The children's pids, as the launcher wrote them into ``events.log``."""
    try:
        return {k: int(v) for k, v in PID.findall((run / "events.log").read_text())}
    except FileNotFoundError:
        return {}


CRASH_MISSION = 'name = "crash"\nduration_s = 6.0\n[trajectory]\nkind = "sine"\n'
CRASH_STEPS = 1500
SPEED = "3"  # lockstep at most 3x real time: the 1500 steps take 2 s, so the kill lands mid-flight


def kill_session(tmp_path: Path, victim: str, at_step: int, key: str | None = None) -> tuple[int, dict[str, Any]]:
    """Fly ``bsst sitl`` and SIGKILL ``victim`` (vehicle, controller, launcher or all) once the
    vehicle has flown ``at_step`` steps; wait for every process to be gone; the launcher's
    exit status and what :func:`tests.hostile.check_run_dir` found."""
    mission = tmp_path / "crash.toml"
    mission.write_text(CRASH_MISSION)
    run = tmp_path / f"run-{victim}"
    with instance_slot() as n:
        p = Proc.bsst("sitl", str(mission), "--out", str(run), "--instance", str(n), "--speed", SPEED, "--no-plots",
                      *(["--key", key] if key else []))
        try:
            wait_for(lambda: count_records(run / "vehicle.bin") >= at_step or p.p.poll() is not None, 60,
                     f"{at_step} steps flown")
            assert p.p.poll() is None, "the session ended before the kill"
            pids = session_pids(run)
            assert set(pids) == {"vehicle", "controller"}, pids
            targets = {"launcher": [p.p.pid], "all": [p.p.pid, *pids.values()]}.get(victim) or [pids[victim]]
            for pid in targets:
                os.kill(pid, signal.SIGKILL)
            p.p.wait(timeout=60)  # a surviving launcher reports and ends by itself
            wait_for(lambda: all(gone(pid) for pid in pids.values()), 10, "both children gone")
        finally:
            p.stop()
    return p.p.returncode, check_run_dir(run)


def gone(pid: int) -> bool:
    """Whether process ``pid`` has exited (a zombie nobody reaped counts as gone)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] in ("Z", "X")
    except (FileNotFoundError, ProcessLookupError, IndexError):
        return True


# -- flood: another source at a multiple of the controller's rate, during a realtime flight ----
class Flood:
    """A thread sending ``rate_hz`` datagrams per second to 127.0.0.1:``port`` from one
    source, from a pool of ``pool`` hostile datagrams (targets from an impostor, NaN targets
    with the controller's ids, damaged frames, random bytes) or the ``datagrams`` given, on a
    drift-free schedule of bursts every ``burst_s``, until :meth:`stop`; it counts what it
    sent and what came back to it (``replies``, ``reply_bytes``)."""

    def __init__(self, port: int, rate_hz: float, sysid: int, seed: int = 3, pool: int = 2000,
                 burst_s: float = 0.002, datagrams: list[bytes] | None = None) -> None:
        if datagrams is None:
            fuzz = Fuzzer(seed, sysid, huge_every=0)
            kinds = ("sender", "not_finite", "bitflip", "random")
            datagrams = [fuzz.make(kinds[i % len(kinds)]) for i in range(pool)]
        self.pool = datagrams
        self.dest = ("127.0.0.1", port)
        self.rate_hz = rate_hz
        self.burst_s = burst_s
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 1 << 20)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.setblocking(False)
        self.sent = 0
        self.bytes_sent = 0
        self.replies = 0
        self.reply_bytes = 0
        self.elapsed_s = 0.0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def start(self) -> Flood:
        self._thread.start()
        return self

    def _run(self) -> None:
        t0 = time.monotonic()
        n = len(self.pool)
        while not self._stop.is_set():
            due = int((time.monotonic() - t0) * self.rate_hz)  # datagrams due by now: no drift
            while self.sent < due:
                d = self.pool[self.sent % n]
                try:
                    self.sock.sendto(d, self.dest)
                    self.bytes_sent += len(d)
                except OSError:  # nobody there (yet or any more: ICMP), or the send buffer is full
                    pass
                self.sent += 1
            self._take_replies()
            self._stop.wait(self.burst_s)
        self.elapsed_s = time.monotonic() - t0
        self._take_replies()

    def _take_replies(self) -> None:
        while True:
            try:
                data = self.sock.recv(65535)
            except BlockingIOError:
                return
            except OSError:  # an ICMP error reported on this socket
                continue
            self.replies += 1
            self.reply_bytes += len(data)

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=10)
        self.sock.close()


def packed_requests(sysid: int, frames: int = 40, src: tuple[int, int] = (255, 190),
                    message_id: int = mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION) -> bytes:
    """One datagram of ``frames`` valid REQUEST_MESSAGE frames (``message_id``, the longest
    answer the vehicle has) to system ``sysid`` from ``src``: a packed flood's datagram."""
    mav = mavlink.MAVLink(None, srcSystem=src[0], srcComponent=src[1])
    out = []
    for i in range(frames):
        mav.seq = i & 0xFF
        out.append(bytes(mavlink.MAVLink_command_long_message(sysid, 1, mavlink.MAV_CMD_REQUEST_MESSAGE, 0,
                                                               message_id, 0, 0, 0, 0, 0, 0).pack(mav)))
    return b"".join(out)


def deadline_misses(state_age_s: Any, rate_hz: float) -> float:
    """The share of control steps (after the first) whose command in force at the vehicle is
    not the answer to the previous step's state, i.e. the target answering state k had not
    arrived when step k + 1 began: ``state_age_s`` above 1.5 periods, or no command at all."""
    import numpy as np

    age = np.asarray(state_age_s, dtype=float)[1:]
    if not len(age):
        return 0.0
    return float(np.mean(~(age <= 1.5 / rate_hz)))


@contextlib.contextmanager
def session_thread(mission: Any, out: Path, **kw: Any) -> Iterator[tuple[int, threading.Thread, dict[str, Any]]]:
    """Fly :func:`bridge.session.sitl` (``mission`` into ``out``, ``kw``) in a thread on an
    instance of its own; yields (instance, thread, result); on leaving, waits for the flight
    and re-raises what it raised. ``result["run"]`` is the :class:`~bridge.record.runlog.Run`."""
    from bridge.session import sitl

    with instance_slot() as n:
        result: dict[str, Any] = {}

        def fly() -> None:
            try:
                result["run"] = sitl(mission, out=out, plots=False, instance=n, **kw)
            except BaseException as exc:  # re-raised below, in the caller's thread
                result["error"] = exc

        th = threading.Thread(target=fly)
        th.start()
        try:
            yield n, th, result
        finally:
            th.join(timeout=600)
    if "error" in result:
        raise result["error"]


def fly_flooded(mission: Any, out: Path, multiple: float, **kw: Any) -> tuple[Any, Flood | None]:
    """Fly ``mission`` as a real-time SITL session into ``out`` while another source floods the
    vehicle's controller link at ``multiple`` times the controller's message rate (none if 0)
    from the first step flown to the end; the :class:`~bridge.record.runlog.Run` and the flood."""
    from bridge.mavlink.endpoint import LINK_PORT

    flood = None
    with session_thread(mission, out, realtime=True, **kw) as (n, th, result):
        try:
            wait_for(lambda: count_records(out / "vehicle.bin") > 0 or not th.is_alive(), 60, "the flight starting",
                       poll_s=0.005)
            if multiple > 0 and th.is_alive():
                flood = Flood(LINK_PORT + n, multiple * mission.rate_hz, n + 1).start()
        finally:
            th.join(timeout=600)
            if flood is not None:
                flood.stop()
    return result["run"], flood


@dataclass
class Fuzzed:
    """What :func:`fly_fuzzed` saw: the run, the fuzzer (what it sent, by kind), the kernel's
    drops on the vehicle's socket, the steps flown when the last datagram had been read, the
    STATUSTEXTs the GCS port got, the burst's wall time and the vehicle's CPU time meanwhile."""

    run: Any
    fuzz: Fuzzer
    sent: int
    drops: int
    flown: int
    texts: list[str]
    elapsed_s: float
    vehicle_cpu_s: float


def fly_fuzzed(mission: Any, out: Path, datagrams: int, seed: int = 7, sources: int = 64,
               speed: float = 2.0, rate_hz: float | None = None, until_step: int | None = None) -> Fuzzed:
    """Fly ``mission`` lockstep (at most ``speed`` x real time) into ``out`` while
    ``datagrams`` hostile ones from :class:`Fuzzer` go, paced by :class:`Sender` from
    ``sources`` addresses (at most ``rate_hz`` per second), to the vehicle's controller link once it is past step
    :data:`MIN_STEP`, and (``until_step``) no more once it has flown that step: a burst a loaded machine slows ends
    inside the flight, fewer sent (:attr:`Fuzzed.sent`); a socket on the GCS port collects the vehicle's
    STATUSTEXTs."""
    from bridge.mavlink.endpoint import GCS_PORT, LINK_PORT

    gcs = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        with session_thread(mission, out, speed=speed) as (n, th, result):
            gcs.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 21)
            gcs.bind(("127.0.0.1", GCS_PORT + n))
            vhalf = out / "vehicle.bin"
            wait_for(lambda: count_records(vhalf) > MIN_STEP or not th.is_alive(), 60, "the fuzzed flight starting",
                       poll_s=0.01)
            pid = session_pids(out)["vehicle"]
            fuzz = Fuzzer(seed=seed, sysid=n + 1)
            sender = Sender(LINK_PORT + n, sources=sources, rate_hz=rate_hz)
            cpu0, t0 = _cpu_s(pid), time.monotonic()
            try:
                indices = range(datagrams) if until_step is None else itertools.takewhile(
                    lambda i: i % 1000 or count_records(vhalf) < until_step, range(datagrams))
                sender.send(fuzz.next(i) for i in indices)
                drops = sender.drained(timeout=120)
            finally:
                sender.close()
            elapsed, cpu = time.monotonic() - t0, _cpu_s(pid) - cpu0
            flown = count_records(vhalf)
        gcs.setblocking(False)
        texts = []
        mav = mavlink.MAVLink(None)
        while True:
            try:
                data = gcs.recv(65535)
            except BlockingIOError:
                break
            texts += [m.text for m in mav.parse_buffer(data) or [] if m.get_type() == "STATUSTEXT"]
    finally:
        gcs.close()
    return Fuzzed(result["run"], fuzz, sender.sent, drops, flown, texts, elapsed, cpu)


def _cpu_s(pid: int) -> float:
    """User + system CPU time of process ``pid`` so far (s); NaN once it has ended (the caller's own checks say why
    it ended too soon, not a missing file)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
    except FileNotFoundError:
        return math.nan
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


# -- a scripted MAVLink speaker: a ground station, a controller, a stranger ---------------------
class Station:
    """A MAVLink 2 speaker on a UDP socket of its own on 127.0.0.1 (``port`` 0: any free one):
    it sends pymavlink-packed messages with its ``ids`` (signed with ``key`` when given, link
    id ``link_id``) to ``dest`` (or, for a ground station bound on the GCS port, to wherever
    the vehicle's datagrams came from), and reads what comes back, with deadlines. Every
    message received is kept in :attr:`got` (type -> count) and :attr:`seen`."""

    def __init__(self, ids: tuple[int, int] = (255, 190), dest: tuple[str, int] | None = None, port: int = 0,
                 key: bytes | None = None, link_id: int = 0) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 21)
        self.sock.bind(("127.0.0.1", port))
        self.sock.setblocking(False)
        self.addr = self.sock.getsockname()
        self.dest = dest
        self.mav = mavlink.MAVLink(None, srcSystem=ids[0], srcComponent=ids[1])
        if key is not None:  # as pymavlink's setup_signing does
            self.mav.signing.secret_key = key
            self.mav.signing.sign_outgoing = True
            self.mav.signing.link_id = link_id
            self.mav.signing.timestamp = int((time.time() - 1420070400) * 100_000)
        self._dec = mavlink.MAVLink(None)  # decodes (a signed frame is taken without checking it)
        self.got: Counter[str] = Counter()
        self.first: Counter[str] = Counter()  # datagrams by the type of their first message (one answer each)
        self.seen: list[Any] = []  # every message received, in order
        self.datagrams = 0

    def frame(self, msg: Any) -> bytes:
        """``msg`` packed with this station's ids (and signature): the bytes :meth:`send` sends."""
        buf = bytes(msg.pack(self.mav))
        self.mav.seq = (self.mav.seq + 1) & 0xFF
        return buf

    def send(self, msg: Any) -> bytes:
        return self.send_raw(self.frame(msg))

    def send_raw(self, data: bytes) -> bytes:
        assert self.dest is not None, "nowhere to send yet: no datagram from the vehicle"
        self.sock.sendto(data, self.dest)
        return data

    def command(self, cmd: int, p1: float = 0.0, p2: float = 0.0, target: tuple[int, int] = (0, 0),
                as_int: bool = False) -> bytes:
        """COMMAND_LONG (or COMMAND_INT) ``cmd`` with param1, param2 (the rest 0)."""
        if as_int:
            return self.send(mavlink.MAVLink_command_int_message(*target, 0, cmd, 0, 0, p1, p2, 0, 0, 0, 0, 0))
        return self.send(mavlink.MAVLink_command_long_message(*target, cmd, 0, p1, p2, 0, 0, 0, 0, 0))

    def poll(self) -> list[Any]:
        """The messages waiting now (never blocks); a bound ground station learns its ``dest``."""
        out = []
        while True:
            try:
                data, addr = self.sock.recvfrom(65535)
            except BlockingIOError:
                return out
            except OSError:  # an ICMP error reported on this socket
                continue
            self.datagrams += 1
            if self.dest is None:
                self.dest = addr
            msgs = self._dec.parse_buffer(data) or []
            if msgs:
                self.first[msgs[0].get_type()] += 1
            for m in msgs:
                self.got[m.get_type()] += 1
                self.seen.append(m)
                out.append(m)

    def wait(self, pred: Callable[[Any], bool], timeout: float = 10.0, what: str = "a message") -> Any:
        """The first message from now on that satisfies ``pred``; fails naming ``what``."""
        deadline = time.monotonic() + timeout
        sel = selectors.DefaultSelector()
        sel.register(self.sock, selectors.EVENT_READ)
        try:
            while True:
                for m in self.poll():
                    if pred(m):
                        return m
                left = deadline - time.monotonic()
                if left <= 0:
                    raise AssertionError(f"{what}: not within {timeout} s (got {dict(self.got)})")
                sel.select(left)
        finally:
            sel.close()

    def ack(self, cmd: int, timeout: float = 10.0) -> int:
        """The result of the next COMMAND_ACK of ``cmd``."""
        m = self.wait(lambda m: m.get_type() == "COMMAND_ACK" and m.command == cmd, timeout, f"COMMAND_ACK {cmd}")
        return m.result

    def close(self) -> None:
        self.sock.close()
