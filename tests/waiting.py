"""The tests' one way to wait for something: poll a predicate until a deadline.

In:  a predicate (no arguments, true once what is awaited has happened), a timeout (s), what is
     awaited (words, for the failure), how often to look (s)
Out: nothing once the predicate holds; an ``AssertionError`` naming what was awaited and the
     timeout when it does not hold in time

No sleep-and-hope: a test waits on the event it needs, polled, and fails saying which event
never came. Waits on a child's output lines are :meth:`tests.sitlkit.Proc.wait_line`
(``select`` on the pipe); waits for a MAVLink message are ``recv_match`` with a timeout.
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Callable
from typing import Any


def wait_for(predicate: Callable[[], object], timeout_s: float, what: str, poll_s: float = 0.01) -> None:
    """Poll ``predicate`` every ``poll_s`` s until it is true, or raise AssertionError naming ``what``
    after ``timeout_s`` s."""
    deadline = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f"{what}: not within {timeout_s} s")
        time.sleep(poll_s)


def sweep_rows(proc: Any, rows: int, timeout_s: float = 60.0) -> None:
    """Wait until a ``bsst sweep`` child (``tests.sitlkit.Bsst``, its stderr a pipe) has said, on its progress
    lines (``sweep: N/M cells ...``), that ``rows`` rows are appended; AssertionError if it ends first or stays
    silent past ``timeout_s``."""
    sweep_said(proc, lambda line: line.startswith("sweep: ") and "/" in line.split()[1]
               and int(line.split()[1].split("/")[0]) >= rows, timeout_s)


def sweep_said(proc: Any, pred: Callable[[str], bool], timeout_s: float = 60.0) -> str:
    """The first line of a ``bsst sweep`` child's stderr (``tests.sitlkit.Bsst``) that satisfies ``pred``, read
    up to it and no further (the rest stays for ``communicate``); AssertionError if the child ends first or no
    such line comes within ``timeout_s``. (A thread reads: a ``select`` on the pipe would not see lines
    already in the file object's buffer.)"""
    found: queue.Queue[str | None] = queue.Queue()

    def read() -> None:
        for line in iter(proc.stderr.readline, ""):
            if pred(line):
                found.put(line)
                return
        found.put(None)

    threading.Thread(target=read, name="sweep-stderr", daemon=True).start()
    try:
        line = found.get(timeout=timeout_s)
    except queue.Empty:
        raise AssertionError(f"no such line from the sweep within {timeout_s} s") from None
    assert line is not None, f"sweep ended first (exit {proc.wait()})"
    return line
