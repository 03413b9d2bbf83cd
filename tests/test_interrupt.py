"""Covers bridge.core.interrupt: Ctrl-C while the main thread waits on a pool's futures.

Each case is a real Python child sent a real SIGINT: the interrupt must come out as KeyboardInterrupt at
the wait's return, never inside concurrent.futures' locks (where it left `bsst sweep` hanging), and a second
Ctrl-C must interrupt at once.
"""

from __future__ import annotations

import signal
import sys
import textwrap
import threading

import pytest

from bridge.core.interrupt import interrupt_future
from tests.sitlkit import Proc

pytestmark = pytest.mark.process

# A pool of one thread finishing thousands of short tasks: the main thread spends most of its time taking
# the futures' locks inside wait(), where a KeyboardInterrupt raised by Python's own handler would leave some
# held, and the pool's shutdown then waits for ever on its thread.
MANY_WAITS = """
    from concurrent.futures import ThreadPoolExecutor
    from bridge.core.interrupt import interrupt_future, wait_or_interrupt

    def tick(i):
        return i

    try:
        with interrupt_future() as interrupted, ThreadPoolExecutor(1) as pool:
            pending = {pool.submit(tick, i) for i in range(2000)}
            print("ready", flush=True)
            rounds = 0
            while True:
                rounds += 1
                done = wait_or_interrupt(pending, interrupted)
                pending -= done
                pending |= {pool.submit(tick, i) for i in range(len(done))}
    except KeyboardInterrupt:
        print("interrupted after", rounds, "waits", flush=True)
"""

TWICE = """
    import signal, threading
    from concurrent.futures import Future
    from bridge.core.interrupt import interrupt_future, wait_or_interrupt

    with interrupt_future() as interrupted:
        print("ready", flush=True)
        try:
            wait_or_interrupt([Future()], interrupted)
        except KeyboardInterrupt:
            print("first at the wait's return", flush=True)
        try:
            print("waiting again", flush=True)
            threading.Event().wait(120)  # a second Ctrl-C: the previous handler, at once
            print("second never came", flush=True)
        except KeyboardInterrupt:
            print("second at once", flush=True)
    print("restored", signal.getsignal(signal.SIGINT) is signal.default_int_handler, flush=True)
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


def test_a_second_ctrl_c_interrupts_at_once_and_the_handler_comes_back() -> None:
    proc = _child(TWICE)
    try:
        proc.p.send_signal(signal.SIGINT)
        proc.wait_line(lambda s: s == "first at the wait's return", timeout=60)
        proc.wait_line(lambda s: s == "waiting again", timeout=60)
        proc.p.send_signal(signal.SIGINT)
        proc.wait_line(lambda s: s == "second at once", timeout=60)
        proc.wait_line(lambda s: s.startswith("restored"), timeout=60)
        assert proc.p.wait(timeout=60) == 0
        assert "restored True" in proc.lines
    finally:
        proc.stop()


def test_outside_the_main_thread_nothing_is_installed() -> None:
    before = signal.getsignal(signal.SIGINT)
    seen: list[object] = []

    def in_a_thread() -> None:
        with interrupt_future() as interrupted:
            seen.extend([interrupted.done(), signal.getsignal(signal.SIGINT)])

    t = threading.Thread(target=in_a_thread)
    t.start()
    t.join(timeout=60)
    assert seen == [False, before]


def test_where_sigint_is_ignored_it_stays_ignored() -> None:
    before = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        with interrupt_future() as interrupted:
            assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
            assert not interrupted.done()
    finally:
        signal.signal(signal.SIGINT, before)


def test_in_the_main_thread_the_handler_is_put_back() -> None:
    before = signal.getsignal(signal.SIGINT)
    with interrupt_future():
        assert signal.getsignal(signal.SIGINT) is not before
    assert signal.getsignal(signal.SIGINT) is before
