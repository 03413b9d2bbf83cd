"""Covers bridge.session.fleet and bridge.nodes.vehicle.authority: one ground station, every vehicle of a fleet.

Real processes: ``bridge.swarm.sitl`` flies three vehicles (a vehicle and a controller process each) whose
ground-station links all go to one UDP port, where a pymavlink ground station (sysid 255) listens. It sees
HEARTBEATs from systems 1, 2 and 3, reads a parameter of each by its ``target_system`` (only that system
answers), and a disarm (COMMAND_LONG to system 3, sent to every vehicle as a MAVLink router would) disarms
system 3 alone: 1 and 2 fly their missions to the end. And, without processes, the vehicle's authority refuses
every kind of message a ground station addresses to another system (``target``), and takes its own and
broadcasts.
"""

from __future__ import annotations

import socket
import threading
import time
from pathlib import Path
from typing import Any

import pytest
from pymavlink.dialects.v20 import common as mavlink

from bridge.mavlink.address import parse_address
from bridge.nodes.vehicle.authority import ADDRESSED, Authority
from bridge.nodes.vehicle.config import VehicleConfig
from bridge.session.children import free_udp_port
from bridge.swarm import sitl
from missions import MISSION_DIR
from tests.waiting import wait_for

pytestmark = pytest.mark.process  # starts processes, opens sockets

FORCE = 21196  # param2 of a disarm in flight (PX4's magic number)
ARMED = mavlink.MAV_MODE_FLAG_SAFETY_ARMED


class Station:
    """A ground station on one UDP port: every message heard, the address each system speaks from."""

    def __init__(self, port: int) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", port))
        self.sock.setblocking(False)
        self.mav = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
        self.addr: dict[int, tuple[str, int]] = {}
        self.armed: dict[int, bool] = {}
        self.heard: list[Any] = []

    def pump(self) -> None:
        while True:
            try:
                data, addr = self.sock.recvfrom(65536)
            except BlockingIOError:
                return
            try:
                msgs = self.mav.parse_buffer(data) or []
            except mavlink.MAVError:
                continue
            for m in msgs:
                src = m.get_srcSystem()
                self.addr[src] = addr
                self.heard.append(m)
                if m.get_type() == "HEARTBEAT" and m.autopilot != mavlink.MAV_AUTOPILOT_INVALID:
                    self.armed[src] = bool(m.base_mode & ARMED)

    def to_all(self, msg: Any) -> None:
        """Send ``msg`` to every vehicle heard (a router's broadcast): its target_system decides who acts."""
        buf = msg.pack(self.mav)
        for a in self.addr.values():
            self.sock.sendto(buf, a)

    def answers(self, kind: str, since: int, **fields: Any) -> list[Any]:
        return [m for m in self.heard[since:] if m.get_type() == kind
                and all(getattr(m, k) == v for k, v in fields.items())]


def test_one_ground_station_sees_three_vehicles_reads_each_and_disarms_only_system_3(tmp_path: Path) -> None:
    port = free_udp_port()
    gcs = Station(port)
    mission = tmp_path / "sine.toml"
    mission.write_text((MISSION_DIR / "sine.toml").read_text().replace("duration_s = 30.0", "duration_s = 12.0"))
    result: dict[str, Any] = {}

    def fly() -> None:
        try:
            result["run"] = sitl(mission, vehicles=3, formation="line:2", instance=None, gcs=f"127.0.0.1:{port}",
                                 speed=1.0, out=tmp_path / "run", plots=False)
        except BaseException as exc:  # noqa: BLE001  (named by the assertion below)
            result["error"] = exc

    flight = threading.Thread(target=fly, daemon=True)
    flight.start()
    try:
        def all_armed() -> bool:
            gcs.pump()
            return sorted(s for s, a in gcs.armed.items() if a) == [1, 2, 3]

        wait_for(all_armed, 90, "heartbeats of systems 1, 2 and 3, armed")
        for i in (1, 2, 3):  # each vehicle's parameter, read by its id: only that system answers
            mark = len(gcs.heard)
            gcs.to_all(gcs.mav.param_request_read_encode(i, 1, b"MAV_SYS_ID", -1))

            def answered(i: int = i, mark: int = mark) -> bool:
                gcs.pump()
                return bool(gcs.answers("PARAM_VALUE", mark, param_id="MAV_SYS_ID"))

            wait_for(answered, 20, f"PARAM_VALUE MAV_SYS_ID from system {i}")
            time.sleep(0.3)  # the other vehicles' chance to answer wrongly (an absence: no event to wait on)
            gcs.pump()
            replies = gcs.answers("PARAM_VALUE", mark, param_id="MAV_SYS_ID")
            assert {m.get_srcSystem() for m in replies} == {i}, [str(m) for m in replies]
        mark = len(gcs.heard)
        gcs.to_all(gcs.mav.command_long_encode(3, 1, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0,
                                                    0, FORCE, 0, 0, 0, 0, 0))

        def three_disarmed() -> bool:
            gcs.pump()
            return gcs.armed.get(3) is False

        wait_for(three_disarmed, 20, "system 3 disarmed")
        acks = gcs.answers("COMMAND_ACK", mark, command=mavlink.MAV_CMD_COMPONENT_ARM_DISARM)
        assert {m.get_srcSystem() for m in acks} == {3} and acks[0].result == mavlink.MAV_RESULT_ACCEPTED
        assert gcs.armed[1] and gcs.armed[2]  # still flying
        flight.join(180)
    finally:
        flight.join(180)
        gcs.sock.close()
    assert "error" not in result, result.get("error")
    s = result["run"].summary
    by_id = {v["id"]: v for v in s["vehicles"]}
    assert by_id[1]["outcome"] == by_id[2]["outcome"] == "completed" and by_id[1]["ok"] and by_id[2]["ok"]
    assert by_id[3]["outcome"] != "completed" and not by_id[3]["ok"]
    assert "255" in str(by_id[3]["ended_by"]), by_id[3]["ended_by"]  # the ground station's disarm ended it
    assert s["sitl"]["gcs"] == f"127.0.0.1:{port}"


def _addressed(kind: str, target: int) -> Any:
    """A message of ``kind`` as a ground station sends it, to system ``target``, component 1."""
    t, c = target, 1
    make = {
        "COMMAND_LONG": lambda: mavlink.MAVLink_command_long_message(t, c, 400, 0, 0, 0, 0, 0, 0, 0, 0),
        "COMMAND_INT": lambda: mavlink.MAVLink_command_int_message(t, c, 0, 176, 0, 0, 0, 0, 0, 0, 0, 0, 0),
        "PARAM_REQUEST_LIST": lambda: mavlink.MAVLink_param_request_list_message(t, c),
        "PARAM_REQUEST_READ": lambda: mavlink.MAVLink_param_request_read_message(t, c, b"MAV_SYS_ID", -1),
        "PARAM_SET": lambda: mavlink.MAVLink_param_set_message(t, c, b"COM_OF_LOSS_T", 1.0, 9),
        "SET_MODE": lambda: mavlink.MAVLink_set_mode_message(t, 1, 0),
        "MISSION_COUNT": lambda: mavlink.MAVLink_mission_count_message(t, c, 1, 0),
        "MISSION_ITEM": lambda: mavlink.MAVLink_mission_item_message(t, c, 0, 6, 16, 0, 1, 0, 0, 0, 0, 0, 0, 0, 0),
        "MISSION_ITEM_INT": lambda: mavlink.MAVLink_mission_item_int_message(t, c, 0, 6, 16, 0, 1, 0, 0, 0, 0, 0, 0,
                                                                             0, 0),
        "MISSION_CLEAR_ALL": lambda: mavlink.MAVLink_mission_clear_all_message(t, c, 0),
        "MISSION_SET_CURRENT": lambda: mavlink.MAVLink_mission_set_current_message(t, c, 0),
        "MISSION_REQUEST_LIST": lambda: mavlink.MAVLink_mission_request_list_message(t, c, 0),
        "MISSION_REQUEST": lambda: mavlink.MAVLink_mission_request_message(t, c, 0, 0),
        "MISSION_REQUEST_INT": lambda: mavlink.MAVLink_mission_request_int_message(t, c, 0, 0),
        "MISSION_ACK": lambda: mavlink.MAVLink_mission_ack_message(t, c, 0, 0),
    }
    m = make[kind]()
    raw = m.pack(mavlink.MAVLink(None, srcSystem=255, srcComponent=190))
    return mavlink.MAVLink(None).decode(bytearray(raw))  # as the vehicle receives it: its sender's ids set


@pytest.mark.parametrize("kind", sorted(ADDRESSED))
def test_the_vehicle_refuses_every_ground_station_message_for_another_system(kind: str) -> None:
    """Vehicle 2 of a fleet: a message for system 3 is for another (refused as ``target``); one for 2, or for
    everyone (0), is its own."""
    cfg = VehicleConfig(parse_address("127.0.0.1:14561", "udpin"), parse_address("127.0.0.1:14550"), sysid=2)
    who = Authority(cfg)
    assert who.for_others(_addressed(kind, 3))
    assert not who.for_others(_addressed(kind, 2))
    assert not who.for_others(_addressed(kind, 0))
    gcs = ("127.0.0.1", 14550)
    assert who.controller_refusal(_addressed(kind, 3), False, gcs, None, True) == "target"
