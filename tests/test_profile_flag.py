"""Covers bridge.core.flight: a bad ``--profile`` is named as the flag, not as the mission's ``profile`` key.

A new user's ``bsst sim missions/sine.toml --profile nosuch`` was told ``bsst: missions/sine.toml: profile: unknown
profile 'nosuch'``: a key the mission does not have. ``--sensors`` already named itself so.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from bridge.cli import main

ROOT = Path(__file__).resolve().parents[1]


def _line(capsys: pytest.CaptureFixture[str], argv: list[str]) -> str:
    rc = main(argv)
    _, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert rc == 2 and len(lines) == 1, err
    return lines[0]


@pytest.mark.parametrize("given, why", [("nosuch", "unknown profile 'nosuch'"),
                                        ("nowhere.toml", "nowhere.toml: no such file")])
def test_the_flag_is_named(given, why, capsys):
    line = _line(capsys, ["sim", str(ROOT / "missions" / "sine.toml"), "--profile", given, "--no-plots"])
    assert line.startswith(f"bsst: --profile {given}: ") and why in line, line


def test_the_missions_key_is_named(tmp_path, capsys):
    mission = tmp_path / "m.toml"
    mission.write_text('name = "m"\nduration_s = 0.2\nprofile = "nosuch"\n[trajectory]\nkind = "sine"\n')
    line = _line(capsys, ["sim", str(mission), "--no-plots", "--out", str(tmp_path / "run")])
    assert line.startswith(f"bsst: {mission}: profile: unknown profile 'nosuch'"), line
