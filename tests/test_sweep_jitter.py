"""Covers bridge.sweep, bridge.batch and bridge.cli: a jitter the delay capped, said in sweep and margin results.

The link draws its jitter within ±min(delay, jitter) (docs/links.md): a cell of ``--delay 0 --jitter 10`` flies no
jitter and one of ``--delay 5 --jitter 10`` ±5 ms. A single run says so (``summary.json["link"]["jitter_capped"]``);
a sweep's row said only ``jitter_ms`` 10, the jitter asked for. Now its ``jitter_capped`` column says what each
capped direction flew, by either engine, ``report.md`` lists those cells and ``bsst sweep`` says how many on stderr;
``bsst margin``'s ``margin.json`` cells say it too, and it warns.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from bridge.cli import main
from bridge.sweep import CELLS_CSV, read_cells
from missions import MISSION_DIR

# a sweep's worker pool (not in make test-fast); flies the batch engine (its kernels loaded first)
pytestmark = [pytest.mark.process, pytest.mark.usefixtures("batch_kernels")]


@pytest.mark.parametrize("engine", ["process", "batch"])
def test_a_sweeps_capped_jitter_is_in_its_rows_its_report_and_on_stderr(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], engine: str) -> None:
    mission = tmp_path / "short.toml"
    mission.write_text((MISSION_DIR / "sine.toml").read_text().replace("duration_s = 30.0", "duration_s = 1.0"))
    out = tmp_path / engine
    assert main(["sweep", str(mission), "--delay", "0,5,20", "--jitter", "10", "--engine", engine, "--jobs", "1",
                 "--no-plots", "--out", str(out)]) == 0  # flown as documented: the exit status stays 0
    rows = read_cells(out / CELLS_CSV)
    assert [(r["delay_ms"], r["jitter_ms"], r["jitter_capped"]) for r in rows] == [
        (0.0, 10.0, "up:0 down:0"), (5.0, 10.0, "up:5 down:5"), (20.0, 10.0, "")]
    report = (out / "report.md").read_text()
    assert "## Jitter capped at the delay" in report and "2 runs flew less jitter" in report
    assert "| 5 | 10 |" in report and "| up:5 down:5 |" in report, report
    err = capsys.readouterr().err
    assert ("bsst sweep: 2 of 3 cells flew a jitter capped at the delay (cells.csv's jitter_capped column, "
            "report.md's Jitter capped at the delay; docs/links.md); the first: delay 0 ms, jitter 10 ms: "
            "up:0 down:0") in err, err



def test_a_margin_over_the_jitter_says_its_probes_flew_it_capped(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``bsst margin --over jitter_ms --delay 2``: every probe above 2 ms flies ±2 ms, so a jitter margin there is
    the delay's: ``margin.json``'s cells say what each flew, stderr warns (it claimed 60000 ms, unsaid), and a margin
    claimed at a capped value was not flown as probed: said, exit 1."""
    mission = tmp_path / "short.toml"
    mission.write_text((MISSION_DIR / "sine.toml").read_text().replace("duration_s = 30.0", "duration_s = 1.0"))
    assert main(["margin", str(mission), "--over", "jitter_ms", "--until", "rms=2", "--delay", "2", "--resolution",
                 "20000", "--check-below", "0", "--out", str(tmp_path / "m")]) == 1
    cells = json.loads((tmp_path / "m" / "margin.json").read_text())["controllers"][0]["cells"]
    assert cells and all(c["jitter_capped"] == ("up:2 down:2" if c["jitter_ms"] > 2 else "") for c in cells), cells
    err = capsys.readouterr().err
    assert f"bsst margin: warning: {len(cells)} of {len(cells)} cells flew a jitter capped at the delay" in err, err
    assert ("bsst margin: bsst's margin 60000 over jitter_ms was flown with its jitter capped at the delay "
            "(up:2 down:2): not the value claimed") in err, err
