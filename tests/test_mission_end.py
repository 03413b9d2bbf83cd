"""Covers missions.mission, bridge.autopilot.simvehicle, bridge.loop and bridge.nodes: the mission's end action.

``[end] action`` (missions.mission), SimVehicle.end_mission, the offline loop's fly_end, the controller's end of
mission (bridge.nodes.offboard), the vehicle's commander (bridge.nodes.vehicle.commander), bridge.record.ending.

The mission's end never leaves the vehicle in the air with its motors off: ``land`` (the default) lands it with
its on-board landing and disarms it on the ground, ``hold`` holds its position until the session ends, in every
clock; lockstep's landing equals offline's to the bit, and the mission's trace and figures stay the mission's.
Real processes for the sessions, waits on events with deadlines.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from bridge.loop import simulate
from bridge.nodes.report import Done, Ready, parse_line
from bridge.record.ending import end_not_taken
from bridge.record.events import RunEvent
from bridge.record.halves import count_records, read_half
from bridge.session import instance_slot, sitl
from missions import MISSION_DIR, load_mission
from tests.sitlkit import CONTROLLER_STALLED, ENV, ROOT, Proc, controller_exit, run_bsst
from tests.waiting import wait_for

pytestmark = pytest.mark.process  # starts processes or opens sockets: not in make test-fast

SINE = MISSION_DIR / "sine.toml"
GROUND_M = 0.1  # m: motors may stop only below this


def _mission(tmp_path: Path, seconds: float, end: str | None = None) -> Path:
    text = SINE.read_text().replace("duration_s = 30.0", f"duration_s = {seconds}")
    if end is not None:
        text += f'\n[end]\naction = "{end}"\n'
    f = tmp_path / f"sine-{end or 'default'}.toml"
    f.write_text(text)
    return f


def _landed(end: dict) -> None:
    assert end["action"] == "land" and end["disarmed"] is True, end
    assert end["disarm_z_m"] < GROUND_M, end  # motors off on the ground, never in the air
    assert end["rows"] > 100 and 0.5 < end["max_descent_mps"] < 1.0, end  # a landing was flown, at its rate


# the sine's first 4 s, whose end landing lockstep flies as offline (the whole 30 s in lockstep flew 26 s more than
# the landing compared, ~1.2 CPU-s)
SINE_4S = replace(load_mission(SINE), duration_s=4.0)


@pytest.fixture(scope="module")
def sine_runs(tmp_path_factory: pytest.TempPathFactory) -> tuple[object, object, object, Path]:
    """The paper's sine offline, then :data:`SINE_4S` offline and in lockstep (run directory kept), with the paper's
    explicit step asked for by name: the whole sine's RMS is the known fingerprint the mission's figures are checked
    against (the default is implicit)."""
    out = tmp_path_factory.mktemp("end") / "ls"
    return (simulate(SINE, plots=False, discretization="explicit"),
            simulate(SINE_4S, plots=False, discretization="explicit"),
            sitl(SINE_4S, out=out, plots=False, instance=None, discretization="explicit"), out)


def test_offline_sine_ends_landed_and_disarmed(sine_runs) -> None:
    offline, _, _, _ = sine_runs
    _landed(offline.summary["end"])
    kinds = [(e["kind"], e["t"]) for e in offline.summary["events"]]
    assert ("end", 30.0) in kinds
    disarms = [t for k, t in kinds if k == "disarmed"]
    assert len(disarms) == 1 and disarms[0] == pytest.approx(30.0 + offline.summary["end"]["landing_s"])
    # the mission's trace and figures are the mission's: its rows end at its last step
    assert len(offline.trace["t"]) == 7500 and offline.rms == 2.4093284288839256e-06


def test_lockstep_sine_lands_as_offline_to_the_bit(sine_runs) -> None:
    _, offline, lockstep, out = sine_runs
    assert lockstep.outcome == "completed" and lockstep.summary["lockstep"] == {"held": True}
    _landed(lockstep.summary["end"])
    assert lockstep.summary["end"] == offline.summary["end"]
    assert lockstep.rms == offline.rms and len(lockstep.trace["t"]) == 1000
    # the vehicle's own record: every record after the mission flown in LAND (vehicle.bin mode 4) on the step
    # clock, no disarm in the air, nothing by command
    v = read_half(out / "vehicle.bin")
    after = v["k"] >= 1000
    assert np.count_nonzero(after) == lockstep.summary["end"]["rows"]
    assert set(v["mode"][after]) == {4.0} and np.array_equal(v["k"][after], v["cmd_k"][after])
    disarms = [e for e in lockstep.summary["events"] if e["kind"] == "disarmed"]
    assert len(disarms) == 1 and "by command" not in disarms[0]["text"]


def test_an_end_landing_that_touches_down_hard_is_a_crash_offline_as_in_lockstep(tmp_path: Path) -> None:
    """The step mission's first set-point (1 m up) held for 6 s, then its end landing at MPC_LAND_SPEED = 4 m/s: it
    touches down at over 3 m/s (CRASH_SPEED_MPS: 2), a crash by the vehicle's own landing, which a session's vehicle
    judged (``crashed``, exit 1) and the offline loop never did (``completed``, exit 0: its fly_end judged nothing).
    Both now end it ``crashed``, ended by the plant at the same time and speed, with the same end block."""
    mission = tmp_path / "step6.toml"
    mission.write_text((MISSION_DIR / "step.toml").read_text().replace("duration_s = 30.0", "duration_s = 6.0")
                       .replace("    { t = 10.0,", "#").replace("    { t = 20.0,", "#"))
    offline = simulate(mission, plots=False, params={"MPC_LAND_SPEED": 4.0})
    lockstep = sitl(mission, out=tmp_path / "ls", plots=False, instance=None, params={"MPC_LAND_SPEED": 4.0})
    for run in (offline, lockstep):
        s = run.summary
        assert s["outcome"] == "crashed" and s["ended_by"]["who"] == "plant", s["ended_by"]
        assert s["impact"]["speed_mps"] > 3.0 and s["end"]["disarmed"] is True, s
    assert lockstep.summary["ended_by"] == offline.summary["ended_by"]
    assert lockstep.summary["impact"] == offline.summary["impact"] and lockstep.summary["end"] == offline.summary["end"]
    assert lockstep.rms == offline.rms


def test_hold_holds_offline_and_in_lockstep(tmp_path: Path) -> None:
    mission = _mission(tmp_path, 3.0, "hold")
    offline = simulate(mission, plots=False)
    assert offline.summary["end"]["action"] == "hold" and offline.summary["end"]["disarmed"] is False
    run = sitl(mission, out=tmp_path / "ls", plots=False, instance=None)
    assert run.outcome == "completed" and run.summary["lockstep"] == {"held": True}
    end = run.summary["end"]
    assert end["action"] == "hold" and end["disarmed"] is False, end
    assert not [e for e in run.summary["events"] if e["kind"] == "disarmed"]
    assert [e["text"] for e in run.summary["events"] if e["kind"] == "end" and e.get("source") == "vehicle"] == [
        e["text"] for e in offline.summary["events"] if e["kind"] == "end"]


def test_hold_on_the_wall_clock_holds_until_stopped(tmp_path: Path) -> None:
    """``bsst vehicle`` and ``bsst controller`` in real time: the controller hands over HOLD and exits; the
    vehicle holds its height, armed, for as long as it runs (here until it has held for 1.5 s)."""
    mission = _mission(tmp_path, 2.0, "hold")
    out = tmp_path / "run"
    with instance_slot() as n:
        vehicle = Proc.bsst("vehicle", str(mission), "--realtime", "--instance", str(n), "--gcs", "none",
                            "--out", str(out), cwd=ROOT)
        try:
            vehicle.wait_line(lambda ln: ln.startswith("ready") or '"report":"ready"' in ln, timeout=60)
            ctl = run_bsst("controller", str(mission), "--realtime", "--instance", str(n), "--out", str(out),
                           "--overwrite", cwd=ROOT, env=ENV, timeout=120)
            assert ctl.returncode == controller_exit(ctl.stderr.splitlines()), ctl.stderr  # 1: stalled by the machine

            def held_z() -> np.ndarray:
                v = read_half(out / "vehicle.bin") if count_records(out / "vehicle.bin") else {"mode": (), "z": ()}
                return np.asarray(v["z"])[np.asarray(v["mode"]) == 3]

            wait_for(lambda: len(held_z()) >= 1.5 * 250, 60, "1.5 s of HOLD records in vehicle.bin")
        finally:
            vehicle.stop()
    z = held_z()
    assert max(z) - min(z) < 0.05, (min(z), max(z))  # held where the mission ended
    assert any('"kind":"end"' in ln or "event t=" in ln and " end: " in ln for ln in vehicle.lines)
    assert not any("disarmed" in ln for ln in vehicle.lines if "event" in ln), vehicle.lines[-10:]


@pytest.mark.parametrize("value", ['"fly away"', "1"])
def test_a_bad_end_action_is_one_line_exit_2(tmp_path: Path, value: str) -> None:
    f = tmp_path / "bad.toml"
    f.write_text(SINE.read_text() + f"\n[end]\naction = {value}\n")
    res = run_bsst("sim", str(f), "--no-plots", "--out", str(tmp_path / "o"), cwd=ROOT, env=ENV, timeout=60)
    assert res.returncode == 2 and len(res.stderr.splitlines()) == 1 and "Traceback" not in res.stderr
    assert res.stderr.startswith(f"bsst: {f}: end.action: "), res.stderr


def test_the_end_action_is_the_missions_and_kept_as_flown(tmp_path: Path) -> None:
    assert load_mission(SINE).end_action == "land"
    hold = load_mission(_mission(tmp_path, 3.0, "hold"))
    assert hold.end_action == "hold" and hold.to_dict()["end"] == {"action": "hold"}
    assert "end" not in load_mission(SINE).to_dict()  # the default unwritten: a run's mission.toml as before
    assert json.loads(json.dumps(hold.to_dict()))["end"]["action"] == "hold"


@pytest.mark.parametrize("blackout", [30.0, 2.0, None], ids=["end-action-lost", "end-action-late", "clean"])
def test_a_controller_alone_whose_end_action_went_unanswered_says_not_flown_as_asked(tmp_path: Path,
                                                                                     blackout: float | None) -> None:
    """``bsst vehicle`` and ``bsst controller`` started alone on the wall clock, ``bsst relay --mission-clock``
    between them, on ``bsst sitl``'s case (test_sitl_link, the end action lost in a blackout over the end): a 2 s
    climb at 1 m/s, a blackout from 1.8 s for 30 s. The relay loses every NAV_LAND of the controller's 3 s of tries;
    the mission was flown (``done``: completed), but the controller says not flown as asked, in ``bsst sitl``'s words
    (bridge.record.asked), and exits 1. Until the third wave's forty-first session it exited 0 and said nothing on
    stderr (its ``done`` report's reason only), where ``bsst sitl`` exits 1. The same flight without the blackout
    (the relay passing all): the vehicle takes LAND, the controller waits for its disarm, exit 0, nothing said. A
    blackout of 2 s: the vehicle's failsafe takes over at ~2.3 s and a NAV_LAND retried through the link back is
    ACCEPTED at ~3.8 s: taken late, not flown as asked, exit 1, as bsst sitl says it (until the third wave's
    forty-second session the controller alone said nothing, exit 0)."""
    mission = tmp_path / "climb2.toml"
    # landed, it disarms 0.5 s later, not PX4's 2 s: the controller waits for the disarm on the wall clock, and
    # nothing reads how long it took (each second is the test's CPU)
    mission.write_text('name = "climb2"\nduration_s = 2.0\n[trajectory]\nkind = "sine"\namplitude = 0.0\n'
                       "climb = 1.0\n[params]\nCOM_DISARM_LAND = 0.5\n"
                       + (f"[link]\nblackouts = [[1.8, {blackout}]]\n" if blackout else
                          "[link]\ndelay_ms = 1.0\n"))  # the relay must model something
    with instance_slot() as n:
        vehicle = Proc.bsst("vehicle", str(mission), "--realtime", "--instance", str(n), "--gcs", "none",
                            "--out", str(tmp_path / "v"), cwd=ROOT)
        relay = None
        try:
            listen = vehicle.wait_report(Ready, timeout=60).listen
            relay = Proc.bsst("relay", "--listen", "127.0.0.1:0", "--to", listen, "--mission", str(mission),
                              "--mission-clock", cwd=ROOT)
            port = relay.wait_report(Ready, timeout=60).listen.rsplit(":", 1)[1]
            ctl = run_bsst("controller", str(mission), "--realtime", "--vehicle", f"127.0.0.1:{port}",
                           "--out", str(tmp_path / "c"), cwd=ROOT, env=ENV, timeout=120)
        finally:
            if relay is not None:
                relay.stop()
            vehicle.stop()
    [done] = [r for r in map(parse_line, ctl.stdout.splitlines()) if isinstance(r, Done)]
    assert done.outcome == "completed", (done, ctl.stderr)
    said = ("bsst controller: not flown as asked: the vehicle was not seen to take the mission's end action (LAND; "
            "its command: no answer): what flew instead not seen (the controller stops there; the vehicle silent "
            "for its last ")
    if blackout == 2.0:
        late = ("bsst controller: not flown as asked: the vehicle did not take the mission's end action at its end "
                "(LAND; its command: accepted late): its failsafe took over at t=")
        assert ctl.returncode == 1 and late in ctl.stderr and "(its EVENT FAILSAFE), LAND only at t=" in ctl.stderr, \
            ctl.stderr
        return
    if not blackout:
        lines = ctl.stderr.splitlines()  # (the machine may stall its ticks: said, exit 1, as bsst sitl does)
        assert ctl.returncode == controller_exit(lines), ctl.stderr
        assert not [ln for ln in lines if "not flown as asked" in ln and not ln.startswith(CONTROLLER_STALLED)], lines
        return
    assert ctl.returncode == 1 and said in ctl.stderr, ctl.stderr
    assert done.reason == "the vehicle did not take the mission's end action (LAND): no answer", done


def test_a_controller_alone_stopped_in_the_end_landing_says_aborted_exit_1(tmp_path: Path) -> None:
    """``bsst vehicle`` (lockstep at 1x, so the 2 s climb's landing from 2 m lasts seconds) and ``bsst controller``
    alone; SIGTERM (a Ctrl-C) to the controller once it has handed over LAND, the vehicle still armed in the air.
    The landing the controller was to see through was cut: ``aborted``, said on stderr, exit 1, as ``bsst sim``'s
    and ``bsst sitl``'s end landing cut by a stop. Until the third wave's forty-first session it exited 0, ``done``
    ``completed``, nothing on stderr, and reported an ``end`` event with no text."""
    mission = tmp_path / "climb2.toml"
    mission.write_text('name = "climb2"\nduration_s = 2.0\n[trajectory]\nkind = "sine"\namplitude = 0.0\n'
                       "climb = 1.0\n")
    with instance_slot() as n:
        vehicle = Proc.bsst("vehicle", str(mission), "--instance", str(n), "--gcs", "none", "--speed", "1",
                            cwd=ROOT)
        try:
            vehicle.wait_report(Ready, timeout=60)
            ctl = Proc.bsst("controller", str(mission), "--instance", str(n), cwd=ROOT)
            try:
                ctl.wait_event(lambda e: "mission over: the vehicle lands" in e, timeout=120)
                status = ctl.stop(timeout=30)
            finally:
                ctl.stop()
        finally:
            vehicle.stop()
    [done] = [r for r in ctl.reports() if isinstance(r, Done)]
    said = "interrupted (Ctrl-C or SIGTERM) in the mission's end landing: the vehicle still armed"
    assert (status, done.outcome, done.reason) == (1, "aborted", said), ctl.lines[-5:]
    assert f"bsst controller: aborted: {said}" in ctl.lines, ctl.lines[-5:]
    assert [e for e in ctl.events() if e.startswith("end: ")][-1].endswith(said), ctl.events()


def test_a_landing_with_no_auto_disarm_is_as_asked_in_a_session(tmp_path: Path) -> None:
    """``bsst sitl`` (lockstep) of a 2 s climb with ``COM_DISARM_LAND = -1`` (no auto-disarm: PX4 leaves the landed
    vehicle armed): the end landing lands, the vehicle stays armed, as asked. The controller says so, after the
    landing, and nothing on stderr; exit 0. Until the third wave's forty-second session the controller said "the
    vehicle did not land and disarm after the mission", on stderr and as an event stamped at the mission's end,
    before the landing it had seen."""
    mission = tmp_path / "climb2.toml"
    mission.write_text('name = "climb2"\nduration_s = 2.0\n[trajectory]\nkind = "sine"\namplitude = 0.0\n'
                       "climb = 1.0\n[params]\nCOM_DISARM_LAND = -1\n")
    with instance_slot() as n:
        res = run_bsst("sitl", str(mission), "--instance", str(n), "--no-plots", "--out", str(tmp_path / "run"),
                       cwd=ROOT, env=ENV, timeout=180)
    assert res.returncode == 0 and "land and disarm" not in res.stderr, res.stderr
    s = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert s["outcome"] == "completed" and s["end"]["disarmed"] is False and s["end"]["taken"] is True, s["end"]
    [landed] = [e["t"] for e in s["events"] if e["kind"] == "landed"]
    said = [e for e in s["events"] if e["kind"] == "end" and "as asked" in e["text"]]
    assert [e["text"] for e in said] == ["the vehicle landed and stays armed, as asked (COM_DISARM_LAND = -1: no "
                                         "auto-disarm)"], s["events"]
    assert said[0]["t"] > landed and not [e for e in s["events"] if e["kind"] == "disarmed"], s["events"]


def test_the_end_actions_answer_is_read_from_its_typed_field_never_cut_out_of_its_text() -> None:
    """``summary.json["end"]["why"]`` of an end action the vehicle never took is the answer its command had, the
    controller's ``end`` event's ``result`` (bridge.nodes.report.Event), whatever the text says: until the third wave's
    forty-fourth session bridge.record.ending cut it out of the text after its last ``): `` ("accepted" without one),
    so a text reworded for people would have changed the record (both the cases below said ``accepted`` or the text's
    tail)."""
    failsafe = RunEvent.at(2.3, "failsafe", "no actuator target for 0.5 s: LAND", "vehicle")
    for text, result in (("the vehicle did not take the mission's end action, LAND, unanswered", "no answer"),
                         ("mission over (LAND): the vehicle lands where it is and disarms on the ground", "accepted"),
                         ("the vehicle did not take the mission's end action (LAND): MAV_RESULT 4", "MAV_RESULT 4")):
        said = RunEvent.at(2.0, "end", text, "controller", result=result)
        end = end_not_taken("completed", "land", [said, failsafe], 2.0)
        assert end is not None and end["why"] == result and end["failsafe_t"] == 2.3, (text, end)
    told = RunEvent.at(2.0, "end", "the vehicle did not take the mission's end action (LAND): no answer", "controller")
    assert end_not_taken("completed", "land", [told, failsafe], 2.0) is None  # no answer said: no end action sent
