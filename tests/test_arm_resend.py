"""Covers bridge.nodes.vehicle.armretry and bridge.nodes.vehicle.commander: resent ARMs.

Over a slow, lossy link (``bsst sitl missions/sine.toml --realtime --delay 150 --loss 60``) the controller resent
its ARM while the first copy had armed the vehicle; its failsafe (no target: the controller had no ACK yet)
disarmed it, and a late resend armed it again: the flight the failsafe had ended went on, and crashed. A real
``bsst vehicle`` on 127.0.0.1 and a scripted controller (pymavlink).
"""

from __future__ import annotations

import os

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from bridge.mavlink.endpoint import LINK_PORT
from bridge.nodes.report import Ready
from bridge.nodes.vehicle.armretry import RETRY_GAP_S, ArmRetries
from bridge.session import instance_slot
from tests.sitlkit import Proc

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
            v.wait_event(lambda s: s.startswith("failsafe:"), timeout=20)  # no target for 0.5 s
            v.wait_event(lambda s: s.startswith("disarmed:"), timeout=20)  # landed: disarmed
            assert not _armed_now(ctl, sysid)
            result, texts = _arm(ctl, sysid, 1)  # the late resend
            assert result == M.MAV_RESULT_ACCEPTED  # the first's answer, nothing done
            said = "".join(texts)  # (chunked: 50 characters a STATUSTEXT)
            assert "ARM resend (confirmation 1)" in said and "not armed again" in said, texts
            assert not _armed_now(ctl, sysid)
            assert sum(e.startswith("armed:") for e in v.events()) == 1, v.events()
            assert _arm(ctl, sysid, 0)[0] == M.MAV_RESULT_ACCEPTED  # a new arm: acted on
            assert sum(e.startswith("armed:") for e in v.events()) == 2, v.events()
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
