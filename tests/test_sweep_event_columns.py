"""Covers bridge.sweep.grid and bridge.sweep.margin: an axis a sweep does not sweep is written as the cell flew it.

From its first step: a t = 0 ``[[events]]`` wind or link event's value in place of the mission's ``[wind]`` and
``[link]`` (mission_value, cells); ``bsst margin``'s "the mission already sets it" still reads those tables alone.

Until the forty-fifth session, ``bsst sweep`` over a mission with ``[wind] speed_mps = 5`` and a t = 0 wind event of
1 m/s wrote ``wind_mps`` 5 in every row of cells.csv (and report.md's fixed values), of cells that flew 1 m/s; a t = 0
link handover's delay and loss likewise.
"""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Any

import pytest

from bridge.cli import main
from bridge.sweep.cells import CELLS_CSV
from missions import Mission, Sine
from params import dump_toml

pytestmark = pytest.mark.process

SHORT = Mission(Sine(), duration_s=2.0, name="short")


# -- a t = 0 [[events]] wind or link table: the columns are the event's ------------------------------------------------
def _evented(tmp_path: Path, t_s: float) -> Path:
    """A short mission whose [wind] (5 m/s) and [link] (20 ms) an event at ``t_s`` replaces (1 m/s; 5 ms, loss 2 %)."""
    p = tmp_path / f"evented-{t_s:g}.toml"
    p.write_text(dump_toml({**SHORT.to_dict(), "wind": {"speed_mps": 5.0, "from_deg": 90.0},
                            "link": {"delay_ms": 20.0},
                            "events": [{"t_s": t_s, "kind": "wind", "speed_mps": 1.0, "from_deg": 90.0},
                                       {"t_s": t_s, "kind": "link", "delay_ms": 5.0, "loss_pct": 2.0}]}))
    return p


def test_a_t0_wind_or_link_event_is_the_cells_columns(tmp_path: Path, capsys: Any) -> None:
    """``bsst sweep`` over a mission whose [[events]] set the steady wind and hand the link over at t = 0: every
    cell flew the event's 1 m/s, 5 ms and 2 % from its first step, and cells.csv wrote [wind]'s 5 m/s and [link]'s
    20 ms and 0 % in every row (until the forty-fifth session). An event later than that leaves the mission's own
    flown until it: its columns stay the mission's (docs/campaigns.md)."""
    for t_s, wind, delay, loss in ((0.0, 1.0, 5.0, 2.0), (0.5, 5.0, 20.0, 0.0)):
        out = tmp_path / f"sweep-{t_s:g}"
        assert main(["sweep", str(_evented(tmp_path, t_s)), "--rate", "200,250", "--no-plots", "--out",
                     str(out)]) == 0, capsys.readouterr()
        with (out / CELLS_CSV).open() as f:
            rows = list(csv.DictReader(f))
        assert len(rows) == 2 and not any(r["error"] for r in rows), rows
        assert {(float(r["wind_mps"]), float(r["delay_ms"]), float(r["loss_pct"])) for r in rows} == \
            {(wind, delay, loss)}, rows
        if t_s == 0.0:
            assert "`wind_mps`: 1" in (out / "report.md").read_text()  # the report's fixed values: the same


def test_margins_refusal_still_names_the_event_not_the_table(tmp_path: Path, capsys: Any) -> None:
    """``bsst margin`` reads the same values to refuse a mission whose own [wind] or [link] already sets the searched
    axis: a t = 0 event's wind or link is not the table's, and is refused as the event (every probe would fly it)."""
    m = tmp_path / "only-events.toml"
    m.write_text(dump_toml({**SHORT.to_dict(),
                            "events": [{"t_s": 0.0, "kind": "wind", "speed_mps": 1.0},
                                       {"t_s": 0.0, "kind": "link", "delay_ms": 5.0}]}))
    for over, kind in (("wind_mps", "wind"), ("delay_ms", "link")):
        assert main(["margin", str(m), "--over", over, "--until", "rms=0.1", "--out", str(tmp_path / over)]) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"bsst: margin over {over}: {m}: events (t_s = 0, kind = {kind}) "), err
        assert "already sets" not in err and not (tmp_path / over).exists(), err
