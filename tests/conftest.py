"""Shared test fixtures."""

from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
MISSIONS = ROOT / "missions"


@pytest.fixture
def missions_dir() -> Path:
    return MISSIONS
