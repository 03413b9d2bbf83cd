"""Covers bridge.nodes.forkserver, bridge.cli.forkserver and bridge.core.kernelpreload: a child forked warm.

It behaves as an exec'd one, and starts with the compiled kernels when its server loaded them.

Real processes throughout: the fork server this test process starts, ``bsst`` children forked by it (a relay
runs until stopped, a ``bsst sim`` of bad input ends at once), and a helper process killed with SIGKILL.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import tempfile
import textwrap
from collections.abc import Iterator
from pathlib import Path

import pytest

from bridge.nodes import forkserver
from bridge.nodes.forkserver import ENV, ForkedChild, forked_cpu_s, start_child
from bridge.nodes.report import Ready, parse_line
from bridge.session.children import instance_slot
from tests.sitlkit import Bsst, run_bsst
from tests.waiting import wait_for

pytestmark = pytest.mark.process  # starts processes or opens sockets: not in make test-fast


@pytest.fixture(autouse=True)
def _the_server_on(monkeypatch):
    """The fork server as a user has it by default (a suite run with BSST_FORK_SERVER=0 tests it all the same)."""
    monkeypatch.delenv(ENV, raising=False)


@pytest.fixture
def own_server(monkeypatch: pytest.MonkeyPatch) -> Iterator[forkserver.Server | None]:
    """This test's children start a fork server of their own, in its environment: the worker's is set aside (kept
    running, with its imports and kernels loaded) and put back at the end, the test's killed. (Tests killed the
    worker's: its next server started cold and flew its next session's pair plain, ~0.3-0.9 CPU-s a kill.)"""
    old = forkserver._server
    monkeypatch.setattr(forkserver, "_server", None)  # the next child starts a server (_the_server)
    yield old
    mine = forkserver._server
    if mine is not None and mine is not old and mine.proc is not None:
        mine.proc.kill()
        mine.proc.wait(30)


def _alive(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie does not)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rpartition(")")[2].split()[0] not in ("Z", "X")
    except (FileNotFoundError, ProcessLookupError):
        return False


class Started:
    """A ``bsst`` child started by :func:`start_child`, its stdout a pipe, its stderr a file."""

    def __init__(self, tmp_path: Path, *argv: str) -> None:
        self.read, write = os.pipe()
        self.err = tmp_path / f"{argv[0]}-{os.getpid()}-{id(self)}.err"
        with open(self.err, "wb") as err:
            self.child = start_child(list(argv), write, err.fileno())
        os.close(write)
        os.set_blocking(self.read, False)
        self.out = b""

    def stdout(self) -> bytes:
        try:
            while chunk := os.read(self.read, 65536):
                self.out += chunk
        except BlockingIOError:
            pass
        return self.out

    def ready(self) -> bool:
        return any(isinstance(parse_line(ln), Ready) for ln in self.stdout().decode().splitlines())

    def close(self) -> None:
        if self.child.poll() is None:
            self.child.kill()
            self.child.wait(30)
        os.close(self.read)


def _relay(tmp_path: Path) -> Started:
    r = Started(tmp_path, "relay", "--listen", "127.0.0.1:0", "--to", "127.0.0.1:9")
    wait_for(lambda: r.ready() or r.child.poll() is not None, 30, "the relay ready")
    assert r.child.poll() is None, r.err.read_text()
    return r


def test_a_forked_child_runs_its_command_with_its_own_files_environment_and_directory(tmp_path, monkeypatch):
    forkserver.warm()  # the server starts first: what changes after must still reach the child
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("BSST_KERNELS", "bogus")
    (tmp_path / "m.toml").write_text('name = "m"\nduration_s = 1.0\n[trajectory]\nkind = "sine"\n')
    s = Started(tmp_path, "sim", "m.toml", "--no-plots")
    assert isinstance(s.child, ForkedChild)
    assert s.child.wait(60) == 2  # bad input, as exec'd
    # the relative path read in this directory, the variable from this environment (set after the server began)
    assert s.err.read_text() == "bsst: m.toml: BSST_KERNELS='bogus' (environment): must be one of plain, compiled, " \
                                "auto\n"
    assert s.stdout() == b""
    s.close()


@pytest.mark.parametrize("length", ["short", "long"])
def test_a_forked_sweep_uses_its_own_tmpdir_and_leaves_nothing_in_it(tmp_path, length):
    """A sweep's pool starts multiprocessing's fork server, whose socket lives in a ``pymp-*`` folder of the
    temporary directory: a forked ``bsst sweep`` left one behind each time (its ``os._exit`` skipped
    multiprocessing's exit finalizers), made in the server's temporary directory, not its own TMPDIR; and a TMPDIR
    too long for the socket's path ended it in a traceback (it now puts that one folder in /tmp)."""
    forkserver.warm()  # the server has chosen its own temporary directory before the child's is given
    with tempfile.TemporaryDirectory(prefix="bsst-t-", dir="/tmp") as short:
        tmp = Path(short) if length == "short" else tmp_path / ("t" * 90)
        tmp.mkdir(exist_ok=True)
        (tmp_path / "m.toml").write_text('name = "m"\nduration_s = 0.2\n[trajectory]\nkind = "sine"\n')
        # (no heat map: matplotlib keeps to the home's cache folder here, bridge.record.mplsetup, not TMPDIR)
        p = Bsst("sweep", "m.toml", "--delay", "0,5", "--jobs", "2", "--engine", "process", "--out", "out",
                 "--no-plots", cwd=tmp_path, env={**os.environ, "TMPDIR": str(tmp)})
        out, err = p.communicate(120)
        assert p.returncode == 0, err
        assert (tmp_path / "out" / "cells.csv").is_file()
        assert [f.name for f in tmp.iterdir()] == [], err


def test_a_forked_child_shows_its_command_line_runs_in_its_own_session_and_obeys_signals(tmp_path):
    r = _relay(tmp_path)
    pid = r.child.pid
    with open(f"/proc/{pid}/cmdline", "rb") as f:
        shown = f.read().rstrip(b"\0").decode()
    assert shown.startswith(f"{sys.executable} -m bridge relay --listen 127.0.0.1:0 --to 127.0.0.1:9"), shown
    assert os.getsid(pid) == pid and os.getsid(pid) != os.getsid(0)  # its own session, as start_new_session
    assert r.child.poll() is None
    r.child.send_signal(signal.SIGTERM)  # a relay stops on SIGTERM and exits 0
    assert r.child.wait(30) == 0 and r.child.returncode == 0 and not _alive(pid)
    r.close()
    k = _relay(tmp_path)
    k.child.kill()
    assert k.child.wait(30) == -signal.SIGKILL
    k.close()
    running = _relay(tmp_path)
    with pytest.raises(subprocess.TimeoutExpired):  # a deadline on a running one's exit, as Popen's
        running.child.wait(0.05)
    running.close()


def test_a_child_ends_with_its_server_and_the_next_child_gets_a_new_server(tmp_path, own_server):
    r = _relay(tmp_path)
    server = forkserver._the_server()
    os.kill(server.proc.pid, signal.SIGKILL)
    assert r.child.wait(30) is not None  # SIGTERM from the server's death (PR_SET_PDEATHSIG): it stopped
    assert not _alive(r.child.pid)
    r.close()
    again = _relay(tmp_path)
    assert forkserver._the_server() is not server and again.child.poll() is None
    again.close()


def test_a_child_ended_and_reaped_before_its_answer_is_read_is_still_the_one_waited_for(tmp_path):
    """The answer carries the pidfd the server opened as it forked: a child that ends (and is reaped, its pid free
    for another process) before the owner reads the answer is still the one waited for, never a stranger."""
    server = forkserver._the_server()
    out = tmp_path / "version.out"
    with open(out, "wb") as f, open(os.devnull, "rb") as null, server.lock:  # nobody else reads the answers
        request = {"id": 0, "argv": ["--version"], "cwd": os.getcwd(), "env": dict(os.environ)}
        socket.send_fds(server.sock, [json.dumps(request).encode()], [null.fileno(), f.fileno(), f.fileno()])
        answer = server._until(lambda: server.answers.pop(0, None), 30)
        pid = answer["pid"]
        server._until(lambda: pid in server.exits or None, 30)
    assert not _alive(pid)  # ended and reaped before we looked at the answer
    child = ForkedChild(server, pid, answer["fds"][0])
    with pytest.raises(ProcessLookupError):  # the pidfd is that process's: gone, whatever now holds its pid
        signal.pidfd_send_signal(answer["fds"][0], 0)
    assert child.wait(5) == 0 and out.read_text().count("bsst") == 1  # run once, not again by exec


HOLDER = """
import os, sys, time
from bridge.nodes.forkserver import _the_server, start_child
r, w = os.pipe()
child = start_child(["relay", "--listen", "127.0.0.1:0", "--to", "127.0.0.1:9"], w, 2)
print(_the_server().proc.pid, child.pid, flush=True)
time.sleep(600)
"""


def test_the_owners_death_ends_its_server_and_every_child(tmp_path):
    p = subprocess.Popen([sys.executable, "-c", textwrap.dedent(HOLDER)], stdout=subprocess.PIPE, text=True,
                         cwd=Path(__file__).resolve().parents[1])
    try:
        server, child = (int(x) for x in p.stdout.readline().split())  # type: ignore[union-attr]
        assert _alive(server) and _alive(child)
        p.kill()
        p.wait(30)
        wait_for(lambda: not _alive(server) and not _alive(child), 30, "the server and its child gone")
    finally:
        p.kill()
        p.wait(30)


def test_without_the_server_a_child_is_execd_and_the_cpu_of_forked_ones_is_counted(tmp_path, monkeypatch):
    before = forked_cpu_s()
    s = Started(tmp_path, "sim", str(tmp_path / "none.toml"))
    assert isinstance(s.child, ForkedChild) and s.child.wait(60) == 2
    wait_for(lambda: forked_cpu_s() > before, 10, "the forked child's CPU time counted")
    s.close()
    monkeypatch.setenv(ENV, "0")
    e = Started(tmp_path, "sim", str(tmp_path / "none.toml"))
    assert isinstance(e.child, subprocess.Popen) and e.child.wait(60) == 2
    assert e.err.read_text() == s.err.read_text()  # the same one line either way
    e.close()


def _children_of(ppid: int) -> dict[int, str]:
    """The running processes whose parent is ``ppid``: pid -> command line."""
    found = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit() and _alive(int(entry)):
            try:
                with open(f"/proc/{entry}/stat") as f:
                    parent = int(f.read().rpartition(")")[2].split()[1])
                with open(f"/proc/{entry}/cmdline", "rb") as f:
                    line = f.read().rstrip(b"\0").replace(b"\0", b" ").decode(errors="replace")
            except (OSError, ValueError, IndexError):
                continue
            if parent == ppid:
                found[int(entry)] = line
    return found


def test_a_forked_bsst_forks_its_children_through_the_same_server_and_they_end_with_it(tmp_path):
    """A ``bsst sitl`` forked by this process's server starts no server of its own: its vehicle and controller
    are forked by the same one (siblings of it), and when it is killed (SIGKILL: no clean-up of its own), they get
    SIGTERM from the server, as they would from a server of its own going with it."""
    server = forkserver._the_server()
    (tmp_path / "m.toml").write_text('name = "m"\nduration_s = 30.0\n[trajectory]\nkind = "sine"\n')
    with instance_slot() as n:
        launcher = Bsst("sitl", "m.toml", "--realtime", "--instance", str(n), "--no-plots", "--out",
                        str(tmp_path / "run"), cwd=tmp_path, stdout=False)
        try:
            def nodes() -> set[int]:
                return {pid for pid, line in _children_of(server.proc.pid).items()
                        if f"{sys.executable} -m bridge vehicle " in line
                        or f"{sys.executable} -m bridge controller " in line}

            wait_for(lambda: len(nodes()) >= 2 or launcher.poll() is not None, 60,
                     "the vehicle and the controller started")
            assert launcher.poll() is None, launcher.communicate(10)[1]
            kids = nodes()
            assert len(kids) == 2 and launcher.pid in _children_of(server.proc.pid), kids
            assert _children_of(launcher.pid) == {}  # no server of its own, no child of its own
            launcher.kill()
            wait_for(lambda: not any(_alive(p) for p in kids), 30, "the killed launcher's children gone")
            assert launcher.wait(30) == -signal.SIGKILL
        finally:
            if launcher.poll() is None:
                launcher.kill()
                launcher.wait(30)


def _maps_llvm(pid: int) -> bool:
    """Whether process ``pid`` has numba's compiler (llvmlite's library) mapped: compiled kernels loaded."""
    with open(f"/proc/{pid}/maps") as f:
        return "llvmlite" in f.read()


@pytest.mark.parametrize("kernels", ["compiled", "plain"])
def test_a_server_started_for_compiled_kernels_forks_children_that_have_them_loaded(tmp_path, monkeypatch, kernels,
                                                                                    own_server):
    """``BSST_KERNELS=compiled`` when the server starts: it loads the compiled kernels once (numba, the cached
    kernels), and each child it forks starts with them in its memory instead of loading them itself; otherwise
    the server does not load numba at all (a plain or ``auto`` session pays nothing for it)."""
    monkeypatch.setenv("BSST_KERNELS", kernels)
    old = own_server  # the next child starts a server in this environment
    r = _relay(tmp_path)  # a relay never loads kernels itself
    server = forkserver._the_server()
    try:
        assert server is not old
        assert _maps_llvm(server.proc.pid) == _maps_llvm(r.child.pid) == (kernels == "compiled")
    finally:
        r.close()  # (own_server kills this server and puts the worker's back)


def _vehicle(tmp_path: Path) -> Started:
    """A vehicle of a one-second mission, waiting for a controller (its flight short: ``auto`` alone would fly it
    plain, loading nothing)."""
    mission = tmp_path / "m.toml"
    mission.write_text('name = "m"\nduration_s = 1.0\n[trajectory]\nkind = "sine"\n')
    v = Started(tmp_path, "vehicle", str(mission), "--listen", "127.0.0.1:0", "--gcs", "none")
    wait_for(lambda: v.ready() or v.child.poll() is not None, 30, "the vehicle ready")
    assert v.child.poll() is None, v.err.read_text()
    return v


@pytest.mark.parametrize("kernels", ["auto", "plain"])
def test_under_auto_a_server_loads_the_compiled_kernels_before_its_third_child_that_flies(tmp_path, monkeypatch,
                                                                                       kernels, own_server):
    """``BSST_KERNELS=auto``: a relay does not count, one session's pair (two vehicles here) is forked plain,
    and before the third child that flies the server loads the kernels, so that the child starts with them (and
    ``auto`` flies what is loaded: tests/test_kernels.py); ``plain``: never."""
    monkeypatch.setenv("BSST_KERNELS", kernels)
    old = own_server  # the next child starts a server in this environment
    started = [_relay(tmp_path)]
    server = forkserver._the_server()
    try:
        assert server is not old
        started += [_vehicle(tmp_path), _vehicle(tmp_path)]
        assert not any(_maps_llvm(pid) for pid in (server.proc.pid, *(s.child.pid for s in started)))
        started.append(_vehicle(tmp_path))
        loaded = kernels == "auto"
        assert _maps_llvm(server.proc.pid) == _maps_llvm(started[-1].child.pid) == loaded
        assert not any(_maps_llvm(s.child.pid) for s in started[:-1])  # the earlier children are as they were
    finally:
        for s in started:
            s.close()  # (own_server kills this server and puts the worker's back)


WARMER_SCRIPT = """
import json
from bridge.core.flight import compiled_kernels_cached
from bridge.core.kernelpreload import KernelWarmer
from bridge.core.scalar import compiled_loaded
warm = KernelWarmer()
for argv in (["relay"], ["vehicle"], ["controller"], ["vehicle"], ["controller"]):
    warm(argv, {})
print(json.dumps({"cached": compiled_kernels_cached(), "loaded": compiled_loaded()}))
"""


@pytest.mark.parametrize("cache", ["warm", "cold"])
def test_the_warmer_loads_from_numbas_cache_and_never_compiles_on_the_childrens_behalf(tmp_path, cache) -> None:
    """With numba's cache on disk (the suite's, filled by conftest) the warmer loads the kernels at the third
    child that flies; with it cold (an empty ``NUMBA_CACHE_DIR``: a first run after an install) it does not
    compile them (~40 s, while a session waited for its child): the children fly plain."""
    env = {**os.environ, "BSST_KERNELS": "auto"}
    if cache == "cold":
        env["NUMBA_CACHE_DIR"] = str(tmp_path / "empty-cache")
    r = subprocess.run([sys.executable, "-c", WARMER_SCRIPT], capture_output=True, text=True, timeout=300,
                       cwd=Path(__file__).resolve().parent.parent, env=env)
    assert r.returncode == 0, r.stderr[-3000:]
    out = json.loads(r.stdout.strip().splitlines()[-1])
    assert (out["cached"], out["loaded"]) == ((True, True) if cache == "warm" else (False, False)), out
    assert "compiling" not in r.stderr, r.stderr  # nothing compiled, so nothing announced



# ``bsst sitl`` as a user starts it (its own fork server), in a process that says after the session which numba modules
# it imported, and whether its fork server (alive until the process ends) has the compiled kernels loaded
LAUNCHER_SCRIPT = """
import json, sys
from bridge.cli import main
from bridge.nodes import forkserver
rc = main(json.loads(sys.argv[1]))
held = [m for m in ("numba", "bridge.autopilot.ekfkernels", "bridge.core.scalarkernels") if m in sys.modules]
with open(f"/proc/{forkserver._the_server().pid}/maps") as f:
    print(json.dumps({"rc": rc, "held": held, "server": "llvmlite" in f.read()}))
"""


@pytest.mark.parametrize("kernels", ["auto", "compiled"])
def test_a_launcher_loads_no_kernels_its_fork_server_loads_them_for_its_children(tmp_path, kernels) -> None:
    """``bsst sitl --estimator ekf`` with a fork server: the launcher, which flies nothing, imports neither numba nor
    a kernel module (it loaded the EKF's kernels, and under ``compiled`` the law's and the plant's, ~0.5-0.7 s of
    CPU with a warm cache, while its server loaded them again for the children); the server loads what the
    session flies before it forks the children, the EKF's under ``auto`` too (one session's pair alone would not
    make it load anything: KernelWarmer)."""
    (tmp_path / "short.toml").write_text('name = "short"\nduration_s = 1.0\n[trajectory]\nkind = "sine"\n')
    env = {k: v for k, v in os.environ.items() if k not in (ENV, "BSST_KERNELS")}
    root = str(Path(__file__).resolve().parent.parent)
    env.update(BSST_KERNELS=kernels, PYTHONPATH=os.pathsep.join(filter(None, [root, env.get("PYTHONPATH")])))
    with instance_slot() as n:
        argv = ["sitl", "short.toml", "--sensors", "gnss", "--estimator", "ekf", "--no-plots", "--instance", str(n),
                "--out", "run"]
        r = subprocess.run([sys.executable, "-c", LAUNCHER_SCRIPT, json.dumps(argv)], capture_output=True,
                           text=True, timeout=300, cwd=tmp_path, env=env)
    assert r.returncode == 0, r.stderr[-3000:]
    out = json.loads(r.stdout.strip().splitlines()[-1])
    assert out == {"rc": 0, "held": [], "server": True}, (out, r.stderr[-3000:])
    assert "compiling" not in (tmp_path / "run" / "vehicle.log").read_text()  # it inherited them


# ``bsst sitl`` as a user starts it, in a process that says after the session which modules it imported
MODULES_SCRIPT = """
import json, sys
from bridge.cli import main
rc = main(json.loads(sys.argv[1]))
print(json.dumps({"rc": rc, "modules": sorted(sys.modules)}))
"""


def test_a_plain_sessions_launcher_imports_no_sweep_nor_vehicle_code_and_its_children_nothing(tmp_path) -> None:
    """``bsst sitl --no-plots`` with no noise or link flag: the launcher imports no campaign code (``bridge.sweep``
    and its multiprocessing: the check of ``--noise`` imported it, ~0.03 CPU-s a process) and no vehicle code (for
    a fleet's gate, ~0.03: its children fly the vehicle), and the children, forked from a server that preloaded
    what they fly, import nothing (each imported ``bridge.sweep`` and ``bridge.swarm`` for that check, ~0.04 CPU-s,
    and ``numpy.ma``, which ``np.percentile`` imports, ~0.01). Seen by Python's own import log
    (``PYTHONPROFILEIMPORTTIME``: a line on stderr per module imported, the children's stderr their logs)."""
    (tmp_path / "short.toml").write_text('name = "short"\nduration_s = 1.0\n[trajectory]\nkind = "sine"\n')
    env = {k: v for k, v in os.environ.items() if k != ENV}
    root = str(Path(__file__).resolve().parent.parent)
    env.update(PYTHONPROFILEIMPORTTIME="1", PYTHONPATH=os.pathsep.join(filter(None, [root, env.get("PYTHONPATH")])))
    with instance_slot() as n:
        argv = ["sitl", "short.toml", "--no-plots", "--instance", str(n), "--out", "run"]
        r = subprocess.run([sys.executable, "-c", MODULES_SCRIPT, json.dumps(argv)], capture_output=True,
                           text=True, timeout=300, cwd=tmp_path, env=env)
    assert r.returncode == 0, r.stderr[-3000:]
    out = json.loads(r.stdout.strip().splitlines()[-1])
    assert out["rc"] == 0, r.stderr[-3000:]
    assert not [m for m in out["modules"] if m.split(".")[0] == "multiprocessing"
                or m.startswith(("bridge.sweep", "bridge.nodes.vehicle"))]
    for child in ("vehicle", "controller"):
        log = (tmp_path / "run" / f"{child}.log").read_text()
        imported = [ln.rpartition("|")[2].strip() for ln in log.splitlines() if ln.startswith("import time:")]
        assert not imported, (child, imported)


@pytest.mark.parametrize("command", ["sim", "sitl"])
def test_a_launcher_forked_by_a_server_imports_nothing_at_its_start(tmp_path, monkeypatch, command, own_server) -> None:
    """Before the first ``bsst sim`` or ``bsst sitl`` it forks, the server imports what the command imports at its
    start (bridge.cli.forkserver.ChildWarmer: the flight's and the session's code, ~0.005 and ~0.016 CPU-s), so a
    process flying run after run through it (a script, this suite) pays it once, not once a run:
    neither the first child nor the next imports a module (Python's own import log, ``PYTHONPROFILEIMPORTTIME``, in
    the server's environment: a line on the child's stderr per module it imports)."""
    (tmp_path / "short.toml").write_text('name = "short"\nduration_s = 0.5\n[trajectory]\nkind = "sine"\n')
    monkeypatch.setenv("PYTHONPROFILEIMPORTTIME", "1")
    # (own_server: the next child starts a server in this environment, killed at the end)
    with instance_slot() as n:
        for run in ("one", "two"):
            argv = [command, "short.toml", "--no-plots", "--out", run]
            r = run_bsst(*argv, *(["--instance", str(n)] if command == "sitl" else []), cwd=tmp_path)
            assert forkserver._the_server() is not own_server
            assert r.returncode == 0, r.stderr[-3000:]
            imported = [ln.rpartition("|")[2].strip() for ln in r.stderr.splitlines()
                        if ln.startswith("import time:") and "imported package" not in ln]
            assert not imported, (run, " ".join(imported))
