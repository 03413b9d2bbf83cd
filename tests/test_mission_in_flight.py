"""Covers bridge.nodes.vehicle.mission, bridge.nodes.vehicle.missiontransfer and bridge.nodes.vehicle.setcurrent: the
mission while it is flown.

``bsst sitl --await-mission`` (lockstep) and a pymavlink ground station on 127.0.0.1: the controller flies the
whole trajectory, planned from item 0, so a current item a ground station chose (MISSION_SET_CURRENT, or the command
DO_SET_MISSION_CURRENT) is refused at the start instead of being dropped, and while the mission flies an upload, a
clear and a new current item are refused (MAV_MISSION_ERROR or DENIED, and a STATUSTEXT saying why) instead of being
taken and not flown; a fence may still change. ``bsst vehicle`` and ``bsst controller --await-mission`` on the wall
clock: once the mission has ended in HOLD (armed, the controller gone) a ground station's upload is taken, as on PX4.
A start refused for an item not flown says so whole, the commands flown listed (a STATUSTEXT once cut at 200
characters). Every wait is on a message or a process with a deadline.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as M

from bridge.mavlink.endpoint import GCS_PORT
from bridge.mavlink.telemetry import StatusTextJoiner
from bridge.nodes.report import Ready
from bridge.session import instance_slot
from missions import MISSION_DIR
from tests.sitlkit import ROOT, Proc, controller_exit
from tests.waiting import wait_for

pytestmark = pytest.mark.process  # starts processes or opens sockets: not in make test-fast

HOME = (473977420, 85455940)  # degE7: the vehicle's default home (PX4 SITL's)
AUTO_MISSION = (4 << 16) | (4 << 24)  # PX4's custom_mode: main AUTO, sub MISSION


def _items(target: tuple[int, int] = (0, 0), up_m: float = 5.0) -> list[Any]:
    """A takeoff to ``up_m``, a waypoint 20 m north, a landing there, addressed to ``target`` (system, component):
    19.8 s of flight at 5 m, 15.9 s at 3 m (its landing the shorter)."""
    north = HOME[0] + 1800
    spec = ((M.MAV_CMD_NAV_TAKEOFF, HOME[0], up_m), (M.MAV_CMD_NAV_WAYPOINT, north, up_m),
            (M.MAV_CMD_NAV_LAND, north, 0.0))
    return [M.MAVLink_mission_item_int_message(*target, seq, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, cmd, 0, 1, 0.0, 0.0,
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

    def upload(self, items: list[Any], mission_type: int = M.MAV_MISSION_TYPE_MISSION) -> int:
        """MISSION_COUNT (of ``mission_type``), each item requested, the MISSION_ACK's result."""
        self.c.mav.mission_count_send(*self.t, len(items), mission_type)
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

    def command(self, cmd: int, *params: float) -> int:
        """COMMAND_LONG ``cmd`` with ``params`` (the rest 0): its COMMAND_ACK's result."""
        self.c.mav.command_long_send(*self.t, cmd, 0, *params, *[0.0] * (7 - len(params)))
        return self.recv("COMMAND_ACK", cond=f"COMMAND_ACK.command=={cmd}").result

    def joined_text(self, part: str, timeout: float = 5.0) -> str:
        """The first STATUSTEXT, its chunks joined (MAVLink 2's id and chunk_seq), that contains ``part``."""
        joiner = StatusTextJoiner()
        found: list[str] = []

        def seen() -> bool:
            m = self.c.recv_match(type="STATUSTEXT", blocking=True, timeout=0.5)
            found.extend(t for _, t in (joiner.add(m, 0.0) if m is not None else []) if part in t)
            return bool(found)

        wait_for(seen, timeout, f"a STATUSTEXT saying {part!r}", poll_s=0.0)
        return found[0]


def _fly_await_mission(out: Path, script: Callable[[_Gcs], None], *flags: str, speed: str = "0",
                       status: int = 0) -> list[str]:
    """``bsst sitl --await-mission --speed SPEED FLAGS`` into ``out``, a ground station's ``script`` run against it;
    the flight must then complete, exit ``status``. Its events.log lines."""
    with instance_slot() as n:
        sitl = Proc.bsst("sitl", "--await-mission", "--speed", speed, "--instance", str(n), "--out", str(out),
                         "--no-plots", *flags)
        gcs = None
        try:
            gcs = _Gcs(n)
            script(gcs)
            rc = sitl.p.wait(timeout=120)
        finally:
            if gcs is not None:
                gcs.c.close()
            sitl.stop()
    summary = json.loads((out / "summary.json").read_text())
    assert rc == status and summary["outcome"] == "completed", "\n".join(sitl.lines[-20:])
    return (out / "events.log").read_text().splitlines()


@pytest.fixture(scope="module")
def current_item_chosen(tmp_path_factory: pytest.TempPathFactory) -> list[str]:
    """One ``bsst sitl --await-mission`` (lockstep) whose ground station chooses the current item both ways, before
    the start and while the mission flies, each answer checked as it comes: DO_SET_MISSION_CURRENT (the second test
    below) before any upload, then with the mission held, item 0 again; then MISSION_SET_CURRENT (the first test),
    whose start flies; in flight, DO_SET_MISSION_CURRENT, then an upload, clears and MISSION_SET_CURRENT. The flight
    completes. Its events.log lines, which the two tests read (each flew a session of its own: the same flight)."""
    def script(gcs: _Gcs) -> None:
        cmd = M.MAV_CMD_DO_SET_MISSION_CURRENT  # (test_do_set_mission_current_..., before the start)
        assert gcs.command(cmd, 0) == M.MAV_RESULT_FAILED
        assert "no mission held" in gcs.joined_text("DO_SET_MISSION_CURRENT")
        assert gcs.upload(_items()) == M.MAV_MISSION_ACCEPTED
        assert gcs.command(cmd, 1) == M.MAV_RESULT_ACCEPTED
        gcs.recv("MISSION_CURRENT", cond="MISSION_CURRENT.seq==1")
        assert gcs.command(cmd, 5) == M.MAV_RESULT_FAILED
        assert "item 5 is not in the mission (items 0 to 2)" in gcs.joined_text("DO_SET_MISSION_CURRENT")
        assert gcs.command(cmd, -2) == M.MAV_RESULT_DENIED
        assert "param1" in gcs.joined_text("DO_SET_MISSION_CURRENT")
        assert gcs.command(cmd, 1, 2) == M.MAV_RESULT_DENIED
        assert "param2" in gcs.joined_text("DO_SET_MISSION_CURRENT")
        assert gcs.command(cmd, -1) == M.MAV_RESULT_ACCEPTED
        gcs.recv("MISSION_CURRENT", cond="MISSION_CURRENT.seq==1")
        assert gcs.start() == M.MAV_RESULT_DENIED
        assert "the current item is 1" in gcs.text("MISSION_START: the current")
        assert gcs.command(cmd, 0) == M.MAV_RESULT_ACCEPTED
        gcs.recv("MISSION_CURRENT", cond="MISSION_CURRENT.seq==0")

        gcs.c.mav.mission_set_current_send(*gcs.t, 1)  # (test_a_chosen_current_item_..., before the start)
        gcs.recv("MISSION_CURRENT", cond="MISSION_CURRENT.seq==1")
        assert gcs.start() == M.MAV_RESULT_DENIED
        assert "the current item is 1" in gcs.text("MISSION_START: the current")
        gcs.c.mav.mission_set_current_send(*gcs.t, 0)
        gcs.recv("MISSION_CURRENT", cond="MISSION_CURRENT.seq==0")
        assert gcs.start() == M.MAV_RESULT_ACCEPTED
        gcs.recv("HEARTBEAT", 30, f"HEARTBEAT.get_srcComponent()==1 and HEARTBEAT.base_mode & 128 and "
                                  f"HEARTBEAT.custom_mode=={AUTO_MISSION}")

        assert gcs.command(cmd, 2) == M.MAV_RESULT_DENIED  # (test_do_set_mission_current_..., in flight)
        assert "flying the mission" in gcs.joined_text("DO_SET_MISSION_CURRENT")

        gcs.c.mav.mission_count_send(*gcs.t, 2, M.MAV_MISSION_TYPE_MISSION)  # (test_a_chosen_current_..., in flight)
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
    return _fly_await_mission(tmp_path_factory.mktemp("current") / "run", script)


def test_a_chosen_current_item_is_refused_at_the_start_and_the_flown_mission_cannot_change(current_item_chosen):
    """MISSION_SET_CURRENT 1 is taken (MISSION_CURRENT says 1, as PX4), but MISSION_START is then DENIED, saying
    the current item is 1 (PX4 would start there; the flight here is the whole trajectory, and it once flew it
    from item 0 while the ground station had been told 1). Item 0 current again, the start is ACCEPTED. While the
    mission flies (AUTO.MISSION, armed): an upload and a clear are MAV_MISSION_ERROR, MISSION_SET_CURRENT changes
    nothing (each with a STATUSTEXT saying why; they were once taken: the heartbeat showed OFFBOARD and
    MISSION_CURRENT a mission not started while the old one flew on); a fence may still be cleared. The flight
    completes, its mission never replaced. (The session's ground station checks each answer as it comes:
    :func:`current_item_chosen`.)"""
    texts = current_item_chosen
    assert not any("replaced by an upload" in t for t in texts), texts
    assert sum("mission: uploaded" in t for t in texts) == 1
    assert not any("mission: current item 2" in t or "mission: cleared" in t for t in texts), texts
    by_message = [t for t in texts if "mission: current item" in t and "DO_SET_MISSION_CURRENT" not in t]
    assert [t.split("mission: ")[1].split(" [")[0] for t in by_message] == ["current item 1", "current item 0"], texts


def _fence_items(half_m: float) -> list[Any]:
    """An inclusion square ``half_m`` m each way about the home (degE7, 1e-5 deg of latitude is 1.11 m), as a ground
    station uploads it (MAV_MISSION_TYPE_FENCE: four vertices, each with the polygon's count)."""
    dlat, dlon = round(half_m / 1.11 * 100), round(half_m / (1.11 * math.cos(math.radians(47.4))) * 100)
    corners = ((-dlat, -dlon), (-dlat, dlon), (dlat, dlon), (dlat, -dlon))
    return [M.MAVLink_mission_item_int_message(0, 0, seq, M.MAV_FRAME_GLOBAL_INT,
                                               M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION, 0, 1, 4.0, 0.0, 0.0, 0.0,
                                               HOME[0] + a, HOME[1] + b, 0.0, M.MAV_MISSION_TYPE_FENCE)
            for seq, (a, b) in enumerate(corners)]


def test_with_gf_action_0_a_fence_uploaded_in_flight_and_left_fails_the_geofence_policy(tmp_path):
    """``--param GF_ACTION=0``: a ground station uploads a fence 5 m about home once the mission flies (armed,
    AUTO.MISSION) and the flight, 20 m north, leaves it. The vehicle acts on nothing (the flight flies on to its end),
    but it says where it left the fence, for the record (a ``geofence`` event: nothing else holds that fence's
    shape), so the geofence policy fails there and ``bsst sitl`` exits 1. Until the third wave's thirty-seventh
    session the vehicle said nothing, the policy held with a note that the new fence was not judged, and the run
    exited 0. summary.json's ``mission_transfer`` has the fence's and the rally points' downloads (none then) beside
    the mission's."""
    def fence_in_flight(gcs: _Gcs) -> None:  # (at 3 m: a flight at 2x real time shorter by 2 s, 5 m north at 5.6 s)
        assert gcs.upload(_items(up_m=3.0)) == M.MAV_MISSION_ACCEPTED
        assert gcs.start() == M.MAV_RESULT_ACCEPTED
        gcs.recv("HEARTBEAT", 30, f"HEARTBEAT.get_srcComponent()==1 and HEARTBEAT.base_mode & 128 and "
                                  f"HEARTBEAT.custom_mode=={AUTO_MISSION}")
        assert gcs.upload(_fence_items(5.0), M.MAV_MISSION_TYPE_FENCE) == M.MAV_MISSION_ACCEPTED

    out = tmp_path / "run"
    # (landed, the vehicle disarms 0.5 s later, not PX4's 2 s: at 2x real time, each second is the test's CPU)
    _fly_await_mission(out, fence_in_flight, "--param", "GF_ACTION=0", "--param", "COM_DISARM_LAND=0.5", speed="2",
                       status=1)
    summary = json.loads((out / "summary.json").read_text())
    fence = next(p for p in summary["policies"] if p["name"] == "geofence")
    assert not fence["ok"] and "outside its fence" in fence["why"], fence
    assert "GF_ACTION = 0: not acted on; said for the run's record" in fence["why"], fence
    north = next(t for t, x in zip(*_trace_tx(out / "trace.csv")) if x > 5.0)  # the square's north side, 5 m
    assert 0.0 < fence["t"] - north <= 0.05, (fence["t"], north)
    kinds = [e["kind"] for e in summary["events"]]
    assert kinds.index("armed") < kinds.index("fence") < kinds.index("geofence"), kinds
    t = summary["mission_transfer"]
    assert t["items"] == 3 and (t["fence"]["items"], t["fence"]["result"]) == (0, "accepted"), t
    assert (t["rally"]["items"], t["rally"]["result"]) == (0, "accepted"), t


def _trace_tx(path: Path) -> tuple[list[float], list[float]]:
    """trace.csv's ``t`` and ``x`` columns (s, m north of the start)."""
    rows = path.read_text().splitlines()
    head = rows[0].split(",")
    it, ix = head.index("t"), head.index("x")
    cells = [r.split(",") for r in rows[1:]]
    return [float(c[it]) for c in cells], [float(c[ix]) for c in cells]


def test_do_set_mission_current_is_answered_as_px4_before_the_start_and_refused_while_the_mission_flies(
        current_item_chosen):
    """MAV_CMD_DO_SET_MISSION_CURRENT (224; the vehicle once answered it UNSUPPORTED), as PX4's navigator answers it:
    without a mission FAILED; item 1 ACCEPTED with MISSION_CURRENT 1 in its datagram; an item out of range FAILED; a
    param1 below -1 or a param2 other than 0 / 1 DENIED (each with a STATUSTEXT saying why); -1 ACCEPTED, the
    current item unchanged. Item 1 chosen, MISSION_START is DENIED as after MISSION_SET_CURRENT; item 0 again, the
    start is ACCEPTED (here after the test above's MISSION_SET_CURRENT 1 and 0: :func:`current_item_chosen`), and
    while the mission flies the command is DENIED (the controller cannot jump). The flight completes from item 0;
    the choices are ``mission`` events naming the ground station."""
    texts = current_item_chosen
    chosen = [t for t in texts if "mission: current item" in t and "DO_SET_MISSION_CURRENT" in t]
    assert len(chosen) == 3 and all("255:190" in t for t in chosen), chosen
    assert sum("mission: current item" in t for t in texts) == 5, texts  # and the test above's two
    assert not any("current item 2" in t for t in texts), texts


def _short_hop() -> list[Any]:
    """A takeoff to 1 m and a waypoint 0.5 m north (MISSION_ITEM_INT): 5.5 s on the wall clock, up 0.5 m after
    0.8 s (2 m north: 6.5 s; 10 m at 3 m took 9.2 s); what the tests flying it check is what the vehicle does after,
    not the flight."""
    spec = ((M.MAV_CMD_NAV_TAKEOFF, HOME[0], 1.0), (M.MAV_CMD_NAV_WAYPOINT, HOME[0] + 45, 1.0))
    return [M.MAVLink_mission_item_int_message(0, 0, seq, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, c, 0, 1, 0.0, 0.0,
                                               0.0, math.nan, lat, HOME[1], z, 0)
            for seq, (c, lat, z) in enumerate(spec)]


@contextlib.contextmanager
def _awaiting_on_the_wall_clock(settings: Path, out: Path) -> Iterator[tuple[_Gcs, Any, Any]]:
    """``bsst vehicle`` and ``bsst controller`` of ``settings`` awaiting a mission in real time, and a ground
    station on the vehicle's instance: (the ground station, the controller, the vehicle), all stopped after."""
    with instance_slot() as n:
        vehicle = Proc.bsst("vehicle", str(settings), "--await-mission", "--realtime", "--instance", str(n),
                            "--out", str(out), cwd=ROOT)
        controller = gcs = None
        try:
            vehicle.wait_report(Ready, timeout=60)
            gcs = _Gcs(n)
            controller = Proc.bsst("controller", str(settings), "--await-mission", "--realtime", "--instance", str(n),
                                   "--out", str(out), "--overwrite", cwd=ROOT)
            controller.wait_report(Ready, timeout=60)
            yield gcs, controller, vehicle
        finally:
            if gcs is not None:
                gcs.c.close()
            if controller is not None:
                controller.stop()
            vehicle.stop()


def test_an_upload_after_the_mission_ended_in_hold_is_taken_while_armed_as_on_px4(tmp_path):
    """``bsst vehicle`` and ``bsst controller`` awaiting a mission on the wall clock, the mission's end action HOLD:
    a ground station uploads a takeoff and a waypoint and starts them; the controller flies them, hands the vehicle
    HOLD and exits. The vehicle holds, armed, its mission COMPLETE; an upload then is ACCEPTED (it was refused until
    a disarm: the controller flies nothing any more, and PX4 takes an upload at any time), the new mission
    NOT_STARTED, and DO_SET_MISSION_CURRENT is ACCEPTED on it; the vehicle still holds, armed. MISSION_START and
    AUTO.MISSION there are DENIED, saying why (PX4 would fly the mission on; AUTO.MISSION was ACCEPTED and did nothing).
    A MISSION_START whose param1 is NaN is DENIED, as PX4's commander denies it (it was taken as item 0). Before, a
    start with an item this vehicle does not fly (DO_JUMP) is refused saying so whole, every command it flies listed
    (its STATUSTEXT was once cut at 200 characters, the list with it)."""
    settings = tmp_path / "hold.toml"
    settings.write_text((MISSION_DIR / "sine.toml").read_text() + '\n[end]\naction = "hold"\n')
    out = tmp_path / "run"
    items = _short_hop()

    def spec_of(it: Any) -> tuple[Any, ...]:  # an item's fields after target and seq
        return (it.frame, it.command, it.current, it.autocontinue, it.param1, it.param2, it.param3, it.param4, it.x,
                it.y, it.z, it.mission_type)
    hold = (4 << 16) | (3 << 24)
    with _awaiting_on_the_wall_clock(settings, out) as (gcs, controller, vehicle):
        jump = M.MAVLink_mission_item_int_message(0, 0, 1, M.MAV_FRAME_MISSION, M.MAV_CMD_DO_JUMP, 0, 1, 0.0,
                                                  1.0, 0.0, 0.0, 0, 0, 0.0, 0)
        last = M.MAVLink_mission_item_int_message(0, 0, 2, *spec_of(items[1]))
        assert gcs.upload([items[0], jump, last]) == M.MAV_MISSION_ACCEPTED  # PX4 takes DO_JUMP
        assert gcs.start() == M.MAV_RESULT_DENIED
        said = gcs.joined_text("MISSION_START: the mission cannot be flown")
        assert gcs.upload(items) == M.MAV_MISSION_ACCEPTED
        assert gcs.command(M.MAV_CMD_MISSION_START, math.nan) == M.MAV_RESULT_DENIED  # PX4: not finite
        assert "got first item nan" in gcs.joined_text("MISSION_START: only from item 0")
        assert gcs.start() == M.MAV_RESULT_ACCEPTED
        gcs.recv("GLOBAL_POSITION_INT", 60, "GLOBAL_POSITION_INT.relative_alt > 500")  # its own mission, up
        assert gcs.start() == M.MAV_RESULT_DENIED  # (it told the ground station to land and start it)
        assert "flies whole, once" in gcs.joined_text("MISSION_START: the mission is flying")
        rc = controller.p.wait(timeout=120)
        controller.reports()  # (reads its last lines)
        assert rc == controller_exit(controller.lines), "\n".join(controller.lines[-20:])  # 1: stalled by the machine
        gcs.recv("HEARTBEAT", 10, f"HEARTBEAT.get_srcComponent()==1 and HEARTBEAT.base_mode & 128 and "
                                  f"HEARTBEAT.custom_mode=={hold}")
        gcs.recv("MISSION_CURRENT", 5, f"MISSION_CURRENT.mission_state=={M.MISSION_STATE_COMPLETE}")
        assert gcs.start() == M.MAV_RESULT_DENIED  # PX4 flies it on; the controller is gone
        assert "land and disarm" in gcs.joined_text("MISSION_START: armed in the air (HOLD)")
        # AUTO.MISSION: once ACCEPTED, nothing done; a mode that cannot run now is PX4's TEMPORARILY_REJECTED
        assert gcs.command(M.MAV_CMD_DO_SET_MODE, 1, 4, 4) == M.MAV_RESULT_TEMPORARILY_REJECTED
        assert "land and disarm" in gcs.joined_text("mode MISSION: armed in the air (HOLD)")  # nothing done
        assert gcs.upload(_items()) == M.MAV_MISSION_ACCEPTED
        gcs.recv("MISSION_CURRENT", 5, f"MISSION_CURRENT.total==3 and "
                                       f"MISSION_CURRENT.mission_state=={M.MISSION_STATE_NOT_STARTED}")
        assert gcs.command(M.MAV_CMD_DO_SET_MISSION_CURRENT, 2) == M.MAV_RESULT_ACCEPTED
        gcs.recv("MISSION_CURRENT", cond="MISSION_CURRENT.seq==2")
        gcs.recv("HEARTBEAT", 5, f"HEARTBEAT.get_srcComponent()==1 and HEARTBEAT.base_mode & 128 and "
                                 f"HEARTBEAT.custom_mode=={hold}")  # still holding, armed
    assert "item 1 (DO_JUMP (177)): not supported" in said and said.endswith("DO_CHANGE_SPEED (178)"), said
    assert len(said) > 200, said
    log = "\n".join(vehicle.lines)
    assert "uploaded 3 items" in log and "disarmed" not in log, vehicle.lines[-20:]


def test_a_start_in_the_air_after_the_mission_was_taken_over_is_told_to_land_not_that_it_flies(tmp_path):
    """``bsst vehicle`` and ``bsst controller`` awaiting a mission on the wall clock: a ground station starts a
    takeoff and a waypoint, then, up, switches the vehicle to HOLD (the controller's flight ends, taken over).
    A MISSION_START then, armed in the air, is DENIED telling it to land and disarm (the mission flies no more:
    ``MissionManager.flown``). Until the third wave's thirty-seventh session it said "the mission is flying" (its
    start was remembered, and it had not completed)."""
    settings = tmp_path / "sine.toml"
    settings.write_text((MISSION_DIR / "sine.toml").read_text())
    out = tmp_path / "run"
    hold = (4 << 16) | (3 << 24)
    with _awaiting_on_the_wall_clock(settings, out) as (gcs, controller, vehicle):
        assert gcs.upload(_short_hop()) == M.MAV_MISSION_ACCEPTED
        assert gcs.start() == M.MAV_RESULT_ACCEPTED
        gcs.recv("GLOBAL_POSITION_INT", 60, "GLOBAL_POSITION_INT.relative_alt > 500")  # its own mission, up
        assert gcs.command(M.MAV_CMD_DO_SET_MODE, 1, 4, 3) == M.MAV_RESULT_ACCEPTED  # AUTO.LOITER: HOLD
        gcs.recv("HEARTBEAT", 10, f"HEARTBEAT.get_srcComponent()==1 and HEARTBEAT.base_mode & 128 and "
                                  f"HEARTBEAT.custom_mode=={hold}")
        assert gcs.start() == M.MAV_RESULT_DENIED
        assert "land and disarm" in gcs.joined_text("MISSION_START: armed in the air (HOLD)")


def test_mission_current_says_no_mission_the_mission_mode_and_a_pause_as_px4_main():
    """MISSION_CURRENT as PX4 main sends it (mavlink_mission.cpp ``send_mission_current``), on a vehicle in this
    process awaiting a mission: without a mission it is sent too, total UINT16_MAX and NO_MISSION (it was not sent:
    PX4 1.14's silence); mission_mode is 1 while a mode that flies items shows (AUTO.MISSION, LAND: PX4's AUTO_LAND
    too), 2 otherwise (it was 0, unknown); once the mission's flight has left AUTO.MISSION after reaching an item
    (a ground station's HOLD) it is PAUSED, as PX4's (it said ACTIVE); cleared, NO_MISSION again."""
    from bridge.core.flight import prepare
    from bridge.mavlink.endpoint import parse_address
    from bridge.mavlink.telemetry import MISSION_MODE_IN_MISSION, MISSION_MODE_SUSPENDED, NO_MISSION_TOTAL
    from bridge.nodes.vehicle import Vehicle, VehicleConfig
    from missions import Mission, Sine
    from tests.sitlkit import GcsSocket
    from tests.test_mission_protocol import _uploaded_in_process

    gcs = GcsSocket()
    v = Vehicle(prepare(Mission(Sine(), duration_s=5.0, name="current")),
                VehicleConfig(parse_address("udpin:127.0.0.1:0"), parse_address(gcs.url), await_mission=True))

    def current() -> tuple[int, int, int, int]:
        m = v.streaming.message(M.MAVLINK_MSG_ID_MISSION_CURRENT)[0]
        return m.seq, m.total, m.mission_state, m.mission_mode

    def command(cmd: int, *params: float) -> int:
        msg = M.MAVLink_command_long_message(1, 1, cmd, 0, *params, *[0.0] * (7 - len(params)))
        return gcs.exchange(v, msg, "COMMAND_ACK").result

    suspended, in_mission = MISSION_MODE_SUSPENDED, MISSION_MODE_IN_MISSION
    try:
        assert current() == (0, NO_MISSION_TOTAL, M.MISSION_STATE_NO_MISSION, suspended)
        assert _uploaded_in_process(gcs, v, _items((1, 1))).type == M.MAV_MISSION_ACCEPTED
        assert current() == (0, 3, M.MISSION_STATE_NOT_STARTED, suspended)
        assert command(M.MAV_CMD_DO_SET_MODE, 1, 4, 4) == M.MAV_RESULT_ACCEPTED  # AUTO.MISSION, disarmed
        assert current() == (0, 3, M.MISSION_STATE_NOT_STARTED, in_mission)
        assert command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1) == M.MAV_RESULT_ACCEPTED  # the start
        assert current() == (0, 3, M.MISSION_STATE_ACTIVE, in_mission)
        v.sim.arm()  # the controller's arm, and its flight's first steps: the takeoff's point reached
        v.missions.flight_armed()
        goal = v.missions.watch.goals[0]
        at = (goal.point[0], 0.0, goal.point[1], 0.0, goal.point[2]) + (0.0,) * 7
        for t in (1.0, 1.0 + goal.hold_s + 0.1):
            v.missions.flight_step(t, at, True)
        assert current() == (1, 3, M.MISSION_STATE_ACTIVE, in_mission)
        assert command(M.MAV_CMD_DO_SET_MODE, 1, 4, 3) == M.MAV_RESULT_ACCEPTED  # HOLD, mid-mission
        assert current() == (1, 3, M.MISSION_STATE_PAUSED, suspended)
        assert command(M.MAV_CMD_NAV_LAND) == M.MAV_RESULT_ACCEPTED
        assert current() == (1, 3, M.MISSION_STATE_ACTIVE, in_mission)
        gcs.exchange(v, M.MAVLink_mission_clear_all_message(1, 1, M.MAV_MISSION_TYPE_MISSION), "MISSION_ACK")
        assert current()[1:3] == (NO_MISSION_TOTAL, M.MISSION_STATE_NO_MISSION)
    finally:
        v.close()
        gcs.close()

