"""Covers bridge.sweep.campaign, bridge.sweep.inputs and bridge.sweep.report: a resumed sweep is the
uninterrupted one: its engine is the whole grid's (recorded in sweep.json, mixed engines said), the files its
cells read besides mission.toml (a plug-in law's, a trace's) are checked, and an interrupted sweep says it is one
(its summary, report.md, ``bsst report``'s exit status)."""

from __future__ import annotations

import json
import os
import shutil
import signal
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest

from bridge.cli import main
from bridge.sweep.campaign import STOPS_HELD
from bridge.sweep.cells import CELLS_CSV, read_cells
from bridge.sweep.inputs import file_sha256, input_hashes
from missions import Mission, Sine
from params import dump_toml
from tests.sitlkit import ROOT, Bsst, pool_workers, process_state
from tests.waiting import sweep_said, wait_for

# starts processes (not in make test-fast); flies the batch engine (its kernels loaded first)
pytestmark = [pytest.mark.process, pytest.mark.usefixtures("batch_kernels")]

SHORT = Mission(Sine(), duration_s=2.0, name="short")  # the sweeps' counts, lines and files are the point, not a figure
LONGER = replace(SHORT, duration_s=4.0)  # a cell still in flight once the one before it has ended (~0.1 CPU-s)


@pytest.fixture(scope="module")
def mission_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    p = tmp_path_factory.mktemp("mission") / "short.toml"
    p.write_text(dump_toml(SHORT.to_dict()))
    return p


def _cut(whole: Path, to: Path, keep: int) -> None:
    """``to``: the sweep directory ``whole`` as a sweep stopped after ``keep`` rows leaves it (no report.md)."""
    shutil.copytree(whole, to)
    lines = (to / CELLS_CSV).read_text().splitlines(keepends=True)
    (to / CELLS_CSV).write_text("".join(lines[:1 + keep]))
    (to / "report.md").unlink()


def test_a_resume_flies_on_the_whole_grids_engine(mission_file: Path, tmp_path: Path, capsys) -> None:
    """36 cells: the batch engine. Stopped after 26 rows, ``bsst report`` says 26 of 36 (exit 1); the resume flies the
    last 10 on the batch too (not the process engine for fewer than 32 cells), so cells.csv and report.md equal the
    uninterrupted sweep's byte for byte; a resume on the other engine is said to mix them."""
    args = ["sweep", str(mission_file), "--delay", "0,5,10", "--loss", "0,10,20,30", "--seeds", "3", "--no-plots"]
    whole = tmp_path / "whole"
    assert main([*args, "--out", str(whole)]) == 0
    assert "engine batch (the grid allows it)" in capsys.readouterr().out
    assert json.loads((whole / "sweep.json").read_text())["engines"] == ["batch"]
    assert "- engine: `batch` flew every row" in (whole / "report.md").read_text()
    cut = tmp_path / "cut"
    _cut(whole, cut, 26)
    assert main(["report", str(cut), "--no-plots"]) == 1
    err = capsys.readouterr().err
    assert "Traceback" not in err, err
    assert f"26 of 36 cells flown; the sweep was interrupted: `bsst sweep … --resume --out {cut}`" in err, err
    assert "**Incomplete: 26 of 36 cells flown; the sweep was interrupted" in (cut / "report.md").read_text()
    assert main([*args, "--out", str(cut), "--resume"]) == 0
    said = capsys.readouterr().out
    assert "36 cells, 10 flown, 26 kept from before" in said and "engine batch (the grid allows it)" in said, said
    assert (cut / CELLS_CSV).read_bytes() == (whole / CELLS_CSV).read_bytes()
    assert (cut / "report.md").read_text() == (whole / "report.md").read_text()
    assert main(["report", str(cut), "--no-plots"]) == 0
    mixed = tmp_path / "mixed"
    _cut(whole, mixed, 26)
    assert main([*args, "--out", str(mixed), "--resume", "--engine", "process", "--jobs", "2"]) == 0
    said = capsys.readouterr().out
    assert "engine process (asked for); MIXED engines: the rows kept from before flew on batch" in said, said
    assert json.loads((mixed / "sweep.json").read_text())["engines"] == ["batch", "process"]
    assert "- engines: MIXED, rows flown by `batch` and `process`" in (mixed / "report.md").read_text()


def _stopped(proc: Any, stop: str, first: Callable[[], Any], look: Callable[[], Any] | None = None,
             ) -> tuple[Any, str, str]:
    """``first()``'s value once it returns, then ``proc`` stopped as ``stop`` says (``ctrl-c``: SIGINT to its
    group, as a terminal's; ``sigterm``: to it alone) and its stdout and stderr to its end (killed if the test
    fails first). ``look``: called with the process group held still (SIGSTOP) between ``first`` and the stop, so
    that what it sees is where the stop lands (the group goes on after it: SIGCONT); the value is then
    ``(first(), look())``."""
    try:
        value = first()
        if look is not None:
            os.killpg(proc.pid, signal.SIGSTOP)
            wait_for(lambda: process_state(proc.pid) in ("T", "Z", None), 10, "the sweep held still (SIGSTOP)")
            value = (value, look())
        if stop == "ctrl-c":
            os.killpg(proc.pid, signal.SIGINT)
        else:
            os.kill(proc.pid, signal.SIGTERM)
        if look is not None:
            os.killpg(proc.pid, signal.SIGCONT)
        said, told = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    return value, said, told


def _rows_written(out: Path) -> int:
    """The whole rows in ``out``'s cells.csv so far (a torn last line is not one; the header is not)."""
    try:
        return max(0, (out / CELLS_CSV).read_bytes().count(b"\n") - 1)
    except FileNotFoundError:
        return 0


GRID = ["--delay", "0,5,10", "--loss", "0,20", "--seeds", "2", "--no-plots"]


@pytest.fixture(scope="module")
def whole(mission_file: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The cells.csv of GRID's sweep flown uninterrupted (``--jobs 2``): what a stopped and resumed one must equal."""
    out = tmp_path_factory.mktemp("whole") / "whole"
    assert main(["sweep", str(mission_file), *GRID, "--jobs", "2", "--out", str(out)]) == 0
    return out / CELLS_CSV


@pytest.mark.parametrize("stop", ["ctrl-c", "sigterm"])
def test_the_cells_in_flight_at_a_ctrl_c_are_kept_and_the_resume_flies_the_rest(mission_file: Path, whole: Path,
                                                                                 tmp_path: Path, capsys,
                                                                                 stop: str) -> None:
    """``--jobs 2``, stopped once cells.csv has its first row: the cells then in flight (both workers', and those
    already handed to them) end first, as the sweep says, and are kept. Until the third wave's thirty-seventh session
    they flew to their end and were dropped: in no row, and flown again by the resume. The summary says ``N of 12
    cells flown (interrupted)`` and counts what was not flown, exit 1; ``bsst report`` on the directory says the sweep
    is incomplete and exits 1. A SIGTERM to the sweep's process alone (a scheduler's) is a Ctrl-C: it died at once,
    silent (-15). The resume flies exactly the cells not flown, and its cells.csv is the uninterrupted sweep's."""
    args = ["sweep", str(mission_file), *GRID]
    out = tmp_path / "stopped"
    proc = Bsst(*args, "--jobs", "2", "--out", str(out))

    def first_row() -> int:
        wait_for(lambda: _rows_written(out) >= 1, 60, "cells.csv's first row")
        return _rows_written(out)

    seen, said, told = _stopped(proc, stop, first_row)
    kept = len(read_cells(out / CELLS_CSV))
    assert proc.returncode == 1, (said, told)
    assert "sweep: interrupted; the cells in flight end first" in told, told
    assert seen + 2 <= kept < 12, (seen, kept, told)  # (the second worker's cell, and the one queued for the first)
    assert f"sweep short: {kept} of 12 cells flown (interrupted): {kept} this run, 0 kept from before" in said, said
    assert f"bsst: interrupted: {12 - kept} of 12 cells not flown; continue with --resume --out {out}" in told, told
    capsys.readouterr()
    assert main(["report", str(out), "--no-plots"]) == 1
    assert f"{kept} of 12 cells flown; the sweep was interrupted" in capsys.readouterr().err
    assert main([*args, "--jobs", "2", "--out", str(out), "--resume"]) == 0
    assert f"12 cells, {12 - kept} flown, {kept} kept from before" in capsys.readouterr().out
    assert (out / CELLS_CSV).read_bytes() == whole.read_bytes()


def test_a_ctrl_c_after_the_last_cell_was_handed_out_leaves_a_whole_sweep(tmp_path: Path) -> None:
    """Three cells on two workers, Ctrl-C at the first row: the other two are already in flight (the third handed
    out as the first ended), fly to their end and are kept, so nothing is missing: the sweep is whole, its
    report.md written, exit 0, and no "cells not flown" line. Until the third wave's thirty-seventh session it was
    still called interrupted (exit 1, no report.md until a --resume that flew nothing)."""
    out = tmp_path / "whole"
    mission = tmp_path / "longer.toml"
    mission.write_text(dump_toml(LONGER.to_dict()))
    proc = Bsst("sweep", str(mission), "--delay", "0,5,10", "--engine", "process", "--jobs", "2", "--no-plots",
                "--out", str(out))
    (_, ended), said, told = _stopped(proc, "ctrl-c", lambda: wait_for(lambda: _rows_written(out) >= 1, 60,
                                                                        "cells.csv's first row"),
                                      look=lambda: (out / "report.md").is_file())
    # said ("sweep: interrupted; the cells in flight end first") when it came while cells flew, and at the end that
    # they flew to their end; one that came once all three had flown (a loaded machine's late signal: a make test)
    # is held while the record is written, and said so (the next test); one that came once report.md was written
    # may have come after the result was final (ignored there): the sweep whole each way
    if "sweep: interrupted; the cells in flight end first" in told:
        assert f"bsst sweep: interrupted {STOPS_HELD['flying']}; nothing is missing: the sweep is whole" in told, told
    elif not ended:
        assert "3/3 cells" in told and f"bsst sweep: interrupted {STOPS_HELD['writing']}; " in told, told
    assert proc.returncode == 0 and "cells not flown" not in told and "bsst: interrupted" not in told, (said, told)
    assert len(read_cells(out / CELLS_CSV)) == 3 and (out / "report.md").is_file(), said


def _engines_recorded(out: Path) -> bool:
    """Whether ``out``'s sweep.json records an engine: the sweep does so once its cells are over, before it rewrites
    cells.csv and writes report.md (an atomic write: never a torn file)."""
    try:
        return bool(json.loads((out / "sweep.json").read_text()).get("engines"))
    except FileNotFoundError:
        return False


@pytest.mark.parametrize("event", ["all rows", "engines recorded"])
def test_a_ctrl_c_once_every_cell_has_flown_leaves_a_whole_sweep(tmp_path: Path, event: str) -> None:
    """Three cells on one worker, heat maps drawn, Ctrl-C once cells.csv has all three rows (the pool shutting down,
    or the report being written) or once sweep.json records the engine (the report being written): the sweep is
    whole, its report.md and heat map written, exit 0, no "bsst: interrupted" line, and stderr says when the stop
    came and that it stopped nothing (until the third wave's forty-third session one held in the writing was said
    by nobody: the old code failed here at both, 2 runs in 2). Until the third wave's forty-second
    session a Ctrl-C in the writing escaped: ``bsst: interrupted``, exit 1, no report.md (a user's tour, an 8-cell
    sine sweep stopped 2.2 and 2.4 s in; the old code failed here 4 times in 4 at sweep.json's engine, and passed at
    all rows, that stop landing in the pool's shutdown, where the executor's wait took it)."""
    out = tmp_path / "whole"
    mission = tmp_path / "short.toml"
    mission.write_text(dump_toml(SHORT.to_dict()))
    proc = Bsst("sweep", str(mission), "--delay", "0,5,10", "--engine", "process", "--jobs", "1", "--out", str(out))
    seen = (lambda: _rows_written(out) >= 3) if event == "all rows" else (lambda: _engines_recorded(out))
    (_, ended), said, told = _stopped(proc, "ctrl-c", lambda: wait_for(seen, 60, event),
                                      look=lambda: (out / "report.md").is_file())
    assert proc.returncode == 0 and "bsst: interrupted" not in told, (proc.returncode, said, told)
    # at sweep.json's engine, in the writing; at the last row, the pool's shutdown (said as a stop in flight) or later;
    # held still as the stop was sent, report.md not yet written: it landed before the result was final, and is said
    # (a loaded machine's late look once saw report.md written: the stop then may come after the result, ignored)
    when = ["writing"] if event == "engines recorded" else ["flying", "writing"]
    held = [w for w in when if f"bsst sweep: interrupted {STOPS_HELD[w]}; nothing is missing: the sweep is whole "
            "(its exit status its cells')" in told.splitlines()]
    assert len(held) == (0 if ended else 1) or (ended and held == ["writing"]), (ended, said, told)
    assert "sweep short: 3 cells, 3 flown" in said, said
    assert len(read_cells(out / CELLS_CSV)) == 3 and (out / "report.md").is_file(), sorted(os.listdir(out))
    assert (out / "map_delay_loss.png").is_file(), sorted(os.listdir(out))


def test_a_second_ctrl_c_does_not_wait_for_the_cell_in_flight(tmp_path: Path) -> None:
    """Ctrl-C lets the cells in flight finish; a second one ends their workers at once. The cell here is a
    half-hour offline flight (17 s of work on a quiet core, more under load), interrupted as its worker starts:
    the sweep must be gone within 10 s of the second Ctrl-C (0.1–0.2 s at load 8), its workers with it, and
    say it was interrupted with nothing flown (exit 1)."""
    mission = tmp_path / "long.toml"
    mission.write_text(dump_toml(Mission(Sine(climb=0.0), duration_s=1800.0, name="long").to_dict()))
    out = tmp_path / "stopped"
    proc = Bsst("sweep", str(mission), "--delay", "0,5", "--jobs", "1", "--no-plots", "--out", str(out))
    try:
        wait_for(lambda: pool_workers(proc.pid), 60, "a pool worker flying the first cell")
        os.killpg(proc.pid, signal.SIGINT)
        sweep_said(proc, lambda line: "Ctrl-C again stops them now" in line)  # (two at once would be one signal)
        os.killpg(proc.pid, signal.SIGINT)
        said, _ = proc.communicate(timeout=10)  # (a sweep waiting for the cell would end after it)
        assert proc.returncode == 1 and "0 of 2 cells flown (interrupted)" in said, (proc.returncode, said)
        assert not pool_workers(proc.pid)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()


def test_resume_refuses_an_edited_plug_in_law(mission_file: Path, tmp_path: Path, capsys) -> None:
    """sweep.json holds the hash of a swept plug-in law's file; the untouched file resumes, an edited one (a comment
    added) is refused in one line naming it."""
    law = tmp_path / "law.py"
    shutil.copyfile(ROOT / "examples" / "my_law.py", law)
    out = tmp_path / "sweep"
    args = ["sweep", str(mission_file), "--controller", f"bsst,{law}:MyLaw", "--delay", "0,10", "--jobs", "2",
            "--no-plots", "--out", str(out)]
    assert main(args) == 0
    assert json.loads((out / "sweep.json").read_text())["input_files_sha256"] == {str(law): file_sha256(law)}
    assert main([*args, "--resume"]) == 0
    law.write_text(law.read_text() + "# tuned later\n")
    capsys.readouterr()
    assert main([*args, "--resume"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"--resume: {law}: edited after the sweep" in err, err


def test_the_files_hashed_are_laws_traces_and_profiles(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A law file, a link trace (either direction), a profile file and the trace it names; not a built-in law, a
    shipped profile's name or a law module that is not there."""
    trace = tmp_path / "t.csv"
    shutil.copyfile(ROOT / "examples" / "link-trace.csv", trace)
    profile = tmp_path / "p.toml"
    profile.write_text('name = "p"\ndescription = "d"\nsources = ["s"]\n[link]\ntrace = "t.csv"\n')
    ident = {"mission": {"controller": "smc", "link": {"up": {"trace": str(trace)}, "profile": str(profile)}},
             "grid": {"controller": ["bsst", "examples/my_law.py:MyLaw", "no_such_module:Law"]}}
    monkeypatch.chdir(ROOT)  # a relative law file is the working directory's, as the cells load it
    got = input_hashes(ident)
    assert set(got) == {str(trace), str(profile), "examples/my_law.py"}, got
    assert got[str(trace)] == file_sha256(trace)
    assert input_hashes({"mission": {"link": {"profile": "lte"}}, "grid": {}}) == {}
