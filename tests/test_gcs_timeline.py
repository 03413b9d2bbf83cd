"""Covers bridge.nodes.vehicle.commander, bridge.autopilot.flightstart and bridge.nodes.vehicle.verdict: a flight
flown by a ground station alone flies the mission's timeline from its takeoff (bridge.autopilot.simvehicle's clock;
an arm that leaves the vehicle on the ground flies nothing), and a vehicle stopped before an event says it never
flew it.

A real ``bsst vehicle --realtime`` on 127.0.0.1 with no controller at all, flown by a pymavlink ground station as
QGroundControl flies PX4: NAV_TAKEOFF, then an arm (armed in TAKEOFF, the vehicle's own controller flies). Its
mission's ``[[events]]`` act at their time of that flight, counted from the arm's control step (docs/weather.md, "In
real time"); until the forty-fourth session the real-time vehicle held its timeline (and its gusts and disturbance)
until a controller's first target, which such a flight never sends: the events never acted and nothing said so.
Then (f546137) its clock started at the first arm from a ground station, whatever came of it: an arm in HOLD on the
ground, disarmed at once, spent the timeline on a vehicle that sat there.
"""

from __future__ import annotations

import math
import signal
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest
from pymavlink.dialects.v20 import common as mavlink

from bridge.nodes.report import Event, Ready, parse_line
from bridge.session import instance_slot
from tests.gcskit import command_ack as _ack
from tests.gcskit import gcs_link as _gcs
from tests.sitlkit import ROOT, Proc, controller_exit
from tests.test_inject import _inject
from tests.test_vehicle import HOLD, _controller_link

pytestmark = pytest.mark.process  # starts processes or opens sockets: not in make test-fast

M = mavlink
RATE_HZ = 50.0  # a coarse control period (20 ms) keeps the real-time vehicle light on a busy machine
# wind steps at 1 s and 6 s of the flight; the test stops the vehicle between them
WINDY = (f'name = "gcswind"\nduration_s = 10.0\nrate_hz = {RATE_HZ}\n[trajectory]\nkind = "sine"\namplitude = 0.0\n'
         '[[events]]\nt_s = 1.0\nkind = "wind"\nspeed_mps = 2.0\n'
         '[[events]]\nt_s = 6.0\nkind = "wind"\nspeed_mps = 4.0\nfrom_deg = 90.0\n')


@contextmanager
def _flown_by_a_gcs(mission: Path, *flags: str) -> Iterator[tuple[int, Proc, Any]]:
    """A real ``bsst vehicle MISSION --realtime FLAGS`` on a free instance and a pymavlink ground station on its
    ground-station port, the vehicle ready and heard (its HEARTBEAT): the instance, the vehicle, the ground station.
    The ground station closed and the vehicle stopped (if it still runs) at the end, however the test ended."""
    with instance_slot() as n:
        gcs = _gcs(n)
        v = Proc.bsst("vehicle", str(mission), "--realtime", "--instance", str(n), *flags, cwd=ROOT)
        try:
            v.wait_report(Ready, timeout=60)
            assert gcs.wait_heartbeat(timeout=20) is not None
            yield n, v, gcs
        finally:
            gcs.close()
            v.stop()


def _events(v: Proc) -> list[Event]:
    return [r for r in map(parse_line, v.lines) if isinstance(r, Event)]


def _take_off(gcs: Any) -> None:
    """A ground station's takeoff as QGroundControl's: NAV_TAKEOFF (the vehicle's own height), then an arm; each
    accepted."""
    tgt = (gcs.target_system, gcs.target_component)
    gcs.mav.command_long_send(*tgt, M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, math.nan, math.nan, math.nan, math.nan)
    assert _ack(gcs, M.MAV_CMD_NAV_TAKEOFF).result == M.MAV_RESULT_ACCEPTED
    gcs.mav.command_long_send(*tgt, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
    assert _ack(gcs, M.MAV_CMD_COMPONENT_ARM_DISARM).result == M.MAV_RESULT_ACCEPTED


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
    with _flown_by_a_gcs(mission) as (_, v, gcs):
        # the vehicle's plant has run 1.5 s on the ground (its time_boot_ms: simulation time) when the flight begins
        ran = gcs.recv_match(type="ATTITUDE", blocking=True, timeout=30, condition="ATTITUDE.time_boot_ms >= 1500")
        assert ran is not None
        _take_off(gcs)
        wind = v.wait_report(Event, lambda e: e.kind == "wind", timeout=30)
        v.p.send_signal(signal.SIGINT)
        status = v.p.wait(timeout=30)
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


def test_a_flight_whose_time_0_never_came_says_its_failsafe_not_its_timeline(tmp_path: Path) -> None:
    """A real-time vehicle armed by its controller (a pymavlink one, on the controller link), which then sends no
    target, as one that died after its arm: the flight's time 0 never comes, and the vehicle's failsafe stops the
    motors on the ground. Stopped (Ctrl-C), the vehicle says the failsafe ended its flight, exit 1, and nothing of its
    timeline: no flight began, so none was asked of it (an arm is not a flight, bridge.autopilot.flightstart). From
    the forty-fourth session to 2026-12-07 it also said each event `not reached: ...: its flight's time 0 never
    came`."""
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
            v.wait_report(Event, lambda e: e.kind == "disarmed", timeout=30)
            v.p.send_signal(signal.SIGINT)
            status = v.p.wait(timeout=30)
        finally:
            ctl.close()
            v.stop()
    said = [ln for ln in v.lines if ln.startswith("bsst vehicle")]
    assert status == 1 and len(said) == 1 and said[0].startswith("bsst vehicle: failsafe at t="), said


# wind steps at 1 s and 2.5 s of a 3 s flight
SHORT = (f'name = "gcsshort"\nduration_s = 3.0\nrate_hz = {RATE_HZ}\n[trajectory]\nkind = "sine"\namplitude = 0.0\n'
         '[[events]]\nt_s = 1.0\nkind = "wind"\nspeed_mps = 2.0\n'
         '[[events]]\nt_s = 2.5\nkind = "wind"\nspeed_mps = 4.0\nfrom_deg = 90.0\n')


def _arm_in_hold_and_disarm(v: Proc, gcs: object) -> Event:
    """The ground station selects HOLD and arms (armed in HOLD on the ground: nothing flies), then disarms at once,
    and the vehicle's plant runs on 1.5 s after the arm; the vehicle's ``armed`` event."""
    tgt = (gcs.target_system, gcs.target_component)  # type: ignore[attr-defined]
    for command, params in ((M.MAV_CMD_DO_SET_MODE, HOLD), (M.MAV_CMD_COMPONENT_ARM_DISARM, (1,)),
                            (M.MAV_CMD_COMPONENT_ARM_DISARM, (0,))):
        gcs.mav.command_long_send(*tgt, command, 0, *params, *(0,) * (7 - len(params)))  # type: ignore[attr-defined]
        assert _ack(gcs, command).result == M.MAV_RESULT_ACCEPTED
    armed = v.wait_report(Event, lambda e: e.kind == "armed", timeout=30)
    v.wait_report(Event, lambda e: e.kind == "disarmed", timeout=30)
    assert armed.text == "armed, HOLD", armed
    # then 1.5 s of the vehicle's time (its time_boot_ms: simulation time), past the 1 s event's time from the arm
    later = f"ATTITUDE.time_boot_ms >= {round(armed.t * 1000) + 1500}"
    assert gcs.recv_match(type="ATTITUDE", blocking=True, timeout=30, condition=later) is not None  # type: ignore
    return armed


def test_an_arm_on_the_ground_flies_nothing_a_controllers_flight_after_it_flies_the_timeline(tmp_path: Path) -> None:
    """No controller at first: the ground station arms the vehicle in HOLD and disarms it at once (nothing flew);
    1.5 s later a real ``bsst controller --realtime`` flies the 3 s mission. The wind events at 1 s and 2.5 s act
    1 s and 2.5 s into the controller's flight (its first target, just after its arm), and both processes exit 0,
    nothing said (the controller 1 for a stall of its ticks alone, on a loaded machine). On the old code (f546137)
    the arm in HOLD started the clock: both winds acted while the vehicle sat disarmed (1.02 s and 2.52 s after the
    vehicle's start), before the controller even armed, and nothing said so."""
    mission = tmp_path / "gcsshort.toml"
    mission.write_text(SHORT)
    with _flown_by_a_gcs(mission) as (n, v, gcs):
        _arm_in_hold_and_disarm(v, gcs)
        ctl = Proc.bsst("controller", str(mission), "--realtime", "--instance", str(n), cwd=ROOT)
        try:
            status = ctl.p.wait(timeout=90)
            first = v.wait_report(Event, lambda e: e.kind == "wind", timeout=30)
            v.wait_report(Event, lambda e: e.kind == "wind" and e.t > first.t, timeout=30)
            v.p.send_signal(signal.SIGINT)
            v_status = v.p.wait(timeout=30)
        finally:
            ctl.stop()
    events = _events(v)
    said = [ln for ln in v.lines if ln.startswith("bsst vehicle")]
    armed = [e for e in events if e.kind == "armed"]
    assert [e.text for e in armed] == ["armed, HOLD", "armed, offboard control"], armed
    flown = armed[1].t  # the controller's arm; its first target, time 0, follows within a few periods
    w1, w2 = [e for e in events if e.kind == "wind"]
    assert (w1.text, w2.text) == ("steady wind 2 m/s from 0 deg", "steady wind 4 m/s from 90 deg")
    # time 0 is the first target's state: after the arm, by the controller's first answers (2 to 6 periods here)
    assert 1.0 - 1e-6 <= w1.t - flown < 2.0, (flown, w1.t)
    assert w2.t - w1.t == pytest.approx(1.5, abs=1e-6), (w1.t, w2.t)
    assert status == controller_exit(ctl.lines), "\n".join(ctl.lines[-12:])  # (1 for a stall of its ticks alone)
    assert v_status == 0 and said == [], "\n".join(v.lines[-12:])


def test_an_arm_in_hold_disarmed_then_a_takeoff_flies_the_timeline_from_the_takeoff(tmp_path: Path) -> None:
    """The ground station arms the vehicle in HOLD on the ground and disarms it (nothing flew), and 1.5 s of the
    vehicle's time after that arm takes off (NAV_TAKEOFF, then an arm: TAKEOFF): the wind event at 1 s acts 1 s into
    that takeoff (within a control period of it), not 1 s after the arm in HOLD; stopped before the 6 s event, the
    vehicle says that one never flew, exit 1. On the old code (f546137) the 1 s wind acted on the ground, 1 s after
    the arm in HOLD, before the takeoff (the 6 s one then 4.5 s into the real flight; a review found it with 4 s)."""
    mission = tmp_path / "gcswind.toml"
    mission.write_text(WINDY)
    period = 1.0 / RATE_HZ
    with _flown_by_a_gcs(mission) as (_, v, gcs):
        held = _arm_in_hold_and_disarm(v, gcs)
        _take_off(gcs)
        v.wait_report(Event, lambda e: e.kind == "armed" and e.t > held.t, timeout=30)
        wind = v.wait_report(Event, lambda e: e.kind == "wind", timeout=30)
        v.p.send_signal(signal.SIGINT)
        status = v.p.wait(timeout=30)
    events = _events(v)
    said = [ln for ln in v.lines if ln.startswith("bsst vehicle")]
    armed = [e for e in events if e.kind == "armed"]
    assert [e.text for e in armed] == ["armed, HOLD", "armed, TAKEOFF"], armed
    takeoff = armed[1]
    assert takeoff.t >= held.t + 1.5, (held.t, takeoff.t)
    assert 1.0 - 1e-6 <= wind.t - takeoff.t < 1.0 + period + 1e-6, (held.t, takeoff.t, wind.t)
    assert [e.text for e in events if e.kind == "wind"] == ["steady wind 2 m/s from 0 deg"]
    assert status == 1 and len(said) == 1, v.lines[-5:]
    assert said[0].startswith("bsst vehicle: not reached: t=6.000 s: steady wind 4 m/s from 90 deg: the vehicle "
                              "stopped at t="), said


def test_a_flight_its_plant_ended_says_its_timeline_was_cut_there_not_at_the_stop(tmp_path: Path) -> None:
    """A ground station's flight of an x500 (NAV_TAKEOFF, arm) whose motors it turns off (MAV_CMD_INJECT_FAILURE,
    all motors, once the wind at 1 s has blown): the plant ends the flight (it crashes, or diverges first) and is
    stepped no more. Stopped after (Ctrl-C), the vehicle says the event at 6 s was never flown because its plant ended
    the flight, at that end's time of its flight: until this test it said ``the vehicle stopped at t=…`` with the
    end's time, as if the user had stopped it there (a MAVSDK tour: ``diverged at t=8.080 s``, then ``not reached:
    t=15.000 s: …: the vehicle stopped at t=2.040 s of its flight's time``, the process stopped seconds later)."""
    mission = tmp_path / "gcswind.toml"
    mission.write_text(WINDY)
    with _flown_by_a_gcs(mission, "--profile", "x500", "--param", "SYS_FAILURE_EN=1") as (_, v, gcs):
        _take_off(gcs)
        v.wait_report(Event, lambda e: e.kind == "wind", timeout=30)
        assert _inject(gcs, M.FAILURE_UNIT_SYSTEM_MOTOR, M.FAILURE_TYPE_OFF, 0) == M.MAV_RESULT_ACCEPTED
        end = v.wait_report(Event, lambda e: e.kind in ("crashed", "diverged"), timeout=30)
        v.p.send_signal(signal.SIGINT)
        status = v.p.wait(timeout=30)
    armed = next(e for e in _events(v) if e.kind == "armed")
    said = [ln for ln in v.lines if ln.startswith("bsst vehicle")]
    assert status == 1 and said[0].startswith(f"bsst vehicle: {end.kind} at t={end.t:.3f} s"), said
    head, tail = ("bsst vehicle: not reached: t=6.000 s: steady wind 4 m/s from 90 deg: its plant ended the flight "
                  "at t=", f" s of its flight's time ({end.kind} at t={end.t:.3f} s)")
    assert len(said) == 2 and said[1].startswith(head) and said[1].endswith(tail), said
    flown = float(said[1][len(head):-len(tail)])  # the end's time of the flight: time 0 is a step at or after the arm
    assert end.t - armed.t - 1.0 / RATE_HZ - 2e-3 <= flown <= end.t - armed.t + 2e-3, (armed.t, end.t, flown)


def test_an_ekf_vehicle_armed_in_hold_on_the_ground_stays_there_until_com_disarm_prflt_disarms_it(
        tmp_path: Path) -> None:
    """A real ``bsst vehicle --realtime`` with an EKF (gnss set), its height estimate ~0.3 m above the ground at the
    start, armed by a pymavlink ground station in HOLD on the ground (a landed HOLD: motors idle, as PX4) stays
    there: every EXTENDED_SYS_STATE while armed says ON_GROUND (the plant's true state rests), until PX4's
    pre-takeoff timeout (COM_DISARM_PRFLT = 2 s) disarms it, an event saying so. On the old code the HOLD held the
    estimate's start height and lifted the vehicle ~0.3 m by itself: IN_AIR at once, and off the ground the
    timeout was dropped (never disarmed)."""
    mission = tmp_path / "gcsekf.toml"
    mission.write_text(f'name = "gcsekf"\nduration_s = 10.0\nrate_hz = {RATE_HZ}\n[trajectory]\nkind = "sine"\n'
                       'amplitude = 0.0\n[sensors]\nset = "gnss"\n[estimator]\nkind = "ekf"\n')
    with _flown_by_a_gcs(mission, "--param", "COM_DISARM_PRFLT=2") as (_, v, gcs):
        tgt = (gcs.target_system, gcs.target_component)
        for command, params in ((M.MAV_CMD_DO_SET_MODE, HOLD), (M.MAV_CMD_COMPONENT_ARM_DISARM, (1,))):
            gcs.mav.command_long_send(*tgt, command, 0, *params, *(0,) * (7 - len(params)))
            assert _ack(gcs, command).result == M.MAV_RESULT_ACCEPTED
        armed = v.wait_report(Event, lambda e: e.kind == "armed", timeout=30)
        landed, was_armed = [], False
        deadline = time.monotonic() + 30.0  # the disarm is due 2 s after the arm
        while time.monotonic() < deadline:
            m = gcs.recv_match(type=["HEARTBEAT", "EXTENDED_SYS_STATE"], blocking=True, timeout=5)
            assert m is not None, "no telemetry"
            if m.get_type() == "HEARTBEAT":
                now_armed = bool(m.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)
                if was_armed and not now_armed:
                    break
                was_armed = now_armed
            elif was_armed:
                landed.append(m.landed_state)
                assert m.landed_state == M.MAV_LANDED_STATE_ON_GROUND, landed
        else:
            pytest.fail(f"still armed 30 s after the arm in HOLD: {len(landed)} EXTENDED_SYS_STATE seen armed")
        disarmed = v.wait_report(Event, lambda e: e.kind == "disarmed", timeout=30)
    assert armed.text == "armed, HOLD", armed
    assert disarmed.text == "disarmed: no takeoff within COM_DISARM_PRFLT = 2 s of arming", disarmed
    assert 2.0 - 0.05 <= disarmed.t - armed.t < 2.0 + 2.0, (armed.t, disarmed.t)  # (its time runs on the wall's)
    assert len(landed) >= 10, landed  # 10 Hz for ~2 s armed
    hold = next(e for e in _events(v) if e.kind == "mode" and e.t >= armed.t)
    assert hold.text.endswith(": landed, idle until a takeoff"), hold


def test_a_controllers_arm_held_on_the_ground_by_a_ground_station_times_out_from_the_arm(tmp_path: Path) -> None:
    """A real ``bsst vehicle --realtime`` (COM_DISARM_PRFLT = 2 s) armed by a scripted controller (offboard, 200 /
    191), which answers its states for 1 s with idle targets (no thrust: on the ground), then a pymavlink ground
    station's HOLD before any lift-off (a landed HOLD, idle): PX4's pre-takeoff timeout runs from the arm (its
    commander counts from arming while landed, whatever the mode), so the vehicle disarms itself 2 s after the arm,
    1 s after the HOLD. Until the forty-fifth session the timeout ran from the HOLD: disarmed 3 s after the arm."""
    mission = tmp_path / "held.toml"
    mission.write_text(f'name = "held"\nduration_s = 10.0\nrate_hz = {RATE_HZ}\n[trajectory]\nkind = "sine"\n')
    idle = [0.0] * 8  # roll, pitch, yaw torques and thrust: nothing lifts it
    with instance_slot() as n:
        gcs, ctl = _gcs(n), _controller_link(n)
        v = Proc.bsst("vehicle", str(mission), "--realtime", "--instance", str(n), "--param", "COM_DISARM_PRFLT=2",
                      cwd=ROOT)
        try:
            v.wait_report(Ready, timeout=60)
            assert gcs.wait_heartbeat(timeout=20) is not None
            tgt = (gcs.target_system, gcs.target_component)
            ctl.mav.heartbeat_send(M.MAV_TYPE_ONBOARD_CONTROLLER, M.MAV_AUTOPILOT_INVALID, 0, 0, 4)
            assert ctl.recv_match(type="HEARTBEAT", blocking=True, timeout=20) is not None
            ctl.mav.command_long_send(*tgt, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
            assert _ack(ctl, M.MAV_CMD_COMPONENT_ARM_DISARM).result == M.MAV_RESULT_ACCEPTED
            answered_until = time.monotonic() + 1.0
            while time.monotonic() < answered_until:  # 1 s on the ground under the controller, each state answered
                m = ctl.recv_match(type="ODOMETRY", blocking=True, timeout=0.1)
                if m is not None:
                    ctl.mav.set_actuator_control_target_send(m.time_usec, 0, *tgt, idle)
            gcs.mav.command_long_send(*tgt, M.MAV_CMD_DO_SET_MODE, 0, *HOLD, 0, 0, 0, 0)
            assert _ack(gcs, M.MAV_CMD_DO_SET_MODE).result == M.MAV_RESULT_ACCEPTED
            disarmed = v.wait_report(Event, lambda e: e.kind == "disarmed", timeout=30)
        finally:
            gcs.close()
            ctl.close()
            v.stop()
    events = _events(v)
    armed = next(e for e in events if e.kind == "armed")
    hold = next(e for e in events if e.kind == "mode" and e.t >= armed.t)
    assert armed.text == "armed, offboard control" and hold.text.endswith(": landed, idle until a takeoff"), hold
    assert not any(e.kind == "failsafe" for e in events), events  # answered until the HOLD: no offboard loss
    assert hold.t - armed.t >= 0.9, (armed.t, hold.t)  # (the premise: the HOLD came a second into the arm)
    assert disarmed.text == "disarmed: no takeoff within COM_DISARM_PRFLT = 2 s of arming", disarmed
    assert 2.0 - 0.05 <= disarmed.t - armed.t < 2.5, (armed.t, hold.t, disarmed.t)  # (from the HOLD: 3 s)


def test_an_arm_in_hold_on_the_ground_that_never_flew_asks_nothing_of_the_timeline(tmp_path: Path) -> None:
    """timeline_not_reached, in process: a real-time vehicle (its time 0 held) armed in HOLD on the ground by a
    ground station and disarmed (by command, or by COM_DISARM_PRFLT: the same events), then stopped, never began a
    flight (flightstart: an arm is not one): no ``not reached`` line, so ``bsst vehicle`` exits 0. On the old code
    any ``armed`` event counted as a flight: both winds said `its flight's time 0 never came`, exit 1. A takeoff
    after it begins the flight, and the events it never reached are said again."""
    from bridge.core.flight import prepare  # (in process: the verdict of the vehicle's own events)
    from bridge.nodes.vehicle.verdict import timeline_not_reached

    mission = tmp_path / "gcswind.toml"
    mission.write_text(WINDY)
    v = prepare(mission).make_vehicle()
    v.hold_timeline()
    v.set_mode("hold")
    v.arm_in_mode()
    for _ in range(50):
        v.advance()
    v.disarm("disarmed: no takeoff within COM_DISARM_PRFLT = 1 s of arming")
    assert [e.kind for e in v.events if e.kind in ("armed", "disarmed")] == ["armed", "disarmed"]
    assert v.mission_t0 is None and timeline_not_reached(v) == []
    v.set_mode("takeoff")
    v.arm_in_mode()
    v.start_mission_clock_now()  # (the commander's, at a flight's begin: flightstart.flight_begun)
    v.advance()
    assert [line.split(": the vehicle stopped")[0] for line in timeline_not_reached(v)] == [
        "not reached: t=1.000 s: steady wind 2 m/s from 0 deg", "not reached: t=6.000 s: steady wind 4 m/s from 90 deg"]
