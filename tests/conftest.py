"""Shared test fixtures, and the environment every test and every process it starts runs in."""

from __future__ import annotations

import atexit
import fcntl
import os
import signal
import sys
from collections import Counter
from collections.abc import Iterator

# Set before numpy loads here, inherited by every child: bsst's own processes give numpy's BLAS one thread
# (bridge/cli/__init__.py says why), and so does each test process.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
# ``BSST_KERNELS`` is left as users have it (unset: ``auto``): each test worker loads the compiled kernels once
# (``_kernels_compiled``), so its own flights fly them (``auto`` takes kernels already loaded, the same bits as the
# plain ones: tests/test_kernels.py), and so do the children its fork server forks once it has forked one
# session's pair (bridge.core.kernelpreload.KernelWarmer); a ``bsst`` process started cold flies short flights
# plain, as a user's does (docs/testing.md).

from pathlib import Path

import pytest
from hypothesis import settings

from bridge.autopilot.estimator import compile_estimator
from bridge.batch import compile_batch
from bridge.core.flight import load_compiled_kernels
from tests.quietgc import collector_off

# No deadline on a Hypothesis example: its default (200 ms) is a timing assertion, and with both cores busy an
# example of tests/test_power.py's took longer (the thirty-eighth session, load ~14). Speed is for benchmarks/.
settings.register_profile("bsst", deadline=None)
settings.load_profile("bsst")


def _leave_without_teardown() -> None:
    """End a pytest-xdist worker here, its results already sent: the interpreter's own teardown (freeing every
    module's objects: numba's, matplotlib's, the flights') took each worker 1.5-2.3 s after its last test,
    which the whole run waited for (``make test-fast`` 61.5 -> 55.6 s, docs/testing.md). Registered first, it
    runs after every other exit handler (they run last-registered first)."""
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(0)


if os.environ.get("PYTEST_XDIST_WORKER"):
    atexit.register(_leave_without_teardown)

ROOT = Path(__file__).resolve().parent.parent
MISSIONS = ROOT / "missions"


KERNELS = {"ekf": lambda: compile_estimator("ekf"), "batch": compile_batch,
           "scalar": lambda: load_compiled_kernels(ekf=False)}


@pytest.fixture
def missions_dir() -> Path:
    return MISSIONS


def _load_kernels(kind: str, shared: Path) -> None:
    """Compile one set of numba's kernels, or load it from its on-disk cache, under a lock per set shared by
    every worker of the session: one worker compiles it, the others then load it."""
    with open(shared / f"compile-{kind}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        KERNELS[kind]()


@pytest.fixture(autouse=True)
def sigint_handler_kept() -> Iterator[None]:
    """Every test leaves SIGINT's handler as it found it: one left ignored (a command's ``ignore_sigint`` called
    outside ``main``) is inherited by every child the worker starts after it, and a child that needs Ctrl-C then
    cannot get it (a test of the sweep's fork server read SIG_IGN where Python's own handler belonged)."""
    before = signal.getsignal(signal.SIGINT)
    yield
    after = signal.getsignal(signal.SIGINT)
    assert after is before, f"the test left SIGINT's handler {after!r} (it was {before!r})"


@pytest.fixture(autouse=True)
def sys_path_kept() -> Iterator[None]:
    """Every test leaves ``sys.path`` as it found it: a folder left on it is inherited by every process the worker
    starts after that test with ``sys.path`` passed on (multiprocessing's spawn, a Dask cluster's workers). Once
    ``benchmarks/`` was left first (a benchmark module imported, its own ``sys.path.insert`` undone by a ``pop(0)`` of
    the wrong entry): a later test's Dask worker imported ``benchmarks/missions.py`` as ``missions`` ("'missions' is
    not a package"). Put it back with :func:`tests.sitlkit.benchmark_module`."""
    before = list(sys.path)
    yield
    assert sys.path == before, f"the test left sys.path {sys.path!r} (it was {before!r})"


@pytest.fixture
def sys_path_restored() -> Iterator[None]:
    """``sys.path`` put back after a test whose code under test changes it by design, before ``sys_path_kept``
    checks: a user's law file that puts its own folder on it, Dask's in-process workers their scratch folders."""
    before = list(sys.path)
    yield
    sys.path[:] = before


INSTANCE_PORTS = range(14550, 14570)  # instances 0-9: their ground-station and vehicle ports (bridge.mavlink.address)


def _instance_sockets() -> dict[int, int]:
    """This process's UDP sockets bound to an instance's port: socket inode -> port (/proc/self/fd, /proc/net/udp)."""
    mine = set()
    for fd in os.listdir("/proc/self/fd"):
        try:
            link = os.readlink(f"/proc/self/fd/{fd}")
        except OSError:
            continue
        if link.startswith("socket:["):
            mine.add(int(link[8:-1]))
    out: dict[int, int] = {}
    for table in ("/proc/net/udp", "/proc/net/udp6"):
        try:
            rows = Path(table).read_text().splitlines()[1:]
        except OSError:
            continue
        for row in rows:
            f = row.split()
            port, inode = int(f[1].rsplit(":", 1)[1], 16), int(f[9])
            if port in INSTANCE_PORTS and inode in mine:
                out[inode] = port
    return out


@pytest.fixture(autouse=True)
def instance_ports_released() -> Iterator[None]:
    """Every test closes the sockets it bound on an instance's port: one left open (a ground station's connection
    never closed) holds that port past the test's instance slot, and the next session that takes the slot, or
    test_an_automatic_instance_is_the_highest_free_one, finds it bound by a worker (twice, for 120 s, 14559)."""
    before = _instance_sockets()
    yield
    left = sorted(p for i, p in _instance_sockets().items() if i not in before)
    assert not left, f"the test left UDP 127.0.0.1:{left} bound in this worker (close its ground station)"


@pytest.fixture(scope="session", autouse=True)
def _kernels_compiled(tmp_path_factory: pytest.TempPathFactory, worker_id: str) -> None:
    """Compile numba's kernels (the EKF's, the scalar engine's), or load them from their on-disk cache, once per
    test process before any test: as ``bsst sitl`` does before it starts a vehicle, so that a test that starts a
    vehicle does not have it compile them (~12 s on a fresh clone) inside its start-up time, and the worker's own
    flights fly them (``auto``). The batch engine's (~23 s of one core on a fresh clone, one kernel) a worker
    loads only before a test that flies it (``batch_kernels``), compiled meanwhile by a process of its own
    (:func:`pytest_configure`): on a fresh clone every worker waited for it before its first test (60 s each in a
    loaded suite), then one did (70 s)."""
    # on a fresh clone each worker compiles a different set first, the others loading it after (the batch
    # engine's: the process pytest_configure started, or the first test that flies it)
    order = ["scalar", "ekf"] if worker_id == "gw1" else ["ekf", "scalar"]
    shared = tmp_path_factory.getbasetemp().parent  # the same directory for every worker of a session
    for kind in order:
        _load_kernels(kind, shared)


@pytest.fixture(scope="session")
def batch_kernels(tmp_path_factory: pytest.TempPathFactory) -> None:
    """The batch engine's kernels compiled or loaded in this worker (and so on disk for the processes a test
    starts: ``bsst sweep``, ``bsst margin``), for the modules whose tests fly it (their ``pytestmark``)."""
    _load_kernels("batch", tmp_path_factory.getbasetemp().parent)


_BATCH_COMPILE = """
from bridge.batch import compile_batch
compile_batch()  # the session's batch lock, taken by the parent, is held until this process ends
"""


@pytest.hookimpl(trylast=True)  # after the tmpdir plugin's: the session's base directory is known
def pytest_configure(config: pytest.Config) -> None:
    """pytest-xdist's controller (``-n N``, N > 0): compile (or load) the batch engine's kernels in a process of
    its own while the workers start and run their first tests, holding the session's batch lock until it is done;
    a worker's ``batch_kernels`` takes the lock after it and loads them from the cache (if the process fails, the
    worker compiles them itself). The process is ended with the session (:func:`pytest_unconfigure`). Before the
    workers start, it parses the test modules for their groups once, for every worker (tests/scheduling.py)."""
    if os.environ.get("PYTEST_XDIST_WORKER") or not getattr(config.option, "numprocesses", 0):
        return
    import subprocess

    from tests.scheduling import write_groups  # the controller's parse, handed on to its workers

    shared = config._tmp_path_factory.getbasetemp()  # type: ignore[attr-defined]  # the workers' base's parent
    write_groups(config.args, shared / "test-groups.json")

    lock = os.open(shared / "compile-batch.lock", os.O_WRONLY | os.O_CREAT, 0o644)
    fcntl.flock(lock, fcntl.LOCK_EX)  # held by the open file, which the child shares (pass_fds) until it ends
    config._batch_compile = subprocess.Popen(  # type: ignore[attr-defined]
        [sys.executable, "-c", _BATCH_COMPILE], cwd=ROOT, pass_fds=(lock,), stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    os.close(lock)


def pytest_unconfigure(config: pytest.Config) -> None:
    proc = getattr(config, "_batch_compile", None)
    if proc is not None and proc.poll() is None:
        proc.kill()
        proc.wait()


@pytest.hookimpl(tryfirst=True, optionalhook=True)  # before pytest-xdist's own (which makes its loadscope one)
def pytest_xdist_make_scheduler(config: pytest.Config, log: object) -> object | None:
    """``--dist loadscope`` (pyproject.toml): the tests that share a module-scoped fixture on one worker,
    every other test on whichever worker is free (tests/scheduling.py says why)."""
    if config.getvalue("dist") != "loadscope":
        return None
    from tests.scheduling import SharedFixtureScheduling  # the controller only: xdist is not loaded without -n

    return SharedFixtureScheduling(config, log)


@pytest.hookimpl(wrapper=True)
def pytest_collection(session: pytest.Session) -> Iterator[None]:
    """Collect with the garbage collector off: importing every test module (numba, pymavlink, MAVSDK, the kits)
    and parsing each module's source for its groups (tests/scheduling.py) makes objects that live as long as the
    worker, and each collection of the oldest generation meanwhile walked all those made before them. Not frozen
    after (a test worker's heap is not: tests/test_plots.py draws in one, as a user's ``bsst`` does)."""
    with collector_off():
        return (yield)


def pytest_ignore_collect(collection_path: Path, config: pytest.Config) -> bool | None:
    """``-m "not process"`` (``make test-fast``): a module marked ``process`` is not imported at all, since
    every test in it would be deselected (its imports cost each worker ~1.4 s: pymavlink, MAVSDK, the kits)."""
    if (config.getoption("markexpr", "") != "not process" or collection_path.suffix != ".py"
            or not collection_path.name.startswith("test_")):
        return None
    text = collection_path.read_text()
    if "pytestmark" not in text:
        return None
    import ast

    from tests.scheduling import is_marked_process  # lazy: it imports pytest-xdist's scheduler

    return True if is_marked_process(ast.parse(text)) else None


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The order the workers are handed the tests in (tests/scheduling.py): first the groups of tests that share
    a module-scoped fixture, the largest first; then every other test, those that start processes or open sockets
    (``pytest.mark.process``: the long ones) before the pure ones, each in its files' order, so that the workers
    end on many short tests, not on one long one. Among the groups, and among the process tests, those that fly
    the batch engine (``batch_kernels``) come last: on a fresh clone its kernel is still compiling in its own
    process (:func:`pytest_configure`) when the workers begin. Every worker sorts alike (pytest-xdist requires one
    collection)."""
    from tests.scheduling import scope_of  # (pure: each module's source read once, or the controller's table)

    scopes = [scope_of(item.nodeid) for item in items]
    size = Counter(scopes)
    first = {scope: i for i, scope in reversed(list(enumerate(scopes)))}

    def key(i: int) -> tuple[int, ...]:
        item, scope = items[i], scopes[i]
        batch = int("batch_kernels" in item.fixturenames)
        if size[scope] > 1:
            return (0, batch, -size[scope], first[scope], i)
        return (1, int(item.get_closest_marker("process") is None), batch, i)

    items[:] = [items[i] for i in sorted(range(len(items)), key=key)]
