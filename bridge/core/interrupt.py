"""Ctrl-C at a safe point: SIGINT as a future that a wait on a pool's futures includes.

In:  SIGINT, while :func:`interrupt_future` is entered in the main thread
Out: a :class:`~concurrent.futures.Future` that completes (its result: the signal number) when SIGINT arrives;
     :func:`wait_or_interrupt`, concurrent.futures' ``wait`` that raises KeyboardInterrupt once it has returned

Why: Python raises KeyboardInterrupt between any two bytecodes of the main thread, so also inside
concurrent.futures' ``wait()`` and ``as_completed()`` while they take the futures' locks one by one
(``_AcquireFutures``, not exception-safe): the locks taken so far stay held, and the pool's shutdown then
waits for ever on a worker (or the pool's manager thread) that needs one. A `bsst sweep --jobs 1` stopped with
Ctrl-C just after a progress line hung 3 times in 40 that way with four busy loops on the two cores (the
manager thread in ``Future.cancel``, the main thread joining it). Here the handler only writes a byte to a
pipe, and a thread completes the future: the waiting code wakes at once and raises where no lock is held.

The first SIGINT puts the previous handler back, so a second Ctrl-C interrupts at once, as before (a user who
will not wait for the cells in flight). Outside the main thread, or where SIGINT is ignored (a sweep's
workers), the future never completes and nothing is installed.
"""

from __future__ import annotations

import os
import signal
import threading
from collections.abc import Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, Future, wait
from contextlib import contextmanager
from typing import Any

_SIGINT = bytes([signal.SIGINT])
_STOP = b"\0"


@contextmanager
def interrupt_future() -> Iterator[Future]:
    """Within the block, SIGINT completes the yielded future instead of raising KeyboardInterrupt."""
    fired: Future = Future()
    previous = signal.getsignal(signal.SIGINT)
    if threading.current_thread() is not threading.main_thread() or previous is signal.SIG_IGN:
        yield fired
        return
    if previous is None:  # installed from C: Python's own is what a second Ctrl-C should meet
        previous = signal.default_int_handler
    read_end, write_end = os.pipe()

    def on_sigint(signum: int, frame: Any) -> None:
        signal.signal(signal.SIGINT, previous)
        os.write(write_end, _SIGINT)

    def watch() -> None:
        if os.read(read_end, 1) == _SIGINT:
            fired.set_result(signal.SIGINT)

    watcher = threading.Thread(target=watch, name="sigint-watch", daemon=True)
    watcher.start()
    signal.signal(signal.SIGINT, on_sigint)
    try:
        yield fired
    finally:
        signal.signal(signal.SIGINT, previous)
        os.write(write_end, _STOP)  # ends the watcher if no SIGINT came
        watcher.join()
        os.close(read_end)
        os.close(write_end)


def wait_or_interrupt(futures: Iterable[Future], interrupted: Future) -> set[Future]:
    """The futures of ``futures`` done once the first of them (or ``interrupted``) is; KeyboardInterrupt
    if ``interrupted`` is done."""
    done, _ = wait([*futures, interrupted], return_when=FIRST_COMPLETED)
    if interrupted.done():
        raise KeyboardInterrupt
    return done


__all__ = ["interrupt_future", "wait_or_interrupt"]
