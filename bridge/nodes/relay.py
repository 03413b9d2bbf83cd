"""A real-time UDP relay that applies the link model on the wall clock (``bsst relay``).

In:  UDP datagrams, whatever they hold: from the client on the listen port, from the target on the
     back socket; the ``[link]`` settings (delays ms, loss %, ``rate_bps`` bytes/s, blackouts s);
     optionally the client's address; optionally a fleet's one radio (its file, this vehicle's user number:
     :class:`bridge.link.radio.ProcessRadio`), whose queue each direction shares with the other vehicles' relays
Out: the same datagrams, unchanged, forwarded when the link model (on the wall clock, s) says they
     are due; :meth:`Relay.summary` (``relay.json``): per direction the model's statistics and
     ``measured_ms``, the delay really added (ms), plus counts, the client, what was refused by
     reason, and CPU time (s, us per packet), on a shared radio this vehicle's part of it (``radio``), each
     jitter the delay capped (``jitter_capped``, as ``summary.json["link"]``'s); with
     ``stats_path`` that summary kept on disk while serving (a snapshot at most every :data:`STATS_EVERY_S` s,
     ``"final": false``), written atomically

Topology (docs/design.md, "Link model")::

    controller ──► LISTEN (front socket) ══ up ══► back socket ──► TARGET (the vehicle)
    controller ◄── front socket ◄══ down ══ back socket ◄── vehicle

Datagrams that arrive on the listen port travel ``up`` (``listen_direction="down"`` swaps
the names) and leave from the back socket to the target; whatever the target sends back
to the back socket travels the other way, to the client. Each
direction has its own :class:`bridge.link.model.LinkImpairment`, driven with the seconds since
the relay started (so blackouts are in relay time; with ``mission_clock`` they are in the
flight's time instead: t = 0 is when the vehicle sent the state the first actuator target that
arrives on the listen side answers, as ``bsst sitl --realtime`` counts mission time: the arrival of
the ``ODOMETRY`` with the target's ``time_usec``, or, if the relay never saw that state, the
target's arrival less the down link's configured delay). Datagrams pass unchanged; the relay
stamps each one on arrival — with the kernel's receive time stamp (``SO_TIMESTAMPNS``) on
Linux, so that the relay's own wake-up latency counts — and measures, when it hands it to
the kernel to forward it, the delay it really added (scheduled delay + the relay's own
latency), next to the model's statistics.

**Two ends only** (docs/hostile-input.md). The relay forwards between its two configured
ends and nobody else: the vehicle side is exactly the ``target`` address (only datagrams
from it go back), the controller side is the ``client`` given, or else the first address
that sends to the listen port, learned once and never re-learned. Anything else is refused
before the link model sees it (so it draws no fate and the seeded run stays the same) and
counted by reason: ``stranger_front`` (to the listen port, not from the client),
``stranger_back`` (to the back socket, not from the target).

**Records that survive a kill.** With ``stats_path`` the statistics are on disk all along: the serving loop
copies its counters (microseconds) at most every :data:`STATS_EVERY_S` s and a writer thread turns the copy
into ``relay.json`` under a temporary name and renames it, as ``summary.json`` is written. A SIGKILL at any
moment leaves the last whole snapshot (``"final": false``); the relay's own last word (``"final": true``) is
its owner's to write once :meth:`Relay.serve` has returned (:meth:`Relay.summary`).
"""

from __future__ import annotations

import math
import os
import resource
import select
import socket
import struct
import sys
import threading
import time
from array import array
from collections.abc import Callable
from pathlib import Path
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

from bridge.core.clock import Stalls
from bridge.link.impairment import LinkStats
from bridge.link.model import LinkImpairment, LinkSettings
from bridge.link.radio import ProcessRadio
from bridge.mavlink.endpoint import parse_address as endpoint_address
from bridge.mavlink.kerneldrops import socket_drops
from bridge.nodes.relaystats import RelayCounters, SnapshotWriter
from bridge.nodes.report import Event, Ready
from params import ConfigError

Address = tuple[str, int]
MAX_DATAGRAM = 65_535
_SO_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", 35)  # Linux: kernel receive time, CLOCK_REALTIME
_TIMESPEC = struct.Struct("qq")
_ANC_SIZE = socket.CMSG_SPACE(_TIMESPEC.size)
MAX_READS = 256  # datagrams read from one socket per wake-up: a flood cannot hold up what is due
REFUSAL_REASONS = ("stranger_front", "stranger_back")  # see the module docstring, "Two ends only"
STATS_EVERY_S = 0.5  # s between snapshots of the statistics on disk (stats_path): what a kill can lose at most
# actuator targets (docs/design.md, "The MAVLink contract"): the first one up marks the flight's time 0
_TARGET_IDS = frozenset((mavlink.MAVLINK_MSG_ID_HIL_ACTUATOR_CONTROLS,
                         mavlink.MAVLINK_MSG_ID_SET_ACTUATOR_CONTROL_TARGET))
_STATE_IDS = frozenset((mavlink.MAVLINK_MSG_ID_ODOMETRY,))  # the vehicle's state: its stamp is what a target answers
STATES_KEPT = 4096  # states' arrivals kept while the flight's time 0 is not known (16 s at 250 Hz)


def parse_address(text: str, flag: str, bind: bool = False) -> Address:
    """``HOST:PORT`` -> (host, port) with :func:`bridge.mavlink.endpoint.parse_address`'s checks (a
    known host, a port in range: 0, any free one, only to ``bind``); a :class:`~params.ConfigError` whose ``source``
    is ``flag`` and the text as given (``--to 'nowhere'``), ``what`` the reason, as every flag's refusal. (Until the
    forty-fifth session a plain ValueError: its ``bad_input`` report had no source.)"""
    mode = "udpin" if bind else "udpout"
    a = endpoint_address(text, mode, flag)  # (its refusals typed: ConfigError.at)
    if a.mode != mode:
        raise ConfigError.at(f"{flag} {text!r}", None, f"the relay {'binds' if bind else 'sends to'} it ({mode}), "
                             f"not {a.mode}")
    return a.host, a.port


def forwards_to_itself(listen: Address, target: Address) -> bool:
    """Whether ``--to`` ``target`` is the relay's own ``--listen`` socket: the same port on the same host, or on a
    loopback address when it listens on every address (0.0.0.0); another machine's host at that port is not."""
    at, to = numeric(listen)[0], numeric(target)[0]
    return target[1] == listen[1] and (to == at or at == "0.0.0.0" and to.startswith("127."))


def numeric(addr: Address) -> Address:
    """(host, port) with the host as its IPv4 dotted quad, the form ``recvfrom`` reports a
    sender in (so that ``localhost:14560`` is the address datagrams from 127.0.0.1:14560 come from)."""
    return socket.getaddrinfo(addr[0], addr[1], socket.AF_INET, socket.SOCK_DGRAM)[0][4][:2]


def hostport(addr: Address | None) -> str | None:
    """``HOST:PORT``, or None."""
    return None if addr is None else f"{addr[0]}:{addr[1]}"


class Relay:
    """Forward UDP both ways between a client and ``target``, through the link model.

    Bind happens in the constructor (``address`` tells the port when 0 was asked for);
    :meth:`serve` runs until :meth:`stop` (from any thread or a signal handler) or
    ``duration_s``; :meth:`start` runs it in a daemon thread. ``client`` fixes the controller
    side's address; without it the first sender to the listen port is the client, for good
    (``on_client`` is then called with its address, once, from the serving thread).
    ``back_port`` is the local port the back socket sends to ``target`` from (0: any free one).
    """

    def __init__(self, listen: Address, target: Address, link: LinkSettings | None = None, *,
                 listen_direction: str = "up", clock: Callable[[], float] = time.perf_counter,
                 mission_clock: bool = False, client: Address | None = None,
                 on_client: Callable[[Address], None] | None = None, back_port: int = 0,
                 stats_path: str | Path | None = None, radio: tuple[str | Path, int] | None = None) -> None:
        if stats_path is not None and (not str(stats_path) or Path(stats_path).is_dir()):  # checked before a socket
            raise ValueError(f"stats_path {str(stats_path)!r}: expected a file to write, not a directory")
        link = link or LinkSettings()
        self.jitter_capped = link.jitter_capped()  # each jitter the delay capped: in its summary (docs/links.md)
        self.mission_clock = mission_clock
        self.origin_s: float | None = None  # relay time (s) of the flight's time 0 (mission_clock)
        self.stalls = Stalls()  # packets handed on more than STALL_S after they were due, from time 0
        self.states_seen: dict[int, float] = {}  # until the origin: a state's time_usec -> relay time of its arrival
        # a fleet's one radio (real time): (its file, this vehicle's user number), each direction's queue shared
        self.radios = {d: ProcessRadio(radio[0], d, cfg.rate_bps, cfg.queue_ms / 1000.0, radio[1])
                       for d, cfg in (("up", link.up), ("down", link.down))} if radio is not None else {}
        up, down = link.make((self.radios["up"], self.radios["down"]), radio[1]) if radio else link.make()
        self.front_link, self.back_link = (up, down) if listen_direction == "up" else (down, up)
        self.links = {"up": up, "down": down}
        if mission_clock:  # no blackout before the flight's time 0 is known
            for lk in self.links.values():
                lk.shift_blackouts(math.inf)
        self.target = numeric(target)
        given = numeric(client) if client is not None else None
        self.clock = clock
        self.front = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.back = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self.front.bind(listen)
            self.back.bind((listen[0], back_port))  # 0: any free port
        except OSError:
            self.close()
            raise
        self.kernel_stamps = sys.platform.startswith("linux")
        for s in (self.front, self.back):
            s.setblocking(False)
            s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
            if self.kernel_stamps:
                try:
                    s.setsockopt(socket.SOL_SOCKET, _SO_TIMESTAMPNS, 1)
                except OSError:
                    self.kernel_stamps = False
        self.client: Address | None = given
        self.client_given = given is not None
        self.on_client = on_client
        self.refused = dict.fromkeys(REFUSAL_REASONS, 0)  # datagrams from neither end, by reason
        self.added = {"up": array("d"), "down": array("d")}  # s, measured arrival -> forward
        self.dropped_no_client = 0
        self.send_errors = 0
        self._wake_r, self._wake_w = os.pipe()
        os.set_blocking(self._wake_w, False)
        self._stopping = False
        self.t0 = clock()
        for r in self.radios.values():  # a shared radio counts on the monotonic clock every process reads
            r.offset = self.t0
        self.cpu_user_s = 0.0  # CPU time of the serving process while serving (all its threads)
        self.cpu_sys_s = 0.0
        self.forwarded = 0
        self._thread: threading.Thread | None = None
        self._snapshots = SnapshotWriter(Path(stats_path)) if stats_path is not None else None
        self._drops: dict[str, int | None] | None = None  # the kernel's drops on each socket, kept at close

    @property
    def address(self) -> Address:
        """Where the client should send (the bound listen address)."""
        return self.front.getsockname()

    @property
    def back_address(self) -> Address:
        """The address the target sees the relay's datagrams come from."""
        return self.back.getsockname()

    def ready(self, settings: LinkSettings) -> Ready:
        """The ready report (:mod:`bridge.nodes.report`) of a relay bound and about to serve ``settings``."""
        (h, p), (bh, bp) = self.address, self.back_address
        client = f"{self.client[0]}:{self.client[1]}" if self.client_given and self.client else None
        return Ready("relay", listen=f"{h}:{p}", to=f"{self.target[0]}:{self.target[1]}", back=f"{bh}:{bp}",
                     client=client, up=settings.up.describe(), down=settings.down.describe())

    def stop(self) -> None:
        """Ask :meth:`serve` to return (safe from signal handlers and other threads)."""
        self._stopping = True
        try:
            os.write(self._wake_w, b"x")
        except OSError:
            pass

    def start(self) -> threading.Thread:
        """Serve in a daemon thread; :meth:`stop` then ``join`` it."""
        self._thread = threading.Thread(target=self.serve, name="bsst-relay", daemon=True)
        self._thread.start()
        return self._thread

    def _receive(self, sock: socket.socket, link: LinkImpairment, from_front: bool) -> None:
        clock = self.clock
        t0 = self.t0
        stamps = self.kernel_stamps
        for _ in range(MAX_READS):
            try:
                if stamps:
                    data, anc, _, addr = sock.recvmsg(MAX_DATAGRAM, _ANC_SIZE)
                else:
                    data, addr = sock.recvfrom(MAX_DATAGRAM)
                    anc = ()
            except (BlockingIOError, InterruptedError):
                return
            except OSError:  # e.g. ICMP port unreachable reported on the next recv
                continue
            if from_front:
                if self.client is None:
                    self._learn_client(addr)
                elif addr != self.client:
                    self.refused["stranger_front"] += 1
                    continue
            elif addr != self.target:
                self.refused["stranger_back"] += 1
                continue
            # the wall clock read before ours: were we preempted between the two, the arrival comes out
            # later than it was, never earlier (read after, it made a datagram leave up to 0.5 ms early)
            wall_ns = time.time_ns() if anc else 0
            now = clock()
            for level, kind, raw in anc:  # the kernel's arrival stamp: count our wake-up latency too
                if level == socket.SOL_SOCKET and kind == _SO_TIMESTAMPNS and len(raw) >= 16:
                    sec, nsec = _TIMESPEC.unpack_from(raw)
                    lag = (wall_ns - sec * 1_000_000_000 - nsec) * 1e-9
                    if 0.0 < lag < 1.0:
                        now -= lag
            if self.mission_clock and self.origin_s is None:
                self._look_for_origin(data, from_front, now - t0)
            link.send(now - t0, len(data), (data, now))

    def _learn_client(self, addr: Address) -> None:
        """The first sender to the listen port is the controller side, for good."""
        self.client = addr
        if self.on_client is not None:
            self.on_client(addr)

    def _look_for_origin(self, data: bytes, from_front: bool, t: float) -> None:
        """Before the flight's time 0 is known: keep when each state came from the vehicle (relay time t, s), and
        at the first actuator target from the controller put time 0 where the state it answers came, as the
        vehicle's own timeline does. A target answering a state the relay did not see (not from this flight)
        puts it at its own arrival less the down link's configured delay: a first answer held up (a loaded
        machine's controller) would put it late by that much, and every blackout with it."""
        if not from_front:
            stamp = _stamp(data, _STATE_IDS)
            if stamp is not None:
                if len(self.states_seen) >= STATES_KEPT:
                    self.states_seen.pop(next(iter(self.states_seen)))
                self.states_seen.setdefault(stamp, t)
            return
        stamp = _stamp(data, _TARGET_IDS)
        if stamp is None:
            return
        sent = self.states_seen.get(stamp)
        self._set_origin(sent if sent is not None else t - self.links["down"].cfg.delay_ms / 1000.0)
        self.states_seen.clear()

    def _set_origin(self, t: float) -> None:
        """The flight's time 0 is at relay time t (s): the blackouts count from there."""
        self.origin_s = t
        for link in self.links.values():
            link.shift_blackouts(t)

    def _forward(self, now: float) -> None:
        t = now - self.t0
        for link, sock, to_front in ((self.front_link, self.back, False), (self.back_link, self.front, True)):
            due = link.deliver(t)
            if not due:
                continue
            added = self.added[link.direction]
            for d in due:
                if self.origin_s is not None:  # a packet handed on late: the machine stalled us (flight time, s)
                    self.stalls.note(d.due_t - self.origin_s, t - d.due_t)
                data, arrived = d.payload
                dest = self.client if to_front else self.target
                if dest is None:
                    self.dropped_no_client += 1
                    continue
                added.append(self.clock() - arrived)  # handed to the kernel now
                try:
                    sock.sendto(data, dest)
                except OSError:
                    self.send_errors += 1
                    added.pop()
                    continue
                self.forwarded += 1

    def serve(self, duration_s: float | None = None) -> None:
        """Relay until :meth:`stop` or for ``duration_s`` seconds."""
        cpu0 = resource.getrusage(resource.RUSAGE_SELF)
        clock = self.clock
        end = None if duration_s is None else clock() + duration_s
        rlist = [self.front, self.back, self._wake_r]
        front, back = self.front, self.back
        snapshots = self._snapshots
        next_snapshot = clock()
        try:
            while not self._stopping:
                now = clock()
                if end is not None and now >= end:
                    break
                nxt = [x for x in (self.front_link.next_due(), self.back_link.next_due()) if x is not None]
                timeout = 1.0
                if nxt:
                    timeout = max(0.0, min(nxt) + self.t0 - now)
                if end is not None:
                    timeout = min(timeout, max(0.0, end - now))
                ready, _, _ = select.select(rlist, [], [], timeout)
                if ready:
                    if front in ready:
                        self._receive(front, self.front_link, True)
                    if back in ready:
                        self._receive(back, self.back_link, False)
                    if self._wake_r in ready:
                        os.read(self._wake_r, 64)
                now = clock()
                self._forward(now)
                if snapshots is not None and now >= next_snapshot:
                    snapshots.put(self._counters(cpu0))
                    next_snapshot = now + STATS_EVERY_S
        finally:
            cpu1 = resource.getrusage(resource.RUSAGE_SELF)
            self.cpu_user_s += cpu1.ru_utime - cpu0.ru_utime
            self.cpu_sys_s += cpu1.ru_stime - cpu0.ru_stime
            if snapshots is not None:
                snapshots.put(self._counters(None))  # whatever is killed from now on, this much is kept
                snapshots.close()

    def _counters(self, cpu0: Any) -> RelayCounters:
        """A copy of everything :meth:`summary` reads (microseconds: the delay arrays are copied whole), with
        the CPU time since ``cpu0`` added when serving (None: the totals kept)."""
        user, system = self.cpu_user_s, self.cpu_sys_s
        if cpu0 is not None:
            now = resource.getrusage(resource.RUSAGE_SELF)
            user, system = user + now.ru_utime - cpu0.ru_utime, system + now.ru_stime - cpu0.ru_stime
        stats = {}
        for d, link in self.links.items():
            st = LinkStats()
            st.__dict__.update(link.stats.__dict__)
            st.delays, st.lost_by = array("d", link.stats.delays), dict(link.stats.lost_by)
            stats[d] = st
        drops = self._drops if self._drops is not None else self._socket_drops()
        fixed = {"origin_s": self.origin_s, "client": hostport(self.client), "kernel_drops": drops,
                 "client_from": "given" if self.client_given else "first sender", "target": hostport(self.target),
                 "refused": dict(self.refused), "forwarded": self.forwarded,
                 "dropped_no_client": self.dropped_no_client, "send_errors": self.send_errors,
                 "stalls": self.stalls.report(), **({"jitter_capped": cap} if (cap := self.jitter_capped) else {})}
        if self.radios:  # this vehicle's part of the fleet's one radio, by direction
            fixed["radio"] = {d: r.part() for d, r in self.radios.items()}
        return RelayCounters(stats, {d: array("d", a) for d, a in self.added.items()}, fixed, user, system)

    def summary(self) -> dict[str, Any]:
        """Per direction: the model's statistics (``delay_ms`` = scheduled one-way delay) and
        ``measured_ms``, the delay the relay really added, arrival to forward; plus CPU time
        (user and system, s; meaningful per packet when the relay has its own process); ``final``: true
        (a snapshot written while serving says false)."""
        return self._counters(None).summary(final=True)

    def _socket_drops(self) -> dict[str, int | None]:
        """Datagrams the kernel dropped on each socket before the relay read them, by the direction they travel
        (:func:`bridge.mavlink.kerneldrops.socket_drops`; None where it does not say)."""
        front, back = socket_drops(self.front), socket_drops(self.back)
        return {self.front_link.direction: front, self.back_link.direction: back}

    def close(self) -> None:
        if getattr(self, "_drops", True) is None and self.front.fileno() >= 0 and self.back.fileno() >= 0:
            self._drops = self._socket_drops()  # (not when a bind failed, before it is set)
        for s in (self.front, self.back):
            s.close()
        for r in getattr(self, "radios", {}).values():
            r.close()
        for fd in (getattr(self, "_wake_r", -1), getattr(self, "_wake_w", -1)):
            if fd >= 0:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self._wake_r = self._wake_w = -1

    def __enter__(self) -> Relay:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        self.close()


def client_event(addr: Address, listen_direction: str = "up") -> Event:
    """The event report of a client learned: the first sender to the listen port, the controller side (its
    datagrams travel up), or with ``listen_direction`` down the vehicle side (its datagrams travel down)."""
    side = "controller" if listen_direction == "up" else "vehicle"
    return Event(0.0, "client", f"{addr[0]}:{addr[1]} is the {side} side (the first sender to --listen, its "
                                f"datagrams travel {listen_direction}); any other sender is refused")


def _stamp(data: bytes, ids: frozenset[int]) -> int | None:
    """The ``time_usec`` of a datagram that starts with a MAVLink 2 frame of one of ``ids`` (each has it first
    in its payload), or None; a payload MAVLink 2 truncated is zero-padded."""
    if len(data) < 10 or data[0] != 0xFD or (data[7] | data[8] << 8 | data[9] << 16) not in ids:
        return None
    return int.from_bytes(data[10:min(18, 10 + data[1])], "little")
