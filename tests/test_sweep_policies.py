"""Covers bridge.sweep and bridge.batch: the safety policies of every cell (bridge.record.policies) in a sweep.

Each process-engine row's ``policies`` column says ``ok`` or names the policies its run broke (``geofence``: the
1 s sine leaves a 0.2 m GF_MAX_HOR_DIST at t = 0.80 s, and holds there: GF_ACTION 2); ``bsst sweep`` says so on
stderr and report.md lists the cells. The batch engine keeps no trace to judge by: its rows say ``""`` (not
judged), and it refuses a mission with a geofence, so ``--engine batch`` stops and ``auto`` flies it by the
process engine, saying why.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from bridge.cli import main
from bridge.sweep import CELLS_CSV, Grid, read_cells, sweep
from missions import MISSION_DIR
from params import ConfigError

pytestmark = [pytest.mark.process, pytest.mark.usefixtures("batch_kernels")]  # a sweep's worker pool


def fenced_sine(tmp_path: Path, limit_m: float | None) -> Path:
    """The sine flown for 1 s (0.33 m from home at most), under GF_MAX_HOR_DIST = ``limit_m`` (None: none)."""
    text = (MISSION_DIR / "sine.toml").read_text().replace("duration_s = 30.0", "duration_s = 1.0")
    f = tmp_path / f"fenced-{limit_m}.toml"
    f.write_text(text + (f"\n[params]\nGF_MAX_HOR_DIST = {limit_m}\n" if limit_m is not None else ""))
    return f


def test_a_cell_that_leaves_its_geofence_says_so_in_its_row_on_stderr_and_in_the_report(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "fenced"
    assert main(["sweep", str(fenced_sine(tmp_path, 0.2)), "--delay", "0,10", "--jobs", "1", "--no-plots",
                 "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert "2 of 2 cells broke a safety policy" in err and ": geofence" in err, err
    rows = read_cells(out / CELLS_CSV)
    assert [(r["delay_ms"], r["outcome"], r["policies"]) for r in rows] == [(0.0, "failsafe", "geofence"),
                                                                             (10.0, "failsafe", "geofence")]
    report = (out / "report.md").read_text()  # (GF_ACTION 2, PX4's default: each held where it left: failsafe)
    assert "0 runs kept every policy, 2 broke one, 0 not judged" in report
    assert report.count("| failsafe | geofence |") == 2
    wide = tmp_path / "wide"  # 5 m: the same flights keep it
    assert main(["sweep", str(fenced_sine(tmp_path, 5.0)), "--delay", "0,10", "--jobs", "1", "--no-plots",
                 "--out", str(wide)]) == 0
    assert "safety policy" not in capsys.readouterr().err
    assert {r["policies"] for r in read_cells(wide / CELLS_CSV)} == {"ok"}
    assert "2 runs kept every policy, 0 broke one, 0 not judged" in (wide / "report.md").read_text()


def test_the_batch_engine_judges_no_policy_and_refuses_a_geofence(tmp_path: Path,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    rows = sweep(fenced_sine(tmp_path, None), Grid(delay_ms=(0.0, 10.0)), engine="batch", report=False)
    assert {r["policies"] for r in rows} == {""}  # not judged, never "ok"
    fenced = fenced_sine(tmp_path, 0.2)
    with pytest.raises(ConfigError, match="geofence .*GF_MAX_HOR_DIST.*read as flown; fly it with --engine process$"):
        sweep(fenced, Grid(delay_ms=(0.0, 10.0)), engine="batch", report=False)
    delays = ",".join(str(d) for d in range(40))  # enough cells for auto to want the batch
    assert main(["sweep", str(fenced), "--delay", delays, "--no-plots", "--out", str(tmp_path / "auto")]) == 0
    out = capsys.readouterr().out
    assert "engine process (the batch engine cannot fly this grid: a geofence" in out, out
    assert {r["policies"] for r in read_cells(tmp_path / "auto" / CELLS_CSV)} == {"geofence"}


def test_a_margin_probe_that_breaks_a_policy_does_not_hold() -> None:
    """``bsst margin``'s criterion (bridge.sweep.margin.Until): a probe that completed within the RMS but broke a
    policy fails; one that kept them (``ok``) or was not judged (``""``: the batch engine) holds by its figures."""
    from bridge.sweep.classes import Classes
    from bridge.sweep.margin import Until

    row = {"outcome": "completed", "rms": 1e-4, "ripple_u2": 1.0}  # clean by its figures
    for until in (Until(rms=0.1), Until(cls="degraded")):
        assert until.failed({**row, "policies": "geofence"}, Classes())
        assert not until.failed({**row, "policies": "ok"}, Classes())
        assert not until.failed({**row, "policies": ""}, Classes())
