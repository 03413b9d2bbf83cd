"""Covers bridge.nodes.vehicle.mission and bridge.nodes.vehicle.missiontransfer: the mission while it is flown.

``bsst sitl --await-mission`` (lockstep) and a pymavlink ground station on 127.0.0.1: the controller flies the
whole trajectory, planned from item 0, so a current item a ground station chose (MISSION_SET_CURRENT) is refused at
the start instead of being dropped, and while the mission flies an upload, a clear and a new current item are
refused (MAV_MISSION_ERROR and a STATUSTEXT saying why) instead of being taken and not flown; a fence may still
change. Every wait is on a message with a deadline.
"""

from __future__ import annotations

import json
import math
import os
from typing import Any

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as M

from bridge.mavlink.endpoint import GCS_PORT
from bridge.session import instance_slot
from tests.sitlkit import Proc

pytestmark = pytest.mark.process  # starts processes or opens sockets: not in make test-fast

HOME = (473977420, 85455940)  # degE7: the vehicle's default home (PX4 SITL's)
AUTO_MISSION = (4 << 16) | (4 << 24)  # PX4's custom_mode: main AUTO, sub MISSION


def _items() -> list[Any]:
    """A takeoff to 5 m, a waypoint 20 m north, a landing there."""
    north = HOME[0] + 1800
    spec = ((M.MAV_CMD_NAV_TAKEOFF, HOME[0], 5.0), (M.MAV_CMD_NAV_WAYPOINT, north, 5.0),
            (M.MAV_CMD_NAV_LAND, north, 0.0))
    return [M.MAVLink_mission_item_int_message(0, 0, seq, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, cmd, 0, 1, 0.0, 0.0,
                                               0.0, math.nan, lat, HOME[1], z, 0)
            for seq, (cmd, lat, z) in enumerate(spec)]


class _Gcs:
    """A pymavlink ground station (255:190) on instance ``n``'s ground-station port, once it heard the vehicle."""

    def __init__(self, n: int) -> None:
        os.environ["MAVLINK20"] = "1"
        self.c = mavutil.mavlink_connection(f"udpin:127.0.0.1:{GCS_PORT + n}", source_system=255,
                                            source_component=190, dialect="common")
        hb = self.recv("HEARTBEAT", 30, "HEARTBEAT.get_srcComponent()==1")
        self.t = (hb.get_srcSystem(), 1)

    def recv(self, kinds: str | list[str], timeout: float = 5.0, cond: str | None = None) -> Any:
        m = self.c.recv_match(type=kinds, blocking=True, timeout=timeout, condition=cond)
        assert m is not None, f"no {kinds} ({cond}) within {timeout} s"
        return m

    def upload(self, items: list[Any]) -> int:
        """MISSION_COUNT, each item requested, the MISSION_ACK's result."""
        self.c.mav.mission_count_send(*self.t, len(items), M.MAV_MISSION_TYPE_MISSION)
        while True:
            m = self.recv(["MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK"])
            if m.get_type() == "MISSION_ACK":
                return m.type
            item = items[m.seq]
            item.target_system, item.target_component = self.t
            self.c.mav.send(item)

    def start(self) -> int:
        """MAV_CMD_MISSION_START from item 0: its COMMAND_ACK's result."""
        self.c.mav.command_long_send(*self.t, M.MAV_CMD_MISSION_START, 0, 0, 0, 0, 0, 0, 0, 0)
        return self.recv("COMMAND_ACK", cond=f"COMMAND_ACK.command=={M.MAV_CMD_MISSION_START}").result

    def text(self, part: str) -> str:
        return self.recv("STATUSTEXT", cond=f"{part!r} in STATUSTEXT.text").text


def test_a_chosen_current_item_is_refused_at_the_start_and_the_flown_mission_cannot_change(tmp_path):
    """MISSION_SET_CURRENT 1 is taken (MISSION_CURRENT says 1, as PX4), but MISSION_START is then DENIED, saying
    the current item is 1 (PX4 would start there; the flight here is the whole trajectory, and it once flew it
    from item 0 while the ground station had been told 1). Item 0 current again, the start is ACCEPTED. While the
    mission flies (AUTO.MISSION, armed): an upload and a clear are MAV_MISSION_ERROR, MISSION_SET_CURRENT changes
    nothing (each with a STATUSTEXT saying why; they were once taken: the heartbeat showed OFFBOARD and
    MISSION_CURRENT a mission not started while the old one flew on); a fence may still be cleared. The flight
    completes, its mission never replaced."""
    out = tmp_path / "run"
    with instance_slot() as n:
        sitl = Proc.bsst("sitl", "--await-mission", "--instance", str(n), "--out", str(out), "--no-plots")
        gcs = None
        try:
            gcs = _Gcs(n)
            assert gcs.upload(_items()) == M.MAV_MISSION_ACCEPTED
            gcs.c.mav.mission_set_current_send(*gcs.t, 1)
            gcs.recv("MISSION_CURRENT", cond="MISSION_CURRENT.seq==1")
            assert gcs.start() == M.MAV_RESULT_DENIED
            assert "the current item is 1" in gcs.text("MISSION_START: the current")
            gcs.c.mav.mission_set_current_send(*gcs.t, 0)
            gcs.recv("MISSION_CURRENT", cond="MISSION_CURRENT.seq==0")
            assert gcs.start() == M.MAV_RESULT_ACCEPTED
            gcs.recv("HEARTBEAT", 30, f"HEARTBEAT.get_srcComponent()==1 and HEARTBEAT.base_mode & 128 and "
                                      f"HEARTBEAT.custom_mode=={AUTO_MISSION}")

            gcs.c.mav.mission_count_send(*gcs.t, 2, M.MAV_MISSION_TYPE_MISSION)
            ack = gcs.recv(["MISSION_ACK", "MISSION_REQUEST_INT", "MISSION_REQUEST"])
            assert (ack.get_type(), ack.type) == ("MISSION_ACK", M.MAV_MISSION_ERROR)
            assert "flying the mission" in gcs.text("IGN MISSION_COUNT")
            gcs.c.mav.mission_clear_all_send(*gcs.t, M.MAV_MISSION_TYPE_ALL)
            assert gcs.recv("MISSION_ACK").type == M.MAV_MISSION_ERROR
            gcs.c.mav.mission_set_current_send(*gcs.t, 2)
            assert "flying the mission" in gcs.text("WP CURR CMD")
            gcs.c.mav.mission_clear_all_send(*gcs.t, M.MAV_MISSION_TYPE_FENCE)
            assert gcs.recv("MISSION_ACK").type == M.MAV_MISSION_ACCEPTED
            current = gcs.recv("MISSION_CURRENT", 3)
            assert current.total == 3 and current.mission_state == M.MISSION_STATE_ACTIVE
            rc = sitl.p.wait(timeout=120)
        finally:
            if gcs is not None:
                gcs.c.close()
            sitl.stop()
    summary = json.loads((out / "summary.json").read_text())
    assert rc == 0 and summary["outcome"] == "completed", "\n".join(sitl.lines[-20:])
    texts = (out / "events.log").read_text().splitlines()
    assert not any("replaced by an upload" in t for t in texts), texts
    assert sum("mission: uploaded" in t for t in texts) == 1
    assert not any("mission: current item 2" in t or "mission: cleared" in t for t in texts), texts
