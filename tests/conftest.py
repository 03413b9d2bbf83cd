"""Shared test fixtures."""

from __future__ import annotations

import fcntl
from pathlib import Path

import pytest

from bridge.autopilot.estimator import compile_estimator
from bridge.batch import compile_batch

ROOT = Path(__file__).resolve().parent.parent
MISSIONS = ROOT / "missions"
KERNELS = {"ekf": lambda: compile_estimator("ekf"), "batch": compile_batch}


@pytest.fixture
def missions_dir() -> Path:
    return MISSIONS


@pytest.fixture(scope="session", autouse=True)
def _kernels_compiled(tmp_path_factory: pytest.TempPathFactory, worker_id: str) -> None:
    """Compile numba's kernels (the EKF's, the batch engine's), or load them from their on-disk cache,
    once per test process before any test: as ``bsst sitl`` does before it starts a vehicle, so that a
    test that starts a subprocess (a vehicle, ``bsst sweep``) does not have it compile them (~12 s each
    on a fresh clone) inside its start-up time. On a fresh clone the two workers compile one set each,
    at once (gw1 the batch engine's first), under a lock per set: the other then loads it from the cache."""
    order = ["batch", "ekf"] if worker_id == "gw1" else ["ekf", "batch"]
    shared = tmp_path_factory.getbasetemp().parent  # the same directory for every worker of a session
    for kind in order:
        with open(shared / f"compile-{kind}.lock", "w") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            KERNELS[kind]()
