"""Covers bridge.nodes.vehicle.announcer and bridge.nodes.offboard.link: the EVENT contract between processes.

A real ``bsst vehicle`` says each event as STATUSTEXT (kept for ground stations) and as a typed EVENT (id per kind,
sequence +1 per event), sends CURRENT_EVENT_SEQUENCE with its 1 Hz HEARTBEAT and answers REQUEST_EVENT. A real
``bsst controller`` decides "failsafe" from the EVENT's id, whatever a STATUSTEXT says or does not say.
"""

from __future__ import annotations

import time
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import common as M

from bridge.mavlink import events as ev
from bridge.nodes.report import Done, parse_line
from bridge.session import instance_slot
from tests.sitlkit import Proc
from tests.test_offboard_realtime import MISSION, RATE, ScriptedVehicle
from tests.test_vehicle import _gcs, _vehicle

pytestmark = pytest.mark.process  # starts processes or opens sockets: not in make test-fast


def test_a_real_vehicle_sends_each_event_as_a_numbered_event_and_resends_on_request(tmp_path: Path) -> None:
    with instance_slot() as n:
        gcs = _gcs(n)
        v = _vehicle(n, tmp_path)
        try:
            assert gcs.wait_heartbeat(timeout=20) is not None
            cur = gcs.recv_match(type="CURRENT_EVENT_SEQUENCE", blocking=True, timeout=10)
            assert cur is not None and cur.get_srcSystem() == n + 1
            arm = M.MAV_CMD_COMPONENT_ARM_DISARM
            got: list = []  # every EVENT received, in order (recv_match drops what it does not match)

            def until(what: str, pred) -> None:
                deadline = time.monotonic() + 10
                while time.monotonic() < deadline:
                    m = gcs.recv_match(blocking=True, timeout=1)
                    if m is not None and m.get_type() == "EVENT":
                        got.append(m)
                    if m is not None and pred(m):
                        return
                raise AssertionError(f"no {what}")

            for p1 in (1, 0):
                gcs.mav.command_long_send(n + 1, 1, arm, 0, p1, 0, 0, 0, 0, 0, 0)
                until("COMMAND_ACK", lambda m: m.get_type() == "COMMAND_ACK" and m.command == arm)
            v.wait_event(lambda s: s.startswith("disarmed: "))
            kinds = [s.partition(":")[0] for s in v.events()]
            until(f"{len(kinds)} EVENTs", lambda m: len(got) >= len(kinds))
            assert [ev.received_id(m) for m in got] == [ev.event_id(k) for k in kinds], (kinds, got)
            assert [m.sequence for m in got] == list(range(len(kinds)))  # the first event is 0, then +1 each
            assert all(m.log_levels == ev.log_levels(M.MAV_SEVERITY_INFO) for m in got)
            gcs.mav.send(ev.MAVLink_request_event_message(n + 1, 1, 0, 0))
            again = gcs.recv_match(type="EVENT", blocking=True, timeout=10)
            assert again is not None and (again.sequence, again.id) == (0, got[0].id)
            gcs.mav.send(ev.MAVLink_request_event_message(n + 1, 1, 500, 500))  # never sent
            err = gcs.recv_match(type="RESPONSE_EVENT_ERROR", blocking=True, timeout=10)
            assert err is not None and (err.sequence, err.reason, err.target_system) == (500, 0, 255)
        finally:
            gcs.close()
            assert v.stop() == 0


def _controller_against(tmp: Path, event: bool, text: bytes | None) -> Done:
    """A real-time ``bsst controller`` against a scripted vehicle that arms, streams resting states, and at step 10
    disarms in its failsafe as PX4's ``disarm`` action does (HEARTBEAT never CRITICAL), saying it with an EVENT
    FAILSAFE (``event``) and/or a CRITICAL STATUSTEXT ``text``; then streams on. The controller's Done report."""
    (tmp / "m.toml").write_text(MISSION)
    v = ScriptedVehicle()
    ctl = Proc.bsst("controller", str(tmp / "m.toml"), "--realtime", "--vehicle", f"127.0.0.1:{v.port}",
                    "--timeout", "30")
    try:
        deadline = time.monotonic() + 60
        while not v.armed and time.monotonic() < deadline:
            v.serve() if v.peer is None else v.heartbeat()
            v.until(time.monotonic() + 0.05)
        assert v.armed, "never armed"
        k, t0 = 0, time.monotonic()
        while ctl.p.poll() is None and time.monotonic() < deadline:
            v.until(t0 + k / RATE)
            v.odometry(k)
            if k == 10:
                if text is not None:
                    v.send(M.MAVLink_statustext_message(M.MAV_SEVERITY_CRITICAL, text))
                if event:
                    v.send(ev.MAVLink_event_message(0, 0, int(ev.EventId.FAILSAFE), 200, 0,
                                                    ev.log_levels(M.MAV_SEVERITY_CRITICAL), [0] * ev.ARGUMENTS))
                v.armed = False
                v.heartbeat()
            k += 1
        ctl.p.wait(timeout=30)
    finally:
        ctl.stop()
        v.sock.close()
    done = [r for r in map(parse_line, ctl.lines) if isinstance(r, Done)]
    assert len(done) == 1, ctl.lines[-5:]
    return done[0]


@pytest.mark.parametrize("text", [None, b"something else entirely"], ids=["no-text", "other-text"])
def test_the_controller_decides_failsafe_from_the_event_id_not_the_text(tmp_path: Path, text: bytes | None) -> None:
    done = _controller_against(tmp_path, True, text)
    assert (done.outcome, done.reason) == ("failsafe", "the vehicle's failsafe took over (its EVENT FAILSAFE)")


def test_a_failsafe_text_without_its_event_is_no_failsafe_to_the_controller(tmp_path: Path) -> None:
    done = _controller_against(tmp_path, False, b"failsafe: no actuator target for 0.5 s: stop the motors")
    assert done.outcome == "aborted", done
