"""Crash safety (issue 7): SIGKILL of the vehicle, the controller or the launcher at a random
moment of a real ``bsst sitl`` session; every file stays readable (benchmarks/crash.py runs
the loop 20 times)."""

from __future__ import annotations

import json
import random
import signal

import pytest

from tests.hostile import CRASH_STEPS, kill_session


@pytest.mark.parametrize("victim", ["vehicle", "controller", "launcher"])
def test_sigkill_at_a_random_moment_leaves_every_file_readable(tmp_path, victim):
    at = random.Random(f"crash-{victim}").randint(1, CRASH_STEPS - 300)
    rc, found = kill_session(tmp_path, victim, at)
    assert found["trace.csv"] >= 0 and found["vehicle.csv"] >= at - 1
    assert found["vehicle.tlog"] > 0 and found["controller.tlog"] > 0
    summary = tmp_path / f"run-{victim}" / "summary.json"
    if victim == "launcher":
        assert rc == -signal.SIGKILL and found["summary"] is None  # killed before it could write one
    else:
        assert rc == 1, found
        s = json.loads(summary.read_text())
        expect = {"vehicle": "aborted", "controller": "failsafe"}[victim]
        assert s["outcome"] == expect and (victim == "controller" or s["sitl"]["died"] == "vehicle")
