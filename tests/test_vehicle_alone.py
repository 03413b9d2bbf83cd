"""Covers bridge.nodes.vehicle.verdict and bridge.nodes.vehicle.node: ``bsst vehicle`` alone, its exit status.

``bsst vehicle`` run alone (docs/sitl.md, "Each side alone") serves until Ctrl-C or SIGTERM; stopped, it says on
stderr what its flights came to that was not a safe end and exits 1 (a crash, a divergence, a collision, a
termination, a failsafe its flight never came back from), as ``bsst controller`` alone says what it knows
(bridge.record.asked); a clean stop of a vehicle whose flights ended well exits 0, nothing said. A real-time
``bsst controller`` alone ends once its vehicle's failsafe has disarmed it (bridge.nodes.offboard.flight). Real
processes: ``bsst vehicle`` and ``bsst controller`` over UDP on 127.0.0.1; the stop a real SIGINT, sent once the
vehicle has reported the event the case waits for.
"""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path
from typing import Any

import pytest
from pymavlink.dialects.v20 import common as M

from bridge.autopilot.modes import OFFBOARD
from bridge.autopilot.vehicleevents import Event
from bridge.nodes.report import Event as ReportedEvent
from bridge.nodes.report import Ready, Stats, parse_line
from bridge.nodes.vehicle.verdict import flights_not_ended_well, start_not_flown
from bridge.record.halves import read_half
from bridge.session import instance_slot
from tests.gcskit import command_ack as _ack
from tests.gcskit import gcs_link as _gcs
from tests.gcskit import upload as _upload
from tests.gcskit import vehicle_of as _vehicle_of
from tests.sitlkit import ENV, ROOT, Proc, controller_exit, run_bsst
from tests.test_await_mission import _small_plan_items

pytestmark = pytest.mark.process  # starts processes or opens sockets: not in make test-fast

# a 1 s climb to 2 m, then the end landing; at MPC_LAND_SPEED 4 m/s it touches down hard (over 2 m/s): crashed
CLIMB = 'name = "climb2"\nduration_s = 1.0\n[trajectory]\nkind = "sine"\namplitude = 0.0\nclimb = 2.0\n'
HARD = "[params]\nMPC_LAND_SPEED = 4.0\n"


def _stats(lines: list[str]) -> dict[str, Any]:
    """A process's ``stats`` report (its last)."""
    return [r.values for r in map(parse_line, lines) if isinstance(r, Stats)][-1]


def _why(ctl: Proc, vehicle: Proc) -> str:
    """What a real-time controller's unexpected exit needs kept: every ``bsst controller`` line, its ``done`` report,
    the targets it sent and both sides' stalls (the mission's and, the controller's, those before its first state).
    This test failed once under load 9-15 with only ``ctl.lines[-5:]`` said, and that output was not kept; a
    controller descheduled ~0.5 s between its arm and its first target is one cause that gives that failure (the
    vehicle's COM_OF_LOSS_T failsafe, exit 1, no stall said: shown with SIGSTOP, docs/testing.md)."""
    said = [ln for ln in ctl.lines if ln.startswith("bsst controller") or '"report":"done"' in ln]
    c, v = ([r.values for r in map(parse_line, p.lines) if isinstance(r, Stats)][-1:] or [{}] for p in (ctl, vehicle))
    return "\n".join([*said, f"controller: targets sent {c[0].get('commands')}, stalls {c[0].get('stalls')}, before "
                                f"its first state {c[0].get('stalls_waiting')}; vehicle: stalls {v[0].get('stalls')}"])


def _stopped(vehicle: Proc) -> tuple[int, list[str]]:
    """SIGINT (a Ctrl-C) to the vehicle; its exit status and its stderr's own lines (``bsst vehicle: ...``: its
    stdout, merged here, is JSON reports)."""
    vehicle.p.send_signal(signal.SIGINT)
    status = vehicle.p.wait(timeout=30)
    vehicle.stop()  # (ended: reads what is left)
    return status, [ln for ln in vehicle.lines if ln.startswith("bsst vehicle")]


@pytest.mark.parametrize("hard", [True, False], ids=["crashed", "landed"])
def test_a_vehicle_alone_that_crashed_says_so_and_exits_1_a_healthy_one_0(tmp_path: Path, hard: bool) -> None:
    """``bsst vehicle`` and ``bsst controller`` alone, lockstep: the controller flies the climb and hands over the
    end landing; at 4 m/s the vehicle crashes on touchdown, at the default speed it lands and disarms. Stopped by a
    Ctrl-C: the crashed one says ``bsst vehicle: crashed at t=...`` and exits 1, the landed one says nothing and exits
    0. Until the third wave's forty-first session both exited 0, nothing on stderr."""
    mission = tmp_path / "climb2.toml"
    mission.write_text(CLIMB + (HARD if hard else ""))
    with instance_slot() as n:
        vehicle = Proc.bsst("vehicle", str(mission), "--instance", str(n), "--gcs", "none", cwd=ROOT)
        try:
            vehicle.wait_report(Ready, timeout=60)
            run_bsst("controller", str(mission), "--instance", str(n), cwd=ROOT, env=ENV, timeout=120)
            vehicle.wait_event(lambda e: e.startswith("crashed: " if hard else "disarmed: "), timeout=60)
            status, said = _stopped(vehicle)
        finally:
            vehicle.stop()
    if hard:
        assert status == 1 and len(said) == 1 and said[0].startswith("bsst vehicle: crashed at t="), vehicle.lines[-5:]
    else:
        assert (status, said) == (0, []), vehicle.lines[-5:]


def test_a_vehicle_alone_whose_flight_ended_in_its_failsafe_says_so_and_exits_1(tmp_path: Path) -> None:
    """The controller killed (SIGKILL) once the vehicle is armed under it: no more targets, the vehicle's failsafe
    takes over and ends the flight. Stopped by a Ctrl-C, the vehicle says ``bsst vehicle: failsafe at t=...: ...:
    its flight ended in it`` and exits 1 (until the third wave's forty-first session: 0, nothing said)."""
    mission = tmp_path / "climb2.toml"
    mission.write_text(CLIMB)
    with instance_slot() as n:
        vehicle = Proc.bsst("vehicle", str(mission), "--instance", str(n), "--gcs", "none", cwd=ROOT)
        ctl = None
        try:
            vehicle.wait_report(Ready, timeout=60)
            ctl = Proc.bsst("controller", str(mission), "--instance", str(n), cwd=ROOT)
            vehicle.wait_event(lambda e: e.startswith("armed: "), timeout=60)
            os.kill(ctl.p.pid, signal.SIGKILL)
            vehicle.wait_event(lambda e: e.startswith("failsafe: "), timeout=60)
            status, said = _stopped(vehicle)
        finally:
            if ctl is not None:
                ctl.stop()
            vehicle.stop()
    assert status == 1 and len(said) == 1, vehicle.lines[-5:]
    assert said[0].startswith("bsst vehicle: failsafe at t=") and said[0].endswith(
        ": its flight ended in it (no arm, no mode selected, took it back)"), said


# the x500 on its pack, read empty 1 s in: its battery failsafe lands it (COM_LOW_BAT_ACT 2) and disarms it 0.5 s
# after the touchdown, some 29 s before the mission's end
EMPTIED = ('name = "emptied"\nduration_s = 30.0\nprofile = "x500"\n[trajectory]\nkind = "sine"\n[effects]\n'
           'battery = true\n[params]\nCOM_LOW_BAT_ACT = 2\nCOM_DISARM_LAND = 0.5\n'
           '[[events]]\nt_s = 1.0\nkind = "battery"\nstate = "empty"\n')


def test_a_real_time_controller_alone_ends_once_the_vehicles_failsafe_has_disarmed_it(tmp_path: Path) -> None:
    """``bsst vehicle --realtime`` and ``bsst controller --realtime`` alone, a 30 s mission whose battery failsafe
    lands and disarms the vehicle ~2.5 s in: nothing is left to fly, so the controller ends within seconds of the
    vehicle's disarm (its own failsafe event, the ``bsst controller: failsafe: ...`` line naming when, exit 1),
    not at the mission's end. Until the third wave's forty-third session it waited out the other ~27 s of the
    mission's ticks (and ``bsst sitl --realtime`` waited for it: 20.7 s for such a 20 s mission, now 3.7 s)."""
    mission = tmp_path / "emptied.toml"
    mission.write_text(EMPTIED)
    with instance_slot() as n:
        vehicle = Proc.bsst("vehicle", str(mission), "--realtime", "--instance", str(n), "--gcs", "none", cwd=ROOT)
        ctl = None
        try:
            vehicle.wait_report(Ready, timeout=60)
            ctl = Proc.bsst("controller", str(mission), "--realtime", "--instance", str(n), cwd=ROOT)
            vehicle.wait_event(lambda e: e.startswith("disarmed: "), timeout=60)
            status = ctl.p.wait(timeout=10)  # (the mission's end is ~27 s away)
        finally:
            if ctl is not None:
                ctl.stop()
            vehicle.stop()
    said = [ln for ln in ctl.lines if ln.startswith("bsst controller: ")]
    assert status == 1 and said[0].startswith("bsst controller: failsafe: the vehicle's failsafe took over ("), said
    assert said[1].startswith("bsst controller: the vehicle's failsafe disarmed it by t=") and said[1].endswith(
        " s of the mission's 30 s, no [failsafe] resume to arm it again: nothing left to fly, so the controller "
        "ended there (not flown as asked)"), said
    # its word stamped when the failsafe took over (the vehicle's EVENT), as at a mission's end
    [took] = [r.t for r in map(parse_line, ctl.lines) if isinstance(r, ReportedEvent) and r.kind == "failsafe"]
    assert 1.0 <= took < 1.1, took


def test_a_controller_that_comes_late_flies_the_disturbance_from_the_flights_time_0(tmp_path: Path) -> None:
    """``bsst vehicle --realtime`` alone, its ``bsst controller --realtime`` started 1.6 s after its Ready (as a loaded
    machine started test_hostile's flood reference 1.66 s late), the robust mission cut to 1 s: its plant ran on the
    ground meanwhile, and yet the flight starts where the mission does (nothing pushed it before) and lifts off as a
    prompt one does, within 0.1 s of the flight's time 0 (the state its first target answers; plus any stall either
    side reported in those 0.1 s), its sine disturbance counted from that time 0 (docs/weather.md). Until
    the forty-third session: x 1.8e-4 m at the first row, lift-off 0.18 s in (offline 0.05 s) under the disturbance
    turned by half a period (the flaky flood reference, RMS 0.290 m for offline's 0.152)."""
    mission = tmp_path / "robust.toml"
    mission.write_text((ROOT / "missions" / "robust.toml").read_text().replace("duration_s = 30.0", "duration_s = 1.0"))
    with instance_slot() as n:
        vehicle = Proc.bsst("vehicle", str(mission), "--realtime", "--instance", str(n), "--gcs", "none",
                            "--out", str(tmp_path / "v"), cwd=ROOT)
        ctl = None
        try:
            vehicle.wait_report(Ready, timeout=60)
            time.sleep(1.6)  # the controller's late start itself, not a wait for something to happen
            ctl = Proc.bsst("controller", str(mission), "--realtime", "--instance", str(n), cwd=ROOT)
            status = ctl.p.wait(timeout=60)
        finally:
            if ctl is not None:
                ctl.stop()
            vehicle.stop()
    assert status == controller_exit(ctl.lines), _why(ctl, vehicle)
    h = read_half(tmp_path / "v" / "vehicle.bin")
    assert h["k"][0] >= 400, h["k"][0]  # the premise: its plant ran 1.6 s before the flight
    # the flight's time 0: the state its first target answers (SimVehicle.start_mission_clock), not the arm (the
    # half's first row): the controller's phase lock and first tick come between, 0.03 s here, 0.22 s for a
    # controller descheduled there (nothing of the mission is due yet: no stall of it). Every row before the
    # first target's (armed, none yet) is at the origin: nothing pushed it before the flight
    first = next(i for i, k in enumerate(h["cmd_k"]) if k >= 0)
    t0 = h["t"][first] * h["cmd_k"][first] / h["k"][first]
    assert first > 0 and all((h["x"][i], h["y"][i], h["z"][i]) == (0.0, 0.0, 0.0) for i in range(first))
    lift = next(i for i, z in enumerate(h["z"]) if z > 0.0)
    # within 0.1 s of time 0, plus what either side said it stalled in those 0.1 s (real time's own slippage)
    ctl_stats = _stats(ctl.lines)["stalls"]["at"]
    veh_stats = _stats(vehicle.lines)["stalls"]["at"]
    slipped = sum(ms for t, ms in ctl_stats if t < 0.1) + sum(ms for t, ms in veh_stats if t0 <= t < t0 + 0.1)
    assert h["t"][lift] - t0 < 0.1 + slipped / 1e3, (lift, h["t"][lift] - t0, h["t"][first] - h["t"][0], slipped)


def test_a_failsafe_the_flight_came_back_from_is_no_end_a_plant_end_always_is() -> None:
    """The verdict on the events alone: a failsafe followed by an arm or a mode selected armed (OFFBOARD, a ground
    station's LAND) is no end of the flight, one followed by a mode selected disarmed is; a crash is, whatever came
    after; in the order they happened."""
    fs = Event(1.0, "failsafe", "no actuator target for 0.500 s: descend")
    back = Event(2.0, "mode", "OFFBOARD", mode=OFFBOARD, armed=True)
    assert flights_not_ended_well([Event(0.0, "armed", "armed, offboard control"), fs, back]) == []
    assert flights_not_ended_well([fs, Event(2.0, "mode", "LAND", mode="land", armed=True)]) == []
    assert len(flights_not_ended_well([fs, Event(2.0, "mode", "HOLD (disarmed: ...)", mode="hold", armed=False)])) == 1
    assert flights_not_ended_well([fs, Event(2.0, "armed", "armed, offboard control")]) == []
    crash = Event(3.0, "crashed", "touched down at 3.1 m/s")
    assert flights_not_ended_well([fs, back, crash, Event(4.0, "armed", "armed")]) == [
        "crashed at t=3.000 s: touched down at 3.1 m/s"]
    assert flights_not_ended_well([crash, Event(5.0, "failsafe", "x")]) == [
        "crashed at t=3.000 s: touched down at 3.1 m/s", "failsafe at t=5.000 s: x: its flight ended in it (no arm, no "
        "mode selected, took it back)"]


def test_a_vehicle_alone_whose_started_mission_no_controller_flew_says_so_and_exits_1() -> None:
    """``bsst vehicle --await-mission`` alone, no controller: a pymavlink ground station uploads a takeoff, a
    waypoint and a landing and starts them (MAV_CMD_MISSION_START, ACCEPTED: the vehicle waits for its controller to
    download and fly them). Stopped (Ctrl-C), it says the started mission was never flown and exits 1. Until the
    forty-fourth session's tour (MAVSDK: MissionRaw upload, start_mission, Action.arm, all SUCCESS, nothing flown) it
    said nothing and exited 0."""
    with instance_slot() as n:
        gcs = _gcs(n)
        vehicle = Proc.bsst("vehicle", "--await-mission", "--realtime", "--instance", str(n), cwd=ROOT)
        try:
            vehicle.wait_report(Ready, timeout=60)
            target = _vehicle_of(gcs)
            _upload(gcs, target, _small_plan_items())
            gcs.mav.command_long_send(*target, M.MAV_CMD_MISSION_START, 0, 0, 0, 0, 0, 0, 0, 0)
            assert _ack(gcs, M.MAV_CMD_MISSION_START).result == M.MAV_RESULT_ACCEPTED
            # (the vehicle's one mission event here, the ground station's: its start; no item was set current)
            vehicle.wait_report(ReportedEvent, lambda e: e.kind == "mission" and e.by is not None, timeout=30)
            status, said = _stopped(vehicle)
        finally:
            gcs.close()
            vehicle.stop()
    assert status == 1 and len(said) == 1, vehicle.lines[-5:]
    assert said[0].startswith("bsst vehicle: not flown: the mission started by MISSION_START [by 255:190 "), said
    assert said[0].endswith(" gcs] was never flown: no controller took it up (bsst controller --await-mission flies "
                            "it; bsst sitl --await-mission runs both)"), said


def test_a_started_mission_whose_controllers_arm_was_refused_says_the_arm_was_refused() -> None:
    """start_not_flown: a controller came after the start but PX4's pre-arm check denied its arm (a ``preflight``
    event after the start): the line says the arm was refused, and why, not that no controller took it up (the old
    words); a refusal before the start, then none, is the old line."""
    from bridge.core.flight import prepare  # (in-process: the vehicle's own refusal, no process needed)

    sim = prepare(ROOT / "missions" / "sine.toml", params={"GF_MAX_HOR_DIST": 5.0}).make_vehicle()
    hx, hy, hz = sim.home
    sim.plant.state = (hx + 6.0, 0.0, hy, 0.0, hz, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    started = {"command": "MISSION_START", "by": "255:190 127.0.0.1:14550 gcs"}
    sim.arm()  # refused before the start
    n0 = len(sim.events)  # the start (MissionManager.started_n0: run.py passes the events from it)
    sim.event("mission", "start requested by MISSION_START: 3 items, for the controller to fly")
    assert start_not_flown(True, started, sim.events[n0:])[0].endswith(": no controller took it up (bsst controller "
                                                                  "--await-mission flies it; bsst sitl "
                                                                  "--await-mission runs both)")
    sim.arm()  # the controller's arm, after the start: refused
    assert not sim.armed
    refused = sim.events[-1]
    assert start_not_flown(True, started, sim.events[n0:]) == [
        f"not flown: the mission started by MISSION_START [by 255:190 127.0.0.1:14550 gcs] was never flown: its arm "
        f"was refused at t={refused.t:.3f} s: arming denied: 6.00 m from home, beyond GF_MAX_HOR_DIST = 5 m "
        "(GF_ACTION = 2: hold)"]
