"""Covers bridge.nodes.relay.

The relay forwards only between its two ends (issue 11, finding 3): real ``bsst relay``
processes and a real ``bsst sitl --realtime --delay 20`` flight, real UDP on 127.0.0.1, real
pymavlink frames from a stranger.

Ordering is what tells "not forwarded" without sleeping: with no impairment the relay
forwards in the order it reads, so a stranger's datagram read before the next one of an end
would arrive before it; once that next one is in, the stranger's is known to be refused.
"""

from __future__ import annotations

import json
import re
import socket
from pathlib import Path

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from bridge.core.wire import state_to_odometry
from bridge.nodes.report import Event, Ready, parse_line
from bridge.record.halves import count_records
from missions import Mission, Sine
from tests.hostile import session_thread
from tests.sitlkit import Proc, controller_exit_text
from tests.test_relay import udp
from tests.waiting import wait_for

pytestmark = pytest.mark.process  # starts processes or opens sockets: not in make test-fast

FAR_FUTURE_USEC = 10**12  # 11.6 days: the controller would call its mission flown at once


def nothing_queued(sock: socket.socket) -> bool:
    """Whether no datagram is waiting on ``sock`` (read without blocking)."""
    sock.setblocking(False)
    try:
        sock.recv(2048)
    except BlockingIOError:
        return True
    finally:
        sock.settimeout(2.0)
    return False


def start_relay(target: socket.socket, tmp: Path, *extra: str) -> tuple[Proc, tuple[str, int], tuple[str, int]]:
    """``bsst relay`` to ``target``: the process, its listen (front) and back addresses."""
    relay = Proc.bsst("relay", "--listen", "127.0.0.1:0", "--to", f"127.0.0.1:{target.getsockname()[1]}",
                      "--stats", str(tmp / "relay.json"), *extra)
    ready = parse_line(relay.wait_line(lambda line: isinstance(parse_line(line), Ready)))
    assert isinstance(ready, Ready) and ready.listen and ready.back
    return relay, _address(ready.listen), _address(ready.back)


def _address(text: str) -> tuple[str, int]:
    host, _, port = text.rpartition(":")
    return host, int(port)


def test_a_stranger_after_the_controller_is_refused_both_ways(tmp_path: Path) -> None:
    """The first sender to the front port is the client for good: a stranger sending there
    afterwards is not forwarded and does not take the vehicle's datagrams; a stranger on the
    back port is not forwarded to the client; both are counted, printed and in relay.json."""
    client, vehicle, stranger, stranger_back = udp(), udp(), udp(), udp()
    me = f"127.0.0.1:{client.getsockname()[1]}"
    relay, front, back = start_relay(vehicle, tmp_path)
    try:
        client.sendto(b"c0", front)
        data, seen_from = vehicle.recvfrom(2048)
        assert data == b"c0" and seen_from == back
        stranger.sendto(b"s0", front)  # read before c1: forwarded, it would arrive first
        client.sendto(b"c1", front)
        assert vehicle.recv(2048) == b"c1"
        assert nothing_queued(vehicle), "the stranger's datagram went to the vehicle"
        vehicle.sendto(b"v0", back)
        assert client.recv(2048) == b"v0", "the vehicle's datagram did not go to the client"
        assert nothing_queued(stranger)
        stranger_back.sendto(b"x0", back)  # read before v1 on the back socket
        vehicle.sendto(b"v1", back)
        assert client.recv(2048) == b"v1"
        assert nothing_queued(client), "the stranger's datagram on the back port went to the client"
        assert relay.stop() == 0
    finally:
        relay.stop()
        for s in (client, vehicle, stranger, stranger_back):
            s.close()
    out = "\n".join(relay.lines)
    stats = json.loads((tmp_path / "relay.json").read_text())
    assert stats["refused"] == {"stranger_front": 1, "stranger_back": 1}
    assert stats["client"] == me and stats["client_from"] == "first sender"
    assert "refused 2: stranger_front 1, stranger_back 1" in out
    learned = [r for r in map(parse_line, relay.lines) if isinstance(r, Event) and r.kind == "client"]
    assert [(e.t, e.text.partition(" ")[0]) for e in learned] == [(0.0, me)], out
    assert stats["up"]["sent"] == 2 and stats["down"]["sent"] == 2  # only the ends' datagrams met the link model


def test_a_given_client_is_the_only_one_even_before_it_sends(tmp_path: Path) -> None:
    """``--client``: a stranger who sends first does not become the client, and the vehicle's
    datagrams go to the given client before it has said anything."""
    client, vehicle, stranger = udp(), udp(), udp()
    me = client.getsockname()
    relay, front, back = start_relay(vehicle, tmp_path, "--client", f"{me[0]}:{me[1]}")
    try:
        stranger.sendto(b"s0", front)
        vehicle.sendto(b"v0", back)
        assert client.recv(2048) == b"v0"
        assert nothing_queued(stranger)
        client.sendto(b"c0", front)
        assert vehicle.recv(2048) == b"c0"
        assert nothing_queued(vehicle), "the stranger's datagram went to the vehicle"
        assert relay.stop() == 0
    finally:
        relay.stop()
        for s in (client, vehicle, stranger):
            s.close()
    stats = json.loads((tmp_path / "relay.json").read_text())
    assert stats["refused"] == {"stranger_front": 1, "stranger_back": 0}
    assert stats["client"] == f"{me[0]}:{me[1]}" and stats["client_from"] == "given"
    assert not any(isinstance(r, Event) and r.kind == "client" for r in map(parse_line, relay.lines)), \
        relay.lines  # nothing learned: it was given


def spoofed_odometry(sysid: int, usec: int) -> bytes:
    """A valid ODOMETRY claiming to be vehicle ``sysid`` (compid 1), at rest, stamped ``usec``."""
    mav = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=1)
    pos, q, vel, rates = state_to_odometry((0.0,) * 12)
    cov = [float("nan")] + [0.0] * 20
    return bytes(mavlink.MAVLink_odometry_message(usec, mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_BODY_FRD,
                                                  *pos, list(q), *vel, *rates, cov, cov, 0,
                                                  mavlink.MAV_ESTIMATOR_TYPE_NAIVE, 100).pack(mav))


LOGGED_READY = re.compile(r"listening on ([\d.]+):(\d+) -> [\d.]+:\d+ from ([\d.]+):(\d+)")


def relay_ports(run: Path) -> tuple[int, int]:
    """The relay's front and back ports, from its ready report as the session logged it (events.log, for a
    person: the ports are not known to the test otherwise while the flight is on)."""
    m = LOGGED_READY.search((run / "events.log").read_text())
    assert m, "the relay's ready line is not in events.log"
    return int(m.group(2)), int(m.group(4))


def test_a_strangers_far_future_state_does_not_end_a_relayed_flight(tmp_path: Path) -> None:
    """``bsst sitl --realtime --delay 20``: once the flight is under way a stranger sends
    ODOMETRY as the vehicle (its sysid), stamped 11.6 days ahead, to the relay's front and back
    ports. It used to be forwarded and end the mission at once (disarmed in the air, outcome
    completed). Now the relay refuses and counts each, the controller never sees one, and the
    flight completes only after its whole duration, its time never jumping."""
    mission = Mission(Sine(), duration_s=3.0, name="spoof")
    run_dir = tmp_path / "run"
    sent = 5
    with session_thread(mission, run_dir, realtime=True, link={"delay_ms": 20.0}) as (n, th, result):
        wait_for(lambda: count_records(run_dir / "controller.bin") > 25 or not th.is_alive(), 60,
                   "the relayed flight under way", poll_s=0.005)
        assert th.is_alive(), "the flight ended before the spoofing"
        front, back = relay_ports(run_dir)
        stranger = udp()
        try:
            spoof = spoofed_odometry(n + 1, FAR_FUTURE_USEC)
            for _ in range(sent):
                stranger.sendto(spoof, ("127.0.0.1", front))
                stranger.sendto(spoof, ("127.0.0.1", back))
        finally:
            stranger.close()
        spoofed_at = count_records(run_dir / "controller.bin")
    run = result["run"]
    s = run.summary
    assert spoofed_at < mission.steps - 250, "the spoof came too late in the flight to tell"
    assert s["outcome"] == "completed", s["events"][-5:]
    assert s["sitl"]["vehicle_exit"] == "exited with status 0"
    assert s["sitl"]["controller_exit"] == controller_exit_text(s)  # 1: the machine stalled its ticks
    t = run.trace["t"]
    assert t[-1] >= mission.duration_s - 0.1, t[-1]  # flown to its end, not ended by the stranger
    assert s["timing"]["flight_wall_s"] >= 0.95 * mission.duration_s
    dt = np.diff(t)
    assert dt.min() > 0.0 and dt.max() < 0.5, (dt.min(), dt.max())  # the mission's time never jumps
    relay = json.loads((run_dir / "relay.json").read_text())
    assert relay["refused"] == {"stranger_front": sent, "stranger_back": sent}
    assert s["link"]["relay_refused"] == relay["refused"]
    assert not s["link"]["rejected_by"]["controller"], s["link"]["rejected_by"]  # none reached it
    # the session named the relay its client (the controller's source port) and the vehicle the relay's back
    # port: nothing was left to learn from a first sender
    started = [e["text"] for e in s["events"] if e["kind"] == "started" and e["text"].startswith("relay pid")]
    assert len(started) == 1 and "(client 127.0.0.1:" in started[0], s["events"]
    back = started[0].split(" from ")[1].split(" ")[0]
    vehicle_start = next(e["text"] for e in s["events"] if e["kind"] == "started" and e["text"].startswith("vehicle"))
    assert f"controller_from={back}" in vehicle_start, vehicle_start
    assert not [e for e in s["events"] if e["source"] == "relay" and e["kind"] == "client"], s["events"]



def test_the_client_is_named_by_the_side_its_datagrams_come_from() -> None:
    """With ``--listen-direction down`` the first sender to --listen is the vehicle's side (it was called the
    controller's whatever the direction)."""
    from bridge.nodes.relay import client_event

    assert client_event(("127.0.0.1", 5)).text == ("127.0.0.1:5 is the controller side (the first sender to --listen, "
                                                   "its datagrams travel up); any other sender is refused")
    assert client_event(("127.0.0.1", 5), "down").text.startswith("127.0.0.1:5 is the vehicle side (the first sender "
                                                                  "to --listen, its datagrams travel down)")


def test_a_relay_forwarding_to_its_own_listen_socket_is_told_from_one_to_another_host() -> None:
    """(``bsst relay --to`` its own ``--listen`` is refused, tests/test_bad_input.py; the first version also refused
    another machine at the port when listening on 0.0.0.0.)"""
    from bridge.nodes.relay import forwards_to_itself

    assert forwards_to_itself(("127.0.0.1", 5), ("localhost", 5))
    assert forwards_to_itself(("0.0.0.0", 5), ("127.0.0.1", 5))
    assert not forwards_to_itself(("0.0.0.0", 5), ("192.168.1.20", 5))
    assert not forwards_to_itself(("127.0.0.1", 5), ("127.0.0.1", 6))
