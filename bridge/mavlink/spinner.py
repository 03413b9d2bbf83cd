"""Polling for a peer's answer before sleeping, while no runnable task waits for a core.

In:  an endpoint (anything with ``poll() -> list``) whose peer's answer is due, a window (s), a deadline
     (``time.monotonic``); the machine's runnable tasks (``/proc/loadavg``)
Out: the messages the poll got within the window, or [] (the caller, :func:`bridge.mavlink.endpoint.wait`,
     then sleeps in ``select``); ``Spinner.skipped``, the waits that did not poll because the machine was busy
"""

from __future__ import annotations

import os
import time
from typing import Any

SPIN_LOOK_S = 0.01  # s of wall time between two looks at how many tasks the machine has runnable
CORES = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def runnable_tasks() -> int | None:
    """The tasks (processes and threads) runnable on the machine right now, this one included: the fourth
    field of ``/proc/loadavg`` (Linux), None where it cannot be read."""
    try:
        with open("/proc/loadavg", "rb") as f:
            return int(f.read().split()[3].split(b"/")[0])
    except (OSError, ValueError, IndexError):
        return None


class Spinner:
    """Polling one endpoint (the peer's answer is due on it) before :func:`~bridge.mavlink.endpoint.wait`
    sleeps, for at most ``window_s`` (s), while no runnable task waits for a core.

    On a machine with idle cores a lockstep answer comes within the window and is taken without a sleep and a
    wake-up (which cost more CPU and time than the poll on loopback). On a busy one the poll takes a core that
    other work, often the very peer it waits for, needs: the scheduler shares a core fairly between every
    runnable task, and a spinning one is always runnable. So every :data:`SPIN_LOOK_S` of wall time the spinner
    looks how many tasks are runnable (:func:`runnable_tasks`, itself among them); while they are more than
    the cores this process may use (:data:`CORES`), some runnable task waits for a core: it does not poll,
    and :func:`wait` sleeps at once (``skipped`` counts those waits). So a lockstep pair polls while it has
    the cores it needs, and sleeps on an oversubscribed machine (docs/sitl.md, "Waiting for the other side")."""

    __slots__ = ("endpoint", "window_s", "skipped", "_busy", "_next_look")

    def __init__(self, endpoint: Any, window_s: float) -> None:
        self.endpoint = endpoint
        self.window_s = window_s
        self.skipped = 0
        self._busy = False
        self._next_look = -1.0

    def spin(self, deadline: float) -> list[tuple[Any, tuple[str, int]]]:
        """The endpoint's messages if any came within the window (and before ``deadline``, ``time.monotonic``);
        [] when none did, the window is 0 or the machine is busy (the caller then sleeps)."""
        if self.window_s <= 0.0:
            return []
        mono = time.monotonic
        now = mono()
        if now >= self._next_look:
            self._next_look = now + SPIN_LOOK_S
            runnable = runnable_tasks()
            self._busy = runnable is not None and runnable > CORES
        if self._busy:
            self.skipped += 1
            return []
        end = min(now + self.window_s, deadline)
        poll = self.endpoint.poll
        while True:
            got = poll()
            if got:
                return got
            if mono() >= end:
                return []
            # let any other runnable task on this core go first: on a busy machine the peer we are waiting for
            # may be that task; on an idle one this returns at once
            os.sched_yield()
