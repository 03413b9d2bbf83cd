"""Where the cells fly: one cell in a worker, a local process pool, a Dask cluster, the batch engine.

In:  a mission, the cells to fly, a mode (``offline`` or ``lockstep``), ``jobs`` workers or a Dask client
Out: each finished ``cells.csv`` row, handed to ``report`` in the main process as it comes (the progress it makes:
     bridge.sweep.progress)

A cell that raises, or whose worker dies, becomes an ``error`` row (a death names how: ``worker process died:
killed by SIGKILL``).
"""

from __future__ import annotations

import ast
import contextlib
import inspect
import multiprocessing as mp
import multiprocessing.forkserver as forkserver
import os
import select
import signal
import sys
import tempfile
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path
from types import FrameType
from typing import Any

from bridge.autopilot.compiling import announce_compiling
from bridge.batch.scope import batch_problem
from bridge.core.interrupt import Interrupts, sigint_futures, wait_or_interrupt
from bridge.core.scalar import compiled_loaded, kernels_choice
from bridge.loop import fly
from bridge.nodes.process import die_with_parent, exit_text
from bridge.record.runlog import Run
from bridge.session import instance_slot, sitl
from bridge.swarm import simulate as simulate_fleet
from bridge.sweep.cells import error_row, row_from_fleet, row_from_run
from bridge.sweep.grid import AXES, FLEET_FORMATION, Cell, cell_flight, cell_overrides
from missions import Mission
from params import ConfigError


def run_cell(mission: Mission, cell: Cell, mode: str = "offline") -> dict[str, Any]:
    """Fly one cell (in a worker process or on a Dask worker) and return its row.

    Never raises for a failing flight: the exception becomes an ``error`` row.
    """
    _idle.clear()
    try:
        if cell.vehicles > 1:  # a fleet, offline (Sweep refuses lockstep fleets): one row, its worst vehicle's
            fleet = simulate_fleet(mission, vehicles=cell.vehicles, formation=FLEET_FORMATION,
                                   overrides=cell_overrides(cell), plots=False)
            return row_from_fleet(cell, fleet)  # type: ignore[arg-type]
        flight = cell_flight(mission, cell)
        run = _fly_lockstep(flight.mission) if mode == "lockstep" else fly(flight, plots=False)
        return row_from_run(cell, run)
    except Exception as exc:  # a failed cell is a result, never the end of the sweep
        return error_row(cell, f"{type(exc).__name__}: {exc}")
    finally:
        _idle.set()


_idle = threading.Event()  # set while this process flies no cell (a worker that lost its sweep then ends)
_idle.set()


def _fly_lockstep(mission: Mission) -> Run:
    """Fly with the full SITL processes in lockstep (the link model applied in simulation
    time, as offline), on an ``--instance`` port set held exclusively while it flies."""
    with instance_slot() as instance:
        return sitl(mission, realtime=False, instance=instance, plots=False)


Report = Callable[[dict[str, Any]], None]  # called in the main process with each finished row


WORKER_STOP_GRACE_S = 10.0  # after its sweep died: time for a lockstep cell to stop its children and clean up


WARM_CELLS = 4  # offline cells from which a first pool's fork server loads the compiled kernels under auto


def _worker_init(sweep_pid: int) -> None:
    # Ctrl-C goes to the whole process group: the main process stops the sweep; a worker
    # finishes (or is ended with) its cell rather than recording it as aborted.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    # A worker must not outlive its sweep: a SIGKILL of `bsst sweep` left its workers flying, then
    # blocked for ever on a queue whose both ends they hold, and the forkserver (their parent) waiting on
    # them. So a thread watches the sweep's own process, and PR_SET_PDEATHSIG covers the forkserver's end.
    die_with_parent()
    threading.Thread(target=_end_with, args=(sweep_pid,), name="end-with-sweep", daemon=True).start()


def _end_with(sweep_pid: int) -> None:
    """Wait for the sweep's process to end, then end this worker: SIGTERM (the default action ends an
    idle worker or an offline cell at once; a lockstep cell's session takes it as a stop: its vehicle
    and controller stopped, its temporary directory removed), then ``os._exit`` once the cell is
    over, or after :data:`WORKER_STOP_GRACE_S` at most. (A session's children die with the worker
    too: ``PR_SET_PDEATHSIG``, bridge.session.children.)"""
    _wait_for_exit(sweep_pid)
    os.kill(os.getpid(), signal.SIGTERM)
    _idle.wait(WORKER_STOP_GRACE_S)  # this thread only: the main thread is stopping its cell
    os._exit(1)


def _wait_for_exit(pid: int) -> None:
    """Return once process ``pid`` has ended (a pidfd where Linux has one, else a poll every 0.2 s)."""
    try:
        fd = os.pidfd_open(pid)
    except ProcessLookupError:
        return  # already gone
    except (AttributeError, OSError):  # no pidfd here: poll
        while _alive(pid):
            time.sleep(0.2)
        return
    try:
        select.select([fd], [], [])  # readable once the process has ended
    finally:
        os.close(fd)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def check_main_guard() -> None:
    """Refuse (ConfigError) to start worker processes from a script's top level without the
    ``if __name__ == "__main__":`` guard.

    A worker (forkserver, like spawn) imports the main script again to start: unguarded, it ran the
    script's flights again, then died starting a pool of its own ("An attempt has been made to start a new
    process before the current process has finished its bootstrapping phase"), and every cell became an
    ``error`` row. The script's source is read with ``ast``: the line of its top level that led here must
    lie in the body of an ``if`` that compares ``__name__`` with ``"__main__"``. Where the workers would
    not import the script again (``python -m package``, an interactive session, ``python -c``) or the
    source cannot be read, nothing is refused."""
    main = sys.modules.get("__main__")
    name = getattr(getattr(main, "__spec__", None), "name", None)
    path = getattr(main, "__file__", None)
    if name == "__main__" or (name or "").endswith(".__main__") or path is None or Path(path).stem == "ipython":
        return  # the rules multiprocessing.spawn follows: the workers run none of the main module's code
    frame = _main_top_level(main)
    if frame is None:  # the script's top level is done (a later call): nothing of it runs again here
        return
    try:
        tree = ast.parse(Path(path).read_bytes(), filename=path)
    except (OSError, SyntaxError, ValueError):
        return
    line = frame.f_lineno
    if any(_is_main_test(n.test) and n.body[0].lineno <= line <= (n.body[-1].end_lineno or line)
           for n in ast.walk(tree) if isinstance(n, ast.If)):
        return
    raise ConfigError(f'{path}:{line}: starts worker processes outside an `if __name__ == "__main__":` block: each '
                      f"worker imports the script again and would run its flights again; put the script's calls "
                      f'under `if __name__ == "__main__":` (as the README\'s Python example does)')


def _main_top_level(main: Any) -> FrameType | None:
    """The frame of the main module's own top-level code on this thread's stack (None: not on it)."""
    frame = inspect.currentframe()  # the stack is the only record of where the call came from
    found = None
    while frame is not None:
        if frame.f_code.co_name == "<module>" and frame.f_globals is getattr(main, "__dict__", None):
            found = frame
        frame = frame.f_back
    return found


def _is_main_test(test: ast.expr) -> bool:
    """Whether an ``if``'s test is ``__name__ == "__main__"`` (either way round)."""
    if not (isinstance(test, ast.Compare) and len(test.ops) == 1 and isinstance(test.ops[0], ast.Eq)):
        return False
    sides = [test.left, *test.comparators]
    return (any(isinstance(x, ast.Name) and x.id == "__name__" for x in sides)
            and any(isinstance(x, ast.Constant) and x.value == "__main__" for x in sides))


def _pool(jobs: int, cells: int = 0, mode: str = "offline") -> ProcessPoolExecutor:
    """A pool of ``jobs`` workers forked from multiprocessing's fork server, which imports the sweep's modules once
    when it starts (the first pool of this process): with ``BSST_KERNELS=compiled`` the kernels too
    (bridge.core.kernelpreload), and under ``auto`` too when this first pool flies at least :data:`WARM_CELLS`
    ``cells`` offline, or this process already holds them (bridge.core.kernelwarm): once, not in each worker, and
    ``auto`` flies what is loaded. The first pool's list stays for every later pool of the process, so a process
    that flies compiled (a script's earlier flights, a test worker) preloads them even for a first pool of one
    cell: its later grids would otherwise fly plain, at ~2.5x the CPU (docs/testing.md)."""
    ctx = mp.get_context("forkserver")
    preload = ["bridge.sweep", "bridge.loop", "bridge.core.kernelpreload"]
    warm = cells >= WARM_CELLS or compiled_loaded()
    if mode == "offline" and warm and kernels_choice() == "auto":
        preload.append("bridge.core.kernelwarm")
    ctx.set_forkserver_preload(preload)  # (no effect once the fork server runs: the first pool's list stays)
    _start_fork_server()
    return ProcessPoolExecutor(max_workers=jobs, mp_context=ctx, initializer=_worker_init, initargs=(os.getpid(),))


def _start_fork_server() -> None:
    """Start multiprocessing's fork server, if it is not running, with SIGINT ignored from its birth (a disposition
    its exec keeps): CPython's ignores SIGINT itself only once it has imported its preload list (about a second
    for a sweep's), and a Ctrl-C to the sweep's process group before that killed it with a traceback of its own
    beside the sweep's "interrupted". Its workers ignore SIGINT anyway (:func:`_worker_init`). A Ctrl-C in the
    few milliseconds this process ignores it for the start is not taken (press it again)."""
    if threading.current_thread() is not threading.main_thread():
        forkserver.ensure_running()
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        with _socket_tempdir():
            forkserver.ensure_running()
    finally:
        signal.signal(signal.SIGINT, previous)


SOCKET_PATH_MAX = 107  # bytes of an AF_UNIX socket's path (sun_path's 108, less its NUL)
_LISTENER_TAIL = len("/pymp-12345678/listener-12345678")  # what multiprocessing adds to the temporary directory


@contextlib.contextmanager
def _socket_tempdir() -> Iterator[None]:
    """The temporary directory while multiprocessing's fork server starts: it listens on a socket in a new folder
    there (``pymp-*``), and a TMPDIR too long for that socket's path made ``bsst sweep`` end in a traceback
    ("AF_UNIX path too long"). Then the first of /tmp, /var/tmp, /dev/shm this process may write in; none: a
    ConfigError naming TMPDIR."""
    base = tempfile.gettempdir()
    if len(os.fsencode(base)) + _LISTENER_TAIL <= SOCKET_PATH_MAX:
        yield
        return
    for short in ("/tmp", "/var/tmp", "/dev/shm"):
        if os.path.isdir(short) and os.access(short, os.W_OK | os.X_OK):
            kept, tempfile.tempdir = tempfile.tempdir, short
            try:
                yield
            finally:
                tempfile.tempdir = kept
            return
    raise ConfigError(f"TMPDIR {base}: too long for the socket of the sweep's worker pool (at most "
                      f"{SOCKET_PATH_MAX - _LISTENER_TAIL} bytes), and no /tmp, /var/tmp or /dev/shm to write in")


def run_local(mission: Mission, todo: Sequence[Cell], mode: str, jobs: int, report: Report,
              name: str = "sweep") -> None:
    """Fly cells in a local process pool, at most 2 x jobs in flight; ``name``: the command, as a Ctrl-C's line
    names it. After a Ctrl-C the cells in flight end first and are reported (not those a second Ctrl-C stops: a
    resume flies them). A Ctrl-C that came after the last cell's wait raises KeyboardInterrupt all the same, so
    that a search (``bsst margin``) stops there and a sweep knows of it (its cells all flown: whole, and said so;
    until the third wave's forty-third session a sweep's was taken by nobody after its "interrupted" line).

    If a worker process dies (the pool breaks), the cells that were in flight are flown again one at a time in a
    fresh one-worker pool: the one that breaks that one too is an error row, the others get their real result.
    """
    check_main_guard()
    queue: deque[Cell] = deque(todo)
    suspects: deque[Cell] = deque()
    with sigint_futures() as sigint:  # Ctrl-C raises here, not inside the pool's locks
        while queue or suspects:
            if suspects:
                _fly_alone(mission, suspects.popleft(), mode, report, sigint, name)
                continue
            _fly_in_pool(mission, queue, suspects, mode, jobs, report, sigint, name)
    if sigint.first.done():  # taken after the last wait (read once the block has read every SIGINT): not lost
        raise KeyboardInterrupt


def _fly_alone(mission: Mission, cell: Cell, mode: str, report: Report, sigint: Interrupts, name: str) -> None:
    """Fly a cell that was in flight when its pool broke, alone in a pool of one worker, and report its row: if it
    breaks this pool too, an ``error`` row naming how the worker ended (``worker process died: killed by SIGKILL``;
    concurrent.futures says only "terminated abruptly"). After a Ctrl-C, its row only if it flew to its end."""
    pool = _pool(1)
    # private, but the only holder of the worker's exit status (its parent, the fork server, sends it to the
    # Process); shutdown drops the attribute, not the dict
    workers: Mapping[int, Any] = pool._processes  # type: ignore[attr-defined]
    future = pool.submit(run_cell, mission, cell, mode)
    try:
        wait_or_interrupt([future], sigint.first)
    except BaseException:  # a Ctrl-C in the wait: the row if the cell flew to its end
        _shut_down(pool, sigint, name)
        _report_flown([future], report)
        raise
    # a Ctrl-C from here on came after the wait (sigint.first.done() is no test of one in it): the row, once, below
    _shut_down(pool, sigint, name)  # (joins the worker: its exit status is known from here)
    try:
        row = future.result()
    except BrokenProcessPool:
        ended = [p.exitcode for p in workers.values() if p.exitcode]
        row = error_row(cell, "worker process died" + (f": {exit_text(ended[0])}" if ended else ""))
    report(row)


def _report_flown(futures: Iterable[Future], report: Report) -> None:
    """Report the rows of the cells of ``futures`` that flew to their end (after a Ctrl-C; the others are not
    results: a resume flies them)."""
    for f in futures:
        if f.done() and not f.cancelled() and f.exception() is None:
            report(f.result())


def _fly_in_pool(mission: Mission, queue: deque[Cell], suspects: deque[Cell], mode: str, jobs: int,
                 report: Report, sigint: Interrupts, name: str) -> None:
    """Fly ``queue``'s cells in one pool of ``jobs`` workers until it is empty or the pool breaks (the cells
    in flight then go to ``suspects``); after a Ctrl-C, report those that end (:func:`run_local`)."""
    pool = _pool(jobs, len(queue), mode)
    inflight: dict[Any, Cell] = {}
    try:
        while queue or inflight:
            while queue and len(inflight) < 2 * jobs:
                c = queue.popleft()
                inflight[pool.submit(run_cell, mission, c, mode)] = c
            broken = False
            for f in wait_or_interrupt(inflight, sigint.first):
                c = inflight.pop(f)
                try:
                    report(f.result())
                except BrokenProcessPool:
                    suspects.append(c)
                    broken = True
            if broken:
                while running := [f for f in inflight if not f.done()]:
                    wait_or_interrupt(running, sigint.first)
                suspects.extend(inflight.values())
                inflight.clear()  # (they fly again one by one: none is reported here)
                return
    finally:
        _shut_down(pool, sigint, name)
        if sigint.first.done():  # the cells in flight have ended: those that flew are results
            _report_flown(inflight, report)


def _shut_down(pool: ProcessPoolExecutor, sigint: Interrupts, name: str) -> None:
    """Shut ``pool`` down once the cells in flight have ended (after a Ctrl-C, ``sigint.first`` done, their workers
    ignore it and finish them, and their rows are reported: :func:`run_local`). The second Ctrl-C
    (``sigint.second``, before or during this wait) ends the workers at once (SIGTERM: an offline cell dies, a
    lockstep cell's session stops its children) rather than wait for them."""
    if sigint.first.done():
        print(f"{name}: interrupted; the cells in flight end first (Ctrl-C again stops them now)", file=sys.stderr,
              flush=True)
    ended: Future = Future()

    def shut() -> None:
        pool.shutdown(wait=True, cancel_futures=True)
        ended.set_result(None)

    closer = threading.Thread(target=shut, name="pool-shutdown", daemon=True)
    closer.start()
    wait([ended, sigint.second], return_when=FIRST_COMPLETED)
    if sigint.second.done():
        for worker in mp.active_children():  # this process's only children: the pool's workers
            worker.terminate()
    closer.join()


def run_dask(client: Any, mission: Mission, todo: Sequence[Cell], mode: str, report: Report) -> None:
    """Fly cells on a Dask distributed cluster; a task that fails there becomes an error row."""
    from distributed import as_completed  # lazy: an optional dependency

    mission_f = client.scatter(mission, broadcast=True)
    futures = {client.submit(run_cell, mission_f, c, mode, pure=False): c for c in todo}
    try:
        for f in as_completed(futures):
            c = futures[f]
            try:
                report(f.result())
            except Exception as exc:  # e.g. KilledWorker: the worker died on this cell
                report(error_row(c, f"{type(exc).__name__}: {exc}"))
    finally:
        client.cancel(list(futures))


# -- the batch engine: many cells of one mission in one numpy loop (bridge.batch) ---------------------
ENGINES = ("auto", "batch", "process")
BATCH_CHUNK = 250  # cells flown together: each chunk's rows are recorded (and cells.csv appended) as it ends
# auto takes the batch from this many cells on. Its kernels are compiled, so it is the faster engine at
# any size (a sweep of 2 sine cells 1.8 s against 2.2, of 8 2.0 against 4.0, the kernels' ~1 s load
# included), but its rows agree with `bsst sim` within 1e-6 (smc, a switching law, 1 %) where the process
# engine's are bsst sim's to the bit: a small grid, whose rows a user checks against single runs, stays
# on the reference
BATCH_MIN_CELLS = 32


def engine_for(mission: Mission, todo: Sequence[Cell], mode: str, engine: str,
               min_cells: int = BATCH_MIN_CELLS) -> tuple[str, str]:
    """The engine that flies ``todo``, and why: ``batch`` where the batch can fly the grid
    (offline cells, :func:`bridge.batch.scope.batch_problem` has nothing against them; for ``auto``
    also at least ``min_cells`` of them), ``process`` otherwise. ``engine`` ``"batch"``
    that cannot be honoured is bad input (ConfigError), not a silent fallback; ``"auto"`` falls
    back and says why: what the batch cannot fly (sensors and an estimator, a law of one's own, ...)
    before the grid's size, so that the reason given is the one that decides (a check that imports no numba: a
    small grid flies on the process engine)."""
    if engine not in ENGINES:
        raise ConfigError(f"--engine: must be one of {', '.join(ENGINES)}, got {engine!r}")
    if engine == "process":
        return "process", "asked for"
    fleets = sorted({c.vehicles for c in todo if c.vehicles > 1})
    why = "lockstep cells fly as SITL sessions" if mode == "lockstep" else (
        f"cells of {', '.join(map(str, fleets))} vehicles (--vehicles) fly a fleet in one world, which the batch "
        "engine does not" if fleets else
        batch_problem(mission, [cell_overrides(c) for c in todo]) if todo else None)
    if why is not None:
        if engine == "batch":
            raise ConfigError(f"--engine batch: {why}; fly it with --engine process")
        return "process", f"the batch engine cannot fly this grid: {why}"
    if engine == "auto" and len(todo) < min_cells:
        return "process", f"fewer than {min_cells} cells to fly"
    return "batch", "the grid allows it" if engine == "auto" else "asked for"


def batch_row(cell: Cell, measures: Mapping[str, Any]) -> dict[str, Any]:
    """A ``cells.csv`` row from a batch cell's measured columns (the same keys as :func:`row_from_run`)."""
    return {**{a: getattr(cell, a) for a in AXES}, "seed": cell.seed, **measures}


def run_batch(mission: Mission, todo: Sequence[Cell], report: Report, chunk: int = BATCH_CHUNK,
              jobs: int | None = None) -> None:
    """Fly cells with the batch engine in this process, ``chunk`` at a time (rows reported per chunk), on
    ``jobs`` threads (default: every core; the rows do not depend on it)."""
    from bridge.batch import fly_batch  # lazy: numba loads only where the batch flies (engine_for)

    announce_compiling("bridge.batch")  # a cold cache: say so before ~24 s of silence
    for i in range(0, len(todo), chunk):
        part = todo[i:i + chunk]
        for cell, m in zip(part, fly_batch(mission, [cell_overrides(c) for c in part], jobs=jobs), strict=True):
            report(batch_row(cell, m))


def run_batch_dask(client: Any, mission: Mission, todo: Sequence[Cell], report: Report,
                   chunk: int = BATCH_CHUNK) -> None:
    """Fly cells with the batch engine on a Dask cluster: a chunk of cells is one task."""
    from distributed import as_completed  # lazy: an optional dependency

    from bridge.batch import fly_batch  # lazy: numba loads only where the batch flies (engine_for)

    mission_f = client.scatter(mission, broadcast=True)
    parts = [todo[i:i + chunk] for i in range(0, len(todo), chunk)]
    futures = {client.submit(fly_batch, mission_f, [cell_overrides(c) for c in p], pure=False): p for p in parts}
    try:
        for f in as_completed(futures):
            part = futures[f]
            try:
                measures = f.result()
            except Exception as exc:  # e.g. KilledWorker: the chunk's cells are error rows, the sweep goes on
                for c in part:
                    report(error_row(c, f"{type(exc).__name__}: {exc}"))
                continue
            for cell, m in zip(part, measures, strict=True):
                report(batch_row(cell, m))
    finally:
        client.cancel(list(futures))
