"""Covers bridge.sweep.classes, bridge.sweep.cells and bridge.cli.campaigns: a cell that flew and crashed is classed
``crashed`` (a result, as a diverged one is), never ``error``, the class of a cell that could not be flown, whose
``error`` column says why; a sweep written before the class (its crash classed ``error``) is resumed."""

from __future__ import annotations

from pathlib import Path

import pytest

from bridge.cli import main
from bridge.sweep.cells import CELLS_CSV, read_cells
from bridge.sweep.classes import CLASSES, Classes, classify
from tests.sitlkit import run_bsst

# starts processes: a sweep's pool (not in make test-fast)
pytestmark = pytest.mark.process

# a step whose 1 s blackout lands as it climbs: at 10 ms of delay it hits the ground at 5 m/s (bsst sim: crashed)
SHORT = """name = "short"
duration_s = 3.0
[trajectory]
kind = "step"
setpoints = [ { t = 0.0, x = 0.5, y = 0.0, z = 1.0, psi = 0.0 } ]
"""


@pytest.mark.parametrize("outcome", ["crashed", "collision", "terminated"])
def test_a_flight_that_ended_on_the_ground_is_crashed_not_error(outcome: str) -> None:
    """Whatever its RMS (a fall's is large): crashed, between diverged and error."""
    for rms in (0.5, 3.2, None):
        assert classify({"outcome": outcome, "rms": rms, "ripple_u2": 0.0}, Classes()) == "crashed"
    assert CLASSES.index("diverged") < CLASSES.index("crashed") < CLASSES.index("error")
    assert classify({"outcome": "law_failed", "rms": None}, Classes()) == "error"


def test_a_crashed_cell_is_classed_crashed_and_said(tmp_path: Path, capsys) -> None:
    """A user's tour: ``bsst sweep short.toml --blackout 1:1 --delay 0,10``; the cell at 10 ms hit the ground
    (``bsst sim`` says ``crashed``, exit 1). Its row said class ``error`` ("the cell could not be flown (see the
    error column)") with an empty error column, and the sweep said nothing of it. Now: class ``crashed``, defined in
    report.md's Classes and counted in its overview, the error column empty (it flew), and a line on stderr; the
    exit status stays 0 (measured, as a diverged cell is: docs/campaigns.md). A resume of the directory as the old
    code left it (the crash classed ``error``) keeps the row, classed as now, and flies nothing."""
    mission = tmp_path / "short.toml"
    mission.write_text(SHORT)
    out = tmp_path / "xs"
    r = run_bsst("sweep", mission, "--blackout", "1:1", "--delay", "0,10", "--jobs", "2", "--no-plots", "--out", out)
    assert r.returncode == 0, (r.stdout, r.stderr)
    rows = read_cells(out / CELLS_CSV)
    assert [(x["delay_ms"], x["outcome"], x["class"], x["error"]) for x in rows] == [
        (0.0, "failsafe", "failsafe", ""), (10.0, "crashed", "crashed", "")], rows
    assert "0 failed" in r.stdout, r.stdout
    assert "bsst sweep: 1 of 2 cells crashed (class crashed" in r.stderr, r.stderr
    assert "the first: delay_ms 10, seed 0: crashed" in r.stderr, r.stderr
    report = (out / "report.md").read_text()
    assert "| crashed | the flight ended on the ground" in report, report
    assert "| failsafe | diverged | crashed | error |" in report and "| 10 | crashed 3.2 |" in report, report

    text = (out / CELLS_CSV).read_text()  # as the old code wrote it
    (out / CELLS_CSV).write_text(text.replace(",crashed,crashed,", ",crashed,error,"))
    (out / "report.md").unlink()
    capsys.readouterr()
    assert main(["sweep", str(mission), "--blackout", "1:1", "--delay", "0,10", "--jobs", "2", "--no-plots",
                 "--out", str(out), "--resume"]) == 0
    assert "2 cells, 0 flown, 2 kept from before" in capsys.readouterr().out
    assert (out / CELLS_CSV).read_text() == text
