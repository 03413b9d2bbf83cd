"""Covers bridge.autopilot.returnland and bridge.autopilot.batterywatch: the x500's battery failsafe Return
(COM_LOW_BAT_ACT 3) near home, with GNSS and the EKF, as PX4 1.14 flies it: Return's height from the cone
(RTL_CONE_ANG, RTL_MIN_DIST), the landing faster above MPC_LAND_ALT2 (MPC_Z_V_AUTO_DN), so that the pack's last
per cent brings it down intact. A real ``bsst sitl`` (lockstep, its vehicle and controller processes over UDP on
127.0.0.1) against offline, and the audit's flight (17 %, docs/ground-station.md, "Return's height and the
landing's speed") offline. The formulas alone: tests/test_return_land.py."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from bridge.loop import simulate
from bridge.record.runlog import read_trace
from bridge.session import instance_slot
from tests.plans import battery_mission
from tests.sitlkit import ROOT, run_bsst

pytestmark = pytest.mark.process  # starts processes: not in make test-fast

SENSED = {"sensors": {"set": "gnss"}, "estimator": "ekf"}
FLAGS = ("--sensors", "gnss", "--estimator", "ekf", "--param", "COM_LOW_BAT_ACT=3")


def _mission(tmp_path: Path, start_pct: float, duration_s: float, up: tuple[float, float] = (6.0, 4.0),
             north: tuple[float, float] = (14.0, 10.0)) -> Path:
    """The x500 with its pack from ``start_pct`` %: up to 4 m in 6 s, 10 m north by 14 s, held there (the audit's;
    ``up`` and ``north`` = (by t s, m) for another)."""
    return battery_mission(tmp_path, start_pct, duration_s, up=up, north=north, name="battery-return")


def _said(events: list[dict]) -> list[tuple[float, str, str]]:
    """The vehicle's battery, failsafe, disarm and crash events (a session's carry the controller's too)."""
    return [(e["t"], e["kind"], e["text"].removesuffix(" [by vehicle]")) for e in events  # (a session names it)
            if e.get("source", "vehicle") == "vehicle" and e["kind"] in ("battery", "failsafe", "landed", "disarmed",
                                                                         "impact", "crashed")]


def test_a_battery_return_10_m_from_home_at_4_m_climbs_only_to_the_cone_and_lands_intact_in_lockstep(
        tmp_path: Path) -> None:
    """Up to 4 m in 3 s, 10 m north by 8 s: from 8.2 % the critical level (7 %) comes at 9.164 s, 10 m north at 4 m
    (its estimate inside RTL_MIN_DIST): Return climbs to the cone's height there, d / tan 45 deg (about 10 m;
    RTL_RETURN_ALT is 30 m), flies home and lands; the emergency level (5 %) lands it where it has got to; it touches
    down within a metre of home below 1 m/s, disarmed COM_DISARM_LAND (2 s) later, nothing hit. ``bsst sitl`` (exit 1,
    outcome ``failsafe``) says and flies what ``bsst sim`` does: the same events at the same times, the trace within
    the float32 wire's 1e-4 m. (The audit's mission from 9.5 % flew the same, 10 s later: critical at 19.468 s,
    disarmed at 42.108 s, a 43 s flight in each twin; this one is 32 s.)"""
    # disarmed at 31.427 s: nothing after it is read but the last row, on the ground
    mission = _mission(tmp_path, 8.2, 32.0, up=(3.0, 4.0), north=(8.0, 10.0))
    offline = simulate(mission, plots=False, params={"COM_LOW_BAT_ACT": 3}, **SENSED)
    with instance_slot() as n:
        r = run_bsst("sitl", str(mission), *FLAGS, "--instance", str(n), "--no-plots", "--out", str(tmp_path / "s"),
                     cwd=ROOT, timeout=300)
    assert r.returncode == 1, r.stdout[-2000:] + r.stderr[-2000:]
    summary = json.loads((tmp_path / "s" / "summary.json").read_text())
    assert summary["outcome"] == offline.summary["outcome"] == "failsafe"
    assert "battery critical" in summary["ended_by"]["how"], summary["ended_by"]
    said = _said(summary["events"])
    assert said == _said(offline.summary["events"])
    kinds = [(k, text.rsplit(": ", 1)[-1]) for _, k, text in said if k != "battery"]
    assert kinds == [("failsafe", "return"), ("failsafe", "land"), ("landed", "disarms in COM_DISARM_LAND = 2 s"),
                     ("disarmed", "disarmed")], said
    t_return = next(t for t, k, _ in said if k == "failsafe")
    tr = read_trace(tmp_path / "s" / "trace.csv")
    k = min(len(tr["t"]), len(offline.trace["t"]))
    assert max(float(np.max(np.abs(tr[c][:k] - offline.trace[c][:k]))) for c in ("x", "y", "z")) < 1e-4
    i = int(np.searchsorted(tr["t"], t_return - 1e-9))
    away = float(np.hypot(tr["x_est"][i], tr["y_est"][i]))  # what the vehicle knew when Return began
    assert 9.5 < away < 10.0 and abs(tr["z"][i] - 4.0) < 0.1, (away, tr["z"][i])
    after = tr["t"] >= t_return
    top = float(tr["z"][after].max())
    assert away - 0.1 < top < away + 0.3, (top, away)  # the cone's height, d / tan 45 deg; nowhere near 30 m
    t_down = next(t for t, k, _ in said if k == "landed")  # on the ground (disarmed 2 s later)
    landing = after & (tr["t"] < t_down)
    assert float(-tr["vz"][landing].min()) < 1.6  # at most MPC_Z_V_AUTO_DN (and the loop's few per cent)
    j = int(np.searchsorted(tr["t"], t_down - 1e-9)) - 1  # the last row before the touchdown
    assert -tr["vz"][j] < 1.0 and float(np.hypot(tr["x"][j], tr["y"][j])) < 1.0, (tr["vz"][j], tr["x"][j])
    assert tr["z"][-1] == pytest.approx(0.0, abs=1e-6)  # at rest on the ground


def test_the_audits_return_from_just_beyond_rtl_min_dist_lands_intact_and_at_land_speed_would_not(
        tmp_path: Path) -> None:
    """The audit's flight offline: from 17 % the critical level comes at 78.784 s after a minute of holding, the EKF's
    estimate 10.04 m from home: beyond RTL_MIN_DIST (10 m), so Return climbs toward RTL_RETURN_ALT, as PX4 1.14 does,
    until the emergency level (93.960 s, 26.77 m) lands it; coming down at 1.5 m/s above 10 m it is on the ground at
    117.063 s, intact, and disarms COM_DISARM_LAND (2 s) later. The same flight with MPC_Z_V_AUTO_DN 0.7 m/s
    (MPC_LAND_SPEED the whole way, the landing before) runs out of pack on the way down and hits the ground hard."""
    mission = _mission(tmp_path, 17.0, 125.0)
    run = simulate(mission, plots=False, params={"COM_LOW_BAT_ACT": 3}, **SENSED)
    said = _said(run.summary["events"])
    assert [(round(t, 3), k) for t, k, _ in said if k != "battery"] == [
        (78.784, "failsafe"), (93.960, "failsafe"), (117.063, "landed"), (119.063, "disarmed")], said
    tr = run.trace
    i = int(np.searchsorted(tr["t"], 78.784 - 1e-9))
    assert float(np.hypot(tr["x_est"][i], tr["y_est"][i])) > 10.0  # beyond RTL_MIN_DIST by its estimate
    assert 26.5 < float(tr["z"].max()) < 27.0
    slow = simulate(mission, plots=False, params={"COM_LOW_BAT_ACT": 3, "MPC_Z_V_AUTO_DN": 0.7}, **SENSED)
    hit = [text for _, k, text in _said(slow.summary["events"]) if k in ("impact", "crashed")]
    assert hit and "hit the ground at" in hit[0], _said(slow.summary["events"])
