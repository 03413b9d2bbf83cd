"""The test kit's pymavlink ground station: its link to a vehicle instance, a command's answer, a mission upload.

In:  a vehicle instance ``n`` (its ground-station port, GCS_PORT + n), a link made here, a command id, mission items
Out: the link (MAVLink 2, common dialect), the COMMAND_ACK, the vehicle's (system, component), an accepted upload

Shared by the SITL tests that speak to ``bsst vehicle`` as a ground station (once private helpers of
tests/test_vehicle.py and tests/test_await_mission.py that other test modules imported).
"""

from __future__ import annotations

import os
from typing import Any

from pymavlink import mavutil
from pymavlink.dialects.v20 import common as M

from bridge.mavlink.endpoint import GCS_PORT


def gcs_link(n: int, sysid: int = 255, compid: int = 190) -> Any:
    """A pymavlink ground station (``sysid``:``compid``, MAVLink 2) on instance ``n``'s ground-station port."""
    os.environ["MAVLINK20"] = "1"
    return mavutil.mavlink_connection(f"udpin:127.0.0.1:{GCS_PORT + n}", source_system=sysid,
                                      source_component=compid, dialect="common")


def command_ack(conn: Any, command: int, timeout: float = 10.0) -> Any:
    """The COMMAND_ACK for ``command`` that ``conn`` hears within ``timeout`` s."""
    m = conn.recv_match(type="COMMAND_ACK", blocking=True, timeout=timeout,
                        condition=f"COMMAND_ACK.command=={command}")
    assert m is not None, f"no COMMAND_ACK for {command}"
    return m


def vehicle_of(gcs: Any) -> tuple[int, int]:
    """The (system, component) of the first HEARTBEAT the ground station hears (30 s deadline)."""
    hb = gcs.recv_match(type="HEARTBEAT", blocking=True, timeout=30)
    assert hb is not None, "no HEARTBEAT within 30 s"
    return hb.get_srcSystem(), hb.get_srcComponent()


def upload(gcs: Any, target: tuple[int, int], items: list[Any]) -> None:
    """``items`` uploaded to ``target`` as the vehicle asks for them, accepted."""
    gcs.mav.mission_count_send(*target, len(items), 0)
    while True:
        m = gcs.recv_match(type=["MISSION_REQUEST_INT", "MISSION_ACK"], blocking=True, timeout=5)
        assert m is not None, "the vehicle stopped asking"
        if m.get_type() == "MISSION_ACK":
            assert m.type == M.MAV_MISSION_ACCEPTED
            return
        item = items[m.seq]
        item.target_system, item.target_component = target
        gcs.mav.send(item)
