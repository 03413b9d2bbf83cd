"""Covers controller.law, bridge.loop and bridge.nodes.offboard: a user's law that fails (CheckedLaw, LawFailed).

Issue 22, defect 6: every way a plug-in law can fail ends honestly, through the real ``bsst sim`` (and
``bsst sitl``) as a subprocess, each bad law a small file:

- it cannot be loaded (a raise, ``SystemExit(0)`` or ``os._exit(0)`` at import or in ``__init__``): one line,
  exit 2, nothing flown (no run directory);
- it fails in flight (``update`` raises, exits, ``os._exit`` in ``update`` or ``advance``, returns the wrong shape,
  None, a string, +-inf, or four values that are not numbers though ``float()`` takes them: bools, numpy bools,
  complex, numeric strings): one line, exit 1, and ``summary.json`` (outcome ``law_failed``, ``ended_by`` the
  controller with the exception's type and message, the step and t), the trace so far and ``events.log`` written;
- it ends ``bsst sim``'s process past any guard in it (a signal, ``posix._exit``): exit 1 and one line saying so
  (bridge.nodes.watched).
"""

from __future__ import annotations

import json
import subprocess
import textwrap
from pathlib import Path

import pytest

from bridge.session import instance_slot
from tests.sitlkit import ENV, ROOT, run_bsst

pytestmark = pytest.mark.process  # runs bsst as real processes: not in make test-fast

GOOD = """
import os
from os import _exit  # bound while bsst loads the file: refused as os._exit is


class Law:
    def __init__(self, nominal, gains, rate_hz):
        self.m, self.g = nominal.mass, nominal.gravity
        self.desired = (0.0, 0.0)
        self.t = 0.0

    def update(self, t, state, ref, omega_d):
        self.t = t
        {update}
        return (self.m * self.g, 0.0, 0.0, 0.0)

    def advance(self, saturated, hold=False):
        {advance}

    def reset(self):
        pass
"""
FAIL_AT = "if t >= 0.5:"  # s: the law fails from this mission time on


def _law(tmp_path: Path, head: str = "", init: str = "", update: str = "pass", advance: str = "pass") -> str:
    """A law file in ``tmp_path`` (``head`` at import, ``init`` in ``__init__``, ``update``'s and ``advance``'s
    first line)."""
    body = GOOD.replace("{update}", update).replace("{advance}", advance)
    if init:
        body = body.replace("self.desired = (0.0, 0.0)", f"self.desired = (0.0, 0.0)\n        {init}")
    path = tmp_path / "bad_law.py"
    path.write_text(head + "\n" + textwrap.dedent(body))
    return f"{path}:Law"


def _sim(tmp_path: Path, spec: str, *args: str) -> subprocess.CompletedProcess:
    return run_bsst("sim", "missions/sine.toml", "--controller", spec, "--out", str(tmp_path / "run"), "--no-plots",
                    *args, cwd=ROOT, env=ENV, timeout=120)


LOAD_FAILS = {  # case: (the line at import or in __init__, what the one line says)
    "raises": ("raise RuntimeError('no gains for me')", "raised RuntimeError: no gains for me"),
    "exits0": ("raise SystemExit(0)", "raised SystemExit"),
    "os_exit0": ("__import__('os')._exit(0)", "called os._exit(0)"),
    # a message of several lines is one line all the same (it gave two lines on stderr)
    "raises_lines": ("raise ValueError('bad gains:\\nline two')", "raised ValueError: bad gains: line two"),
}


@pytest.mark.parametrize("where", ["import", "init"])
@pytest.mark.parametrize("how", LOAD_FAILS)
def test_a_law_that_cannot_be_loaded_is_bad_input_nothing_flown(tmp_path, where, how):
    line, says = LOAD_FAILS[how]
    spec = _law(tmp_path, head=line if where == "import" else "", init=line if where == "init" else "")
    r = _sim(tmp_path, spec)
    assert r.returncode == 2, (r.stdout, r.stderr)
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "bad_law.py" in lines[0] and "Traceback" not in r.stderr, r.stderr
    assert says in lines[0], lines[0]
    assert not (tmp_path / "run").exists()


IN_FLIGHT = {  # case: (the method that fails, its first line, what the line says)
    "raises": ("update", f"{FAIL_AT} raise ZeroDivisionError('my bad')", "ZeroDivisionError: my bad"),
    "exits0": ("update", f"{FAIL_AT} raise SystemExit(0)", "update() raised SystemExit"),
    "shape": ("update", f"{FAIL_AT} return (1.0, 2.0)", "got (1.0, 2.0)"),
    "none": ("update", f"{FAIL_AT} return None", "got None"),
    "string": ("update", f"{FAIL_AT} return 'thrust'", "got 'thrust'"),
    "inf": ("update", f"{FAIL_AT} return (float('inf'), 0.0, 0.0, 0.0)", "got (inf, 0.0, 0.0, 0.0)"),
    "minus_inf": ("update", f"{FAIL_AT} return (1.0, float('-inf'), 0.0, 0.0)", "got (1.0, -inf, 0.0, 0.0)"),
    # four values that float() takes but that are not numbers: refused, never flown as 1.0 and 0.0
    "bools": ("update", f"{FAIL_AT} return (True, False, False, False)", "(u1 is a bool, not a number)"),
    "numpy_bools": ("update", f"{FAIL_AT} return __import__('numpy').array([1, 0, 0, 0], dtype=bool)",
                    "(u1 is a bool, not a number)"),  # (numpy's bool_ is named bool too)
    "complex": ("update", f"{FAIL_AT} return (self.m * self.g, 0j, 0.0, 0.0)", "(u2 is a complex, not a number)"),
    "numeric_strings": ("update", f"{FAIL_AT} return ('9.81', '0', '0', '0')", "(u1 is a str, not a number)"),
    # a message or a repr of several lines stays on the record's one line (events.log had the matrix on 4 lines)
    "raises_lines": ("update", f"{FAIL_AT} raise ValueError(f'matrix singular:\\n{{__import__(\"numpy\").eye(3)}}')",
                     "raised ValueError: matrix singular: [[1. 0. 0.] [0. 1. 0.] [0. 0. 1.]] (in bad_law.py:"),
    "column": ("update", f"{FAIL_AT} return __import__('numpy').ones((4, 1))",
               "got array([[1.], [1.], [1.], [1.]]) (u1 is a ndarray, not a number)"),
    # an unordered container is refused as any wrong return (a dict had its keys flown, a set flew in any order)
    "dict": ("update", f"{FAIL_AT} return {{0: self.m * self.g, 1: 0.0, 2: 0.0, 3: 0.0}}",
             "(a dict: a mapping, not a sequence of four numbers)"),
    "set": ("update", f"{FAIL_AT} return {{self.m * self.g, 0.0, 1.0, 2.0}}",
            "(a set: unordered, not a sequence of four numbers)"),
    # a law that ends the process: os._exit raises in its calls, so the flight ends recorded, not at exit 0
    "os_exit0": ("advance", "if self.t >= 0.5: os._exit(0)", "advance() called os._exit(0)"),
    "os_exit3_update": ("update", f"{FAIL_AT} os._exit(3)", "update() called os._exit(3)"),
    "bound_exit": ("advance", "if self.t >= 0.5: _exit(0)", "advance() called os._exit(0)"),
}


@pytest.mark.parametrize("case", IN_FLIGHT)
def test_a_law_that_fails_in_flight_ends_law_failed_with_its_record(tmp_path, case):
    method, line, says = IN_FLIGHT[case]
    r = _sim(tmp_path, _law(tmp_path, **{method: line}))
    assert r.returncode == 1, (r.stdout, r.stderr)
    assert "Traceback" not in r.stderr + r.stdout, r.stderr
    assert "outcome: law_failed" in r.stdout
    run = tmp_path / "run"
    s = json.loads((run / "summary.json").read_text())
    assert s["outcome"] == "law_failed"
    end = s["ended_by"]
    assert end["who"] == "controller" and says in end["how"] and "at step 125 (t=0.500 s)" in end["how"], end
    assert "\n" not in end["how"], end
    rows = (run / "trace.csv").read_text().splitlines()
    assert len(rows) == 1 + 125  # the header, and every step flown before the failing one
    events = (run / "events.log").read_text().splitlines()
    assert any(" law_failed: " in e for e in events) and all(e.startswith("t=") for e in events), events
    assert any(ln.startswith("ended by controller") and says in ln for ln in r.stdout.splitlines()), r.stdout
    if case.startswith("raises"):  # where in the law's file: the line that raised (it was not said)
        text = (tmp_path / "bad_law.py").read_text().splitlines()
        line = 1 + next(i for i, ln in enumerate(text) if " raise " in ln)
        assert f" (in bad_law.py:{line}) at step 125" in end["how"], end


PROCESS_ENDS = {  # case: (advance's line: a law that ends bsst sim's process past any guard in it, how it is said)
    "sigkill": ("if self.t >= 0.5: os.kill(os.getpid(), 9)", "killed by SIGKILL"),
    "posix_exit0": ("if self.t >= 0.5: __import__('posix')._exit(0)", "exited with status 0"),  # a C exit(0)
}


@pytest.mark.parametrize("case", PROCESS_ENDS)
def test_a_law_that_ends_bsst_sims_process_ends_the_command_exit_1_said(tmp_path, case):
    """bsst sim flies a law of the user's own in a watched child process: its death is the command's exit 1 and
    one line naming how it ended and the law, never exit 0 and silence; what was written before stays."""
    line, how = PROCESS_ENDS[case]
    r = _sim(tmp_path, _law(tmp_path, advance=line))
    assert r.returncode == 1, (r.stdout, r.stderr)
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    assert f"bsst sim: the flight's process ended before the flight did ({how})" in lines[0], lines[0]
    assert "bad_law.py:Law" in lines[0] and "no summary.json" in lines[0], lines[0]
    run = tmp_path / "run"
    assert (run / "trace.csv").is_file() and (run / "mission.toml").is_file()
    assert not (run / "summary.json").exists()


def test_the_sitl_controller_ends_law_failed_when_its_law_exits(tmp_path):
    """``SystemExit(0)`` in ``update`` inside ``bsst sitl``'s controller: not a controller that completed (exit
    0, no report), but the outcome ``law_failed`` named, exit 1, the summary written."""
    spec = _law(tmp_path, update=f"{FAIL_AT} raise SystemExit(0)")
    mission = tmp_path / "short.toml"
    mission.write_text((ROOT / "missions" / "sine.toml").read_text().replace("duration_s = 30.0", "duration_s = 3.0"))
    with instance_slot() as n:
        r = run_bsst("sitl", str(mission), "--controller", spec, "--instance", str(n), "--out", str(tmp_path / "run"),
                     "--no-plots", cwd=ROOT, env=ENV, timeout=120)
    assert r.returncode == 1, (r.stdout, r.stderr)
    s = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert s["outcome"] == "law_failed", s["ended_by"]
    assert s["ended_by"]["who"] == "controller" and "update() raised SystemExit" in s["ended_by"]["how"]


NAMED_WHERE = {  # case: (argv, with {m} the mission; the line's start: the flag when the flag gave the law)
    "sim_flag_no_file": (["sim", "{m}", "--controller", "./nofile.py:Law"],
                         "bsst: --controller ./nofile.py:Law: no file {d}/nofile.py"),
    "sim_flag_directory": (["sim", "{m}", "--controller", "./dirlaw.py:Law"],
                           "bsst: --controller ./dirlaw.py:Law: {d}/dirlaw.py is a directory, not a Python file"),
    "sim_key_directory": (["sim", "{d}/keyed.toml"],
                          "bsst: {d}/keyed.toml: controller '{d}/dirlaw.py:Law': {d}/dirlaw.py is a directory"),
    "sitl_flag": (["sitl", "{m}", "--controller", "nofile.py:Law", "--gcs", "none"],
                  "bsst: --controller nofile.py:Law: no file {d}/nofile.py"),
    "controller_flag": (["controller", "{m}", "--controller", "nofile.py:Law"],
                        "bsst: --controller nofile.py:Law: no file {d}/nofile.py"),
    "margin_flag": (["margin", "{m}", "--over", "delay_ms", "--until", "rms=1", "--controller", "bsst,nofile.py:Law"],
                    "bsst: --controller nofile.py:Law: no file {d}/nofile.py"),
}


@pytest.mark.parametrize("case", NAMED_WHERE)
def test_a_law_that_cannot_be_flown_is_named_where_it_was_given(tmp_path, case):
    """A law from ``--controller`` is the flag's, not the mission file's ``controller`` key; one from the key is the
    file's; a directory given as a law file is said to be one (not "no file")."""
    (tmp_path / "dirlaw.py").mkdir()
    mission = (ROOT / "missions" / "sine.toml").read_text()
    (tmp_path / "keyed.toml").write_text(mission.replace('controller = "bsst"', 'controller = "dirlaw.py:Law"'))
    argv, start = NAMED_WHERE[case]
    r = run_bsst(*(a.format(m=ROOT / "missions" / "sine.toml", d=tmp_path) for a in argv), cwd=tmp_path, env=ENV,
                 timeout=60)
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    assert lines[0].startswith(start.format(d=tmp_path)), lines[0]
