"""Covers bridge.nodes.vehicle.commander, bridge.autopilot.simvehicle and bridge.nodes.vehicle.verdict: a flight
flown by a ground station alone flies the mission's timeline from its arm, and a vehicle stopped before an event
says it never flew it.

A real ``bsst vehicle --realtime`` on 127.0.0.1 with no controller at all, flown by a pymavlink ground station as
QGroundControl flies PX4: NAV_TAKEOFF, then an arm (armed in TAKEOFF, the vehicle's own controller flies). Its
mission's ``[[events]]`` act at their time of that flight, counted from the arm's control step (docs/weather.md, "In
real time"); until the forty-fourth session the real-time vehicle held its timeline (and its gusts and disturbance)
until a controller's first target, which such a flight never sends: the events never acted and nothing said so.
"""

from __future__ import annotations

import math
import signal
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import common as mavlink

from bridge.nodes.report import Event, Ready, parse_line
from bridge.session import instance_slot
from tests.sitlkit import ROOT, Proc
from tests.test_vehicle import _ack, _controller_link, _gcs

pytestmark = pytest.mark.process  # starts processes or opens sockets: not in make test-fast

M = mavlink
RATE_HZ = 50.0  # a coarse control period (20 ms) keeps the real-time vehicle light on a busy machine
# wind steps at 1 s and 6 s of the flight; the test stops the vehicle between them
WINDY = (f'name = "gcswind"\nduration_s = 10.0\nrate_hz = {RATE_HZ}\n[trajectory]\nkind = "sine"\namplitude = 0.0\n'
         '[[events]]\nt_s = 1.0\nkind = "wind"\nspeed_mps = 2.0\n'
         '[[events]]\nt_s = 6.0\nkind = "wind"\nspeed_mps = 4.0\nfrom_deg = 90.0\n')


def _events(v: Proc) -> list[Event]:
    return [r for r in map(parse_line, v.lines) if isinstance(r, Event)]


def test_a_ground_stations_takeoff_flies_the_timeline_from_its_arm_and_says_what_it_never_reached(
        tmp_path: Path) -> None:
    """No controller: the ground station's NAV_TAKEOFF and arm, 1.5 s after the vehicle's start, fly the vehicle
    (TAKEOFF, then HOLD). The wind event at 1 s acts 1 s of the flight after the arm (not of the vehicle's start), at
    the control step that begins at or after it: within one period of the arm's time + 1 s (the arm acts between
    physics steps; time 0 is the next control period's start). Stopped (Ctrl-C) before the event at 6 s, the vehicle
    says it never flew it, on stderr, and exits 1 (the flight was not flown as asked). On the old code the first
    wind never came (the deadline failed)."""
    mission = tmp_path / "gcswind.toml"
    mission.write_text(WINDY)
    period = 1.0 / RATE_HZ
    with instance_slot() as n:
        gcs = _gcs(n)
        v = Proc.bsst("vehicle", str(mission), "--realtime", "--instance", str(n), cwd=ROOT)
        try:
            v.wait_report(Ready, timeout=60)
            assert gcs.wait_heartbeat(timeout=20) is not None
            # the vehicle's plant has run 1.5 s on the ground (its time_boot_ms: simulation time) when the flight begins
            ran = gcs.recv_match(type="ATTITUDE", blocking=True, timeout=30, condition="ATTITUDE.time_boot_ms >= 1500")
            assert ran is not None
            tgt = (gcs.target_system, gcs.target_component)
            gcs.mav.command_long_send(*tgt, M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, math.nan, math.nan, math.nan, math.nan)
            assert _ack(gcs, M.MAV_CMD_NAV_TAKEOFF).result == M.MAV_RESULT_ACCEPTED
            gcs.mav.command_long_send(*tgt, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
            assert _ack(gcs, M.MAV_CMD_COMPONENT_ARM_DISARM).result == M.MAV_RESULT_ACCEPTED
            wind = v.wait_event(lambda e: e.startswith("wind: "), timeout=30)
            v.p.send_signal(signal.SIGINT)
            status = v.p.wait(timeout=30)
        finally:
            gcs.close()
            v.stop()
    events = _events(v)
    said = [ln for ln in v.lines if ln.startswith("bsst vehicle")]
    armed = next(e for e in events if e.kind == "armed")
    assert armed.text == "armed, TAKEOFF" and armed.t >= 1.5, armed
    assert wind.text == "steady wind 2 m/s from 0 deg", wind
    assert 1.0 - 1e-6 <= wind.t - armed.t < 1.0 + period + 1e-6, (armed.t, wind.t)
    # time 0 is a control step's start: the event at 1 s acts at a step's start too
    assert abs(wind.t * RATE_HZ - round(wind.t * RATE_HZ)) < 1e-6, wind.t
    assert [e.text for e in events if e.kind == "wind"] == [wind.text]  # the 6 s one: never flown
    assert status == 1 and len(said) == 1, v.lines[-5:]
    assert said[0].startswith("bsst vehicle: not reached: t=6.000 s: steady wind 4 m/s from 90 deg: the vehicle "
                              "stopped at t="), said
    assert said[0].endswith(" s of its flight's time"), said


def test_a_flight_whose_time_0_never_came_says_its_timeline_was_never_flown(tmp_path: Path) -> None:
    """A real-time vehicle armed by its controller (a pymavlink one, on the controller link), which then sends no
    target, as one that died after its arm: the flight's time 0 never comes, and the vehicle's failsafe stops the
    motors on the ground. Stopped (Ctrl-C), the vehicle says the failsafe ended its flight and, for each event of its
    timeline, that it was never flown and why; exit 1. Until the forty-fourth session it said the failsafe alone:
    nothing named the events never flown."""
    mission = tmp_path / "gcswind.toml"
    mission.write_text(WINDY)
    with instance_slot() as n:
        ctl = _controller_link(n)
        v = Proc.bsst("vehicle", str(mission), "--realtime", "--instance", str(n), "--gcs", "none", cwd=ROOT)
        try:
            v.wait_report(Ready, timeout=60)
            ctl.mav.heartbeat_send(M.MAV_TYPE_ONBOARD_CONTROLLER, M.MAV_AUTOPILOT_INVALID, 0, 0, 4)
            assert ctl.recv_match(type="HEARTBEAT", blocking=True, timeout=20) is not None
            ctl.mav.command_long_send(n + 1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
            assert _ack(ctl, M.MAV_CMD_COMPONENT_ARM_DISARM).result == M.MAV_RESULT_ACCEPTED
            v.wait_event(lambda e: e.startswith("disarmed: "), timeout=30)
            v.p.send_signal(signal.SIGINT)
            status = v.p.wait(timeout=30)
        finally:
            ctl.close()
            v.stop()
    said = [ln for ln in v.lines if ln.startswith("bsst vehicle")]
    never = "its flight's time 0 never came (no controller's target, no ground station's flight)"
    assert status == 1 and said[0].startswith("bsst vehicle: failsafe at t="), "\n".join(v.lines[-12:])
    assert said[1:] == [f"bsst vehicle: not reached: t=1.000 s: steady wind 2 m/s from 0 deg: {never}",
                        f"bsst vehicle: not reached: t=6.000 s: steady wind 4 m/s from 90 deg: {never}"], said
