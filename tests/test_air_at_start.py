"""Covers bridge.core.weather, plant.wind and bridge.record.metrics: a t = 0 wind event's wind is the one said.

A wind event at the flight's first control step (an ``[[events]]`` table at ``t_s = 0``, or ``--at 0:wind:...``) sets
the steady wind flown from the start. Until the forty-fifth session the printed summary's ``air:`` line (and
``summary.json``'s ``wind`` block, which it reads) named the ``[wind]`` table's steady wind all the same: a mission
of ``[wind] speed_mps = 10`` and a 3 m/s event at 0 s printed ``air: wind 10 m/s from 0 deg`` and flew 3 m/s from
90 deg. Now the block has ``steady_at_start`` (speed, direction, where the event was given) and the line names it,
with the ``[wind]`` steady wind it replaced (with turbulence, still its pass speed and axes). An event later than
that leaves both as they were: the ``[wind]`` wind is flown from the start, the event is an event line.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from bridge.cli import main

HEAD = ('name = "air"\nduration_s = 2.0\nrate_hz = 250\n[trajectory]\nkind = "step"\n'
        'setpoints = [ { t = 0.0, x = 0.5, y = 0.0, z = 1.0, psi = 0.0 } ]\n')
EVENT = '[[events]]\nt_s = {t}\nkind = "wind"\nspeed_mps = 3.0\nfrom_deg = 90.0\n'


def _fly(capsys: Any, tmp_path: Path, text: str, *argv: str) -> tuple[list[str], dict[str, Any]]:
    """``bsst sim`` of the mission ``text`` (m.toml): the printed summary's ``air:`` lines and the ``wind`` block."""
    m = tmp_path / "m.toml"
    m.write_text(text)
    out = tmp_path / "run"
    rc = main(["sim", str(m), *argv, "--no-plots", "--out", str(out)])
    printed = capsys.readouterr()
    assert rc == 0, printed.err
    air = [line for line in printed.out.splitlines() if line.startswith("air:")]
    return air, json.loads((out / "summary.json").read_text())["wind"]


def test_a_t0_wind_event_over_the_wind_table_is_the_wind_said(capsys: Any, tmp_path: Path) -> None:
    """[wind] 10 m/s from the north, an event at 0 s of 3 m/s from the east: flown (mean 3 m/s) and said so."""
    air, wind = _fly(capsys, tmp_path, HEAD + EVENT.format(t=0.0) + "[wind]\nspeed_mps = 10.0\n")
    where = f"{tmp_path / 'm.toml'}: events (t_s = 0, kind = wind)"
    assert air == [f"air: wind 3 m/s from 90 deg from t = 0 ({where}; in place of [wind]'s 10 m/s from 0 deg), "
                   "turbulence none; drag on the airspeed"], air  # 'air: wind 10 m/s from 0 deg' on the old code
    assert wind["steady_at_start"] == {"speed_mps": 3.0, "from_deg": 90.0, "by": where}, wind
    assert wind["mean_speed_mps"] == pytest.approx(3.0), wind  # what was flown: the event's


def test_a_t0_wind_flag_with_turbulence_names_the_pass_speed_it_leaves(capsys: Any, tmp_path: Path) -> None:
    """--at 0:wind:3:90 over --wind 10 --turbulence moderate: the event's steady wind, the flag's pass speed."""
    air, wind = _fly(capsys, tmp_path, HEAD, "--wind", "10", "--turbulence", "moderate", "--at", "0:wind:3:90")
    assert air == ["air: wind 3 m/s from 90 deg from t = 0 (--at 0:wind:3:90; in place of [wind]'s 10 m/s from "
                   "0 deg, the turbulence's pass speed and axes), turbulence moderate (scaling exact); drag on the "
                   "airspeed"], air
    assert wind["steady_at_start"]["by"] == "--at 0:wind:3:90" and wind["dryden"]["pass_speed_mps"] == 10.0, wind


def test_a_later_wind_event_leaves_the_wind_table_said_from_the_start(capsys: Any, tmp_path: Path) -> None:
    air, wind = _fly(capsys, tmp_path, HEAD + EVENT.format(t=1.0) + "[wind]\nspeed_mps = 10.0\n")
    assert air == ["air: wind 10 m/s from 0 deg, turbulence none; drag on the airspeed"], air
    assert "steady_at_start" not in wind, wind
