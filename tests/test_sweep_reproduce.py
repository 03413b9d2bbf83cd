"""Covers bridge.sweep.report: the command ``report.md`` prints under "Reproducing a row" flies that row again.

A new user's ``bsst sweep missions/sine.toml --wind 5,10 --turbulence moderate,light`` got ``bsst sim mission.toml
--controller bsst --rate 250 --seed 0`` there: a flight in still air (RMS 3e-9 m) for a row of 5 m/s and moderate
turbulence (0.081 m), and ``--vehicles 2,4``'s first row, a fleet of two, was said to be the mission alone. The
command names every swept axis now: the wind with the mission's direction (``--wind S`` alone blows from the north),
the turbulence, and a fleet's size in the sweep's formation; run in the sweep's directory, as the report says, it
gives the row's RMS to the last bit.
"""

from __future__ import annotations

import csv
import json
import shlex
from pathlib import Path

import pytest

from tests.sitlkit import run_bsst

pytestmark = pytest.mark.process  # bsst sweep and bsst sim as the user runs them

BRIEF_WINDY = """name = "brief"
duration_s = 2.0

[trajectory]
kind = "sine"

[wind]
speed_mps = 1.0
from_deg = 270.0
"""


def test_the_reports_command_flies_a_windy_fleets_first_row_again(tmp_path: Path) -> None:
    (tmp_path / "brief.toml").write_text(BRIEF_WINDY)
    sweep = run_bsst("sweep", "brief.toml", "--wind", "3", "--turbulence", "moderate", "--vehicles", "2",
                     "--jobs", "1", "--no-plots", "--out", "sw", cwd=tmp_path, timeout=240)
    assert sweep.returncode == 0, sweep.stderr
    with (tmp_path / "sw" / "cells.csv").open() as f:
        row = next(csv.DictReader(f))
    report = (tmp_path / "sw" / "report.md").read_text()
    command = report.split("```sh\n", 1)[1].split("\n", 1)[0]
    assert command == ("bsst sim mission.toml --controller bsst --rate 250 --wind 3:270 --turbulence moderate "
                       "--vehicles 2 --formation line:2 --seed 0"), command
    again = run_bsst(*shlex.split(command)[1:], "--no-plots", "--out", str(tmp_path / "again"), cwd=tmp_path / "sw",
                     timeout=240)
    assert again.returncode == 0, again.stderr
    summary = json.loads((tmp_path / "again" / "summary.json").read_text())
    assert repr(summary["rms_3d"]) == row["rms"] and len(summary["vehicles"]) == 2, (summary["rms_3d"], row)


def test_the_reports_command_says_every_number_exactly_and_flies_the_row_to_the_last_bit(tmp_path: Path) -> None:
    """A mission's wind from 123.4567891 deg and a swept delay of 12.3456789 ms: the command says both as given (``:g``
    said ``--wind 3:123.457 --delay 12.3457``, another flight: its RMS not the row's), and flies the row again."""
    (tmp_path / "brief.toml").write_text(BRIEF_WINDY.replace("270.0", "123.4567891"))
    sweep = run_bsst("sweep", "brief.toml", "--wind", "3", "--delay", "12.3456789", "--jobs", "1", "--no-plots",
                     "--out", "sw", cwd=tmp_path, timeout=240)
    assert sweep.returncode == 0, sweep.stderr
    with (tmp_path / "sw" / "cells.csv").open() as f:
        row = next(csv.DictReader(f))
    report = (tmp_path / "sw" / "report.md").read_text()
    command = report.split("```sh\n", 1)[1].split("\n", 1)[0]
    assert "--delay 12.3456789 " in command and "--wind 3:123.4567891 " in command, command
    again = run_bsst(*shlex.split(command)[1:], "--no-plots", "--out", str(tmp_path / "again"), cwd=tmp_path / "sw",
                     timeout=240)
    assert again.returncode == 0, again.stderr
    summary = json.loads((tmp_path / "again" / "summary.json").read_text())
    assert repr(summary["rms_3d"]) == row["rms"], (summary["rms_3d"], row)
