"""Shared test fixtures."""

from __future__ import annotations

from pathlib import Path

import pytest

from bridge.core.estimator import compile_estimator

ROOT = Path(__file__).resolve().parent.parent
MISSIONS = ROOT / "missions"


@pytest.fixture
def missions_dir() -> Path:
    return MISSIONS


@pytest.fixture(scope="session", autouse=True)
def _ekf_kernels_compiled() -> None:
    """Compile the EKF's numba kernels (or load them from their on-disk cache) once per test process,
    before any test: as ``bsst sitl`` does before it starts a vehicle, so that a test that starts a
    vehicle subprocess itself does not have that vehicle compile them (~13 s) inside its start-up time."""
    compile_estimator("ekf")
