"""Covers bridge.sweep.margin and bridge.core.interrupt: Ctrl-C during ``bsst margin``.

A margin search stopped by Ctrl-C keeps what it flew: margin.json is written with ``interrupted`` true, each law's
``interrupted_in`` and its bracket so far (no margin its bisection did not reach), the summary says so, and the
exit status is 1; on the process pool the cells in flight end first and are kept, and a second Ctrl-C ends the
workers at once. A Ctrl-C that lands once margin.json is complete changes nothing: the exit status is the
result's (it was 130, death by SIGINT in the interpreter's exit, or 1, or a traceback). Each case is a real
``bsst margin`` process sent a real SIGINT to its process group, as a terminal's Ctrl-C is.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from bridge.core.interrupt import sigint_deferred
from bridge.sweep.margin import MarginInterrupted, margin, parse_until
from missions import Mission, Sine
from params import dump_toml
from tests.sitlkit import ROOT, Bsst, pool_workers, run_bsst
from tests.waiting import sweep_said, wait_for

# starts processes (not in make test-fast); flies the batch engine (its kernels loaded first)
pytestmark = [pytest.mark.process, pytest.mark.usefixtures("batch_kernels")]

UNTIL = ["--over", "delay_ms", "--until", "rms=0.1"]
SHORT = Mission(Sine(), duration_s=6.0, name="short")  # its search: ~24 cells of ~10 ms each on the batch
MID = Mission(Sine(), duration_s=60.0, name="mid")  # ~2.5 s of work a cell on the process engine
HALF = Mission(Sine(), duration_s=30.0, name="half")  # ~1 s of work a cell flown plain in the command's process
# a cell: ~0.3 s on the batch; its search fails at every value (8 rounds, 16 ms down to 0): a Ctrl-C after the
# third round lands with five still to fly
WIDE = Mission(Sine(climb=0.0), duration_s=200.0, name="wide")
LONG = Mission(Sine(climb=0.0), duration_s=1800.0, name="long")  # a cell: ~17 s of work on the process engine


def _file(tmp_path: Path, m: Mission) -> Path:
    f = tmp_path / f"{m.name}.toml"
    f.write_text(dump_toml(m.to_dict()))
    return f


def _stopped(proc: Bsst, timeout_s: float = 120.0) -> tuple[str, str]:
    """What ``proc`` says once it has ended (within ``timeout_s``), killed if it has not."""
    try:
        return proc.communicate(timeout=timeout_s)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()


def _flying(group: int, cpu_s: float = 0.3) -> bool:
    """Whether a pool worker of ``group`` has used ``cpu_s`` of CPU: it flies a cell (a forked worker imports
    nothing first)."""
    def cpu(pid: int) -> float:
        try:
            fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            return 0.0
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")  # utime, stime

    return any(cpu(pid) >= cpu_s for pid in pool_workers(group))


def _after_round(n: int):  # noqa: ANN202  (a predicate on the search's progress lines)
    return lambda line: line.startswith("margin over delay_ms: ") and line.split()[3].isdigit() \
        and int(line.split()[3]) >= n


def _interrupted(out: Path, said: str, err: str) -> dict[str, Any]:
    """margin.json of an interrupted search, checked against what the command said."""
    res = json.loads((out / "margin.json").read_text())
    assert res["interrupted"] is True, res
    assert f"{res['cells_flown']} cells flown (interrupted)" in said, said
    assert "bsst margin: interrupted: margin.json keeps the cells flown" in err and "Traceback" not in err, err
    assert sum(len(e["cells"]) for e in res["controllers"]) == res["cells_flown"]
    return res


@pytest.mark.parametrize("stop", ["ctrl-c", "sigterm"])
def test_an_interrupted_search_keeps_its_bracket(tmp_path: Path, stop: str) -> None:
    """Ctrl-C after three rounds of the batch engine (a cell ~0.3 s): margin.json holds every cell flown, the bracket
    they give (the largest value held, the smallest failed), no margin, and the command exits 1. A SIGTERM to the
    command's process alone (a scheduler's) is a Ctrl-C (it died at once, no margin.json)."""
    out = tmp_path / "m"
    proc = Bsst("margin", _file(tmp_path, WIDE), *UNTIL, "--out", out)
    try:
        sweep_said(proc, _after_round(3), timeout_s=300)
        if stop == "ctrl-c":
            os.killpg(proc.pid, signal.SIGINT)
        else:
            os.kill(proc.pid, signal.SIGTERM)
    finally:
        said, err = _stopped(proc)
    assert proc.returncode == 1, (said, err)
    res = _interrupted(out, said, err)
    (law,) = res["controllers"]
    assert res["cells_flown"] >= 3 and law["interrupted_in"] == "bisection" and law["margin"] is None, law
    held = [c["delay_ms"] for c in law["cells"] if not c["failed"]]
    failed = [c["delay_ms"] for c in law["cells"] if c["failed"]]
    assert law["bracket"] == [max(held, default=None), min(failed, default=None)], law
    assert not law["held_to_range"] and law["checked_below"] is None and law["monotone"] is None
    assert "margin bsst: delay_ms: interrupted (bracket so far [" in said, said
    refused = run_bsst("report", out)  # not a sweep's directory: said in one line
    assert refused.returncode == 2 and "a `bsst margin` directory (margin.json" in refused.stderr, refused.stderr


def test_a_cell_flown_in_this_process_stops_at_once_and_is_not_a_result(tmp_path: Path) -> None:
    """``--engine process`` with one law and seed flies each probe in the command's own process: a Ctrl-C during the
    second probe ends that flight, which is not recorded (it was recorded as a failed value, ``aborted``, and the
    search went on to its end, exit 0)."""
    out = tmp_path / "m"
    proc = Bsst("margin", _file(tmp_path, HALF), *UNTIL, "--engine", "process", "--out", out)
    try:
        sweep_said(proc, _after_round(1), timeout_s=300)  # the second probe (32 ms) flies from here, ~1 s
        os.killpg(proc.pid, signal.SIGINT)
    finally:
        said, err = _stopped(proc)
    assert proc.returncode == 1, (said, err)
    (law,) = _interrupted(out, said, err)["controllers"]
    assert [(c["delay_ms"], c["outcome"]) for c in law["cells"]] == [(16.0, "completed")], law["cells"]
    assert law["bracket"] == [16.0, None] and law["margin"] is None


def test_the_cells_in_flight_end_and_are_kept(tmp_path: Path) -> None:
    """On the process pool (two laws, two seeds: four cells a round, two in flight with ``--jobs 1``) the first
    Ctrl-C lets the cells in flight end, says so, and keeps them: bsst's at 16 ms, none of pid's; a value only some
    of whose seeds were flown is neither held nor failed."""
    out = tmp_path / "m"
    proc = Bsst("margin", _file(tmp_path, MID), *UNTIL, "--engine", "process", "--seeds", "2", "--scatter", "0.01",
                "--controller", "bsst,pid", "--jobs", "1", "--out", out)
    try:
        wait_for(lambda: _flying(proc.pid), 120, "a pool worker flying the first round's first cell")
        os.killpg(proc.pid, signal.SIGINT)
        sweep_said(proc, lambda line: line.startswith("margin: interrupted; the cells in flight end first"))
    finally:
        said, err = _stopped(proc)
    assert proc.returncode == 1, (said, err)
    own, pid = _interrupted(out, said, err)["controllers"]
    assert [c["seed"] for c in own["cells"]] in ([0], [0, 1]) and not pid["cells"], own["cells"]
    assert all(c["delay_ms"] == 16.0 and c["outcome"] == "completed" for c in own["cells"])
    assert own["bracket"] == ([16.0, None] if len(own["cells"]) == 2 else [None, None]), own
    assert pid["bracket"] == [None, None] and own["interrupted_in"] == pid["interrupted_in"] == "bisection"


def test_a_second_ctrl_c_ends_the_workers_at_once(tmp_path: Path) -> None:
    """Half-hour cells on the pool: the second Ctrl-C ends their workers at once (the command gone within 10 s, its
    workers with it: 0.1 s here), and margin.json says nothing was flown."""
    out = tmp_path / "m"
    proc = Bsst("margin", _file(tmp_path, LONG), *UNTIL, "--engine", "process", "--seeds", "3", "--scatter", "0.01",
                "--jobs", "1", "--out", out)
    try:
        wait_for(lambda: pool_workers(proc.pid), 120, "a pool worker flying the first round")
        os.killpg(proc.pid, signal.SIGINT)
        sweep_said(proc, lambda line: "Ctrl-C again stops them now" in line)  # (two at once would be one signal)
        os.killpg(proc.pid, signal.SIGINT)
        said, err = proc.communicate(timeout=10)  # (a search waiting for the cells would end 17 s or more later)
        assert proc.returncode == 1 and not pool_workers(proc.pid), (said, err)
    finally:
        _stopped(proc, 0)
    (law,) = _interrupted(out, said, err)["controllers"]
    assert not law["cells"] and law["bracket"] == [None, None] and law["margin"] is None


def test_a_ctrl_c_once_margin_json_is_written_keeps_the_results_status(tmp_path: Path) -> None:
    """SIGINT as soon as the complete margin.json exists, to a ``python -m bridge`` that exits as a terminal's
    ``bsst`` does (its interpreter's own exit, not a fork server's child): exit 0, no traceback, the file complete.
    Before, 15 times in 15: death by SIGINT in the interpreter's exit (130 in a shell) 7 times, a traceback 4 times,
    ``bsst: interrupted`` and exit 1 4 times."""
    out = tmp_path / "m"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen([sys.executable, "-m", "bridge", "margin", _file(tmp_path, SHORT), *UNTIL,
                             "--check-below", "0", "--out", out], cwd=ROOT, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        wait_for(lambda: (out / "margin.json").exists() or proc.poll() is not None, 300, "margin.json", 0.001)
        os.killpg(proc.pid, signal.SIGINT)  # (not reaped yet: its group is there, whether it has ended or not)
        said, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0 and "Traceback" not in err and "KeyboardInterrupt" not in err, (proc.returncode, err)
    res = json.loads((out / "margin.json").read_text())
    assert res["interrupted"] is False and res["controllers"][0]["margin"] is not None, res
    assert "cells flown; margin.json" in said and "interrupted" not in said, said


def test_a_ctrl_c_between_rounds_stops_the_search_before_the_next(tmp_path: Path) -> None:
    """In-process (the Python API): a SIGINT that lands in the search's bookkeeping, between two rounds (here from its
    progress callback, after the second), is taken at the next round's start: MarginInterrupted, a
    KeyboardInterrupt carrying the two rounds' result; the caller's handler is back after it."""
    rounds: list[str] = []

    def progress(text: str) -> None:
        rounds.append(text)
        if len(rounds) == 2:
            signal.raise_signal(signal.SIGINT)

    before = signal.getsignal(signal.SIGINT)
    with pytest.raises(MarginInterrupted) as stop:
        margin(SHORT, "delay_ms", parse_until("rms=0.1"), progress=progress)
    assert isinstance(stop.value, KeyboardInterrupt) and signal.getsignal(signal.SIGINT) is before
    res = stop.value.result
    (law,) = res["controllers"]
    assert len(rounds) == 2 and res["interrupted"] and res["cells_flown"] == 2, (rounds, res)
    assert [c["delay_ms"] for c in law["cells"]] == [16.0, 32.0] and law["bracket"] == [32.0, None], law
    with sigint_deferred() as deferred:  # the same, as a block: a SIGINT outside raising() is only noted
        signal.raise_signal(signal.SIGINT)
        assert deferred.pending
        with pytest.raises(KeyboardInterrupt), deferred.raising():
            pass
