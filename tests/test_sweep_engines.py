"""Covers bridge.sweep.executors, bridge.core.kernelwarm and bridge.batch.

``bsst sweep --engine batch | process | auto``: the same cells.csv rows from either engine (a link grid, and a
grid of wind, turbulence and laws: issue 27),
``--resume`` with the batch, and an engine that cannot be honoured refused in one line; the
``discretization`` axis (issue 24) in both engines, on the command line and in a sweep file.

The cell-by-cell agreement of the batch with the scalar loop over every link feature is
tests/test_batch.py's; here the sweep's own path is checked end to end: grid -> engine ->
rows -> cells.csv, the command line run by its ``main`` in this process (its lines, files and refusals are the
point, not a process's start: a forked ``bsst sweep`` imports numba and loads the batch's kernels again).
"""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import pytest

from bridge import simulate
from bridge.cli import main
from bridge.core.flight import prepare
from bridge.sweep import CELLS_CSV, COLUMNS, Grid, Sweep, load_sweep, read_cells, sweep
from bridge.sweep.cells import FLEET_COLUMNS
from bridge.sweep.executors import BATCH_MIN_CELLS, WARM_CELLS, engine_for
from bridge.sweep.grid import LINK_AXES, cells, mission_value
from bridge.sweep.margin import margin, parse_until, probe
from bridge.sweep.report import recorded_cell_count
from missions import Mission, Sine
from params import ConfigError, dump_toml

# starts processes or opens sockets (not in make test-fast); flies the batch engine (its kernels loaded first)
pytestmark = [pytest.mark.process, pytest.mark.usefixtures("batch_kernels")]

ROOT = Path(__file__).resolve().parents[1]
# 3 s: the sweep's path end to end (grid, engine, rows, cells.csv); the engines' agreement over longer flights is
# tests/test_batch.py's
SHORT = Mission(Sine(), duration_s=3.0, name="short")
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


def test_a_wind_turbulence_and_law_grid_gives_the_same_rows_with_either_engine(tmp_path: Path) -> None:
    """Issue 27's batch agreement: steady wind (0, 6 m/s) x turbulence (none, moderate) x the three laws; the
    batch flies each cell's own turbulence samples (its seed's: bridge.batch.weather), so its cells.csv rows are
    the process engine's within what the batch keeps (bsst, pid 1e-6; smc 1 %)."""
    short = Mission(Sine(), duration_s=3.0, name="short3", end_action="hold")  # (a landing in wind: not batched)
    grid = Grid(controller=("bsst", "pid", "smc"), wind_mps=(0.0, 6.0), turbulence=("none", "moderate"))
    batch = sweep(short, grid, engine="batch", out=tmp_path / "b", report=False)
    process = sweep(short, grid, engine="process", jobs=2, out=tmp_path / "p", report=False)
    assert len(batch) == len(process) == 12
    for a, b in zip(batch, process, strict=True):
        assert (a["wind_mps"], a["turbulence"]) == (b["wind_mps"], b["turbulence"])
        _same(a, b)
    rms = {(r["controller"], r["wind_mps"], r["turbulence"]): r["rms"] for r in batch}
    for law in grid.controller:  # the turbulence is flown, not ignored
        assert rms[law, 6.0, "moderate"] != rms[law, 6.0, "none"] and rms[law, 0.0, "moderate"] != rms[law, 0.0, "none"]


def test_a_mission_that_lands_in_wind_flies_on_the_process_engine_which_judges_its_landing(tmp_path: Path) -> None:
    """The batch flies no end action: a windy grid whose mission ends in a landing read ``completed`` there where
    the process engine, which flies the landing, said ``crashed`` (the sine at 40 m/s in severe turbulence; the x500
    at 25 m/s). ``auto`` flies it on the process engine and says why; ``--engine batch`` is refused; ending in a
    hold, or in still air at the end (a wind event back to 0, a gust over), it is batched."""
    from bridge.batch.scope import air_at_end

    sine = Mission(Sine(), duration_s=3.0, name="short3")
    windy = cells(sine, Grid(wind_mps=tuple(float(w) for w in range(BATCH_MIN_CELLS))))
    engine, why = engine_for(sine, windy, "offline", "auto")
    said = "the batch engine cannot fly this grid: a steady wind of 1 m/s at the mission's end: its end landing"
    assert engine == "process" and why.startswith(said), why
    with pytest.raises(ConfigError, match=r"^--engine batch: a steady wind of 1 m/s at the mission's end: .*"
                                          r"flies in the batch\); fly it with --engine process$"):
        engine_for(sine, windy, "offline", "batch")
    assert engine_for(replace(sine, end_action="hold"), windy, "offline", "auto")[0] == "batch"
    calm = {"at": ("1:wind:5:90", "2:wind:0", "0.5:gust:1,2")}  # blown, then still before the end
    assert air_at_end(prepare(sine, **calm)) is None
    for over, says in (({"wind": {"speed_mps": 0.0, "turbulence": "light"}}, "light turbulence"),
                       ({"at": ("1:wind:5:90",)}, "a steady wind of 5 m/s"),
                       ({"at": ("2.5:gust:2,1",)}, "a gust from t = 2.5 s not over"),
                       ({"wind": {"speed_mps": 0.0, "gusts": [[2.0, 2.0, 3.0, 0.0]]}}, "a gust from t = 2 s not over")):
        assert air_at_end(prepare(sine, **over)) == says, over


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
def test_an_engine_that_cannot_be_honoured_is_refused_in_one_line(tmp_path: Path, capsys, monkeypatch,
                                                                   extra: list[str], names: str) -> None:
    monkeypatch.chdir(ROOT)  # (the mission and the law file named from the repository's folder)
    capsys.readouterr()
    assert main(["sweep", "missions/sine.toml", "--delay", "0,5", "--engine", "batch", "--out", str(tmp_path / "s"),
                 *extra]) == 2
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and names in lines[0], err
    assert not (tmp_path / "s").exists()


def test_the_command_line_says_which_engine_flew(tmp_path: Path, capsys) -> None:
    short = tmp_path / "short.toml"  # the sine cut to 3 s: the engine and its reason do not depend on the length
    short.write_text((ROOT / "missions" / "sine.toml").read_text().replace("duration_s = 30.0", "duration_s = 3.0"))
    capsys.readouterr()
    assert main(["sweep", str(short), "--delay", "0,5", "--out", str(tmp_path / "s"), "--no-plots"]) == 0
    assert f"engine process (fewer than {BATCH_MIN_CELLS} cells to fly)" in capsys.readouterr().out


# the commands as a user starts them, in one process that says after each whether numba was imported, then which
# engine a grid of BATCH_MIN_CELLS cells would take
NO_NUMBA_SCRIPT = """
import json, sys
from bridge.cli import main
out = []
for argv in json.loads(sys.argv[1]):
    out.append([main(argv), "numba" in sys.modules])
from bridge.sweep.executors import engine_for
from bridge.sweep.grid import Grid, cells
from missions import load_mission
m = load_mission("short.toml")
big = cells(m, Grid(delay_ms=tuple(float(d) for d in range(int(sys.argv[2])))))
print(json.dumps({"runs": out, "big": list(engine_for(m, big, "offline", "auto")), "numba": "numba" in sys.modules}))
"""


def test_a_small_sweep_or_a_margin_the_batch_cannot_fly_imports_no_numba(tmp_path: Path) -> None:
    """``--engine auto`` asks what the batch can fly before it counts the cells (its reason names that first), and
    that check imported the batch engine and numba with it (~0.25 CPU-s of a 2-cell sweep's ~0.55 in its main
    process) for a grid then flown on the process engine; a ``bsst margin`` the batch cannot fly (over sensor noise)
    likewise. Now neither imports numba (bridge.batch.scope), a large grid still takes the batch, and the reasons
    are the same (a real command in a fresh process: ``sys.modules`` read after each)."""
    (tmp_path / "short.toml").write_text('name = "short"\nduration_s = 1.0\n[trajectory]\nkind = "sine"\n')
    runs = [["sweep", "short.toml", "--delay", "0,5", "--no-plots", "--out", "s"],
            ["margin", "short.toml", "--over", "noise", "--sensors", "mocap", "--estimator", "raw", "--until",
             "rms=0.5", "--out", "m"]]
    env = {k: v for k, v in os.environ.items() if k != "BSST_KERNELS"}  # (auto: no kernels loaded unasked)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH")]))
    r = subprocess.run([sys.executable, "-c", NO_NUMBA_SCRIPT, json.dumps(runs), str(BATCH_MIN_CELLS)],
                       capture_output=True, text=True, timeout=300, cwd=tmp_path, env=env)
    assert r.returncode == 0, r.stderr[-3000:]
    out = json.loads(r.stdout.strip().splitlines()[-1])
    assert out == {"runs": [[0, False], [0, False]], "big": ["batch", "the grid allows it"], "numba": False}, out
    assert f"engine process (fewer than {BATCH_MIN_CELLS} cells to fly)" in r.stdout
    assert [r["outcome"] for r in read_cells(tmp_path / "s" / CELLS_CSV)] == ["completed"] * 2


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


def test_jobs_changes_no_row_of_a_batch_sweep_or_margin(tmp_path: Path, capsys) -> None:
    """``--jobs N``: the batch engine's threads (bridge.batch.engine) fly blocks of cells in whatever order
    they come free; ``bsst sweep --engine batch`` writes the same cells.csv, byte for byte, with 1 and 2,
    and ``bsst margin`` finds the same margin from the same cells."""
    short = tmp_path / "short.toml"
    short.write_text((ROOT / "missions" / "sine.toml").read_text().replace("duration_s = 30.0", "duration_s = 3.0"))
    outs = {}
    for jobs in (1, 2):
        capsys.readouterr()
        assert main(["sweep", str(short), "--delay", "0,6,12", "--loss", "0,20", "--controller", "bsst,pid",
                     "--seeds", "3", "--engine", "batch", "--jobs", str(jobs), "--out", str(tmp_path / f"s{jobs}"),
                     "--no-plots"]) == 0
        said = capsys.readouterr().out
        assert "engine batch" in said, said
        outs[jobs] = (tmp_path / f"s{jobs}" / CELLS_CSV).read_text()
    assert len(outs[1].splitlines()) == 1 + 36
    assert outs[1] == outs[2]
    found = [margin(SHORT, "delay_ms", parse_until("rms=0.01"), controllers=("bsst", "pid"), seeds=2, resolution=4.0,
                    below=8.0, jobs=jobs, engine="batch") for jobs in (1, 2)]
    assert found[0] == found[1] and found[0]["cells_flown"] > 4


SCHEMES = Grid(controller=("bsst", "smc"), discretization=("explicit", "implicit"), delay_ms=(0.0, 8.0))


def test_a_discretization_axis_flies_each_scheme_in_both_engines(tmp_path: Path) -> None:
    """Issue 24: ``discretization`` is an axis: each row names its scheme and is the one ``simulate`` of that
    law, scheme and delay (the process engine's to the bit, the batch's as for every law); bsst flies each
    scheme its own way; smc (no super-twisting step) one cell per delay, its discretization empty: the one
    ``simulate`` without a scheme, which refuses one for smc (as ``bsst sim`` does). Until the third wave's
    thirty-ninth session smc was flown once per scheme, the same flight under two labels."""
    assert Sweep(SHORT, SCHEMES).cell_count() == len(Sweep(SHORT, SCHEMES).cells()) == 6  # (announced, and capped)
    rows = {e: sweep(SHORT, SCHEMES, engine=e, jobs=2, out=tmp_path / e, report=False) for e in ("batch", "process")}
    for a, b in zip(rows["batch"], rows["process"], strict=True):
        assert a["discretization"] == b["discretization"]
        _same(a, b)
    got = rows["process"]
    assert [(r["controller"], r["delay_ms"], r["discretization"]) for r in got] == [
        ("bsst", d, s) for d in (0.0, 8.0) for s in ("explicit", "implicit")] + [("smc", 0.0, ""), ("smc", 8.0, "")]
    for r in got:
        run = simulate(SHORT, controller=r["controller"], discretization=r["discretization"] or None,
                       link={"up": {"delay_ms": r["delay_ms"]}, "down": {"delay_ms": r["delay_ms"]}})
        assert (run.rms, run.summary["inputs"]["u2"]["tv_per_s"]) == (r["rms"], r["tv_u2"]), r
    by = {(r["controller"], r["delay_ms"], r["discretization"]): r for r in got}
    for d in (0.0, 8.0):
        assert by[("bsst", d, "implicit")]["rms"] != by[("bsst", d, "explicit")]["rms"]
    assert [r["discretization"] for r in read_cells(tmp_path / "batch" / CELLS_CSV)] == ["explicit", "implicit"] * 2 \
        + ["", ""]  # (the empty field reads back)
    assert "discretization" in (tmp_path / "batch" / CELLS_CSV).read_text().splitlines()[0].split(",")
    ident = json.loads((tmp_path / "batch" / "sweep.json").read_text())
    assert ident["axes"]["discretization"] == ["explicit", "implicit"] and "discretization" in ident["swept"]


def test_the_discretization_axis_on_the_command_line_and_in_a_sweep_file(tmp_path: Path, capsys) -> None:
    """``bsst sweep --discretization explicit,implicit``: rows and report name the scheme, the report's
    reproduction line carries it; one scheme is an axis of one value; a bad one is one line, exit 2; a sweep
    file's ``[grid] discretization``; without the flag every cell flies the mission's own scheme."""
    mission = tmp_path / "short.toml"
    mission.write_text(dump_toml(SHORT.with_overrides(discretization="implicit").to_dict()))
    out = tmp_path / "both"
    assert main(["sweep", str(mission), "--discretization", "explicit,implicit", "--out", str(out),
                 "--no-plots"]) == 0
    rows = read_cells(out / CELLS_CSV)
    assert [r["discretization"] for r in rows] == ["explicit", "implicit"]
    report = (out / "report.md").read_text()
    assert "| bsst (explicit) | 1 |" in report and "| bsst (implicit) | 1 |" in report, report
    assert "--discretization explicit --seed" in report
    one = tmp_path / "one"
    assert main(["sim", str(out / "mission.toml"), "--discretization", "explicit", "--no-plots", "--out",
                 str(one)]) == 0
    assert json.loads((one / "summary.json").read_text())["rms_3d"] == rows[0]["rms"]
    assert main(["sweep", str(mission), "--delay", "0", "--out", str(tmp_path / "own"), "--no-plots"]) == 0
    assert [r["discretization"] for r in read_cells(tmp_path / "own" / CELLS_CSV)] == ["implicit"]
    assert read_cells(tmp_path / "own" / CELLS_CSV)[0]["rms"] == rows[1]["rms"]
    capsys.readouterr()
    assert main(["sweep", str(mission), "--discretization", "explicit,trapezoid", "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--discretization takes distinct names among explicit,implicit" in err, err
    f = tmp_path / "s.toml"
    f.write_text(f'mission = "{mission}"\n[grid]\ndiscretization = ["explicit"]\n')
    assert [c.discretization for c in load_sweep(f).cells()] == ["explicit"]
    f.write_text(f'mission = "{mission}"\n[grid]\ndiscretization = ["semi"]\n')
    with pytest.raises(ConfigError, match="discretization: element 0 must be one of explicit, implicit"):
        load_sweep(f)


def test_a_law_without_a_scheme_is_one_cell_announced_reported_and_resumed(tmp_path: Path, capsys) -> None:
    """``bsst sweep --controller bsst,smc --discretization explicit,implicit``: 3 cells, not 4 (smc has no
    super-twisting step: one cell, its discretization empty), as the command's count, cells.csv and report.md say;
    ``--resume`` of an older sweep's cells.csv, whose smc cell is two rows labelled explicit and implicit (the same
    flight), keeps one of them as that cell, flies only what is missing, and ends with the file a new sweep writes."""
    mission = tmp_path / "short.toml"
    mission.write_text(dump_toml(replace(SHORT, duration_s=1.0).to_dict()))
    out = tmp_path / "s"
    args = ["sweep", str(mission), "--controller", "bsst,smc", "--discretization", "explicit,implicit", "--jobs", "1",
            "--out", str(out), "--no-plots"]
    capsys.readouterr()
    assert main(args) == 0
    assert ": 3 cells, 3 flown" in capsys.readouterr().out
    text = (out / CELLS_CSV).read_text()
    rows = read_cells(out / CELLS_CSV)
    assert [(r["controller"], r["discretization"]) for r in rows] == [("bsst", "explicit"), ("bsst", "implicit"),
                                                                      ("smc", "")]
    report = (out / "report.md").read_text()
    assert "| smc | 1 |" in report and "| bsst (implicit) | 1 |" in report, report
    assert "- `discretization`: explicit, implicit (swept); none for smc (no super-twisting step" in report, report
    header, bsst_explicit, bsst_implicit, smc = text.splitlines()
    older = [header, bsst_explicit, smc.replace(",,1,0,", ",explicit,1,0,"), smc.replace(",,1,0,", ",implicit,1,0,")]
    assert older[2] != smc and older[3] != smc  # (the empty discretization field, labelled as before)
    (out / CELLS_CSV).write_text("\n".join(older) + "\n")  # bsst's implicit cell not flown yet
    capsys.readouterr()
    assert main([*args, "--resume"]) == 0
    assert ": 3 cells, 1 flown, 2 kept from before" in capsys.readouterr().out
    assert (out / CELLS_CSV).read_text() == text
    assert recorded_cell_count(json.loads((out / "sweep.json").read_text())) == 3  # (a report of it: complete)


def test_an_older_sweep_without_the_discretization_column_is_reported(tmp_path: Path) -> None:
    """A cells.csv written before the axis (issue 24) reads with its mission's scheme (explicit before it)."""
    out = tmp_path / "old"
    sweep(SHORT, Grid(delay_ms=(0.0,)), out=out, jobs=1, report=False)
    keep = [i for i, c in enumerate(COLUMNS) if c not in ("discretization", *FLEET_COLUMNS, "policies",
                                                          "jitter_capped")]
    lines = (out / CELLS_CSV).read_text().splitlines()
    (out / CELLS_CSV).write_text("".join(",".join(line.split(",")[i] for i in keep) + "\n" for line in lines))
    meta = json.loads((out / "sweep.json").read_text())
    del meta["mission"]["discretization"]
    (out / "sweep.json").write_text(json.dumps(meta))
    assert main(["report", str(out), "--no-plots"]) == 0
    assert "- `discretization`: explicit" in (out / "report.md").read_text()
    lacks = "no discretization, vehicles, worst_vehicle, closest_m, policies, jitter_capped columns"
    with pytest.raises(ConfigError, match=f"a cells.csv of an older bsst \\({lacks}\\)"):
        read_cells(out / CELLS_CSV)
    shutil.rmtree(out)


def test_a_margin_probes_the_missions_own_scheme() -> None:
    """``bsst margin --discretization implicit``: every probe cell flies the scheme laid over the mission."""
    m = SHORT.with_overrides(discretization="implicit")
    base = {a: float(mission_value(m, a)) for a in LINK_AXES}
    vehicle = {"estimator": "truth", "noise": 1.0, "turbulence": "none", "wind_mps": 0.0}
    for over in ("delay_ms", "noise", "wind_mps"):
        assert probe(m, "bsst", over, 1.0, 0, base, vehicle).discretization == "implicit"


POOL_SCRIPT = """
import json, sys
from multiprocessing import forkserver
from bridge.sweep import Grid, sweep
from missions import Mission, Sine
if sys.argv[2] == "held":  # this process flies compiled already (a script's earlier flights, a test worker)
    from bridge.core.flight import load_compiled_kernels
    load_compiled_kernels(ekf=False)
delays = tuple(float(d) for d in range(int(sys.argv[1])))
rows = sweep(Mission(Sine(), duration_s=0.2, name="k"), Grid(delay_ms=delays), jobs=2, engine="process")
pid = forkserver._forkserver._forkserver_pid  # the pool's fork server: every worker is forked from it
with open(f"/proc/{pid}/maps") as f:
    print(json.dumps({"outcomes": [r["outcome"] for r in rows], "kernels_loaded": "llvmlite" in f.read()}))
"""


@pytest.mark.parametrize("kernels, cells, held, loaded", [("compiled", 2, "", True), ("plain", 4, "", False),
                                                          ("auto", 2, "", False), ("auto", 4, "", True),
                                                          ("auto", 2, "held", True)])
def test_the_process_pools_workers_are_forked_with_the_compiled_kernels_loaded_when_asked(kernels: str, cells: int,
                                                                                         held: str,
                                                                                         loaded: bool) -> None:
    """``BSST_KERNELS=compiled``: the process engine's pool loads the kernels once, in the fork server its workers
    are forked from (bridge.core.kernelpreload), not in each worker (~1 s of CPU each: the suite's sweep files
    took 113 CPU-s with the kernels loaded per worker, 83 so); under ``auto`` it does so for a grid of at least
    WARM_CELLS offline cells (bridge.core.kernelwarm: ``auto`` then flies them), or for any grid of a process that
    holds them already (the first pool's preload stays for the process's later pools: a test worker's first pool of
    two cells left every later grid of that worker flying plain, ~2.5x the CPU), and for a smaller one, or with
    ``plain``, it does not load numba at all."""
    assert WARM_CELLS == 4
    r = subprocess.run([sys.executable, "-c", POOL_SCRIPT, str(cells), held], capture_output=True, text=True,
                       timeout=300, cwd=ROOT, env={**os.environ, "BSST_KERNELS": kernels})
    assert r.returncode == 0, r.stderr[-3000:]
    out = json.loads(r.stdout.strip().splitlines()[-1])
    assert out == {"outcomes": ["completed"] * cells, "kernels_loaded": loaded}, out


FORK_SERVER_SIGINT = """
import multiprocessing as mp, os, signal, sys
mp.get_context("forkserver").set_forkserver_preload(["sigint_probe"])
from bridge.sweep.executors import _start_fork_server
_start_fork_server()
print(signal.getsignal(signal.SIGINT) is signal.default_int_handler)
from tests.waiting import wait_for  # the fork server ends with this process: wait for its preload's word
wait_for(lambda: os.path.exists(sys.argv[2]) and open(sys.argv[2]).read() != "", 60.0, "the fork server's preload")
print(open(sys.argv[2]).read())
"""


def test_the_fork_server_ignores_ctrl_c_from_its_birth(tmp_path: Path) -> None:
    """The sweep's fork server is started with SIGINT ignored, so a Ctrl-C while it imports its preload list (before
    CPython's own SIG_IGN, after it) no longer kills it with a traceback of its own: a module it preloads finds
    SIGINT ignored (its SigIgn), and the sweep's process has its own handler back."""
    seen = tmp_path / "sigign"
    (tmp_path / "sigint_probe.py").write_text(
        "import os, signal\n"
        "line = next(x for x in open('/proc/self/status') if x.startswith('SigIgn'))\n"
        f"open({str(seen)!r}, 'w').write(str(bool(int(line.split()[1], 16) & (1 << (signal.SIGINT - 1)))))\n")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}  # (the fork server's path too)
    env["PYTHONPATH"] = os.pathsep.join([str(tmp_path), *filter(None, [os.environ.get("PYTHONPATH")])])
    r = subprocess.run([sys.executable, "-c", FORK_SERVER_SIGINT, str(tmp_path), str(seen)], capture_output=True,
                       text=True, timeout=120, env=env, cwd=Path(__file__).parent.parent)
    assert r.returncode == 0 and r.stdout.split() == ["True", "True"], (r.stdout, r.stderr)
