"""Covers bridge.sweep, bridge.cli and bridge.autopilot.compiling: what a new user meets first (issue 23).

- the README's Python example, verbatim, saved as a script (``python example.py``) and typed into
  ``python -i``: it flies, its sweep's cells are measured, nothing errors (both read a 1-second
  ``missions/sine.toml`` disarming 0.5 s after its landing, every other key as shipped: what the tests
  cover is how the code arrives, a script's ``__main__`` the sweep's workers import again and an
  interactive one they cannot, not the 30 seconds of the real-time flight, nor its twelve cells' 30
  seconds each, nor PX4's 2 s wait for the disarm);
- a script that starts a sweep's pool without the ``if __name__ == "__main__":`` guard fails at
  once, naming the guard (its workers used to re-run the script and come back as 'error' rows, exit 0);
- a sweep whose every cell failed never passes for a result: ``bsst sweep`` exits 1 with a line
  saying so, :func:`bridge.sweep.sweep` raises :class:`bridge.sweep.SweepFailed`;
- the first EKF and batch run on a cold numba cache say on stderr, once, that they compile; a warm
  run says nothing.

Every script here runs as a real ``python`` subprocess in a temporary working directory.
"""

from __future__ import annotations

import fcntl
import io
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
import tomllib
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from bridge.cli import main
from bridge.sweep import Grid, SweepFailed, sweep
from missions import Mission, Sine
from params import dump_toml
from tests.sitlkit import Proc

pytestmark = pytest.mark.process  # starts processes (scripts, pools, SITL sessions): not in make test-fast

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
SHORT = Mission(Sine(), duration_s=1.0, name="short")
BAD_LAW = '''
class BadLaw:
    """Fits the Law interface and is built; fails at its first update, so every cell of a sweep fails."""

    desired = (0.0, 0.0)

    def __init__(self, nominal, gains, rate_hz):
        pass

    def update(self, t, state, ref, omega_d):
        raise ValueError("this law fails in flight")

    def advance(self, saturated, hold=False):
        pass

    def reset(self):
        pass
'''


def readme_python() -> str:
    (block,) = re.findall(r"^```python\n(.*?)^```$", README.read_text(encoding="utf-8"), re.S | re.M)
    return block


def env() -> dict[str, str]:
    """This environment, with the repository importable from any working directory, and no ``BSST_KERNELS`` (the
    suite's choice, tests/conftest.py): a new user's ``auto``."""
    paths = [str(ROOT), *filter(None, os.environ.get("PYTHONPATH", "").split(os.pathsep))]
    mine = {k: v for k, v in os.environ.items() if k != "BSST_KERNELS"}
    return {**mine, "PYTHONPATH": os.pathsep.join(paths)}


def user_dir(tmp_path: Path) -> Path:
    """A working directory as a user's: ``missions/`` copied in, nothing else."""
    shutil.copytree(ROOT / "missions", tmp_path / "missions", ignore=shutil.ignore_patterns("*.py", "__pycache__"))
    return tmp_path


def short_sine(cwd: Path) -> None:
    """The user directory's ``missions/sine.toml`` flown for 1 s, not 30, its vehicle disarmed 0.5 s after its
    landing, not PX4's 2 s (the real-time flight's wall clock is the test's CPU); every other key as shipped."""
    sine = cwd / "missions" / "sine.toml"
    text = sine.read_text(encoding="utf-8")
    assert "\nduration_s = 30.0\n" in text, "missions/sine.toml no longer says duration_s = 30.0"
    assert "[params]" not in text, "missions/sine.toml has a [params] table now: set COM_DISARM_LAND in it"
    text = text.replace("\nduration_s = 30.0\n", "\nduration_s = 1.0\n") + "\n[params]\nCOM_DISARM_LAND = 0.5\n"
    sine.write_text(text, encoding="utf-8")


def run_python(args: list[str], cwd: Path, stdin: str | None = None, timeout: float = 600.0,
               extra_env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, *args], cwd=cwd, input=stdin, capture_output=True, text=True,
                          timeout=timeout, env={**env(), **(extra_env or {})},
                          stdin=None if stdin is not None else subprocess.DEVNULL)


@contextmanager
def instance(n: int, timeout_s: float = 600.0) -> Iterator[None]:
    """Hold SITL instance ``n`` (the README's example flies ``instance=1``) as bridge.session.instance_slot
    does, so that no other test's session shares its ports meanwhile."""
    fd = os.open(os.path.join(tempfile.gettempdir(), f"bsst-instance-{n}.lock"), os.O_RDWR | os.O_CREAT, 0o644)
    deadline = time.monotonic() + timeout_s
    try:
        while True:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except BlockingIOError:
                assert time.monotonic() < deadline, f"SITL instance {n} stayed taken for {timeout_s:g} s"
                time.sleep(0.05)
        yield
    finally:
        os.close(fd)


def assert_clean(proc: subprocess.CompletedProcess[str]) -> None:
    for bad in ("Traceback", "bootstrapping phase", "worker process died"):
        assert bad not in proc.stderr, f"{bad!r} in stderr:\n{proc.stderr[-3000:]}"


# -- the README's Python example, verbatim ---------------------------------------------------------------


def test_the_readmes_python_example_runs_verbatim_as_a_script(tmp_path: Path) -> None:
    cwd = user_dir(tmp_path)
    short_sine(cwd)  # the script is verbatim; the mission it reads flies 1 s, not 30 (its real-time flight)
    (cwd / "example.py").write_text(readme_python())
    with instance(1):
        proc = run_python(["example.py"], cwd)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert_clean(proc)
    assert (cwd / "runs" / "rt" / "summary.json").is_file()


def test_the_readmes_python_example_runs_as_typed_into_python_i(tmp_path: Path) -> None:
    cwd = user_dir(tmp_path)
    short_sine(cwd)
    # typed in: the example, Enter on an empty line to end its block, then a look at what it made
    typed = readme_python() + "\nprint('ERRORS', [r['error'] for r in rows if r['outcome'] == 'error'], len(rows))\n"
    with instance(1):
        proc = run_python(["-i"], cwd, stdin=typed)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert_clean(proc)
    assert "ERRORS [] 12" in proc.stdout, proc.stdout[-2000:] + proc.stderr[-2000:]
    assert (cwd / "runs" / "rt" / "summary.json").is_file()
    flown = tomllib.loads((cwd / "runs" / "rt" / "mission.toml").read_text(encoding="utf-8"))
    assert flown["duration_s"] == 1.0, flown


# -- a script without the main guard ---------------------------------------------------------------------


def test_a_script_without_the_main_guard_fails_at_once_naming_it(tmp_path: Path) -> None:
    cwd = user_dir(tmp_path)
    script = cwd / "unguarded.py"
    script.write_text("from bridge.sweep import Grid, sweep\n\n"
                      "print('SCRIPT RAN', flush=True)\n"
                      "rows = sweep('missions/sine.toml', Grid(delay_ms=(0, 10)), jobs=2, engine='process')\n"
                      "print('ROWS', [r['outcome'] for r in rows])\n")
    proc = run_python([script.name], cwd, timeout=120.0)
    assert proc.returncode != 0, f"an unguarded sweep passed: {proc.stdout[-2000:]}"
    last = proc.stderr.strip().splitlines()[-1]
    assert "ConfigError" in last and 'if __name__ == "__main__":' in last and "unguarded.py:4" in last, last
    assert proc.stdout.count("SCRIPT RAN") == 1, "a worker ran the script again"
    assert "ROWS" not in proc.stdout and "bootstrapping phase" not in proc.stderr


def test_the_same_script_under_the_guard_flies(tmp_path: Path) -> None:
    cwd = user_dir(tmp_path)
    (cwd / "short.toml").write_text(dump_toml(SHORT.to_dict()))
    (cwd / "guarded.py").write_text("from bridge.sweep import Grid, sweep\n\n\n"
                                    "def main():\n"
                                    "    rows = sweep('short.toml', Grid(delay_ms=(0, 10)), jobs=2, engine='process')\n"
                                    "    print('ROWS', [r['outcome'] for r in rows])\n\n\n"
                                    "if __name__ == '__main__':\n"
                                    "    main()\n")
    proc = run_python(["guarded.py"], cwd, timeout=300.0)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "ROWS ['completed', 'completed']" in proc.stdout


def test_a_sweep_started_in_a_folder_holding_missions_imports_bsst_s_own(tmp_path: Path) -> None:
    """A user's folder holds ``missions/`` (their mission files, no ``__init__.py``). multiprocessing's fork
    server is started by ``python -c``, so its path begins with its working directory: started there, it took that
    folder for the ``missions`` package (a namespace one, an editable install's finder coming after), its preload
    failed silently, and every worker died importing ``bridge.sweep`` ("cannot import name 'CONTROLLERS' from
    'missions'"), every later sweep of the process too (until the third wave's fortieth session). A fresh process,
    so the fork server starts here."""
    cwd = user_dir(tmp_path)
    (cwd / "short.toml").write_text(dump_toml(SHORT.to_dict()))
    script = ("from bridge.sweep import Grid, sweep\n"
              "rows = sweep('short.toml', Grid(delay_ms=(0, 10)), jobs=2, engine='process')\n"
              "print('ROWS', [r['outcome'] for r in rows])\n")
    # no PYTHONPATH: bsst as installed (make's venv: editable, by a finder after the path's own folders)
    proc = run_python(["-c", script], cwd, timeout=300.0, extra_env={"PYTHONPATH": ""})
    assert proc.returncode == 0 and "ROWS ['completed', 'completed']" in proc.stdout, proc.stderr[-3000:]


# -- a sweep whose every cell failed -----------------------------------------------------------------------


def test_a_sweep_whose_every_cell_failed_exits_1_saying_so(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                           monkeypatch: pytest.MonkeyPatch) -> None:
    """``bsst sweep`` (bsst's ``main`` in this process, in the user's directory: its exit status and stderr)."""
    cwd = user_dir(tmp_path)
    (cwd / "bad_law.py").write_text(BAD_LAW)
    (cwd / "short.toml").write_text(dump_toml(SHORT.to_dict()))
    monkeypatch.chdir(cwd)
    capsys.readouterr()
    rc = main(["sweep", "short.toml", "--controller", "bad_law.py:BadLaw", "--delay", "0,10", "--out", "sw",
               "--no-plots", "--jobs", "2"])
    err = capsys.readouterr().err
    assert rc == 1, err[-3000:]
    lines = [ln for ln in err.splitlines() if ln.startswith("bsst sweep: every cell failed")]
    head = ("bsst sweep: every cell failed (2 of 2): nothing was measured; the first error: its law failed "
            "at t=0.000 s: ")
    assert len(lines) == 1 and lines[0].startswith(head), err[-3000:]
    assert "update() raised ValueError: this law fails in flight" in lines[0], lines
    assert "Traceback" not in err


def test_a_sweep_whose_every_cell_failed_raises_from_python(tmp_path: Path) -> None:
    law = tmp_path / "bad_law.py"
    law.write_text(BAD_LAW)
    with pytest.raises(SweepFailed, match=r"every cell of the sweep failed \(2 of 2\); the first: its law failed "
                                          r".*raised ValueError: this law fails in flight") as caught:
        sweep(SHORT, Grid(controller=(f"{law}:BadLaw",), delay_ms=(0.0, 10.0)), jobs=2, engine="process")
    out = caught.value.outcome
    assert out.status == "all failed" and [r["outcome"] for r in out.rows] == ["law_failed", "law_failed"]


# -- the first compile says so -----------------------------------------------------------------------------

COMPILING = {"ekf": "bsst: compiling the EKF's kernels (first run after an install, ~7 s; cached on disk after) ...",
             "batch": "bsst: compiling the batch engine's kernels (first run after an install, ~24 s; cached on disk "
                      "after) ..."}


# the EKF's kernels only (the batch engine's call site is the same one line, bridge.sweep.executors.run_batch).
# The cold run is stopped once it has said so: the compile itself (13 s to over a minute of the suite's time) is
# numba's; the warm run reads the cache the suite's own start made (tests/conftest.py).
@pytest.mark.parametrize("kernels", ["ekf"])
def test_a_cold_numba_cache_is_announced_once_and_a_warm_one_not(tmp_path: Path, kernels: str) -> None:
    """numba's cache pointed at an empty directory (NUMBA_CACHE_DIR) is a first run after an install: the line
    comes first, before any compiling; with the warm cache no line comes."""
    (tmp_path / "short.toml").write_text(dump_toml(SHORT.to_dict()))
    argv = [sys.executable, "-m", "bridge", "sim", "short.toml", "--sensors", "mocap", "--estimator", "ekf",
            "--no-plots"]
    cold = Proc(["env", "-u", "BSST_KERNELS", f"NUMBA_CACHE_DIR={tmp_path / 'numba-cache'}", *argv, "--out", "cold"],
                cwd=tmp_path)  # a new user's ``auto`` (env()): the controller's and the plant's kernels stay plain
    try:
        said = cold.wait_line(lambda ln: ln.startswith("bsst: "), timeout=120.0)
    finally:
        cold.stop(timeout=0.0)
    assert said == COMPILING[kernels]
    warm = run_python([*argv[1:], "--out", "warm"], tmp_path)
    assert warm.returncode == 0, warm.stderr[-3000:]
    assert [ln for ln in warm.stderr.splitlines() if ln.startswith("bsst: compiling")] == []


def test_the_compile_notice_looks_once_per_process() -> None:
    """Warm or cold, a second call in one process prints nothing and reads no index again."""
    from bridge.autopilot import compiling, ekfkernels  # noqa: F401 (imported: its kernels are what is looked at)

    compiling._checked.discard("bridge.autopilot.ekfkernels")
    first, second = io.StringIO(), io.StringIO()
    compiling.announce_compiling("bridge.autopilot.ekfkernels", first)
    assert not compiling.announce_compiling("bridge.autopilot.ekfkernels", second)
    assert second.getvalue() == ""
    assert first.getvalue() == "", "the suite compiled the EKF's kernels first (tests/conftest.py): the cache is warm"
