"""Covers bridge.nodes.vehicle.intention and bridge.nodes.vehicle.streams: a failsafe's disarm clears it, as PX4.

PX4 clears its failsafe on disarm (failsafe/framework.cpp: no action is selected while disarmed), shows the user's
mode again (UserModeIntention::onDisarm) and says STANDBY (streams/HEARTBEAT.hpp: any disarmed vehicle). A real
``bsst vehicle`` and a ground station on pymavlink: a geofence Land failsafe from HOLD lands and disarms the vehicle,
which then shows HOLD (pymavlink's LOITER), STANDBY, and arms there again. A real ``bsst sitl`` session (lockstep):
the sine's failsafe landing past the mission's end (the sine cut to 15 s, ``--blackout 12.5:3``) ends in OFFBOARD,
STANDBY, with the same events at the same times as offline.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as M

from bridge.loop import simulate
from bridge.mavlink.modes import MAIN_AUTO, MAIN_OFFBOARD, SUB_LAND, SUB_LOITER, custom_mode
from bridge.session import instance_slot
from missions import MISSION_DIR
from tests.gcskit import command_ack, gcs_link
from tests.sitlkit import ENV, run_bsst
from tests.test_ground_stations import FAST, _from
from tests.test_vehicle import _vehicle

pytestmark = pytest.mark.process  # starts processes or opens sockets: not in make test-fast

CLEARED = ("(disarmed after its failsafe: PX4 clears the failsafe on disarm and takes the last mode it arms in; "
           "armed in it next)")
ARMED = M.MAV_MODE_FLAG_SAFETY_ARMED
HOLD_MODE, LAND_MODE = custom_mode(MAIN_AUTO, SUB_LOITER), custom_mode(MAIN_AUTO, SUB_LAND)


def vehicle_heartbeats(tlog: Path) -> list[tuple[bool, int, int]]:
    """From a vehicle's tlog: each HEARTBEAT it sent, as (armed, custom_mode, system_status), in order."""
    log = mavutil.mavlink_connection(str(tlog), dialect="common")
    beats = []
    while (m := log.recv_match(type="HEARTBEAT")) is not None:
        if m.autopilot == M.MAV_AUTOPILOT_PX4:
            beats.append((bool(m.base_mode & ARMED), m.custom_mode, m.system_status))
    return beats


def never_critical_disarmed(beats: list[tuple[bool, int, int]]) -> None:
    """PX4's HEARTBEAT: CRITICAL only armed (its failsafe flying); disarmed always STANDBY."""
    assert all(armed or status == M.MAV_STATE_STANDBY for armed, _, status in beats), sorted(set(beats))


def test_a_ground_stations_vehicle_disarmed_by_its_geofence_failsafe_shows_hold_standby_and_arms_again(tmp_path):
    """GF_ACTION 5 (Land): armed in HOLD, a takeoff (its end is HOLD), then GF_MAX_VER_DIST set to 1 m at 2.5 m: the
    fence's failsafe lands (LAND, CRITICAL, armed) and COM_DISARM_LAND (1 s) after the touchdown disarms; then, not
    LAND and CRITICAL as it once stayed until armed again, HOLD (LOITER) and STANDBY, a ``mode`` event of the
    vehicle's own saying why; a plain arm is ACCEPTED in HOLD."""
    with instance_slot() as n:
        gcs = gcs_link(n)
        v = _vehicle(n, tmp_path, *FAST, "--param", "COM_DISARM_LAND=1", "--param", "GF_ACTION=5")
        try:
            assert gcs.wait_heartbeat(timeout=20) is not None

            def command(cmd: int, *p: float) -> int:
                gcs.mav.command_long_send(n + 1, 1, cmd, 0, *p)
                return command_ack(gcs, cmd).result

            def heartbeat(armed: bool, mode: int, status: int) -> None:
                hb = gcs.recv_match(type="HEARTBEAT", blocking=True, timeout=10, condition=(
                    f"bool(HEARTBEAT.base_mode & {ARMED}) == {armed} and HEARTBEAT.custom_mode == {mode} "
                    f"and HEARTBEAT.system_status == {status}"))
                assert hb is not None, f"no HEARTBEAT armed={armed} custom_mode={mode} system_status={status}"

            nan, arm = math.nan, M.MAV_CMD_COMPONENT_ARM_DISARM
            assert command(arm, 1, 0, 0, 0, 0, 0, 0) == M.MAV_RESULT_ACCEPTED
            v.wait_event(lambda s: s.startswith("armed: armed, HOLD [by 255:190"))
            assert command(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, nan, nan, nan, nan) == M.MAV_RESULT_ACCEPTED
            v.wait_event(lambda s: s.startswith("mode: HOLD: takeoff done"))
            gcs.mav.param_set_send(n + 1, 1, b"GF_MAX_VER_DIST", 1.0, M.MAV_PARAM_TYPE_REAL32)
            v.wait_event(lambda s: s.startswith("failsafe: geofence: ") and s.endswith(": land here"))
            heartbeat(True, LAND_MODE, M.MAV_STATE_CRITICAL)
            landed = v.wait_event(lambda s: s.startswith("landed: landing detected at "))
            off = v.wait_event(lambda s: s == "disarmed: landed: disarmed [by vehicle]")
            assert off.t == pytest.approx(landed.t + 1.0, abs=1e-6)
            back = v.wait_event(lambda s: s.startswith("mode: HOLD (disarmed after its failsafe"))
            assert back.text == f"HOLD {CLEARED}" and (back.mode, back.armed) == ("hold", False), back
            heartbeat(False, HOLD_MODE, M.MAV_STATE_STANDBY)
            mark = len(v.events())
            assert command(arm, 1, 0, 0, 0, 0, 0, 0) == M.MAV_RESULT_ACCEPTED
            v.wait_event(_from(mark, lambda s: s.startswith("armed: armed, HOLD [by 255:190")))
            heartbeat(True, HOLD_MODE, M.MAV_STATE_ACTIVE)
            assert command(arm, 0, 0, 0, 0, 0, 0, 0) == M.MAV_RESULT_ACCEPTED
        finally:
            gcs.close()
            assert v.stop() == 0
    beats = vehicle_heartbeats(tmp_path / "vehicle.tlog")
    never_critical_disarmed(beats)
    assert (True, LAND_MODE, M.MAV_STATE_CRITICAL) in beats and beats[-1] == (False, HOLD_MODE, M.MAV_STATE_STANDBY)


def test_the_briefs_failsafe_landing_in_lockstep_ends_offboard_standby_as_offline(tmp_path):
    """The brief's ``bsst sitl missions/sine.toml --blackout 27.5:3`` (the sine's failsafe landing past the mission's
    end), flown on the sine cut to 15 s, ``--blackout 12.5:3``: the failsafe's descent from 13.0 s, still going at the
    mission's end, lands at 15.424 s and disarms at 17.424 s; at 17.428 s the vehicle is back in OFFBOARD (the mode it
    was armed in), disarmed, saying why, and its HEARTBEAT says STANDBY (it said CRITICAL, LAND, until armed again).
    The run is still ``failsafe`` (exit 1), and ``bsst sim`` says the same events at the same times. (The whole sine's
    flew 34.6 s in each twin; this one 17.4 s. Offline, the whole sine's: tests/test_landed_event.py.)"""
    sine = tmp_path / "sine15.toml"
    sine.write_text((MISSION_DIR / "sine.toml").read_text().replace("duration_s = 30.0", "duration_s = 15.0"))
    with instance_slot() as n:
        r = run_bsst("sitl", str(sine), "--blackout", "12.5:3", "--instance", str(n),
                     "--no-plots", "--out", str(tmp_path / "s"), env=ENV, timeout=300)
    assert r.returncode == 1, r.stdout[-2000:] + r.stderr[-2000:]
    sitl = json.loads((tmp_path / "s" / "summary.json").read_text())
    offline = simulate(sine, plots=False, link={"blackouts": [[12.5, 3.0]]}).summary
    assert sitl["outcome"] == offline["outcome"] == "failsafe" and sitl["ended_by"] == offline["ended_by"]

    def said(events: list) -> list:
        return [(e["t"], e["kind"], e["text"].removesuffix(" [by vehicle]")) for e in events
                if e.get("source", "vehicle") == "vehicle" and e["kind"] in ("failsafe", "landed", "disarmed", "mode")]

    assert said(sitl["events"]) == said(offline["events"])
    assert said(offline["events"])[-2:] == [(17.424, "disarmed", "landed: disarmed"),
                                            (17.428, "mode", f"OFFBOARD {CLEARED}")]
    assert [t for t, k, _ in said(offline["events"]) if k == "landed"] == [15.424]  # after the mission's end
    beats = vehicle_heartbeats(tmp_path / "s" / "vehicle.tlog")
    never_critical_disarmed(beats)
    assert (True, LAND_MODE, M.MAV_STATE_CRITICAL) in beats  # its failsafe, while it flew
    assert beats[-1] == (False, custom_mode(MAIN_OFFBOARD), M.MAV_STATE_STANDBY)
