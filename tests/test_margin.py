"""Covers bridge.sweep.margin.

``bsst margin``: the boundary of one impairment by bisection, within a few dozen cells.

The figures are the README's (docs/figures.md, "A bad link"): the sine mission's BS-ST loop
holds a 3-D RMS under 10 cm up to 36 ms of equal delay both ways, and up to 57 ms with
prediction (the offline loop flies the float32 wire as SITL does: lockstep gives the same); a
grid at the same 0.25 ms over 0-100 ms would fly 400 cells.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from bridge import simulate
from missions import Mission, Sine
from params import dump_toml

pytestmark = pytest.mark.process  # starts processes or opens sockets: not in make test-fast

ROOT = Path(__file__).resolve().parents[1]
SHORT = Mission(Sine(), duration_s=6.0, name="short")  # the raw estimator's RMS: 2.9 cm at noise 1, 8.1 cm at 2


def bsst(*argv: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "bridge", *argv], cwd=ROOT, capture_output=True, text=True,
                          timeout=600)


@pytest.mark.parametrize("extra, expected", [([], 36.0), (["--compensation", "predict"], 57.0)])
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
    (["--over", "noise", "--until", "rms=0.1"], "estimator is 'truth'"),  # the true state: noise changes nothing
    (["--over", "noise", "--until", "rms=0.1", "--estimator", "ekf"], "sensor set 'ideal' has no noise"),
    (["--over", "noise", "--until", "rms=0.1", "--sensors", "mocap", "--estimator", "ekf", "--noise", "2"],
     "--noise conflicts with --over noise"),
    (["--over", "noise", "--until", "rms=0.1", "--sensors", "mocap", "--estimator", "ekf", "--engine", "batch"],
     "--engine batch: [estimator] kind = 'ekf'"),
])
def test_bad_margin_input_is_one_line(argv: list[str], names: str) -> None:
    r = bsst("margin", "missions/sine.toml", *argv)
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1 and names in lines[0], r.stderr


def test_the_noise_margin_is_found_inside_its_bracket(tmp_path: Path) -> None:
    """``--over noise``: the scale of every sigma of the motion-capture set, flown with the raw measurements
    on the process engine; each end of the bracket flown again on its own lands on its side of the bound."""
    mission = tmp_path / "short.toml"
    mission.write_text(dump_toml(SHORT.to_dict()))
    r = bsst("margin", str(mission), "--over", "noise", "--until", "rms=0.05", "--sensors", "mocap", "--estimator",
             "raw", "--out", str(tmp_path / "m"))
    assert r.returncode == 0, r.stderr
    res = json.loads((tmp_path / "m" / "margin.json").read_text())
    lo, hi = res["bracket"]
    assert res["over"] == "noise" and res["estimator"] == "raw" and res["sensors"] == "mocap"
    assert res["margin"] == lo and 1.0 <= lo < hi <= 2.0 and hi - lo <= 0.25, res
    assert res["cells_flown"] == len(res["cells"]) <= 6
    assert all(c["failed"] for c in res["cells"] if c["noise"] >= hi)
    assert not any(c["failed"] for c in res["cells"] if c["noise"] <= lo)
    fly = SHORT.with_overrides(sensors={"set": "mocap"}, estimator={"kind": "raw"})
    assert simulate(fly.with_overrides(sensors={"set": "mocap", "noise_scale": lo})).rms <= 0.05
    assert simulate(fly.with_overrides(sensors={"set": "mocap", "noise_scale": hi})).rms > 0.05
    assert f"noise {lo:g} x the sigmas of mocap, estimator raw" in r.stdout


def test_a_law_that_fails_everywhere_has_no_margin(tmp_path: Path) -> None:
    """The raw measurements never hold 1 mm on the short mission: the search flies down to the range's
    low end (noise 0) itself, rather than claim it holds, and reports no margin; --require then fails."""
    mission = tmp_path / "short.toml"
    mission.write_text(dump_toml(SHORT.to_dict()))
    r = bsst("margin", str(mission), "--over", "noise", "--until", "rms=0.001", "--sensors", "mocap", "--estimator",
             "raw", "--require", "0", "--out", str(tmp_path / "m"))
    res = json.loads((tmp_path / "m" / "margin.json").read_text())
    assert r.returncode == 1 and "below --require 0: bsst" in r.stderr, r.stderr
    assert res["margin"] is None and res["bracket"] == [None, 0.0] and all(c["failed"] for c in res["cells"])
    assert [c["noise"] for c in res["cells"]] == [1.0, 0.5, 0.25, 0.0]
    assert "margin bsst: noise: none" in r.stdout


def test_a_refused_out_directory_is_named_before_any_flight(tmp_path: Path) -> None:
    """A non-empty --out is refused up front: with 1000 seeds a probe, a search that flew first would
    run for many minutes before it refused to write (the deadline below would end the test)."""
    (tmp_path / "kept.txt").write_text("a user's file\n")
    r = subprocess.run([sys.executable, "-m", "bridge", "margin", "missions/sine.toml", "--over", "delay_ms",
                        "--until", "rms=0.1", "--seeds", "1000", "--out", str(tmp_path)],
                       cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "--out" in r.stderr and "not empty" in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr
    assert (tmp_path / "kept.txt").read_text() == "a user's file\n" and not (tmp_path / "margin.json").exists()


# -- issue 22, defect 8: every --resolution the search takes ends ------------------------------------------------------
@pytest.mark.parametrize("over", ["delay_ms", "loss_pct", "jitter_ms", "burst_len", "noise", "wind_mps"])
def test_a_resolution_too_fine_to_end_is_refused_naming_the_flag_and_its_range(over: str) -> None:
    r = subprocess.run([sys.executable, "-m", "bridge", "margin", "missions/sine.toml", "--over", over, "--until",
                        "rms=0.1", "--resolution", "1e-300"], cwd=ROOT, capture_output=True, text=True, timeout=60)
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    assert "--resolution must be in [" in lines[0] and f"for --over {over}" in lines[0] and "1e-300" in lines[0]


@pytest.mark.parametrize("over", ["delay_ms", "loss_pct", "jitter_ms", "burst_len", "noise", "wind_mps"])
def test_the_finest_resolution_taken_ends_within_its_rounds(over: str) -> None:
    """The search's own steps (no flight: a value fails above a threshold) from the finest resolution the
    search takes to the coarsest, for a boundary near the range's bottom, inside it, at its top and nowhere
    (every value fails): the rounds stay within the doublings to the top plus MAX_HALVINGS + 1."""
    import math

    from bridge.sweep.grid import RANGES
    from bridge.sweep.margin import MAX_HALVINGS, START, Search, resolution_range

    lo, top = RANGES[over]
    least, most = resolution_range(over)
    bound = math.ceil(math.log2(top / START[over])) + 2 + MAX_HALVINGS + 1
    for resolution in (least, least * 1.5, (top - lo) / 1000.0, most):
        for boundary in (lo - 1.0, lo + least / 3.0, lo + (top - lo) * 0.3141, top, math.inf):
            s = Search("bs_st", lo)
            value: float | None = START[over]
            rounds = 0
            while value is not None:
                rounds += 1
                assert rounds <= bound, (resolution, boundary, s)
                s.record(value, value > boundary)
                value = s.next_value(resolution, top)
            if s.hi is not None and s.held:
                assert s.hi - s.lo <= resolution or math.nextafter(s.lo, math.inf) >= s.hi, (resolution, s)


def test_the_wind_margin_is_found_inside_its_bracket(tmp_path: Path) -> None:
    """``--over wind_mps`` (issue 27): the steady wind the BS-ST law takes on the sine before its RMS passes
    10 cm, its probes on the batch engine (steady wind), in at most 80 cells; each end of the
    bracket flown again on its own lands on its side of the bound."""
    r = bsst("margin", "missions/sine.toml", "--over", "wind_mps", "--until", "rms=0.1", "--controller", "bsst",
             "--out", str(tmp_path))
    assert r.returncode == 0, r.stderr
    res = json.loads((tmp_path / "margin.json").read_text())
    lo, hi = res["bracket"]
    assert res["over"] == "wind_mps" and res["margin"] == lo and 0.0 < lo < hi and hi - lo <= 0.25, res
    assert res["cells_flown"] == len(res["cells"]) <= 80
    assert all(c["failed"] for c in res["cells"] if c["wind_mps"] >= hi)
    assert not any(c["failed"] for c in res["cells"] if c["wind_mps"] <= lo)
    assert simulate("missions/sine.toml", wind=lo).rms <= 0.1 < simulate("missions/sine.toml", wind=hi).rms
    assert f"wind_mps {lo:g}" in r.stdout
    windy = tmp_path / "windy.toml"
    windy.write_text(dump_toml({**SHORT.to_dict(), "wind": {"speed_mps": 3.0}}))
    refused = bsst("margin", str(windy), "--over", "wind_mps", "--until", "rms=0.1")
    assert refused.returncode == 2 and "already sets speed_mps = 3" in refused.stderr, refused.stderr
