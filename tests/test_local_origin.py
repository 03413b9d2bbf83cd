"""Covers bridge.mavlink.telemetry, bridge.nodes.vehicle.streams and bridge.nodes.vehicle.node: own origins.

A ground station reads each vehicle's local position about that vehicle's own start, as PX4 multi-vehicle SITL
gives it (EKF2 sets its origin where the vehicle boots): LOCAL_POSITION_NED reads about (0, 0, 0) at the start
and over it, HOME_POSITION's latitude and longitude are the start's (x, y, z 0), GLOBAL_POSITION_INT is absolute
and agrees with both. The controller link keeps the paper frame (its ODOMETRY's, what the law flies). Built from
the real stream registry, then against real two-vehicle ``bsst sitl`` fleets (``bridge.swarm.sitl``, lockstep and
real time) with pymavlink and with MAVSDK (one ``System`` per vehicle) over UDP on 127.0.0.1.
"""

from __future__ import annotations

import socket
import threading
from pathlib import Path
from typing import Any

import pytest
from pymavlink.dialects.v20 import common as mavlink

from bridge.mavlink import telemetry as tm
from bridge.mavlink.endpoint import GCS_PORT
from bridge.nodes.vehicle.streams import VehicleView, message
from bridge.session import instance_slot
from bridge.swarm import sitl
from tests.sitlkit import ENV, MAVSDK_GROUND_STATION, run_script, script_result
from tests.waiting import wait_for

pytestmark = pytest.mark.process  # starts processes, opens sockets

HOME = tm.Home()
# a hover: up 1 m over the start in 2 s, held there; vehicle 2 of line:2 starts 2 m along +y (west), so 2 m east.
# Its end holds: the end landing (down from 1 m, then COM_DISARM_LAND) flew ~3.5 s more of each pair on the wall
# clock, which no assertion reads (tests/test_mission_end.py flies the end landing)
HOVER = """name = "hover"
duration_s = {T}
[trajectory]
kind = "waypoints"
points = [{{ t = 0.0, x = 0.0, y = 0.0, z = 0.0 }}, {{ t = 2.0, x = 0.0, y = 0.0, z = 1.0 }},
          {{ t = {T}, x = 0.0, y = 0.0, z = 1.0 }}]
[end]
action = "hold"
"""
STARTS = {1: (0.0, 0.0), 2: (0.0, 2.0)}  # paper x, y of each vehicle's start (line:2)


def _view(X: tuple[float, ...], origin: tuple[float, float]) -> VehicleView:
    return VehicleView(X, 1.0, "OFFBOARD", None, True, False, False, (0.0,) * 4, 1.0, 0, None, HOME, 2,
                       origin=origin)


def test_the_streams_read_about_the_vehicles_own_origin_and_the_paper_frames_on_the_controller_link():
    """Built from the registry: at its origin (3, -4) a vehicle 1 m up reads (0, 0, -1) in LOCAL_POSITION_NED,
    HOME_POSITION names that origin's latitude and longitude (x, y, z 0, home's altitude), GLOBAL_POSITION_INT
    is the same point whatever the origin; at the paper frame's own origin every field is as it was, bit for bit
    (-0.0 included)."""
    X = (3.0, 0.5, -4.0, -0.25, 1.0, 0.0) + (0.0,) * 6  # x, vx, y, vy, z, vz (paper frame, NWU)
    own, world = _view(X, (3.0, -4.0)), _view(X, (0.0, 0.0))
    lp = message(mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED, own)[0]
    assert (lp.x, lp.y, lp.z, lp.vx, lp.vy, lp.vz) == (0.0, 0.0, -1.0, 0.5, 0.25, -0.0)
    home = message(mavlink.MAVLINK_MSG_ID_HOME_POSITION, own)[0]
    lat, lon, _ = HOME.global_of(3.0, 4.0, 0.0)
    assert (home.latitude, home.longitude, home.altitude) == (round(lat * 1e7), round(lon * 1e7), 488000)
    assert (home.x, home.y, home.z) == (0.0, 0.0, 0.0)
    gp = message(mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, own)[0]
    assert gp.to_dict() == message(mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, world)[0].to_dict()
    assert (gp.lat, gp.lon, gp.relative_alt) == (home.latitude, home.longitude, 1000)
    wp = message(mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED, world)[0]
    assert (wp.x, wp.y, wp.z) == (3.0, 4.0, -1.0)
    rest = _view((0.0,) * 12, (0.0, 0.0))  # at the paper frame's origin: the bytes of before
    packed = message(mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED, rest)[0].pack(mavlink.MAVLink(None))
    assert packed == tm.mavlink.MAVLink_local_position_ned_message(1000, 0.0, -0.0, -0.0, 0.0, -0.0, -0.0).pack(
        mavlink.MAVLink(None))
    assert message(mavlink.MAVLINK_MSG_ID_HOME_POSITION, rest)[0].to_dict() == tm.home_position(HOME).to_dict()


def _fly(tmp_path: Path, gcs_port: int, realtime: bool, seconds: float) -> tuple[threading.Thread, dict[str, Any]]:
    """Two vehicles (line:2) hovering over their starts, their GCS links to ``gcs_port``, in a thread. Their control
    steps at 100 Hz, not 250: each message a ground station reads is the same at any rate (where the vehicle is,
    said in its frames), and the paced steps (state, target, each process woken) cost each pair ~0.08 CPU-s a second
    more at 250 Hz (tests/test_swarm_gcs.py)."""
    mission = tmp_path / "hover.toml"
    mission.write_text(HOVER.format(T=seconds))
    result: dict[str, Any] = {}

    def fly() -> None:
        try:
            result["run"] = sitl(mission, vehicles=2, formation="line:2", instance=None, gcs=f"127.0.0.1:{gcs_port}",
                                 realtime=realtime, speed=None if realtime else 1.0, out=tmp_path / "run",
                                 plots=False, rate_hz=100.0)
        except BaseException as exc:  # noqa: BLE001  (named by the caller's assertion)
            result["error"] = exc

    flight = threading.Thread(target=fly, daemon=True)
    flight.start()
    return flight, result


def _completed(result: dict[str, Any]) -> None:
    assert "error" not in result, result.get("error")
    assert [v["outcome"] for v in result["run"].summary["vehicles"]] == ["completed", "completed"]


def _home_of(i: int) -> tuple[int, int]:
    """Vehicle i's start's latitude and longitude (degE7): its HOME_POSITION."""
    x, y = STARTS[i]
    lat, lon, _ = HOME.global_of(x, -y, 0.0)
    return round(lat * 1e7), round(lon * 1e7)


@pytest.mark.parametrize("realtime", [False, True], ids=["lockstep", "realtime"])
def test_pymavlink_reads_each_fleet_vehicle_about_its_own_start(tmp_path: Path, realtime: bool) -> None:
    """Each vehicle's HOME_POSITION is its own start; hovering 1 m over it, its LOCAL_POSITION_NED reads (0, 0, -1)
    (vehicle 2 read (0, -2, -1), the fleet's shared frame, before); every LOCAL_POSITION_NED agrees with the
    GLOBAL_POSITION_INT of the same instant projected about the HOME_POSITION (PX4's projection). A 4 s hover
    flight: at 1 m from 2 s on, asked for HOME_POSITION at the first HEARTBEAT (6 s flew 2 s more of the hover)."""
    local: dict[tuple[int, int], Any] = {}
    glob: dict[tuple[int, int], Any] = {}
    homes: dict[int, Any] = {}
    every_home: list[Any] = []  # streamed, and the answers to GET_HOME_POSITION (it named the world's origin)
    asked: dict[int, int] = {}  # sysid: GET_HOME_POSITION's result
    senders: dict[int, tuple[str, int]] = {}  # sysid: where its first HOME_POSITION came from
    with instance_slot() as n:
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.bind(("127.0.0.1", GCS_PORT + n))
        sock.setblocking(False)
        mav, tx = mavlink.MAVLink(None), mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
        flight, result = _fly(tmp_path, GCS_PORT + n, realtime, 4.0)

        def pump() -> bool:
            while True:
                try:
                    data, addr = sock.recvfrom(65536)
                except BlockingIOError:
                    return not flight.is_alive()
                for m in mav.parse_buffer(data) or []:
                    kind, key = m.get_type(), (m.get_srcSystem(), getattr(m, "time_boot_ms", 0))
                    if kind == "LOCAL_POSITION_NED":
                        local[key] = m
                    elif kind == "GLOBAL_POSITION_INT":
                        glob[key] = m
                    elif kind == "HOME_POSITION":
                        homes[m.get_srcSystem()] = m
                        every_home.append(m)
                        senders.setdefault(m.get_srcSystem(), addr)
                    elif kind == "HEARTBEAT" and m.get_srcSystem() not in asked:
                        asked[m.get_srcSystem()] = -1
                        sock.sendto(tx.command_long_encode(m.get_srcSystem(), 1, mavlink.MAV_CMD_GET_HOME_POSITION,
                                                           0, 0, 0, 0, 0, 0, 0, 0).pack(tx), addr)
                    elif kind == "COMMAND_ACK" and m.command == mavlink.MAV_CMD_GET_HOME_POSITION:
                        asked[m.get_srcSystem()] = m.result

        try:
            wait_for(pump, 180, "the fleet's flight to end")
        finally:
            flight.join(60)
            sock.close()
    _completed(result)
    # a stranger's HOME_POSITION on this instance's port (system 8 from an unknown sender twice in loaded suites,
    # 2026-12-06): named with its address, for whoever flew an instance without holding its slot
    assert sorted(homes) == [1, 2], (sorted(homes), senders, n)
    assert asked == {1: mavlink.MAV_RESULT_ACCEPTED, 2: mavlink.MAV_RESULT_ACCEPTED}, asked
    for h in every_home:
        i = h.get_srcSystem()
        assert (h.latitude, h.longitude, h.altitude, h.x, h.y, h.z) == (*_home_of(i), 488000, 0.0, 0.0, 0.0), h
    pairs = [(lp, glob[key]) for key, lp in local.items() if key in glob]
    assert {lp.get_srcSystem() for lp, _ in pairs} == {1, 2}
    for lp, gp in pairs:
        h = homes[lp.get_srcSystem()]
        north, east, _ = tm.Home(h.latitude * 1e-7, h.longitude * 1e-7, 488.0).ned(gp.lat * 1e-7, gp.lon * 1e-7, 0.0)
        assert abs(north - lp.x) < 0.02 and abs(east - lp.y) < 0.02, (lp, gp)  # degE7: about 1 cm
        assert abs(gp.relative_alt * 1e-3 + lp.z) < 0.002, (lp, gp)
    for i in (1, 2):
        hover = [lp for (s, _), lp in local.items() if s == i and lp.z < -0.95]
        assert hover, f"vehicle {i} never hovered"
        assert all(abs(lp.x) < 0.05 and abs(lp.y) < 0.05 for lp in hover), (i, hover[0])


MAVSDK_SCRIPT = MAVSDK_GROUND_STATION + r"""
import math
from mavsdk.plugins.telemetry import Telemetry
out["two_found"] = until(lambda: sum(s.has_autopilot() for s in sdk.get_systems()) >= 2, 90)
by = {s.get_system_id(): s for s in sdk.get_systems() if s.has_autopilot()}
tel = {i: Telemetry(s) for i, s in by.items()}
seen = {}
def hovering(i):  # and its home heard (MAVSDK's NaN until the first HOME_POSITION, 0.5 Hz, or its request's answer)
    ned = tel[i].position_velocity_ned().position
    pos, home = tel[i].position(), tel[i].home()
    if ned.down_m < -0.95 and i not in seen and not math.isnan(home.latitude_deg):
        seen[i] = {"ned": [ned.north_m, ned.east_m, ned.down_m], "pos": [pos.latitude_deg, pos.longitude_deg],
                   "home": [home.latitude_deg, home.longitude_deg, home.local_north_m, home.local_east_m]}
    return i in seen
out["hovered"] = until(lambda: all([hovering(i) for i in sorted(tel)]), 90)
out["seen"] = seen
print("RESULT " + json.dumps(out), flush=True)
sdk.destroy()
"""


def test_mavsdk_reads_each_fleet_vehicle_about_its_own_start(tmp_path: Path) -> None:
    """MAVSDK, a ``System`` per vehicle: hovering 1 m over its start each vehicle's ``position_velocity_ned`` reads
    (0, 0, -1), its ``home`` is its start's latitude and longitude, its ``position`` over that home. A 6 s flight,
    at 1 m from 2 s on: MAVSDK finds the two while they start (tests/test_swarm_gcs.py: four found and one killed
    0.96 s into the flight with two busy loops); 10 s flew 4 s more of the hover."""
    with instance_slot() as n:
        flight, result = _fly(tmp_path, GCS_PORT + n, False, 6.0)
        try:
            r = run_script("-c", MAVSDK_SCRIPT, f"udpin://127.0.0.1:{GCS_PORT + n}", timeout=240, env=ENV)
        finally:
            flight.join(240)
    out = script_result(r)
    assert out["two_found"] and out["hovered"], out
    _completed(result)
    for i in (1, 2):
        s = out["seen"][str(i)]
        north, east, down = s["ned"]
        assert abs(north) < 0.05 and abs(east) < 0.05 and abs(down + 1.0) < 0.05, (i, s)
        lat, lon = (v * 1e-7 for v in _home_of(i))
        assert abs(s["home"][0] - lat) < 2e-7 and abs(s["home"][1] - lon) < 2e-7, (i, s)
        assert s["home"][2:] == [0.0, 0.0], (i, s)
        pn, pe, _ = tm.Home(lat, lon, 488.0).ned(*s["pos"], 488.0)
        assert abs(pn) < 0.05 and abs(pe) < 0.05, (i, s)  # over its home
