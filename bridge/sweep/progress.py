"""A sweep's progress: cells done of the total, the failures, and how long the rest will take.

In:  each finished cell's row (its ``outcome``) as it comes; how many cells fly at once (``lanes``: the process
     engine's workers, the batch engine's chunk, times a Dask cluster's threads)
Out: a tqdm bar on a terminal, plain lines on stderr otherwise (``sweep: 12/48 cells, 0 failed, ETA 3 s``; a test
     waits on them); :func:`eta_s`, the estimate those lines give, in s

The first cell of each lane carries the start-up (the worker pool, the kernels loaded or, on a cold numba cache,
compiled: ~24 s for the batch engine's), which is no flying time: a 32-cell batch sweep on a cold cache said
``ETA 2568 s`` with nothing left to fly. So the estimate counts from the first row on, in rounds of ``lanes`` cells,
and says none (``ETA after the first N cells``) until the first round is in.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Mapping
from typing import Any

from bridge.sweep.cells import FAILED


def eta_s(left: int, ran: int, lanes: int, since_first_s: float) -> float | None:
    """Seconds until the ``left`` cells are flown, after ``ran`` rows of this run, ``since_first_s`` s after the first
    came, ``lanes`` cells flying at once; None while the first round (``lanes`` rows, each with its start-up) is not in.
    The time since the first row is over the rounds finished since; a row past a round's end counts its round whole
    (the batch engine hands a chunk's rows over together, the first of them when the chunk is flown)."""
    if left <= 0:
        return 0.0
    if ran <= lanes:
        return None
    rounds = -(-(ran - lanes) // lanes)
    return since_first_s / rounds * left / lanes


class Progress:
    """Cells done / total, ETA and failures: a tqdm bar on a terminal, plain lines otherwise (about 20 per sweep,
    and at most one a second besides), their ETA :func:`eta_s`'s."""

    def __init__(self, total: int, done: int, stream: Any = None, enabled: bool = True, lanes: int = 1) -> None:
        self.total, self.done, self.failed, self.ran = total, done, 0, 0
        self.lanes = max(1, min(lanes, total - done))  # (a grid smaller than a round: one round)
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = enabled
        self._bar = None
        self._first: float | None = None  # when this run's first row came
        self._last = 0.0
        self._every = max(1, (total - done) // 20)
        if enabled and getattr(self.stream, "isatty", lambda: False)():
            from tqdm import tqdm  # lazy: only on a terminal

            self._bar = tqdm(total=total, initial=done, unit="cell", desc="sweep", file=self.stream,
                             dynamic_ncols=True, postfix={"failed": 0})

    def update(self, row: Mapping[str, Any]) -> None:
        self.done += 1
        self.ran += 1
        if row["outcome"] in FAILED:  # (as the sweep's summary counts them)
            self.failed += 1
        if self._bar is not None:
            self._bar.set_postfix(failed=self.failed, refresh=False)
            self._bar.update(1)
            return
        now = time.monotonic()
        if self._first is None:
            self._first = now
        if self.enabled and (self.ran % self._every == 0 or now - self._last >= 1.0 or self.done == self.total):
            self._last = now
            eta = eta_s(self.total - self.done, self.ran, self.lanes, now - self._first)
            said = f"ETA after the first {self.lanes} cells" if eta is None else f"ETA {eta:.0f} s"
            self.stream.write(f"sweep: {self.done}/{self.total} cells, {self.failed} failed, {said}\n")
            self.stream.flush()

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()
