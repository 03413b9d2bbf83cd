"""MAVLink 2 over UDP: an endpoint that owns its socket, and how it waits.

In:  UDP datagrams of MAVLink 2 frames; an address (``udpin:`` / ``udpout:`` HOST:PORT), the
     endpoint's sysid and compid, an optional signing key
Out: checked, decoded messages with their senders' addresses (pymavlink messages, or a
     :class:`~bridge.mavlink.frames.HotMessage` for ODOMETRY and the two actuator targets); encoded
     frames sent to the peer; refusals counted by reason; every frame recorded in a
     :class:`~bridge.mavlink.tlog.Tlog`

An :class:`Endpoint` is one UDP socket and one pymavlink ``MAVLink`` object (its own
sequence numbers: one per link, as MAVLink wants). It encodes with pymavlink and decodes
whole datagrams with ``parse_buffer``; it never uses ``recv_match``, whose per-message
bookkeeping and polling ``select`` are the slow path. Every frame it sends or receives is
appended to a :class:`~bridge.mavlink.tlog.Tlog`.

Addresses follow pymavlink's connection strings (docs/design.md, "The MAVLink contract"):

- ``udpin:HOST:PORT``  bind HOST:PORT and answer whoever sent last (port 0: any free port);
- ``udpout:HOST:PORT`` send to HOST:PORT from a free local port, answer on it;
- ``HOST:PORT``        either, as the option that takes it says.

Receiving is the project's one receive path (:mod:`bridge.mavlink.receive`): :meth:`Endpoint.poll`
reads a bounded batch, sheds excess from sources other than the peer, and
:func:`~bridge.mavlink.frames.parse_datagram` takes whole MAVLink 2 frames only, checked (CRC, length, known id,
and with a key their signature: :mod:`bridge.mavlink.signing`) before anything is decoded;
everything refused is counted by reason in the endpoint's :class:`bridge.mavlink.receive.Rejections`.

The two messages of every control step (ODOMETRY down, the actuator target up) take a
hot path (:class:`~bridge.mavlink.frames.HotLayout`): framed and checked with ``struct`` and the CRC directly from
pymavlink's own message metadata (field order, ``crc_extra``), signed and verified by
:class:`bridge.mavlink.signing.Signing`, without building a pymavlink message object; every other
frame is decoded by pymavlink's ``decode`` once it has passed the same checks. Both paths
give the same fields and bytes (tests/test_endpoint.py, tests/test_signing.py).

Waiting is :func:`wait`: with a :class:`Spinner` it first polls the hot socket for a short while (a reply
that comes within tens of microseconds is taken without a sleep and wake-up, which costs more than the poll
on loopback), then blocks in ``select`` on every socket until the deadline. The spinner polls only while no
runnable task waits for a core (on an oversubscribed machine the poll takes CPU from the peer it waits for,
or from other work).
"""

from __future__ import annotations

import select
import socket
import struct
import time
from collections.abc import Callable, Sequence
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

# the codec and the tlog live in their own modules; their names are re-exported here, where the nodes,
# the tests and the benchmarks import them with the endpoint
from bridge.mavlink.address import (  # noqa: F401 - re-exported: the nodes import them with the endpoint
    CONTROLLER_COMPID,
    CONTROLLER_SYSID,
    GCS_PORT,
    LINK_PORT,
    VEHICLE_COMPID,
    Address,
    check_free,
    parse_address,
)
from bridge.mavlink.frames import (  # noqa: F401 - re-exported
    HEADER2,
    HIL_ACTUATOR_CONTROLS,
    HOT,
    MAGIC2,
    ODOMETRY,
    SET_ACTUATOR_CONTROL_TARGET,
    HotLayout,
    HotMessage,
    hot_frame,
    parse_datagram,
)
from bridge.mavlink.kerneldrops import socket_drops
from bridge.mavlink.receive import (
    BATCH,
    FORCE_DISARM,  # noqa: F401 - re-exported: the controller imports it from here
    RateLimiter,
    Rejections,
    ReplyBudget,
    ReplyCredit,
)
from bridge.mavlink.signing import IFLAG_SIGNED, Signing
from bridge.mavlink.signing import crc16 as _crc16
from bridge.mavlink.spinner import Spinner  # noqa: F401 - re-exported with wait
from bridge.mavlink.tlog import Tlog
from params import ConfigError

_MAX_DATAGRAM = 65535
EARLY_READS = 64  # batches of the main socket read when the peer's own opens (64 x BATCH datagrams at most)


class Endpoint:
    """One MAVLink 2 UDP link: its socket, its ``MAVLink`` codec, its counters.

    ``peer`` is where :meth:`send` goes: fixed for ``udpout`` (which then hears nobody
    else); for ``udpin`` the sender of the last valid frame (pymavlink's behaviour) while
    ``follow`` is true, else whoever its owner sets (the vehicle: its configured controller,
    once it has spoken). With ``signing`` every frame sent is signed and every frame
    received must be. ``rejected`` counts what the receive path refused (shared by the
    endpoints of one process); ``batch`` and ``limiter`` bound what one :meth:`poll` reads
    and what sources other than the peer may send in datagrams, frames and bytes
    (:mod:`bridge.mavlink.receive`). With ``exempt_peer`` false (the vehicle's GCS link:
    a ground station is not the flight's controller) the peer is charged like anyone and
    its refusals are not counted as the peer's. :meth:`reply` answers a source within its
    :class:`ReplyBudget` (:attr:`replies`), one datagram per request.

    With ``priority`` (a ``udpin`` link whose owner sets its peer), :meth:`prioritise` gives
    the peer's datagrams a socket of their own: a second socket bound to the same port
    (``SO_REUSEPORT``) and connected to the peer, which the kernel hands every datagram of
    that address to. :func:`wait` then sleeps on that socket only: a flood from anyone else
    queues on the main socket, never wakes the owner, and is read (bounded, shed) whenever
    it wakes for its own duties; when the main queue overflows, the kernel drops the
    others' datagrams, never the peer's.
    """

    def __init__(self, address: Address, *, sysid: int, compid: int, tlog: Tlog | None = None,
                 name: str = "link", rcvbuf: int = 1 << 20, signing: Signing | None = None,
                 rejected: Rejections | None = None, batch: int = BATCH, limiter: RateLimiter | None = None,
                 priority: bool = False, exempt_peer: bool = True, replies: ReplyBudget | None = None,
                 source_port: int = 0) -> None:
        self.address = address
        self.name = name
        self.tlog = tlog
        self.signing = signing
        self.rejected = rejected if rejected is not None else Rejections()
        self.batch = batch
        self.limiter = limiter or RateLimiter()
        self.exempt_peer = exempt_peer
        self.replies = replies or ReplyBudget()
        self.trial: ReplyCredit | None = None  # set: the peer is on trial, its replies charged (its owner says)
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf)
            if address.mode == "udpin":
                if priority:
                    check_free(address)  # SO_REUSEPORT must not let a second vehicle share the port
                    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT, 1)
                sock.bind((address.host, address.port))
                self.peer: tuple[str, int] | None = None
                self.follow = True
            else:
                # bind on the interface that reaches the peer: loopback stays loopback
                local = "127.0.0.1" if address.host.startswith("127.") or address.host == "localhost" else ""
                sock.bind((local, source_port))  # udpout: the port it sends from (0: any free one)
                self.peer = (socket.gethostbyname(address.host), address.port)
                self.follow = False
        except OSError as exc:
            sock.close()
            what = f"--source-port {source_port}" if source_port and address.mode == "udpout" else f"{name} {address}"
            raise ConfigError.at(what, None, f"cannot bind ({exc.strerror})") from None
        sock.setblocking(False)
        self.sock = sock
        self.fileno = sock.fileno()
        self.local = sock.getsockname()
        # encodes (unsigned: self.signing signs) and decodes what the frame stage passed; no key of its own
        self.mav = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)
        self.sent = 0
        self.received = 0
        self.send_errors = 0
        self._priority = priority and address.mode == "udpin"
        self._rcvbuf = rcvbuf
        self.prio: socket.socket | None = None  # the peer's own socket (see the class docstring)
        self.prio_peer: tuple[str, int] | None = None
        self.backlog = False  # the last poll left datagrams on the main socket
        self._early: list[tuple[Any, tuple[str, int]]] = []  # read off the main socket when the peer's opened
        self._turn = 0  # polls since the main socket was read (with a peer socket)
        self._dropped_before = 0  # the kernel's drops on sockets of this endpoint already closed
        self._dropped_at_close: int | None = None

    def prioritise(self, addr: tuple[str, int]) -> None:
        """Give the datagrams of ``addr`` (the peer) their own socket, if this endpoint was made
        with ``priority``; another address replaces the last one. Without it (an error, or no
        ``SO_REUSEPORT``), everything keeps coming on the main socket."""
        if not self._priority or addr == self.prio_peer or self.fileno < 0:
            return
        self._close_prio()
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, self._rcvbuf)
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT, 1)
            s.bind(self.local)
            s.connect(addr)
        except OSError:
            s.close()
            return
        s.setblocking(False)
        self.prio, self.prio_peer = s, addr
        # what the peer sent before now waits on the main socket, older than anything its own socket gets: read it
        # now, in the order it came, and hand it out first (a signed stream's timestamps are checked in that order:
        # read after newer ones, these frames were refused as replayed, one session in some hundreds under load)
        for _ in range(EARLY_READS):
            if not self._read(self.sock, self._early, None, False):
                break

    def forget_peer(self) -> None:
        """No peer any more (its own socket closed): the owner learns the next one."""
        self.peer = None
        self._close_prio()

    def _close_prio(self) -> None:
        if self.prio is not None:
            self._dropped_before += socket_drops(self.prio) or 0
            self.prio.close()
            self.prio = self.prio_peer = None

    @property
    def wake_socket(self) -> socket.socket:
        """The socket :func:`wait` sleeps on: the peer's own one when there is one."""
        return self.prio if self.prio is not None else self.sock

    @property
    def bad(self) -> int:
        """Datagrams and messages refused so far (all reasons)."""
        return self.rejected.total

    # -- sending ------------------------------------------------------------------------
    def send(self, msg: Any, to: tuple[str, int] | None = None) -> bool:
        """Encode ``msg`` (a pymavlink message) and send it to ``to`` or the peer.

        Returns False when there is nowhere to send yet or the send failed (UDP: a lost
        datagram, counted in ``send_errors``; nothing is raised).
        """
        return self.send_frame(self.pack(msg), to)

    def pack(self, msg: Any) -> bytes:
        """The frame of a pymavlink message (next sequence number; signed with a key)."""
        mav = self.mav
        buf = msg.pack(mav)
        mav.seq = (mav.seq + 1) & 0xFF
        return self.signing.resign(buf) if self.signing is not None else bytes(buf)

    def send_many(self, msgs: Sequence[Any], to: tuple[str, int] | None = None) -> bool:
        """Send ``msgs`` as the frames of one datagram (a ground station parses every frame of
        a datagram) to ``to`` or the peer; False as :meth:`send_frame`."""
        return self.send_frames([self.pack(m) for m in msgs], to)

    def reply_allowed(self, to: tuple[str, int]) -> bool:
        """Whether a reply to ``to`` is within its budget now (the exempt peer: always, unless on :attr:`trial`:
        then within its reply budget and the trial's credit too)."""
        peer = self.exempt_peer and to == self.peer
        trial = self.trial if peer else None
        if peer and trial is None:
            return True
        return (trial is None or trial.bytes > 0) and self.replies.allows(to, time.monotonic())

    def reply(self, msgs: Sequence[Any], to: tuple[str, int]) -> bool:
        """Answer one request from ``to``: ``msgs`` in one datagram, charged to its reply
        budget (the exempt peer is not charged, unless on :attr:`trial`: then to the trial's
        credit too); False when nothing was sent."""
        if not msgs:
            return False
        frames = [self.pack(m) for m in msgs]
        peer = self.exempt_peer and to == self.peer
        trial = self.trial if peer else None
        if not peer or trial is not None:
            nbytes = sum(map(len, frames))
            if (trial is not None and trial.bytes < nbytes) or not self.replies.charge(to, time.monotonic(), nbytes):
                if trial is not None:
                    trial.cut += 1
                return False
        return self.send_frames(frames, to)

    def send_hot(self, layout: HotLayout, values: tuple[Any, ...], to: tuple[str, int] | None = None) -> bool:
        """Encode a hot-path message from its flat field values (see :class:`HotLayout`) and
        send it: the same bytes pymavlink would make, without a message object."""
        return self.send_frame(self.encode_hot(layout, values), to)

    def send_payload(self, layout: HotLayout, payload: bytes, to: tuple[str, int] | None = None) -> bool:
        """:meth:`send_hot` of values already packed (``layout.struct``'s bytes, trailing zeros and all)."""
        return self.send_frame(self.encode_payload(layout, payload), to)

    def encode_hot(self, layout: HotLayout, values: tuple[Any, ...]) -> bytes:
        """The frame of a hot-path message (next sequence number; signed with a key)."""
        return self.encode_payload(layout, layout.struct.pack(*values))

    def encode_payload(self, layout: HotLayout, packed: bytes) -> bytes:
        """:meth:`encode_hot` of values already packed by ``layout.struct``."""
        mav = self.mav
        signing = self.signing
        payload = packed.rstrip(b"\0") or b"\0"  # MAVLink 2 drops trailing zeros
        head = HEADER2.pack(MAGIC2, len(payload), 0 if signing is None else IFLAG_SIGNED, 0, mav.seq,
                             mav.srcSystem, mav.srcComponent, layout.id & 0xFFFF, layout.id >> 16)
        body = head + payload
        buf = body + struct.pack("<H", _crc16(body[1:] + layout.crc_extra, 0xFFFF))
        if signing is not None:
            buf = signing.sign(buf)
        mav.seq = (mav.seq + 1) & 0xFF
        return buf

    def send_frames(self, frames: Sequence[bytes], to: tuple[str, int] | None = None) -> bool:
        """Send already-encoded frames in one datagram; each recorded in the tlog (a record is
        one frame). False as :meth:`send_frame`."""
        if len(frames) <= 1:
            return bool(frames) and self.send_frame(frames[0], to)
        if self.tlog is not None and (to or self.peer) is not None:
            for f in frames[:-1]:
                self.tlog.record(f)
        return self._send_datagram(b"".join(frames), to, frames[-1])

    def send_frame(self, buf: bytes, to: tuple[str, int] | None = None) -> bool:
        """Send one already-encoded frame; recorded in the tlog when it has somewhere to go.
        Returns False when there is nowhere to send yet or the send failed (UDP: a lost
        datagram, counted in ``send_errors``; nothing is raised)."""
        return self._send_datagram(buf, to, buf)

    def _send_datagram(self, buf: bytes, to: tuple[str, int] | None, last: bytes) -> bool:
        dest = to or self.peer
        if dest is None:
            return False
        trial = self.trial  # on trial, every datagram to the peer is charged to its credit (ReplyCredit)
        if trial is not None and dest == self.peer and not trial.charge(len(buf)):
            return False
        tlog = self.tlog
        # stamped as it is handed to the kernel, recorded once it is gone (off the peer's critical path): a stamp
        # taken after sendto is late by however long a loaded machine kept this process off the CPU, and a
        # TIMESYNC exchange with a late-stamped request has the shortest round trip (link extract picks it)
        stamp = time.time_ns() // 1000 if tlog is not None else 0
        try:
            self.sock.sendto(buf, dest)
        except OSError:  # e.g. ECONNREFUSED from an earlier ICMP, ENOBUFS
            self.send_errors += 1
            sent = False
        else:
            self.sent += 1
            sent = True
        if tlog is not None:
            tlog.record(last, stamp)
        return sent

    # -- receiving ----------------------------------------------------------------------
    def poll(self, until: float | None = None) -> list[tuple[Any, tuple[str, int]]]:
        """The valid messages among the next :attr:`batch` datagrams waiting (the peer's own
        socket first, if any: see :meth:`prioritise`), with their senders; never blocks,
        never raises (the receive path of :mod:`bridge.mavlink.receive`: read, shed, frame; what it
        refuses is counted in :attr:`rejected`). With ``until`` (``time.monotonic``), it also
        stops reading the main socket once that time has come (looked at every 8 datagrams),
        so that a backlog never delays its caller's next duty past it; :attr:`backlog` then
        says that datagrams may be left."""
        if self._early:  # read when the peer's socket opened: older than anything on it
            out, self._early = self._early, []
            return out
        out: list[tuple[Any, tuple[str, int]]] = []
        if self.prio is not None:
            self._read(self.prio, out, None, True)
            self._turn = (self._turn + 1) & 3
            if out or (self._turn and not self.backlog):
                # the peer's first; the others' socket at a later poll (at one in four when it
                # was empty: a caller spinning for its peer's answer pays one system call, not two)
                self.backlog = self.backlog or bool(out)
                return out
        self.backlog = self._read(self.sock, out, until, False)
        return out

    def _read(self, sock: socket.socket, out: list[tuple[Any, tuple[str, int]]], until: float | None,
              own: bool) -> bool:
        """Read at most :attr:`batch` datagrams of ``sock`` into ``out`` (``own``: the peer's
        socket); True when it stopped with datagrams possibly left."""
        signing = self.signing
        rejected = self.rejected
        sending = self.address.mode == "udpout"
        limiter = self.limiter
        exempt_peer = self.exempt_peer
        for i in range(self.batch):
            if until is not None and i & 7 == 7 and time.monotonic() >= until:
                return True
            try:
                data, addr = sock.recvfrom(_MAX_DATAGRAM)
            except (BlockingIOError, InterruptedError):
                return False
            except OSError:  # ICMP port unreachable reported on a later recv
                continue
            heard = own or addr == self.peer
            if not heard and sending:  # a sending link hears its peer only
                rejected.add("sender")
                continue
            from_peer = heard and exempt_peer  # never charged; its refusals counted as the peer's
            if not from_peer and not limiter.admit(addr, time.monotonic(), len(data)):
                rejected.add("rate_limited")
                continue
            budget = None if from_peer else limiter.frame  # others pay for every frame
            hot = hot_frame(data)
            if hot is not None and budget is not None:
                if not budget():
                    rejected.add("rate_limited")
                    continue
                budget = None  # its one frame is paid for
            if hot is not None and (signing is None or signing.verify(data, data[5], data[6]) is None):
                self.received += 1  # (a step's message: one frame, the whole datagram)
                if self.tlog is not None:
                    self.tlog.record(data)
                out.append((hot, addr))
            else:  # everything else, and a hot frame whose signature failed (to name the reason)
                msgs = parse_datagram(data, self.mav, signing, rejected, from_peer, budget)
                if not msgs:
                    continue
                self.received += len(msgs)
                if self.tlog is not None:
                    for m in msgs:
                        self.tlog.record(m.get_msgbuf())
                out.extend((m, addr) for m in msgs)
            if self.follow:
                self.peer = addr
        return True

    def queued(self) -> bool:
        """Whether a datagram waits to be read on any of its sockets now (never blocks; False once closed)."""
        if self.fileno < 0:
            return False
        socks = [self.sock] if self.prio is None else [self.sock, self.prio]
        return bool(self._early) or bool(select.select(socks, [], [], 0)[0])

    def drain(self, handle: Callable[[Any, tuple[str, int]], None], batches: int = 64) -> float:
        """Read what is already queued (each message and its source address to ``handle``), bounded by ``batches``
        polls (a flood still queued is left), never blocking; the ``time.monotonic`` just before the look that found
        the socket empty: a datagram queued before it was read, one sent after it never was (on one host the
        sender's clock too: ``summary.json``'s link counts, docs/sitl.md)."""
        t = time.monotonic()
        for _ in range(batches):
            t = time.monotonic()
            if not self.queued():
                break
            for m, addr in self.poll():
                handle(m, addr)
        return t

    def kernel_drops(self) -> int | None:
        """Datagrams the kernel dropped before this endpoint could read them (its receive buffer full), all its
        sockets so far (:func:`socket_drops`; kept at :meth:`close`); None where the kernel does not say."""
        if self.fileno < 0:
            return self._dropped_at_close
        now = socket_drops(self.sock)
        prio = socket_drops(self.prio) if self.prio is not None else 0
        return None if now is None or prio is None else self._dropped_before + now + prio

    def close(self) -> None:
        if self.fileno >= 0:
            self._dropped_at_close = self.kernel_drops()
            self._close_prio()
            self.sock.close()
            self.fileno = -1


def wait(endpoints: Sequence[Endpoint], deadline: float,
         spinner: Spinner | None = None) -> list[tuple[Endpoint, Any, tuple[str, int]]]:
    """Messages from any endpoint, waiting at most until ``deadline`` (``time.monotonic``).

    With a ``spinner``, its endpoint is polled without sleeping first (:meth:`Spinner.spin`): on loopback the
    answer to a message often arrives within its window, and a sleeping process pays a scheduler wake-up (tens
    of microseconds) to receive it.
    """
    mono = time.monotonic
    if spinner is not None:
        got = spinner.spin(deadline)
        if got:
            ep = spinner.endpoint
            return [(ep, m, a) for m, a in got]
    while True:
        out = sweep(endpoints, deadline)
        if out:
            return out
        left = deadline - mono()
        if left <= 0.0:
            return out
        if any(ep.backlog for ep in endpoints):
            continue  # more waiting on a main socket: read on (each poll stops at the deadline)
        try:  # an endpoint with a peer socket sleeps on it only (Endpoint.prioritise)
            select.select([ep.wake_socket for ep in endpoints], [], [], left)
        except InterruptedError:
            pass


def sweep(endpoints: Sequence[Endpoint], deadline: float | None = None) -> list[tuple[Endpoint, Any, tuple[str, int]]]:
    """One poll of every endpoint (:meth:`Endpoint.poll`), the messages of an earlier one first. When a later one
    yields, the earlier ones are polled again, and what reached them meanwhile goes first: two datagrams on two
    sockets have no order the reader can see, and the first endpoint is the one a step waits on (a controller's
    answer sent before a ground station's HOLD was read after it, when the sweep passed the controller's link just
    before the answer came, and was refused as ``not_offboard``)."""
    out: list[tuple[Endpoint, Any, tuple[str, int]]] = []
    for i, ep in enumerate(endpoints):
        got = ep.poll(deadline)
        if got and i:
            for earlier in endpoints[:i]:
                out.extend((earlier, m, a) for m, a in earlier.poll(deadline))
        out.extend((ep, m, a) for m, a in got)
    return out
