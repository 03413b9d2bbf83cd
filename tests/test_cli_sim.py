"""Covers bridge.cli and bridge.loop.

`bsst sim` as a real subprocess (``python -m bridge sim ...``).

A good run exits 0 and writes the run directory of docs/design.md, "Files of a run"; bad input exits 2
with exactly one line on stderr and no traceback; a non-empty --out is refused without
--overwrite.
"""

from __future__ import annotations

import csv
import importlib.metadata
import json
import os
import subprocess
import tomllib
from pathlib import Path

import pytest

from missions import MISSION_DIR, load_mission
from tests.sitlkit import Bsst, run_bsst

pytestmark = pytest.mark.process  # starts processes or opens sockets: not in make test-fast

ROOT = Path(__file__).resolve().parent.parent

# docs/design.md, "Files of a run": fixed names (more may follow)
TRACE_COLUMNS = [
    "t", "x", "y", "z", "vx", "vy", "vz", "phi", "theta", "psi", "dphi", "dtheta", "dpsi",
    "x_ref", "y_ref", "z_ref", "psi_ref", "u1", "u2", "u3", "u4", "c1", "c2", "c3", "c4",
    "u1_act", "u2_act", "u3_act", "u4_act",
]
SUMMARY_KEYS = {"mission", "clock", "rate_hz", "duration_s", "axes", "inputs", "link", "events", "outcome"}
AXIS_KEYS = {"rms", "max", "settling_s", "bound_s"}
INPUT_KEYS = {"min", "max", "tv_per_s"}
LINK_KEYS = {"sent", "delivered", "lost", "duplicated", "reordered", "delay_ms"}
PLOTS = {"positions.png", "errors.png", "angles.png", "inputs.png", "path3d.png"}


def bsst(*args: str | Path, cwd: Path = ROOT) -> subprocess.CompletedProcess[str]:
    env = dict(os.environ, MPLBACKEND="Agg")
    return run_bsst("sim", *map(str, args), cwd=cwd, env=env, timeout=120)


def short_sine(tmp_path: Path, seconds: float = 4.0) -> Path:
    text = (MISSION_DIR / "sine.toml").read_text().replace("duration_s = 30.0", f"duration_s = {seconds}")
    f = tmp_path / "short.toml"
    f.write_text(text)
    return f


def test_good_run_writes_the_run_directory(tmp_path: Path) -> None:
    out = tmp_path / "run"
    res = bsst(short_sine(tmp_path), "--out", out, "--rate", "200", "--seed", "3")
    assert res.returncode == 0, res.stderr
    assert "outcome: completed" in res.stdout and str(out) in res.stdout
    assert "Traceback" not in res.stderr

    files = {p.name for p in out.iterdir()}
    assert {"mission.toml", "trace.csv", "summary.json", "events.log", "plots"} <= files
    assert {p.name for p in (out / "plots").glob("*.png")} >= PLOTS
    for png in (out / "plots").glob("*.png"):
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    # the mission as flown: overrides applied, loads again
    flown = (out / "mission.toml").read_text()
    assert "rate_hz = 200.0" in flown and "seed = 3" in flown
    assert load_mission(out / "mission.toml").rate_hz == 200.0

    with open(out / "trace.csv") as f:
        rows = list(csv.reader(f))
    header, body = rows[0], rows[1:]
    assert header[: len(TRACE_COLUMNS)] == TRACE_COLUMNS
    assert len(body) == 4 * 200 and all(len(r) == len(header) for r in body)
    assert float(body[1][0]) == pytest.approx(1 / 200)

    s = json.loads((out / "summary.json").read_text())
    assert SUMMARY_KEYS <= set(s)
    assert s["clock"] == "offline" and s["outcome"] == "completed" and s["rate_hz"] == 200.0
    assert s["mission"] == "sine" and s["duration_s"] == pytest.approx(4.0)
    assert set(s["axes"]) == {"x", "y", "z", "psi"} and all(AXIS_KEYS <= set(v) for v in s["axes"].values())
    assert set(s["inputs"]) == {"u1", "u2", "u3", "u4"} and all(INPUT_KEYS <= set(v) for v in s["inputs"].values())
    assert {"up", "down", "rejected"} <= set(s["link"])
    for d in ("up", "down"):
        assert LINK_KEYS <= set(s["link"][d]) and {"p50", "p95", "p99", "max"} <= set(s["link"][d]["delay_ms"])
    assert isinstance(s["events"], list)
    assert not list(out.glob(".*tmp*"))  # the atomic write left no temporary behind


def test_refuses_a_non_empty_out_without_overwrite(tmp_path: Path) -> None:
    out = tmp_path / "busy"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    mission = short_sine(tmp_path, 1.0)
    res = bsst(mission, "--out", out, "--no-plots")
    assert res.returncode == 2
    assert len(res.stderr.splitlines()) == 1 and "--overwrite" in res.stderr and "Traceback" not in res.stderr
    assert {p.name for p in out.iterdir()} == {"keep.txt"}
    res = bsst(mission, "--out", out, "--no-plots", "--overwrite")
    assert res.returncode == 0, res.stderr
    assert (out / "trace.csv").exists() and (out / "keep.txt").read_text() == "mine"


def _mission(tmp_path: Path, old: str, new: str) -> Path:
    text = (MISSION_DIR / "step.toml").read_text()
    assert old in text
    f = tmp_path / "bad.toml"
    f.write_text(text.replace(old, new, 1))
    return f


BAD = {
    "negative duration": (lambda p: [_mission(p, "duration_s = 30.0", "duration_s = -1.0")], "duration_s"),
    "unknown key": (lambda p: [_mission(p, 'name = "step"', 'name = "step"\nspeed = 3')], "speed: unknown key"),
    "wrong type": (lambda p: [_mission(p, "rate_hz = 250", 'rate_hz = "fast"')], "rate_hz"),
    "bad trajectory": (lambda p: [_mission(p, 'kind = "step"', 'kind = "loop"')], "trajectory.kind"),
    "bad gains": (lambda p: [_mission(p, "seed = 0", "seed = 0\n[gains.z]\nk2 = 0.5")], "gains.z.k2"),
    "missing file": (lambda p: [p / "nowhere.toml"], "no such file"),
    "non-TOML": (lambda p: [_write(p / "junk.toml", "<xml>not toml</xml>")], "not valid TOML"),
    "a directory": (lambda p: [p], "is a directory"),
    "--rate 5": (lambda p: [MISSION_DIR / "step.toml", "--rate", "5"], "--rate"),
    "--rate nan": (lambda p: [MISSION_DIR / "step.toml", "--rate", "nan"], "--rate"),
    "--seed -1": (lambda p: [MISSION_DIR / "step.toml", "--seed", "-1"], "--seed"),
    "--seed x": (lambda p: [MISSION_DIR / "step.toml", "--seed", "x"], "--seed"),
    "unknown profile": (lambda p: [MISSION_DIR / "step.toml", "--profile", "f450"], "unknown profile"),
    "unknown controller": (lambda p: [MISSION_DIR / "step.toml", "--controller", "lqr"], "--controller"),
    "unknown flag": (lambda p: [MISSION_DIR / "step.toml", "--fast"], "--fast"),
    "no mission": (lambda p: [], "mission"),
}


def _write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


@pytest.mark.parametrize("case", list(BAD))
def test_bad_input_exits_2_with_one_line(tmp_path: Path, case: str) -> None:
    make, words = BAD[case]
    out = tmp_path / "out"
    res = bsst(*make(tmp_path), "--out", out, "--no-plots")
    assert res.returncode == 2, (res.returncode, res.stdout, res.stderr)
    lines = res.stderr.splitlines()
    assert len(lines) == 1, res.stderr
    assert "Traceback" not in res.stderr and lines[0].startswith("bsst")
    assert words in lines[0], lines[0]
    assert not out.exists() or not any(out.iterdir())  # nothing flown, nothing written


def test_files_saved_with_a_byte_order_mark_fly(tmp_path: Path) -> None:
    """A mission, a vehicle profile and a link profile each starting with UTF-8's byte-order mark (EF BB BF, as a
    Windows editor saves them) fly as without it: a link profile so was ``not valid TOML (Invalid statement (at
    line 1, column 1))``, exit 2 (tests/test_text_files.py: every kind of file)."""
    bom = b"\xef\xbb\xbf"
    mission = tmp_path / "m.toml"
    mission.write_bytes(bom + b'name = "m"\nduration_s = 1.0\n[trajectory]\nkind = "sine"\n')
    profile = tmp_path / "v.toml"
    profile.write_bytes(bom + (ROOT / "plant" / "profiles" / "paper.toml").read_bytes())
    link = tmp_path / "l.toml"
    link.write_bytes(bom + (ROOT / "bridge" / "link" / "profiles" / "wifi.toml").read_bytes())
    res = bsst(mission, "--profile", profile, "--link-profile", link, "--out", tmp_path / "run", "--no-plots")
    assert res.returncode == 0, res.stderr
    assert json.loads((tmp_path / "run" / "summary.json").read_text())["outcome"] == "completed"


def test_divergence_exits_1_and_is_recorded(tmp_path: Path) -> None:
    """A constant 20 N push the law cannot hold against takes the vehicle past |position| = 100 m
    (a set-point out there is refused up front: tests/test_mission.py): the run stops there,
    every file is written, the summary says why, and the exit status is 1."""
    far = tmp_path / "far.toml"
    far.write_text('name = "far"\nduration_s = 30.0\n[trajectory]\nkind = "step"\n'
                   "setpoints = [{ t = 0.0, x = 50.0, y = 0.0, z = 2.0 }]\n"
                   "[effects.disturbance]\nforce = [20.0, 0.0, 0.0]\n")
    out = tmp_path / "run"
    res = bsst(far, "--out", out, "--no-plots")
    assert res.returncode == 1, res.stderr
    assert "Traceback" not in res.stderr
    # why it exits 1, on stderr (bridge.record.asked.ended_text): until the third wave's forty-second session, nothing
    assert res.stderr.splitlines() == ["bsst sim: diverged: ended by plant: diverged at t=3.632 s: position beyond "
                                       "100 m"], res.stderr
    s = json.loads((out / "summary.json").read_text())
    assert s["outcome"] == "diverged"
    assert any(e["kind"] == "diverged" and "100 m" in e["text"] for e in s["events"])
    assert "diverged" in (out / "events.log").read_text()
    with open(out / "trace.csv") as f:
        rows = list(csv.reader(f))[1:]
    assert 0 < len(rows) < 30 * 250
    last_x = float(rows[-1][1])
    assert 90.0 < last_x <= 100.5


def test_a_failsafe_exits_1_saying_why(tmp_path: Path) -> None:
    """A 4 s sine whose up link is blacked out from 1 s: the vehicle's offboard-loss failsafe takes over 0.5 s later
    (every policy holds). Exit 1, and stderr says why in one line, as the summary's ``ended_by`` says it; until the
    third wave's forty-second session ``bsst sim`` exited 1 with nothing on stderr."""
    mission = short_sine(tmp_path)
    mission.write_text(mission.read_text() + "\n[link]\nblackouts = [[1.0, 10.0]]\n")
    res = bsst(mission, "--out", tmp_path / "run", "--no-plots")
    assert res.returncode == 1 and "Traceback" not in res.stderr, res.stderr
    assert res.stderr.splitlines() == ["bsst sim: failsafe: ended by vehicle: failsafe at t=1.500 s: no actuator "
                                       "target for 0.504 s: level and descend"], res.stderr


def test_a_reader_that_stops_early_costs_no_traceback_nor_the_exit_status(tmp_path):
    """``bsst sim ... | head -1``: the summary's print meets a closed pipe; the run is on disk and
    the exit status is the run's (0), with nothing on stderr."""
    # the sine's first 10 s (not 30): still flying for a tenth of a second or more when stdout is closed at once
    p = Bsst("sim", str(short_sine(tmp_path, 10.0)), "--no-plots", "--out", str(tmp_path / "r"))
    p.stdout.close()  # as head does once it has its lines: every write of the summary meets a closed pipe
    err = p.stderr.read()
    assert p.wait(timeout=60) == 0 and "Traceback" not in err and "Exception" not in err, err
    assert (tmp_path / "r" / "summary.json").is_file()


def test_bsst_version_prints_the_packages_version() -> None:
    """``bsst --version``: the installed distribution's version (pyproject.toml's in a checkout never installed)."""
    try:
        want = importlib.metadata.version("bsst-sitl")
    except importlib.metadata.PackageNotFoundError:
        want = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]
    r = run_bsst("--version", cwd=ROOT, timeout=60)
    assert (r.returncode, r.stdout, r.stderr) == (0, f"bsst {want}\n", "")
