"""Covers bridge.nodes.vehicle.

``bsst vehicle`` (the package bridge/nodes/vehicle/) as a real process: ground stations (pymavlink,
MAVProxy, MAVSDK) and the controller contract, over real UDP on 127.0.0.1.

Each test holds an instance slot (bridge.session.instance_slot), so the ports 14550 + N and
14560 + N are its own while it runs, whatever else runs beside it.
"""

from __future__ import annotations

import math
import os
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from bridge.mavlink.endpoint import GCS_PORT, LINK_PORT
from bridge.mavlink.receive import MAX_FRAME
from bridge.nodes.report import Event, Ready, Stats
from bridge.record.halves import read_half
from bridge.session import instance_slot
from tests.gcskit import command_ack, gcs_link
from tests.sitlkit import ENV, ROOT, MavProxy, Proc, run_bsst, run_script, script_result, shown
from tests.waiting import wait_for

pytestmark = pytest.mark.process  # starts processes or opens sockets: not in make test-fast

M = mavlink


def _vehicle(n: int, tmp_path, *extra: str) -> Proc:
    v = Proc.bsst("vehicle", "--instance", str(n), "--out", str(tmp_path), *extra)
    v.wait_report(Ready)
    return v


def _controller_link(n: int, sysid: int = 200):
    """A scripted controller's link to the vehicle of instance ``n`` (as ``bsst controller``'s: 200 / 191)."""
    os.environ["MAVLINK20"] = "1"
    return mavutil.mavlink_connection(f"udpout:127.0.0.1:{LINK_PORT + n}", source_system=sysid,
                                      source_component=191, dialect="common")


def _stats(v: Proc) -> dict:
    return v.wait_report(Stats, timeout=10).values


def test_pymavlink_ground_station(tmp_path):
    """Heartbeat, arm and disarm with ACKs, telemetry, requests answered, TIMESYNC."""
    with instance_slot() as n:
        gcs = gcs_link(n)
        v = _vehicle(n, tmp_path)
        try:
            hb = gcs.wait_heartbeat(timeout=20)
            assert hb is not None
            assert (hb.type, hb.autopilot, hb.system_status) == (M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_PX4,
                                                                   M.MAV_STATE_STANDBY)
            # PX4's boot mode: HOLD (AUTO.LOITER: main mode 4, sub mode 3)
            assert hb.custom_mode == (4 << 16) | (3 << 24) and mavutil.mode_string_v10(hb) == "LOITER"
            assert gcs.target_system == n + 1 and not hb.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED
            tgt = (gcs.target_system, gcs.target_component)

            gcs.mav.command_long_send(*tgt, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
            assert command_ack(gcs, M.MAV_CMD_COMPONENT_ARM_DISARM).result == M.MAV_RESULT_ACCEPTED
            armed = gcs.recv_match(type="HEARTBEAT", blocking=True, timeout=5,
                                   condition="HEARTBEAT.base_mode & 128")
            assert armed is not None and armed.system_status == M.MAV_STATE_ACTIVE
            gcs.mav.command_long_send(*tgt, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 0, 0, 0, 0, 0, 0, 0)
            assert command_ack(gcs, M.MAV_CMD_COMPONENT_ARM_DISARM).result == M.MAV_RESULT_ACCEPTED
            text = gcs.recv_match(type="STATUSTEXT", blocking=True, timeout=5)
            assert text is not None and "disarmed" in text.text  # events are said in STATUSTEXT

            gcs.mav.command_long_send(*tgt, M.MAV_CMD_REQUEST_MESSAGE, 0, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION,
                                      0, 0, 0, 0, 0, 0)
            assert command_ack(gcs, M.MAV_CMD_REQUEST_MESSAGE).result == M.MAV_RESULT_ACCEPTED
            ver = gcs.recv_match(type="AUTOPILOT_VERSION", blocking=True, timeout=5)
            # PX4's capabilities that this vehicle serves (FTP: the metadata, read-only; flight termination), not
            # the offboard set-points it does not take (docs/ground-station.md)
            served = (M.MAV_PROTOCOL_CAPABILITY_MAVLINK2 | M.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
                      | M.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT | M.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
                      | M.MAV_PROTOCOL_CAPABILITY_MISSION_INT | M.MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT
                      | M.MAV_PROTOCOL_CAPABILITY_MISSION_FENCE | M.MAV_PROTOCOL_CAPABILITY_MISSION_RALLY
                      | M.MAV_PROTOCOL_CAPABILITY_FTP | M.MAV_PROTOCOL_CAPABILITY_FLIGHT_TERMINATION)
            assert ver is not None and ver.capabilities == served, hex(ver.capabilities if ver else 0)
            gcs.mav.command_long_send(*tgt, M.MAV_CMD_SET_MESSAGE_INTERVAL, 0, M.MAVLINK_MSG_ID_ATTITUDE, 20000,
                                      0, 0, 0, 0, 0)
            assert command_ack(gcs, M.MAV_CMD_SET_MESSAGE_INTERVAL).result == M.MAV_RESULT_ACCEPTED
            # NAV_TAKEOFF's param7 is m AMSL (as PX4 reads it): 600 m is 112 m above the 488 m home, beyond the
            # plant's envelope: refused, saying why
            gcs.mav.command_long_send(*tgt, M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 0, 600)
            seen: dict[str, object] = {}  # the ACK and the STATUSTEXT, in either order
            deadline = time.monotonic() + 10
            while len(seen) < 2 and time.monotonic() < deadline:
                m = gcs.recv_match(type=["COMMAND_ACK", "STATUSTEXT"], blocking=True, timeout=1)
                if m is not None and m.get_type() == "COMMAND_ACK" and m.command == M.MAV_CMD_NAV_TAKEOFF:
                    seen["ack"] = m.result
                elif m is not None and m.get_type() == "STATUSTEXT" and m.text.startswith("NAV_TAKEOFF"):
                    seen["why"] = m.text
            assert seen.get("ack") == M.MAV_RESULT_DENIED and "600 m AMSL" in str(seen.get("why")), seen

            gcs.mav.timesync_send(0, 123456789)
            ts = gcs.recv_match(type="TIMESYNC", blocking=True, timeout=5, condition="TIMESYNC.tc1!=0")
            assert ts is not None and ts.ts1 == 123456789
            for kind in ("ATTITUDE", "LOCAL_POSITION_NED", "GLOBAL_POSITION_INT", "SYS_STATUS",
                         "ACTUATOR_OUTPUT_STATUS", "VFR_HUD"):
                assert gcs.recv_match(type=kind, blocking=True, timeout=5) is not None, kind
            pos = gcs.recv_match(type="GLOBAL_POSITION_INT", blocking=True, timeout=5)
            assert abs(pos.lat - 473977420) < 10 and abs(pos.lon - 85455940) < 10  # the default home
        finally:
            assert v.stop() == 0
            gcs.close()
    assert (tmp_path / "vehicle.tlog").stat().st_size > 0


def test_targets_only_from_the_configured_controller(tmp_path):
    """Lockstep: the state of step k goes out; the vehicle steps only on the target for k
    from sysid 200 / compid 191, armed; others are rejected and counted."""
    with instance_slot() as n:
        v = _vehicle(n, tmp_path)
        ctl = _controller_link(n)
        impostor = _controller_link(n, sysid=201)
        try:
            ctl.mav.heartbeat_send(M.MAV_TYPE_ONBOARD_CONTROLLER, M.MAV_AUTOPILOT_INVALID, 0, 0, 4)
            hb = ctl.recv_match(type="HEARTBEAT", blocking=True, timeout=20)
            assert hb is not None
            sysid = n + 1
            hover = (1.1 * 9.81 / 43.164, 0.0, 0.0, 0.0)  # paper profile: (u1/u1_max, roll, pitch, yaw)
            wire = (hover[1], hover[2], hover[3], hover[0])
            # disarmed: a target is refused
            ctl.mav.set_actuator_control_target_send(0, 0, sysid, 1, list(wire) + [0.0] * 4)
            ctl.mav.command_long_send(sysid, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
            assert command_ack(ctl, M.MAV_CMD_COMPONENT_ARM_DISARM).result == M.MAV_RESULT_ACCEPTED
            odo = ctl.recv_match(type="ODOMETRY", blocking=True, timeout=5)
            assert odo.time_usec == 0 and (odo.frame_id, odo.child_frame_id) == (M.MAV_FRAME_LOCAL_NED,
                                                                                  M.MAV_FRAME_BODY_FRD)
            impostor.mav.set_actuator_control_target_send(0, 0, sysid, 1, list(wire) + [0.0] * 4)
            # a motors target to a wrench vehicle (SAFETY_ARMED in mode: with it clear, the same
            # message is the controller's no-target acknowledgement of a lockstep step)
            ctl.mav.hil_actuator_controls_send(0, [0.5] * 16, M.MAV_MODE_FLAG_SAFETY_ARMED, 1)
            ctl.mav.set_actuator_control_target_send(0, 1, sysid, 1, list(wire) + [0.0] * 4)  # group 1
            ctl.mav.set_actuator_control_target_send(4000, 0, sysid, 1, list(wire) + [0.0] * 4)  # future step
            ctl.mav.set_actuator_control_target_send(0, 0, sysid, 1, list(wire) + [0.0] * 4)  # the one
            nxt = ctl.recv_match(type="ODOMETRY", blocking=True, timeout=5, condition="ODOMETRY.time_usec==4000")
            assert nxt is not None  # stepped once: t = 1 / 250 s
            ctl.mav.command_long_send(sysid, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 0, 21196, 0, 0, 0, 0, 0)
            assert command_ack(ctl, M.MAV_CMD_COMPONENT_ARM_DISARM).result == M.MAV_RESULT_ACCEPTED
        finally:
            assert v.stop() == 0
            ctl.close()
            impostor.close()
    s = _stats(v)
    assert s["accepted"] == 1 and s["steps"] == 1
    assert s["rejected"] == {"not_offboard": 1, "sender": 1, "message": 1, "group": 1, "future": 1}
    v = read_half(tmp_path / "vehicle.bin")
    assert list(v["k"]) == [0.0] and list(v["t"]) == [0.0]  # one record: step 0


HOVER_WIRE = [0.0, 0.0, 0.0, 1.1 * 9.81 / 43.164] + [0.0] * 4  # hover, paper profile


def _two_answers_to_step_0(tmp_path, idle_copy: bool) -> dict:
    """A scripted controller arms a lockstep vehicle and answers step 0 twice: the idle copy of its state read
    before arming and the state arming sends (``idle_copy``), or the state and the copy resent 50 ms later. Then
    step 1's state, a disarm, and the vehicle's stats."""
    with instance_slot() as n:
        v = _vehicle(n, tmp_path)
        ctl = _controller_link(n)
        sysid = n + 1
        try:
            ctl.mav.heartbeat_send(M.MAV_TYPE_ONBOARD_CONTROLLER, M.MAV_AUTOPILOT_INVALID, 0, 0, 4)
            heard = ("ODOMETRY", "ODOMETRY.time_usec==0") if idle_copy else ("HEARTBEAT", None)
            assert ctl.recv_match(type=heard[0], blocking=True, timeout=20, condition=heard[1]) is not None
            ctl.mav.command_long_send(sysid, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
            assert command_ack(ctl, M.MAV_CMD_COMPONENT_ARM_DISARM).result == M.MAV_RESULT_ACCEPTED
            if not idle_copy:
                first = ctl.recv_match(type="ODOMETRY", blocking=True, timeout=5, condition="ODOMETRY.time_usec==0")
                again = ctl.recv_match(type="ODOMETRY", blocking=True, timeout=5, condition="ODOMETRY.time_usec==0")
                assert first is not None and again is not None  # step 0's state, then its copy (not answered)
            for _ in range(2):  # one answer to each copy, as the controller does
                ctl.mav.set_actuator_control_target_send(0, 0, sysid, 1, HOVER_WIRE)
            nxt = ctl.recv_match(type="ODOMETRY", blocking=True, timeout=5, condition="ODOMETRY.time_usec==4000")
            assert nxt is not None
            ctl.mav.command_long_send(sysid, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 0, 21196, 0, 0, 0, 0, 0)
            assert command_ack(ctl, M.MAV_CMD_COMPONENT_ARM_DISARM).result == M.MAV_RESULT_ACCEPTED
        finally:
            assert v.stop() == 0
            ctl.close()
    return _stats(v)


def test_a_resent_arm_that_finds_the_vehicle_armed_is_accepted_not_in_progress(tmp_path):
    """The controller resends its ARM (confirmation 1, 2, ...) every 0.1 s of wall time until an ACK comes; on
    a loaded machine the first ACCEPTED can come after the resend has left. The resend, reaching a lockstep
    vehicle armed in OFFBOARD, is ACCEPTED and does nothing: it answered IN_PROGRESS and entered the up-link
    model, whose packet fates offline never drew, and its IN_PROGRESS overtook the ACCEPTED in the controller
    ("arming refused (MAV_RESULT 5)", a flight of tests/test_params.py under load). A guard's ask to arm
    again (confirmation 0) still crosses the model as offline's does: IN_PROGRESS, and its final ACCEPTED
    once the model has delivered it and the vehicle acted on it (MAVLink's command protocol)."""
    with instance_slot() as n:
        v = _vehicle(n, tmp_path)
        ctl = _controller_link(n)
        sysid = n + 1
        arm = M.MAV_CMD_COMPONENT_ARM_DISARM
        try:
            ctl.mav.heartbeat_send(M.MAV_TYPE_ONBOARD_CONTROLLER, M.MAV_AUTOPILOT_INVALID, 0, 0, 4)
            assert ctl.recv_match(type="HEARTBEAT", blocking=True, timeout=20) is not None
            ctl.mav.command_long_send(sysid, 1, arm, 0, 1, 0, 0, 0, 0, 0, 0)
            assert command_ack(ctl, arm).result == M.MAV_RESULT_ACCEPTED
            assert ctl.recv_match(type="ODOMETRY", blocking=True, timeout=5,
                                  condition="ODOMETRY.time_usec==0") is not None
            ctl.mav.command_long_send(sysid, 1, arm, 1, 1, 0, 0, 0, 0, 0, 0)  # the resend
            assert command_ack(ctl, arm).result == M.MAV_RESULT_ACCEPTED
            ctl.mav.command_long_send(sysid, 1, arm, 0, 1, 0, 0, 0, 0, 0, 0)  # a guard's ask
            assert command_ack(ctl, arm).result == M.MAV_RESULT_IN_PROGRESS
            # step 0 answered: the vehicle steps, the model delivers the arm, and its final answer follows
            ctl.mav.set_actuator_control_target_send(0, 0, sysid, 1, HOVER_WIRE)
            final = command_ack(ctl, arm)
            assert (final.result, final.target_system, final.target_component) == (M.MAV_RESULT_ACCEPTED, 200, 191)
            ctl.mav.command_long_send(sysid, 1, arm, 0, 0, 21196, 0, 0, 0, 0, 0)
            assert command_ack(ctl, arm).result == M.MAV_RESULT_ACCEPTED
        finally:
            assert v.stop() == 0
            ctl.close()


def test_a_slow_answer_to_a_resent_state_is_taken_once_and_refuses_nothing(tmp_path):
    """Lockstep resends a state unanswered for 50 ms of wall time, and the controller answers
    every copy: an answer that was slow (not lost) comes twice. The vehicle steps once on the
    first and counts the second in ``answered_again``, not as a ``stale`` refusal (that made a
    loaded machine's lockstep summary differ from the offline one)."""
    s = _two_answers_to_step_0(tmp_path, idle_copy=False)
    assert s["steps"] == 1 and s["accepted"] == 1 and s["resends"] >= 1
    assert s["answered_again"] == 1 and s["rejected"] == {}
    # its round trip from the state's first sending, not from the copy
    assert read_half(tmp_path / "vehicle.bin")["rtt_s"][0] >= 0.05


def test_answers_to_the_idle_and_the_armed_state_of_one_step_refuse_nothing(tmp_path):
    """Disarmed in lockstep, time stands still and the vehicle shows its state of step k every 0.1 s; armed,
    it sends that step's state again and awaits its answer. A controller that read an idle copy while arming
    answers it, then the armed one: two answers to step k. The vehicle steps once and counts the second in
    ``answered_again``, not as a ``repeated`` or ``stale`` refusal (seen under load: a lockstep session's
    summary with ``rejected: {"repeated": 1}``)."""
    s = _two_answers_to_step_0(tmp_path, idle_copy=True)
    assert s["steps"] == 1 and s["accepted"] == 1
    assert s["answered_again"] == 1 and s["rejected"] == {}


class _Answering(threading.Thread):
    """A scripted controller on its own thread (a context manager: started on entry, stopped on exit): it answers
    every state with :data:`HOVER_WIRE` stamped with that state's time (``answered``: their steps, at ``rate_hz``),
    says a HEARTBEAT whenever no state came for 50 ms (a ground station's arm makes the vehicle learn its controller
    afresh: the flight's is the first to speak) and keeps the results of the COMMAND_ACKs it gets (``acks``)."""

    def __init__(self, ctl, sysid: int, rate_hz: float) -> None:
        super().__init__(daemon=True)
        self.ctl, self.sysid, self.period_us = ctl, sysid, round(1e6 / rate_hz)
        self.answered: list[int] = []
        self.acks: list[int] = []
        self._done = threading.Event()

    def run(self) -> None:
        ctl = self.ctl
        while not self._done.is_set():
            m = ctl.recv_match(type=["ODOMETRY", "COMMAND_ACK"], blocking=True, timeout=0.05)
            if m is None:
                ctl.mav.heartbeat_send(M.MAV_TYPE_ONBOARD_CONTROLLER, M.MAV_AUTOPILOT_INVALID, 0, 0, 4)
            elif m.get_type() == "COMMAND_ACK":
                self.acks.append(m.result)
            else:
                ctl.mav.set_actuator_control_target_send(m.time_usec, 0, self.sysid, 1, HOVER_WIRE)
                self.answered.append(m.time_usec // self.period_us)

    def __enter__(self) -> _Answering:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._done.set()
        self.join(5.0)

    def more(self, n: int, what: str) -> None:
        """Until ``n`` more states have been answered."""
        seen = len(self.answered)
        wait_for(lambda: len(self.answered) >= seen + n, 20.0, what)


HOLD, OFFBOARD = (1, 4, 3), (1, 6, 0)  # DO_SET_MODE's base, main and sub mode (PX4's AUTO.LOITER, OFFBOARD)


@dataclass
class _Links:
    """A lockstep vehicle (:class:`Proc`), a ground station's link to it and a scripted controller's (pymavlink)."""

    v: Proc
    gcs: Any
    ctl: Any
    sysid: int

    def gcs_says(self, cmd: int, *params: float) -> None:
        """The ground station's COMMAND_LONG ``cmd``, ACCEPTED."""
        self.gcs.mav.command_long_send(self.sysid, 1, cmd, 0, *params, *[0.0] * (7 - len(params)))
        assert command_ack(self.gcs, cmd).result == M.MAV_RESULT_ACCEPTED, (cmd, params)


@contextmanager
def _gcs_and_controller(tmp_path, rate: float) -> Iterator[_Links]:
    """A vehicle stepped at ``rate`` Hz, its ground station's and its controller's links, each heard by it; the
    vehicle stopped (exit 0) and the links closed after."""
    with instance_slot() as n:
        links = _Links(_vehicle(n, tmp_path, "--rate", f"{rate:g}"), gcs_link(n), _controller_link(n), n + 1)
        try:
            links.ctl.mav.heartbeat_send(M.MAV_TYPE_ONBOARD_CONTROLLER, M.MAV_AUTOPILOT_INVALID, 0, 0, 4)
            assert links.ctl.recv_match(type="HEARTBEAT", blocking=True, timeout=20) is not None
            assert links.gcs.wait_heartbeat(timeout=20) is not None
            yield links
        finally:
            assert links.v.stop() == 0
            links.gcs.close()
            links.ctl.close()


def test_a_ground_stations_offboard_or_arm_on_the_wall_clock_engages_lockstep_at_a_control_periods_start(tmp_path):
    """A lockstep vehicle a ground station put in HOLD runs on the wall clock, its controller still answering its
    states; the ground station's OFFBOARD again, or its arm in OFFBOARD after a disarm there, is taken at the next
    control period's start, where lockstep engages with that step's state: every step vehicle.bin records as flown
    with its own answer is one whose state the controller answered, and the mode and arm are at a step's time.
    Taken mid-period (20 physics steps to a 50 Hz period: 19 times in 20), OFFBOARD sent the state of a step the
    vehicle then went on flying on the wall clock, and the answer to it flew the next step, recorded as that step's
    own answer (its state never sent); the mode and arm were between two steps."""
    rate = 50.0
    with _gcs_and_controller(tmp_path, rate) as links:
        v, ctl, sysid, gcs_says, hold, offboard = links.v, links.ctl, links.sysid, links.gcs_says, HOLD, OFFBOARD
        with _Answering(ctl, sysid, rate) as controller:
            ctl.mav.command_long_send(sysid, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
            controller.more(10, "the controller's flight")
            for _ in range(3):
                gcs_says(M.MAV_CMD_DO_SET_MODE, *hold)
                controller.more(10, "the states of the wall clock, answered")
                gcs_says(M.MAV_CMD_DO_SET_MODE, *offboard)  # armed: back to lockstep
                controller.more(10, "the lockstep flight again")
                gcs_says(M.MAV_CMD_DO_SET_MODE, *hold)
                gcs_says(M.MAV_CMD_COMPONENT_ARM_DISARM, 0)  # on the ground: on the wall clock, disarmed
                gcs_says(M.MAV_CMD_DO_SET_MODE, *offboard)  # disarmed: armed in it next
                gcs_says(M.MAV_CMD_COMPONENT_ARM_DISARM, 1)  # back to lockstep
                controller.more(10, "the lockstep flight after the ground station's arm")
            ctl.mav.command_long_send(sysid, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 0, 21196, 0, 0, 0, 0, 0)
            wait_for(lambda: M.MAV_RESULT_ACCEPTED in controller.acks[1:], 10.0, "the controller's disarm")
    answered = set(controller.answered)
    rows = read_half(tmp_path / "vehicle.bin")
    k, lockstep = rows["k"].astype(int), rows["k"] == rows["cmd_k"]
    again = lockstep[1:] & ~(lockstep[:-1] & (k[1:] == k[:-1] + 1))  # (a HOLD and disarm within a period: no row)
    assert again.sum() == 6, k[1:][again]  # each OFFBOARD and each arm engaged lockstep again
    assert set(k[lockstep]) <= answered, sorted(set(k[lockstep]) - answered)  # before: each step after a switch
    by_gcs = [e for e in v.reports() if isinstance(e, Event) and e.by is not None and e.by.link == "gcs"
              and e.kind in ("armed", "mode") and (e.mode == "offboard" or e.kind == "armed")]
    assert len(by_gcs) == 9, [shown(e) for e in by_gcs]  # (an OFFBOARD armed, one disarmed, an arm: 3 times)
    between = [shown(e) + f" at t={e.t}" for e in by_gcs if abs(e.t * rate - round(e.t * rate)) > 1e-6]
    assert not between, between


@pytest.mark.parametrize("late", [0, 6])
def test_an_answer_to_a_wall_clock_state_after_lockstep_engages_again_is_counted_apart_not_stale(tmp_path, late):
    """A ground station's HOLD takes a lockstep flight onto the wall clock, where the vehicle sends a state each period
    that a controller answers as any other; its OFFBOARD again engages lockstep at the next period's start, so the
    answer to the last state sent on the wall clock can come after it. That answer is too late to fly but nobody's
    fault: it is counted in ``answered_wall_clock``, not refused as ``stale`` (docs/hostile-input.md: a target for a
    lockstep step already flown, a late or repeated datagram), which it was until the third wave's thirty-ninth
    session. An answer to a lockstep step long flown is still ``stale``. ``late``: the controller reads that many more
    states of the wall clock before the OFFBOARD (a loaded machine) and answers that backlog after it. Until the
    forty-fourth session this answered the three states after ``wall`` whatever step lockstep engaged at: OFFBOARD taken
    more than three periods later (the test's process held 60 ms), all three were wall-clock states, none flew, and
    ``accepted`` stayed 4 (``late`` 6 failed so every time)."""
    rate = 50.0
    period = round(1e6 / rate)  # us
    with _gcs_and_controller(tmp_path, rate) as links:
        v, ctl, sysid, gcs_says, hold, offboard = links.v, links.ctl, links.sysid, links.gcs_says, HOLD, OFFBOARD

        def answer(usec: int) -> None:
            ctl.mav.set_actuator_control_target_send(usec, 0, sysid, 1, HOVER_WIRE)

        def state_after(usec: int) -> int:
            """The stamp of the first state sent after the one stamped ``usec``."""
            while True:
                m = ctl.recv_match(type="ODOMETRY", blocking=True, timeout=5)
                assert m is not None
                if m.time_usec > usec:
                    return m.time_usec

        ctl.mav.command_long_send(sysid, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
        assert command_ack(ctl, M.MAV_CMD_COMPONENT_ARM_DISARM).result == M.MAV_RESULT_ACCEPTED
        t = -1
        while t < 3 * period:  # lockstep: steps 0-3 flown on their answers
            t = state_after(t)
            answer(t)
        gcs_says(M.MAV_CMD_DO_SET_MODE, *hold)  # on the wall clock from the next step
        # a state sent on the wall clock, left unanswered for now: the second after step 3's (the first, step 4's, may
        # be the one lockstep sent before the HOLD came)
        behind = [state_after(state_after(t))]
        for _ in range(late):  # the controller behind: ``late`` more states of the wall clock read, not yet answered
            behind.append(state_after(behind[-1]))
        wall = behind[0]
        gcs_says(M.MAV_CMD_DO_SET_MODE, *offboard)  # lockstep again (ACKed at the period's start it engages at)
        again = v.wait_report(Event, lambda e: e.kind == "mode" and e.mode == "offboard" and e.by is not None
                              and e.by.link == "gcs")
        j = round(again.t * rate)  # the step lockstep engaged at: its state the first one sent in lockstep again
        assert behind[-1] < j * period, (behind, j)
        answer(wall)  # its answer, late
        answer(period)  # an answer to step 1, flown in lockstep long ago
        for k in behind[1:]:  # the rest of the controller's backlog
            answer(k)
        k = state_after(behind[-1])
        while k <= (j + 2) * period:  # every newer state answered, as the controller does: the wall clock's left, if
            answer(k)  # any, then steps j, j + 1 and j + 2 in lockstep
            k = state_after(k)
        ctl.mav.command_long_send(sysid, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 0, 21196, 0, 0, 0, 0, 0)
        assert command_ack(ctl, M.MAV_CMD_COMPONENT_ARM_DISARM).result == M.MAV_RESULT_ACCEPTED
    s = _stats(v)
    # step 1's answer is stale, or, had step 1's state been resent (unanswered 50 ms on a loaded machine), expected
    assert s["rejected"] == {"stale": 1} or (s["rejected"] == {} and s["answered_again"] >= 1), s
    # every answer to a state of the wall clock, from ``wall``'s to step j's, counted apart; steps j to j + 2 flown
    assert s["answered_wall_clock"] == j - wall // period and s["accepted"] >= 4 + 3, (j, wall // period, s)


def test_mavproxy_arms_through_stdin(tmp_path):
    """MAVProxy, unmodified, as the issue runs it: heartbeat and attitude seen, and
    ``arm throttle`` typed into it is ACKed and arms the vehicle. Stopped, it ends itself (exit 1, its modules
    unloaded: its stdin closed, tests/sitlkit.py ``MavProxy.stop``); until the third wave's thirty-ninth session
    the kit typed ``exit`` (no command to it) and sent SIGTERM (a flag it reads between lines of stdin), and a
    MAVProxy that had read the line first was SIGKILLed 5 s later."""
    with instance_slot() as n:
        v = _vehicle(n, tmp_path / "v")
        mp = MavProxy(f"udpin:127.0.0.1:{GCS_PORT + n}", tmp_path)
        say = mp.say
        try:
            mp.wait_online()
            deadline = time.monotonic() + 20
            while True:  # "status" lists what MAVProxy has received so far: ask until attitude is in it
                say("status")
                try:
                    mp.wait_line(lambda s: "ATTITUDE {" in s, timeout=1)
                    break
                except AssertionError:
                    assert time.monotonic() < deadline, "MAVProxy never listed ATTITUDE"
            mp.wait_line(lambda s: "HEARTBEAT {" in s and "type : 2" in s, timeout=5)
            say("arm throttle")
            mp.wait_line(lambda s: "COMPONENT_ARM_DISARM: ACCEPTED" in s, timeout=15)
            mp.wait_line(lambda s: s.strip().endswith("ARMED") and "DISARMED" not in s, timeout=15)
        finally:
            stopped = mp.stop()
            assert v.stop() == 0
    assert stopped == 1, "\n".join(mp.lines[-20:])  # (-9: killed)
    v.wait_event(lambda s: s.startswith("armed: armed"))


MAVSDK_SCRIPT = r"""
import json, math, sys, threading
from mavsdk import Mavsdk, Configuration, ComponentType
from mavsdk.plugins.action import Action
from mavsdk.plugins.telemetry import Telemetry

sdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
out = {"connect": str(sdk.add_any_connection(sys.argv[1]))}
system = sdk.first_autopilot(30.0)
out["found"] = system is not None
tel, act = Telemetry(system), Action(system)
att, pos, armed = threading.Event(), threading.Event(), threading.Event()
seen = {}
def on_att(a, ud=None):
    if math.isfinite(a.roll_deg):
        seen["att"] = (a.roll_deg, a.pitch_deg, a.yaw_deg); att.set()
def on_pos(p, ud=None):
    if math.isfinite(p.latitude_deg):
        seen["pos"] = (p.latitude_deg, p.longitude_deg, p.relative_altitude_m); pos.set()
def on_armed(a, ud=None):
    if a:
        armed.set()
tel.subscribe_attitude_euler(on_att)
tel.subscribe_position(on_pos)
tel.subscribe_armed(on_armed)
out["attitude"] = att.wait(30) and seen["att"]
out["position"] = pos.wait(30) and seen["pos"]
out["arm"] = act.arm().name
out["armed_seen"] = armed.wait(10)
out["disarm"] = act.disarm().name
print("RESULT " + json.dumps(out), flush=True)
sdk.destroy()
"""


def test_mavsdk_finds_reads_arms_disarms(tmp_path):
    """MAVSDK 4's native binding, unmodified: finds the vehicle, reads attitude and position,
    arms and disarms it. In its own process: the native library keeps threads of its own."""
    with instance_slot() as n:
        v = _vehicle(n, tmp_path)
        try:
            r = run_script("-c", MAVSDK_SCRIPT, f"udpin://127.0.0.1:{GCS_PORT + n}", timeout=120, env=ENV)
        finally:
            assert v.stop() == 0
    out = script_result(r)
    assert out["found"]
    assert out["attitude"] == [0.0, 0.0, 0.0]
    lat, lon, alt = out["position"]
    assert math.isclose(lat, 47.397742, abs_tol=1e-6) and math.isclose(lon, 8.545594, abs_tol=1e-6)
    assert abs(alt) < 0.01
    assert out["arm"] == "SUCCESS" and out["armed_seen"] and out["disarm"] == "SUCCESS"
    # MAVSDK asks for messages and capabilities on connect: every command was answered
    log = mavutil.mavlink_connection(str(tmp_path / "vehicle.tlog"), dialect="common")
    asked, acked = set(), set()
    while (m := log.recv_match(type=["COMMAND_LONG", "COMMAND_INT", "COMMAND_ACK"])) is not None:
        (acked if m.get_type() == "COMMAND_ACK" else asked).add(m.command)
    assert asked and asked <= acked, f"unanswered commands: {asked - acked}"


@pytest.mark.parametrize("args, names", [
    (["vehicle", "--listen", "nowhere"], "--listen"),
    (["vehicle", "--gcs", "127.0.0.1:notaport"], "--gcs"),
    (["vehicle", "--speed", "-1"], "--speed"),
    (["vehicle", "--realtime", "--speed", "3"], "--speed"),  # as bsst sitl refuses it (it was taken)
    (["vehicle", "--instance", "10"], "--instance"),
    (["vehicle", "--home", "47,8"], "--home"),
    (["vehicle", "--controller-id", "200"], "--controller-id"),
    (["vehicle", "--listen", "udpout:127.0.0.1:14560"], "--listen"),
    (["vehicle", "missions/nope.toml"], "nope.toml"),
    (["controller", "missions/sine.toml", "--vehicle", "udpin:127.0.0.1:5"], "--vehicle"),
    (["controller", "missions/sine.toml", "--timeout", "0"], "--timeout"),
    (["sitl", "missions/sine.toml", "--instance", "12"], "--instance"),
    (["sitl", "missions/sine.toml", "--gcs", "udpin:x"], "--gcs"),
    (["sitl", "missions/sine.toml", "--realtime", "--speed", "nan"], "--speed"),
])
def test_bad_input_is_one_line_exit_2(args, names):
    r = run_bsst(*args, cwd=ROOT, timeout=60)
    assert r.returncode == 2, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and names in r.stderr, r.stderr
    assert "Traceback" not in r.stderr


def test_port_in_use_is_bad_input(tmp_path):
    with instance_slot() as n:
        v = _vehicle(n, tmp_path)
        try:
            r = run_bsst("vehicle", "--instance", str(n), timeout=60)
        finally:
            v.stop()
    assert r.returncode == 2 and "--listen" in r.stderr and "in use" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1


def test_would_be_controllers_get_back_no_more_bytes_than_they_sent(tmp_path):
    """Issue 22, defect 9: before any flight a bare ``bsst vehicle`` (no ``--controller-from``) cannot know
    its controller, and each new address claiming the controller's ids (200:191) is a would-be controller.
    200 of them, each sending one PARAM_REQUEST_LIST (14 bytes; the answer is every PARAM_VALUE, 259 bytes),
    get back together at most the bytes they sent plus one frame (docs/hostile-input.md, "Load shedding": a
    flood is not amplified); the excess is refused (``reply_limited``). A real controller still connects afterwards:
    its ARM is ACCEPTED and its states come."""
    from tests.hostile import Station  # noqa: PLC0415 - a test helper only this test needs

    with instance_slot() as n:
        v = _vehicle(n, tmp_path, "--gcs", "none")
        to = (n + 1, 1)
        would_be = [Station((200, 191), ("127.0.0.1", LINK_PORT + n)) for _ in range(200)]
        try:
            sent = sum(len(s.send(M.MAVLink_param_request_list_message(*to))) for s in would_be)
            ctl = Station((200, 191), ("127.0.0.1", LINK_PORT + n))  # after them on the vehicle's one socket
            ctl.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1.0, target=to)
            assert ctl.ack(M.MAV_CMD_COMPONENT_ARM_DISARM) == M.MAV_RESULT_ACCEPTED
            ctl.wait(lambda m: m.get_type() == "ODOMETRY", 10, "the controller's first state")
            back = 0
            for s in would_be:
                while True:
                    try:
                        back += len(s.sock.recv(65535))
                    except BlockingIOError:
                        break
            ctl.close()
        finally:
            for s in would_be:
                s.close()
            assert v.stop() == 0
    stats = _stats(v)
    print(f"200 would-be controllers: sent {sent} B, got back {back} B; refused {stats['rejected']}")
    assert sent == 200 * 14
    assert back <= sent + MAX_FRAME, (back, sent)  # before: 56 266 bytes back
    assert stats["rejected"].get("reply_limited", 0) >= 180, stats["rejected"]


def test_a_disarm_in_the_air_is_refused_as_px4s_saying_why_and_a_forced_one_is_taken():
    """A ground station's disarm in the air without PX4's force (param2 21196): TEMPORARILY_REJECTED with PX4's
    commander's "Disarming denied: not landed" (it was DENIED with no reason given); forced, ACCEPTED. (A vehicle in
    this process, put 2 m up.)"""
    from bridge.core.flight import prepare
    from bridge.mavlink.endpoint import parse_address
    from bridge.nodes.vehicle import Vehicle, VehicleConfig
    from missions import Mission, Sine
    from tests.sitlkit import GcsSocket

    gcs = GcsSocket()
    v = Vehicle(prepare(Mission(Sine(), duration_s=5.0, name="air")),
                VehicleConfig(parse_address("udpin:127.0.0.1:0"), parse_address(gcs.url)))

    def disarm(p2: float) -> object:
        return mavlink.MAVLink_command_long_message(1, 1, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 0, p2, 0, 0, 0, 0, 0)

    try:
        v.sim.arm()
        v.sim.plant.state = (0.0, 0.0, 0.0, 0.0, 2.0, 0.0) + (0.0,) * 6
        assert v.sim.armed and not v.sim.plant.on_ground
        seen = gcs.exchange_until(v, disarm(0.0), lambda m: m.get_type() == "STATUSTEXT" and "Disarming" in m.text,
                                  "the refusal's text")
        assert [m.result for m in seen if m.get_type() == "COMMAND_ACK"] == [mavlink.MAV_RESULT_TEMPORARILY_REJECTED]
        assert [m.text for m in seen if m.get_type() == "STATUSTEXT" and "Disarming" in m.text] == [
            "Disarming denied: not landed"]
        assert v.sim.armed
        assert gcs.exchange(v, disarm(21196.0), "COMMAND_ACK").result == mavlink.MAV_RESULT_ACCEPTED
        assert not v.sim.armed
    finally:
        v.close()
        gcs.close()
