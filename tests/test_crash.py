"""Covers bridge.session, bridge.record.runlog and bridge.sweep.executors.

Crash safety (issue 7): SIGKILL of the vehicle, the controller or the launcher at a random
moment of a real ``bsst sitl`` session; every file stays readable (benchmarks/crash.py runs
the loop 20 times). Issue 11: SIGKILL of ``bsst sweep`` leaves none of its processes running."""

from __future__ import annotations

import json
import os
import random
import signal
import sys

import pytest

from bridge.session import instance_slot
from tests.hostile import CRASH_STEPS, kill_session
from tests.sitlkit import ROOT, Proc
from tests.waiting import wait_for

pytestmark = pytest.mark.process  # starts processes or opens sockets: not in make test-fast


@pytest.mark.parametrize("victim", ["vehicle", "controller", "launcher"])
def test_sigkill_at_a_random_moment_leaves_every_file_readable(tmp_path, victim):
    at = random.Random(f"crash-{victim}").randint(1, CRASH_STEPS - 300)
    rc, found = kill_session(tmp_path, victim, at)
    assert found["vehicle.bin"] >= at - 1
    if victim == "launcher":  # killed mid-join: the trace may lag its halves, never lead them
        assert found["trace.csv"] <= min(found["vehicle.bin"], found["controller.bin"]), found
    else:  # the launcher survives and joins the rest: one trace row per step the vehicle wrote up to the
        # mission's last (a failsafe's steps after it are kept apart, as offline's trace ends there)
        assert found["trace.csv"] == min(found["vehicle.bin"], CRASH_STEPS), found
    assert found["vehicle.tlog"] > 0 and found["controller.tlog"] > 0
    summary = tmp_path / f"run-{victim}" / "summary.json"
    if victim == "launcher":
        assert rc == -signal.SIGKILL and found["summary"] is None  # killed before it could write one
    else:
        assert rc == 1, found
        s = json.loads(summary.read_text())
        expect = {"vehicle": "aborted", "controller": "failsafe"}[victim]
        assert s["outcome"] == expect and (victim == "controller" or s["sitl"]["died"] == "vehicle")


# -- issue 11: a SIGKILL of `bsst sweep` leaves no worker, and no cell's vehicle or controller -----------
def _processes() -> dict[int, tuple[int, int, str, str]]:
    """Every process now: pid -> (parent pid, process group, start time, command line); zombies left out."""
    out = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
            with open(f"/proc/{entry}/cmdline", "rb") as f:
                cmd = f.read().replace(b"\0", b" ").decode(errors="replace")
        except (FileNotFoundError, ProcessLookupError):
            continue
        if fields[0] not in ("Z", "X"):
            out[int(entry)] = (int(fields[1]), int(fields[2]), fields[19], cmd)
    return out


def _descendants(root: int) -> dict[int, tuple[str, str]]:
    """The processes below ``root`` (children, theirs, ...): pid -> (start time, command line)."""
    procs = _processes()
    found = {root}
    grew = True
    while grew:
        more = {pid for pid, (ppid, *_rest) in procs.items() if ppid in found} - found
        found |= more
        grew = bool(more)
    return {pid: (procs[pid][2], procs[pid][3]) for pid in found - {root} if pid in procs}


def _left(seen: dict[int, tuple[str, str]], group: int) -> list[str]:
    """Which of ``seen`` still run (the same pid and start time), and anything still in process group ``group``."""
    now = _processes()
    left = {pid for pid, (start, _) in seen.items() if pid in now and now[pid][2] == start}
    left |= {pid for pid, (_, pgid, _, _) in now.items() if pgid == group}
    return sorted(f"{pid} {now[pid][3][:90]}" for pid in left if pid in now)


@pytest.mark.parametrize("mode", ["offline", "lockstep"])
def test_sigkill_of_a_sweep_ends_its_workers_and_their_children(tmp_path, mode):
    """``bsst sweep --jobs 2`` (its own process group) flies two long cells; SIGKILL of its main process
    only: every process it started (forkserver, workers and, with ``--lockstep``, each cell's vehicle
    and controller) is gone within the deadline, and no session's temporary directory is left."""
    mission = tmp_path / "long.toml"
    mission.write_text(f'name = "long"\nduration_s = {300.0 if mode == "offline" else 120.0}\n'
                       '[trajectory]\nkind = "sine"\nclimb = 0.0\n')
    p = Proc.bsst("sweep", str(mission), "--delay", "0,5", "--jobs", "2", f"--{mode}", "--out", str(tmp_path / "s"),
                  "--no-plots")
    seen: dict[int, tuple[str, str]] = {}
    try:
        def flying() -> bool:
            tree = _descendants(p.p.pid)
            seen.update(tree)
            workers = [pid for pid, (_, cmd) in tree.items() if "multiprocessing.forkserver" in cmd]
            cells = [cmd for _, cmd in tree.values() if " -m bridge vehicle " in cmd or " -m bridge controller " in cmd]
            return len(workers) >= 3 and (mode == "offline" or len(cells) >= 4)  # the forkserver and 2 workers

        # (each look reads every process of the machine, ~3 ms with 80 of them: looked at every 10 ms, the wait
        # took a quarter of a core)
        wait_for(lambda: flying() or p.p.poll() is not None, 120, "two cells in flight", poll_s=0.05)
        assert p.p.poll() is None, p.lines
        temp = {cmd.split("/mission.toml")[0].rsplit(" ", 1)[1] for _, cmd in seen.values() if "bsst-sitl-" in cmd}
        assert len(temp) == (2 if mode == "lockstep" else 0), temp
        os.kill(p.p.pid, signal.SIGKILL)
        p.p.wait(timeout=10)
        try:
            wait_for(lambda: not _left(seen, p.p.pid), 30, "every process of the killed sweep gone", poll_s=0.05)
        except AssertionError as exc:
            raise AssertionError(f"{exc}; still running: {_left(seen, p.p.pid)}") from None
        assert not [d for d in temp if os.path.exists(d)], temp  # each session stopped and removed its directory
    finally:
        for entry in _left(seen, p.p.pid):  # only what this test started, by pid: a failed run leaves nothing
            os.kill(int(entry.split()[0]), signal.SIGKILL)
        p.stop()


# -- the suite's own children: a bare vehicle (it runs until stopped) does not outlive a killed test process ----
HOLDER = """
import sys, time
from bridge.nodes.report import Ready
from tests.sitlkit import Proc
p = Proc.bsst("vehicle", "--instance", sys.argv[1])
p.wait_report(Ready, timeout=60)
print(p.p.pid, flush=True)
time.sleep(600)
"""


def test_a_bare_vehicle_started_by_a_test_dies_with_the_test_process():
    """tests/sitlkit.py's ``Proc`` starts a child in its own session (so a test can signal its group) and asks
    for SIGTERM when its parent dies: a pytest killed mid-test leaves no bare vehicle holding its ports."""
    vehicle = -1
    with instance_slot() as n:
        holder = Proc([sys.executable, "-c", HOLDER, str(n)], cwd=ROOT)
        try:
            line = holder.wait_line(lambda s: s.strip().isdigit(), timeout=60)
            vehicle = int(line)
            assert vehicle in _processes(), "the vehicle was not running"
            os.kill(holder.p.pid, signal.SIGKILL)
            holder.p.wait(timeout=10)
            wait_for(lambda: vehicle not in _processes(), 30, "the orphaned vehicle's exit")
        finally:
            if vehicle in _processes():  # only what this test started: a failed run leaves nothing behind
                os.kill(vehicle, signal.SIGKILL)
            holder.stop()
