"""Covers bridge.autopilot.touchdownwatch: an armed touchdown mid-flight under OFFBOARD is a ``touchdown``, its
event and the ``touchdown`` policy, exit 1 (docs/weather.md "Outcomes"); a normal sine and step run have none."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from tests.sitlkit import run_bsst

pytestmark = pytest.mark.process  # runs bsst sim as a real process (its exit status)

ROOT = Path(__file__).resolve().parents[1]
FAULTS = ["--sensors", "gnss", "--estimator", "ekf", "--at", "1:gps:off", "--at", "3:gps:on", "--at",
          "2:baro:drift=0.3", "--at", "2.5:gyro:bias=0.01,0,0"]


def _sim(tmp_path: Path, name: str, *args: str) -> tuple[int, dict]:
    src = (ROOT / "missions" / f"{name}.toml").read_text()
    m = tmp_path / f"{name}4.toml"
    m.write_text(src.replace("duration_s = 30.0", "duration_s = 4.0") if name == "sine" else src)
    out = tmp_path / "run"
    # forked warm by the fork server (a cold ``python -m bridge sim`` loaded numpy, numba and the EKF's kernels
    # afresh: 1.1-2.1 CPU-s a run, most of this file's cost)
    r = run_bsst("sim", m, *args, "--out", out, "--no-plots", cwd=tmp_path, env=dict(os.environ), timeout=300)
    return r.returncode, json.loads((out / "summary.json").read_text())


def test_faults_that_set_it_down_mid_mission_are_a_touchdown(tmp_path: Path) -> None:
    rc, s = _sim(tmp_path, "sine", *FAULTS)
    [down] = [e for e in s["events"] if e["kind"] == "touchdown"]
    assert down["t"] == pytest.approx(3.612, abs=0.01) and "not a landing it was asked to make" in down["text"]
    broken = [p for p in s["policies"] if not p["ok"]]
    assert rc == 1 and [p["name"] for p in broken] == ["touchdown"] and broken[0]["t"] == down["t"]


@pytest.mark.parametrize("name", ["sine", "step"])
def test_a_normal_flight_has_no_touchdown(tmp_path: Path, name: str) -> None:
    rc, s = _sim(tmp_path, name)
    assert rc == 0 and s["outcome"] == "completed" and all(p["ok"] for p in s["policies"])
    assert not [e for e in s["events"] if e["kind"] == "touchdown"]
