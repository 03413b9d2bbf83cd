"""Covers bridge.nodes.vehicle.armretry, bridge.nodes.vehicle.commander and bridge.nodes.offboard.flight: resent ARMs.

Over a slow, lossy link (``bsst sitl missions/sine.toml --realtime --delay 150 --loss 60``) the controller resent
its ARM while the first copy had armed the vehicle; its failsafe (no target: the controller had no ACK yet)
disarmed it, and a late resend armed it again: the flight the failsafe had ended went on, and crashed. Real
processes (``bsst vehicle``, ``bsst controller``) on 127.0.0.1, a scripted controller (pymavlink) or a link in the
middle that loses what the test says (:class:`Lossy`: the ARM's ACKs, the vehicle's HEARTBEATs after the arm).
"""

from __future__ import annotations

import os
import selectors
import socket
import threading
import time
from pathlib import Path

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from bridge.mavlink.endpoint import LINK_PORT
from bridge.mavlink.events import EventId, received_id
from bridge.nodes.report import Done, Event, Ready, Stats
from bridge.nodes.vehicle.armretry import RETRY_GAP_S, ArmRetries
from bridge.session import instance_slot
from tests.sitlkit import ROOT, Proc, run_bsst

pytestmark = pytest.mark.process  # starts processes or opens sockets: not in make test-fast

M = mavlink
ARM = M.MAV_CMD_COMPONENT_ARM_DISARM


def _controller_link(n: int):
    """A scripted controller's link to the vehicle of instance ``n`` (as ``bsst controller``'s ids: 200 / 191)."""
    os.environ["MAVLINK20"] = "1"
    return mavutil.mavlink_connection(f"udpout:127.0.0.1:{LINK_PORT + n}", source_system=200,
                                      source_component=191, dialect="common")


def _heartbeat(conn, armed: bool, timeout: float = 20.0):
    """The vehicle's next HEARTBEAT that shows it ``armed`` (or not)."""
    want = M.MAV_MODE_FLAG_SAFETY_ARMED if armed else 0
    hb = conn.recv_match(type="HEARTBEAT", blocking=True, timeout=timeout,
                         condition=f"HEARTBEAT.base_mode & {M.MAV_MODE_FLAG_SAFETY_ARMED} == {want}")
    assert hb is not None, f"no HEARTBEAT {'armed' if armed else 'disarmed'} within {timeout} s"
    return hb


def _armed_now(conn, sysid: int) -> bool:
    """Whether the vehicle is armed: a HEARTBEAT asked for (REQUEST_MESSAGE), the next that comes."""
    conn.mav.command_long_send(sysid, 1, M.MAV_CMD_REQUEST_MESSAGE, 0, M.MAVLINK_MSG_ID_HEARTBEAT, 0, 0, 0, 0, 0, 0)
    hb = conn.recv_match(type="HEARTBEAT", blocking=True, timeout=5)
    assert hb is not None, "no HEARTBEAT within 5 s of asking for one"
    return bool(hb.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)


def _arm(conn, sysid: int, confirmation: int) -> tuple[int, list[str]]:
    """ARM (``confirmation``: 0 the first copy, 1, 2 ... its resends); its COMMAND_ACK's result, and the
    STATUSTEXTs said with it (in its datagram, after it)."""
    conn.mav.command_long_send(sysid, 1, ARM, confirmation, 1, 0, 0, 0, 0, 0, 0)
    ack = conn.recv_match(type="COMMAND_ACK", blocking=True, timeout=10, condition=f"COMMAND_ACK.command=={ARM}")
    assert ack is not None, "no COMMAND_ACK of the ARM within 10 s"
    texts = []
    while (t := conn.recv_match(type="STATUSTEXT", blocking=True, timeout=0.3)) is not None:
        texts.append(t.text)
    return ack.result, texts


def test_a_resend_of_an_arm_acted_on_does_not_arm_again_the_vehicle_its_failsafe_disarmed(tmp_path):
    """A real-time vehicle armed by an ARM (confirmation 0) gets no target: its failsafe disarms it on the ground.
    A resend of that ARM (confirmation 1) that comes after it is answered with the first's result (ACCEPTED) and a
    STATUSTEXT, and arms nothing: the vehicle stays disarmed, armed once in its events. A new ARM (confirmation 0)
    arms it. On the previous code the resend armed it again (the tour's crash)."""
    with instance_slot() as n:
        v = Proc.bsst("vehicle", "--instance", str(n), "--realtime", "--gcs", "none", "--out", str(tmp_path))
        v.wait_report(Ready)
        ctl = _controller_link(n)
        sysid = n + 1
        try:
            ctl.mav.heartbeat_send(M.MAV_TYPE_ONBOARD_CONTROLLER, M.MAV_AUTOPILOT_INVALID, 0, 0, 4)
            _heartbeat(ctl, armed=False)
            assert _arm(ctl, sysid, 0)[0] == M.MAV_RESULT_ACCEPTED
            confirmation, deadline = 1, time.monotonic() + 30
            # resends on their way meanwhile (each within RETRY_GAP_S of the last, however loaded the machine):
            # answered, acted on no more; until its failsafe (no target for 0.5 s) has disarmed it on the ground
            while not any(e.startswith("disarmed:") for e in v.events()):
                assert time.monotonic() < deadline, v.events()
                assert _arm(ctl, sysid, confirmation)[0] == M.MAV_RESULT_ACCEPTED
                confirmation += 1
            result, texts = _arm(ctl, sysid, confirmation)  # the late resend, after the failsafe's disarm
            assert result == M.MAV_RESULT_ACCEPTED  # the first's answer, nothing done
            said = "".join(texts)  # (chunked: 50 characters a STATUSTEXT)
            assert f"ARM resend (confirmation {confirmation})" in said and "not armed again" in said, texts
            assert not _armed_now(ctl, sysid)
            assert sum(e.startswith("armed:") for e in v.events()) == 1, v.events()
            assert _arm(ctl, sysid, 0)[0] == M.MAV_RESULT_ACCEPTED  # a new arm: acted on
            assert sum(e.startswith("armed:") for e in v.events()) == 2, v.events()
            # its own disarm ends that arm: a resend of its next ARM (the first copy lost) is the next arm's, acted
            # on (it was answered ACCEPTED as the old arm's resend and left the vehicle disarmed: a review's finding)
            ctl.mav.command_long_send(sysid, 1, ARM, 0, 0, 0, 0, 0, 0, 0, 0)
            _heartbeat(ctl, armed=False)
            assert _arm(ctl, sysid, 1)[0] == M.MAV_RESULT_ACCEPTED and _armed_now(ctl, sysid)
            assert sum(e.startswith("armed:") for e in v.events()) == 3, v.events()
        finally:
            v.stop()
            ctl.close()


def test_a_resend_long_after_its_arm_is_a_new_arm():
    """Copies of one arm come within RETRY_GAP_S of each other; a resend later than that (a new controller whose
    first ARM was lost) is acted on, as is any confirmation 0."""
    arms = ArmRetries()
    src = (200, 191, ("127.0.0.1", 5000))
    first = arms.copy(src, 0, 10.0)
    ArmRetries.acted(first, M.MAV_RESULT_ACCEPTED)
    assert arms.copy(src, 1, 10.1) is first and first.result == M.MAV_RESULT_ACCEPTED
    assert arms.copy(src, 2, 10.1 + RETRY_GAP_S - 0.01) is first
    assert arms.copy(src, 3, 10.1 + 2 * RETRY_GAP_S).result is None  # too late to be a resend of it
    assert arms.copy(src, 0, 30.0).result is None
    assert arms.copy((200, 191, ("127.0.0.1", 5001)), 1, 30.0).result is None  # another sender's


class Lossy(threading.Thread):
    """A link between ``bsst controller`` and ``bsst vehicle`` that loses the vehicle's COMMAND_ACKs of ARM_DISARM
    and, with ``no_heartbeat_after_arm``, its HEARTBEATs once an ARM has passed up (or before
    ``heartbeat_after_states`` states) (the controller then learns what
    came of its arm only from the vehicle's EVENTs); it notes when each ARM passed up (``arms``: (time.monotonic,
    confirmation)), and when the vehicle's first armed HEARTBEAT and its first EVENT FAILSAFE passed down."""

    def __init__(self, vehicle: tuple[str, int], no_heartbeat_after_arm: bool = False,
                 heartbeat_after_states: int = 0) -> None:
        super().__init__(daemon=True)
        self.vehicle = vehicle
        self.no_hb = no_heartbeat_after_arm
        self.hb_after = heartbeat_after_states  # the vehicle's HEARTBEATs lost until this many states passed down
        self.states = 0
        self.front = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.front.bind(("127.0.0.1", 0))
        self.back = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.back.bind(("127.0.0.1", 0))
        self.port = self.front.getsockname()[1]
        self.client: tuple[str, int] | None = None
        self.arms: list[tuple[float, int]] = []
        self.armed_hb_at: float | None = None  # the first HEARTBEAT showing the vehicle armed, passed down
        self.failsafe_at: float | None = None  # the vehicle's first EVENT FAILSAFE, passed down
        self._halt = threading.Event()
        os.environ["MAVLINK20"] = "1"
        self._up = mavlink.MAVLink(None)
        self._down = mavlink.MAVLink(None)
        self._up.robust_parsing = self._down.robust_parsing = True

    def run(self) -> None:
        sel = selectors.DefaultSelector()
        sel.register(self.front, selectors.EVENT_READ)
        sel.register(self.back, selectors.EVENT_READ)
        while not self._halt.is_set():
            for key, _ in sel.select(0.05):
                data, addr = key.fileobj.recvfrom(65535)
                if key.fileobj is self.front:
                    self.client = addr
                    self._pass_up(data)
                elif self.client is not None:
                    kept = self._pass_down(data)
                    if kept:
                        self.front.sendto(kept, self.client)
        sel.close()

    def _pass_up(self, data: bytes) -> None:
        for m in self._up.parse_buffer(data) or []:
            if m.get_type() == "COMMAND_LONG" and m.command == ARM and m.param1 == 1:
                self.arms.append((time.monotonic(), m.confirmation))
        self.back.sendto(data, self.vehicle)

    def _pass_down(self, data: bytes) -> bytes:
        kept = b""
        for m in self._down.parse_buffer(data) or []:
            kind = m.get_type()
            if kind == "COMMAND_ACK" and m.command == ARM:
                continue
            self.states += kind == "ODOMETRY"
            if kind == "HEARTBEAT":
                if (self.no_hb and self.arms) or self.states < self.hb_after:
                    continue
                if m.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED and self.armed_hb_at is None:
                    self.armed_hb_at = time.monotonic()
            if kind == "EVENT" and received_id(m) is EventId.FAILSAFE and self.failsafe_at is None:
                self.failsafe_at = time.monotonic()
            kept += m.get_msgbuf()
        return kept

    def stop(self) -> None:
        self._halt.set()
        self.join(5)
        self.front.close()
        self.back.close()


def _short_mission(tmp_path: Path, seconds: float) -> Path:
    text = (ROOT / "missions" / "sine.toml").read_text().replace("duration_s = 30.0", f"duration_s = {seconds}")
    path = tmp_path / "short.toml"
    path.write_text(text)
    return path


def _fly_through(tmp_path: Path, lossy_hb: bool, hb_after: int = 0) -> tuple[Proc, Proc, Lossy, Done]:
    with instance_slot() as n:
        v = Proc.bsst("vehicle", "--instance", str(n), "--realtime", "--gcs", "none", "--out", str(tmp_path / "v"))
        v.wait_report(Ready)
        link = Lossy(("127.0.0.1", LINK_PORT + n), no_heartbeat_after_arm=lossy_hb, heartbeat_after_states=hb_after)
        link.start()
        # (a 1 s mission: what these tests look at, the ARMs and the states before the first HEARTBEAT heard, all
        # come before the mission's first target; a flight that ends in its failsafe never starts the mission)
        c = Proc.bsst("controller", str(_short_mission(tmp_path, 1.0)), "--realtime", "--vehicle",
                      f"127.0.0.1:{link.port}", "--out", str(tmp_path / "c"))
        try:
            done = c.wait_report(Done, timeout=60)
            c.ended()
        finally:
            c.stop()
            v.stop()
            link.stop()
    return v, c, link, done


def test_the_controller_stops_resending_its_arm_once_the_vehicles_heartbeat_shows_it_armed(tmp_path):
    """Every ACK of the ARM lost: the controller stops resending it once the vehicle's HEARTBEAT shows it armed in
    OFFBOARD (sent at once on the arm), and flies. On the previous code it resent 30 times, 3 s, then gave up
    ("arming not acknowledged"), while the vehicle, armed since the first, flew its failsafe."""
    v, c, link, done = _fly_through(tmp_path, lossy_hb=False)
    assert link.armed_hb_at is not None
    assert any(e.startswith("armed: vehicle armed, offboard control") for e in c.events()), c.lines[-20:]
    late = [conf for t, conf in link.arms if t > link.armed_hb_at + 0.5]  # (0.5 s: a loaded machine's wake-up)
    assert not late, (link.arms, link.armed_hb_at)
    assert len(link.arms) < 10, link.arms
    assert done.reason is None or "arming" not in done.reason, done
    assert sum(e.startswith("armed:") for e in v.events()) == 1, v.events()


def test_a_failsafe_before_the_arms_answer_ends_the_flight_no_arm_sent_again(tmp_path):
    """Every ACK of the ARM and every HEARTBEAT after it lost: the vehicle, armed by the first copy, gets no target,
    and its failsafe disarms it on the ground. The controller learns it from the vehicle's EVENT FAILSAFE: it sends
    no ARM again and ends as ``failsafe``, said so; the vehicle was armed once. On the previous code the controller
    resent its ARM 30 times (the vehicle armed again after each failsafe) and ended ``aborted: arming not
    acknowledged``."""
    v, c, link, done = _fly_through(tmp_path, lossy_hb=True)
    assert done.outcome == "failsafe", done
    assert link.failsafe_at is not None and link.arms
    assert isinstance(v.wait_event(lambda s: s.startswith("failsafe:"), timeout=1), Event)
    # no ARM after the vehicle's EVENT FAILSAFE had come down, but one the controller sent before it read it
    # (0.5 s: a loaded machine's wake-up)
    assert not [a for a in link.arms if a[0] > link.failsafe_at + 0.5], (link.arms, link.failsafe_at)
    assert sum(e.startswith("armed:") for e in v.events()) == 1, v.events()
    assert any("bsst controller: failsafe" in ln for ln in c.lines), c.lines[-10:]


def test_states_before_the_vehicles_first_heartbeat_are_counted_unheard_not_sender(tmp_path):
    """``bsst controller`` without ``--target-sysid`` learns the vehicle's system from its HEARTBEAT; the states
    that come before it (a lossy link loses the first HEARTBEATs, the 1 Hz stream's next is up to 1 s later) are
    refused as ``unheard``. On the previous code they were ``sender``, said "from an address other than the peer":
    the tour's 306 of 499 frames through ``bsst relay --loss 60``, all from the relay's listen port, the peer."""
    _, c, link, _ = _fly_through(tmp_path, lossy_hb=False, hb_after=50)
    stats = c.wait_report(Stats, timeout=5).values
    assert stats["rejected"].get("unheard", 0) >= 40 and "sender" not in stats["rejected"], stats["rejected"]
    assert link.states >= 50, stats["rejected"]


def test_the_controller_says_a_crash_not_a_failsafe(tmp_path):
    """A lockstep session whose vehicle crashes (the law cannot fly 150 ms-old states: the sine through
    ``--delay 150 --loss 60`` hits the ground at 1.09 s): the controller's final word is ``crashed`` by the vehicle's
    EVENT, not ``failsafe`` (its HEARTBEAT EMERGENCY taken for one, until the third wave's forty-second session)."""
    with instance_slot() as n:
        r = run_bsst("sitl", "missions/sine.toml", "--delay", "150", "--loss", "60", "--seed", "1", "--instance",
                     str(n), "--no-plots", "--out", str(tmp_path / "s"), timeout=120)
    assert r.returncode == 1, r.stderr
    said = (tmp_path / "s" / "controller.log").read_text()
    assert said.startswith("bsst controller: crashed: the vehicle's flight ended: it crashed"), said
    assert "outcome: crashed" in r.stdout
