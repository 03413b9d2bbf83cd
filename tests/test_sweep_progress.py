"""Covers bridge.sweep.progress: a sweep's ETA counts flying time, not the start-up its first cells carry.

The first sweep after an install (a cold numba cache) said ``sweep: 1/32 cells, 0 failed, ETA 2568 s`` with
nothing left to fly: the rate was the time since the sweep began over the cells done, the ~24 s of compiling the
batch engine's kernels included. The estimate is fed times here; no clock is read.
"""

from __future__ import annotations

import io
import re

import pytest

from bridge.sweep.progress import Progress, eta_s


def test_the_first_round_carries_the_start_up_and_gives_no_estimate() -> None:
    # one batch chunk of 32 cells (lanes 32), its rows handed over together after a cold compile: no estimate
    # until the last, which has nothing left (the old rate said 2568 s at the first row)
    assert [eta_s(32 - ran, ran, 32, 0.001 * ran) for ran in (1, 2, 16, 31)] == [None] * 4
    assert eta_s(0, 32, 32, 0.05) == 0.0


def test_the_process_engine_is_timed_from_its_first_row_in_rounds_of_its_workers() -> None:
    # 2 workers, 16 cells of 0.6 s each, whatever the start-up before the first row (60 s of compiling, or none)
    assert eta_s(14, 2, 2, 0.0) is None  # each worker's first cell: the start-up's
    assert eta_s(13, 3, 2, 0.6) == pytest.approx(0.6 * 13 / 2)  # 13 cells, 2 at a time, 0.6 s a round
    assert eta_s(12, 4, 2, 0.6) == pytest.approx(0.6 * 12 / 2)
    assert eta_s(11, 5, 2, 1.2) == pytest.approx(0.6 * 11 / 2)


def test_a_batch_chunks_rows_count_their_chunk_whole() -> None:
    # 1000 cells in chunks of 250 flying 10 s each: a chunk's first row says its chunk is flown
    assert eta_s(749, 251, 250, 10.0) == pytest.approx(10.0 * 749 / 250)  # three chunks' worth, not 749 x 10 s
    assert eta_s(500, 500, 250, 10.0) == pytest.approx(20.0)
    assert eta_s(249, 751, 250, 30.0) == pytest.approx(10.0 * 249 / 250)  # (the fourth chunk, 30 s after the first)


def test_the_progress_lines_say_when_an_estimate_will_come() -> None:
    out = io.StringIO()
    bar = Progress(5, 0, stream=out, lanes=2)
    for _ in range(5):
        bar.update({"outcome": "completed"})
    lines = out.getvalue().splitlines()
    assert lines[:2] == [f"sweep: {n}/5 cells, 0 failed, ETA after the first 2 cells" for n in (1, 2)], lines
    assert all(re.fullmatch(rf"sweep: {n}/5 cells, 0 failed, ETA \d+ s", line)
               for n, line in zip((3, 4, 5), lines[2:], strict=True)), lines
    assert lines[-1] == "sweep: 5/5 cells, 0 failed, ETA 0 s"
    out = io.StringIO()
    bar = Progress(6, 3, stream=out, lanes=250)  # a resume with 3 cells to fly: one round of 3, not of 250
    bar.update({"outcome": "error"})
    assert out.getvalue() == "sweep: 4/6 cells, 1 failed, ETA after the first 3 cells\n"
