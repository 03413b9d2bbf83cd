"""Covers bridge.mavlink.receive, bridge.mavlink.frames and bridge.nodes.vehicle.

Hostile and broken input (issue 7): the receive path under fuzz, as properties and during
a real lockstep mission (real processes, real UDP on 127.0.0.1, real pymavlink encoding)."""

from __future__ import annotations

import math
import socket
from collections import Counter
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import common as mavlink

from bridge.core.flight import prepare
from bridge.loop import simulate
from bridge.mavlink.endpoint import parse_address, parse_datagram
from bridge.mavlink.receive import MAX_POSITION_M, Rejections, odometry_problem, wire_problem
from bridge.mavlink.signing import Signing
from bridge.nodes.vehicle import Vehicle, VehicleConfig
from missions import MISSION_DIR, Mission, Sine, load_mission
from tests.benchkit import benchmark_module
from tests.hostile import Fuzzer, drop_held_answer, fly_flooded, fly_fuzzed, vehicle_state
from tests.sitlkit import trace_blackouts, unexplained_outages
from tests.waiting import wait_for

pytestmark = pytest.mark.process  # starts processes or opens sockets: not in make test-fast

FUZZ_DATAGRAMS = 30_000
KEY = bytes(range(32))
CTL = mavlink.MAVLink(None, srcSystem=200, srcComponent=191)


def _frames() -> list[bytes]:
    """Valid frames of every kind the vehicle handles, from the controller's ids."""
    f = Fuzzer(0, 1)
    return [
        f.target(0, (0.0, 0.0, 0.0, 0.3)),
        f.target(0, (math.nan, 0.0, 0.0, 0.3)),
        f.target(0, (0.0, 0.0, 0.0, 1.5)),
        f.target(4000, (0.1, 0.0, 0.0, 0.3)),
        mavlink.MAVLink_heartbeat_message(18, 8, 0, 0, 4, 3).pack(CTL),
        mavlink.MAVLink_command_long_message(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0).pack(CTL),
        mavlink.MAVLink_command_long_message(1, 1, 511, 0, 33, 20000, 0, 0, 0, 0, 0).pack(CTL),
        mavlink.MAVLink_timesync_message(0, 5).pack(CTL),
        mavlink.MAVLink_hil_actuator_controls_message(0, [0.0] * 16, 0, 1).pack(CTL),
    ]


FRAMES = _frames()


@st.composite
def damaged(draw: Any) -> bytes:
    """A valid frame, whole or damaged: cut, a bit flipped, bytes added before or after, doubled."""
    frame = bytearray(draw(st.sampled_from(FRAMES)))
    op = draw(st.sampled_from(["whole", "cut", "flip", "append", "prepend", "double", "byte"]))
    if op == "cut":
        frame = frame[:draw(st.integers(0, len(frame) - 1))]
    elif op == "flip":
        frame[draw(st.integers(0, len(frame) - 1))] ^= 1 << draw(st.integers(0, 7))
    elif op == "append":
        frame += draw(st.binary(min_size=1, max_size=40))
    elif op == "prepend":
        frame = bytearray(draw(st.binary(min_size=1, max_size=3))) + frame
    elif op == "double":
        frame = frame + frame
    elif op == "byte":
        frame[draw(st.integers(0, len(frame) - 1))] = draw(st.integers(0, 255))
    return bytes(frame)


ANY_BYTES = st.one_of(st.binary(max_size=600), damaged(), st.just(b"\xfd" * 12), st.just(b"\xfe" * 8))


@settings(max_examples=400, deadline=None)
@given(ANY_BYTES, st.booleans())
def test_any_bytes_parse_without_exception_and_count_once(data, signed):
    """parse_datagram never raises; a datagram gives its valid frames (each a whole slice of
    it) and is counted at most once, exactly once when it gives none."""
    rej = Rejections()
    out = parse_datagram(data, mavlink.MAVLink(None), Signing(KEY) if signed else None, rej)
    assert rej.total <= 1
    assert out or rej.total == 1
    for m in out:
        assert bytes(m.get_msgbuf()) in data
    if signed:  # nothing here was signed with our key
        assert not out and set(rej) <= {"unsigned", "truncated", "oversized", "no_frame", "mavlink1", "bad_flags",
                                        "unknown_id", "bad_crc", "bad_signature"}


@settings(max_examples=300, deadline=None)
@given(st.tuples(*[st.floats(width=32)] * 4), st.sampled_from(["wrench", "motors"]))
def test_actuator_values_are_checked(wire, actuation):
    why = wire_problem(actuation, wire)
    lo = (-1.0, -1.0, -1.0, 0.0) if actuation == "wrench" else (0.0,) * 4
    ok = all(math.isfinite(v) and a <= v <= 1.0 for v, a in zip(wire, lo))
    assert (why is None) == ok
    if not ok:
        assert why == ("out_of_range" if all(map(math.isfinite, wire)) else "not_finite")


class _Odo:
    def __init__(self, v: tuple[float, ...]) -> None:
        self.x, self.y, self.z = v[:3]
        self.q = v[3:7]
        self.vx, self.vy, self.vz, self.rollspeed, self.pitchspeed, self.yawspeed = v[7:]


@settings(max_examples=300, deadline=None)
@given(st.lists(st.one_of(st.floats(-2e4, 2e4), st.sampled_from([math.nan, math.inf, -math.inf, 0.5, 1.0])),
                min_size=13, max_size=13))
def test_states_are_checked(v):
    why = odometry_problem(_Odo(tuple(v)))
    finite = all(map(math.isfinite, v))
    unit = finite and abs(sum(x * x for x in v[3:7]) - 1.0) <= 1e-3
    near = finite and math.hypot(*v[:3]) <= MAX_POSITION_M
    assert (why is None) == (finite and unit and near)
    assert why is None or why == ("out_of_range" if finite else "not_finite")


@pytest.fixture(scope="module")
def armed_vehicle():
    """A real vehicle object (its sockets on 127.0.0.1), armed at step 0 of a lockstep flight,
    and the controller's socket that talks to it."""
    flight = prepare(Mission(Sine(), duration_s=5.0, name="prop"))
    v = Vehicle(flight, VehicleConfig(parse_address("udpin:127.0.0.1:0"), None))
    ctl = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    ctl.bind(("127.0.0.1", 0))
    ctl.settimeout(5.0)
    v.link.peer = ctl.getsockname()
    v.commander.arm_disarm(1.0, 0.0)
    yield v, ctl
    v.close()
    ctl.close()




@settings(max_examples=250, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(ANY_BYTES)
def test_any_datagram_leaves_the_vehicle_as_it_was_unless_valid(armed_vehicle, data):
    """Any bytes over real UDP into a real armed vehicle: nothing raises; a refused datagram
    (counted once) changes no state; a changed state comes only from a frame nothing refused."""
    v, ctl = armed_vehicle
    before = vehicle_state(v)
    ctl.sendto(data, v.link.local)
    got: list = []
    count = {"frame": 0, "message": 0}

    def consumed() -> bool:
        r0 = v.rejected.total
        msgs = v.link.poll()
        r1 = v.rejected.total
        for m, addr in msgs:
            v._handle(v.link, m, addr)
        count["frame"] += r1 - r0
        count["message"] += v.rejected.total - r1
        got.extend(msgs)
        return bool(got) or count["frame"] > 0

    wait_for(consumed, 5.0, "the vehicle receiving the datagram", poll_s=0.001)
    assert count["frame"] <= 1 and (got or count["frame"] == 1)
    accepted = len(got) - count["message"]
    if accepted == 0:
        assert vehicle_state(v) == before
    drop_held_answer(v)  # stay at step 0, armed, for the next example
    if not v.sim.armed:
        v.commander.arm_disarm(1.0, 0.0)


# the lockstep mission both fuzzers fly: 5 s (the datagrams' burst was over by step 404-531 at 1x, the commands' by
# step ~200 at 2x; it was 8 s), ending in hold (a land and COM_DISARM_LAND fly ~3.5 s more, read by no test here;
# trace.csv, the mission's steps, is the same byte for byte either way)
FUZZED = Mission(Sine(), duration_s=5.0, name="fuzz", end_action="hold")


@pytest.fixture
def undisturbed(tmp_path):
    """:data:`FUZZED` flown with nobody else speaking: the run, and its directory (trace.csv). Flown offline: a
    lockstep session's trace.csv is its offline twin's to the byte (tests/test_sitl.py); a session of its own
    once, shared by the two tests below, which it then kept on one worker."""
    out = tmp_path / "ref"
    return simulate(FUZZED, out=out, plots=False), out


def test_fuzz_during_a_lockstep_mission(undisturbed, tmp_path):
    """Up to 30 000 hostile datagrams from 64 sources into the vehicle's controller link while it
    flies a lockstep mission: the trace is the undisturbed run's byte for byte, both
    processes stay up, and the refusals add up to what was sent (the benchmark sends 10^6)."""
    mission, (ref, ref_dir) = FUZZED, undisturbed
    assert ref.outcome == "completed" and ref.summary["link"]["rejected"] == {}
    # at real time's pace (the lockstep clock paced, not slowed: the trace is the same), and no more sent once three
    # quarters of it has flown: at 2x, with two busy loops on the cores, the flight ended first; at 1x, in a loaded
    # suite, 30 000 took longer than the flight (the vehicle gone before the burst was read: 2.1 s beside two busy
    # loops alone)
    f = fly_fuzzed(mission, tmp_path / "fuzz", FUZZ_DATAGRAMS, speed=1.0, until_step=3 * mission.steps // 4)
    assert f.flown < mission.steps, "the mission ended before the fuzz did: fly longer"
    assert f.sent >= 5_000, f"only {f.sent} sent while three quarters of the flight flew"
    s = f.run.summary
    assert s["outcome"] == "completed" and s["sitl"]["died"] is None
    assert s["sitl"]["vehicle_exit"] == s["sitl"]["controller_exit"] == "exited with status 0"
    assert (tmp_path / "fuzz" / "trace.csv").read_bytes() == (ref_dir / "trace.csv").read_bytes()
    assert f.drops == 0, f"the kernel dropped {f.drops} datagrams: the count cannot add up"
    link = s["link"]
    by_vehicle = link["rejected_by"]["vehicle"]
    assert sum(by_vehicle.values()) - link["rejected_from_peer"]["vehicle"] == f.sent <= FUZZ_DATAGRAMS
    for reason, least in f.fuzz.expected().items():
        assert by_vehicle.get(reason, 0) >= least, (reason, by_vehicle, f.fuzz.sent)
    assert "rate_limited" not in by_vehicle
    assert link["rejected_by"]["controller"] == {}
    assert any(t.startswith("rejected ") for t in f.texts), f.texts[:5]


def test_an_outage_of_the_first_tick_is_a_blackout_from_the_flights_start() -> None:
    """The flood test's model of a disturbed run (tests/sitlkit.trace_blackouts): a first tick no command answered
    (a vehicle stalled at its start: its trace's first row at 8 ms) is a blackout from 0 s, not from -2 ms, which the
    mission's [link] refuses (a loaded suite's flood test failed so, its flights both fine)."""
    trace = {"t": [0.008, 0.012, 0.016], "state_age_s": [0.004, 0.008, 0.008]}
    assert trace_blackouts(trace, 250.0) == [[0.0, 0.002]]
    trace = {"t": [0.004, 0.008, 0.016, 0.020], "state_age_s": [0.004, 0.004, 0.008, 0.004]}
    assert trace_blackouts(trace, 250.0) == [[0.01, 0.004]]  # tick 3's state, lost: from half a period before it


def test_a_flood_from_another_source_is_shed_and_the_flight_holds(tmp_path):
    """Real time, another source at 20x the controller's rate (5000 datagrams/s) during the
    whole flight: the flight completes with its RMS within 10 % of an undisturbed run's, the
    vehicle sheds and counts the excess, and none of it reaches the controller.

    The share of steps that miss their deadline (the issue's <= 1 %) is a timing figure of
    this machine, measured by benchmarks/flood.py, not asserted here. The robust mission, as
    in the benchmark: its RMS (centimetres) is set by the physics, not by real-time jitter."""
    # 3 s of each (a real-time run costs its length: it was 5 s and a landing nobody reads), ending in hold; measured
    # with both cores busy, the flooded run within 1.5 % of its reference, each within 4 % of offline
    mission = load_mission(MISSION_DIR / "robust.toml").with_overrides(duration_s=3.0, name="flood",
                                                                       end_action="hold")
    ref, _ = fly_flooded(mission, tmp_path / "ref", 0)
    run, flood = fly_flooded(mission, tmp_path / "flood", 20)
    assert ref.outcome == run.outcome == "completed" and flood is not None
    assert flood.sent >= 0.9 * 20 * 250 * flood.elapsed_s
    # the host's stalls (docs/sitl.md, "Stalls"), listed, explain each outage either trace shows
    stalled = False
    for r in (ref, run):
        stalls = r.summary["timing"]["stalls"]
        assert unexplained_outages(r.trace, stalls) == {"rows": [], "stalls": []}
        # a run the machine disturbed (a stall, or more than 1 % of the controller's ticks skipped for waking a
        # period late: a loaded CI run's reference skipped 46 of 1250 and flew 0.92 of offline, its flood run
        # none and 1.02) flies as offline through the outages it flew does (the ticks no command in force
        # answered), within the jitter of a loaded machine (0.88 to 1.10 of it with both cores busy and the suite
        # running); through its listed stalls alone, which model neither a slowed catch-up nor skipped ticks, until the
        # third wave's forty-second session
        if stalls["count"] or r.summary["timing"]["overruns"] > 0.01 * mission.duration_s * mission.rate_hz:
            stalled = True
            outages = trace_blackouts(r.trace, mission.rate_hz)
            offline = simulate(mission, plots=False, link={"blackouts": outages})
            ages = Counter(int(a * 1e3 + 0.5) for a in r.trace["state_age_s"])  # ms: rows (a sustained delay too)
            assert abs(r.rms / offline.rms - 1.0) <= 0.20, (r.rms, offline.rms, stalls, outages, sorted(ages.items()),
                                                              r.summary["timing"])
    if not stalled:  # the machine gave both real time: the flood is all that differs
        assert abs(run.rms / ref.rms - 1.0) <= 0.10, (run.rms, ref.rms)
    by = run.summary["link"]["rejected_by"]
    assert by["vehicle"].get("rate_limited", 0) > 0 and by["vehicle"].get("sender", 0) > 0
    assert by["controller"] == {}  # the flood never reached it


def test_valid_frames_of_every_message_id_from_strangers_and_a_gcs_change_nothing(undisturbed, tmp_path):
    """The command surface (issue 11; benchmarks/fuzz.py --commands sends 10^5): 3000 valid
    pymavlink frames, message ids of the whole common dialect in turn and commands the vehicle
    acts on, every field random or extreme, from strangers to the controller link and from the
    ground station to the GCS link (never a valid ARM_DISARM), during a lockstep mission: the
    trace is the undisturbed run's byte for byte, every stranger's frame is refused and every
    GCS frame the vehicle handles is refused or answered, and no safety policy is violated."""
    fuzz = benchmark_module("fuzz")  # the benchmark's fuzzer: one copy of it
    command_checks, fly_commands = fuzz.command_checks, fuzz.fly_commands

    mission, (ref, ref_dir) = FUZZED, undisturbed
    assert ref.outcome == "completed"
    f = fly_commands(mission, tmp_path / "cmd", 3000, speed=2.0)
    res = command_checks(f, ref_dir / "trace.csv", mission.steps)
    assert res["done_before_mission_end"], "the mission ended before the fuzz did: fly longer"
    assert {c.msgname for c in mavlink.mavlink_map.values()} <= set(f.fuzz.sent), "not every message id was sent"
    assert res["outcome"] == "completed" and res["trace_identical"], res
    assert res["kernel_drops"] == 0 and res["adds_up"], res
    assert res["answered"] > 0 and res["bad_number"] > 0 and res["refused_by_reason"].get("not_authorised"), res
    assert res["policies_checked"] > 0 and res["policies_violated"] == [], f.run.summary["policies"]
    assert res["controller_refused"] == {}
