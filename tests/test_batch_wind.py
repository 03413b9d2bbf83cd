"""Covers bridge.batch.plant, bridge.batch.flight and bridge.batch.weather: the batch engine in the air and
with a timeline.

Cells with their own steady wind, Dryden turbulence and gusts — the three laws, a delayed and lossy link, the
x500 (rotor drag, motors) — and the timeline's motor, wind and gust events (the x500 without and with its
battery, with motor lag) are flown by the batch engine and by the scalar loop and compared as
tests/test_batch.py compares still air: the same outcome, packet counts and flown time; for ``bsst`` and
``pid`` the figures within 1e-6 relative, for ``smc`` (a switching law) the RMS within 1 %. The turbulence's
samples are the scalar generator's own (plant.wind.turbulence_series: checked equal to what Wind.now adds). A
``link`` event is refused: tests/test_batch.py.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from bridge.batch import fly_batch
from bridge.core.flight import prepare
from bridge.loop import fly
from bridge.sweep.cells import row_from_run
from bridge.sweep.grid import Cell
from missions import load_mission
from plant.wind import Wind, WindConfig, turbulence_series

pytestmark = pytest.mark.usefixtures("batch_kernels")  # flies the batch engine: its kernels loaded first

ROOT = Path(__file__).resolve().parents[1]
GUSTS = [[2.0, 1.5, 4.0, 45.0], [4.0, 2.0, 3.0, 200.0], [4.5, 0.5, 2.0, 0.0]]  # t_s, duration_s, m/s, from_deg
MODERATE = {"speed_mps": 5.0, "from_deg": 270.0, "turbulence": "moderate"}


def _close(a: float | None, b: float | None, rel: float) -> bool:
    if a is None or b is None:
        return a is b
    return abs(a - b) <= rel * max(abs(a), abs(b), 1e-300)


@pytest.mark.parametrize("name, cells", [
    ("sine.toml", [
        {"controller": "bsst", "wind": {"speed_mps": 5.0, "from_deg": 270.0}},
        {"controller": "pid", "wind": {"speed_mps": 3.0, "from_deg": 30.0, "gusts": GUSTS},
         "link": {"delay_ms": 10.0, "loss_pct": 10.0}},
        {"controller": "smc", "wind": {"speed_mps": 0.0, "gusts": GUSTS}},
        {"controller": "bsst", "wind": {"speed_mps": 8.0, "from_deg": 135.0, "gusts": GUSTS[:1]},
         "link": {"delay_ms": 12.0, "compensation": "predict"}},
    ]),
    ("sine.toml", [  # Dryden turbulence: each cell its seed's samples; still air and a wind event beside it
        {"controller": "bsst", "wind": MODERATE},
        {"controller": "pid", "wind": {**MODERATE, "gusts": GUSTS}, "seed": 3, "link": {"delay_ms": 10.0}},
        {"controller": "smc", "wind": {"speed_mps": 0.0, "turbulence": "light"}},
        {"controller": "bsst", "at": ("2:wind:4:90", "3:gust:1.5,3,200")},
        {"controller": "pid"},
    ]),
    ("robust-x500.toml", [  # rotor drag, allocation on real rotors
        {"controller": "bsst", "wind": {"speed_mps": 4.0, "from_deg": 90.0, "gusts": GUSTS}},
        {"controller": "pid", "wind": {"speed_mps": 2.0, "from_deg": 10.0}, "link": {"delay_ms": 6.0}},
    ]),
])
def test_wind_turbulence_and_gusts_fly_as_in_the_scalar_loop(name: str, cells: list[dict]) -> None:
    # (ending in a hold: the batch flies no end action, and refuses a landing in wind, which it cannot judge)
    _agree(replace(load_mission(ROOT / "missions" / name), duration_s=6.0, end_action="hold"), cells)


@pytest.mark.parametrize("effects", [{}, {"battery": True}, {"battery": True, "motor_lag": True}])
def test_motor_events_and_the_battery_fly_as_in_the_scalar_loop(effects: dict) -> None:
    # the x500 with fault-sized gains: a rotor at 75 % (flown), one off (diverged), faults with wind events and
    # turbulence, a cell without events beside them; without and with the battery (its cap on the rotors' speed
    # taken at each command's arrival and each physics step), with motor lag (the speeds held, not the wrench)
    # (ending in a hold: the batch refuses a motor fault before an end landing, which it cannot judge)
    m = replace(load_mission(ROOT / "examples" / "x500-motor-fault.toml"), duration_s=5.0, effects=effects,
                end_action="hold")
    cells = [{"controller": "bsst", "at": ("2:motor:1=0.75",)},
             {"controller": "pid", "at": ("1:gust:1,2,45", "2:motor:2=0.6", "3:wind:3:90"), "link": {"delay_ms": 10.0}},
             {"controller": "smc"},
             {"controller": "bsst", "at": ("2:motor:1=0",)},
             {"controller": "bsst", "wind": {"speed_mps": 4.0, "turbulence": "light"}, "at": ("2:motor:3=0.8",)}]
    rows = _agree(m, cells)
    assert rows[3]["outcome"] == "diverged" and rows[0]["outcome"] == "completed"
    if effects.get("battery"):  # the sag capped a rotor somewhere (the battery acts on the flight only so)
        still = fly_batch(replace(m, effects={k: v for k, v in effects.items() if k != "battery"}), cells)
        assert any(a["tv_u2"] != b["tv_u2"] for a, b in zip(rows, still, strict=True)), (rows, still)


def test_the_turbulence_series_is_what_the_scalar_wind_adds() -> None:
    config = WindConfig(**MODERATE, altitude_m=1.5)
    series = turbulence_series(config, 7, 0.001, 500)
    wind, steady = Wind(config, 7, 0.001), Wind(WindConfig(5.0, 270.0), 7, 0.001)
    for k in range(500):
        t = k * 0.001
        got = wind.now(t)
        base = steady.now(t)
        assert got == tuple(b + s for b, s in zip(base, series[k], strict=True)), k
        wind.advance()
    assert series.std(axis=0).min() > 0.1  # it is turbulence, not zeros


def test_the_fault_and_battery_kernels_give_the_plain_bits() -> None:
    # bridge.core.kernels compiles plant.rotors.wrench_from_degraded_rotors, .clip and plant.battery.pack_step
    from bridge.core import kernels as K
    from plant.battery import pack_constants, pack_step
    from plant.profiles import load_profile
    from plant.rotors import clip, wrench_from_degraded_rotors

    p = load_profile("x500")
    pack = pack_constants(p.battery)
    rng = np.random.default_rng(27)
    for _ in range(300):
        om = tuple(float(v) for v in rng.uniform(0.0, p.omega_max, 4))
        eff = tuple(float(v) for v in rng.choice([0.0, 0.6, 1.0], 4))
        assert K.wrench_from_degraded_rotors(om, eff, p.thrust_coeff, p.drag_coeff) == \
            wrench_from_degraded_rotors(om, eff, p.thrust_coeff, p.drag_coeff)
        used = float(rng.uniform(0.0, 6000.0))
        args = (pack, used, used * 3.6, om, p.drag_coeff * p.arm, 1e-3)
        assert K.pack_step(*args) == pack_step(*args)
        v = float(rng.normal(0.5, 1.0))
        assert K.clip(v, 0.0, 0.9) == clip(v, 0.0, 0.9)


def _agree(m, cells: list[dict]) -> list[dict]:
    """Fly ``cells`` of mission m in one batch and each alone in the scalar loop: the same rows (see the docstring)."""
    rows = fly_batch(m, cells)
    for over, got in zip(cells, rows, strict=True):
        run = fly(prepare(m, **over), plots=False)
        want = row_from_run(Cell(over["controller"], m.rate_hz, 0.0, 0.0, 0.0, 0.0, 0), run)
        where = f"{over}: batch {got}, scalar {want}"
        for k in ("outcome", "up_sent", "up_lost", "down_sent", "down_lost", "flown_s", "error"):
            assert got[k] == want[k], f"{k}: {where}"
        if over["controller"] == "smc":
            assert _close(got["rms"], want["rms"], 0.01), f"rms: {where}"
            continue
        for k in ("rms", "max", "tv_u2", "ripple_u2"):
            assert _close(got[k], want[k], 1e-6), f"{k}: {where}"
    return rows


def test_still_and_windy_cells_fly_in_one_batch_as_alone() -> None:
    # a sweep's wind axis (0, 5 m/s: no [wind], a [wind]) in one batch: each cell as it flies alone (to the
    # bit but the ripple's summation), and the wind is flown, not ignored
    m = replace(load_mission(ROOT / "missions" / "sine.toml"), duration_s=6.0, end_action="hold")
    windy = {"controller": "pid", "wind": {"speed_mps": 6.0, "from_deg": 90.0, "gusts": GUSTS}}
    both = fly_batch(m, [{"controller": "pid"}, windy])
    alone = fly_batch(m, [{"controller": "pid"}]) + fly_batch(m, [windy])
    for a, b in zip(both, alone, strict=True):  # the ripple is numpy's over the batch's cells: its last bit may move
        assert _close(a.pop("ripple_u2"), b.pop("ripple_u2"), 1e-12) and a == b, (a, b)
    assert both[1]["rms"] > 2.0 * both[0]["rms"]
