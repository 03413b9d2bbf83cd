"""Covers bridge.sweep and bridge.cli: ``--vehicles`` as a sweep axis (a cell of N vehicles is one fleet's flight).

A real sweep (its worker pool) of a 1 s sine over ``--vehicles 1,2`` and two loss values: each row names its
vehicle count; a fleet's row holds its worst vehicle's figures (the largest RMS, the worst outcome), its vehicles'
packets summed, which vehicle was worst and the closest approach; the batch engine refuses fleets and ``auto``
falls back to the process engine saying why; lockstep fleets, fractional sizes and a fleet outside the envelope
are refused before any cell flies; a ``cells.csv`` of before the axis reads as one vehicle.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from bridge.cli import main
from bridge.swarm import simulate
from bridge.sweep import CELLS_CSV, COLUMNS, Grid, Sweep, read_cells
from bridge.sweep.cells import FLEET_COLUMNS
from bridge.sweep.executors import engine_for
from bridge.sweep.grid import FLEET_FORMATION, cell_overrides, cells
from bridge.sweep.report import legacy_values
from missions import MISSION_DIR, load_mission
from params import ConfigError

pytestmark = [pytest.mark.process, pytest.mark.usefixtures("batch_kernels")]  # a sweep's worker pool


def short_sine(tmp_path: Path) -> Path:
    f = tmp_path / "short.toml"
    f.write_text((MISSION_DIR / "sine.toml").read_text().replace("duration_s = 30.0", "duration_s = 1.0"))
    return f


def test_a_sweep_over_vehicles_writes_one_row_per_fleet_with_its_worst_vehicle(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    mission, out = short_sine(tmp_path), tmp_path / "sw"
    assert main(["sweep", str(mission), "--vehicles", "1,2", "--loss", "0,30", "--jobs", "1", "--no-plots",
                 "--out", str(out)]) == 0
    said = capsys.readouterr().out
    assert "engine process (the batch engine cannot fly this grid: cells of 2 vehicles (--vehicles) fly a fleet" \
        in said, said
    rows = read_cells(out / CELLS_CSV)
    assert [(r["loss_pct"], r["vehicles"]) for r in rows] == [(0.0, 1), (0.0, 2), (30.0, 1), (30.0, 2)]
    one, pair = rows[2], rows[3]
    assert one["worst_vehicle"] is None and one["closest_m"] is None
    m = load_mission(mission)
    cell = [c for c in cells(m, Grid(vehicles=(2,), loss_pct=(30.0,)))][0]
    fleet = simulate(m, vehicles=2, formation=FLEET_FORMATION, overrides=cell_overrides(cell), plots=False)
    rms = [v["rms_3d"] for v in fleet.summary["vehicles"]]
    assert rms[0] != rms[1]  # each vehicle's own seed: the worst is one of them
    assert pair["rms"] == max(rms) and pair["worst_vehicle"] == 1 + rms.index(max(rms))
    assert one["rms"] == rms[0]  # vehicle 1 of a fleet flies the mission's one vehicle
    assert pair["up_sent"] == 2 * one["up_sent"] and pair["outcome"] == "completed"
    assert pair["closest_m"] == pytest.approx(2.0 - 2 * 0.315, abs=1e-3)
    meta = json.loads((out / "sweep.json").read_text())
    assert meta["grid"]["vehicles"] == [1, 2] and "vehicles" in meta["swept"]
    # a cells.csv of before the axis (no fleet columns; its one-vehicle rows: a row per cell) reads as one vehicle each
    keep = [i for i, c in enumerate(COLUMNS) if c not in (*FLEET_COLUMNS, "policies", "jitter_capped")]  # before fleets
    lines = [ln for ln in (out / CELLS_CSV).read_text().splitlines() if ln.split(",")[COLUMNS.index("vehicles")] != "2"]
    old = tmp_path / "old.csv"
    old.write_text("".join(",".join(ln.split(",")[i] for i in keep) + "\n" for ln in lines))
    assert {r["vehicles"] for r in read_cells(old, legacy=legacy_values(meta))} == {1}


def test_the_batch_engine_refuses_fleets_and_auto_falls_back(tmp_path: Path) -> None:
    m = load_mission(short_sine(tmp_path))
    todo = cells(m, Grid(vehicles=(1, 4), delay_ms=tuple(range(20))))
    with pytest.raises(ConfigError, match="--engine batch: cells of 4 vehicles"):
        engine_for(m, todo, "offline", "batch")
    assert engine_for(m, todo, "offline", "auto")[0] == "process"
    assert engine_for(m, cells(m, Grid(vehicles=(1,), delay_ms=tuple(range(40)))), "offline", "auto")[0] == "batch"


def test_fleet_cells_that_cannot_fly_are_refused_before_any_cell(tmp_path: Path,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    m = load_mission(short_sine(tmp_path))
    with pytest.raises(ConfigError, match="offline only for now"):
        Sweep(m, Grid(vehicles=(1, 2)), mode="lockstep")
    with pytest.raises(ConfigError, match="grid.vehicles: must be whole numbers"):
        Grid(vehicles=(1.5,))
    with pytest.raises(ConfigError, match="grid.vehicles: must be in"):
        Grid(vehicles=(65,))
    with pytest.raises(ConfigError, match=r"grid.vehicles \(--vehicles 64\): .*vehicle"):
        Sweep(m, Grid(vehicles=(1, 64))).validate()  # 126 m of line: past the plant's envelope
    assert main(["sweep", str(short_sine(tmp_path)), "--vehicles", "1,2.5"]) == 2
    err = capsys.readouterr().err
    assert "--vehicles: expected whole numbers of vehicles, got '1,2.5'" in err and err.count("\n") == 1
    # a mission with its own [[vehicles]]: said once, with where fleets are swept (it was said as the first cell's,
    # `sweep cell (controller=bsst ... vehicles=2 seed=0): ...: sweeps ... fly one vehicle`, cut before its end)
    near_miss = MISSION_DIR.parent / "examples" / "swarm-near-miss.toml"
    assert main(["sweep", str(near_miss), "--delay", "0,10", "--out", str(tmp_path / "s")]) == 2
    err = capsys.readouterr().err
    assert err == (f"bsst: {near_miss}: vehicles: a mission of several vehicles ([[vehicles]]) is not a sweep's cell: "
                   "a sweep lays fleets out itself (--vehicles N,... on a mission without [[vehicles]]); bsst margin, "
                   "vehicle and controller fly one vehicle\n"), err
    assert not (tmp_path / "s").exists()
