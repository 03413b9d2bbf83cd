"""Covers missions.scatter: ``[start] scatter_m`` and ``--scatter``, each seed's flight begun at its own start
around the mission's, in both engines, in lockstep, in the run's records, and from the command line."""

from __future__ import annotations

import json
import subprocess
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from bridge import simulate
from bridge.batch.engine import fly_batch
from bridge.cli import main
from bridge.core.flight import prepare
from missions import Mission, Sine, load_mission, mission_from_table
from missions.scatter import scattered_start
from params import ConfigError, dump_toml
from tests.sitlkit import run_bsst

# starts processes (bsst margin, sim, sitl): not in make test-fast; flies the batch engine (its kernels loaded first)
pytestmark = [pytest.mark.process, pytest.mark.usefixtures("batch_kernels")]

START = (1.0, -2.0, 0.0, 0.3)


def test_no_scatter_is_the_start_itself() -> None:
    assert scattered_start(START, 0.0, 7) is START


def test_each_seed_draws_its_start_uniformly_in_the_horizontal_disc() -> None:
    starts = [scattered_start(START, 0.5, k) for k in range(2000)]
    assert starts[:5] == [scattered_start(START, 0.5, k) for k in range(5)]  # the seed's, every time
    assert len(set(starts)) == len(starts)
    assert all(z == START[2] and psi == START[3] for _, _, z, psi in starts)  # still on its pad, same heading
    off = np.array([(x - START[0], y - START[1]) for x, y, _, _ in starts])
    r = np.hypot(off[:, 0], off[:, 1])
    assert r.max() <= 0.5
    # uniform in area: a quarter of the draws within half the radius (binomial sd 0.0097), no direction favoured
    assert abs(np.mean(r <= 0.25) - 0.25) < 0.05
    assert np.all(np.abs(off.mean(axis=0)) < 0.03)  # sd of each mean 0.0056


def _sine(seconds: float = 12.0) -> Mission:
    """The sine cut to ``seconds``: 4 s where two engines' or two seeds' flights are compared, 6 s for a delay margin
    (the sine's RMS over its second half under 10 cm at no delay: 18 cm at 3 s), 3 s where a start and a report's
    words are the point, 1 s for a mission file written."""
    return replace(load_mission("missions/sine.toml"), duration_s=seconds)


def _here(capsys: pytest.CaptureFixture[str], *argv: str | Path) -> subprocess.CompletedProcess[str]:
    """``bsst ARGV`` run by the command line's ``main`` in this process: its exit status, stdout and stderr, as
    :func:`tests.sitlkit.run_bsst` gives a forked one's (without a process that imports numba and starts its own
    pool)."""
    capsys.readouterr()
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return subprocess.CompletedProcess(["bsst", *map(str, argv)], code, out, err)


def test_the_mission_file_takes_scatter_m_and_refuses_it_out_of_range(tmp_path: Path) -> None:
    m = replace(_sine(), start_scatter_m=0.02)
    back = mission_from_table(m.to_dict(), "<test>")
    assert back.start_scatter_m == 0.02 and back.start == m.start
    assert "scatter_m" not in _sine().to_dict()["start"]  # none: mission.toml as before
    for value, words in (("-0.5", "[0, 100]"), ("101", "[0, 100]"), ('"wide"', "expected a number")):
        f = tmp_path / "bad.toml"
        f.write_text(dump_toml(m.to_dict()).replace("scatter_m = 0.02", f"scatter_m = {value}"))
        with pytest.raises(ConfigError) as exc:
            load_mission(f)
        assert str(exc.value).startswith(f"{f}: start.scatter_m:") and words in str(exc.value), str(exc.value)
    with pytest.raises(ConfigError, match=r"start.scatter_m: must be in \[0, 100\] m; got nan"):
        replace(m, start_scatter_m=float("nan"))
    with pytest.raises(ConfigError, match=r"start.position: the start with its scatter is 100.5 m"):
        Mission(Sine(), 10.0, start=(99.0, 0.0, 0.0, 0.0), start_scatter_m=1.5)
    fleet = {**m.to_dict(), "vehicles": [{"offset": [0.0, 0.0, 0.0]}, {"offset": [2.0, 0.0, 0.0]}]}
    with pytest.raises(ConfigError, match="start.scatter_m: a fleet's starts are its formation's"):
        mission_from_table(fleet, "<test>")


def test_the_vehicle_rests_at_its_seeds_start_and_calls_it_home() -> None:
    for seed in (0, 5):
        f = prepare(_sine(), seed=seed, scatter_m=0.01)
        x, y, z, psi = f.mission.flight_start
        v = f.make_vehicle()
        assert (v.plant.state[0], v.plant.state[2], v.plant.state[4], v.plant.state[10]) == (x, y, z, psi)
        assert v.home == (x, y, z)
        assert 0.0 < np.hypot(x, y) <= 0.01


def test_seeds_fly_one_flight_without_scatter_and_several_with_it() -> None:
    """The sine draws nothing at random: every seed flies the same flight. Scattered, each its own."""
    link = {"up": {"delay_ms": 20.0}, "down": {"delay_ms": 20.0}}
    same = {simulate(_sine(4.0), seed=s, link=link, plots=False).summary["rms_3d"] for s in (0, 1)}
    assert len(same) == 1
    own = {simulate(_sine(4.0), seed=s, scatter_m=0.01, link=link, plots=False).summary["rms_3d"] for s in (0, 1)}
    assert len(own) == 2


def test_the_batch_engine_flies_each_seeds_start_as_the_scalar_loop_does() -> None:
    m = replace(_sine(4.0), start_scatter_m=0.01)
    cells = [{"controller": law, "seed": s, "link": {"delay_ms": d}}
             for law in ("bsst", "pid") for s in (0, 3) for d in (0.0, 10.0)]
    rows = fly_batch(m, cells)
    for cell, got in zip(cells, rows, strict=True):
        want = simulate(m, plots=False, **cell).summary
        assert got["outcome"] == "completed", (cell, got)
        assert got["rms"] == pytest.approx(want["rms_3d"], rel=1e-6), (cell, got["rms"], want["rms_3d"])


def test_margin_over_scattered_starts_records_them(tmp_path: Path, capsys) -> None:
    """``bsst margin --scatter`` run by the command line's ``main`` in this process (its lines and margin.json are the
    point: tests/test_margin_interrupt.py runs ``bsst margin`` as a real process)."""
    f = tmp_path / "sine6.toml"
    f.write_text(dump_toml(_sine(6.0).to_dict()))
    r = _here(capsys, "margin", f, "--over", "delay_ms", "--until", "rms=0.1", "--seeds", "2", "--scatter", "0.01",
              "--resolution", "1", "--check-below", "0", "--out", tmp_path / "m")
    assert r.returncode == 0, r.stderr
    assert "each value from 2 starts within 0.01 m of the mission's" in r.stdout, r.stdout
    res = json.loads((tmp_path / "m" / "margin.json").read_text())
    law = res["controllers"][0]  # margin.json: one entry per law, one law here
    assert res["start_scatter_m"] == 0.01 and res["seeds"] == [0, 1] and law["margin"] > 0
    assert law["seeds_alike"] is False and "flew the same flight" not in r.stderr
    # without the scatter the two seeds fly one flight twice: margin.json and a warning say so
    same = _here(capsys, "margin", f, "--over", "delay_ms", "--until", "rms=0.1", "--seeds", "2", "--resolution", "1",
                 "--check-below", "0", "--out", tmp_path / "m2")
    assert same.returncode == 0, same.stderr
    assert json.loads((tmp_path / "m2" / "margin.json").read_text())["controllers"][0]["seeds_alike"] is True
    assert "warning: the 2 seeds of each value flew the same flight" in same.stderr and "--scatter M" in same.stderr
    bad = run_bsst("margin", f, "--over", "delay_ms", "--until", "rms=0.1", "--scatter", "-1")  # a real process
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1 and "--scatter" in bad.stderr, bad.stderr
    assert "[0, 100]" in bad.stderr and "Traceback" not in bad.stderr


def test_a_scattered_sim_writes_its_scatter_into_the_runs_mission(tmp_path: Path) -> None:
    f = tmp_path / "sine1.toml"
    f.write_text(dump_toml(_sine(1.0).to_dict()))
    r = run_bsst("sim", f, "--seed", "4", "--scatter", "0.01", "--no-plots", "--out", tmp_path / "run")
    assert r.returncode == 0, r.stderr
    again = load_mission(tmp_path / "run" / "mission.toml")
    assert again.start_scatter_m == 0.01 and again.seed == 4
    assert again.flight_start == prepare(f, seed=4, scatter_m=0.01).mission.flight_start


def test_lockstep_flies_the_scattered_start_as_offline_does(tmp_path: Path) -> None:
    """The vehicle process draws its start from the run's mission and seed: the same flight, bit for bit."""
    f = tmp_path / "sine3.toml"
    f.write_text(dump_toml(_sine(3.0).to_dict()))
    for cmd in ("sitl", "sim"):
        r = run_bsst(cmd, f, "--seed", "2", "--scatter", "0.01", "--no-plots", "--out", tmp_path / cmd)
        assert r.returncode == 0, r.stderr
    traces = [np.genfromtxt(tmp_path / cmd / "trace.csv", delimiter=",", names=True) for cmd in ("sitl", "sim")]
    x0, y0, _, _ = prepare(f, seed=2, scatter_m=0.01).mission.flight_start
    assert (traces[0]["x"][0], traces[0]["y"][0]) == (x0, y0)
    for col in ("x", "y", "z", "phi", "theta"):
        assert np.array_equal(traces[0][col], traces[1][col]), col


def test_a_sweeps_report_says_what_its_seeds_drew(tmp_path: Path, capsys) -> None:
    """Scattered, each seed its own start (and the sweep's mission.toml keeps it); not, the sine's seeds fly one
    flight: the report says they added nothing. (``bsst sweep`` by ``main`` in this process: its report is the
    point.)"""
    f = tmp_path / "sine3.toml"
    f.write_text(dump_toml(_sine(3.0).to_dict()))
    lines = {}
    for name, extra in (("scattered", ["--scatter", "0.01"]), ("plain", [])):
        r = _here(capsys, "sweep", f, "--delay", "0,20", "--seeds", "2", *extra, "--no-plots", "--out", tmp_path / name)
        assert r.returncode == 0, r.stderr
        lines[name] = (tmp_path / name / "report.md").read_text().splitlines()
    assert "- start: each seed's own, within 0.01 m of the mission's (`[start] scatter_m`)" in lines["scattered"]
    assert load_mission(tmp_path / "scattered" / "mission.toml").start_scatter_m == 0.01
    assert not any("flew the same flight" in s for s in lines["scattered"])
    assert any(s.startswith("- the seeds of every grid point flew the same flight") for s in lines["plain"])


def test_over_sixteen_starts_the_implicit_scheme_keeps_the_explicit_laws_delay_margin() -> None:
    """docs/law.md, "One initial condition": one start gives the sine's explicit law 36 ms and the implicit scheme
    35 (tests/test_margin.py); 16 starts within 1 cm, every one of which must hold, give 32 and 33 ms."""
    from bridge.sweep.margin import margin, parse_until

    m = replace(load_mission("missions/sine.toml"), start_scatter_m=0.01)
    found = {d: margin(replace(m, discretization=d), "delay_ms", parse_until("rms=0.1"), seeds=16, below=0.0)
             for d in ("explicit", "implicit")}
    assert {d: r["controllers"][0]["margin"] for d, r in found.items()} == {"explicit": 32.0, "implicit": 33.0}
    assert all(r["controllers"][0]["seeds_alike"] is False and r["start_scatter_m"] == 0.01 for r in found.values())
