"""Covers bridge.record.joiner: vehicle.bin + controller.bin -> trace.csv rows, on real halves.

The files are written here as the vehicle and the controller write them (bridge.record.halves' writer), for
the case a SITL flight cannot produce on demand: a controller killed between sending a
command and writing its row.
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from bridge.autopilot.modes import MODES
from bridge.core.flight import prepare
from bridge.nodes.vehicle import MODE_CODES
from bridge.record.columns import CONTROLLER_COLUMNS, TRACE_COLUMNS, VEHICLE_COLUMNS, ControllerRow, VehicleRow
from bridge.record.halves import HalfReader, HalfWriter
from bridge.record.joiner import TraceJoiner
from bridge.record.metrics import ripple_rms
from missions import MISSION_DIR, load_mission

RATE = 250.0


def _write(path: Path, columns: tuple[str, ...], rows: list[dict[str, float]]) -> None:
    out = HalfWriter(path, columns)
    for r in rows:
        out.write([float(r.get(c, 0.0)) for c in columns])
    out.close()


def test_steps_flown_on_a_command_whose_row_was_never_written_are_kept_with_the_demand_unknown(tmp_path: Path) -> None:
    """Steps 0..5 answered; the controller dies after sending 5 and before writing its row; the vehicle
    holds command 5 for steps 6..8, then its failsafe flies 9..11. Every step is a trace row, in order;
    the rows on command 5 have u and the desired attitude NaN, and are counted missing."""
    flight = prepare(MISSION_DIR / "sine.toml")
    vehicle, controller = [], []
    for k in range(12):
        key = k if k <= 5 else 5 if k <= 8 else -1
        mode = MODE_CODES["offboard"] if key >= 0 else MODE_CODES["failsafe"]
        vehicle.append({"k": k, "t": k / RATE, "x": 0.001 * k, "mode": mode, "cmd_k": key, "c1": 0.5, "u1": 3.0,
                        "u1_act": 3.0, "odo_sent_wall": 100.0 + k / RATE, "cmd_recv_wall": 100.0 + k / RATE,
                        "rtt_s": 1e-4, "state_age_s": 0.0, "nees": 0.0})
        if k <= 4:
            controller.append({"k": k, "t": k / RATE, "u1": 4.0 + k, "u2": 0.1, "phi_d": 0.01, "theta_d": 0.02,
                               "odo_recv_wall": 100.0 + k / RATE, "cmd_sent_wall": 100.0 + k / RATE})
    _write(tmp_path / "vehicle.bin", VEHICLE_COLUMNS, vehicle)
    _write(tmp_path / "controller.bin", CONTROLLER_COLUMNS, controller)
    j = TraceJoiner(tmp_path, flight, None, lockstep=True)
    assert j.update() == 5  # rows 0..4 joined; row 5 waits for a controller row that may still come
    j.controller_done = True
    assert j.update() == 7
    j.close()
    col = {c: np.array([getattr(r, c) for r in j.rows]) for c in TRACE_COLUMNS}
    assert np.allclose(col["t"], np.arange(12) / RATE) and np.allclose(col["x"], 0.001 * np.arange(12))
    assert np.all(np.diff(col["t"]) > 0)
    assert list(col["u1"][:5]) == [4.0, 5.0, 6.0, 7.0, 8.0]
    assert all(math.isnan(v) for v in (*col["u1"][5:9], *col["u2"][5:9], *col["phi_d"][5:9], *col["theta_d"][5:9]))
    assert list(col["u1"][9:]) == [3.0, 3.0, 3.0] and list(col["phi_d"][9:]) == [0.0, 0.0, 0.0]  # the landing loop
    assert j.missing == 4



def test_a_step_the_controller_answered_takes_the_reference_its_row_recorded(tmp_path: Path) -> None:
    """Lockstep: the reference columns of a step whose state the controller answered at the step's time are its
    row's (the mission's reference, sampled by the same code: not sampled again in the session's process, 0.1-0.4
    CPU-s of a 20 s session); a step it never answered (its failsafe after it died), or whose row is at another
    time (a real-time tick's), is sampled from the mission. The rows' recorded values here are marks no sine has."""
    flight = prepare(MISSION_DIR / "sine.toml")
    sample = flight.mission.trajectory.sample
    vehicle, controller = [], []
    for k in range(8):
        key = k if k <= 4 else -1
        vehicle.append({"k": k, "t": k / RATE, "mode": MODE_CODES["offboard" if key >= 0 else "failsafe"],
                        "cmd_k": key, "odo_sent_wall": 100.0, "cmd_recv_wall": 100.0, "rtt_s": 1e-4})
        if k <= 4:
            controller.append({"k": k, "t": k / RATE + (0.001 if k == 2 else 0.0), "x_ref": 100.0 + k,
                               "y_ref": 200.0 + k, "z_ref": 300.0 + k, "psi_ref": 400.0 + k,
                               "odo_recv_wall": 100.0, "cmd_sent_wall": 100.0})
    _write(tmp_path / "vehicle.bin", VEHICLE_COLUMNS, vehicle)
    _write(tmp_path / "controller.bin", CONTROLLER_COLUMNS, controller)
    j = TraceJoiner(tmp_path, flight, None, lockstep=True)
    j.controller_done = True
    assert j.update() == 8
    j.close()
    refs = [(r.x_ref, r.y_ref, r.z_ref, r.psi_ref) for r in j.rows]
    sampled = [tuple(a[0] for a in sample(k / RATE)) for k in range(8)]
    assert refs == [(100.0 + k, 200.0 + k, 300.0 + k, 400.0 + k) if k in (0, 1, 3, 4) else sampled[k] for k in range(8)]


def test_a_failsafes_rows_after_the_missions_last_step_are_not_the_traces(tmp_path: Path) -> None:
    """A 10-step mission, its failsafe from step 6 still landing (and waiting out its disarm) at steps 10..15: the
    trace is steps 0..9, as offline's, which ends at the mission's last step whatever flies after it; the rest is
    kept after it (its heights and positions, for a fleet's judgement). They were the trace's, its RMS and duration
    too (the sine's ``--blackout 27.5:3`` in lockstep: 34.57 s and 8643 rows against offline's 30 s and 7500)."""
    flight = prepare(replace(load_mission(MISSION_DIR / "sine.toml"), duration_s=10 / RATE))
    vehicle, controller = [], []
    for k in range(16):
        key = k if k < 6 else -1
        mode = MODE_CODES["offboard"] if key >= 0 else MODE_CODES["failsafe"]
        vehicle.append({"k": k, "t": k / RATE, "x": 0.001 * k, "z": 0.3 - 0.01 * k, "mode": mode, "cmd_k": key,
                        "odo_sent_wall": 100.0 + k / RATE, "cmd_recv_wall": 100.0 + k / RATE})
        controller.append({"k": k, "t": k / RATE, "odo_recv_wall": 100.0 + k / RATE,
                           "cmd_sent_wall": 100.0 + k / RATE})
    _write(tmp_path / "vehicle.bin", VEHICLE_COLUMNS, vehicle)
    _write(tmp_path / "controller.bin", CONTROLLER_COLUMNS, controller)
    j = TraceJoiner(tmp_path, flight, None, lockstep=True)
    j.controller_done = True
    j.update()
    j.close()
    assert [r.t for r in j.rows] == [k / RATE for k in range(10)]
    assert [a[0] for a in j.after] == [k / RATE for k in range(10, 16)]
    assert j.after_at[0] == (0.010, 0.0, 0.3 - 0.1) and len(j.after_at) == 6


def test_a_real_time_step_flown_re_armed_before_its_first_target_is_a_row(tmp_path: Path) -> None:
    """Real time, ``[failsafe] resume``: the controller's ARM and the target it sends with it are two datagrams,
    and the vehicle may fly a step between them (the target lost, or read after the step began): armed in OFFBOARD,
    no target in force. That step is the trace's, demand unknown; it was dropped as a step before the flight's
    first target, and ``time_steady`` broke on the gap (``t goes from 12.600000 s to 12.608000 s``). The steps
    before the flight's first target are still not the trace's."""
    flight = prepare(MISSION_DIR / "sine.toml")
    offboard, failsafe = MODE_CODES["offboard"], MODE_CODES["failsafe"]
    vehicle, controller = [], []
    for k in range(14):
        # 0, 1: armed, the first target not in; 2..5 on targets 0..3; 6..8 the failsafe's landing loop;
        # 9 re-armed, its target not in yet; 10..13 on targets 8..11
        key = -1 if k < 2 or 6 <= k <= 9 else k - 2
        mode = failsafe if 6 <= k <= 8 else offboard
        free = key < 0 and mode == offboard  # no target in force: the vehicle writes NaN
        vehicle.append({"k": k, "t": k / RATE, "x": 0.001 * k, "mode": mode, "cmd_k": key,
                        "c1": math.nan if free else 0.5, "u1": math.nan if free else 3.0, "u1_act": 3.0,
                        "odo_sent_wall": 100.0 + k / RATE, "cmd_recv_wall": math.nan if key < 0 else 100.0 + k / RATE,
                        "rtt_s": 1e-4, "state_age_s": math.nan if key < 0 else 0.008, "nees": 0.0})
        controller.append({"k": k, "t": k / RATE, "u1": 4.0 + k, "phi_d": 0.01, "theta_d": 0.02,
                           "odo_recv_wall": 100.0 + k / RATE, "cmd_sent_wall": 100.0 + k / RATE})
    _write(tmp_path / "vehicle.bin", VEHICLE_COLUMNS, vehicle)
    _write(tmp_path / "controller.bin", CONTROLLER_COLUMNS, controller)
    j = TraceJoiner(tmp_path, flight, None)
    j.update()
    j.close()
    col = {c: np.array([getattr(r, c) for r in j.rows]) for c in TRACE_COLUMNS}
    assert np.allclose(col["t"], np.arange(2, 14) / RATE) and np.allclose(col["x"], 0.001 * np.arange(2, 14))
    rearmed = 9 - 2  # its row
    assert all(math.isnan(col[c][rearmed]) for c in ("u1", "c1", "phi_d", "theta_d", "state_age_s"))
    assert col["u1_act"][rearmed] == 3.0 and col["u1"][rearmed + 1] == 4.0 + 8  # then the law's demand again
    assert j.missing == 0


def test_ripple_ignores_an_unknown_stretch_of_demand() -> None:
    t = np.arange(2000) / RATE
    u = np.sin(2 * np.pi * 20 * t)
    clean = ripple_rms(t, u, RATE)
    holed = u.copy()
    holed[1500:1600] = np.nan
    got = ripple_rms(t, holed, RATE)
    assert math.isfinite(got) and abs(got - clean) < 0.05 * clean


def test_a_half_is_read_by_its_own_header(tmp_path: Path) -> None:
    """Columns in another order are read by name; a missing column is an error that names it."""
    shuffled = tuple(reversed(CONTROLLER_COLUMNS))
    _write(tmp_path / "controller.bin", shuffled, [{"k": 3.0, "u1": 4.5, "cmd_sent_wall": 7.0}])
    rows = HalfReader(tmp_path / "controller.bin", ControllerRow).read()
    assert [(r.k, r.u1, r.cmd_sent_wall, r.u2) for r in rows] == [(3.0, 4.5, 7.0, 0.0)]
    _write(tmp_path / "vehicle.bin", tuple(c for c in VEHICLE_COLUMNS if c != "cmd_k"), [{"k": 0.0}])
    with pytest.raises(ValueError, match="vehicle.bin: no column 'cmd_k'"):
        HalfReader(tmp_path / "vehicle.bin", VehicleRow).read()


def test_every_mode_has_a_code_of_its_own_in_vehicle_bin() -> None:
    """An RTL or a terminated flight was written 0, as offboard, and the joiner took an RTL takeover's rows for a
    vehicle not flying yet."""
    assert set(MODE_CODES) == set(MODES) and len(set(MODE_CODES.values())) == len(MODES)
