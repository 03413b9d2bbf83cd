"""Covers bridge.mavlink.endpoint, bridge.mavlink.frames and bridge.mavlink.tlog.

bridge.mavlink.endpoint: addresses, the hot-path codec against pymavlink, real UDP, tlogs."""

from __future__ import annotations

import math
import os
import select
import socket
import subprocess
import sys
import time

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from bridge.mavlink.endpoint import (
    HIL_ACTUATOR_CONTROLS,
    ODOMETRY,
    SET_ACTUATOR_CONTROL_TARGET,
    Endpoint,
    Spinner,
    Tlog,
    hot_frame,
    parse_address,
    sweep,
    wait,
)
from bridge.mavlink.receive import RateLimiter, ReplyBudget
from bridge.mavlink.signing import Signing
from bridge.mavlink.spinner import CORES, runnable_tasks
from params import ConfigError
from tests.hostile import packed_requests, udp_queue
from tests.sitlkit import run_script
from tests.waiting import wait_for

pytestmark = pytest.mark.process  # starts processes or opens sockets: not in make test-fast

f32 = st.floats(width=32, allow_nan=False, allow_infinity=False)


def _pair(tmp_path, tlog_a: bool = True):
    """Two endpoints on 127.0.0.1: ``a`` bound to a free port, ``b`` sending to it."""
    ta = Tlog(tmp_path / "a.tlog") if tlog_a else None
    tb = Tlog(tmp_path / "b.tlog")
    a = Endpoint(parse_address("udpin:127.0.0.1:0"), sysid=1, compid=1, tlog=ta)
    b = Endpoint(parse_address(f"udpout:127.0.0.1:{a.local[1]}"), sysid=200, compid=191, tlog=tb)
    return a, b, ta, tb


def _recv(ep: Endpoint, n: int = 1, timeout: float = 5.0) -> list:
    out: list = []
    deadline = time.monotonic() + timeout
    while len(out) < n and time.monotonic() < deadline:
        out += [m for _, m, _a in wait((ep,), deadline)]
    assert len(out) >= n, f"got {len(out)} of {n} messages"
    return out


@pytest.mark.parametrize("text, mode, host, port", [
    ("udpin:127.0.0.1:14560", "udpin", "127.0.0.1", 14560),
    ("udpout:127.0.0.1:14550", "udpout", "127.0.0.1", 14550),
    ("udp:0.0.0.0:14550", "udpin", "0.0.0.0", 14550),
    ("udpin://127.0.0.1:0", "udpin", "127.0.0.1", 0),
    ("localhost:14551", "udpout", "localhost", 14551),
])
def test_parse_address(text, mode, host, port):
    a = parse_address(text)
    assert (a.mode, a.host, a.port) == (mode, host, port)


@pytest.mark.parametrize("text", ["14550", "udpin:127.0.0.1", "127.0.0.1:port", "udpout:127.0.0.1:0",
                                  "127.0.0.1:70000", "no.such.host.invalid:1"])
def test_parse_address_rejects(text):
    with pytest.raises(ConfigError, match="--gcs"):
        parse_address(text, flag="--gcs")


def test_bind_conflict_is_bad_input():
    a = Endpoint(parse_address("udpin:127.0.0.1:0"), sysid=1, compid=1)
    try:
        with pytest.raises(ConfigError, match="cannot bind"):
            Endpoint(parse_address(f"udpin:127.0.0.1:{a.local[1]}"), sysid=1, compid=1, name="--listen")
    finally:
        a.close()


def _odo_values(t, pos, q, vel, rates):
    cov = (math.nan,) + (0.0,) * 20
    return (t, *pos, *q, *vel, *rates, *cov, *cov, 1, 12, 0, 1, 100)


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**63), st.tuples(f32, f32, f32), st.tuples(f32, f32, f32, f32), st.tuples(f32, f32, f32),
       st.tuples(f32, f32, f32))
def test_hot_odometry_matches_pymavlink(t, pos, q, vel, rates):
    """send_hot's frame is what pymavlink would make; pymavlink's frame decodes alike on the hot path."""
    mav = mavlink.MAVLink(None, srcSystem=7, srcComponent=1)
    msg = mavlink.MAVLink_odometry_message(t, 1, 12, *pos, list(q), *vel, *rates, [math.nan] + [0.0] * 20,
                                           [math.nan] + [0.0] * 20, 0, 1, 100)
    ref = msg.pack(mav)
    hot = hot_frame(ref)
    assert hot is not None and hot._type == "ODOMETRY" and hot.get_srcSystem() == 7
    assert (hot.time_usec, hot.x, hot.y, hot.z, hot.q, hot.vx, hot.rollspeed) == (
        t, pos[0], pos[1], pos[2], q, vel[0], rates[0])
    ours = _frame(ODOMETRY, _odo_values(t, pos, q, vel, rates), sysid=7, compid=1)
    assert ours == ref


def _frame(layout, values, sysid=200, compid=191):
    """The bytes send_hot puts on the wire (captured through a real socket pair)."""
    rx = Endpoint(parse_address("udpin:127.0.0.1:0"), sysid=1, compid=1)
    tx = Endpoint(parse_address(f"udpout:127.0.0.1:{rx.local[1]}"), sysid=sysid, compid=compid)
    try:
        tx.send_hot(layout, values)
        rx.sock.settimeout(5.0)  # a blocking receive with a deadline
        data, _ = rx.sock.recvfrom(65535)
        return data
    finally:
        rx.close()
        tx.close()


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**63), st.lists(f32, min_size=16, max_size=16), st.integers(0, 255), st.integers(0, 2**63))
def test_hot_actuator_messages_match_pymavlink(t, controls, mode, flags):
    mav = mavlink.MAVLink(None, srcSystem=200, srcComponent=191)
    ref = mavlink.MAVLink_hil_actuator_controls_message(t, controls, mode, flags).pack(mav)
    assert _frame(HIL_ACTUATOR_CONTROLS, (t, flags, *controls, mode)) == ref
    hot = hot_frame(ref)
    assert (hot.time_usec, list(hot.controls), hot.mode, hot.flags) == (t, controls, mode, flags)
    ref = mavlink.MAVLink_set_actuator_control_target_message(t, 0, 7, 1, controls[:8]).pack(mav)
    assert _frame(SET_ACTUATOR_CONTROL_TARGET, (t, *controls[:8], 0, 7, 1)) == ref
    hot = hot_frame(ref)
    assert (hot.group_mlx, hot.target_system, list(hot.controls)) == (0, 7, controls[:8])


def test_hot_path_refuses_what_it_cannot_check():
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    good = mavlink.MAVLink_hil_actuator_controls_message(5, [0.5] * 16, 0, 1).pack(mav)
    assert hot_frame(good) is not None
    bad_crc = good[:-1] + bytes([good[-1] ^ 0xFF])
    assert hot_frame(bad_crc) is None
    assert hot_frame(good + good) is None  # two frames in one datagram: parse_buffer's job
    hb = mavlink.MAVLink_heartbeat_message(2, 0, 0, 0, 3, 3).pack(mav)
    assert hot_frame(hb) is None


def test_udp_exchange_peer_and_bad_data(tmp_path):
    a, b, ta, tb = _pair(tmp_path)
    try:
        assert a.peer is None
        b.send(mavlink.MAVLink_heartbeat_message(18, 8, 0, 0, 4, 3))
        b.send_hot(HIL_ACTUATOR_CONTROLS, (42, 1, *([0.25] * 16), 128))
        got = _recv(a, 2)
        assert [m.get_type() for m in got] == ["HEARTBEAT", "HIL_ACTUATOR_CONTROLS"]
        assert got[1].time_usec == 42 and got[1].controls[0] == 0.25
        assert a.peer == b.local  # udpin answers whoever sent
        a.send(mavlink.MAVLink_timesync_message(0, 7))
        (ts,) = _recv(b)
        assert ts.get_type() == "TIMESYNC" and ts.ts1 == 7 and ts.get_srcSystem() == 1
        b.sock.sendto(b"\xfd\x09garbage that is not a frame", a.local)
        b.send(mavlink.MAVLink_heartbeat_message(18, 8, 0, 0, 4, 3))
        (hb,) = _recv(a)
        assert hb.get_type() == "HEARTBEAT" and a.bad >= 1
    finally:
        for ep in (a, b):
            ep.close()
        ta.close()
        tb.close()


def test_a_spinner_polls_while_the_machine_has_a_core_to_spare_and_sleeps_at_once_when_busy(tmp_path):
    """The machine's runnable tasks are read from /proc/loadavg (this process among them). With more CPU-bound
    tasks than cores, the spinner looks within SPIN_LOOK_S, finds the machine busy and skips its poll even with
    an answer waiting (``skipped`` counts it); wait() then takes the answer from its sleep."""
    assert 1 <= runnable_tasks()
    a, b, ta, tb = _pair(tmp_path, tlog_a=False)
    spinner = Spinner(a, 0.02)
    hogs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(CORES + 1)]
    try:
        wait_for(lambda: spinner.spin(time.monotonic() + 0.001) == [] and spinner.skipped, 10.0,
                 "a wait skipped for a busy machine")
        b.send(mavlink.MAVLink_heartbeat_message(18, 8, 0, 0, 4, 3))
        wait_for(lambda: select.select([a.sock], [], [], 0.1)[0], 5.0, "the heartbeat in the socket")
        skipped = spinner.skipped
        assert spinner.spin(time.monotonic() + 1.0) == [] and spinner.skipped == skipped + 1  # not polled
        assert [m.get_type() for _, m, _a in wait((a,), time.monotonic() + 5.0, spinner)] == ["HEARTBEAT"]
    finally:
        for h in hogs:
            h.kill()
            h.wait()
        a.close()
        b.close()
        tb.close()


def test_a_spinner_takes_an_answer_within_its_window(tmp_path):
    """However busy the machine, a spinner given an answer takes it: by its poll on a machine with a core to
    spare, else by wait()'s sleep; a spinner with no window never polls."""
    a, b, ta, tb = _pair(tmp_path, tlog_a=False)
    try:
        b.send(mavlink.MAVLink_heartbeat_message(18, 8, 0, 0, 4, 3))
        wait_for(lambda: select.select([a.sock], [], [], 0.1)[0], 5.0, "the heartbeat in the socket")
        assert Spinner(a, 0.0).spin(time.monotonic() + 1.0) == []  # no window: not polled, though it waits
        got = wait((a,), time.monotonic() + 5.0, Spinner(a, 0.05))
        assert [m.get_type() for _, m, _a in got] == ["HEARTBEAT"]
    finally:
        a.close()
        b.close()
        tb.close()


def test_wait_honours_its_deadline(tmp_path):
    a, b, ta, tb = _pair(tmp_path, tlog_a=False)
    try:
        t0 = time.monotonic()
        assert wait((a,), t0 + 0.05, Spinner(a, 0.01)) == []
        assert 0.045 <= time.monotonic() - t0 < 1.0
    finally:
        a.close()
        b.close()
        tb.close()


class _ReachedWhileSwept(Endpoint):
    """A ground station's link reached by the sweep just after its controller's answer and its own HOLD came,
    in that order, both after the sweep had read the controller's link: the moment a loaded machine can choose."""

    def __init__(self, *args, before: list, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.before = before

    def poll(self, until=None):
        while self.before:
            self.before.pop(0)()
        return super().poll(until)


def test_a_controllers_answer_sent_before_a_ground_stations_command_is_read_first():
    """:func:`wait` reads the first endpoint (the controller's link) again when a later one (the ground station's)
    yields, and hands out what reached the first meanwhile first. It read the HOLD alone, and the vehicle refused
    the answer the HOLD came after as ``not_offboard`` (the CI's test_vehicle, once)."""
    link = Endpoint(parse_address("udpin:127.0.0.1:0"), sysid=1, compid=1, priority=True)
    ctl = Endpoint(parse_address(f"udpout:127.0.0.1:{link.local[1]}"), sysid=200, compid=191)
    events: list = []
    gcs = _ReachedWhileSwept(parse_address("udpin:127.0.0.1:0"), sysid=1, compid=1, before=events)
    ground = Endpoint(parse_address(f"udpout:127.0.0.1:{gcs.local[1]}"), sysid=255, compid=190)
    try:
        ctl.send(mavlink.MAVLink_heartbeat_message(18, 8, 0, 0, 4, 3))
        got = [m for _, m, _a in wait((link,), time.monotonic() + 5.0)]
        link.peer = ctl.local
        link.prioritise(ctl.local)  # as a vehicle does on its controller's first word
        assert [m.get_type() for m in got] == ["HEARTBEAT"]
        answer = mavlink.MAVLink_set_actuator_control_target_message(20000, 0, 1, 1, [0.0] * 8)
        hold = mavlink.MAVLink_command_long_message(1, 1, 176, 0, 1, 4, 3, 0, 0, 0, 0)
        events += [lambda: ctl.send(answer), lambda: ground.send(hold)]
        got = wait((link, gcs), time.monotonic() + 5.0)
        assert [(ep is link, m.get_type()) for ep, m, _a in got] == [
            (True, "SET_ACTUATOR_CONTROL_TARGET"), (False, "COMMAND_LONG")]
        assert sweep((link, gcs)) == []
    finally:
        for ep in (link, ctl, gcs, ground):
            ep.close()


def test_tlog_holds_both_directions_and_mavlogdump_reads_it(tmp_path):
    a, b, ta, tb = _pair(tmp_path)
    try:
        b.send(mavlink.MAVLink_heartbeat_message(18, 8, 0, 0, 4, 3))
        _recv(a)
        a.send_hot(ODOMETRY, _odo_values(4000, (1.0, 2.0, -3.0), (1.0, 0.0, 0.0, 0.0), (0.1, 0.2, 0.3),
                                         (0.0, 0.0, 0.0)))
        _recv(b)
        b.send_hot(SET_ACTUATOR_CONTROL_TARGET, (4000, 0.1, 0.2, 0.3, 0.4, 0, 0, 0, 0, 0, 1, 1))
        _recv(a)
    finally:
        for ep in (a, b):
            ep.close()
        ta.close()
        tb.close()
    os.environ["MAVLINK20"] = "1"
    types = []
    log = mavutil.mavlink_connection(str(tmp_path / "a.tlog"))
    while (m := log.recv_match()) is not None:
        types.append(m.get_type())
        assert 0 < m._timestamp - time.time() + 60 < 120  # a wall-clock stamp of just now
    assert types == ["HEARTBEAT", "ODOMETRY", "SET_ACTUATOR_CONTROL_TARGET"]  # received, sent, received
    dump = run_script(os.path.join(os.path.dirname(sys.executable), "mavlogdump.py"), str(tmp_path / "b.tlog"),
                      timeout=60, env={**os.environ, "MAVLINK20": "1"})
    assert dump.returncode == 0, dump.stderr
    assert "ODOMETRY" in dump.stdout and "SET_ACTUATOR_CONTROL_TARGET" in dump.stdout and "HEARTBEAT" in dump.stdout


def test_the_peer_gets_a_socket_of_its_own():
    """With priority, the peer's datagrams come on a socket connected to it (SO_REUSEPORT):
    read first, ahead of any backlog of others', and the only one wait() sleeps on; a second
    endpoint still cannot take the port."""
    a = Endpoint(parse_address("udpin:127.0.0.1:0"), sysid=1, compid=1, priority=True)
    a.follow = False
    ctl = Endpoint(parse_address(f"udpout:127.0.0.1:{a.local[1]}"), sysid=200, compid=191)
    other = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    other.bind(("127.0.0.1", 0))
    try:
        with pytest.raises(ConfigError, match="cannot bind"):
            Endpoint(parse_address(f"udpin:127.0.0.1:{a.local[1]}"), sysid=1, compid=1, priority=True)
        a.peer = ctl.local
        a.prioritise(ctl.local)
        assert a.prio is not None and a.wake_socket is a.prio
        for _ in range(200):
            other.sendto(b"\x00junk", a.local)
        ctl.send(mavlink.MAVLink_heartbeat_message(18, 8, 0, 0, 4, 3))
        wait_for(lambda: (udp_queue(a.local[1]) or (0, 0))[0] > 0, 5.0, "datagrams queued", poll_s=0.001)
        got = a.poll()
        assert got and got[0][0].get_type() == "HEARTBEAT" and got[0][1] == ctl.local  # ahead of the backlog
        while a.backlog:
            a.poll()
        assert a.rejected == {"no_frame": 200}
        # others' datagrams do not wake a wait: it sleeps on the peer's socket to its deadline
        other.sendto(b"\x00junk", a.local)
        t0 = time.monotonic()
        assert wait((a,), t0 + 0.05) == [] and time.monotonic() - t0 >= 0.045
        ctl.send(mavlink.MAVLink_heartbeat_message(18, 8, 0, 0, 4, 3))
        got = [m for _, m, _a in wait((a,), time.monotonic() + 5.0)]
        assert [m.get_type() for m in got] == ["HEARTBEAT"]
        for _ in range(4):  # the others' socket is read at one poll in four while it looked empty
            a.poll()
        assert a.rejected == {"no_frame": 201}
    finally:
        a.close()
        ctl.close()
        other.close()


def test_what_the_peer_sent_before_its_socket_opened_is_read_first_and_in_order():
    """The peer's datagrams already queued on the main socket when :meth:`Endpoint.prioritise` opens the peer's
    own are older than anything that socket gets: they come out first, in order. Signed, out of order they were
    refused as replayed (the CI's ``test_signed_session_flies_and_never_writes_the_key``: ``{'replayed': 1}``)."""
    key = bytes(range(32))
    a = Endpoint(parse_address("udpin:127.0.0.1:0"), sysid=1, compid=1, priority=True, batch=1,
                 signing=Signing(key))
    a.follow = False
    ctl = Endpoint(parse_address(f"udpout:127.0.0.1:{a.local[1]}"), sysid=200, compid=191, signing=Signing(key))
    try:
        def ping(n: int) -> None:
            ctl.send(mavlink.MAVLink_ping_message(n, n, 0, 0))

        for n in range(3):
            ping(n)
        wait_for(lambda: (udp_queue(a.local[1]) or (0, 0))[0] >= 3, 5.0, "three datagrams queued", poll_s=0.001)
        got = [m.seq for m, _a in a.poll()]  # one datagram a poll: the first only
        a.peer = ctl.local
        a.prioritise(ctl.local)
        assert a.prio is not None
        for n in range(3, 5):
            ping(n)

        def all_in() -> bool:
            got.extend(m.seq for m, _a in a.poll())
            return len(got) >= 5

        wait_for(all_in, 5.0, "the five pings", poll_s=0.001)
        assert got == [0, 1, 2, 3, 4] and a.rejected.total == 0, (got, dict(a.rejected))
    finally:
        a.close()
        ctl.close()


def _take(ep: Endpoint, n_refused: int) -> list:
    """What ``ep`` makes of the datagrams sent to it, once ``n_refused`` refusals are counted
    or a message is in."""
    got: list = []

    def done() -> bool:
        got.extend(m for m, _a in ep.poll())
        return bool(got) or ep.rejected.total >= n_refused

    wait_for(done, 5.0, "the endpoint reading its datagram", poll_s=0.001)
    return got


def test_budgets_count_frames_and_bytes_not_only_datagrams():
    """A source other than the peer pays for every frame and every byte (issue 11): of a
    datagram packing 40 frames, only its frame budget is decoded and the rest is refused
    (``rate_limited``, once); the next such datagram is over its byte budget and dropped
    unparsed; the peer pays nothing."""
    a = Endpoint(parse_address("udpin:127.0.0.1:0"), sysid=1, compid=1,
                 limiter=RateLimiter(source_hz=10, others_hz=1000, source_bytes_s=2000, others_bytes_s=1e6))
    a.follow = False
    other, peer = socket.socket(socket.AF_INET, socket.SOCK_DGRAM), socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    packed = packed_requests(1, 40)
    assert 1600 < len(packed) <= 2000  # one fits the byte budget, two do not
    try:
        for s in (other, peer):
            s.bind(("127.0.0.1", 0))
        a.peer = peer.getsockname()
        other.sendto(packed, a.local)
        assert len(_take(a, 1)) == 10 and a.rejected == {"rate_limited": 1}
        other.sendto(packed, a.local)
        assert _take(a, 2) == [] and a.rejected == {"rate_limited": 2}
        peer.sendto(packed, a.local)
        assert len(_take(a, 3)) == 40 and a.rejected == {"rate_limited": 2}
    finally:
        a.close()
        other.close()
        peer.close()


def test_replies_are_one_datagram_within_the_sources_budget(tmp_path):
    """:meth:`Endpoint.reply`: a COMMAND_ACK and what was asked for go in one datagram (each
    frame its own tlog record), at most the reply budget's worth to a source; the exempt peer
    is not charged."""
    tlog = Tlog(tmp_path / "a.tlog")
    a = Endpoint(parse_address("udpin:127.0.0.1:0"), sysid=1, compid=1, tlog=tlog, replies=ReplyBudget(5, 1e5))
    a.follow = False
    other, peer = socket.socket(socket.AF_INET, socket.SOCK_DGRAM), socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        for s in (other, peer):
            s.bind(("127.0.0.1", 0))
            s.settimeout(5.0)
        a.peer = peer.getsockname()
        answer = (mavlink.MAVLink_command_ack_message(512, 0, 0, 0, 255, 190),
                  mavlink.MAVLink_heartbeat_message(2, 0, 0, 0, 3, 3))
        sent = [a.reply(answer, other.getsockname()) for _ in range(20)]
        assert sent[:5] == [True] * 5 and sent.count(True) <= 6  # 5 a second (a refill while it ran at most)
        msgs = mavlink.MAVLink(None).parse_buffer(other.recv(65535))
        assert [m.get_type() for m in msgs] == ["COMMAND_ACK", "HEARTBEAT"]
        assert all(a.reply(answer, peer.getsockname()) for _ in range(20))
    finally:
        a.close()
        other.close()
        peer.close()
        tlog.close()
    log = mavutil.mavlink_connection(str(tmp_path / "a.tlog"))
    types = []
    while (m := log.recv_match()) is not None:
        types.append(m.get_type())
    assert types == ["COMMAND_ACK", "HEARTBEAT"] * (sent.count(True) + 20)
