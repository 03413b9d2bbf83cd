"""Covers bridge.autopilot.failsafe and bridge.autopilot.simvehicle.

The vehicle's failsafe actions (issue 14): ``[failsafe] action = descend | land | hold | disarm``.

``bsst sitl missions/sine.toml --blackout 15:2 --failsafe-action A`` (the sine cut to a second after
the action's disarm, at 26 s for hold's at 24.802 s) is flown for each action as a real ``bsst sitl`` process
(lockstep, its vehicle and controller real processes over UDP on 127.0.0.1), each on an instance of
its own; the same flights offline with ``simulate``. Both clocks fly the same vehicle core, so they
must agree on every event and, up to touchdown, on every row (the float32 wire aside). Then the
on-board controller alone: the earlier landing loop is ``Level`` exactly, and ``Takeoff`` /
``PositionHold`` fly as a later NAV_TAKEOFF / HOLD mode needs.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import resource
import signal
import subprocess
import time
from collections.abc import Iterator
from dataclasses import replace
from math import cos, hypot
from pathlib import Path

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as M

from bridge.autopilot.failsafe import (
    FAILSAFE_ACTIONS,
    FailsafeConfig,
    Level,
    PositionHold,
    ReturnHome,
    Takeoff,
    failsafe_target,
    return_point,
)
from bridge.autopilot.simvehicle import FAILSAFE, LANDED, RTL
from bridge.cli import build_parser, main
from bridge.core.flight import prepare
from bridge.loop import simulate
from bridge.mavlink.endpoint import LINK_PORT
from bridge.mavlink.modes import MAIN_OFFBOARD, custom_mode
from bridge.record.halves import read_half
from bridge.record.runlog import read_trace
from bridge.session import instance_slot, sitl
from bridge.session.children import check_port_free
from missions import MISSION_DIR, Mission, Setpoint, Sine, Step
from params import ConfigError, load_toml
from tests.sitlkit import ENV, Bsst
from tests.test_failsafe_disarm import never_critical_disarmed, vehicle_heartbeats

pytestmark = pytest.mark.process  # starts processes or opens sockets: not in make test-fast

SINE = MISSION_DIR / "sine.toml"
BLACKOUT = {"blackouts": [[15.0, 2.0]]}
# the sine's failsafe at 15.5 s begins 1.0 m from home, where Return lands at once (as land): return has its own test
SINE_ACTIONS = tuple(a for a in FAILSAFE_ACTIONS if a != "return")
STEP_S = 1 / 250  # one control step of the sine mission
# the sine each action flies, s: cut from 30 s to a second on the ground after its disarm and 0.2 s more (descend's
# at 20.283 s, land's 19.816, hold's 24.802, disarm's 15.5 and its fall's impact 16.076), which holds every event the
# tests read and rows past the disarm's second (the rest flew four sessions and their twins on the ground, disarmed:
# 34.5 s of the 120; descend, land and disarm flew 2 s more to the fortieth session)
SINE_S = {"descend": 21.5, "land": 21.0, "hold": 26.0, "disarm": 17.0}
FLIGHT_TIMEOUT_S = 180  # a lockstep sine flies in seconds; this only stops a hang


@contextlib.contextmanager
def _free_instance() -> Iterator[int]:
    """An instance held by :func:`instance_slot` whose port is free too: a slot whose port some
    process outside the lock convention has bound (a vehicle left running) is kept held, so
    that the next one is taken."""
    with contextlib.ExitStack() as held:
        for _ in range(10):
            n = held.enter_context(instance_slot())
            try:
                check_port_free(LINK_PORT + n, f"--instance {n}")
            except ConfigError:
                continue
            yield n
            return
    raise AssertionError("no SITL instance with a free port")


def _sine(folder: Path, action: str) -> Path:
    """The sine cut to ``action``'s :data:`SINE_S`, written in ``folder``."""
    path = folder / f"sine-{action}.toml"
    path.write_text(SINE.read_text().replace("duration_s = 30.0", f"duration_s = {SINE_S[action]}"))
    return path


def _bsst_sitl(sine: Path, out: Path, action: str) -> subprocess.CompletedProcess:
    """``bsst sitl SINE --blackout 15:2 --failsafe-action ACTION`` as a real process on
    an instance of its own; on a hang its whole process group (vehicle, controller) is killed."""
    with _free_instance() as n:
        p = Bsst("sitl", str(sine), "--blackout", "15:2", "--failsafe-action", action, "--instance", str(n),
                 "--out", str(out), "--no-plots", env=ENV)
        try:
            stdout, stderr = p.communicate(timeout=FLIGHT_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            os.killpg(p.pid, signal.SIGKILL)
            p.communicate()
            raise
    assert (out / "summary.json").exists(), f"bsst sitl --failsafe-action {action}: exit {p.returncode}: {stderr}"
    return subprocess.CompletedProcess(p.args, p.returncode, stdout, stderr)


@pytest.fixture(scope="module")
def flown(tmp_path_factory: pytest.TempPathFactory) -> dict[str, dict]:
    """Each action through ``bsst sitl`` (one after the other: each flight keeps two processes
    busy) and offline."""
    root = tmp_path_factory.mktemp("failsafe_actions")
    runs: dict[str, dict] = {}
    for a in SINE_ACTIONS:
        out = root / a
        sine = _sine(root, a)
        p = _bsst_sitl(sine, out, a)
        summary = json.loads((out / "summary.json").read_text())
        runs[a] = {"rc": p.returncode, "stdout": p.stdout, "stderr": p.stderr, "out": out, "summary": summary,
                   "trace": read_trace(out / "trace.csv"),
                   "vehicle": {e["kind"]: e["t"] for e in summary["events"] if e["source"] == "vehicle"},
                   "offline": simulate(sine, plots=False, link=BLACKOUT, failsafe={"action": a}), "sine": sine}
    return runs


def _at(trace: dict, t: float) -> int:
    """The row of control step time t."""
    return int(np.searchsorted(trace["t"], t - 1e-9))


def _start(run: dict) -> tuple[float, np.ndarray]:
    """The failsafe's time and the position (x, y, z) of its row: where it began."""
    t0 = run["vehicle"]["failsafe"]
    tr = run["trace"]
    i = _at(tr, t0)
    return t0, np.array([tr["x"][i], tr["y"][i], tr["z"][i]])


def _touchdown(trace: dict, after: float) -> float:
    """The time of the first row on the ground after ``after``."""
    t, z = trace["t"], trace["z"]
    return float(t[(t > after) & (z <= 0.0)][0])


# -- the four actions in lockstep, as the acceptance says ------------------------------------
@pytest.mark.parametrize("action", SINE_ACTIONS)
def test_each_action_ends_in_failsafe_exit_1_and_flies_as_written(flown, action: str) -> None:
    run = flown[action]
    assert run["rc"] == 1, run["stderr"]
    assert "outcome: failsafe" in run["stdout"]
    assert run["summary"]["outcome"] == "failsafe" and run["summary"]["clock"] == "lockstep"
    assert run["summary"]["sitl"]["died"] is None
    assert load_toml(run["out"] / "mission.toml")["failsafe"]["action"] == action  # what both children read
    t0 = run["vehicle"]["failsafe"]
    assert 15.5 <= t0 <= 15.5 + STEP_S + 1e-9
    for log in ("vehicle.log", "controller.log"):
        assert "Traceback" not in (run["out"] / log).read_text()
    tr = run["trace"]
    assert len(tr["t"]) == round(SINE_S[action] / STEP_S)  # the step clock ran on to the mission's end
    assert tr["z"][tr["t"] > run["vehicle"]["disarmed"] + 1.0].max() == 0.0  # at rest on the ground


@pytest.mark.parametrize("action", SINE_ACTIONS)
def test_its_disarm_clears_the_failsafe_offboard_standby_and_the_controller_still_says_failsafe(flown, action) -> None:
    """PX4 clears the failsafe on disarm: at the end of the disarm's control period the vehicle is back in OFFBOARD
    (the mode it was armed in), its HEARTBEAT STANDBY (never CRITICAL disarmed), saying why, as offline does at the
    same time. ``disarm`` stops the motors and disarms in the failsafe's own period, so no HEARTBEAT ever says
    CRITICAL: the controller learns it from the vehicle's typed EVENT (id FAILSAFE), and still flies the
    mission's steps to the end and says ``failsafe`` (not "the vehicle was disarmed during the mission")."""
    run = flown[action]

    def said(events: list) -> list:
        return [(e["t"], e["kind"], e["text"].removesuffix(" [by vehicle]")) for e in events
                if e.get("source", "vehicle") == "vehicle" and e["kind"] in ("failsafe", "landed", "disarmed", "mode")]

    mine = said(run["summary"]["events"])
    assert mine == said(run["offline"].summary["events"])
    (t_off, _, _), (t_mode, kind, text) = mine[-2:]
    assert kind == "mode" and text.startswith("OFFBOARD (disarmed after its failsafe: PX4 clears the failsafe on "
                                               "disarm") and t_off < t_mode <= t_off + STEP_S + 1e-9, mine
    beats = vehicle_heartbeats(run["out"] / "vehicle.tlog")
    never_critical_disarmed(beats)
    assert beats[-1] == (False, custom_mode(MAIN_OFFBOARD), M.MAV_STATE_STANDBY)
    how = [e["text"] for e in run["summary"]["events"] if e["source"] == "controller" and e["kind"] == "failsafe"]
    assert how == ["the vehicle's failsafe took over (" + ("its EVENT FAILSAFE" if action ==
                                                         "disarm" else "HEARTBEAT system_status CRITICAL") + ")"]


@pytest.mark.parametrize("action", SINE_ACTIONS)
def test_the_controllers_failsafe_judgement_is_stamped_when_the_failsafe_took_over(flown, action: str) -> None:
    """The controller judges the flight ``failsafe`` at the mission's end (its failsafe alone does not end it: it may
    hand the vehicle back), but stamps that word when the failsafe took over, the vehicle's EVENT's time: 15.5 s, as
    the vehicle's own event, in summary.json and events.log (written when said, after later lines; in its place in
    time once the session closes the log). Until the third wave's thirty-seventh session it was stamped at the
    mission's end (t=22.000 for descend)."""
    run = flown[action]
    t0 = run["vehicle"]["failsafe"]
    said = [e for e in run["summary"]["events"] if e["source"] == "controller" and e["kind"] == "failsafe"]
    assert [e["t"] for e in said] == [t0], said
    log = (run["out"] / "events.log").read_text()
    assert f"t={t0:.3f} failsafe: the vehicle's failsafe took over (" in log, log


def test_descend_is_the_default_and_todays_figure(flown) -> None:
    """The docs' figure (docs/design.md, "Failsafe"): on the ground at 18.283 s with the default, implicit step, and
    disarmed COM_DISARM_LAND (2 s) later, at 20.283 s; the paper's explicit step, asked for by name, held another last
    command when the state stopped: down at 18.274 s, disarmed at 20.274 s."""
    v = flown["descend"]["vehicle"]
    assert v["failsafe"] == pytest.approx(15.5) and v["landed"] == pytest.approx(18.283, abs=0.005)
    assert v["disarmed"] == pytest.approx(v["landed"] + 2.0, abs=1e-6)
    log = (flown["descend"]["out"] / "events.log").read_text()
    assert "failsafe: no actuator target for 0.504 s: level and descend" in log and "landed: disarmed" in log
    sine = flown["descend"]["sine"]
    plain = simulate(sine, plots=False, link=BLACKOUT)  # no action given: descend, row for row
    for c in ("x", "y", "z", "u1_act", "u2_act"):
        assert np.array_equal(plain.trace[c], flown["descend"]["offline"].trace[c])
    explicit = simulate(sine, plots=False, link=BLACKOUT, discretization="explicit").summary["events"]
    assert [e["t"] for e in explicit if e["kind"] in ("landed", "disarmed")] == [pytest.approx(18.274, abs=0.005),
                                                                                  pytest.approx(20.274, abs=0.005)]


def test_hold_keeps_within_half_a_metre_for_3s_then_lands(flown) -> None:
    run = flown["hold"]
    t0, p0 = _start(run)
    tr = run["trace"]
    t = tr["t"]
    held = (t >= t0) & (t <= t0 + 3.0)
    away = np.sqrt((tr["x"] - p0[0]) ** 2 + (tr["y"] - p0[1]) ** 2 + (tr["z"] - p0[2]) ** 2)
    assert away[held].max() <= 0.5, away[held].max()
    assert abs(tr["z"][_at(tr, t0 + 4.9)] - p0[2]) < 0.05  # and its height, to the end of the hold
    v = run["vehicle"]
    assert v["landing"] == pytest.approx(t0 + 5.0)  # [failsafe] hold_s, PX4's COM_FAIL_ACT_T default
    assert v["disarmed"] > v["landing"] + 1.5  # from 1.55 m at 0.7 m/s
    assert "landing: held 5.000 s" in (run["out"] / "events.log").read_text()


def test_land_drifts_at_most_half_a_metre_lands_and_disarms(flown) -> None:
    run = flown["land"]
    t0, p0 = _start(run)
    tr = run["trace"]
    t = tr["t"]
    v = run["vehicle"]
    flying = (t >= t0) & (t <= v["disarmed"])
    drift = np.hypot(tr["x"] - p0[0], tr["y"] - p0[1])
    assert drift[flying].max() <= 0.5, drift[flying].max()
    assert np.all(drift[t > v["disarmed"]] <= 0.5)  # where it rests
    assert "landed: disarmed" in (run["out"] / "events.log").read_text()
    assert v["disarmed"] < flown["descend"]["vehicle"]["disarmed"] + 0.5  # it sank, it did not hover
    # descend, for contrast, drifts on with the 0.5 m/s it had
    d0 = _start(flown["descend"])[1]
    dtr = flown["descend"]["trace"]
    assert np.hypot(dtr["x"] - d0[0], dtr["y"] - d0[1]).max() > 1.0


def test_return_flies_home_from_the_step_missions_second_set_point_in_lockstep_as_offline(tmp_path: Path) -> None:
    """``return`` (PX4 3, Return): the step mission's link blacked out at 12 s, at its second set-point (2.2 m from
    home, 2 m up), RTL_RETURN_ALT 3 m, RTL_DESCEND_ALT 2.5 m, no cone (RTL_CONE_ANG 0: with PX4's 45 deg it would
    return at 2 NAV_ACC_RAD = 4 m, tests/test_return_land.py): ``bsst sitl`` (lockstep, real processes) ends
    ``failsafe``, exit 1; the vehicle climbs to 3 m, flies home, comes down and lands within 0.2 m of home,
    disarmed; offline flies the same rows to 1e-9 m until touchdown, and the same events. The step mission cut to
    22 s: disarmed at 20.624 s, the rest of its 30 s flew nothing the test reads."""
    step = tmp_path / "step22.toml"
    step.write_text((MISSION_DIR / "step.toml").read_text().replace("duration_s = 30.0", "duration_s = 22.0"))
    rtl = ("--param", "RTL_RETURN_ALT=3", "--param", "RTL_DESCEND_ALT=2.5", "--param", "RTL_CONE_ANG=0")
    with _free_instance() as n:
        p = Bsst("sitl", str(step), "--blackout", "12:6", "--failsafe-action", "return", *rtl, "--instance", str(n),
                 "--out", str(tmp_path / "r"), "--no-plots", env=ENV)
        p.communicate(timeout=FLIGHT_TIMEOUT_S)
    assert p.returncode == 1
    summary = json.loads((tmp_path / "r" / "summary.json").read_text())
    assert summary["outcome"] == "failsafe"
    v = {e["kind"]: e["t"] for e in summary["events"] if e["source"] == "vehicle"}
    tr = read_trace(tmp_path / "r" / "trace.csv")
    t0 = v["failsafe"]
    i0 = _at(tr, t0)
    assert hypot(tr["x"][i0], tr["y"][i0]) > 2.0 and tr["z"][i0] > 1.9  # away from home, below the return height
    flying = (tr["t"] >= t0) & (tr["t"] <= v["disarmed"])
    assert 2.9 < tr["z"][flying].max() < 3.1  # climbed to RTL_RETURN_ALT
    end = _at(tr, v["disarmed"] + 0.5)
    assert hypot(tr["x"][end], tr["y"][end]) < 0.2 and tr["z"][end] == 0.0  # home, on the ground
    assert "failsafe: no actuator target for 0.504 s: return home (RTL), then land" in \
        (tmp_path / "r" / "events.log").read_text()
    off = simulate(step, plots=False, link={"blackouts": [[12.0, 6.0]]}, failsafe={"action": "return"},
                   params={"RTL_RETURN_ALT": 3.0, "RTL_DESCEND_ALT": 2.5, "RTL_CONE_ANG": 0})
    assert [(e["kind"], round(e["t"], 3)) for e in off.summary["events"] if e["kind"] in ("failsafe", "disarmed")] \
        == [("failsafe", round(t0, 3)), ("disarmed", round(v["disarmed"], 3))]
    until = tr["t"] < _touchdown(off.trace, t0)
    assert max(float(np.max(np.abs(tr[c][until] - off.trace[c][until]))) for c in ("x", "y", "z")) < 1e-9


def test_disarm_stops_the_motors_within_one_control_step(flown) -> None:
    run = flown["disarm"]
    v = run["vehicle"]
    assert 0.0 <= v["disarmed"] - v["failsafe"] <= STEP_S
    assert "disarmed: failsafe: motors stopped" in (run["out"] / "events.log").read_text()
    tr = run["trace"]
    after = tr["t"] >= v["failsafe"] + STEP_S
    for c in ("u1_act", "u2_act", "u3_act", "u4_act"):
        assert np.all(tr[c][after] == 0.0), c
    t_ground = _touchdown(tr, v["failsafe"])
    assert t_ground - v["failsafe"] < 0.7  # it fell: from 1.55 m, 0.56 s


@pytest.mark.parametrize("action", SINE_ACTIONS)
def test_offline_and_lockstep_fly_the_same_failsafe(flown, action: str) -> None:
    run = flown[action]
    off = run["offline"]
    assert off.outcome == "failsafe"
    ev = [(e["kind"], round(e["t"], 3)) for e in off.summary["events"] if e["kind"] in ("failsafe", "landing")]
    assert ev == [(k, round(run["vehicle"][k], 3)) for k, _ in ev]
    off_disarm = next(e["t"] for e in off.summary["events"] if e["kind"] == "disarmed")
    assert abs(off_disarm - run["vehicle"]["disarmed"]) <= STEP_S + 1e-9
    tr = run["trace"]
    assert np.array_equal(tr["t"], off.trace["t"])
    until = tr["t"] < _touchdown(off.trace, run["vehicle"]["failsafe"])
    worst = max(float(np.max(np.abs(tr[c][until] - off.trace[c][until]))) for c in ("x", "y", "z"))
    # the offline loop flies the float32 wire as lockstep does (bridge.core.wire.state_over_wire):
    # the same rows, also for descend, which has no horizontal control to pull a difference back
    assert worst < 1e-9, worst


# -- real time: the same vehicle core on the wall clock -------------------------------------------
def test_hold_on_the_wall_clock_brakes_and_returns_to_where_it_began(tmp_path: Path) -> None:
    """Real time, the same vehicle core: a blackout from 3 s leaves the vehicle on the held target
    for 0.5 s, then ``hold`` brakes it and brings it back. Flown by PID, settled by 3 s (its torques
    below 0.3 N·m): the held target is a small push whatever the wall clock's timing. (The BS-ST law's
    torques alternate by several N·m, and early in the flight the one held decides: a run at load 2
    drifted 1.64 m before it braked, as tests/test_params.py's blackout once crashed.) It holds 2.1 s (``hold_s``),
    not the default 5 s (the lockstep test's): what is read here is its first 2 s of holding and that it then lands
    (COM_DISARM_LAND 0.5 s, not 2: its wait on the ground after the touchdown, on the wall clock, reads nothing),
    and the session waited out every second of the hold on the wall clock, asleep between its children's words: a
    controller that ended first left its pipe at its end, always readable, and the session's wait spun on it until the
    vehicle disarmed (2.8 CPU-s of the launcher's thread in 9.0 s; 0.09 since)."""
    wall, cpu = time.monotonic(), resource.getrusage(resource.RUSAGE_THREAD)
    run = sitl(Mission(Sine(), duration_s=6.0, name="rt-hold", controller="pid"), realtime=True,
               out=tmp_path / "rt", plots=False, instance=None, link={"delay_ms": 5.0, "blackouts": [[3.0, 1.5]]},
               failsafe={"action": "hold", "hold_s": 2.1}, params={"COM_DISARM_LAND": 0.5})
    after = resource.getrusage(resource.RUSAGE_THREAD)
    used = after.ru_utime + after.ru_stime - cpu.ru_utime - cpu.ru_stime
    assert used < 0.15 * (time.monotonic() - wall), (used, time.monotonic() - wall)  # a spin takes all it can get
    assert run.outcome == "failsafe"
    fs = [e for e in run.summary["events"] if e["kind"] == "failsafe" and e["source"] == "vehicle"]
    assert len(fs) == 1 and "hold here" in fs[0]["text"]
    col = read_half(tmp_path / "rt" / "vehicle.bin")
    holding = np.flatnonzero(col["mode"] == 1)[:500]  # the vehicle's own rows, its first 2 s of holding
    assert len(holding) == 500 and np.all(np.diff(holding) == 1)
    p0 = np.array([col[c][holding[0]] for c in ("x", "y", "z")])
    away = np.sqrt(sum((col[c][holding] - p0[j]) ** 2 for j, c in enumerate(("x", "y", "z"))))
    speed = np.sqrt(sum(col[c][holding] ** 2 for c in ("vx", "vy", "vz")))
    assert away.max() < 0.8, away.max()  # it braked
    assert away[-1] < 0.3 and speed[-1] < 0.3, (away[-1], speed[-1])  # and came back
    assert col["z"][holding].min() > 0.05  # in the air all along
    assert any(e["kind"] == "landing" and e["source"] == "vehicle" for e in run.summary["events"])  # then it landed


# -- the [failsafe] table and the flag ---------------------------------------------------------------
def test_the_flags_choices_are_the_actions() -> None:
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    for cmd in ("sim", "sitl", "vehicle"):
        flag = next(a for a in sub.choices[cmd]._actions if "--failsafe-action" in a.option_strings)
        assert tuple(flag.choices) == FAILSAFE_ACTIONS
    ctl = sub.choices["controller"]._actions  # the vehicle flies its failsafe: not the controller's flag
    assert not any("--failsafe-action" in a.option_strings for a in ctl)


def test_the_override_is_laid_over_the_mission_table() -> None:
    m = Mission(Sine(), duration_s=1.0, name="s", failsafe={"timeout_s": 0.2, "action": "land"})
    f = prepare(m, failsafe={"action": "hold"})
    assert (f.failsafe.action, f.failsafe.timeout_s, f.failsafe.hold_s) == ("hold", 0.2, 5.0)
    assert f.mission.failsafe == {"timeout_s": 0.2, "action": "hold"}  # what mission.toml carries
    assert prepare(m).failsafe.action == "land"


@pytest.mark.parametrize("table, key", [({"action": "fly"}, "failsafe.action"), ({"action": 4}, "failsafe.action"),
                                        ({"hold_s": 30.0}, "failsafe.hold_s"), ({"hold_s": -1.0}, "failsafe.hold_s")])
def test_a_bad_failsafe_value_is_named(table: dict, key: str) -> None:
    with pytest.raises(ConfigError, match=key):
        prepare(Mission(Sine(), duration_s=1.0, name="s", failsafe=table))


def test_a_bad_flag_is_one_line_exit_2(capsys) -> None:
    assert main(["sim", str(SINE), "--failsafe-action", "fly", "--no-plots"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--failsafe-action" in err[0] and "'fly'" in err[0]


# -- the on-board controller alone -------------------------------------------------------------------
HOVER = (0.3, 0.2, -0.1, -0.1, 1.0, 0.3, 0.05, 0.4, -0.04, -0.2, 0.5, 0.3)


def test_level_is_the_earlier_landing_loop_exactly() -> None:
    """``descend`` flies the loop the failsafe had before it had actions, to the last bit."""
    sim = prepare(Mission(Sine(), duration_s=1.0, name="s")).make_vehicle(armed=True)
    n = sim.onboard.n
    sim.fly_onboard(Level(0.7), FAILSAFE)
    _, _, _, _, _, vz, phi, dphi, th, dth, _, dpsi = HOVER
    earlier = (n.mass * (n.gravity + 2.0 * (-0.7 - vz)) / max(cos(phi) * cos(th), 0.5),
               n.ixx / n.arm * (-36.0 * phi - 12.0 * dphi), n.iyy / n.arm * (-36.0 * th - 12.0 * dth),
               n.izz / n.arm * (-4.0 * dpsi))
    assert sim.onboard.demand(HOVER) == earlier
    sim.onboard.step(HOVER, 0.001)
    assert sim.onboard.integral == (0.0, 0.0, 0.0) and sim.onboard.demand(HOVER) == earlier


def _ground_mission(**effects) -> Mission:
    return Mission(Step((Setpoint(0.0, 0.0, 0.0, 0.0, 0.0),)), duration_s=60.0, name="g", effects=effects)


def _fly(sim, seconds: float) -> list[tuple[float, ...]]:
    states = []
    for _ in range(int(seconds * 250)):
        sim.advance()
        states.append(sim.plant.state)
    return states


def test_takeoff_climbs_to_its_height_and_holds_there() -> None:
    """What a later NAV_TAKEOFF needs: from rest on the ground, up at most 1.5 m/s to 2 m, then held."""
    sim = prepare(_ground_mission()).make_vehicle(armed=True)
    sim.fly_onboard(Takeoff.here(sim.plant.state, 2.0), "takeoff")
    states = _fly(sim, 6.0)
    assert 1.4 < max(s[5] for s in states) <= 1.5 * 1.1  # its climb rate (the integral overshoots it < 10 %)
    assert max(s[4] for s in states) < 2.1
    end = states[-1]
    assert abs(end[4] - 2.0) < 0.02 and abs(end[0]) < 1e-6 and abs(end[2]) < 1e-6 and sim.armed


def test_return_mode_climbs_flies_home_comes_down_and_lands() -> None:
    """RTL (PX4's Return, home type) from a hover 6.7 m from home at 2 m, RTL_RETURN_ALT 4 m, RTL_DESCEND_ALT
    2.5 m: it stops and climbs to 4 m where it is, flies home at 4 m, comes down to 2.5 m over home, lands and
    disarms on the ground at home; its phases in that order, each once."""
    sim = prepare(_ground_mission(), params={"RTL_RETURN_ALT": 4.0, "RTL_DESCEND_ALT": 2.5}).make_vehicle(armed=True)
    sim.plant.state = (6.0, 0.0, 3.0, 0.0, 2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    sim.set_mode(RTL)
    target = sim.onboard.target
    assert isinstance(target, ReturnHome) and (target.x, target.y, target.z_return, target.z_descend) == \
        (0.0, 0.0, 4.0, 2.5)
    states = _fly(sim, 40.0)
    phases = [target.phase(X) for X in states[:[s[4] for s in states].index(min(s[4] for s in states)) + 1]]
    assert list(dict.fromkeys(phases)) == ["climb", "return", "descend", "land"], list(dict.fromkeys(phases))
    climbing = [X for X, ph in zip(states, phases) if ph == "climb"]
    assert max(hypot(X[0] - 6.0, X[2] - 3.0) for X in climbing) < 0.3  # it climbs where it is
    home_run = [X for X, ph in zip(states, phases) if ph == "return"]
    assert max(abs(X[4] - 4.0) for X in home_run) < 0.35 and max(X[4] for X in states) < 4.2
    end = states[-1]
    assert not sim.armed and hypot(end[0], end[2]) < 0.2 and end[4] < 0.01, (sim.armed, end[:6])
    assert [e.kind for e in sim.events][-1] == "disarmed"


def test_return_lands_at_the_closest_of_home_and_the_rally_points() -> None:
    """With rally points (a plan's rallyPoints, ``[rally]``), Return flies to the closest, horizontally, of the
    home and them (PX4's RTL_TYPE 0) and lands there; its event names the rally point. Home wins a tie, and a
    rally point farther than home changes nothing; the ``return`` failsafe picks the same way."""
    assert return_point((6.0, 0, 3.0, 0, 2.0), (0.0, 0.0, 0.0), ((9.0, 6.0), (5.0, 5.0))) == ((5.0, 5.0, 0.0), 1)
    assert return_point((3.0, 0, 0.0, 0, 2.0), (0.0, 0.0, 0.0), ((6.0, 0.0),)) == ((0.0, 0.0, 0.0), None)  # a tie
    assert return_point((1.0, 0, 1.0, 0, 2.0), (0.0, 0.0, 0.0), ((9.0, 9.0),)) == ((0.0, 0.0, 0.0), None)
    mission = replace(_ground_mission(), rally=((9.0, 6.0), (5.0, 5.0)))
    sim = prepare(mission, params={"RTL_RETURN_ALT": 4.0, "RTL_DESCEND_ALT": 2.5}).make_vehicle(armed=True)
    sim.plant.state = (6.0, 0.0, 3.0, 0.0, 2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    sim.set_mode(RTL)
    assert "rally point 1 x=5.000 y=5.000 m" in sim.events[-1].text, sim.events[-1].text
    states = _fly(sim, 30.0)
    end = states[-1]
    assert not sim.armed and hypot(end[0] - 5.0, end[2] - 5.0) < 0.2 and end[4] < 0.01, (sim.armed, end[:6])
    target = failsafe_target(FailsafeConfig(action="return"), (6.0, 0, 3.0, 0, 2.0, 0, 0, 0, 0, 0, 0, 0),
                             (0.0, 0.0, 0.0), sim.rtl, mission.rally)
    assert isinstance(target, ReturnHome) and (target.x, target.y) == (5.0, 5.0)


def test_position_hold_takes_up_a_heavier_plant_with_its_integral() -> None:
    """20 % more mass than the model: the height sags while the integral fills, then returns."""
    sim = prepare(_ground_mission(mismatch={"mass_scale": 1.2})).make_vehicle(armed=True)
    sim.plant.state = (0.0, 0.0, 0.0, 0.0, 2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    sim.fly_onboard(PositionHold(0.0, 0.0, 2.0), "hold")
    states = _fly(sim, 8.0)
    assert min(s[4] for s in states) < 1.95  # it did sag: the model is light
    assert abs(states[-1][4] - 2.0) < 0.01  # and the integral brought it back


def test_position_hold_flies_to_a_distant_point_at_its_speed_and_holds_it() -> None:
    """HOLD sent 6 m away (DO_REPOSITION): across at most the on-board 2 m/s, or at a ground speed it was given
    (0.5 m/s, PX4's param1; a faster one, 7 m/s, flies as the 2 m/s), the velocity loop's integral overshooting
    the limit by ~15 % at its peak; at the point within 5 cm, at rest."""
    flown = {}
    for speed, limit, flight_s in ((None, 2.0, 9.0), (0.5, 0.5, 18.0), (7.0, 2.0, 9.0)):
        sim = prepare(_ground_mission()).make_vehicle(armed=True)
        sim.plant.state = (0.0, 0.0, 0.0, 0.0, 2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        sim.fly_onboard(PositionHold(6.0, 0.0, 2.0, speed=speed), "hold")
        states = flown[speed] = _fly(sim, flight_s)
        fastest = max(hypot(s[1], s[3]) for s in states)
        assert limit < fastest < limit * 1.2, (speed, fastest)
        end = states[-1]
        assert hypot(end[0] - 6.0, end[2]) < 0.05 and abs(end[4] - 2.0) < 0.05 and hypot(end[1], end[3]) < 0.05, end
    assert flown[7.0] == flown[None]


def test_a_failsafe_on_the_ground_disarms_at_once_whatever_the_action() -> None:
    for action in FAILSAFE_ACTIONS:
        sim = prepare(_ground_mission(), failsafe={"action": action}).make_vehicle(armed=True)
        _fly(sim, 0.6)  # no target for over timeout_s
        assert not sim.armed and sim.mode == LANDED
        fs = [e for e in sim.events if e.kind == "failsafe"]
        disarmed = [e for e in sim.events if e.kind == "disarmed"]
        assert len(fs) == 1 and len(disarmed) == 1 and disarmed[0].t == fs[0].t, action
