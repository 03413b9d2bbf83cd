"""Covers bridge.session.

``bsst sitl`` / :func:`bridge.session.sitl`: real processes over real UDP on 127.0.0.1,
checked against the offline loop (the truth), and under SIGKILL and Ctrl-C."""

from __future__ import annotations

import fcntl
import json
import os
import random
import signal
import socket
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from bridge.cli import main
from bridge.loop import simulate
from bridge.mavlink.endpoint import CONTROLLER_SYSID, GCS_PORT, LINK_PORT
from bridge.mavlink.telemetry import StatusTextJoiner
from bridge.record.columns import TRACE_COLUMNS
from bridge.record.halves import count_records, read_half
from bridge.record.policies import POLICIES
from bridge.record.runlog import read_trace
from bridge.session import instance_slot, sitl
from bridge.session.children import CHOSEN_PORTS_LOW, PORT_LOCKS, RECENT_PORTS, ephemeral_low, free_udp_port
from missions import MISSION_DIR, Mission, Sine, load_mission
from tests.plans import OUTSIDE_WHY, battery_mission, outside_fence_plan
from tests.sitlkit import (
    ENV,
    ROOT,
    Bsst,
    child_pids,
    run_bsst,
    stall_blackouts,
    tlog_messages,
    unexplained_outages,
)
from tests.test_air_at_start import EVENT, HEAD
from tests.waiting import wait_for

pytestmark = pytest.mark.process  # starts processes or opens sockets: not in make test-fast

SINE = MISSION_DIR / "sine.toml"
# the flights below end in hold where no test reads the end landing (a land and COM_DISARM_LAND fly ~3.5 s more: 6 s
# of sine took 9.5 s in lockstep; trace.csv, the mission's steps, is the same byte for byte either way), and SHORT is
# 3 s, 750 steps (it was 6 s: a real-time session costs its length, 1.6-2.1 CPU-s for 6 s, 0.8-0.9 for 3 s)
HOLD = '[end]\naction = "hold"\n'
SHORT = Mission(Sine(), duration_s=3.0, name="sine3", end_action="hold")
SINE_6S = 'name = "sine6"\nduration_s = 6.0\n[trajectory]\nkind = "sine"\n' + HOLD
SINE_3S = 'name = "sine3"\nduration_s = 3.0\n[trajectory]\nkind = "sine"\n' + HOLD


def _positions_close(a: dict, b: dict, tol: float) -> float:
    assert len(a["t"]) == len(b["t"])
    assert np.array_equal(a["t"], b["t"])
    worst = max(float(np.max(np.abs(a[c] - b[c]))) for c in ("x", "y", "z"))
    assert worst < tol, f"positions differ by {worst:.3e} m"
    return worst


def _tlog_types(path: Path) -> dict[str, int]:
    os.environ["MAVLINK20"] = "1"
    log = mavutil.mavlink_connection(str(path), dialect="common")
    seen: dict[str, int] = {}
    while (m := log.recv_match()) is not None:
        seen[m.get_type()] = seen.get(m.get_type(), 0) + 1
    return seen


def test_a_lockstep_flight_shows_its_progress_from_the_halves_and_writes_its_trace_at_the_end(tmp_path):
    """In lockstep the halves are the flight's live record: the progress callback follows the vehicle's newest
    record (its t rising to the mission's end, its error the trace's at that t), while ``trace.csv`` stays a
    header until the controller is done (writing it took a core's share from the flight, issue 25), and then
    holds every row of the run."""
    out = tmp_path / "run"
    seen: list[tuple[float, float, int]] = []

    def progress(t: float, duration: float, err: float) -> None:
        seen.append((t, err, (out / "trace.csv").read_bytes().count(b"\n") if (out / "trace.csv").exists() else 0))

    run = sitl(Mission(Sine(), duration_s=10.0, name="sine10"), out=out, plots=False, instance=None, speed=4.0,
               progress=progress)
    assert run.outcome == "completed"
    during = [s for s in seen if s[0] < 9.0]
    # 2.5 s of flight at 4x real time, a look every 0.1 s (at 10x, 1 s, a fresh clone's loaded CI run saw none)
    assert len(during) >= 3, seen
    assert all(b[0] >= a[0] for a, b in zip(seen, seen[1:], strict=False)), seen
    assert during[-1][0] > 5.0 and max(t for t, _, _ in seen) <= 10.0 - 1 / 250  # the mission's steps only
    assert all(lines <= 1 for _, _, lines in during), during  # the header alone while the flight flies
    err = np.sqrt(sum((run.trace[c] - run.trace[f"{c}_ref"]) ** 2 for c in ("x", "y", "z")))
    for t, e, _ in during:
        assert e == pytest.approx(err[round(t * 250)], rel=1e-9, abs=1e-12), (t, e)
    on_disk = read_trace(out / "trace.csv")
    assert len(on_disk["t"]) == 2500 and np.array_equal(on_disk["x"], run.trace["x"])


def test_lockstep_sine_matches_offline(tmp_path):
    """The acceptance: every trace row within 1e-4 m of ``bsst sim`` (float32 wire only). In fact every column
    to the bit: offline flies the float32 wire too, and both record the targets as sent (c1..c4 in float32).
    Ended in hold: the rows are the mission's 7500 whatever the end action, the landing after them is read by
    nobody here (tests/test_mission_end.py flies the landing, lockstep as offline to the bit)."""
    sine = replace(load_mission(SINE), end_action="hold")
    off = simulate(sine, plots=False)
    run = sitl(sine, out=tmp_path / "run", plots=False, instance=None)
    assert run.outcome == "completed" and run.summary["clock"] == "lockstep"
    worst = _positions_close(run.trace, off.trace, 1e-4)
    assert worst < 1e-5
    differ = [c for c in TRACE_COLUMNS if not np.array_equal(run.trace[c], off.trace[c], equal_nan=True)]
    assert not differ, differ
    assert np.all(run.trace["state_age_s"] == 0.0)
    link = run.summary["link"]
    assert link["up"]["sent"] == link["up"]["delivered"] == 7500 and link["rejected"] == {}
    assert run.summary["timing"]["step_rate_hz"] > 250  # faster than real time
    d = run.path
    for f in ("mission.toml", "vehicle.tlog", "controller.tlog", "trace.csv", "summary.json", "events.log",
              "vehicle.bin", "controller.bin"):
        assert (d / f).stat().st_size > 0, f
    on_disk = read_trace(d / "trace.csv")
    assert list(on_disk) == list(TRACE_COLUMNS)
    assert all(np.array_equal(on_disk[c], run.trace[c], equal_nan=True) for c in TRACE_COLUMNS)
    assert json.loads((d / "summary.json").read_text())["outcome"] == "completed"
    v = _tlog_types(d / "vehicle.tlog")
    c = _tlog_types(d / "controller.tlog")
    for kind in ("HEARTBEAT", "ODOMETRY", "SET_ACTUATOR_CONTROL_TARGET", "COMMAND_LONG", "COMMAND_ACK", "TIMESYNC"):
        assert v.get(kind) and c.get(kind), kind  # both directions on both sides
    # one target a step, and a second answer to each state resent after 50 ms unanswered (a loaded machine)
    again = run.summary["timing"]["answered_again"]
    assert v["ODOMETRY"] >= 7501 and v["SET_ACTUATOR_CONTROL_TARGET"] == 7500 + again


@pytest.fixture(scope="module")
def short_runs(tmp_path_factory) -> dict:
    """SHORT flown once in lockstep with the compiled kernels (``BSST_KERNELS=compiled``, as a warm worker's
    sessions fly under ``auto``) and once in real time (``bsst sitl`` defaults otherwise, no plots): the
    runs that test_lockstep_is_deterministic, test_lockstep_with_compiled_kernels_is_the_plain_lockstep,
    test_realtime_tracks_and_records_its_timing and test_a_clean_session_passes_every_policy each read (each flew
    its own copy before: three sessions more)."""
    d = tmp_path_factory.mktemp("short")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("BSST_KERNELS", "compiled")
        lockstep = sitl(SHORT, out=d / "l", plots=False, instance=None)
    return {"lockstep": lockstep, "realtime": sitl(SHORT, realtime=True, out=d / "r", plots=False, instance=None)}


def test_lockstep_is_deterministic(short_runs, tmp_path, monkeypatch):
    """The same flight twice, the same kernels (the fixture's): the same trace, byte for byte."""
    a = short_runs["lockstep"]
    monkeypatch.setenv("BSST_KERNELS", "compiled")
    b = sitl(SHORT, out=tmp_path / "b", plots=False, instance=None)
    assert a.outcome == b.outcome == "completed"
    assert (a.path / "trace.csv").read_bytes() == (tmp_path / "b" / "trace.csv").read_bytes()


def test_lockstep_with_compiled_kernels_is_the_plain_lockstep(short_runs, tmp_path, monkeypatch):
    """BSST_KERNELS=compiled (bridge.core.scalar, inherited by both children; the fixture's flight): the
    controller's law and the vehicle's plant compiled, the trace byte for byte the plain one's."""
    monkeypatch.setenv("BSST_KERNELS", "plain")
    a = sitl(SHORT, out=tmp_path / "a", plots=False, instance=None)
    b = short_runs["lockstep"]
    assert a.outcome == b.outcome == "completed"
    assert (tmp_path / "a" / "trace.csv").read_bytes() == (b.path / "trace.csv").read_bytes()


def test_lockstep_x500_motors_match_offline(tmp_path):
    """Motors over HIL_ACTUATOR_CONTROLS (flags bit 0: lockstep) also match offline."""
    off = simulate(SHORT, profile="x500", plots=False)
    run = sitl(SHORT, profile="x500", out=tmp_path / "x", plots=False, instance=None)
    assert run.outcome == "completed"
    _positions_close(run.trace, off.trace, 1e-4)
    os.environ["MAVLINK20"] = "1"
    log = mavutil.mavlink_connection(str(tmp_path / "x" / "controller.tlog"), dialect="common")
    m = log.recv_match(type="HIL_ACTUATOR_CONTROLS")
    assert m is not None and m.flags & 1 and 0.0 <= min(m.controls[:4]) and max(m.controls[:4]) <= 1.0


def test_realtime_tracks_and_records_its_timing(short_runs):
    off = simulate(SHORT, plots=False)
    run = short_runs["realtime"]
    assert run.outcome == "completed" and run.summary["clock"] == "realtime"
    stalls = run.summary["timing"]["stalls"]
    # every outage the trace shows is a stall the processes measured, and every long stall shows in the trace
    assert unexplained_outages(run.trace, stalls) == {"rows": [], "stalls": []}, stalls
    # the loop tracks as offline does, but for the socket, through the same outages: a host that takes its cores
    # back stalls the run (docs/sitl.md, "Stalls"), which then says so
    if stalls["count"]:
        off = simulate(SHORT, plots=False, link={"blackouts": stall_blackouts(stalls, SHORT.duration_s)})
        assert any(e["kind"] == "stall" for e in run.summary["events"])
    assert run.rms <= 2.0 * off.rms + 1e-3, stalls
    timing = run.summary["timing"]
    assert 0.9 < timing["real_time_factor"] < 1.1
    # the mission's time flown, from its time 0 (the printed header's duration): the trace's first row is step 1's,
    # step 0 flown on a target that came mid-period; until the third wave's thirty-ninth session both said rows x
    # period, one period short of the mission it completed
    assert run.summary["duration_s"] == pytest.approx(SHORT.duration_s) == timing["sim_s"], (timing, run.trace["t"][0])
    period = timing["period_error_ms"]
    assert period["p50"] < 1.0 and period["max"] >= period["p99"] >= period["p50"] >= 0.0
    for key in ("state_to_command_ms", "state_to_command_timesync_ms"):
        s = timing[key]
        assert 0.0 < s["p50"] <= s["p99"] <= s["max"], (key, s)
    assert np.all(run.trace["state_age_s"][10:] > 0.0)  # the command in force answers an older state


def _stall(pid: int, seconds: float) -> None:
    """Stop a process ``seconds`` long (SIGSTOP, SIGCONT), as a host that takes its core back stops it."""
    os.kill(pid, signal.SIGSTOP)
    time.sleep(seconds)  # the stall itself, not a wait for something to happen
    os.kill(pid, signal.SIGCONT)


def test_a_real_time_run_the_machine_stalls_lists_each_stall_by_side_and_exits_1(tmp_path):
    """The vehicle (0.3 s: past the 0.25 s a paced lockstep re-bases at), the controller and the relay (a 2 ms
    link; 0.2 s each) stopped (SIGSTOP, SIGCONT) mid-flight, as a host that takes its cores back stops them:
    ``timing.stalls`` lists the three, each on its side, the run completes (the vehicle caught its physics up:
    its clock is still the controller's), and its summary, stderr and exit status say it was not flown as asked.
    4.5 s of sine (a real-time run costs its length: it was 6 s), the stops 1.1 s apart, the last 1.1 s before
    the end."""
    (tmp_path / "m.toml").write_text('name = "stalls"\nduration_s = 4.5\n[trajectory]\nkind = "sine"\n' + HOLD)
    run = tmp_path / "run"
    with instance_slot() as n:
        p = _bsst_sitl(n, tmp_path / "m.toml", run, "--realtime", "--delay", "2")
        try:
            for rows, side, stop_s in ((250, "vehicle", 0.3), (525, "controller", 0.2), (800, "relay", 0.2)):
                wait_for(lambda rows=rows: count_records(run / "controller.bin") > rows, 60, f"{rows} rows flown")
                _stall(child_pids(run)[side], stop_s)
            out, err = p.communicate(timeout=60)
        finally:
            if p.poll() is None:
                p.kill()
    summary = json.loads((run / "summary.json").read_text())
    stalls = summary["timing"]["stalls"]
    assert summary["outcome"] == "completed" and p.returncode == 1, err
    long = [s for s in stalls["at"] if s["ms"] >= 180.0]  # the machine's own are ~100 ms (docs/sitl.md)
    assert [s["side"] for s in long] == ["vehicle", "controller", "relay"], stalls
    assert 1.0 <= long[0]["t"] < long[1]["t"] < long[2]["t"] < 4.5 and long[0]["ms"] >= 290.0, stalls
    assert stalls["count"] == len(stalls["at"]) >= 3
    assert "not flown as asked: the machine stalled the real-time loop" in err
    assert f"worst {stalls['worst_ms']:g} ms" in out
    notes = [e for e in summary["events"] if e["kind"] == "stall"]
    assert len(notes) == 1 and notes[0]["source"] == "session"


def test_a_controller_stalled_between_the_arm_and_its_first_target_is_named_with_the_failsafe(tmp_path):
    """The controller stopped (SIGSTOP) for 1.5 s as the vehicle arms on its ARM (a 200 ms link each way: its
    answer, and its first target, 200 ms off), as a machine busy at start-up stops it: no target comes for 0.5 s,
    the vehicle's failsafe takes over (as PX4's offboard loss), the run fails, and its summary names the stall with
    the failsafe: ``timing.stalls_waiting`` (not the mission's ``timing.stalls``), a session note, a line on
    stderr, exit 1. Until the forty-fifth session only the failsafe was said (``no actuator target for 0.5 s``):
    nothing noted the controller's stalls between the arm and its first target, nor said them."""
    (tmp_path / "m.toml").write_text('name = "armstall"\nduration_s = 2.0\n[trajectory]\nkind = "sine"\n' + HOLD)
    run = tmp_path / "run"
    with instance_slot() as n:
        p = _bsst_sitl(n, tmp_path / "m.toml", run, "--realtime", "--delay", "200")
        try:
            log = run / "events.log"
            wait_for(lambda: "[by 200:" in (log.read_text() if log.is_file() else ""), 60, "the vehicle armed")
            _stall(child_pids(run)["controller"], 1.5)
            out, err = p.communicate(timeout=60)
        finally:
            if p.poll() is None:
                p.kill()
    summary = json.loads((run / "summary.json").read_text())
    waiting = summary["timing"]["stalls_waiting"]
    assert summary["outcome"] == "failsafe" and p.returncode == 1, err
    assert waiting["count"] >= 1 and waiting["worst_ms"] >= 1300.0 and waiting["at"][0][0] < 0, waiting
    assert summary["timing"]["stalls"]["count"] == 0 or summary["timing"]["stalls"]["worst_ms"] < 180.0
    said = (f"the machine stalled the controller {waiting['count']} time(s) before the mission's first state "
            f"(after the vehicle's arm), worst {waiting['worst_ms']:g} ms")
    assert said in err and said in out, err
    notes = [e for e in summary["events"] if e["kind"] == "stall" and e["source"] == "session" and said in e["text"]]
    assert len(notes) == 1, summary["events"]  # (beside it, the loaded machine's own in the mission, if any)


def _start_session(tmp_path: Path, n: int, mission: Path = SINE) -> Bsst:
    return Bsst("sitl", str(mission), "--instance", str(n), "--out", str(tmp_path / "run"), "--no-plots", env=ENV)


def _interrupted(tmp_path: Path, interrupt) -> tuple[Bsst, Path, str, str, dict[str, int], float]:
    """Start ``bsst sitl``, let it fly a second, call ``interrupt(launcher, children pids)``;
    return the launcher (exited), its run directory, stdout, stderr, the pids and how long
    the launcher took to exit after the interrupt (s)."""
    with instance_slot() as n:
        p = _start_session(tmp_path, n)
        run = tmp_path / "run"
        try:
            wait_for(lambda: count_records(run / "controller.bin") > 250, 60, "a second of flight")
            pids = child_pids(run)
            t0 = time.monotonic()
            interrupt(p, pids)
            out, err = p.communicate(timeout=60)
            return p, run, out, err, pids, time.monotonic() - t0
        finally:
            if p.poll() is None:
                p.kill()


def test_controller_sigkill_means_failsafe_landing_exit_1(tmp_path):
    p, run, out, err, _, _ = _interrupted(tmp_path, lambda p, pids: os.kill(pids["controller"], signal.SIGKILL))
    assert p.returncode == 1, err
    assert "controller" in err and "SIGKILL" in err
    summary = json.loads((run / "summary.json").read_text())
    assert summary["outcome"] == "failsafe" and "outcome: failsafe" in out
    events = {e["kind"]: e for e in summary["events"] if e["source"] == "vehicle"}
    v = read_half(run / "vehicle.bin")
    last_cmd_t = v["cmd_k"][v["cmd_k"] >= 0].max() / 250.0
    t_fs = events["failsafe"]["t"]
    assert 0.5 < t_fs - last_cmd_t <= 0.5 + 1 / 250 + 1e-6  # within the timeout plus one step
    assert events["disarmed"]["text"].startswith("landed") and events["disarmed"]["t"] > t_fs
    trace = read_trace(run / "trace.csv")
    assert trace["t"][-1] > t_fs and abs(trace["z"][-1]) < 0.02  # flown down to the ground
    assert np.all(np.diff(trace["t"]) > 0)
    # the record: who ended it, the lockstep the vehicle left once its controller fell silent; flown safely
    assert summary["ended_by"] == {"who": "controller", "how": "died (killed by SIGKILL); the vehicle's failsafe "
                                                               "took over"}
    left = events["lockstep"]
    assert summary["lockstep"]["held"] is False and summary["lockstep"]["left_at_s"] == left["t"] < t_fs
    _policies_hold(summary)


SINE_8S = 'name = "long"\nduration_s = 8.0\n[trajectory]\nkind = "sine"\n'  # the user's tour's mission


@pytest.mark.parametrize("side", ["vehicle", "controller"])
def test_a_real_time_child_killed_leaves_link_counts_that_add_up_and_says_the_flight_was_cut_short(tmp_path, side):
    """A real-time session's vehicle or controller SIGKILLed a second into an 8 s mission leaves no stats report:
    each direction of the link is counted from both tlogs up to the dead side's cut, said so (``counted``), and adds
    up (sent = delivered + lost, none negative; delivered: the per-step messages both tlogs hold, read here with
    pymavlink), and the header gives the time flown beside the mission's 8 s. Until the third wave's forty-second
    session one side's counts stood in for the missing other's: a vehicle killed read ``up: sent 561 delivered 0
    lost 561``, ``down: sent 0 delivered 567 lost -567``, a controller killed ``up: sent 436 delivered 457 lost
    -21``, under ``duration 2.23 s`` alone."""
    mission = tmp_path / "long.toml"
    mission.write_text(SINE_8S)
    run = tmp_path / "run"
    with instance_slot() as n:
        # (COM_DISARM_LAND=0.5: a controller killed leaves the vehicle's failsafe to land it; its disarm, 0.5 s on
        # the ground rather than PX4's 2 s of wall time, ends the session sooner: nothing here looks at that wait)
        p = _bsst_sitl(n, mission, run, "--realtime", "--param", "COM_DISARM_LAND=0.5")
        try:
            wait_for(lambda: count_records(run / "vehicle.bin") > 250 or p.poll() is not None, 60,
                     "a second of flight")
            os.kill(child_pids(run)[side], signal.SIGKILL)
            out, err = p.communicate(timeout=60)
        finally:
            if p.poll() is None:
                p.kill()
    assert p.returncode == 1 and f"{side} (pid " in err and "killed by SIGKILL" in err, err
    s = json.loads((run / "summary.json").read_text())
    assert s["sitl"]["died"] == side and s["outcome"] == ("aborted" if side == "vehicle" else "failsafe"), s
    sysid = s["sitl"]["sysid"]
    for d, sender, receiver, src, kinds in (
            ("up", "controller", "vehicle", CONTROLLER_SYSID, ["SET_ACTUATOR_CONTROL_TARGET", "HIL_ACTUATOR_CONTROLS"]),
            ("down", "vehicle", "controller", sysid, "ODOMETRY")):
        link = s["link"][d]
        sent = {bytes(m.get_msgbuf()) for m in tlog_messages(run / f"{sender}.tlog", src, kinds)}
        both = sent & {bytes(m.get_msgbuf()) for m in tlog_messages(run / f"{receiver}.tlog", src, kinds)}
        assert link["delivered"] == len(both) > 200 and link["lost"] >= 0, (d, link)
        assert link["sent"] == link["delivered"] + link["lost"] <= len(sent), (d, link, len(sent))
        # reordered: each first copy the receiver's tlog holds after one sent later (null until the third wave's
        # forty-third session), as pymavlink reads the two tlogs
        order = {b: i for i, b in enumerate(bytes(m.get_msgbuf())
                                            for m in tlog_messages(run / f"{sender}.tlog", src, kinds))}
        seen, highest, late = set(), -1, 0
        for b in (bytes(m.get_msgbuf()) for m in tlog_messages(run / f"{receiver}.tlog", src, kinds)):
            if b in order and b not in seen:
                seen.add(b)
                late += order[b] < highest
                highest = max(highest, order[b])
        assert link["reordered"] == late, (d, link, late)
        assert f" reordered {late} " in out, out
        assert link["counted"].startswith(f"the {side} ended without its stats (killed by SIGKILL): each "), link
        assert f"link {d:4}: sent {link['sent']} delivered {link['delivered']} lost {link['lost']} " in out, out
        assert f"link {d:4}: counted: {link['counted']}" in out, out
    # the time flown, and the mission's length beside it: summary.json's duration_s is the time flown (as offline)
    flown = s["duration_s"]
    assert flown == s["timing"]["sim_s"] < 7.0 and s["mission_duration_s"] == 8.0, s["timing"]
    assert f"duration {flown:.2f} s of the mission's 8 s (cut short)" in out.splitlines()[0], out


def test_ctrl_c_stops_everything_within_2_s(tmp_path):
    p, run, _, err, pids, elapsed = _interrupted(tmp_path, lambda p, pids: p.send_signal(signal.SIGINT))
    assert elapsed < 2.0 and p.returncode == 1
    # named on stderr, as every exit-1 reason is (until the third wave's forty-first session on stdout alone)
    assert "bsst sitl: aborted: ended by user: interrupted (Ctrl-C or SIGTERM)" in err.splitlines(), err
    assert set(pids) == {"vehicle", "controller"}
    for pid in pids.values():
        with pytest.raises(ProcessLookupError):
            os.kill(pid, 0)  # reaped: gone, not even a zombie
    summary = json.loads((run / "summary.json").read_text())
    assert summary["outcome"] == "aborted"
    assert summary["ended_by"] == {"who": "user", "how": "interrupted (Ctrl-C or SIGTERM)"}
    trace = read_trace(run / "trace.csv")
    assert len(trace["t"]) > 250 and list(trace) == list(TRACE_COLUMNS)
    assert _tlog_types(run / "vehicle.tlog")["ODOMETRY"] > 250
    assert _tlog_types(run / "controller.tlog")["SET_ACTUATOR_CONTROL_TARGET"] > 250


def test_a_sessions_ports_are_picked_below_the_kernels_ephemeral_range():
    """The ports a session names to its children before they bind them (the controller's source port, the
    vehicle's listen port) come from below the range the kernel hands to sockets bound to port 0, so that no
    other socket takes one in between; each is free when picked."""
    lo = ephemeral_low()
    ports = [free_udp_port() for _ in range(RECENT_PORTS)]
    assert all(CHOSEN_PORTS_LOW <= p < lo for p in ports), ports
    # never one handed out again while its child may not have bound it yet (at random alone, 256 choices of ~12 800
    # ports repeat one nine times in ten)
    assert len(set(ports)) == len(ports)
    assert len({p // 1000 for p in ports}) > 5  # at random over the range, not in a row
    for port in ports[:5]:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.bind(("127.0.0.1", port))


# another process on the machine: it holds the port lock file's bytes from LO up to HI but KEEP, or says which
# of the PORTS it could not lock (each held by a process of its own)
_HOLD_BUT_ONE = """
import fcntl, os, sys
fd = os.open(sys.argv[1], os.O_RDWR | os.O_CREAT, 0o666)
lo, hi, keep = map(int, sys.argv[2:5])
fcntl.lockf(fd, fcntl.LOCK_EX | fcntl.LOCK_NB, keep - lo, lo)
fcntl.lockf(fd, fcntl.LOCK_EX | fcntl.LOCK_NB, hi - keep - 1, keep + 1)
print("held", flush=True)
sys.stdin.read()
"""
_HELD_ELSEWHERE = """
import fcntl, json, os, sys
fd = os.open(sys.argv[1], os.O_RDWR | os.O_CREAT, 0o666)
held = []
for port in map(int, sys.argv[2:]):
    try:
        fcntl.lockf(fd, fcntl.LOCK_EX | fcntl.LOCK_NB, 1, port)
        held.append(False)
    except OSError:
        held.append(True)
print(json.dumps(held))
"""


def test_a_port_chosen_in_one_process_is_never_chosen_in_another_before_it_is_forgotten(tmp_path, monkeypatch):
    """Two processes that start sessions side by side (the suite's workers) choose ports from the same range; a
    port is free until its child binds it, so each choice is held machine-wide (a byte of ``bsst-ports.lock`` in
    the temporary directory, here this test's own): another process sees it held, and skips the ports another
    process holds (the CI's suite met "--source-port 27523: cannot bind (Address already in use)")."""
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    lock = tmp_path / PORT_LOCKS
    lo = ephemeral_low()
    keep = random.randrange(CHOSEN_PORTS_LOW + 1, lo - 1)
    holder = subprocess.Popen([sys.executable, "-c", _HOLD_BUT_ONE, str(lock), str(CHOSEN_PORTS_LOW), str(lo),
                               str(keep)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline() == "held\n"  # type: ignore[union-attr]
        picks = [free_udp_port() for _ in range(10)]
    finally:
        holder.stdin.close()  # type: ignore[union-attr]
        holder.wait(timeout=30)
    mine = [free_udp_port() for _ in range(3)]  # (the other process gone: any port of the range again)
    probe = subprocess.run([sys.executable, "-c", _HELD_ELSEWHERE, str(lock), *map(str, mine)],
                           capture_output=True, text=True, timeout=60, check=True)
    assert json.loads(probe.stdout) == [True, True, True]
    assert all(CHOSEN_PORTS_LOW <= p < lo for p in mine), mine
    # the one port left, or (64 random tries missing it) the kernel's choice above the range: never a held one
    assert all(p == keep or p >= lo for p in picks), picks


def test_an_automatic_instance_is_the_highest_free_one(tmp_path, monkeypatch):
    """``instance_slot`` takes the highest free instance first, so that the low ones stay for the sessions a
    person starts by number (0 is ``bsst sitl``'s default; the README's example takes 1). Its lock files here
    in a directory of this test's own, so that no other test's slots count; a slot whose ports another process
    holds is passed over, as ever: instance 9's ground-station port held here, and any other instance's that
    the suite's sessions hold meanwhile (each pick is checked against what the real port check said, observed as
    it ran: the test once asserted 9 > 8 > 7-like order and failed when a loaded suite's sessions held 1-5)."""
    from bridge.session import children

    # the suite's own instance 9 held first (its lock in the real temp directory), so that no session of another
    # test binds instance 9's ground-station port while this test holds it
    suite_lock = os.open(os.path.join(tempfile.gettempdir(), "bsst-instance-9.lock"), os.O_RDWR | os.O_CREAT, 0o644)

    def locked() -> bool:
        try:
            fcntl.flock(suite_lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            return False
        return True

    wait_for(locked, 300.0, "the suite's instance 9")
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    checked: list[tuple[int, bool]] = []
    real = children._ports_free

    def observed(n: int) -> bool:
        free = real(n)
        checked.append((n, free))
        return free

    monkeypatch.setattr(children, "_ports_free", observed)
    held = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)

    def bound() -> bool:  # (a session of the suite's may hold it a while: then bound once it lets go)
        try:
            held.bind(("127.0.0.1", GCS_PORT + 9))
        except OSError:
            return False
        return True

    try:
        wait_for(bound, 120.0, f"UDP 127.0.0.1:{GCS_PORT + 9} free to hold")
    except AssertionError as exc:  # (once, in an eight-worker run: say who held it, for the next time)
        held.close()
        try:
            ss = subprocess.run(["ss", "-uanpH", f"sport = :{GCS_PORT + 9}"], capture_output=True, text=True)
            who = ss.stdout.strip() or ss.stderr.strip() or "nobody ss can see"
        except OSError as why:
            who = f"unknown ({why})"
        raise AssertionError(f"{exc}; held by: {who}") from None
    calls = []
    try:
        with instance_slot() as a:
            calls.append(checked[:])
            checked.clear()
            with instance_slot() as b:
                calls.append(checked[:])
                checked.clear()
                with instance_slot() as c:
                    calls.append(checked[:])
    finally:
        held.close()
        os.close(suite_lock)  # (closing releases the lock)
    assert calls[0][0] == (9, False), calls  # its port held: passed over
    for pick, seen in zip((a, b, c), calls, strict=True):
        # the highest first: every instance checked before the pick (higher, not locked here) had its ports held
        assert seen[-1] == (pick, True) and not any(free for _, free in seen[:-1]), (pick, seen)
        assert [n for n, _ in seen] == sorted((n for n, _ in seen), reverse=True), seen
    assert a not in [n for n, _ in calls[1] + calls[2]] and b not in [n for n, _ in calls[2]]  # locked: not checked
    assert {f"bsst-instance-{n}.lock" for n in (a, b, c)} <= {p.name for p in tmp_path.iterdir()}


def test_two_instances_fly_side_by_side(tmp_path):
    mission = tmp_path / "sine3.toml"
    mission.write_text(SINE_3S)
    with instance_slot() as a, instance_slot() as b:
        pa = _start_session(tmp_path / "a", a, mission)
        pb = _start_session(tmp_path / "b", b, mission)
        outs = [p.communicate(timeout=120) for p in (pa, pb)]
    assert pa.returncode == pb.returncode == 0, outs
    sa = json.loads((tmp_path / "a" / "run" / "summary.json").read_text())
    sb = json.loads((tmp_path / "b" / "run" / "summary.json").read_text())
    assert (sa["sitl"]["sysid"], sb["sitl"]["sysid"]) == (a + 1, b + 1)
    assert sa["link"]["rejected"] == sb["link"]["rejected"] == {}
    assert sa["link"]["up"]["delivered"] == sb["link"]["up"]["delivered"] == 750
    # nothing crossed: the same mission flown twice, side by side, gives the same trace
    assert (tmp_path / "a" / "run" / "trace.csv").read_bytes() == (tmp_path / "b" / "run" / "trace.csv").read_bytes()


# -- honest records: lockstep left, a flight ended by someone, the policies --------------------------------
def _policies_hold(summary: dict) -> None:
    assert [p["name"] for p in summary["policies"]] == list(POLICIES)
    assert all(p["ok"] for p in summary["policies"]), summary["policies"]


def test_a_clean_session_passes_every_policy(short_runs):
    """Both clocks: every policy holds, lockstep held, the mission ended the flight, and the
    controller's refused frames and everyone else's are counted apart (none of either here)."""
    lock, real = short_runs["lockstep"], short_runs["realtime"]
    for run in (lock, real):
        s = run.summary
        assert s["outcome"] == "completed" and s["ended_by"] == {"who": "mission", "how": "completed"}
        _policies_hold(s)
        assert s["link"]["rejected_from_peer"] == s["link"]["rejected_from_others"] == {"vehicle": 0, "controller": 0}
        assert "ended: completed: by mission: completed [session]" in (run.path / "events.log").read_text()
    assert lock.summary["lockstep"] == {"held": True} and "lockstep" not in real.summary


def _bsst_sitl(n: int, mission: Path, out: Path, *extra: str) -> Bsst:
    return Bsst("sitl", str(mission), "--instance", str(n), "--out", str(out), "--no-plots", *extra, env=ENV)


def test_a_lockstep_run_that_leaves_lockstep_says_so_and_exits_1(tmp_path):
    """The controller stalls (SIGSTOP) mid-flight until the vehicle gives it up and leaves
    lockstep, then goes on (SIGCONT): the rest is flown on the wall clock. The run says when and
    why (summary.json, events.log, the printed summary), and it is no lockstep completion: exit 1,
    whatever the outcome (the controller back in time completes the mission; too late, the
    vehicle's failsafe took over). A 3 s mission: what follows the stall (~1.1 s) is all on the wall clock."""
    mission = tmp_path / "sine3.toml"
    mission.write_text(SINE_3S)
    run = tmp_path / "run"
    with instance_slot() as n:
        p = _bsst_sitl(n, mission, run)
        try:
            wait_for(lambda: count_records(run / "controller.bin") > 250 or p.poll() is not None, 60,
                     "a second of flight")
            pid = child_pids(run)["controller"]
            os.kill(pid, signal.SIGSTOP)
            try:
                wait_for(lambda: "lockstep: controller silent" in (run / "events.log").read_text(), 20,
                         "the vehicle leaving lockstep")
            finally:
                os.kill(pid, signal.SIGCONT)
            out, err = p.communicate(timeout=120)
        finally:
            if p.poll() is None:
                p.kill()
    assert p.returncode == 1, (out, err)
    s = json.loads((run / "summary.json").read_text())
    left = next(e for e in s["events"] if e["kind"] == "lockstep" and e["source"] == "vehicle")
    assert s["clock"] == "lockstep" and s["outcome"] in ("completed", "failsafe")
    assert s["lockstep"] == {"held": False, "left_at_s": left["t"], "why": left["text"], "times": 1}
    assert 1.0 <= left["t"] < 3.0 and "controller silent for 0.5 s" in left["text"]
    assert f"left lockstep at t={left['t']:.3f} s: controller silent" in out
    assert f"bsst sitl: not a lockstep run: the vehicle left lockstep at t={left['t']:.3f} s" in err
    assert "not a lockstep run: the vehicle left lockstep" in (run / "events.log").read_text()
    _policies_hold(s)  # recorded, and flown safely
    if s["outcome"] == "completed":  # exit 1 all the same (it was exit 0 and "completed" before)
        assert s["ended_by"] == {"who": "mission", "how": "completed"}
        assert s["sitl"]["controller_exit"] == "exited with status 1"  # it heard the vehicle say so


def test_a_ground_station_that_disarms_the_vehicle_in_flight_is_named(tmp_path):
    """A ground station (pymavlink, on the GCS link, as MAVProxy would) sends a few corrupted
    frames, then a forced disarm in the air: the mission is ended by someone, so outcome
    ``aborted``, exit 1, and ``ended_by`` names the sender; the station's bad frames are not
    the controller's; the arm and the disarm had authority."""
    mission = tmp_path / "sine6.toml"
    mission.write_text(SINE_6S)
    run = tmp_path / "run"
    os.environ["MAVLINK20"] = "1"
    with instance_slot() as n:
        gcs = mavutil.mavlink_connection(f"udpin:127.0.0.1:{GCS_PORT + n}", source_system=255, source_component=190,
                                         dialect="common")
        p = _bsst_sitl(n, mission, run, "--speed", "1")
        try:
            assert gcs.wait_heartbeat(timeout=30) is not None

            def flown_2s() -> bool:  # reading the telemetry meanwhile, as a ground station does: a full
                while gcs.recv_msg() is not None:  # socket buffer would drop the COMMAND_ACK to come
                    pass
                return count_records(run / "vehicle.bin") > 500 or p.poll() is not None

            wait_for(flown_2s, 60, "2 s of flight")
            bad = bytearray(gcs.mav.heartbeat_encode(6, 8, 0, 0, 4, 3).pack(gcs.mav))
            bad[-1] ^= 0xFF  # a wrong checksum
            for _ in range(3):
                gcs.write(bytes(bad))  # to the vehicle's GCS link, which it heard from
            gcs.mav.command_long_send(n + 1, 1, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 0, 21196, 0, 0, 0, 0, 0)
            ack = gcs.recv_match(type="COMMAND_ACK", blocking=True, timeout=10)
            assert ack is not None and ack.result == mavlink.MAV_RESULT_ACCEPTED
            out, err = p.communicate(timeout=120)
        finally:
            if p.poll() is None:
                p.kill()
            gcs.close()
    assert p.returncode == 1, (out, err)
    s = json.loads((run / "summary.json").read_text())
    assert s["outcome"] == "aborted"
    disarm = next(e for e in s["events"] if e["kind"] == "disarmed" and e["source"] == "vehicle")
    assert 2.0 <= disarm["t"] < 6.0
    assert s["ended_by"]["how"] == f"disarmed in flight by command at t={disarm['t']:.3f} s"
    if "[by " in disarm["text"]:  # the vehicle names the sender of every arm and disarm
        assert s["ended_by"]["who"] == f"255:190 127.0.0.1:{GCS_PORT + n} gcs"
    else:
        assert s["ended_by"]["who"].startswith("someone")
    assert f"ended by {s['ended_by']['who']}: disarmed in flight" in out
    assert f"ended: aborted: by {s['ended_by']['who']}" in (run / "events.log").read_text()
    _policies_hold(s)
    link = s["link"]
    assert link["rejected"].get("bad_crc") == 3
    # the station's three are others'; the controller's own are its targets still in flight after the disarm
    assert link["rejected_from_others"]["vehicle"] == 3
    own = sum(link["rejected_by"]["vehicle"].values()) - 3
    assert link["rejected_from_peer"]["vehicle"] == own == link["rejected"].get("not_offboard", 0)


def test_the_lines_a_child_writes_after_ready_in_the_same_read_are_kept(tmp_path):
    """The children start at once, so the controller may arm the vehicle before the session reads the
    vehicle's ``ready``: its ``event ... armed`` line then comes in the same read, and must count (it was
    dropped once, and the session's policy saw a flight that was never armed: exit 1 on a clean run).
    A real process writes both lines in one write to a real pipe."""
    from bridge.core.flight import prepare
    from bridge.nodes.report import Event, Ready, to_line
    from bridge.session import Session
    from bridge.session.children import Child

    session = Session(prepare(Mission(Sine(), duration_s=1.0, name="ready")), tmp_path, realtime=False,
                      instance=None, gcs=None, speed=None, progress=None, live=False)
    child = Child.__new__(Child)  # a Child whose process is not bsst: one that writes the two lines at once
    child.name, child.log, child._buf, child.eof, child.stats, child.done = "vehicle", tmp_path / "v.log", b"", \
        False, {}, None
    lines = to_line(Ready("vehicle", listen="x")) + "\n" + to_line(Event(0.0, "armed", "armed, offboard control"))
    child.proc = subprocess.Popen([sys.executable, "-c", f"import os; os.write(1, {(lines + chr(10)).encode()!r})"],
                                  stdout=subprocess.PIPE)
    child.fd = child.proc.stdout.fileno()
    child.proc.wait(timeout=30)  # both lines are in the pipe before the session reads
    os.set_blocking(child.fd, False)
    ready = session._wait_ready(child)
    child.proc.stdout.close()
    assert ready.listen == "x"
    # kept, and handled once every child is up, with the others' in the order of their times (Session._start)
    assert [r.kind for _, r in session._early] == ["armed"]
    session._handle(session._early)
    assert session.vehicle_armed and [e.kind for e in session.events] == ["armed"]


def test_an_instance_whose_port_another_program_holds_is_passed_over() -> None:
    """instance_slot: a slot whose ground-station or vehicle port something outside the locks has bound (a ground
    station listening, or a process of the slot's last holder still closing: the suite's "Address already in use")
    is not handed out; once the port is free the slot is taken again."""
    import socket

    with instance_slot() as n:
        pass
    for port in (GCS_PORT + n, LINK_PORT + n):  # its ground station's port, then its vehicle's
        holder = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        holder.bind(("127.0.0.1", port))
        try:
            with instance_slot() as m:
                assert m != n
        finally:
            holder.close()


def test_a_mission_that_starts_outside_its_fence_ends_as_offline(tmp_path: Path, capsys) -> None:
    """PX4's pre-arm geofence check in a session: the controller's arm of a vehicle standing outside its fence is
    answered TEMPORARILY_REJECTED, as PX4's commander answers it (its event names whose arm); the session ends as
    ``bsst sim`` does (tests/test_geofence.py): ``denied``, ended by the vehicle saying why, nothing flown, exit 1.
    A sweep of it
    measures nothing (its cells ``denied``, exit 1); a margin search refuses it (exit 2, one line)."""
    plan = outside_fence_plan(tmp_path)
    offline = simulate(plan, plots=False)
    with instance_slot() as n:
        r = run_bsst("sitl", str(plan), "--instance", str(n), "--no-plots", "--out", str(tmp_path / "sitl"), cwd=ROOT,
                     timeout=120)
    assert r.returncode == 1, r.stdout[-2000:] + r.stderr[-2000:]
    summary = json.loads((tmp_path / "sitl" / "summary.json").read_text())
    assert summary["outcome"] == offline.summary["outcome"] == "denied", summary["ended_by"]
    assert summary["ended_by"] == offline.summary["ended_by"], (summary["ended_by"], offline.summary["ended_by"])
    assert summary["ended_by"]["how"].startswith(f"{OUTSIDE_WHY} (GF_ACTION = 2: hold)"), summary["ended_by"]
    said = {e["kind"]: e["text"] for e in summary["events"]}
    assert said["preflight"].startswith(OUTSIDE_WHY) and "MAV_RESULT_TEMPORARILY_REJECTED" in said["aborted"], said
    assert " [by 200:191 127.0.0.1:" in said["preflight"] and said["preflight"].endswith(" controller]"), said  # whose
    assert len(read_trace(tmp_path / "sitl" / "trace.csv")["t"]) == 0
    # a campaign of it measures nothing: a sweep's cells say why (exit 1), a margin search refuses it (exit 2)
    # (run by their main in this process, as the suite runs the campaigns whose results it reads: a forked sweep
    # starts a pool server of its own, ~1 CPU-s; this process's serves all its sweeps)
    capsys.readouterr()
    rc = main(["sweep", str(plan), "--delay", "0,20", "--out", str(tmp_path / "sweep"), "--no-plots", "--jobs", "1"])
    err = capsys.readouterr().err
    assert rc == 1 and "every cell failed (2 of 2)" in err, err
    cells = (tmp_path / "sweep" / "cells.csv").read_text().splitlines()
    assert len(cells) == 3 and all(",denied,error," in c and OUTSIDE_WHY in c for c in cells[1:]), cells
    report = (tmp_path / "sweep" / "report.md").read_text()
    assert report.count(f"| {OUTSIDE_WHY}") == 2 and "## Cells that could not be flown" in report, report
    rc = main(["margin", str(plan), "--over", "delay_ms", "--until", "rms=0.1", "--out", str(tmp_path / "m")])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1, err
    assert err.startswith("bsst: margin: a cell could not be flown: arming denied: outside its fence"), err


def test_the_battery_failsafe_flies_in_lockstep_as_offline_and_the_ground_station_sees_it(tmp_path: Path) -> None:
    """The x500 from 8 % of its pack, COM_LOW_BAT_ACT 2 (tests/test_battery_failsafe.py): the
    session flies what ``bsst sim`` flies (the same events at the same times, the trace within the float32 wire's
    1e-4 m), and the ground-station link says it: CRITICAL STATUSTEXTs of the levels, and BATTERY_STATUS's charge
    state LOW."""
    mission = battery_mission(tmp_path, 8.0)
    params = ("--param", "COM_LOW_BAT_ACT=2")
    offline = simulate(mission, plots=False, params={"COM_LOW_BAT_ACT": 2})
    with instance_slot() as n:
        r = run_bsst("sitl", str(mission), *params, "--instance", str(n), "--no-plots", "--out", str(tmp_path / "s"),
                     cwd=ROOT, timeout=240)
    assert r.returncode == 1, r.stdout[-2000:] + r.stderr[-2000:]
    summary = json.loads((tmp_path / "s" / "summary.json").read_text())
    assert summary["outcome"] == offline.summary["outcome"] == "failsafe"
    assert summary["ended_by"] == offline.summary["ended_by"], (summary["ended_by"], offline.summary["ended_by"])

    def said(events: list) -> list:  # the vehicle's (a session's events carry the controller's too)
        return [(e["t"], e["text"]) for e in events if e["kind"] in ("battery", "failsafe")
                and e.get("source", "vehicle") == "vehicle"]

    assert said(summary["events"]) == said(offline.summary["events"]) and len(said(offline.summary["events"])) == 3
    lock = read_trace(tmp_path / "s" / "trace.csv")
    k = min(len(lock["t"]), len(offline.trace["t"]))
    assert max(float(np.max(np.abs(lock[c][:k] - offline.trace[c][:k]))) for c in ("x", "y", "z")) < 1e-4
    log = mavutil.mavlink_connection(str(tmp_path / "s" / "vehicle.tlog"), dialect="common")
    texts, states, joiner = [], [], StatusTextJoiner()  # (the chunks of a long text joined, as a ground station does)
    while (m := log.recv_match(type=["STATUSTEXT", "BATTERY_STATUS"])) is not None:
        if m.get_type() == "STATUSTEXT":
            texts += joiner.add(m, 0.0)
        elif not states or states[-1] != m.charge_state:
            states.append(m.charge_state)
    crit = list(dict.fromkeys(t for sev, t in texts  # (each once: the tlog holds both links' copies)
                              if sev == mavlink.MAV_SEVERITY_CRITICAL and t.startswith(("battery:", "failsafe: b"))))
    assert crit[:2] == ["battery: low: 8.0 % left (BAT_LOW_THR = 15 %)",
                        "battery: critical: 7.0 % left (BAT_CRIT_THR = 7 %)"], texts
    assert states[0] == mavlink.MAV_BATTERY_CHARGE_STATE_LOW, states  # (0.5 Hz of wall time: CRITICAL, test_inject)


def test_sitl_names_a_t0_wind_event_where_it_was_given(tmp_path: Path) -> None:
    """``bsst sitl`` of tests/test_air_at_start.py's mission ([wind] 10 m/s, an event of 3 m/s from 90 deg at 0 s):
    its vehicle reads the run's copy of the mission (``run/mission.toml``), and
    until the forty-fifth session's review the block and the line named that copy's event, where bsst sim and the
    session's other lines name the file given (``m.toml: events (t_s = 0, kind = wind)``)."""
    m = tmp_path / "m.toml"
    m.write_text(HEAD + EVENT.format(t=0.0) + "[wind]\nspeed_mps = 10.0\n")
    run = sitl(m, instance=None, out=tmp_path / "run", plots=False)
    wind = run.summary["wind"]
    assert wind["steady_at_start"] == {"speed_mps": 3.0, "from_deg": 90.0,
                                       "by": f"{m}: events (t_s = 0, kind = wind)"}, wind  # run/mission.toml's before
    assert wind["mean_speed_mps"] == pytest.approx(3.0, abs=0.01), wind
