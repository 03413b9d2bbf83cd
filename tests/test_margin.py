"""Covers bridge.sweep.margin.

``bsst margin``: the boundary of one impairment by bisection, within a few dozen cells.

The figures are the README's and docs/law.md's ("The delay margin, scanned"): the sine mission's BS-ST
loop with the paper's explicit step (asked for by name: ``--discretization explicit``) holds a 3-D RMS
under 10 cm up to 36 ms of equal delay both ways by bisection, and up to 57 ms with prediction (the
offline loop flies the float32 wire as SITL does: lockstep gives the same); a grid at the same 0.25 ms
over 0-100 ms would fly 400 cells. Below its 36 ms the sine fails again at 34.25-35 ms: the check below
the margin says so (``monotone``, ``failed_below``, ``holds_below``), and ``--require`` reads
``holds_below``. The default, the implicit step, holds to 35 ms, monotone below it. ``SHORT`` flies the
explicit step too: its figures below are that law's.
"""

from __future__ import annotations

import json
import subprocess
from collections.abc import Callable
from pathlib import Path

import pytest

from bridge import simulate
from bridge.cli import main
from missions import MISSION_DIR, Mission, Sine, load_mission
from params import dump_toml
from tests.lawfiles import HOVERING
from tests.sitlkit import run_bsst

# starts processes or opens sockets (not in make test-fast); flies the batch engine (its kernels loaded first)
pytestmark = [pytest.mark.process, pytest.mark.usefixtures("batch_kernels")]

ROOT = Path(__file__).resolve().parents[1]
# the raw estimator's RMS: 2.9 cm at noise 1, 8.1 cm at 2 (explicit: the figures here are the paper's law's)
SHORT = Mission(Sine(), duration_s=6.0, name="short", discretization="explicit")
# SHORT's 3-D RMS over t >= 3 s with an equal delay both ways (cm): 9.3 at 36 ms, 12.7 at 37, 4.9 at 38, 18.1 at 39
Completed = subprocess.CompletedProcess[str]


@pytest.fixture
def here(capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> Callable[..., Completed]:
    """``bsst ARGS`` run by the command line's ``main`` in this process, in the repository's folder: its exit status,
    stdout and stderr as :func:`tests.sitlkit.run_bsst` gives a forked one's, without a process that imports numba
    and loads the batch's kernels again (~0.35 CPU-s a search). The searches' results and lines, and the refusals'
    lines, are the point of the tests that use it; the refusals whose deadline is the point (a search that flew
    first would pass it) and tests/test_margin_interrupt.py run ``bsst margin`` as a real process."""
    monkeypatch.chdir(ROOT)

    def run(*argv: str | Path) -> Completed:
        capsys.readouterr()
        code = main([str(a) for a in argv])
        out, err = capsys.readouterr()
        return subprocess.CompletedProcess(["bsst", *map(str, argv)], code, out, err)

    return run


@pytest.mark.parametrize("extra, expected, holds", [
    (["--discretization", "explicit"], 36.0, 34.0),
    (["--discretization", "explicit", "--compensation", "predict"], 57.0, 57.0),
    ([], 35.0, 35.0),  # the default, implicit: the README's example
])
def test_the_delay_margin_is_found_inside_its_bracket(tmp_path: Path, here, extra: list[str], expected: float,
                                                     holds: float) -> None:
    """The bisection's margin (explicit: 36 and 57 ms, issue 21's figures; implicit, the default: 35 ms), then
    the 4 ms below it flown at 0.25 ms: the explicit step without prediction fails at 34.25-35 ms (every
    delay flown holds up to 34 ms); with prediction, and the implicit step, every one holds."""
    r = here("margin", "missions/sine.toml", "--over", "delay_ms", "--until", "rms=0.1", "--out", str(tmp_path),
             *extra)
    assert r.returncode == 0, r.stderr
    res = json.loads((tmp_path / "margin.json").read_text())
    law = res["controllers"][0]  # margin.json: one entry per law, one law here
    lo, hi = law["bracket"]
    assert res["over"] == "delay_ms" and res["until"] == "rms=0.1" and law["margin"] == lo == expected
    assert hi - lo <= 0.25 and law["checked_below"] == [expected - 4.0, expected] and res["check_below"] == 4.0
    assert res["cells_flown"] <= 80 and len(law["cells"]) == res["cells_flown"]
    bisection = [c for c in law["cells"] if c["phase"] == "bisection"]
    assert all(c["failed"] for c in bisection if c["delay_ms"] >= hi)
    assert not any(c["failed"] for c in bisection if c["delay_ms"] <= lo)
    below = sorted(c["delay_ms"] for c in law["cells"] if c["phase"] == "below")
    flown = {c["delay_ms"] for c in bisection}  # not flown again
    assert below == [v for v in (expected - 0.25 * k for k in range(16, 0, -1)) if v not in flown]
    assert law["holds_below"] == holds and law["monotone"] is (holds == expected)
    assert law["failed_below"] == ([] if holds == expected else [34.25, 34.5, 34.75, 35.0])
    assert f"delay_ms {lo:g}" in r.stdout
    if holds == expected:
        assert "monotone below the margin" in r.stdout and "warning" not in r.stderr
    else:
        assert "NOT MONOTONE below the margin: fails at 34.25, 34.5, 34.75, 35 in [32, 36); holds_below 34" in r.stdout
        assert "warning: bsst is not monotone over delay_ms" in r.stderr


def test_require_reads_the_value_every_smaller_one_holds_to(tmp_path: Path, here) -> None:
    """SHORT at 1 ms: the bisection holds at 38 ms (fails at 39) but 37 ms, the one value it skipped in the
    2 ms below, fails: --require 37 fails a user's CI although the margin is 38, and says why."""
    mission = tmp_path / "short.toml"
    mission.write_text(dump_toml(SHORT.to_dict()))
    r = here("margin", str(mission), "--over", "delay_ms", "--until", "rms=0.1", "--resolution", "1",
             "--check-below", "2", "--require", "37", "--out", str(tmp_path / "m"))
    res = json.loads((tmp_path / "m" / "margin.json").read_text())
    law = res["controllers"][0]  # margin.json: one entry per law, one law here
    assert r.returncode == 1 and "below --require 37 (holds_below): bsst" in r.stderr, r.stderr
    assert law["margin"] == 38.0 and law["bracket"] == [38.0, 39.0] and law["checked_below"] == [36.0, 38.0]
    assert law["monotone"] is False and law["failed_below"] == [37.0] and law["holds_below"] == 36.0
    assert sorted((c["delay_ms"], c["phase"]) for c in law["cells"] if 36 <= c["delay_ms"] <= 39) == [
        (36.0, "bisection"), (37.0, "below"), (38.0, "bisection"), (39.0, "bisection")]
    assert "NOT MONOTONE below the margin: fails at 37 in [36, 38); holds_below 36" in r.stdout
    assert "margin bsst: delay_ms 38 (bracket [38, 39]" in r.stdout


def test_the_check_below_can_be_turned_off(tmp_path: Path) -> None:
    """``below=0``: the bisection alone, as before the check; ``monotone`` is then unknown (None), not true."""
    from bridge.sweep.margin import Until, margin

    res = margin(SHORT, "delay_ms", Until(rms=0.1), resolution=1.0, below=0.0)
    law = res["controllers"][0]  # margin.json: one entry per law, one law here
    assert law["margin"] == 38.0 and law["monotone"] is None and law["checked_below"] is None
    assert law["holds_below"] == 38.0 and law["failed_below"] == []
    assert {c["phase"] for c in law["cells"]} == {"bisection"} and res["cells_flown"] == 8


def test_require_fails_a_users_ci_when_the_margin_is_short(tmp_path: Path, here) -> None:
    r = here("margin", "missions/sine.toml", "--over", "delay_ms", "--until", "rms=0.1", "--resolution", "4",
             "--check-below", "4", "--require", "50", "--out", str(tmp_path))
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
    (["--over", "delay_ms", "--until", "rms=0.1", "--noise", "2"],  # fixed for every probe: as bsst sim's
     "bsst: --noise 2: the estimator is 'truth' (the true state: the sensors are not read), so noise changes nothing"),
    (["--over", "noise", "--until", "rms=0.1", "--sensors", "mocap", "--estimator", "ekf", "--engine", "batch"],
     "--engine batch: [estimator] kind = 'ekf'"),
    (["--over", "delay_ms", "--until", "rms=0.1", "--check-below", "300"], "--check-below must be in [0, 1024 x"),
    (["--over", "delay_ms", "--until", "rms=0.1", "--check-below", "-1"], "--check-below"),
    # a link trace gives every link axis: refused up front, naming the two flags (not the search's first probe)
    (["--over", "delay_ms", "--until", "rms=0.1", "--link-trace", "examples/link-trace.csv"],
     "bsst margin: --over delay_ms with --link-trace: the trace gives the link's delay_ms, jitter_ms, loss_pct, "
     "burst_len, so delay_ms cannot be searched over it; drop --link-trace"),
    (["--over", "burst_len", "--until", "rms=0.1", "--down-link-trace", "examples/link-trace.csv"],
     "bsst margin: --over burst_len with --down-link-trace"),
])
def test_bad_margin_input_is_one_line(here, argv: list[str], names: str) -> None:
    r = here("margin", "missions/sine.toml", *argv)
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1 and names in lines[0], r.stderr


@pytest.mark.parametrize("argv, names", [
    (["margin", "{m}", "--over", "loss_pct", "--until", "rms=0.1"],
     "margin over loss_pct: {m} replays the link trace {t}, which gives the link's delay_ms, jitter_ms, loss_pct, "
     "burst_len: loss_pct cannot be searched over it"),
    (["sweep", "{m}", "--delay", "0,10", "--no-plots"],
     "grid.delay_ms (--delay): {m} replays the link trace {t}"),
])
def test_a_link_axis_is_not_searched_over_the_missions_own_link_trace(tmp_path: Path, argv: list[str],
                                                                      names: str) -> None:
    """The mission's ``[link] trace`` gives the link's delays and losses: a margin or a sweep over a link axis is
    refused before any cell flies, naming the file and the trace (not a probe's value the user never gave)."""
    trace = ROOT / "examples" / "link-trace.csv"
    m = tmp_path / "traced.toml"
    m.write_text(dump_toml({**SHORT.to_dict(), "link": {"trace": str(trace)}}))
    r = run_bsst(*(a.format(m=m) for a in argv), "--out", str(tmp_path / "out"), cwd=tmp_path, timeout=120)
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    assert names.format(m=m, t=trace) in lines[0] and "--controller" not in lines[0], lines[0]
    assert not (tmp_path / "out").exists()


def test_the_noise_margin_is_found_inside_its_bracket(tmp_path: Path, here) -> None:
    """``--over noise``: the scale of every sigma of the motion-capture set, flown with the raw measurements
    on the process engine; each end of the bracket flown again on its own lands on its side of the bound."""
    mission = tmp_path / "short.toml"
    mission.write_text(dump_toml(SHORT.to_dict()))
    r = here("margin", str(mission), "--over", "noise", "--until", "rms=0.05", "--sensors", "mocap", "--estimator",
             "raw", "--check-below", "0.5", "--out", str(tmp_path / "m"))
    assert r.returncode == 0, r.stderr
    res = json.loads((tmp_path / "m" / "margin.json").read_text())
    law = res["controllers"][0]  # margin.json: one entry per law, one law here
    lo, hi = law["bracket"]
    assert res["over"] == "noise" and res["estimator"] == "raw" and res["sensors"] == "mocap"
    assert law["margin"] == lo and 1.0 <= lo < hi <= 2.0 and hi - lo <= 0.25, res
    assert res["cells_flown"] == len(law["cells"]) <= 8 and law["checked_below"] == [lo - 0.5, lo]
    assert law["monotone"] is True and law["holds_below"] == lo and "monotone below the margin" in r.stdout
    assert all(c["failed"] for c in law["cells"] if c["noise"] >= hi)
    assert not any(c["failed"] for c in law["cells"] if c["noise"] <= lo)
    fly = SHORT.with_overrides(sensors={"set": "mocap"}, estimator={"kind": "raw"})
    assert simulate(fly.with_overrides(sensors={"set": "mocap", "noise_scale": lo})).rms <= 0.05
    assert simulate(fly.with_overrides(sensors={"set": "mocap", "noise_scale": hi})).rms > 0.05
    assert f"noise {lo:g} x the sigmas of mocap, estimator raw" in r.stdout


def test_a_law_that_fails_everywhere_has_no_margin(tmp_path: Path, here) -> None:
    """The raw measurements never hold 1 mm on the short mission: the search flies down to the range's
    low end (noise 0) itself, rather than claim it holds, and reports no margin; --require then fails."""
    mission = tmp_path / "short.toml"
    mission.write_text(dump_toml(SHORT.to_dict()))
    r = here("margin", str(mission), "--over", "noise", "--until", "rms=0.001", "--sensors", "mocap", "--estimator",
             "raw", "--require", "0", "--out", str(tmp_path / "m"))
    res = json.loads((tmp_path / "m" / "margin.json").read_text())
    law = res["controllers"][0]  # margin.json: one entry per law, one law here
    assert r.returncode == 1 and "below --require 0 (holds_below): bsst" in r.stderr, r.stderr
    assert law["monotone"] is None and law["holds_below"] is None and law["checked_below"] is None
    assert law["margin"] is None and law["bracket"] == [None, 0.0] and all(c["failed"] for c in law["cells"])
    assert [c["noise"] for c in law["cells"]] == [1.0, 0.5, 0.25, 0.0]
    assert "margin bsst: noise: none" in r.stdout


def test_a_refused_out_directory_is_named_before_any_flight(tmp_path: Path) -> None:
    """A non-empty --out is refused up front: with 1000 seeds a probe, a search that flew first would
    run for many minutes before it refused to write (the deadline below would end the test)."""
    (tmp_path / "kept.txt").write_text("a user's file\n")
    r = run_bsst("margin", "missions/sine.toml", "--over", "delay_ms", "--until", "rms=0.1", "--seeds", "1000",
                 "--out", str(tmp_path), cwd=ROOT, timeout=60)
    assert r.returncode == 2 and "--out" in r.stderr and "not empty" in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr
    assert (tmp_path / "kept.txt").read_text() == "a user's file\n" and not (tmp_path / "margin.json").exists()


def test_a_law_that_cannot_be_built_is_named_before_any_flight(tmp_path: Path) -> None:
    """Every law of ``--controller`` is built before the first probe flies: a search that flew the good law's
    probes first (1000 seeds of them here) refused the missing file only minutes later on a loaded machine."""
    r = run_bsst("margin", "missions/sine.toml", "--over", "delay_ms", "--until", "rms=0.1", "--seeds", "1000",
                 "--controller", "bsst,nofile.py:Law", "--out", str(tmp_path / "m"), cwd=ROOT, timeout=60)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert "--controller nofile.py:Law: " in r.stderr and "no file" in r.stderr, r.stderr
    assert not (tmp_path / "m").exists()


# -- issue 22, defect 8: every --resolution the search takes ends ------------------------------------------------------
@pytest.mark.parametrize("over", ["delay_ms", "loss_pct", "jitter_ms", "burst_len", "noise", "wind_mps"])
def test_a_resolution_too_fine_to_end_is_refused_naming_the_flag_and_its_range(here, over: str) -> None:
    r = here("margin", "missions/sine.toml", "--over", over, "--until", "rms=0.1", "--resolution", "1e-300")
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


def test_the_wind_margin_is_found_inside_its_bracket(tmp_path: Path, here) -> None:
    """``--over wind_mps`` (issue 27): the steady wind the BS-ST law takes on the sine (cut to 6 s, as SHORT) before
    its RMS passes 10 cm, its probes on the batch engine (steady wind; the sine ending in a hold: a landing in wind is
    the process engine's), in at most 80 cells; each end of the bracket flown again on its own, ending in its landing,
    lands on its side of the bound."""
    sine = tmp_path / "sine6.toml"
    sine.write_text((MISSION_DIR / "sine.toml").read_text().replace("duration_s = 30.0", "duration_s = 6.0"))
    held = tmp_path / "sine6-hold.toml"
    held.write_text(sine.read_text() + '\n[end]\naction = "hold"\n')
    r = here("margin", str(held), "--over", "wind_mps", "--until", "rms=0.1", "--controller", "bsst",
             "--out", str(tmp_path / "m"))
    assert r.returncode == 0, r.stderr
    res = json.loads((tmp_path / "m" / "margin.json").read_text())
    law = res["controllers"][0]  # margin.json: one entry per law, one law here
    lo, hi = law["bracket"]
    assert res["over"] == "wind_mps" and law["margin"] == lo and 0.0 < lo < hi and hi - lo <= 0.25, res
    assert res["cells_flown"] == len(law["cells"]) <= 80
    assert all(c["failed"] for c in law["cells"] if c["wind_mps"] >= hi)
    assert not any(c["failed"] for c in law["cells"] if c["wind_mps"] <= lo)
    assert simulate(sine, wind=lo).rms <= 0.1 < simulate(sine, wind=hi).rms
    assert f"wind_mps {lo:g}" in r.stdout
    windy = tmp_path / "windy.toml"
    windy.write_text(dump_toml({**SHORT.to_dict(), "wind": {"speed_mps": 3.0}}))
    refused = here("margin", str(windy), "--over", "wind_mps", "--until", "rms=0.1")
    assert refused.returncode == 2 and "already sets speed_mps = 3" in refused.stderr, refused.stderr


def test_a_swept_wind_or_link_a_missions_event_replaces_is_refused(tmp_path: Path, capsys) -> None:
    """A mission whose ``[[events]]`` set the steady wind at 0 s: every probe flew the event's 3 m/s, and ``bsst margin
    --over wind_mps`` said ``wind_mps 50 (bracket [50, -], held over the whole range)``, exit 0; a sweep's ``--wind
    0,5`` wrote two rows of one flight; a link handover likewise (``delay_ms 60000``, held over the whole range: a
    user's tour). Refused, exit 2, naming the event, nothing written; a gust is kept (it adds to the swept wind)."""
    windy = tmp_path / "evented.toml"
    windy.write_text(dump_toml({**SHORT.to_dict(), "events": [{"t_s": 0.0, "kind": "wind", "speed_mps": 3.0}]}))
    for argv, head, each in ((["margin", "--over", "wind_mps", "--until", "rms=0.1"], "margin over wind_mps", "probe"),
                             (["sweep", "--wind", "0,5"], "grid.wind_mps (--wind)", "cell")):
        assert main([argv[0], str(windy), *argv[1:], "--out", str(tmp_path / argv[0])]) == 2
        err = capsys.readouterr().err
        assert err == (f"bsst: {head}: {windy}: events (t_s = 0, kind = wind) sets the steady wind from 0 s, so every "
                       f"{each} would fly that event's 3 m/s from then, not its own: sweep the steady wind of a "
                       "mission without wind events (gusts add to it and are kept)\n"), err
        assert not (tmp_path / argv[0]).exists()
    handed = tmp_path / "handed.toml"  # a link handover at 1 s: the link's axes alike
    handed.write_text(dump_toml({**SHORT.to_dict(), "events": [{"t_s": 1.0, "kind": "link", "profile": "wifi"}]}))
    for argv, head, each in ((["margin", "--over", "delay_ms", "--until", "rms=0.1"], "margin over delay_ms", "probe"),
                             (["sweep", "--loss", "0,20"], "grid.loss_pct (--loss)", "cell")):
        assert main([argv[0], str(handed), *argv[1:], "--out", str(tmp_path / argv[0])]) == 2
        err = capsys.readouterr().err
        assert err == (f"bsst: {head}: {handed}: events (t_s = 1, kind = link) hands the link over (link handover to "
                       f"wifi) from 1 s, so every {each} would fly that link from then, not its own: sweep the link of "
                       "a mission without link events\n"), err
    gusty = tmp_path / "gusty.toml"
    gusty.write_text(dump_toml({**SHORT.to_dict(), "events": [{"t_s": 0.5, "kind": "gust", "duration_s": 0.2,
                                                                "amplitude_mps": 1.0}]}))
    from bridge.core.weather import swept_replaced_problem  # here: the check alone (the refusals above fly nothing)
    assert swept_replaced_problem(load_mission(gusty), "wind") is None


# -- a plug-in law that cannot be flown is no boundary ----------------------------------------------------------------
BAD_LAWS = '''
import os
''' + HOVERING + '''

class Dies(_Hovering):  # ends its worker past any guard (docs/usage.md: a failed cell, "worker process died: ...")
    def update(self, t, state, ref, omega_d):
        if t > 5.0:
            os.abort()
        return (self.m * self.g, 0.0, 0.0, 0.0)


class Raises(_Hovering):  # fails every flight: law_failed, at every value
    def update(self, t, state, ref, omega_d):
        raise ZeroDivisionError("my bad")
'''


def test_a_law_whose_worker_dies_ends_its_own_search_not_the_others(tmp_path: Path, here) -> None:
    """A plug-in law that kills its worker (``os.abort()`` at 5 s): its first probe is a failed cell (``worker
    process died: killed by SIGABRT``), its search ends there with no margin and says why; bsst's search goes on to
    its margin, margin.json is written, and the command exits 1 (not as asked), naming the law."""
    laws = tmp_path / "bad_laws.py"
    laws.write_text(BAD_LAWS)
    mission = tmp_path / "short.toml"
    mission.write_text(dump_toml(SHORT.to_dict()))
    r = here("margin", str(mission), "--over", "delay_ms", "--until", "rms=0.1", "--resolution", "4",
             "--check-below", "4", "--controller", f"bsst,{laws}:Dies", "--jobs", "2", "--out", str(tmp_path / "m"))
    assert r.returncode == 1 and "Traceback" not in r.stderr, (r.stdout, r.stderr)
    res = json.loads((tmp_path / "m" / "margin.json").read_text())
    own, dies = res["controllers"]
    assert own["controller"] == "bsst" and own["error"] is None and own["margin"] == 36.0, own
    assert own["bracket"] == [36.0, 40.0] and own["monotone"] is True and not own["held_to_range"]
    assert res["laws_failed"] == [f"{laws}:Dies"]
    assert dies["margin"] is None and dies["bracket"] == [None, None] and not dies["held_to_range"]
    assert dies["error"] == {"delay_ms": 16.0, "seed": 0, "outcome": "error", "phase": "bisection",
                             "error": "worker process died: killed by SIGABRT"}, dies["error"]
    assert [(c["delay_ms"], c["outcome"], c["error"]) for c in dies["cells"]] == [
        (16.0, "error", "worker process died: killed by SIGABRT")]
    assert res["cells_flown"] == len(own["cells"]) + 1
    assert "margin bsst: delay_ms 36 (bracket [36, 40]" in r.stdout
    assert (f"margin {laws}:Dies: delay_ms: none (the law failed, not the criterion: error at 16; worker process "
            "died: killed by SIGABRT)") in r.stdout, r.stdout
    assert (f"bsst margin: {laws}:Dies could not be flown at delay_ms = 16 (seed 0, error): worker process died: "
            "killed by SIGABRT") in r.stderr, r.stderr


def test_a_law_that_fails_every_flight_is_not_reported_as_a_boundary(tmp_path: Path, here) -> None:
    """A plug-in law that raises in every flight measured nothing: not "fails at every value flown" and exit 0,
    but the law's failure with its first message, in the line, on stderr and in margin.json, and exit 1."""
    laws = tmp_path / "bad_laws.py"
    laws.write_text(BAD_LAWS)
    r = here("margin", "missions/sine.toml", "--over", "delay_ms", "--until", "rms=0.1", "--controller",
             f"{laws}:Raises", "--out", str(tmp_path / "m"))
    assert r.returncode == 1 and "Traceback" not in r.stderr, (r.stdout, r.stderr)
    res = json.loads((tmp_path / "m" / "margin.json").read_text())
    (law,) = res["controllers"]
    assert res["laws_failed"] == [f"{laws}:Raises"] and law["margin"] is None and law["holds_below"] is None
    says = "update() raised ZeroDivisionError: my bad"
    assert law["error"]["outcome"] == "law_failed" and says in law["error"]["error"], law["error"]
    (cell,) = law["cells"]  # its search ends at its first probe: no other value is flown for nothing
    assert cell["outcome"] == "law_failed" and cell["class"] == "error" and cell["failed"] and says in cell["error"]
    assert cell["policies"] == "ok"
    assert "fails at every value flown" not in r.stdout
    assert "none (the law failed, not the criterion: law_failed at 16; " in r.stdout and says in r.stdout, r.stdout
    assert f"{laws}:Raises could not be flown at delay_ms = 16 (seed 0, law_failed): " in r.stderr, r.stderr


def test_a_probes_unsearched_columns_are_the_wind_and_link_it_flew(tmp_path: Path, here) -> None:
    """Each cell of margin.json says the wind the probe flew: the mission's ``[wind] speed_mps = 5`` (the cells
    held the searched axis alone, the probes' rows 0 m/s, until the forty-fifth session; the flight flew 5)."""
    mission = tmp_path / "windy.toml"
    mission.write_text(dump_toml(SHORT.with_overrides(wind={"speed_mps": 5.0}).to_dict()))
    r = here("margin", str(mission), "--over", "delay_ms", "--until", "rms=0.05", "--resolution", "16",
             "--check-below", "0", "--out", str(tmp_path / "m"))
    assert r.returncode == 0, r.stderr
    cells = json.loads((tmp_path / "m" / "margin.json").read_text())["controllers"][0]["cells"]
    assert cells and all(c["wind_mps"] == 5.0 for c in cells), cells
