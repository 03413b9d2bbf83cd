"""Covers bridge.autopilot.params, bridge.mavlink.modes and bridge.nodes.vehicle.

The vehicle's parameters and flight modes (issue 14), without a ground-station program.

The pure parts (bridge.autopilot.params, bridge.mavlink.modes) on their own; then ``bsst vehicle`` as a
real process spoken to by a pymavlink ground station over UDP on 127.0.0.1 (the parameter
protocol, DO_SET_MODE / SET_MODE, NAV_TAKEOFF and NAV_LAND); then whole flights: a parameter set
at a mission time (``--param-at``) gives the same trace twice in lockstep and matches offline,
and a ground station's HOLD during a lockstep flight ends it, named. MAVSDK and MAVProxy against
the same vehicle: tests/test_ground_stations.py.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import struct
import subprocess
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as M

from bridge.autopilot.failsafe import FAILSAFE_RANGES
from bridge.autopilot.params import (
    BY_NAME,
    PARAMS,
    ParamChange,
    ParamRefused,
    VehicleParams,
    change_param,
    check_param_changes,
    float32,
    parse_change,
    read_param,
    value_problem,
)
from bridge.cli.flags import param_assignment
from bridge.core.flight import prepare
from bridge.loop import simulate
from bridge.mavlink.endpoint import GCS_PORT
from bridge.mavlink.modes import (
    param_from_wire,
    param_to_wire,
    requested_custom_mode,
    requested_mode,
    shown_name,
)
from bridge.nodes.report import Ready, Stats
from bridge.nodes.vehicle.paramservice import MAV_PARAM_ERROR_TYPE_MISMATCH, MAV_PARAM_ERROR_TYPE_UNSUPPORTED
from bridge.record.runlog import read_trace
from bridge.session import instance_slot, sitl
from missions import Mission, Sine
from params import ConfigError
from params.text import quoted
from tests.gcskit import upload
from tests.sitlkit import ENV, ROOT, Bsst, Proc, clean_exit, run_bsst
from tests.test_await_mission import _small_plan_items

pytestmark = pytest.mark.process  # starts processes or opens sockets: not in make test-fast


# -- the pure parts -------------------------------------------------------------------------------
def test_every_parameter_reads_back_what_was_set_and_refuses_outside_its_range():
    p = VehicleParams()
    for spec in PARAMS:
        if spec.at_start_only:
            with pytest.raises(ParamRefused, match="at start only"):
                change_param(p, spec.name, spec.lo)
            continue
        values = list(spec.choices) if spec.choices else [spec.lo, spec.hi, (spec.lo + spec.hi) / 2]
        for v in values:
            assert read_param(change_param(p, spec.name, v), spec.name) == pytest.approx(v)
        with pytest.raises(ParamRefused, match=spec.name):
            change_param(p, spec.name, spec.hi + 1)
        with pytest.raises(ParamRefused, match="must be finite" if spec.kind == "REAL32" else "INT32.*got nan$"):
            change_param(p, spec.name, math.nan)  # (an INT32's refusal names what it takes: the check of 1.5)
    with pytest.raises(ParamRefused, match="no such parameter"):
        change_param(p, "FS_GCS_ENABLE", 1)
    with pytest.raises(ParamRefused, match="not one the vehicle flies"):
        change_param(p, "COM_OBL_RC_ACT", 0)  # PX4's Position mode: not flown here
    with pytest.raises(ParamRefused, match="INT32"):
        change_param(p, "COM_OBL_ACT", 0.5)


def test_a_param_event_says_the_values_in_their_own_digits():
    """A change's ``param`` event (and so its intervention's text): an INT32 whole, a REAL32 as float32 tells it
    apart (``:g`` said EKF2_NOAID_TOUT = 1.23457e+06 and GF_MAX_HOR_DIST 1234.57)."""
    sim = prepare("missions/sine.toml").make_vehicle()
    assert sim.change_param("EKF2_NOAID_TOUT", 1234567.0).text == "EKF2_NOAID_TOUT = 1234567 (was 5000000)"
    wire = struct.unpack("<f", struct.pack("<f", 1234.5678))[0]  # as a PARAM_SET carries it
    assert sim.change_param("GF_MAX_HOR_DIST", wire).text == "GF_MAX_HOR_DIST = 1234.56775 (was 0)"


def test_the_failsafe_parameters_share_the_failsafe_tables_ranges():
    for spec in PARAMS:
        if spec.failsafe_key in FAILSAFE_RANGES:
            assert (spec.lo, spec.hi) == FAILSAFE_RANGES[spec.failsafe_key], spec.name


def test_both_offboard_loss_parameters_are_the_failsafe_action():
    p = change_param(VehicleParams(), "COM_OBL_ACT", 1)
    assert p.failsafe.action == "hold" and read_param(p, "COM_OBL_RC_ACT") == 5
    p = change_param(p, "COM_OBL_RC_ACT", 7)
    assert p.failsafe.action == "disarm" and read_param(p, "COM_OBL_ACT") == 3
    assert read_param(VehicleParams(), "COM_OBL_ACT") == -1  # descend, the default


def test_int32_values_cross_the_wire_bytewise_and_cast_values_are_read_too():
    for v in (-1, 0, 1, 3, 7, 254):
        wire = param_to_wire(v, M.MAV_PARAM_TYPE_INT32)
        assert struct.pack("<f", wire) == struct.pack("<i", v)
        assert param_from_wire(wire, M.MAV_PARAM_TYPE_INT32) == v
        assert param_from_wire(float(v), M.MAV_PARAM_TYPE_INT32) == v  # a C cast (ArduPilot's way)
    assert param_to_wire(0.25, M.MAV_PARAM_TYPE_REAL32) == 0.25
    for v in (-2**31, 2**31 - 1, 10_000_001):  # the extremes (-0.0's bytes, a NaN's) and a bound's neighbour
        wire = param_to_wire(v, M.MAV_PARAM_TYPE_INT32)
        assert param_from_wire(wire, M.MAV_PARAM_TYPE_INT32) == v
        why = value_problem(BY_NAME["EKF2_NOAID_TOUT"], param_from_wire(wire, M.MAV_PARAM_TYPE_INT32))
        assert why == f"EKF2_NOAID_TOUT: must be in [500000, 10000000] us, got {v}", why  # every digit (not 1e+07)
    why = value_problem(BY_NAME["COM_DISARM_LAND"], 20.000001)  # (it said 'got 20' of [-1, 20])
    assert why == "COM_DISARM_LAND: must be in [-1, 20] s, got 20.000001", why
    assert value_problem(BY_NAME["COM_DISARM_LAND"], struct.unpack("<f", struct.pack("<f", 25.3))[0]).endswith(
        "got 25.3")  # a float32 from the wire in its own digits


def test_px4_modes_decode_and_others_are_named_when_refused():
    assert requested_mode(29, 4, 3) == ("hold", "")
    assert requested_mode(1, 6, 0) == ("offboard", "")
    assert requested_custom_mode(1, (4 << 16) | (6 << 24)) == ("land", "")
    assert requested_mode(29, 4, 5) == ("rtl", "")  # PX4's Return
    mode, why = requested_mode(29, 4, 7)
    assert mode is None and why == ("mode RTGS: not flown here; OFFBOARD, HOLD, LAND, TAKEOFF, MISSION, RTL are "
                                    "flown here")  # (it ended "... RTL are")
    assert requested_mode(1, 4, 0) == requested_mode(4, 0, 0) == ("mission", "")  # AUTO, no sub mode; base AUTO
    assert requested_mode(0, 4, 3) == (None, "")  # no CUSTOM_MODE_ENABLED, no AUTO or MANUAL_INPUT: no mode asked
    assert requested_mode(64 | 8, 0, 0)[1].startswith("mode POSCTL: not flown here")  # base MANUAL_INPUT, GUIDED
    assert requested_mode(29, math.nan, 3)[0] is None
    assert shown_name((4 << 16) | (2 << 24)) == "TAKEOFF"


def test_a_missions_params_table_and_the_flags_are_checked_and_ordered(tmp_path):
    f = prepare("missions/sine.toml", params={"COM_OF_LOSS_T": 1.0, "COM_OBL_RC_ACT": 4})
    assert (f.failsafe.timeout_s, f.failsafe.action) == (1.0, "land")
    # a flag wins over the file, whichever of the file's tables holds the setting
    src = (ROOT / "missions" / "sine.toml").read_text()
    path = tmp_path / "m.toml"
    path.write_text(src + "\n[params]\nCOM_OBL_ACT = 1\n")
    assert prepare(path).failsafe.action == "hold"
    assert prepare(path, failsafe={"action": "land"}).failsafe.action == "land"
    path.write_text(src + "\n[params]\nCOM_OBL_ACT = 1\n\n[failsafe]\naction = \"land\"\n")
    with pytest.raises(ConfigError, match="params.COM_OBL_ACT and failsafe.action"):
        prepare(path)
    path.write_text(src + "\n[params]\nCOM_OF_LOSS_T = 99.0\n")
    with pytest.raises(ConfigError, match=r"m.toml: params.COM_OF_LOSS_T: must be in \[0.01, 60\]"):
        prepare(path)
    with pytest.raises(ConfigError, match="--failsafe-action"):
        prepare("missions/sine.toml", params={"COM_OBL_ACT": 1}, failsafe={"action": "land"})
    with pytest.raises(ConfigError, match="mission's duration"):
        prepare("missions/sine.toml", param_at=[parse_change("31:COM_OF_LOSS_T=1")])


@pytest.mark.parametrize("args, says", [
    (["--param", "COM_OF_LOSS_T=99"], "COM_OF_LOSS_T: must be in [0.01, 60] s"),
    (["--param", "NOPE=1"], "NOPE: no such parameter"),
    (["--param", "COM_OBL_RC_ACT=1"], "not one the vehicle flies"),
    (["--param-at", "x:COM_OBL_ACT=1"], "--param-at"),
    (["--param-at", "5:MAV_SYS_ID=3"], "at start only"),
])
def test_bad_parameter_flags_are_one_line_exit_2(args, says):
    r = run_bsst("sim", "missions/sine.toml", *args, cwd=ROOT, timeout=60)
    assert r.returncode == 2 and says in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr


@pytest.mark.parametrize("name, shown", [("A: B", "'A: B'"), ("X" * 3000, "'" + "X" * 60 + "'… (3000 characters)")],
                         ids=["colon", "long"])
def test_an_unknown_params_name_is_quoted_whole_and_a_long_one_shortened(name: str, shown: str) -> None:
    """``--param 'A: B=1'`` and ``params={"A: B": 1}``: the name quoted, whole (a user's tour: ``A: B: no such
    parameter``, and from Python its ``: `` taken for the message's own, cut to ``--param A: B=1: B: no such
    parameter``); a 3000-character name by its first 60 characters and its length (it was echoed whole, twice on
    the command line)."""
    r = run_bsst("sim", "missions/sine.toml", "--param", f"{name}=1", cwd=ROOT, timeout=60)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr[:500]
    assert f": {shown}: no such parameter; the vehicle has " in r.stderr and len(r.stderr) < 1000, r.stderr[:500]
    with pytest.raises(ConfigError) as e:
        simulate(Mission(Sine(), duration_s=1.0), params={name: 1}, plots=False)
    said = str(e.value)
    assert said.startswith(f"--param {shown}=1: no such parameter; the vehicle has ") and len(said) < 1000, said[:500]


def test_the_offboard_loss_parameter_flies_the_failsafe_action_it_names():
    """``--param COM_OBL_ACT=1`` is ``--failsafe-action hold``, row for row (offline): 10.5 s of sine, a blackout at
    6 s (the 30 s sine's at 15 s flew 20 s more than its failsafe needs)."""
    a = simulate(SHORT, link=EARLY_BLACKOUT, params={"COM_OBL_ACT": 1}, plots=False)
    b = simulate(SHORT, link=EARLY_BLACKOUT, failsafe={"action": "hold"}, plots=False)
    assert np.array_equal(a.trace["x"], b.trace["x"]) and a.summary["outcome"] == "failsafe"


# -- a pymavlink ground station against bsst vehicle --------------------------------------------------
def _gcs(n: int):
    os.environ["MAVLINK20"] = "1"
    return mavutil.mavlink_connection(f"udpin:127.0.0.1:{GCS_PORT + n}", source_system=255, source_component=190,
                                      dialect="common")


def _recv(conn, kind: str, cond: str | None = None, timeout: float = 10.0):
    m = conn.recv_match(type=kind, blocking=True, timeout=timeout, condition=cond)
    assert m is not None, f"no {kind} ({cond})"
    return m


def test_parameter_protocol_over_udp(tmp_path):
    with instance_slot() as n:
        gcs = _gcs(n)
        v = Proc.bsst("vehicle", "--instance", str(n), "--out", str(tmp_path), "--param", "COM_OF_LOSS_T=0.8")
        try:
            v.wait_report(Ready)
            hb = gcs.wait_heartbeat(timeout=20)
            assert hb.autopilot == M.MAV_AUTOPILOT_PX4 and mavutil.mode_string_v10(hb) == "LOITER"  # HOLD at boot
            tgt = (gcs.target_system, gcs.target_component)
            gcs.mav.param_request_list_send(*tgt)
            got = {}
            while len(got) < len(PARAMS):
                m = _recv(gcs, "PARAM_VALUE")
                assert m.param_count == len(PARAMS)
                got[m.param_id] = (m.param_index, param_from_wire(m.param_value, m.param_type))
            assert got["COM_OF_LOSS_T"][1] == pytest.approx(0.8)  # --param, at start
            assert got["MAV_SYS_ID"][1] == n + 1 and got["COM_OBL_ACT"][1] == -1
            assert sorted(i for i, _ in got.values()) == list(range(len(PARAMS)))
            gcs.mav.param_request_read_send(*tgt, b"MPC_LAND_SPEED", -1)
            assert _recv(gcs, "PARAM_VALUE").param_value == pytest.approx(0.7)
            gcs.mav.param_request_read_send(*tgt, b"", BY_NAME and list(BY_NAME).index("MIS_TAKEOFF_ALT"))
            assert _recv(gcs, "PARAM_VALUE").param_id == "MIS_TAKEOFF_ALT"
            # a set: made, answered with the new value; out of range, wrong type, start-only: refused, answered
            # with PARAM_ERROR (its code) before the unchanged value, and a STATUSTEXT saying why
            gcs.mav.param_set_send(*tgt, b"COM_OF_LOSS_T", 1.5, M.MAV_PARAM_TYPE_REAL32)
            assert _recv(gcs, "PARAM_VALUE").param_value == 1.5
            for name, value, kind, code, why in (
                    ("COM_OF_LOSS_T", 100.0, M.MAV_PARAM_TYPE_REAL32, M.MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE,
                     "COM_OF_LOSS_T: must be in [0.01, 60] s, got 100"),
                    # the type a set says is named (it said "the set says type 6", a bare number; a STATUSTEXT's
                    # first chunk, 50 characters, is what is matched)
                    ("COM_OF_LOSS_T", 1.0, M.MAV_PARAM_TYPE_INT32, MAV_PARAM_ERROR_TYPE_MISMATCH,
                     "is REAL32, the set says INT32 (type"),
                    # a type no parameter here has: PX4 main's TYPE_UNSUPPORTED (it was TYPE_MISMATCH)
                    ("COM_OF_LOSS_T", 1.0, M.MAV_PARAM_TYPE_REAL64, MAV_PARAM_ERROR_TYPE_UNSUPPORTED,
                     "the set says REAL64 (type 10): the"),
                    ("COM_OF_LOSS_T", 1.0, 42, MAV_PARAM_ERROR_TYPE_UNSUPPORTED,
                     "the set says type 42, not a MAV_PAR"),
                    ("MAV_SYS_ID", param_to_wire(42, 6), 6, M.MAV_PARAM_ERROR_READ_ONLY, "at start only")):
                gcs.mav.param_set_send(*tgt, name.encode(), value, kind)
                error = _recv(gcs, ["PARAM_ERROR", "PARAM_VALUE"])
                assert error.get_type() == "PARAM_ERROR", error
                # by name, as the set named it (PX4 main's -1; it was the parameter's index)
                assert (error.param_id, error.error, error.param_index) == (name, code, -1)
                assert (error.target_system, error.target_component) == (255, 190)  # to the sender
                m = _recv(gcs, "PARAM_VALUE")
                text = _recv(gcs, "STATUSTEXT", f"{why!r} in STATUSTEXT.text")
                assert m.param_id == name
                assert text.severity == M.MAV_SEVERITY_WARNING
                assert param_from_wire(m.param_value, m.param_type) == (1.5 if name == "COM_OF_LOSS_T" else n + 1)
            # an unknown name or index: PARAM_ERROR DOES_NOT_EXIST naming what was asked for, no PARAM_VALUE
            gcs.mav.param_set_send(*tgt, b"NO_SUCH_PARAM", 1.0, M.MAV_PARAM_TYPE_REAL32)
            gcs.mav.param_request_read_send(*tgt, b"NO_SUCH_PARAM", -1)
            gcs.mav.param_request_read_send(*tgt, b"", len(PARAMS))
            for asked in (("NO_SUCH_PARAM", -1), ("NO_SUCH_PARAM", -1), ("", len(PARAMS))):
                error = _recv(gcs, ["PARAM_ERROR", "PARAM_VALUE"])
                assert error.get_type() == "PARAM_ERROR", error
                assert (error.param_id, error.param_index, error.error) == (*asked, M.MAV_PARAM_ERROR_DOES_NOT_EXIST)
            # by a name it does not give (index -2: by name, as -1): the STATUSTEXT says what was asked (it said
            # "param : no such parameter")
            gcs.mav.param_request_read_send(*tgt, b"", -2)
            error = _recv(gcs, ["PARAM_ERROR", "PARAM_VALUE"])
            assert (error.get_type(), error.param_id, error.param_index) == ("PARAM_ERROR", "", -2), error
            _recv(gcs, "STATUSTEXT", "'param index -2 (no name): no such parameter' in STATUSTEXT.text")
            gcs.mav.param_set_send(*tgt, b"COM_OBL_RC_ACT", param_to_wire(5, 6), M.MAV_PARAM_TYPE_INT32)
            assert param_from_wire(_recv(gcs, "PARAM_VALUE").param_value, 6) == 5
        finally:
            assert v.stop() == 0
            gcs.close()
    e = v.wait_event(lambda s: "param: COM_OF_LOSS_T = 1.5 (was 0.8) [by 255:190" in s)
    assert (e.param.name, e.param.new, e.by.link) == ("COM_OF_LOSS_T", 1.5, "gcs")  # typed, for the policies
    v.wait_event(lambda s: "param: COM_OBL_RC_ACT = 5 (was -1)" in s)
    stats = v.wait_report(Stats).values
    assert stats["rejected"]["param_refused"] == 5 and stats["rejected"]["param_unknown"] == 4


@pytest.mark.parametrize("link", ["link", "gcs"])
def test_a_parameter_changed_is_said_to_the_session_before_its_echo_goes_out(link):
    """A PARAM_SET that changes a parameter, from the controller on the vehicle's own link or from a ground station:
    the vehicle's ``param`` event line is out (its report) before the setter's PARAM_VALUE echo is. The session reads
    the controller's pipe before the vehicle's, so an answer's cause is read with it or before it
    (:mod:`bridge.session.eventorder`) only if the vehicle says its event before it answers, as it does a command's
    before its COMMAND_ACK. The echo went out first: in 1 of ~10 real-time runs of
    test_a_scheduled_change_confirmed_only_after_the_flights_end_is_not_made[late] the controller's "echoed by the
    vehicle only after the flight's end" was read before the vehicle's change, at the same t=3.201, and events.log
    put it first. A vehicle built in this process, real UDP on 127.0.0.1: what the setter had received when the
    line was said is read from its socket then."""
    from bridge.mavlink.endpoint import CONTROLLER_COMPID, CONTROLLER_SYSID, parse_address
    from bridge.nodes.report import Event
    from bridge.nodes.vehicle import Vehicle, VehicleConfig
    from tests.sitlkit import GcsSocket
    from tests.waiting import wait_for

    gcs = GcsSocket()
    setter = GcsSocket(CONTROLLER_SYSID, CONTROLLER_COMPID, link="link") if link == "link" else gcs
    got: list[Any] = []  # what the setter received, in order
    said: list[list[str]] = []  # at each param event's line: the setter's messages received by then

    def status(report: Any) -> None:
        if isinstance(report, Event) and report.kind == "param":
            got.extend(setter.received())
            said.append([m.get_type() for m in got])

    v = Vehicle(prepare(Mission(Sine(), duration_s=5.0, name="said")),
                VehicleConfig(parse_address("udpin:127.0.0.1:0"), parse_address(gcs.url)), status=status)
    try:
        ep = getattr(v, link)
        set_ = M.MAVLink_param_set_message(1, 1, b"MIS_TAKEOFF_ALT", 5.0, M.MAV_PARAM_TYPE_REAL32)
        setter.sock.sendto(set_.pack(setter.mav), ep.local)

        def echoed() -> bool:
            for m, addr in ep.poll():
                v._handle(ep, m, addr)
            got.extend(setter.received())
            return any(m.get_type() == "PARAM_VALUE" for m in got)

        wait_for(echoed, 5.0, "the vehicle's PARAM_VALUE echo", poll_s=0.001)
        assert [m.param_value for m in got if m.get_type() == "PARAM_VALUE"] == [5.0]
        assert len(said) == 1 and "PARAM_VALUE" not in said[0], said  # the line first, then the echo
    finally:
        v.close()
        gcs.close()
        setter.close()


def test_the_controllers_change_reaches_the_ground_station_as_px4_sends_it(tmp_path):
    """A lockstep session whose controller sets COM_OF_LOSS_T at 1 s (``--param-at``): the ground station, which
    asked nothing, gets the new PARAM_VALUE (PX4's ``MavlinkParametersManager::send_untransmitted``: each changed
    parameter on every link), so its copy follows; the ground station's own set is answered once, not echoed
    again by that broadcast. (At 2x real time, landed and disarmed 0.5 s later: the session's wall clock is the
    test's CPU.)"""
    mission = tmp_path / "short.toml"
    mission.write_text((ROOT / "missions" / "sine.toml").read_text().replace("duration_s = 30.0", "duration_s = 3.0"))
    with instance_slot() as n:
        gcs = _gcs(n)
        s = Bsst("sitl", str(mission), "--instance", str(n), "--param-at", "1:COM_OF_LOSS_T=2.5", "--out",
                 str(tmp_path / "run"), "--no-plots", "--speed", "2", "--param", "COM_DISARM_LAND=0.5", env=ENV)
        try:
            gcs.wait_heartbeat(timeout=30)
            tgt = (gcs.target_system, gcs.target_component)
            m = _recv(gcs, "PARAM_VALUE", timeout=30)  # the first it hears, unasked
            assert (m.param_id, m.param_value, m.param_count) == ("COM_OF_LOSS_T", 2.5, len(PARAMS))
            assert m.param_index == list(BY_NAME).index("COM_OF_LOSS_T")
            gcs.mav.param_set_send(*tgt, b"COM_OF_LOSS_T", 1.5, M.MAV_PARAM_TYPE_REAL32)
            assert _recv(gcs, "PARAM_VALUE").param_value == 1.5  # its answer
            gcs.mav.param_request_read_send(*tgt, b"MPC_LAND_SPEED", -1)  # the next PARAM_VALUE is this one's
            assert _recv(gcs, "PARAM_VALUE").param_id == "MPC_LAND_SPEED"
            s.communicate(timeout=90)
        finally:
            if s.poll() is None:
                s.kill()
            gcs.close()


def test_modes_takeoff_hold_land_over_udp(tmp_path):
    """HOLD (the boot mode, as PX4's) selected again on the ground, which changes nothing, armed in it; NAV_TAKEOFF
    above the envelope is refused, below MIS_TAKEOFF_ALT (below home) raised to it, which it climbs to and then
    holds; SET_MODE LAND lands
    and disarms; modes a ground station cannot have are refused, named."""
    with instance_slot() as n:
        gcs = _gcs(n)
        v = Proc.bsst("vehicle", "--instance", str(n), "--out", str(tmp_path), "--speed", "4",
                      "--param", "MIS_TAKEOFF_ALT=1.5", "--param", "MPC_LAND_SPEED=1.5")
        try:
            v.wait_report(Ready)
            gcs.wait_heartbeat(timeout=20)
            tgt = (gcs.target_system, gcs.target_component)

            def command(cmd: int, *p: float) -> int:
                gcs.mav.command_long_send(*tgt, cmd, 0, *p)
                return _recv(gcs, "COMMAND_ACK", f"COMMAND_ACK.command=={cmd}").result

            # RTL disarmed: PX4's answer to a mode that cannot run now
            assert command(M.MAV_CMD_DO_SET_MODE, 29, 4, 5, 0, 0, 0, 0) == M.MAV_RESULT_TEMPORARILY_REJECTED
            assert "RTL" in _recv(gcs, "STATUSTEXT").text
            assert command(M.MAV_CMD_DO_SET_MODE, 29, 4, 3, 0, 0, 0, 0) == M.MAV_RESULT_ACCEPTED
            _recv(gcs, "HEARTBEAT", f"HEARTBEAT.custom_mode=={(4 << 16) | (3 << 24)}")
            assert command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1, 0, 0, 0, 0, 0, 0) == M.MAV_RESULT_ACCEPTED
            nan = math.nan
            assert command(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, nan, nan, nan, 600.0) == M.MAV_RESULT_DENIED  # 112 m up
            assert "600 m AMSL is 112 m" in _recv(gcs, "STATUSTEXT").text  # the first 50-character chunk
            # 5 m AMSL is below home (488 m): raised to MIS_TAKEOFF_ALT, the least it climbs to, as PX4 does
            assert command(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, nan, nan, nan, 5.0) == M.MAV_RESULT_ACCEPTED
            assert _recv(gcs, "STATUSTEXT").text == "Using minimum takeoff altitude: 489.50 m"
            _recv(gcs, "STATUSTEXT", "'takeoff done' in STATUSTEXT.text", timeout=20)
            pos = _recv(gcs, "LOCAL_POSITION_NED")
            assert abs(-pos.z - 1.5) < 0.15 and math.hypot(pos.x, pos.y) < 0.1
            hb = _recv(gcs, "HEARTBEAT")
            assert mavutil.mode_string_v10(hb) == "LOITER" and hb.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED
            # armed, OFFBOARD needs a controller sending targets (PX4's rule too, and its answer)
            assert command(M.MAV_CMD_DO_SET_MODE, 29, 6, 0, 0, 0, 0, 0) == M.MAV_RESULT_TEMPORARILY_REJECTED
            assert "no controller" in _recv(gcs, "STATUSTEXT").text
            gcs.mav.set_mode_send(tgt[0], 1, (4 << 16) | (6 << 24))  # SET_MODE LAND
            assert _recv(gcs, "COMMAND_ACK", "COMMAND_ACK.command==176").result == M.MAV_RESULT_ACCEPTED
            _recv(gcs, "STATUSTEXT", "'landed: disarmed' in STATUSTEXT.text", timeout=20)
            # disarmed, back in HOLD (PX4's mode after a disarm in LAND); STANDBY: a landing asked for, not a failsafe
            hb = _recv(gcs, "HEARTBEAT", f"not HEARTBEAT.base_mode & {M.MAV_MODE_FLAG_SAFETY_ARMED} and "
                                         f"HEARTBEAT.custom_mode == {(4 << 16) | (3 << 24)}")
            assert mavutil.mode_string_v10(hb) == "LOITER" and hb.system_status == M.MAV_STATE_STANDBY
        finally:
            assert v.stop() == 0
            gcs.close()
    for text in ("armed: armed, HOLD [by 255:190",
                 "mode: TAKEOFF to 1.5 m", "mode: HOLD: takeoff done", "mode: LAND at", "landed: disarmed"):
        v.wait_event(lambda s, text=text: text in s)
    assert not any("disarmed: armed in it next" in s for s in v.events())  # HOLD in HOLD: no event


HOLD_MODE, MISSION_MODE = (4 << 16) | (3 << 24), (4 << 16) | (4 << 24)  # custom_mode: AUTO.LOITER, AUTO.MISSION


@contextlib.contextmanager
def _awaiting_vehicle(tmp_path) -> Iterator[tuple[Any, Callable[..., tuple[int, str]]]]:
    """``bsst vehicle --await-mission`` holding the small plan a pymavlink ground station uploaded, disarmed in HOLD:
    the ground station and its ``command(cmd, *params)``: (COMMAND_ACK's result, the STATUSTEXT after a refusal)."""
    with instance_slot() as n:
        gcs = _gcs(n)
        v = Proc.bsst("vehicle", "--await-mission", "--instance", str(n), "--out", str(tmp_path))
        try:
            v.wait_report(Ready)
            gcs.wait_heartbeat(timeout=20)
            tgt = (gcs.target_system, gcs.target_component)
            upload(gcs, tgt, _small_plan_items())

            def command(cmd: int, *p: float) -> tuple[int, str]:
                gcs.mav.command_long_send(*tgt, cmd, 0, *p, *[0.0] * (7 - len(p)))
                result = _recv(gcs, "COMMAND_ACK", f"COMMAND_ACK.command=={cmd}").result
                return result, "" if result == M.MAV_RESULT_ACCEPTED else _recv(gcs, "STATUSTEXT").text

            yield gcs, command
        finally:
            assert v.stop() == 0
            gcs.close()


def test_auto_with_sub_mode_0_is_auto_mission_as_px4s(tmp_path):
    """PX4's commander takes main mode AUTO with sub mode 0 as AUTO.MISSION (Commander.cpp, handle_command,
    VEHICLE_CMD_DO_SET_MODE; SET_MODE is the same command there, mavlink_receiver.cpp handle_message_set_mode): a
    vehicle awaiting a mission, holding one, selects MISSION on DO_SET_MODE 1/4/0 and on SET_MODE AUTO sub 0, each
    ACCEPTED and shown in its HEARTBEAT (HOLD between). Until the third wave's thirty-eighth session both were DENIED
    (`mode main 4 sub 0: not flown here`)."""
    with _awaiting_vehicle(tmp_path) as (gcs, command):
        assert command(M.MAV_CMD_DO_SET_MODE, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 4, 0) == (M.MAV_RESULT_ACCEPTED, "")
        _recv(gcs, "HEARTBEAT", f"HEARTBEAT.custom_mode=={MISSION_MODE}")
        assert command(M.MAV_CMD_DO_SET_MODE, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 4, 3) == (M.MAV_RESULT_ACCEPTED, "")
        _recv(gcs, "HEARTBEAT", f"HEARTBEAT.custom_mode=={HOLD_MODE}")
        gcs.mav.set_mode_send(gcs.target_system, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 4 << 16)  # AUTO, sub mode 0
        assert _recv(gcs, "COMMAND_ACK", "COMMAND_ACK.command==176").result == M.MAV_RESULT_ACCEPTED
        _recv(gcs, "HEARTBEAT", f"HEARTBEAT.custom_mode=={MISSION_MODE}")


def test_a_base_mode_without_custom_mode_is_read_as_px4s_commander_reads_it(tmp_path):
    """DO_SET_MODE and SET_MODE with CUSTOM_MODE_ENABLED clear, as PX4's commander's "use base mode" branch reads them
    (Commander.cpp, handle_command, VEHICLE_CMD_DO_SET_MODE): AUTO_ENABLED is AUTO.MISSION, ACCEPTED on a vehicle
    awaiting a mission and holding one; MANUAL_INPUT_ENABLED is POSCTL (with GUIDED), STABILIZED (with STABILIZE) or
    MANUAL, none flown here, so DENIED naming it, as DO_SET_MODE of that mode is; neither flag asks for no mode:
    ACCEPTED, nothing changes (AUTO.MISSION stays selected). Until the third wave's thirty-eighth session every one
    was DENIED (`only PX4 custom modes`)."""
    manual = M.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED
    with _awaiting_vehicle(tmp_path) as (gcs, command):
        for base, name in ((manual | M.MAV_MODE_FLAG_GUIDED_ENABLED, "POSCTL"),
                           (manual | M.MAV_MODE_FLAG_STABILIZE_ENABLED, "STABILIZED"), (manual, "MANUAL")):
            result, said = command(M.MAV_CMD_DO_SET_MODE, base)
            assert result == M.MAV_RESULT_DENIED and said.startswith(f"mode {name}: not flown here"), (base, said)
        auto = M.MAV_MODE_FLAG_AUTO_ENABLED | M.MAV_MODE_FLAG_GUIDED_ENABLED | M.MAV_MODE_FLAG_STABILIZE_ENABLED
        assert command(M.MAV_CMD_DO_SET_MODE, auto) == (M.MAV_RESULT_ACCEPTED, "")
        _recv(gcs, "HEARTBEAT", f"HEARTBEAT.custom_mode=={MISSION_MODE}")
        assert command(M.MAV_CMD_DO_SET_MODE, 0, 4, 3) == (M.MAV_RESULT_ACCEPTED, "")  # no mode asked: MISSION stays
        assert _recv(gcs, "HEARTBEAT").custom_mode == MISSION_MODE  # (sent after that answer)
        gcs.mav.set_mode_send(gcs.target_system, 0, HOLD_MODE)  # the same as SET_MODE
        assert _recv(gcs, "COMMAND_ACK", "COMMAND_ACK.command==176").result == M.MAV_RESULT_ACCEPTED
        assert _recv(gcs, "HEARTBEAT").custom_mode == MISSION_MODE
        assert command(M.MAV_CMD_DO_SET_MODE, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 4, 3) == (M.MAV_RESULT_ACCEPTED, "")
        _recv(gcs, "HEARTBEAT", f"HEARTBEAT.custom_mode=={HOLD_MODE}")
        gcs.mav.set_mode_send(gcs.target_system, M.MAV_MODE_FLAG_AUTO_ENABLED, 0)
        assert _recv(gcs, "COMMAND_ACK", "COMMAND_ACK.command==176").result == M.MAV_RESULT_ACCEPTED
        _recv(gcs, "HEARTBEAT", f"HEARTBEAT.custom_mode=={MISSION_MODE}")

# -- whole flights --------------------------------------------------------------------------------
CHANGES = [ParamChange(2.0, "COM_OF_LOSS_T", 0.3), ParamChange(4.0, "COM_OBL_ACT", 1),
           ParamChange(4.0, "COM_FAIL_ACT_T", 1.0), ParamChange(4.0, "MPC_LAND_SPEED", 2.0)]
# the failsafe at 6.3 s holds 1 s, lands, and disarms at 9.86 s (COM_DISARM_LAND): the mission outlasts it, so the
# whole flight is lockstep (at 9 s the vehicle left lockstep, the session waiting on the wall clock for its disarm)
SHORT = Mission(Sine(), duration_s=10.5, name="short")
EARLY_BLACKOUT = {"blackouts": [[6.0, 2.0]]}



def _line_of(log: list[str], *parts: str) -> int:
    """The index of the first line of ``log`` holding every one of ``parts``."""
    return next(i for i, line in enumerate(log) if all(p in line for p in parts))


def test_a_parameter_set_at_a_mission_time_is_reproducible_in_lockstep_and_matches_offline(tmp_path):
    """``--param-at``: the controller sends PARAM_SET before the answer of its step, the vehicle makes
    it before it flies that step, the offline loop at the start of it: twice the same trace.csv in
    lockstep, and offline within 1e-4 m (the same, bit for bit: the offline loop flies the float32 wire).
    events.log lists each change by cause at its one time: the controller's PARAM_SET, the vehicle's change, the
    controller's word of its echo (the change came first, before the PARAM_SET that made it, until the forty-first
    session: bridge.session.eventorder put the vehicle's events first on every tie)."""
    runs = []
    for i in range(2):
        sitl(SHORT, out=tmp_path / f"r{i}", instance=None, link=EARLY_BLACKOUT, param_at=CHANGES, plots=False)
        runs.append((tmp_path / f"r{i}" / "trace.csv").read_bytes())
        log = (tmp_path / f"r{i}" / "events.log").read_text().splitlines()
        for c in CHANGES:
            sent = _line_of(log, f"param: PARAM_SET {c.name} = ")
            made = _line_of(log, f"param: {c.name} = ", "(was", "[vehicle]")
            echoed = _line_of(log, f"param: {c.name} = ", "confirmed by the vehicle")
            assert sent < made < echoed, [log[j] for j in (sent, made, echoed)]
    assert runs[0] == runs[1]
    s = json.loads((tmp_path / "r0" / "summary.json").read_text())
    assert s["outcome"] == "failsafe" and "hold here" in s["ended_by"]["how"]
    assert "0.304 s" in s["ended_by"]["how"]  # COM_OF_LOSS_T 0.3 from t = 2 s: the failsafe at 6.3 s
    off = simulate(SHORT, link=EARLY_BLACKOUT, param_at=CHANGES, plots=False)
    lock = read_trace(tmp_path / "r0" / "trace.csv")
    n = min(len(off.trace["t"]), len(lock["t"]))
    err = max(float(np.max(np.abs(np.asarray(off.trace[c][:n]) - np.asarray(lock[c][:n])))) for c in "xyz")
    assert err < 1e-4
    assert all(p["ok"] for p in s["policies"])


def test_a_ground_stations_hold_ends_a_lockstep_flight_named(tmp_path):
    """During ``bsst sitl``, a ground station's DO_SET_MODE HOLD at t >= 3 s: the vehicle holds on its
    own (a lockstep event says it leaves lockstep), the controller stops sending targets, the run is
    ``aborted``, ended by that ground station, exit 1, and every policy holds."""
    with instance_slot() as n:
        gcs = _gcs(n)
        out = tmp_path / "run"
        s = Bsst("sitl", "missions/step.toml", "--instance", str(n), "--out", str(out), "--no-plots", "--speed", "2",
                 env=ENV, stdout=False)
        try:
            gcs.wait_heartbeat(timeout=30)
            _recv(gcs, "LOCAL_POSITION_NED", "LOCAL_POSITION_NED.time_boot_ms >= 3000", timeout=30)
            gcs.mav.command_long_send(gcs.target_system, gcs.target_component, M.MAV_CMD_DO_SET_MODE, 0,
                                      29, 4, 3, 0, 0, 0, 0)
            assert _recv(gcs, "COMMAND_ACK", "COMMAND_ACK.command==176").result == M.MAV_RESULT_ACCEPTED
            _, err = s.communicate(timeout=90)
        finally:
            if s.poll() is None:
                s.kill()
            gcs.close()
    assert s.returncode == 1, err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["outcome"] == "aborted"
    assert summary["ended_by"]["who"].startswith("255:190 127.0.0.1:") and "HOLD" in summary["ended_by"]["how"]
    assert summary["lockstep"]["held"] is False and "HOLD set by a ground station" in summary["lockstep"]["why"]
    assert all(p["ok"] for p in summary["policies"]), summary["policies"]
    log = (out / "events.log").read_text()
    assert "the vehicle was switched to HOLD: no more targets sent [controller]" in log


@pytest.mark.parametrize("spec", PARAMS, ids=lambda s: s.name)
def test_every_parameter_has_its_range_in_the_usage_and_the_ground_station_pages(spec):
    """A meta-test, as tests/test_link_keys.py for ``[link]``: docs/usage.md's row names the parameter
    and its range (or its choices), and so does docs/ground-station.md."""
    def shown(v: float) -> str:
        return f"{v:.12g}".replace("-", "−")  # (10000000, not 1e+07)

    want = ([f"{shown(v)} {a}" for v, a in spec.choices.items()] if spec.choices
            else [f"{shown(spec.lo)}–{shown(spec.hi)}"])
    for page in ("docs/usage.md", "docs/ground-station.md"):
        rows = [ln for ln in (ROOT / page).read_text().splitlines() if ln.startswith(f"| `{spec.name}` |")]
        assert rows, f"{page} has no row for {spec.name}"
        for w in want:
            assert w.split()[0] in rows[0], f"{page}: {spec.name}'s row does not give {w!r}: {rows[0]}"


def test_a_long_refusal_goes_out_whole_in_statustext_chunks():
    """MAVLink 2's chunked STATUSTEXT: one id, chunk_seq 0.., a short last chunk (an empty one after an
    exact multiple of 50), the text whole up to 500 bytes (a longer one cut there, ending in "..."); a short text
    is one plain message."""
    from bridge.mavlink.telemetry import statustext

    assert [(m.id, m.chunk_seq) for m in statustext(4, "short", 7)] == [(0, 0)]
    why = "NAV_TAKEOFF: altitude 5 m AMSL is -483 m above home; must be 0.5..50 m above (home 488 m)"
    msgs = statustext(4, why, 7)
    assert [(m.id, m.chunk_seq) for m in msgs] == [(7, 0), (7, 1)]
    assert b"".join(m.text if isinstance(m.text, bytes) else m.text.encode() for m in msgs) == why.encode()
    assert [len(m.text) for m in statustext(4, "x" * 100, 3)] == [50, 50, 0]
    long = statustext(4, "y" * 1000, 3)
    assert len(long) == 11 and long[-2].text.endswith("...") and long[-1].text == ""  # 500 bytes, the empty end
    assert len(statustext(4, "z" * 239, 3)) == 5  # the longest the vehicle says (a start refused), whole


# -- issue 22: parameters as typed flags, float32 bounds, two entries for one setting ------------------
def _f32(x: float) -> float:
    return struct.unpack("<f", struct.pack("<f", x))[0]


def _bsst(*args: str, cwd=ROOT) -> subprocess.CompletedProcess:
    return run_bsst(*args, cwd=cwd, env=ENV, timeout=120)


@pytest.mark.parametrize("name, value", [("COM_OBL_ACT", "1"), ("COM_OBL_RC_ACT", "5"), ("MAV_SYS_ID", "7")])
def test_an_integer_parameter_flag_is_parsed_as_an_integer(tmp_path, name, value):
    """Issue 22, defect 4: ``--param COM_OBL_ACT=1`` flies (it was refused as 'expected an integer, got
    1.0', blamed on the mission file); the run's mission.toml holds the integer."""
    mission = tmp_path / "short.toml"  # the flag is read and written before the flight: a second of it will do
    mission.write_text((ROOT / "missions" / "sine.toml").read_text().replace("duration_s = 30.0", "duration_s = 1.0"))
    r = _bsst("sim", str(mission), "--param", f"{name}={value}", "--out", str(tmp_path / "r"), "--no-plots")
    assert r.returncode == 0, r.stderr
    assert f"{name} = {value}\n" in (tmp_path / "r" / "mission.toml").read_text()


@pytest.mark.parametrize("cmd", ["sim", "sitl", "vehicle"])
@pytest.mark.parametrize("args, says", [
    (["--param", "COM_OBL_ACT=1.5"], "--param 'COM_OBL_ACT=1.5': COM_OBL_ACT: an INT32, expected an integer"),
    (["--param", "MAV_SYS_ID=x"], "--param 'MAV_SYS_ID=x': MAV_SYS_ID: an INT32, expected an integer"),
    (["--param", "EKF2_NOAID_TOUT=nan"], "--param 'EKF2_NOAID_TOUT=nan': EKF2_NOAID_TOUT: an INT32, expected an "
                                         "integer in [500000, 10000000] us, got nan"),
    (["--param", "COM_DISARM_LAND=x"], "--param 'COM_DISARM_LAND=x': COM_DISARM_LAND: a REAL32, expected a number, "
                                       "got 'x'"),
    (["--param", "COM_OBL_ACT=1", "--param", "COM_OBL_RC_ACT=7"],
     "--param COM_OBL_RC_ACT=7 and --param COM_OBL_ACT=1 set one setting, [failsafe] action, two ways"),
], ids=["fraction", "word", "not-finite", "real-word", "clash"])
def test_a_bad_parameter_flag_is_named_as_the_flag_not_the_mission(cmd, args, says):
    mission = [] if cmd == "vehicle" else ["missions/sine.toml"]
    r = _bsst(cmd, *mission, *args)  # refused before a port is bound
    assert r.returncode == 2 and says in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "sine.toml" not in r.stderr, r.stderr


def test_two_offboard_loss_entries_of_one_file_must_agree(tmp_path):
    """Issue 22, defect 10: ``[params]`` COM_OBL_ACT and COM_OBL_RC_ACT are one setting; two different
    actions are refused naming the file and both keys, the same action twice is taken."""
    src = (ROOT / "missions" / "sine.toml").read_text()
    path = tmp_path / "m.toml"
    path.write_text(src + "\n[params]\nCOM_OBL_ACT = 1\nCOM_OBL_RC_ACT = 7\n")
    with pytest.raises(ConfigError, match=r"m.toml: params.COM_OBL_RC_ACT and params.COM_OBL_ACT set one setting"):
        prepare(path)
    r = _bsst("sim", str(path))
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert all(w in r.stderr for w in ("m.toml", "params.COM_OBL_ACT", "params.COM_OBL_RC_ACT")), r.stderr
    path.write_text(src + "\n[params]\nCOM_OBL_ACT = 1\nCOM_OBL_RC_ACT = 5\n")  # hold, twice
    assert prepare(path).failsafe.action == "hold"
    # a flag for the setting wins over both of the file's entries
    path.write_text(src + "\n[params]\nCOM_OBL_RC_ACT = 7\n")
    assert prepare(path, params={"COM_OBL_ACT": 1}).failsafe.action == "hold"



# -- an INT32 given as a whole float (1e6, 1000000.0): in a file, on a flag, from Python -----------------------------
def _with_params(tmp_path, lines: str):
    path = tmp_path / "m.toml"
    path.write_text((ROOT / "missions" / "sine.toml").read_text() + f"\n[params]\n{lines}\n")
    return path


def test_an_int32_given_as_a_whole_float_is_that_integer_everywhere(tmp_path):
    """``EKF2_NOAID_TOUT = 1e6`` (or ``1000000.0``) in ``[params]``, ``--param EKF2_NOAID_TOUT=1e6``, ``--param-at
    5:EKF2_NOAID_TOUT=1e6`` and ``params={"EKF2_NOAID_TOUT": 1e6}`` are the integer 1000000, as a PARAM_SET's whole
    float is: the vehicle's parameters the same as with it, an ``int``; likewise a choice (COM_OBL_ACT = 1.0, hold)
    and the system id (MAV_SYS_ID = 7.0)."""
    want = prepare("missions/sine.toml", params={"EKF2_NOAID_TOUT": 1_000_000}).params
    for text in ("1e6", "1000000.0", "1.0e+06", "1_000_000.0", "1000000"):
        got = prepare(_with_params(tmp_path, f"EKF2_NOAID_TOUT = {text}")).params
        assert got == want and type(got.noaid_timeout_us) is int, text
    assert prepare("missions/sine.toml", params={"EKF2_NOAID_TOUT": 1e6}).params == want
    for text in ("1e6", "1000000.0", "1E6", "+1e6"):
        name, value = param_assignment("--param")(f"EKF2_NOAID_TOUT={text}")
        flown = prepare("missions/sine.toml", params={name: value})
        assert flown.params == want and flown.mission.params == {"EKF2_NOAID_TOUT": 1_000_000}, text
        assert type(flown.mission.params["EKF2_NOAID_TOUT"]) is int  # (the run's mission.toml: 1000000)
        (change,) = check_param_changes([param_assignment("--param-at", timed=True)(f"5:EKF2_NOAID_TOUT={text}")], 30.0)
        assert change == ParamChange(5.0, "EKF2_NOAID_TOUT", 1_000_000) and type(change.value) is int
    other = prepare(_with_params(tmp_path, "COM_OBL_ACT = 1.0\nMAV_SYS_ID = 7.0"))
    assert other.failsafe.action == "hold" and other.params.sysid == 7 and type(other.params.sysid) is int


RANGE = "[500000, 10000000] us"
NOT_INT32 = [  # (the value as TOML writes it, and as a flag; what the refusal says after the key)
    ("1.5", f"an INT32, expected an integer in {RANGE}, got 1.5"),
    ("1000000.5", f"an INT32, expected an integer in {RANGE}, got 1000000.5"),
    ("nan", f"an INT32, expected an integer in {RANGE}, got nan"),
    ("inf", f"an INT32, expected an integer in {RANGE}, got inf"),
    ("-inf", f"an INT32, expected an integer in {RANGE}, got -inf"),
    ("2e7", f"must be in {RANGE}, got 20000000"),
    ("4e5", f"must be in {RANGE}, got 400000"),
    ("1e300", f"must be in {RANGE}, got 1e+300"),
]


@pytest.mark.parametrize("text, says", NOT_INT32, ids=[t for t, _ in NOT_INT32])
def test_an_int32_that_is_not_a_whole_number_in_range_is_refused_naming_where_and_the_range(tmp_path, text, says):
    """Not whole, not finite, or out of range: refused by the one check (:func:`value_problem`) with one line naming
    the file and key, or the flag, and the range, whether given as a file's float or a flag's text."""
    with pytest.raises(ConfigError) as got:
        prepare(_with_params(tmp_path, f"EKF2_NOAID_TOUT = {text}"))
    assert str(got.value) == f"{tmp_path / 'm.toml'}: params.EKF2_NOAID_TOUT: {says}"
    with pytest.raises(argparse.ArgumentTypeError) as flag:
        param_assignment("--param")(f"EKF2_NOAID_TOUT={text}")
    assert str(flag.value) == f"--param 'EKF2_NOAID_TOUT={text}': EKF2_NOAID_TOUT: {says}"
    with pytest.raises(ConfigError) as python:
        prepare("missions/sine.toml", params={"EKF2_NOAID_TOUT": float(text)})
    assert str(python.value) == f"--param EKF2_NOAID_TOUT={float(text)}: {says}"


PAST_FLOAT = [("9" * 4400, "an integer of 4400 digits"), ("-" + "9" * 400, "an integer of 400 digits"),
              ("1e400", "1e400")]


@pytest.mark.parametrize("name, says", [("COM_OF_LOSS_T", "must be in [0.01, 60] s"),
                                        ("EKF2_NOAID_TOUT", f"must be in {RANGE}")])
def test_a_flags_number_past_the_float_range_is_out_of_range_not_inf(name, says):
    """``--param NAME=<an integer of over 4300 digits>`` (past Python's ``int()``) said ``got inf`` (``must be
    finite``, or an INT32 ``expected an integer``), as did a REAL32's integer past the float range and ``1e400``:
    ``float()`` took each to inf. Each is out of the parameter's range (so of float32's), as a shorter integer is
    (``got an integer of 400 digits``); ``inf`` itself still says inf."""
    for text, got in PAST_FLOAT:
        for flag, given in (("--param", f"{name}={text}"), ("--param-at", f"5:{name}={text}")):
            with pytest.raises(argparse.ArgumentTypeError) as err:
                param_assignment(flag, timed=flag == "--param-at")(given)
            assert str(err.value) == f"{flag} {quoted(given)}: {name}: {says}, got {got}"  # (a long one shortened)
    with pytest.raises(argparse.ArgumentTypeError, match=r": (must be finite|an INT32, .*), got inf$"):
        param_assignment("--param")(f"{name}=inf")
    r = _bsst("sim", "missions/sine.toml", "--param", f"{name}={PAST_FLOAT[0][0]}")
    assert r.returncode == 2 and r.stderr.strip().endswith(f"{name}: {says}, got an integer of 4400 digits"), \
        r.stderr[-300:]


def test_float32_is_the_wires_rounding():
    """The one float32 rounding of the scalar code (``bridge.autopilot.params.float32``; the offboard controller's
    PARAM_SET and its echo used a twin, ``_f32``): as struct's ``<f`` round trip, None past float32's range."""
    for x in (0.01, 25.3, -1e-45, 3.4028234663852886e38, 0.0):
        assert float32(x) == _f32(x)
    assert float32(10**400) is None and float32(1e39) is None and float32(-1e39) is None
    assert math.isnan(float32(math.nan)) and float32(math.inf) == math.inf


def test_a_boolean_or_text_is_no_integer_and_a_choice_names_its_values(tmp_path):
    """``true`` is not 1, in a file, a flag or from Python; a text is not a number; an INT32 of choices that is not
    whole names its values."""
    for lines, says in (("EKF2_NOAID_TOUT = true", "params.EKF2_NOAID_TOUT: expected an integer, got True"),
                        ("SYS_FAILURE_EN = true", "params.SYS_FAILURE_EN: expected an integer, got True"),
                        ('EKF2_NOAID_TOUT = "1e6"', "params.EKF2_NOAID_TOUT: expected an integer, got '1e6'"),
                        ("COM_OBL_ACT = 1.5", "params.COM_OBL_ACT: an INT32, expected an integer (-1 descend, 0 land, "
                                              "1 hold, 2 return, 3 disarm), got 1.5")):
        with pytest.raises(ConfigError) as got:
            prepare(_with_params(tmp_path, lines))
        assert str(got.value) == f"{tmp_path / 'm.toml'}: {says}"
    for text in ("true", "True", "x", "1e6x", ""):
        with pytest.raises(argparse.ArgumentTypeError) as flag:
            param_assignment("--param")(f"SYS_FAILURE_EN={text}")
        assert str(flag.value) == (f"--param 'SYS_FAILURE_EN={text}': SYS_FAILURE_EN: an INT32, expected an integer "
                                   f"(0 disabled, 1 enabled), got {text!r}")
    with pytest.raises(ConfigError, match=r"^--param SYS_FAILURE_EN=True: expected a number, got True$"):
        prepare("missions/sine.toml", params={"SYS_FAILURE_EN": True})


def test_a_whole_float_flag_and_file_fly_as_the_integer(tmp_path):
    """``bsst sim --param EKF2_NOAID_TOUT=1e6``, the file's ``EKF2_NOAID_TOUT = 1e6`` and ``--param
    EKF2_NOAID_TOUT=1000000``: the same flight (the GPS off at 1 s: the position lost 1 s after the last fix is fused,
    within the 3 s flown, where the default 5 s would not), the flag's run's mission.toml holding the integer."""
    mission = tmp_path / "short.toml"
    text = (ROOT / "missions" / "sine.toml").read_text().replace("duration_s = 30.0", "duration_s = 3.0")
    mission.write_text(text)
    (tmp_path / "file.toml").write_text(text + "\n[params]\nEKF2_NOAID_TOUT = 1e6\n")
    common = ("--sensors", "gnss", "--estimator", "ekf", "--at", "1:gps:off", "--no-plots")
    runs = {"int": (str(mission), "--param", "EKF2_NOAID_TOUT=1000000"),
            "float": (str(mission), "--param", "EKF2_NOAID_TOUT=1e6"), "file": (str(tmp_path / "file.toml"),)}
    for name, args in runs.items():
        r = _bsst("sim", *args, *common, "--out", str(tmp_path / name))
        assert r.returncode == 1, r.stderr  # PX4's failsafe on the lost position
    trace = (tmp_path / "int" / "trace.csv").read_text()
    assert all((tmp_path / n / "trace.csv").read_text() == trace for n in ("float", "file"))
    lost = [e["t"] for e in json.loads((tmp_path / "float" / "summary.json").read_text())["events"]
            if e["kind"] == "position"]
    assert lost and 2.0 < lost[0] < 2.5, lost
    assert "EKF2_NOAID_TOUT = 1000000\n" in (tmp_path / "float" / "mission.toml").read_text()

def test_two_scheduled_changes_of_one_parameter_at_one_time_the_last_given_wins(tmp_path):
    """Issue 22, defect 10: ``--param-at 3:COM_OBL_ACT=3 --param-at 3:COM_OBL_ACT=1``: hold (the last
    given), not disarm (the larger value, as it was), in the blackout at 6 s of 10 s of sine (the 30 s sine's at
    15 s flew 15 s more than its failsafe needs)."""
    mission = tmp_path / "short.toml"
    mission.write_text((ROOT / "missions" / "sine.toml").read_text().replace("duration_s = 30.0", "duration_s = 10.0"))
    out = tmp_path / "r"
    r = _bsst("sim", str(mission), "--param-at", "3:COM_OBL_ACT=3", "--param-at", "3:COM_OBL_ACT=1",
              "--blackout", "6:2", "--out", str(out), "--no-plots")
    assert r.returncode == 1, r.stderr  # the failsafe
    log = (out / "events.log").read_text()
    assert "COM_OBL_ACT = 1 (was 3)" in log and "hold here" in json.loads((out / "summary.json").read_text())[
        "ended_by"]["how"], log
    assert [c.value for c in prepare("missions/sine.toml", param_at=[
        ParamChange(10.0, "COM_OBL_ACT", 3), ParamChange(10.0, "COM_OBL_ACT", 1), ParamChange(5.0, "COM_OBL_ACT", 0),
    ]).param_changes] == [0, 3, 1]


def test_a_value_that_rounds_to_a_bound_in_float32_is_the_bound():
    """Issue 22, defect 5: every bound of every REAL32 parameter survives the float32 wire (0.01 arrives as
    0.0099999998, and is set as 0.01 itself: the setting stays in its range); the next float32 beyond a
    bound is still refused."""
    assert _f32(0.01) < 0.01
    for far in (0.0099999, 1e300, -1e300):  # beyond float32 rounding, or beyond float32
        with pytest.raises(ParamRefused, match="must be in"):
            change_param(VehicleParams(), "COM_OF_LOSS_T", far)
    for spec in PARAMS:
        if spec.kind != "REAL32":
            continue
        for bound in (spec.lo, spec.hi):
            got = read_param(change_param(VehicleParams(), spec.name, _f32(bound)), spec.name)
            assert spec.lo <= got <= spec.hi and got == pytest.approx(bound, rel=1e-7), spec.name
        # the next float32 beyond each bound: a value that crossed the wire and is not the bound
        for outside in (np.nextafter(np.float32(spec.lo), np.float32(-np.inf)),
                        np.nextafter(np.float32(spec.hi), np.float32(np.inf))):
            with pytest.raises(ParamRefused, match="must be in"):
                change_param(VehicleParams(), spec.name, float(outside))
    assert change_param(VehicleParams(), "COM_OF_LOSS_T", _f32(0.01)).failsafe.timeout_s == 0.01


def test_the_documented_minimum_loss_timeout_is_set_over_mavlink(tmp_path):
    """Issue 22, defects 4 and 5 against a real ``bsst vehicle``: started with integer ``--param`` flags
    (MAV_SYS_ID=7: its heartbeat's system id; COM_OBL_ACT=1 read back), then a pymavlink ground station's
    PARAM_SET COM_OF_LOSS_T 0.01 (float32 0.0099999998) is made, and one truly below is refused."""
    with instance_slot() as n:
        gcs = _gcs(n)
        v = Proc.bsst("vehicle", "--instance", str(n), "--out", str(tmp_path), "--param", "MAV_SYS_ID=7",
                      "--param", "COM_OBL_ACT=1")
        try:
            v.wait_report(Ready)
            hb = gcs.wait_heartbeat(timeout=20)
            assert hb.get_srcSystem() == 7
            tgt = (7, gcs.target_component)
            gcs.mav.param_request_read_send(*tgt, b"COM_OBL_ACT", -1)
            assert param_from_wire(_recv(gcs, "PARAM_VALUE").param_value, M.MAV_PARAM_TYPE_INT32) == 1
            gcs.mav.param_set_send(*tgt, b"COM_OF_LOSS_T", 0.01, M.MAV_PARAM_TYPE_REAL32)
            m = _recv(gcs, "PARAM_VALUE", "PARAM_VALUE.param_id == 'COM_OF_LOSS_T'")
            assert m.param_value == _f32(0.01)
            gcs.mav.param_set_send(*tgt, b"COM_OF_LOSS_T", 0.0099, M.MAV_PARAM_TYPE_REAL32)
            assert _recv(gcs, "PARAM_VALUE", "PARAM_VALUE.param_id == 'COM_OF_LOSS_T'").param_value == _f32(0.01)
            _recv(gcs, "STATUSTEXT", "'must be in [0.01, 60]' in STATUSTEXT.text")
        finally:
            assert v.stop() == 0
            gcs.close()
    e = v.wait_event(lambda s: "param: COM_OF_LOSS_T = 0.01 (was 0.5) [by 255:190" in s)
    assert (e.param.name, e.param.new) == ("COM_OF_LOSS_T", 0.01)
    stats = v.wait_report(Stats).values
    assert stats["rejected"]["param_refused"] == 1


def test_integer_flags_and_the_minimum_timeout_fly_in_lockstep_as_offline(tmp_path):
    """``bsst sitl`` with ``--param COM_OBL_ACT=1`` (hold) and ``--param-at 2:COM_OF_LOSS_T=0.01``: the
    controller's PARAM_SET (float32) is made by the vehicle process, and the lockstep trace is the offline
    one: the failsafe holds 0.01 s into the blackout (at 3 s) in both, for COM_FAIL_ACT_T (1 s), then lands and
    disarms. The mission outlasts that disarm (6.7 s), so the whole failsafe is flown in lockstep; a shorter one left
    the vehicle holding on the wall clock once the controller was done, the session waiting for its landing. (A
    blackout at 6 s and PX4's 5 s hold flew 15 s for the same.)"""
    mission = tmp_path / "short.toml"
    mission.write_text((ROOT / "missions" / "sine.toml").read_text().replace("duration_s = 30.0", "duration_s = 8.0"))
    flags = ["--param", "COM_OBL_ACT=1", "--param", "COM_FAIL_ACT_T=1", "--param-at", "2:COM_OF_LOSS_T=0.01",
             "--blackout", "3:2", "--no-plots"]
    with instance_slot() as n:
        r = _bsst("sitl", str(mission), *flags, "--instance", str(n), "--out", str(tmp_path / "lock"))
    assert r.returncode == 1, r.stderr  # the failsafe
    s = json.loads((tmp_path / "lock" / "summary.json").read_text())
    assert "hold here" in s["ended_by"]["how"] and "0.012 s" in s["ended_by"]["how"], s["ended_by"]
    assert "COM_OF_LOSS_T = 0.01 (was 0.5)" in (tmp_path / "lock" / "events.log").read_text()
    off = _bsst("sim", str(mission), *flags, "--out", str(tmp_path / "off"))
    assert off.returncode == 1, off.stderr
    lock, offline = read_trace(tmp_path / "lock" / "trace.csv"), read_trace(tmp_path / "off" / "trace.csv")
    n = min(len(offline["t"]), len(lock["t"]))
    assert max(float(np.max(np.abs(np.asarray(offline[c][:n]) - np.asarray(lock[c][:n])))) for c in "xyz") < 1e-4


# -- issue 22, defect 1: a ground station's parameter change is recorded, and ends the clean record ---------
def test_a_ground_stations_parameter_change_is_recorded_who_what_when_and_ends_reproducibility(tmp_path):
    """During a lockstep ``bsst sitl`` (7 s of sine, a blackout at 5 s), a ground station sets COM_OF_LOSS_T to
    the value in force (no change: not recorded), then COM_OBL_ACT = 3 (terminate) at t >= 2 s. The failsafe
    stops the motors in the blackout: ``ended_by`` names that ground station and its change, not the vehicle;
    ``interventions`` has the one change (sender, name, old -> new, t and step), the lockstep record says the run
    is reproducible only until that step, the printout says it was not flown as asked, exit 1. (At 2x real time:
    the ground station's change has 1.5 s of wall clock before the blackout.)"""
    mission = tmp_path / "short.toml"
    mission.write_text((ROOT / "missions" / "sine.toml").read_text().replace("duration_s = 30.0", "duration_s = 7.0"))
    out = tmp_path / "run"
    with instance_slot() as n:
        gcs = _gcs(n)
        s = Bsst("sitl", str(mission), "--instance", str(n), "--blackout", "5:2", "--out", str(out), "--no-plots",
                 "--speed", "2", env=ENV)
        try:
            gcs.wait_heartbeat(timeout=30)
            tgt = (gcs.target_system, gcs.target_component)
            _recv(gcs, "LOCAL_POSITION_NED", "LOCAL_POSITION_NED.time_boot_ms >= 1000", timeout=30)
            gcs.mav.param_request_read_send(*tgt, b"COM_OF_LOSS_T", -1)
            now = _recv(gcs, "PARAM_VALUE", "PARAM_VALUE.param_id == 'COM_OF_LOSS_T'").param_value
            gcs.mav.param_set_send(*tgt, b"COM_OF_LOSS_T", now, M.MAV_PARAM_TYPE_REAL32)  # the value in force
            assert _recv(gcs, "PARAM_VALUE", "PARAM_VALUE.param_id == 'COM_OF_LOSS_T'").param_value == now
            _recv(gcs, "LOCAL_POSITION_NED", "LOCAL_POSITION_NED.time_boot_ms >= 2000", timeout=30)
            gcs.mav.param_set_send(*tgt, b"COM_OBL_ACT", param_to_wire(3, 6), M.MAV_PARAM_TYPE_INT32)
            m = _recv(gcs, "PARAM_VALUE", "PARAM_VALUE.param_id == 'COM_OBL_ACT'")
            assert param_from_wire(m.param_value, M.MAV_PARAM_TYPE_INT32) == 3
            stdout, err = s.communicate(timeout=90)
        finally:
            if s.poll() is None:
                s.kill()
            gcs.close()
    assert s.returncode == 1, err
    summary = json.loads((out / "summary.json").read_text())
    [change] = summary["interventions"]
    assert change["by"].startswith("255:190 127.0.0.1:") and change["by"].endswith(" gcs")
    assert change["kind"] == "param" and change["name"] == "COM_OBL_ACT" and change["new"] == 3
    assert change["old"] != 3 and change["t"] >= 2.0 and change["step"] == round(change["t"] * 250)
    assert summary["outcome"] == "failsafe"
    end = summary["ended_by"]
    assert end["who"] == change["by"] and "COM_OBL_ACT = 3" in end["how"] and f"(step {change['step']})" in end["how"]
    lock = summary["lockstep"]
    assert lock["held"] is True and lock["reproducible"] is False
    assert lock["reproducible_until_step"] == change["step"] and "COM_OBL_ACT" in lock["because"]
    assert "not flown as asked" in err and "COM_OBL_ACT" in err
    assert f"reproducible until step {change['step']}" in stdout


# -- issue 22, defect 3: a scheduled change is confirmed by the vehicle's echo, resent until it is, or said lost ---
# lost: the blackout outlasts the controller's end (its disarm's 3 s of tries): the held command brings the vehicle
# down hard (crashed, issue 27), after which a resend reaching it at the blackout's end would be answered. Its flight
# is 3 s, the blackout from 2 s (crashed at 2.9-3.3 s; 5 s and 4 s until the forty-fifth session, crashed at 5.8 s:
# what is checked, the sends and their end unconfirmed, is the same ~1 s after the blackout's start either way)
# rides-through flies PID: a blackout holds the last target (as PX4 does until COM_OF_LOSS_T), and the BS-ST
# law's torques alternate by several N·m (issue 24), so which one is held for the 1 s is the wall clock's draw,
# and some draws tip the vehicle into the ground (seen under load: "no new state from the vehicle", crashed).
# PID's torques are below 0.3 N·m from 3 s on: the same hold is a small drift, every time.
@pytest.mark.parametrize("seconds, blackout, at, law, confirmed",
                         [(5.0, "3:1", "3.2", "pid", True), (3.0, "2:30", "2.2", "bsst", False)],
                         ids=["rides-through", "lost"])
def test_a_scheduled_change_in_a_realtime_blackout_is_resent_until_confirmed_or_said_not_made(tmp_path, seconds,
                                                                                               blackout, at, law,
                                                                                               confirmed):
    """``bsst sitl --realtime`` through the relay, the up link blacked out over ``--param-at``'s time (the loss
    timeout 5 s: the blackout alone is no failsafe). Rides through: the PARAM_SET lost in the blackout is sent
    again every 0.2 s until the vehicle's PARAM_VALUE echoes it after the blackout; the vehicle made the change,
    ``param_at`` says confirmed (more than one send), exit 0. Lost (the blackout outlasts the flight and the
    controller's end): never confirmed, the summary and stderr say it was not made, exit 1. (Landed, the vehicle
    disarms 0.5 s later, not PX4's 2 s: each second on the wall clock is the test's CPU.)"""
    mission = tmp_path / "short.toml"
    mission.write_text((ROOT / "missions" / "sine.toml").read_text().replace("duration_s = 30.0",
                                                                             f"duration_s = {seconds}"))
    with instance_slot() as n:
        r = _bsst("sitl", str(mission), "--realtime", "--instance", str(n), "--out", str(tmp_path / "run"),
                  "--no-plots", "--controller", law, "--delay", "2", "--param", "COM_OF_LOSS_T=5",
                  "--param", "COM_DISARM_LAND=0.5",
                  "--up-blackout", blackout, "--param-at", f"{at}:MIS_TAKEOFF_ALT=5")
    s = json.loads((tmp_path / "run" / "summary.json").read_text())
    [sent] = s["param_at"]
    assert sent["name"] == "MIS_TAKEOFF_ALT" and sent["value"] == 5 and sent["sends"] >= 2, sent
    log = (tmp_path / "run" / "events.log").read_text()
    if confirmed:
        assert r.returncode == clean_exit(s), r.stderr
        assert sent["confirmed"] is True and sent["confirmed_t"] >= 4.0, sent
        assert "MIS_TAKEOFF_ALT = 5 (was 2.5)" in log  # the vehicle made it
    else:
        assert r.returncode == 1, r.stderr
        assert sent["confirmed"] is False and sent["confirmed_t"] is None
        assert "MIS_TAKEOFF_ALT = 5 (was" not in log
        assert f"--param-at {at}:MIS_TAKEOFF_ALT=5 was never confirmed by the vehicle" in r.stderr


# the up link's delay from 2.85 s: the PARAM_SET of 2.9 s reaches the vehicle 0.3 s later, after the 3 s flight's end
LATE_TRACE = "t_s,delay_ms\n0,0\n2.85,300\n4,300\n"


@pytest.mark.parametrize("link", ["late", "blackout"])
def test_a_scheduled_change_confirmed_only_after_the_flights_end_is_not_made(tmp_path, link):
    """``bsst sitl --realtime``, ``--param-at 2.9`` of a 3 s flight. Late: the up link's delay (0.3 s from 2.85 s)
    brings the PARAM_SET to the vehicle after the flight's end; it makes the change then and echoes it: not made in
    flight (``confirmed`` false, ``late_t`` its time after 3 s), the controller's word after the vehicle's own in
    events.log, exit 1. Blackout: the up link dark from 2.8 to 3.3 s: no PARAM_SET is sent again after the flight's
    end, the vehicle never makes it, exit 1. Until the third wave's thirty-ninth session both said ``confirmed``, at
    the mission's end (t=5.000 of the 5 s flight flown then, before the vehicle's change at 5.2-5.3 s), exit 0, the
    second resent into the landing. (The flight was 5 s until the forty-first session: what is checked is in its
    last 0.2 s and after it, and each second of a real-time flight is ~0.3 CPU-s of the test.)"""
    mission = tmp_path / "short.toml"
    mission.write_text((ROOT / "missions" / "sine.toml").read_text().replace("duration_s = 30.0", "duration_s = 3.0"))
    (tmp_path / "late.csv").write_text(LATE_TRACE)
    flags = ["--up-link-trace", str(tmp_path / "late.csv")] if link == "late" else ["--up-blackout", "2.8:0.5"]
    with instance_slot() as n:
        r = _bsst("sitl", str(mission), "--realtime", "--instance", str(n), "--out", str(tmp_path / "run"),
                  "--no-plots", "--controller", "pid", "--param", "COM_OF_LOSS_T=5", "--param", "COM_DISARM_LAND=0.5",
                  *flags, "--param-at", "2.9:MIS_TAKEOFF_ALT=5")
    assert r.returncode == 1, r.stderr
    s = json.loads((tmp_path / "run" / "summary.json").read_text())
    [sent] = s["param_at"]
    assert sent["confirmed"] is False and sent["confirmed_t"] is None, sent
    log = (tmp_path / "run" / "events.log").read_text().splitlines()
    made = [i for i, line in enumerate(log) if "MIS_TAKEOFF_ALT = 5 (was 2.5)" in line]
    if link == "late":
        assert sent["late_t"] > s["duration_s"] == 3.0, sent
        [said] = [i for i, line in enumerate(log) if "echoed by the vehicle only after the flight's end" in line]
        assert made and made[0] < said, log  # the vehicle's change, then the controller's word of it
        assert "2.9:MIS_TAKEOFF_ALT=5 was confirmed by the vehicle only at t=3." in r.stderr
    else:
        assert "late_t" not in sent and not made, log
        assert "--param-at 2.9:MIS_TAKEOFF_ALT=5 was never confirmed by the vehicle" in r.stderr
