"""Covers bridge.session.fleet and bridge.nodes.vehicle.authority: one ground station, every vehicle of a fleet.

Real processes: ``bridge.swarm.sitl`` flies four vehicles (a vehicle and a controller process each) whose
ground-station links all go to one UDP port, where a pymavlink ground station (sysid 255) listens. It sees
HEARTBEATs from systems 1 to 4, reads a parameter of each by its ``target_system`` (only that system
answers), and a disarm (COMMAND_LONG to system 3, sent to every vehicle as a MAVLink router would) disarms
system 3 alone: 1, 2 and 4 fly their missions to the end. The same with MAVSDK's native binding (one ``System``
per vehicle, ``Action.kill`` on system 3). And, without processes, the vehicle's authority refuses
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
from tests.sitlkit import ENV, MAVSDK_GROUND_STATION, run_script, script_result, tlog_messages
from tests.waiting import wait_for

pytestmark = pytest.mark.process  # starts processes, opens sockets

FORCE = 21196  # param2 of a disarm in flight (PX4's magic number)
ARMED = mavlink.MAV_MODE_FLAG_SAFETY_ARMED


class Station:
    """A ground station on one UDP port: the address each system speaks from, and every HEARTBEAT, PARAM_VALUE
    and COMMAND_ACK heard (the rest of four vehicles' streams, ~520 messages/s, is known by its header alone:
    a starved test process that parsed all of it fell seconds behind them, past the end of their flight)."""

    KEPT = (mavlink.MAVLINK_MSG_ID_HEARTBEAT, mavlink.MAVLINK_MSG_ID_PARAM_VALUE, mavlink.MAVLINK_MSG_ID_COMMAND_ACK)

    def __init__(self, port: int) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 21)
        self.sock.bind(("127.0.0.1", port))
        self.sock.setblocking(False)
        self.mav = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
        self.addr: dict[int, tuple[str, int]] = {}
        self.armed: dict[int, bool] = {}
        self.heard: list[Any] = []

    def _keeps(self, data: bytes, addr: tuple[str, int]) -> bool:
        """Whether a frame of the datagram is one kept (each MAVLink 2 frame's header names its sender and message:
        the senders' addresses are learnt here); anything else is parsed, to be judged by pymavlink."""
        i = 0
        while i + 10 <= len(data) and data[i] == mavlink.PROTOCOL_MARKER_V2:
            self.addr[data[i + 5]] = addr
            if int.from_bytes(data[i + 7:i + 10], "little") in self.KEPT:
                return True
            i += 10 + data[i + 1] + 2 + (13 if data[i + 2] & mavlink.MAVLINK_IFLAG_SIGNED else 0)
        return i != len(data)

    def pump(self) -> None:
        while True:
            try:
                data, addr = self.sock.recvfrom(65536)
            except BlockingIOError:
                return
            if not self._keeps(data, addr):
                continue
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


def _fly_fleet(tmp_path: Path, port: int, seconds: float) -> tuple[threading.Thread, dict[str, Any]]:
    """Four vehicles of the sine in lockstep at real time's pace, their GCS links to ``port``, in a thread. The
    mission's end holds (``[end] action = "hold"``): its landing (to the ground and COM_DISARM_LAND after) added
    ~4 s of four paced pairs that no assertion reads (tests/test_mission_end.py flies the end landing). Its control
    steps at 100 Hz, not the sine's 250: what a ground station sees and is answered (HEARTBEAT, the parameters, the
    disarm and its ACK, each vehicle's refusals) is the same at any rate, and each paced step (the state, the target,
    the gate's word, a wake-up of each process) cost four paced pairs ~0.3 CPU-s a second more at 250 Hz."""
    mission = tmp_path / "sine.toml"
    mission.write_text((MISSION_DIR / "sine.toml").read_text().replace("duration_s = 30.0", f"duration_s = {seconds}")
                       + '\n[end]\naction = "hold"\n')
    result: dict[str, Any] = {}

    def fly() -> None:
        try:
            result["run"] = sitl(mission, vehicles=4, formation="line:2", instance=None, gcs=f"127.0.0.1:{port}",
                                 speed=1.0, out=tmp_path / "run", plots=False, rate_hz=100.0)
        except BaseException as exc:  # noqa: BLE001  (named by the caller's assertion)
            result["error"] = exc

    flight = threading.Thread(target=fly, daemon=True)
    flight.start()
    return flight, result


def _only_three_disarmed(result: dict[str, Any], port: int) -> None:
    """The fleet's summary: 1, 2 and 4 completed, 3 ended by the ground station's disarm."""
    assert "error" not in result, result.get("error")
    s = result["run"].summary
    by_id = {v["id"]: v for v in s["vehicles"]}
    assert all(by_id[i]["outcome"] == "completed" and by_id[i]["ok"] for i in (1, 2, 4)), by_id
    assert by_id[3]["outcome"] != "completed" and not by_id[3]["ok"]
    assert "255" in str(by_id[3]["ended_by"]) or "245" in str(by_id[3]["ended_by"]), by_id[3]["ended_by"]
    assert s["sitl"]["gcs"] == f"127.0.0.1:{port}"


def test_one_ground_station_sees_four_vehicles_reads_each_and_disarms_only_system_3(tmp_path: Path) -> None:
    """The fleet flies 5 s: this station (parsing only the frames it keeps) disarmed system 3 at t = 1.26 s of the
    fleet's flight quiet, 1.12 s with two busy loops on the cores, 1.26 s at load 10.6 (forty-fifth session); the
    8 s it flew until then were 3 s more of four paced pairs (~1 CPU-s) for nothing. 5 s, not less: before it parsed
    only those frames, a starved test process once fell seconds behind four vehicles' streams, its request to
    system 3 out at +4.1 s (docs/figures.md)."""
    port = free_udp_port()
    gcs = Station(port)
    flight, result = _fly_fleet(tmp_path, port, 5.0)
    try:
        def all_armed() -> bool:
            gcs.pump()
            return sorted(s for s, a in gcs.armed.items() if a) == [1, 2, 3, 4]

        wait_for(all_armed, 90, "heartbeats of systems 1 to 4, armed")
        for i in (1, 2, 3, 4):  # each vehicle's parameter, read by its id: only that system answers
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
        assert gcs.armed[1] and gcs.armed[2] and gcs.armed[4]  # still flying
        flight.join(180)
    finally:
        flight.join(180)
        gcs.sock.close()
    _only_three_disarmed(result, port)
    for i in (1, 2, 3, 4):  # each refused what was for the others, counted, said to no one (PX4 drops it silently)
        said = [m.text for m in tlog_messages(tmp_path / "run" / f"vehicle-{i}" / "vehicle.tlog", i, "STATUSTEXT")]
        assert not [t for t in said if t.startswith("rejected") and "target" in t], (i, said)
        assert result["run"].runs[i - 1].summary["link"]["rejected"]["target"] >= 3, i



MAVSDK_SCRIPT = MAVSDK_GROUND_STATION + r"""
from mavsdk.plugins.action import Action
from mavsdk.plugins.param import Param
from mavsdk.plugins.telemetry import Telemetry
out["four_found"] = until(lambda: sum(s.has_autopilot() for s in sdk.get_systems()) >= 4, 90)
by = {s.get_system_id(): s for s in sdk.get_systems() if s.has_autopilot()}
out["ids"] = sorted(by)
out["MAV_SYS_ID"] = {str(i): Param(s).get_param_int("MAV_SYS_ID") for i, s in by.items()}
tel = {i: Telemetry(s) for i, s in by.items()}
out["all_armed"] = until(lambda: all(t.armed() for t in tel.values()), 30)
out["kill_3"] = Action(by[3]).kill().name
out["three_disarmed"] = until(lambda: not tel[3].armed(), 20)
out["armed_after"] = {str(i): t.armed() for i, t in tel.items()}
print("RESULT " + json.dumps(out), flush=True)
sdk.destroy()
"""


def test_mavsdk_sees_four_systems_on_one_port_reads_each_and_kills_only_system_3(tmp_path: Path) -> None:
    """MAVSDK's native binding, one ``System`` per vehicle on the one port: ids 1-4, each one's MAV_SYS_ID read
    through its own System, and ``Action.kill`` (a forced disarm) on system 3 disarms only 3. The fleet flies 4 s:
    MAVSDK's script (its native binding: its own threads, not this process's) found the four while they started and
    killed system 3 at t = 0.97 s of the fleet's flight quiet, 0.96 s with two busy loops on the cores, 0.94 s at
    load 10.6; the 20 s it flew once, then 8 s, were four paced pairs for nothing after that (~0.35 CPU-s a second:
    forty-fifth session)."""
    port = free_udp_port()
    flight, result = _fly_fleet(tmp_path, port, 4.0)
    try:
        r = run_script("-c", MAVSDK_SCRIPT, f"udpin://127.0.0.1:{port}", timeout=240, env=ENV)
    finally:
        flight.join(240)
    out = script_result(r)
    assert out["four_found"] and out["ids"] == [1, 2, 3, 4], out
    assert out["MAV_SYS_ID"] == {"1": 1, "2": 2, "3": 3, "4": 4}, out
    assert out["all_armed"] and out["kill_3"] == "SUCCESS" and out["three_disarmed"], out
    assert out["armed_after"] == {"1": True, "2": True, "3": False, "4": True}, out
    _only_three_disarmed(result, port)


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
