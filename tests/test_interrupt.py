"""Covers bridge.core.interrupt, bridge.__main__, bridge.cli.flying and bridge.cli.runreport: Ctrl-C while the main
thread waits on a pool's futures, while the ``bsst`` command is still importing the CLI, and once its run is on disk.

Each case is a real Python child sent a real SIGINT: the interrupt must come out as KeyboardInterrupt at
the wait's return, never inside concurrent.futures' locks (where it left `bsst sweep` hanging), even when the
signal lands on another thread while the main thread sleeps on a lock (where it was taken only once the lock
was released); the second Ctrl-C is counted, and a third interrupts at once. A Ctrl-C during the CLI's imports
(a real SIGINT, sent by an import hook as ``bridge.cli`` starts to load) ends as the CLI says it, not as a traceback;
one once the run is on disk and its summary printing changes nothing.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import threading
from concurrent.futures import FIRST_COMPLETED, Future, wait
from pathlib import Path

import pytest

from bridge import simulate
from bridge.core.interrupt import sigint_futures, sigint_held
from bridge.loop import StopAfterRecord, recorded_run
from bridge.record.runlog import Run
from missions import Mission, Sine
from tests.sitlkit import Proc, csv_rows
from tests.waiting import wait_for

pytestmark = pytest.mark.process

# A pool of one thread finishing thousands of short tasks: the main thread spends most of its time taking
# the futures' locks inside wait(), where a KeyboardInterrupt raised by Python's own handler would leave some
# held, and the pool's shutdown then waits for ever on its thread.
MANY_WAITS = """
    from concurrent.futures import ThreadPoolExecutor
    from bridge.core.interrupt import sigint_futures, wait_or_interrupt

    def tick(i):
        return i

    try:
        with sigint_futures() as sigint, ThreadPoolExecutor(1) as pool:
            pending = {pool.submit(tick, i) for i in range(2000)}
            print("ready", flush=True)
            rounds = 0
            while True:
                rounds += 1
                done = wait_or_interrupt(pending, sigint.first)
                pending -= done
                pending |= {pool.submit(tick, i) for i in range(len(done))}
    except KeyboardInterrupt:
        print("interrupted after", rounds, "waits", flush=True)
"""

THRICE = """
    import signal, threading
    from concurrent.futures import Future
    from bridge.core.interrupt import sigint_futures, wait_or_interrupt

    with sigint_futures() as sigint:
        print("ready", flush=True)
        try:
            wait_or_interrupt([Future()], sigint.first)
        except KeyboardInterrupt:
            print("first at the wait's return", flush=True)
        print("second:", sigint.second.result(timeout=120), flush=True)
        try:
            print("waiting again", flush=True)
            for _ in range(1200):
                threading.Event().wait(0.1)  # a third Ctrl-C: the previous handler, at once
            print("third never came", flush=True)
        except KeyboardInterrupt:
            print("third at once", flush=True)
    print("restored", signal.getsignal(signal.SIGINT) is signal.default_int_handler, flush=True)
"""

# SIGINT sent to a thread other than the main one while the main thread sleeps on a lock: the C handler runs
# there, and Python's handler would wait for the main thread's next bytecode, after the lock (here: never).
# A SIGINT to the process that lands just before the main thread blocks meets the same fate.
ELSEWHERE = """
    import os, signal, threading, time
    from concurrent.futures import Future
    from bridge.core.interrupt import sigint_futures, wait_or_interrupt

    def main_asleep():
        tid = threading.main_thread().native_id
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            with open(f"/proc/self/task/{tid}/stat") as f:
                if f.read().rpartition(")")[2].split()[0] == "S":
                    return True
            time.sleep(0.01)
        return False

    def kill_here():
        print("main asleep", main_asleep(), flush=True)
        signal.pthread_kill(threading.get_ident(), signal.SIGINT)
        time.sleep(120)  # (a daemon: the process ends before this)

    with sigint_futures() as sigint:
        print("ready", flush=True)
        threading.Thread(target=kill_here, daemon=True).start()
        try:
            wait_or_interrupt([Future()], sigint.first)
        except KeyboardInterrupt:
            print("interrupted at the wait's return", flush=True)
"""


def _child(script: str) -> Proc:
    proc = Proc([sys.executable, "-c", textwrap.dedent(script)])
    proc.wait_line(lambda s: s == "ready", timeout=60)
    return proc


@pytest.mark.parametrize("attempt", range(3))
def test_ctrl_c_among_thousands_of_waits_ends_the_pool(attempt: int) -> None:
    proc = _child(MANY_WAITS)
    try:
        proc.p.send_signal(signal.SIGINT)
        proc.wait_line(lambda s: s.startswith("interrupted after"), timeout=60)
        assert proc.p.wait(timeout=60) == 0
    finally:
        proc.stop()


def test_the_second_ctrl_c_is_counted_and_a_third_interrupts_at_once() -> None:
    proc = _child(THRICE)
    try:
        proc.p.send_signal(signal.SIGINT)
        proc.wait_line(lambda s: s == "first at the wait's return", timeout=60)
        proc.p.send_signal(signal.SIGINT)
        proc.wait_line(lambda s: s == f"second: {int(signal.SIGINT)}", timeout=60)
        proc.wait_line(lambda s: s == "waiting again", timeout=60)
        proc.p.send_signal(signal.SIGINT)
        proc.wait_line(lambda s: s == "third at once", timeout=60)
        proc.wait_line(lambda s: s.startswith("restored"), timeout=60)
        assert proc.p.wait(timeout=60) == 0
        assert "restored True" in proc.lines
    finally:
        proc.stop()


def test_a_sigint_landing_on_another_thread_wakes_the_wait() -> None:
    proc = _child(ELSEWHERE)
    try:
        proc.wait_line(lambda s: s == "interrupted at the wait's return", timeout=60)
        assert proc.p.wait(timeout=60) == 0
        assert "main asleep True" in proc.lines
    finally:
        proc.stop()


def test_outside_the_main_thread_nothing_is_installed() -> None:
    before = signal.getsignal(signal.SIGINT)
    seen: list[object] = []

    def in_a_thread() -> None:
        with sigint_futures() as sigint:
            seen.extend([sigint.first.done(), signal.getsignal(signal.SIGINT)])

    t = threading.Thread(target=in_a_thread)
    t.start()
    t.join(timeout=60)
    assert seen == [False, before]


def test_where_sigint_is_ignored_it_stays_ignored() -> None:
    before = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        with sigint_futures() as sigint:
            assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
            assert not sigint.first.done()
    finally:
        signal.signal(signal.SIGINT, before)


def _wakeup_fd() -> int:
    fd = signal.set_wakeup_fd(-1)
    signal.set_wakeup_fd(fd)
    return fd


def test_in_the_main_thread_the_handler_and_the_wakeup_fd_are_put_back() -> None:
    before, fd_before = signal.getsignal(signal.SIGINT), _wakeup_fd()
    with sigint_futures():
        assert signal.getsignal(signal.SIGINT) is not before
        assert _wakeup_fd() not in (-1, fd_before)
    assert signal.getsignal(signal.SIGINT) is before
    assert _wakeup_fd() == fd_before


def test_a_sigint_whose_handler_has_run_is_in_the_first_once_the_block_has_ended_and_counted_once() -> None:
    """Python's handler has run (``raise_signal`` runs it before it returns): once the block has ended, the first is
    done whether or not the reader had read the wakeup fd's byte inside it (a sweep checking it inside the block
    after its last cell lost such a Ctrl-C: it reads it after the block now, tests/test_sweep_resume.py), and one
    SIGINT is counted once; two are the first and the second."""
    with sigint_futures() as sigint:
        signal.raise_signal(signal.SIGINT)
    assert sigint.first.done() and not sigint.second.done()
    with sigint_futures() as sigint:
        signal.raise_signal(signal.SIGINT)
        signal.raise_signal(signal.SIGINT)
    assert sigint.first.done() and sigint.second.done()


def test_a_sigint_handled_inside_a_waits_hold_on_the_first_still_wakes_that_wait() -> None:
    """``concurrent.futures.wait`` holds each future's lock from its look at which are done to its waiter's install:
    a handler run in the main thread there that completed the first (as one did for an hour of the third wave's
    forty-third session) did so under that (reentrant) lock after the look, before the waiter was on it, and no one
    woke that waiter (the reader's byte found the first done): the wait slept on until another future ended, a
    sweep's Ctrl-C held up by its longest cell. Only the reader completes it inside the block, its completion taking
    the lock once the waiter is on. Here the SIGINT is raised as the wait puts its waiter on a future it installs
    before the first (after its look), and the wait must wake with the first."""
    with sigint_futures() as sigint:
        futures = {sigint.first}
        while (order := list(set(futures)))[0] is sigint.first:  # the wait installs its waiter on each in this order
            futures.add(Future())
        before = order[0]  # (installed on before the first)
        tripped: list[bool] = []

        class Waiters(list):  # the waiter's install on ``before``: a SIGINT, the wait holding the first's lock
            def append(self, waiter: object) -> None:
                super().append(waiter)
                if not tripped and sigint.first._condition._is_owned():
                    tripped.append(True)
                    signal.raise_signal(signal.SIGINT)  # its handler runs before this returns

        before._waiters = Waiters()  # type: ignore[attr-defined]
        done, _ = wait(futures, timeout=10, return_when=FIRST_COMPLETED)
    assert tripped and sigint.first in done, (tripped, done)


# The ``bsst`` console script's own lines (pyproject: bridge.__main__:main), with a hook that sends this process a real
# SIGINT as the CLI's first submodule starts to load: Python raises KeyboardInterrupt inside the import.
DURING_IMPORTS = """
    import os, signal, sys

    class SigintOnImport:
        def find_spec(self, name, path, target=None):
            if name == "bridge.cli.flags":
                os.kill(os.getpid(), signal.SIGINT)
            return None

    sys.meta_path.insert(0, SigintOnImport())
    sys.argv = ["bsst", "--help"]
    from bridge.__main__ import main
    sys.exit(main())
"""


def test_ctrl_c_while_the_cli_imports_is_said_not_traced() -> None:
    proc = Proc([sys.executable, "-c", textwrap.dedent(DURING_IMPORTS)])
    try:
        proc.wait_line(lambda s: s == "bsst: interrupted", timeout=120)
        assert proc.p.wait(timeout=60) == 1
        assert not any("Traceback" in line for line in proc.lines), proc.lines
    finally:
        proc.stop()


# The ``bsst`` console script's own lines, its parser's building (bridge.cli.build_parser: the flags' modules, numpy
# and the missions' imported, about 0.1 s of a command's start) first sending this process a real SIGINT and waiting
# for it to come back as KeyboardInterrupt
WHILE_THE_PARSER_IS_BUILT = """
    import os, signal, sys, time
    import bridge.cli as cli

    building = cli.build_parser
    def stop_then_build():
        os.kill(os.getpid(), signal.SIGINT)
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            time.sleep(0.001)
        return building()

    cli.build_parser = stop_then_build
    sys.argv = ["bsst", "--help"]
    from bridge.__main__ import main
    sys.exit(main())
"""


def test_ctrl_c_while_the_parser_is_built_is_said_not_traced() -> None:
    """A Ctrl-C while the CLI builds its parser (a command's first ~0.1 s after its imports) is said as any other
    before the command runs: ``bsst: interrupted``, exit 1. Before, the parser was built outside the CLI's
    ``try``: a KeyboardInterrupt traceback (python -m bridge: exit 130), seen in 12 of 40 random SIGINTs in the
    first 0.45 s of a ``bsst sim`` of a 1 s sine."""
    proc = Proc([sys.executable, "-c", textwrap.dedent(WHILE_THE_PARSER_IS_BUILT)])
    try:
        assert proc.p.wait(timeout=120) == 1
        proc.stop()  # (ended: reads what is left)
        assert proc.lines == ["bsst: interrupted"], proc.lines
    finally:
        proc.stop()


# imported by ``site`` at start-up (sitecustomize, on PYTHONPATH): the CLI's parser is built only after a real SIGINT
# that lands in code run from a string by exec, as a dataclass's generated __init__ is while a command imports
IN_GENERATED_CODE = """
    import bridge.cli as cli

    building = cli.build_parser
    def stop_in_generated_code():
        exec("import os, signal, time\\nos.kill(os.getpid(), signal.SIGINT)\\ndeadline = time.monotonic() + 60\\n"
             "while time.monotonic() < deadline:\\n    time.sleep(0.001)\\n")
        return building()

    cli.build_parser = stop_in_generated_code
"""


def test_python_m_bridge_interrupted_in_generated_code_exits_as_bsst_does(tmp_path) -> None:
    """``python -m bridge --help`` whose Ctrl-C lands in code run by ``exec`` (a dataclass's ``__init__``): it says
    ``bsst: interrupted`` and exits 1, as the ``bsst`` script does. Before, CPython's ``-m`` kept that caught
    KeyboardInterrupt in mind and killed the process by SIGINT at its exit (-2 here, 130 in a shell): 4 of 30 random
    Ctrl-Cs in a ``python -m bridge sim``'s first 0.45 s."""
    (tmp_path / "sitecustomize.py").write_text(textwrap.dedent(IN_GENERATED_CODE))
    path = os.pathsep.join(p for p in (str(tmp_path), os.environ.get("PYTHONPATH")) if p)
    p = subprocess.run([sys.executable, "-m", "bridge", "--help"], env={**os.environ, "PYTHONPATH": path},
                       capture_output=True, text=True, timeout=120, start_new_session=True)
    assert (p.returncode, p.stderr, p.stdout) == (1, "bsst: interrupted\n", ""), (p.returncode, p.stderr)


# ``bsst sim`` whose summary printing first sends this process a real SIGINT: a Ctrl-C once the run is on disk
# (of a 2 s sine: how long it flew before does not matter; missions/sine.toml's 30 s cost 1.0 CPU-s, this 0.26)
SUMMARY_SIGINT = """
    import os, signal, sys
    import bridge.cli.runreport as runreport

    printing = runreport.print_summary
    def sigint_then_print(*args, **kwargs):
        os.kill(os.getpid(), signal.SIGINT)
        return printing(*args, **kwargs)

    runreport.print_summary = sigint_then_print
    sys.argv = ["bsst", "sim", sys.argv[2], "--no-plots", "--out", sys.argv[1]]
    from bridge.__main__ import main
    sys.exit(main())
"""


def test_ctrl_c_while_the_summary_is_printed_changes_nothing(tmp_path) -> None:
    """``bsst sim`` sent SIGINT as its summary starts to print (the run on disk): it ends as the run did (0), its
    summary whole, no traceback. Before, such a signal (sent by hand as the ``outcome:`` line came out, 12 times)
    killed it 6 times, gave a traceback 4 times, and let it exit 0 twice."""
    mission = tmp_path / "sine2.toml"
    mission.write_text('name = "sine2"\nduration_s = 2.0\n[trajectory]\nkind = "sine"\n')
    proc = Proc([sys.executable, "-c", textwrap.dedent(SUMMARY_SIGINT), str(tmp_path / "run"), str(mission)])
    try:
        proc.wait_line(lambda s: s.startswith("run directory:"), timeout=120)
        assert proc.p.wait(timeout=60) == 0, proc.lines
        assert not any("Traceback" in line or "interrupted" in line for line in proc.lines), proc.lines
    finally:
        proc.stop()


# never over before the signal; under auto's 240 s (bridge.core.scalar.AUTO_STEPS), so no run loads numba's compiled
# kernels (~0.6 CPU-s a run, nothing these tests look at)
LONG_SINE = 'name = "sine200"\nduration_s = 200.0\n[trajectory]\nkind = "sine"\n'


@pytest.mark.parametrize("controller", ["bsst", "examples/my_law.py:MyLaw"])  # in this process; in a watched child
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_stop_sent_to_bsst_sim_alone_ends_it_aborted_recorded(tmp_path, sig: signal.Signals, controller: str) -> None:
    """SIGINT or SIGTERM sent to ``bsst sim``'s process alone (``kill -INT PID``, a script's ``send_signal``), as
    its trace grows: the flight ends ``aborted``, summary.json, trace and events written, exit 1, with a law of
    the user's own (flown in a watched child, bridge.nodes.watched) as with a built-in one. Before, SIGINT with a
    user's law was never answered (the parent ignored it, the child never had it), SIGTERM killed the run with no
    summary.json (exit 143 said, or -15 silent)."""
    mission = tmp_path / "sine200.toml"
    mission.write_text(LONG_SINE)
    out = tmp_path / "run"
    proc = Proc.bsst("sim", str(mission), "--no-plots", "--out", str(out), "--controller", controller)
    try:
        wait_for(lambda: csv_rows(out / "trace.csv") >= 250 or proc.p.poll() is not None, 120, "a second flown")
        proc.p.send_signal(sig)
        _assert_aborted_recorded(out, proc)
    finally:
        proc.stop()


SIM_STOPPED = "bsst sim: aborted: ended by user: interrupted (Ctrl-C or SIGTERM)"  # its line on stderr


# ``bsst`` started with SIGINT ignored, as a shell without job control starts a script's ``bsst sim ... &``
SIGINT_IGNORED = ("import os, signal, sys; signal.signal(signal.SIGINT, signal.SIG_IGN); "
                  "os.execv(sys.executable, [sys.executable, '-m', 'bridge', *sys.argv[1:]])")


def test_a_sigterm_ends_bsst_sim_aborted_recorded_where_sigint_is_ignored(tmp_path) -> None:
    """A script's background ``bsst sim`` (SIGINT ignored, inherited) sent SIGTERM as its trace grows: ``aborted``,
    recorded, exit 1, and a SIGINT sent before it still ignored. Until the third wave's forty-first session the
    SIGTERM, taken as a Ctrl-C by raising SIGINT, met SIGINT's SIG_IGN: the 300 s sine flew to its end, ``completed``,
    exit 0 (8.9 s after the SIGTERM, measured)."""
    mission = tmp_path / "sine200.toml"
    mission.write_text(LONG_SINE)
    out = tmp_path / "run"
    proc = Proc([sys.executable, "-c", SIGINT_IGNORED, "sim", str(mission), "--no-plots", "--out", str(out)])
    try:
        wait_for(lambda: csv_rows(out / "trace.csv") >= 250 or proc.p.poll() is not None, 120, "a second flown")
        proc.p.send_signal(signal.SIGINT)  # ignored: the flight flies on
        rows = csv_rows(out / "trace.csv")
        wait_for(lambda: csv_rows(out / "trace.csv") >= rows + 250 or proc.p.poll() is not None, 120,
                 "a second more flown after the SIGINT")
        assert proc.p.poll() is None, proc.lines[-5:]
        proc.p.send_signal(signal.SIGTERM)
        _assert_aborted_recorded(out, proc, rows + 250)
    finally:
        proc.stop()


# ``bsst sim`` whose loop (bridge.loop.fly) has its steps' ``next`` wrapped: after the 300th step has yielded, a real
# stop is sent to the bsst process (this one; a watched flight's parent), and the wrapper waits for the stop to come
# back as KeyboardInterrupt (passed on to a watched child): it is raised in fly's own frame, between two steps, as
# Python raises a signal that lands as a step ends
BETWEEN_STEPS = """
    import os, signal, sys, time
    import bridge.loop as loop

    top, sig, steps = os.getpid(), signal.Signals[sys.argv[3]], [0]
    def next_then_stop(flight):
        step = next(flight)
        steps[0] += 1
        if steps[0] == 300:
            os.kill(top, sig)
            deadline = time.monotonic() + 60
            while time.monotonic() < deadline:
                time.sleep(0.001)
        return step

    loop.next = next_then_stop
    sys.argv = ["bsst", "sim", sys.argv[2], "--no-plots", "--out", sys.argv[1], "--controller", sys.argv[4]]
    from bridge.__main__ import main
    sys.exit(main())
"""


@pytest.mark.parametrize("controller", ["bsst", "examples/my_law.py:MyLaw"])  # in this process; in a watched child
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_stop_landing_between_two_steps_ends_the_flight_aborted_recorded(tmp_path, sig: signal.Signals,
                                                                           controller: str) -> None:
    """A stop whose KeyboardInterrupt is raised between two steps of the flight (in bridge.loop.fly, as a step has
    yielded): the flight ends ``aborted`` at that step, recorded, exit 1. Before, it escaped the flight: ``bsst:
    interrupted``, exit 1, no summary.json; with a watched law, the test above failed so once in a quiet make
    test (SIGTERM, six workers on two cores)."""
    mission = tmp_path / "sine200.toml"
    mission.write_text(LONG_SINE)
    out = tmp_path / "run"
    proc = Proc([sys.executable, "-c", textwrap.dedent(BETWEEN_STEPS), str(out), str(mission), sig.name, controller])
    try:
        _assert_aborted_recorded(out, proc, rows=300)
        assert json.loads((out / "summary.json").read_text())["duration_s"] == pytest.approx(300 / 250)
    finally:
        proc.stop()


# ``bsst sim`` with a watched law whose run_watched is entered only after a real stop has been sent to this process:
# the stop lands once the mission is loaded, as the command turns to starting the flight's child
BEFORE_THE_FORK = """
    import os, signal, sys
    import bridge.nodes.watched as watched

    forking, sig = watched.run_watched, signal.Signals[sys.argv[3]]
    def stop_then_fork(*args, **kwargs):
        os.kill(os.getpid(), sig)
        return forking(*args, **kwargs)

    watched.run_watched = stop_then_fork
    sys.argv = ["bsst", "sim", sys.argv[2], "--no-plots", "--out", sys.argv[1], "--controller",
                "examples/my_law.py:MyLaw"]
    from bridge.__main__ import main
    sys.exit(main())
"""


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_stop_before_a_watched_flight_starts_is_said(tmp_path, sig: signal.Signals) -> None:
    """A stop sent to ``bsst sim`` as it starts a watched flight's child: said (``bsst: interrupted``, exit 1, no
    traceback), nothing flown. Before, the command ignored SIGINT from just before it (SIGTERM became that SIGINT)
    until the child was watched: the stop was lost, and the long mission flew on (here: to its end, exit 0, or past
    the 60 s wait)."""
    mission = tmp_path / "sine200.toml"
    mission.write_text(LONG_SINE)
    out = tmp_path / "run"
    proc = Proc([sys.executable, "-c", textwrap.dedent(BEFORE_THE_FORK), str(out), str(mission), sig.name])
    try:
        assert proc.p.wait(timeout=60) == 1
        proc.stop()  # (ended: reads what is left)
        assert proc.lines == ["bsst: interrupted"], "\n".join(proc.lines)
        assert not out.exists()
    finally:
        proc.stop()


# ``bsst sim`` whose flight, once its last step is flown, is judged (bridge.loop.summarise) only after a real stop has
# been sent to the bsst process (this one; a watched flight's parent) and held (the held handler's note, seen in it)
WHILE_JUDGED = """
    import os, signal, sys, time
    import bridge.loop as loop

    top, sig, judging = os.getpid(), signal.Signals[sys.argv[3]], loop.summarise
    def held():  # (the handler is bridge.core.interrupt.Held.on_sigint, of the Held that notes it)
        return getattr(getattr(signal.getsignal(signal.SIGINT), "__self__", None), "pending", False)

    def stop_then_summarise(*args, **kwargs):
        os.kill(top, sig)
        deadline = time.monotonic() + 60
        while not held() and time.monotonic() < deadline:
            time.sleep(0.001)
        return judging(*args, **kwargs)

    loop.summarise = stop_then_summarise
    sys.argv = ["bsst", "sim", sys.argv[2], "--no-plots", "--out", sys.argv[1], "--controller", sys.argv[4]]
    from bridge.__main__ import main
    sys.exit(main())
"""


@pytest.mark.parametrize("end", ["land", "hold"])
@pytest.mark.parametrize("controller", ["bsst", "examples/my_law.py:MyLaw"])  # in this process; in a watched child
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_stop_while_the_flight_is_judged_never_cuts_its_record(tmp_path, sig: signal.Signals, controller: str,
                                                                end: str) -> None:
    """A stop once the flight's last step is flown, while it is judged: held, never cutting the record. With an end
    landing to fly, the landing takes it (``aborted``, recorded, exit 1); with none (``[end] action = "hold"``) the
    record is written whole as the flight ended (``completed``), then the command says ``bsst: interrupted``, exit
    1. Before, either way it escaped: ``bsst: interrupted``, no summary.json (a real signal at a random moment of a
    1 s sine's run did so 63 times in 1135)."""
    mission = tmp_path / "sine2.toml"
    mission.write_text(f'name = "sine2"\nduration_s = 2.0\n[trajectory]\nkind = "sine"\n[end]\naction = "{end}"\n')
    out = tmp_path / "run"
    proc = Proc([sys.executable, "-c", textwrap.dedent(WHILE_JUDGED), str(out), str(mission), sig.name, controller])
    try:
        if end == "land":
            _assert_aborted_recorded(out, proc, rows=500)
            return
        assert proc.p.wait(timeout=60) == 1
        proc.stop()  # (ended: reads what is left)
        assert proc.lines == ["bsst: interrupted"], proc.lines
        assert json.loads((out / "summary.json").read_text())["outcome"] == "completed"
        assert csv_rows(out / "trace.csv") == 500
    finally:
        proc.stop()


FLEET_JUDGED = """
    import os, signal, sys, time
    import bridge.loop as loop

    top, nth, judging, calls = os.getpid(), int(sys.argv[3]), loop.summarise, []
    def held():  # (the handler is bridge.core.interrupt.Held.on_sigint, of the Held that notes it)
        return getattr(getattr(signal.getsignal(signal.SIGINT), "__self__", None), "pending", False)

    def stop_then_summarise(*args, **kwargs):  # the nth flight judged meets the stop
        calls.append(1)
        if len(calls) == nth:
            os.kill(top, signal.SIGINT)
            deadline = time.monotonic() + 60
            while not held() and time.monotonic() < deadline:
                time.sleep(0.001)
        return judging(*args, **kwargs)

    loop.summarise = stop_then_summarise
    sys.argv = ["bsst", "sim", sys.argv[2], "--no-plots", "--out", sys.argv[1]]
    from bridge.__main__ import main
    sys.exit(main())
"""


@pytest.mark.parametrize("nth", [1, 2], ids=["first-judged", "last-judged"])
def test_a_stop_while_a_fleets_flight_is_judged_keeps_the_fleets_record(tmp_path, nth: int) -> None:
    """Two vehicles, ``[end] action = "hold"``, a stop as one of them is judged (held: its record written whole,
    then raised). The first judged: the other, not yet, takes the stop (``aborted``), the fleet's summary.json says
    so, exit 1. The last judged (the other ``completed``): the fleet's record is written whole, both ``completed``,
    then ``bsst: interrupted``, exit 1. Until the forty-first session's review the fleet threw the stop again into
    the flight that had raised it, took it for one not started, and lost its summary.json either way."""
    mission = tmp_path / "pair.toml"
    mission.write_text('name = "pair"\nduration_s = 2.0\n[trajectory]\nkind = "sine"\n[end]\naction = "hold"\n'
                       '[[vehicles]]\nid = 1\n[[vehicles]]\nid = 2\noffset = [0.0, 2.0, 0.0]\n')
    out = tmp_path / "run"
    proc = Proc([sys.executable, "-c", textwrap.dedent(FLEET_JUDGED), str(out), str(mission), str(nth)])
    try:
        assert proc.p.wait(timeout=120) == 1
        proc.stop()  # (ended: reads what is left)
        assert not any("Traceback" in s for s in proc.lines), proc.lines
        summary = json.loads((out / "summary.json").read_text())
        outcomes = sorted(v["outcome"] for v in summary["vehicles"])
        if nth == 1:
            assert summary["outcome"] == "aborted" and outcomes == ["aborted", "completed"], summary["vehicles"]
            assert "bsst: interrupted" not in proc.lines, proc.lines
        else:
            assert summary["outcome"] == "completed" and outcomes == ["completed", "completed"], summary["vehicles"]
            assert proc.lines[-1] == "bsst: interrupted", proc.lines
        for v in (1, 2):
            assert json.loads((out / f"vehicle-{v}" / "summary.json").read_text())["outcome"] in outcomes
            assert csv_rows(out / f"vehicle-{v}" / "trace.csv") == 500
    finally:
        proc.stop()


def test_a_held_blocks_release_gives_sigint_back_to_its_previous_handler_and_holds_it_again_after() -> None:
    """:meth:`bridge.core.interrupt.Held.released`, around each control period's ``yield`` of a flight's end landing
    (swapped with signal's C half since the forty-fourth session, 18 -> 3 us a period): inside, SIGINT's handler is the
    one before the block and a SIGINT raises KeyboardInterrupt; a SIGINT that came before it is held (``pending``),
    never raised; after it the held handler is back; after the block, the one before it."""
    before = signal.getsignal(signal.SIGINT)
    with sigint_held() as held:
        mine = signal.getsignal(signal.SIGINT)
        assert mine != before and not held.pending
        with pytest.raises(KeyboardInterrupt), held.released():
            assert signal.getsignal(signal.SIGINT) is before
            signal.raise_signal(signal.SIGINT)
            pytest.fail("SIGINT inside the release did not raise")  # (never reached)
        assert signal.getsignal(signal.SIGINT) == mine and not held.pending
        signal.raise_signal(signal.SIGINT)  # held: noted, not raised, here or in the release that follows
        with held.released():
            assert held.pending and signal.getsignal(signal.SIGINT) is before
        assert signal.getsignal(signal.SIGINT) == mine
    assert signal.getsignal(signal.SIGINT) is before


def test_a_held_blocks_release_gives_back_a_default_or_python_handler_too() -> None:
    """:meth:`Held.released` swaps with signal's C half, which refuses the enum ``signal.SIG_DFL`` that
    ``signal.getsignal`` gives: a Python caller whose SIGINT handler was the default one had every offline flight
    end in a TypeError at its end landing (from the forty-fourth session's swap until its review). A default handler
    and a Python function are each given back inside the release and held again after it."""
    before = signal.getsignal(signal.SIGINT)
    try:
        for previous in (signal.SIG_DFL, lambda signum, frame: None):
            signal.signal(signal.SIGINT, previous)
            with sigint_held() as held:
                mine = signal.getsignal(signal.SIGINT)
                with held.released():
                    assert signal.getsignal(signal.SIGINT) == previous
                assert signal.getsignal(signal.SIGINT) == mine
            assert signal.getsignal(signal.SIGINT) == previous
    finally:
        signal.signal(signal.SIGINT, before)


def test_an_offline_flight_of_a_caller_with_the_default_sigint_handler_completes(tmp_path: Path) -> None:
    """A script that set ``signal.SIG_DFL`` for SIGINT flies :func:`bridge.simulate` to its end (its end landing
    releases the held stop each control period: the swap refused the enum and the flight died with no summary)."""
    before = signal.getsignal(signal.SIGINT)
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    try:
        run = simulate(Mission(Sine(), duration_s=0.5), out=tmp_path / "run", plots=False)
    finally:
        signal.signal(signal.SIGINT, before)
    assert run.outcome == "completed"
    assert (tmp_path / "run" / "summary.json").is_file()


def test_a_stop_carries_its_flights_run_only_when_held_until_it_was_recorded() -> None:
    """The one reading of a stop a fleet's flight raised (bridge.loop.recorded_run), said twice in
    bridge.swarm._fly_together until the third wave's forty-second session: a stop held as the flight was judged
    carries its run (recorded whole), a plain one none (nothing recorded). The fleet's stops: the test above."""
    run = Run({}, {"outcome": "completed"}, None)
    assert recorded_run(StopAfterRecord(run)) is run and recorded_run(KeyboardInterrupt()) is None


def test_a_ctrl_c_to_the_group_is_one_stop_for_a_watched_flight(tmp_path) -> None:
    """A terminal's Ctrl-C (SIGINT to the process group) reaches ``bsst sim`` and its watched child both: the parent
    passes it on, and the child takes the two as one stop, its record whole (a second KeyboardInterrupt, raised
    while the first was recorded, would cut it)."""
    mission = tmp_path / "sine200.toml"
    mission.write_text(LONG_SINE)
    out = tmp_path / "run"
    proc = Proc.bsst("sim", str(mission), "--no-plots", "--out", str(out), "--controller", "examples/my_law.py:MyLaw")
    try:
        wait_for(lambda: csv_rows(out / "trace.csv") >= 250 or proc.p.poll() is not None, 120, "a second flown")
        os.killpg(proc.p.pid, signal.SIGINT)
        _assert_aborted_recorded(out, proc)
    finally:
        proc.stop()


def _assert_aborted_recorded(out: Path, proc: Proc, rows: int = 250) -> None:
    """The run ended ``aborted`` by the user, exit 1, said (in the summary on stdout, and in one line on stderr, as
    every exit-1 reason is: until the third wave's forty-first session on stdout alone) and on disk whole
    (summary.json, the trace of ``rows`` at least, the event)."""
    assert proc.p.wait(timeout=60) == 1
    proc.stop()  # (ended: reads what is left)
    assert "outcome: aborted" in proc.lines and "ended by user: interrupted (Ctrl-C or SIGTERM)" in proc.lines, \
        proc.lines
    assert not any("Traceback" in s for s in proc.lines), proc.lines
    assert [s for s in proc.lines if s.startswith("bsst")] == [SIM_STOPPED], proc.lines  # (stderr's own prefix)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["outcome"] == "aborted" and summary["ended_by"]["who"] == "user", summary["ended_by"]
    assert csv_rows(out / "trace.csv") >= rows
    assert "aborted: interrupted" in (out / "events.log").read_text()
