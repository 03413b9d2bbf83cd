"""Covers bridge.sweep.executors and bridge.batch.

``bsst sweep --engine batch | process | auto``: the same cells.csv rows from either engine,
``--resume`` with the batch, and an engine that cannot be honoured refused in one line.

The cell-by-cell agreement of the batch with the scalar loop over every link feature is
tests/test_batch.py's; here the sweep's own path is checked end to end: grid -> engine ->
rows -> cells.csv, with real subprocesses for the command line.
"""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import pytest

from bridge.sweep import CELLS_CSV, Grid, read_cells, sweep
from bridge.sweep.executors import BATCH_MIN_CELLS, engine_for
from bridge.sweep.grid import cells
from bridge.sweep.margin import margin, parse_until
from missions import Mission, Sine
from params import ConfigError

pytestmark = pytest.mark.process  # starts processes or opens sockets: not in make test-fast

ROOT = Path(__file__).resolve().parents[1]
SHORT = Mission(Sine(), duration_s=4.0, name="short")
MIXED = Grid(controller=("bsst", "pid", "smc"), delay_ms=(0.0, 8.0), loss_pct=(0.0, 20.0), seeds=2)


def _same(a: dict, b: dict) -> None:
    assert a["outcome"] == b["outcome"] and a["class"] == b["class"], (a, b)
    for k in ("up_sent", "up_lost", "down_sent", "down_lost", "seed", "controller", "delay_ms", "loss_pct"):
        assert a[k] == b[k], (k, a, b)
    if a["rms"] is None:
        assert b["rms"] is None
        return
    tol = 1e-2 if a["controller"] == "smc" else 1e-6  # smc: a switching law (tests/test_batch.py says why)
    assert math.isclose(a["rms"], b["rms"], rel_tol=tol), (a, b)


def test_a_mixed_grid_gives_the_same_rows_with_either_engine(tmp_path: Path) -> None:
    batch = sweep(SHORT, MIXED, engine="batch", out=tmp_path / "b", report=False)
    process = sweep(SHORT, MIXED, engine="process", jobs=2, out=tmp_path / "p", report=False)
    assert len(batch) == len(process) == 24
    for a, b in zip(batch, process, strict=True):
        _same(a, b)
    on_disk = read_cells(tmp_path / "b" / CELLS_CSV)
    assert [r["rms"] for r in on_disk] == [r["rms"] for r in batch]
    assert (tmp_path / "b" / CELLS_CSV).read_text().splitlines()[0] == \
        (tmp_path / "p" / CELLS_CSV).read_text().splitlines()[0]


def test_resume_with_the_batch_engine_flies_only_the_missing_cells(tmp_path: Path) -> None:
    out = tmp_path / "s"
    first = sweep(SHORT, MIXED, engine="batch", out=out, report=False)
    lines = (out / CELLS_CSV).read_text().splitlines()
    (out / CELLS_CSV).write_text("\n".join(lines[:-5]) + "\n")  # five cells lost, as after a kill
    again = sweep(SHORT, MIXED, engine="batch", out=out, resume=True, report=False)
    assert [r["rms"] for r in again] == [r["rms"] for r in first]


def test_auto_takes_the_batch_for_a_large_offline_grid_and_says_why_not_otherwise() -> None:
    big = Grid(delay_ms=tuple(float(d) for d in range(BATCH_MIN_CELLS)))
    assert engine_for(SHORT, cells(SHORT, big), "offline", "auto")[0] == "batch"
    small = cells(SHORT, Grid(delay_ms=(0.0, 5.0)))
    assert engine_for(SHORT, small, "offline", "auto") == ("process", f"fewer than {BATCH_MIN_CELLS} cells to fly")
    used, why = engine_for(SHORT, cells(SHORT, big), "lockstep", "auto")
    assert used == "process" and "lockstep" in why
    with pytest.raises(ConfigError, match="--engine batch: lockstep"):
        engine_for(SHORT, small, "lockstep", "batch")


@pytest.mark.parametrize("extra, names", [
    (["--lockstep"], "lockstep"),
    (["--controller", "examples/my_law.py:MyLaw"], "--engine batch"),
    (["--bandwidth", "5000"], "--engine batch"),
    (["--sensors", "mocap", "--estimator", "ekf"], "--engine batch: [estimator] kind = 'ekf'"),
    (["--sensors", "mocap", "--estimator", "truth,raw"], "--engine batch: [estimator] kind = 'raw'"),
])
def test_an_engine_that_cannot_be_honoured_is_refused_in_one_line(tmp_path: Path, extra: list[str],
                                                                   names: str) -> None:
    r = subprocess.run([sys.executable, "-m", "bridge", "sweep", "missions/sine.toml", "--delay", "0,5",
                        "--engine", "batch", "--out", str(tmp_path / "s"), *extra],
                       cwd=ROOT, capture_output=True, text=True, timeout=120)
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1 and names in lines[0], r.stderr
    assert not (tmp_path / "s").exists()


def test_the_command_line_says_which_engine_flew(tmp_path: Path) -> None:
    r = subprocess.run([sys.executable, "-m", "bridge", "sweep", "missions/sine.toml", "--delay", "0,5",
                        "--out", str(tmp_path / "s"), "--no-plots"], cwd=ROOT, capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0, r.stderr
    assert f"engine process (fewer than {BATCH_MIN_CELLS} cells to fly)" in r.stdout


def test_cells_with_sensors_fly_on_the_process_engine_and_say_so() -> None:
    """The batch has no sensors or estimator: under ``auto`` a grid with them goes to the process engine,
    whatever its size, and the reason names the estimator; ``truth`` cells (the mission's own kind, no
    override) still go to the batch."""
    mocap = SHORT.with_overrides(sensors={"set": "mocap"})
    delays = tuple(float(d) for d in range(BATCH_MIN_CELLS))
    for grid in (Grid(estimator=("truth", "ekf")), Grid(estimator=("truth", "raw"), delay_ms=delays)):
        used, why = engine_for(mocap, cells(mocap, grid), "offline", "auto")
        assert used == "process" and why.startswith("the batch engine cannot fly this grid: [estimator] kind"), why
    truth = cells(mocap, Grid(estimator=("truth",), delay_ms=delays))
    assert all(c.estimator == "truth" and not c.sensing for c in truth)
    assert engine_for(mocap, truth, "offline", "auto") == ("batch", "the grid allows it")


def test_jobs_changes_no_row_of_a_batch_sweep_or_margin(tmp_path: Path) -> None:
    """``--jobs N``: the batch engine's threads (bridge.batch.engine) fly blocks of cells in whatever order
    they come free; ``bsst sweep --engine batch`` writes the same cells.csv, byte for byte, with 1 and 2,
    and ``bsst margin`` finds the same margin from the same cells."""
    short = tmp_path / "short.toml"
    short.write_text((ROOT / "missions" / "sine.toml").read_text().replace("duration_s = 30.0", "duration_s = 3.0"))
    outs = {}
    for jobs in (1, 2):
        r = subprocess.run([sys.executable, "-m", "bridge", "sweep", str(short),
                            "--delay", "0,6,12", "--loss", "0,20", "--controller", "bsst,pid", "--seeds", "3",
                            "--engine", "batch", "--jobs", str(jobs), "--out", str(tmp_path / f"s{jobs}"),
                            "--no-plots"], cwd=ROOT, capture_output=True, text=True, timeout=300)
        assert r.returncode == 0, r.stderr
        assert "engine batch" in r.stdout, r.stdout
        outs[jobs] = (tmp_path / f"s{jobs}" / CELLS_CSV).read_text()
    assert len(outs[1].splitlines()) == 1 + 36
    assert outs[1] == outs[2]
    found = [margin(SHORT, "delay_ms", parse_until("rms=0.01"), controllers=("bsst", "pid"), seeds=2, resolution=4.0,
                    jobs=jobs, engine="batch") for jobs in (1, 2)]
    assert found[0] == found[1] and found[0]["cells_flown"] > 4
