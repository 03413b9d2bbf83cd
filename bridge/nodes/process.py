"""Plumbing shared by the session launcher and its two child processes.

In:  reports (:mod:`bridge.nodes.report`) or status lines to write, SIGTERM / SIGINT, the death of the parent;
     a child's return code
Out: one line on stdout per report, flushed at once; ``stop()`` called on a stop signal; SIGTERM to a
     child whose parent died; how a child ended, in words (:func:`exit_text`)

- Children report on stdout, one JSON line each, flushed at once (:func:`report_printer`; the
  kinds and their fields are :mod:`bridge.nodes.report`'s). The launcher reads them live
  (:func:`bridge.nodes.report.parse_line`) and waits on them with deadlines.
- SIGTERM and SIGINT ask a node to stop at its next look; it then closes its files whole.
- A child dies with its parent (``PR_SET_PDEATHSIG``), so a launcher killed with SIGKILL
  leaves no vehicle running on its port.
"""

from __future__ import annotations

import ctypes
import os
import signal
from collections.abc import Callable
from typing import Any

from bridge.nodes.report import Report, to_line

_PR_SET_TIMERSLACK = 29  # prctl(2): the thread's timer slack, ns
_PR_SET_PDEATHSIG = 1


def status_printer(prefix: str = "") -> Callable[[str], None]:
    """A status sink: one line on stdout per call, written at once (no buffering)."""
    def emit(line: str) -> None:
        try:
            os.write(1, f"{prefix}{line}\n".encode())
        except OSError:  # the reader is gone: keep flying, the files still say everything
            pass

    return emit


def report_printer() -> Callable[[Report], None]:
    """A report sink: each report as one JSON line on stdout, written at once."""
    emit = status_printer()
    return lambda report: emit(to_line(report))


def on_stop_signals(stop: Callable[[], None]) -> None:
    """SIGTERM and SIGINT call ``stop()`` (which must only set a flag)."""
    def handler(signum: int, frame: Any) -> None:
        stop()

    signal.signal(signal.SIGTERM, handler)
    signal.signal(signal.SIGINT, handler)


def tight_timer_slack() -> None:
    """Let this process's timed waits (``select``) wake within 1 us of their deadline, not Linux's default
    50 us late: a real-time node then sleeps until just before its tick instead of polling for it (Linux;
    a no-op elsewhere)."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_TIMERSLACK, 1000, 0, 0, 0)
    except (OSError, AttributeError):
        pass


def die_with_parent() -> None:
    """``preexec_fn`` for a child: SIGTERM when the parent dies (Linux; a no-op elsewhere)."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0)
    except (OSError, AttributeError):
        pass



def exit_text(returncode: int | None) -> str:
    """How a child process ended, from its return code as ``Popen.returncode`` and ``Process.exitcode`` give it
    (negative: the signal that killed it): ``killed by SIGKILL``, ``exited with status 3``; ``still running``
    for None."""
    if returncode is None:
        return "still running"
    if returncode < 0:
        try:
            return f"killed by {signal.Signals(-returncode).name}"
        except ValueError:
            return f"killed by signal {-returncode}"
    return f"exited with status {returncode}"
