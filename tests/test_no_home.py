"""Covers bridge.session, bridge.core.kernelpreload, bridge.nodes.forkserver and bridge.record.mplsetup: without a
writable home and numba cache (a container, a CI runner) ``bsst`` compiles each kernel once a session, quietly; and
bridge.autopilot.kernelcache: the kernels it compiled fly the cached ones' bits.

Each ``bsst`` here is a real exec'd process (not forked by the suite's fork server, whose kernels come from a cache),
starting its own fork server as a user's does: ``python -m bridge``, or for the two compiled sessions one ``python``
that runs bsst's ``main`` for each in turn. ``HOME`` is a path no process may create (under ``/proc/self``), a
regular file, or a read-only folder (not for root, who may write in it); numba's cache is taken away as
tests/test_kernelcache_off.py does (its locators narrowed to ``NUMBA_CACHE_DIR``, under ``/proc/self``).

Before the fix, ``BSST_KERNELS=compiled bsst sitl`` compiled the law's and the plant's kernels in the launcher and
again in its fork server (two compiling lines), and the fork server the EKF's too whether a vehicle flew one or not;
with ``--estimator ekf`` the launcher compiled the EKF's as well (four lines); and a run that drew its figures printed
matplotlib's own two lines ("mkdir -p failed for path ...", "Matplotlib created a temporary cache directory ...").
A compile in the fork server before it answers can outlast its client's 30 s wait on a loaded machine: the client
waits on while the server works (the last tests).
"""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import pytest

from bridge.autopilot import kernelcache
from bridge.autopilot.compiling import KERNELS, compiling_line
from bridge.autopilot.kernelcache import CACHE_OFF_NOTE
from bridge.cli import main
from bridge.nodes import forkserver
from bridge.record.mplsetup import PREFIX
from bridge.session import instance_slot
from tests.sitlkit import run_bsst

pytestmark = pytest.mark.process  # real bsst processes, a session's children, UDP

ROOT = Path(__file__).resolve().parent.parent
NO_HOME = "/proc/self/no-home"  # no process, root included, may create it
NO_CACHE = {"NUMBA_CACHE_LOCATOR_CLASSES": "UserProvidedCacheLocator", "NUMBA_CACHE_DIR": "/proc/self/no-cache"}
SHORT = 'name = "short"\nduration_s = 2.0\n[trajectory]\nkind = "sine"\n'
TIMEOUT_S = 600.0  # s: the kernels' compile is ~4-11 s of CPU; a loaded machine stretches it
SCALAR, EKF = "bridge.core.scalarkernels", "bridge.autopilot.ekfkernels"


def _env(home: str, **extra: str) -> dict[str, str]:
    """This environment without what would give matplotlib or numba a folder, and without the suite's fork server
    switch (the launcher starts one of its own, as a user's does)."""
    mine = {k: v for k, v in os.environ.items()
            if not k.startswith(("NUMBA_CACHE", "XDG_", "MPLCONFIGDIR", "BSST_KERNELS", "BSST_FORK_SERVER"))}
    paths = [str(ROOT), *filter(None, os.environ.get("PYTHONPATH", "").split(os.pathsep))]
    return {**mine, "PYTHONPATH": os.pathsep.join(paths), "HOME": home, **extra}


def _bsst(tmp_path: Path, env: dict[str, str], *argv: str, python: bool = False) -> subprocess.CompletedProcess:
    """``python -m bridge ARGV`` (with ``python``: ``python ARGV``) in ``tmp_path``, beside ``short.toml``."""
    (tmp_path / "short.toml").write_text(SHORT)
    return subprocess.run([sys.executable, *(() if python else ("-m", "bridge")), *argv], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=TIMEOUT_S, stdin=subprocess.DEVNULL)


# the two compiled sessions, flown one after the other by one exec'd process (``bsst``'s own ``main``, as ``bsst sitl``
# runs it) whose fork server serves both, as a script's or a notebook's does: the first flies no EKF, the second one
# (each a whole bsst process of its own compiled the law's and the plant's kernels again: 28.7 against 18.9 CPU-s)
SESSIONS = """
import json, sys
from bridge.cli import main
for argv in json.loads(sys.argv[1]):
    print(sys.argv[2], main(argv), file=sys.stderr, flush=True)
"""
END = "-- session ended, exit"  # what the process says on stderr after each session, before its exit status


@pytest.fixture(scope="module")
def compiled_sessions(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[Counter[str]]]:
    """``BSST_KERNELS=compiled bsst sitl short.toml`` (figures drawn), then ``... --estimator ekf --no-plots``, in one
    process without a home or numba's cache: their folder (runs ``one`` and ``two``) and what each said on stderr
    (but its ``bsst sitl:`` line, where a ground station connects)."""
    cwd = tmp_path_factory.mktemp("compiled")
    with instance_slot() as n:
        argv = ["sitl", "short.toml", "--instance", str(n), "--out"]
        runs = [[*argv, "one"], [*argv, "two", "--estimator", "ekf", "--no-plots"]]
        r = _bsst(cwd, _env(NO_HOME, BSST_KERNELS="compiled", **NO_CACHE), "-c", SESSIONS,
                  json.dumps(runs), END, python=True)
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr[-3000:]
    said: list[Counter[str]] = [Counter()]
    for ln in r.stderr.splitlines():
        if ln.startswith(END):
            assert ln == f"{END} 0", r.stderr[-3000:]
            said.append(Counter())
        elif not ln.startswith("bsst sitl: "):
            said[-1][ln] += 1
    assert len(said) == 3 and not said[2], r.stderr[-3000:]
    return cwd, said[:2]


def _children_compiled_nothing(run: Path) -> None:
    for log in ("vehicle.log", "controller.log"):
        text = (run / log).read_text()
        assert not any(compiling_line(p, True) in text for p in KERNELS), (log, text)


def test_a_compiled_session_compiles_the_law_and_plant_once_and_draws_quietly(
        compiled_sessions: tuple[Path, list[Counter[str]]], capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The fork server compiles them (its children inherit them); the launcher, which does not fly, does not; the EKF
    is compiled by no one (the sine flies the true state); matplotlib finds a folder without a word. The kernels
    compiled without a cache fly what the cached ones fly, bit for bit: the lockstep session's trace.csv is the same
    ``bsst sim`` flown in this process's (every kernel of which has its cache: none said the note) to the byte.
    (numba's "no locator available" traceback at the kernels' import before bridge.autopilot.kernelcache: the
    first way of tests/test_kernelcache_off.py.)"""
    cwd, said = compiled_sessions
    assert said[0] == Counter([CACHE_OFF_NOTE, compiling_line(SCALAR, True)]), said
    _children_compiled_nothing(cwd / "one")
    assert (cwd / "one" / "plots" / "positions.png").stat().st_size > 0
    monkeypatch.setenv("BSST_KERNELS", "compiled")
    capsys.readouterr()
    assert main(["sim", str(cwd / "short.toml"), "--no-plots", "--out", str(cwd / "cached")]) == 0
    here = capsys.readouterr().err
    assert "bsst: note:" not in here and not kernelcache.UNCACHED, (here[-3000:], kernelcache.UNCACHED)
    assert (cwd / "one" / "trace.csv").read_bytes() == (cwd / "cached" / "trace.csv").read_bytes()


def test_a_compiled_session_with_an_ekf_compiles_it_once(compiled_sessions: tuple[Path, list[Counter[str]]]) -> None:
    """The EKF's kernels are compiled in the fork server before it forks the vehicle that flies them, once: neither
    the launcher nor a child compiles them, nor the law's and the plant's again."""
    cwd, said = compiled_sessions
    assert said[1] == Counter([compiling_line(EKF, True)]), said
    _children_compiled_nothing(cwd / "two")


def _homes(tmp_path: Path) -> dict[str, str]:
    (tmp_path / "home-file").write_text("")
    (tmp_path / "read-only").mkdir(mode=0o555)
    (tmp_path / "writable").mkdir()
    return {"file": str(tmp_path / "home-file"), "read-only": str(tmp_path / "read-only"),
            "writable": str(tmp_path / "writable")}


# a home that cannot be made ("none") is one more folder matplotlib's cannot be made in (bridge.record.mplsetup's one
# branch, as for "file"): flown by the compiled sessions (a bsst sitl) and the forked bsst sim below
@pytest.mark.parametrize("home", ["file", "read-only", "writable"])
def test_figures_without_a_writable_home_are_drawn_quietly(tmp_path: Path, home: str) -> None:
    """``bsst sim`` draws its figures and says nothing on stderr; the temporary folder it gave matplotlib is gone once
    it has ended. A writable home is matplotlib's own, as before."""
    if home == "read-only" and os.geteuid() == 0:
        pytest.skip("root writes in a read-only folder")
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    r = _bsst(tmp_path, _env(_homes(tmp_path)[home], TMPDIR=str(tmp)), "sim", "short.toml", "--out", "run")
    assert r.returncode == 0 and r.stderr == "", r.stderr[-3000:]
    assert (tmp_path / "run" / "plots" / "positions.png").stat().st_size > 0
    assert not [p.name for p in tmp.iterdir() if p.name.startswith((PREFIX, "matplotlib-"))]
    assert (tmp_path / "writable" / ".config" / "matplotlib").is_dir() == (home == "writable")


def test_a_forked_bsst_sim_without_a_home_removes_matplotlibs_folder_too(tmp_path: Path) -> None:
    """Forked warm (the suite's fork server, as a ``bsst sitl``'s children and a script's runs are), ``bsst sim`` runs
    its own exit handlers before the child's ``os._exit`` (bridge.nodes.forkserver): the temporary folder it gave
    matplotlib is removed as in an exec'd one (it was left behind in TMPDIR each time)."""
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    (tmp_path / "short.toml").write_text(SHORT)
    r = run_bsst("sim", "short.toml", "--out", "run", cwd=tmp_path, env=_env(NO_HOME, TMPDIR=str(tmp)),
                 timeout=TIMEOUT_S)
    assert r.returncode == 0 and r.stderr == "", r.stderr[-3000:]
    assert (tmp_path / "run" / "plots" / "positions.png").stat().st_size > 0
    assert not [p.name for p in tmp.iterdir() if p.name.startswith((PREFIX, "matplotlib-"))]


# the busy server works as a compile starved by a loaded machine does: a tenth of a core (10 ms of CPU in each 100 ms)
# for 3 s of the wall clock, past the client's 2 s, then answers (it spun 1 s of CPU, answering within the 2 s on
# an idle machine, so that only a loaded one waited past them)
SERVER = """
import socket, sys, time
s = socket.socket(fileno=int(sys.argv[1]))
if sys.argv[2] == "busy":
    end = time.monotonic() + 3.0
    while time.monotonic() < end:
        spun = time.process_time() + 0.01
        while time.process_time() < spun:
            pass
        time.sleep(0.09)
    s.send(b'{"id": 1, "pid": 0}')
time.sleep(600)
"""


@pytest.mark.parametrize("server", ["busy", "idle"])
def test_a_client_waits_on_a_server_that_works(monkeypatch: pytest.MonkeyPatch, server: str) -> None:
    """A server that spends CPU (a tenth of a core for 3 s, then answers) is waited for past the client's timeout;
    an idle one that never answers is given up at it."""
    monkeypatch.setattr(forkserver, "BUSY_CPU_S", 0.05)  # CPU s in each 2 s window: met by a process at 1/40 of a core
    ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
    proc = subprocess.Popen([sys.executable, "-c", SERVER, str(theirs.fileno()), server], pass_fds=(theirs.fileno(),))
    theirs.close()
    try:
        client = forkserver.Server(ours, proc)
        if server == "busy":
            asked = time.monotonic()
            assert client._until(lambda: client.answers.pop(1, None), 2.0)["pid"] == 0
            assert time.monotonic() - asked > 2.0  # the answer came after the timeout: it was waited for
        else:
            with pytest.raises(forkserver.ServerGone):
                client._until(lambda: client.answers.pop(1, None), 2.0)
    finally:
        proc.kill()
        proc.wait()
        ours.close()
