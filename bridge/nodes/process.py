"""Plumbing shared by the session launcher and its two child processes.

In:  status lines to report, SIGTERM / SIGINT, the death of the parent; a status line read back
Out: one line on stdout per status, flushed at once; ``stop()`` called on a stop signal; SIGTERM to a
     child whose parent died; a status line split into its first word and the rest

- Children report on stdout, one line each, flushed at once: ``ready ...``,
  ``event t=<s> <kind>: <text>``, ``statustext ...``, ``warning ...`` (the controller's
  refusals, :meth:`bridge.mavlink.receive.Rejections.report`), ``stats {json}``, ``done outcome=...``.
  The launcher reads them live (:func:`parse_status`) and waits on them with deadlines.
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

_PR_SET_PDEATHSIG = 1


def status_printer(prefix: str = "") -> Callable[[str], None]:
    """A status sink: one line on stdout per call, written at once (no buffering)."""
    def emit(line: str) -> None:
        try:
            os.write(1, f"{prefix}{line}\n".encode())
        except OSError:  # the reader is gone: keep flying, the files still say everything
            pass

    return emit


def on_stop_signals(stop: Callable[[], None]) -> None:
    """SIGTERM and SIGINT call ``stop()`` (which must only set a flag)."""
    def handler(signum: int, frame: Any) -> None:
        stop()

    signal.signal(signal.SIGTERM, handler)
    signal.signal(signal.SIGINT, handler)


def die_with_parent() -> None:
    """``preexec_fn`` for a child: SIGTERM when the parent dies (Linux; a no-op elsewhere)."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0)
    except (OSError, AttributeError):
        pass


def parse_status(line: str) -> tuple[str, str]:
    """``"event t=1.000 armed: ..."`` -> ``("event", "t=1.000 armed: ...")``."""
    word, _, rest = line.strip().partition(" ")
    return word, rest
