"""``bsst margin``: the boundary of one impairment by bisection, within a few dozen cells.

The figures are the README's (docs/figures.md, "A bad link"): the sine mission's BS-ST loop
holds a 3-D RMS under 10 cm up to 36 ms of equal delay both ways, and up to 59 ms with
prediction; a grid at the same 0.25 ms over 0-100 ms would fly 400 cells.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def bsst(*argv: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "bridge", *argv], cwd=ROOT, capture_output=True, text=True,
                          timeout=600)


@pytest.mark.parametrize("extra, expected", [([], 36.0), (["--compensation", "predict"], 59.0)])
def test_the_delay_margin_is_found_inside_its_bracket(tmp_path: Path, extra: list[str], expected: float) -> None:
    r = bsst("margin", "missions/sine.toml", "--over", "delay_ms", "--until", "rms=0.1", "--out", str(tmp_path),
             *extra)
    assert r.returncode == 0, r.stderr
    res = json.loads((tmp_path / "margin.json").read_text())
    lo, hi = res["bracket"]
    assert res["over"] == "delay_ms" and res["until"] == "rms=0.1" and res["margin"] == lo
    assert lo <= expected <= hi and hi - lo <= 0.25
    assert res["cells_flown"] <= 80 and len(res["cells"]) == res["cells_flown"]
    assert all(c["failed"] for c in res["cells"] if c["delay_ms"] >= hi)
    assert not any(c["failed"] for c in res["cells"] if c["delay_ms"] <= lo)
    assert f"delay_ms {lo:g}" in r.stdout


def test_require_fails_a_users_ci_when_the_margin_is_short(tmp_path: Path) -> None:
    r = bsst("margin", "missions/sine.toml", "--over", "delay_ms", "--until", "rms=0.1", "--resolution", "4",
             "--require", "50", "--out", str(tmp_path))
    assert r.returncode == 1 and "below --require 50" in r.stderr, r.stderr


@pytest.mark.parametrize("argv, names", [
    (["--over", "delay_ms", "--until", "rms=-1"], "--until"),
    (["--over", "delay_ms", "--until", "class=sparkly"], "--until"),
    (["--over", "delay_ms", "--until", "rms=0.1", "--delay", "5"], "--over delay_ms"),
    (["--over", "wind", "--until", "rms=0.1"], "--over"),
])
def test_bad_margin_input_is_one_line(argv: list[str], names: str) -> None:
    r = bsst("margin", "missions/sine.toml", *argv)
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1 and names in lines[0], r.stderr
