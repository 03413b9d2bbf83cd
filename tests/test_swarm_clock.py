"""Covers bridge.nodes.vehicle.gate, bridge.session.fleet and bridge.swarm: a lockstep SITL fleet's shared step clock.

The gate alone (real UDP sockets on 127.0.0.1, in this process): no vehicle flies step k before every other one has
flown step k - 1 (its answer held meanwhile), a contact is judged as the offline loop judges it (its text, its
pair), a vehicle that left stays an obstacle where it said (one flying on, on the wall clock, is nowhere), one silent
too long is taken as gone, one waiting for its turn on the fleet's one radio says its word again; the trace judge
with where each vehicle stayed.
Whole fleets (real ``bsst vehicle`` and ``bsst controller`` processes, free ports): two runs of one fleet write
the same ``trace.csv`` bytes, and two vehicles that touch both end ``collision`` at the offline loop's step, their
traces the offline ones (≤ 1e-4 m), the separation and its closest approaches the offline fleet's.
"""

from __future__ import annotations

import json
import math
import socket
import time
from pathlib import Path

import numpy as np
import pytest

from bridge.cli import main
from bridge.cli.runreport import report_fleet
from bridge.link.radio import make_radio_file
from bridge.link.turns import TurnRadio
from bridge.nodes.vehicle import gate as gatemod
from bridge.nodes.vehicle.clock import Answer, Clock, ClockState, Trigger
from bridge.nodes.vehicle.gate import Gate, GateConfig, resting, say_lost
from bridge.record.separation import CONTINUED, Watch, judge_traces
from bridge.session.children import free_udp_port
from bridge.swarm import FleetRun, simulate, sitl
from params import ConfigError
from tests.test_swarm_sitl import short_sine
from tests.waiting import wait_for

pytestmark = pytest.mark.process  # starts processes, opens sockets

ROOT = Path(__file__).resolve().parents[1]
TOUCH = ROOT / "examples" / "swarm-touch.toml"
RATE = 250.0
ANSWER = Answer((0.5, 0.5, 0.5, 0.5), 1.0)


def gates(n: int, radii: float = 0.3) -> list[tuple[Gate, Clock, list]]:
    """n gates of one fleet, each with a lockstep clock engaged and a position the test moves."""
    ports, out = tuple(free_udp_port() for _ in range(n)), []
    for i in range(n):
        clock = Clock(False, 1000.0, 1.0, 0.0)
        clock.fire(Trigger.ENGAGE)
        where = [(0.0, 2.0 * i, 1.0)]
        cfg = GateConfig(i, tuple(range(1, n + 1)), (radii,) * n, ports)
        out.append((Gate(cfg, clock, lambda w=where: w[0], RATE), clock, where))
    return out


def at(g: Gate, clock: Clock, k: int) -> None:
    """Step k - 1 flown: the state of step k out (the others told), and its answer come."""
    g.after_step(k, alive=True)
    clock.hold(ANSWER)


def cleared(g: Gate) -> str | None:
    """Wait until step k may be flown (None) or the flight ended in a contact (its text)."""
    told: list[str] = []
    wait_for(lambda: g.clear(told.append) or g.judged == g.step, 10, "every other vehicle's word at the gate")
    return told[0] if told else None


def test_no_vehicle_flies_a_step_before_every_other_has_flown_the_one_before() -> None:
    (a, ca, _), (b, cb, _), (c, cc, _) = fleet = gates(3)
    try:
        at(a, ca, 1)
        at(b, cb, 1)
        assert not a.clear(pytest.fail) and ca.state is ClockState.GATED  # vehicle 3 has not flown step 0
        assert ca.answer == ANSWER  # held while gated
        at(c, cc, 1)
        assert [cleared(g) for g, _, _ in fleet] == [None, None, None]
        assert ca.state is ClockState.ANSWERED and ca.take() == ANSWER
        at(a, ca, 2)  # one step ahead: a's word for step 2 comes before b and c have flown step 1
        assert not a.clear(pytest.fail)
        for g, clock in ((b, cb), (c, cc)):
            clock.take()
            at(g, clock, 2)
        assert [cleared(g) for g, _, _ in fleet] == [None, None, None]
        assert a.stats()["steps"] == 2 and a.stats()["contact"] is None
    finally:
        for g, _, _ in fleet:
            g.close()


def test_a_contact_is_judged_as_the_offline_loop_judges_it_and_a_vehicle_gone_stays_an_obstacle() -> None:
    (a, ca, wa), (b, cb, wb), (c, cc, wc) = fleet = gates(3)
    try:
        wa[0], wb[0], wc[0] = (0.0, 0.0, 1.0), (0.5, 0.0, 1.0), (0.0, 5.0, 1.0)  # 1 and 2 overlap; 3 clear
        for g, clock, _ in fleet:
            at(g, clock, 7)
        told = [cleared(g) for g, _, _ in fleet]
        watch = Watch([1, 2, 3], [0.3] * 3, 0.5)
        offline = {i: why for x, y, why in watch.check(7 / RATE, [wa[0], wb[0], wc[0]]) for i in (x, y)}
        assert told == [offline[0], offline[1], None] and "touched at t=0.028 s" in told[0]
        assert a.stats()["contact"]["with"] == 2 and b.stats()["contact"]["with"] == 1
        assert a.stats()["left"] == {"step": 7, "position": [0.0, 0.0, 1.0]}  # it stays there, an obstacle
        cc.take()
        wc[0] = (0.0, 0.3, 1.0)  # 3 flies into where 1 and 2 stayed
        at(c, cc, 8)
        assert "vehicles 2 and 3 touched" in cleared(c)  # the last pair in id order, as offline
    finally:
        for g, _, _ in fleet:
            g.close()


def test_a_vehicle_disarmed_in_the_air_stays_on_the_ground_below_not_in_the_air() -> None:
    """A ground station's disarm in flight: lockstep time stands still for that vehicle (its plant never flies the
    fall), so it leaves the shared clock to lie on the ground below where it was (:func:`resting`), as the offline
    fleet's vehicle falls and lies there; another flying through where it hung passes. (Under load a vehicle
    disarmed 0.65 m up once hung there, and its neighbour's circle ran into it: both ended ``collision``.)"""
    assert resting((1.0, 0.0, 2.0, 0.0, 0.65, -0.1, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0), armed=False) == (1.0, 2.0, 0.0)
    assert resting((1.0, 0.0, 2.0, 0.0, 0.65, -0.1, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0), armed=True) == (1.0, 2.0, 0.65)
    ports = (free_udp_port(), free_udp_port())
    fleet = []
    for i in range(2):
        clock = Clock(False, 1000.0, 1.0, 0.0)
        clock.fire(Trigger.ENGAGE)
        where, armed = [(0.0, 0.8 * i, 1.0)], [True]

        def rest(w: list = where, a: list = armed) -> tuple[float, float, float]:
            x, y, z = w[0]
            return resting((x, 0.0, y, 0.0, z, *[0.0] * 7), a[0])

        cfg = GateConfig(i, (1, 2), (0.3, 0.3), ports)
        fleet.append((Gate(cfg, clock, lambda w=where: w[0], RATE, None, rest), clock, where, armed))
    (a, ca, wa, arm_a), (b, cb, wb, _) = fleet
    try:
        for g, clock, _, _ in fleet:
            at(g, clock, 3)
        assert [cleared(g) for g, _, _, _ in fleet] == [None, None]
        arm_a[0] = False
        ca.fire(Trigger.DISARM)  # disarmed by command, 1 m up: idle
        a.over(3)
        assert a.stats()["left"] == {"step": 3, "position": [0.0, 0.0, 0.0]}
        cb.take()
        wb[0] = (0.0, 0.3, 1.0)  # through where 1 hung: 0.3 m off, 1 m above it on the ground
        at(b, cb, 4)
        assert cleared(b) is None
    finally:
        for g, _, _, _ in fleet:
            g.close()


def test_a_vehicle_its_plant_ended_in_the_air_stays_there_as_offline() -> None:
    """Diverged 2 m up (its plant's verdict, which disarms it): the offline fleet's vehicle stays where it ended, an
    obstacle there, so the lockstep fleet's does too (it was put on the ground below like a disarmed one, and a
    neighbour that flew through where it hung passed: a collision offline, none in SITL)."""
    ports = (free_udp_port(), free_udp_port())
    fleet = []
    for i in range(2):
        clock = Clock(False, 1000.0, 1.0, 0.0)
        clock.fire(Trigger.ENGAGE)
        where = [(0.0, 0.8 * i, 2.0)]
        cfg = GateConfig(i, (1, 2), (0.3, 0.3), ports)
        fleet.append((Gate(cfg, clock, lambda w=where: w[0], RATE, None,
                           lambda w=where: resting((w[0][0], 0.0, w[0][1], 0.0, w[0][2], *[0.0] * 7), False)),
                      clock, where))
    (a, ca, wa), (b, cb, wb) = fleet
    try:
        for g, clock, _ in fleet:
            at(g, clock, 3)
        assert [cleared(g) for g, _, _ in fleet] == [None, None]
        ca.take()
        a.after_step(4, alive=False)  # step 3 flown: its plant ended the flight there (disarmed by it)
        assert a.stats()["left"] == {"step": 4, "position": [0.0, 0.0, 2.0]}
        cb.take()
        wb[0] = (0.0, 0.3, 2.0)  # through where 1 hangs
        at(b, cb, 4)
        assert "vehicles 1 and 2 touched" in cleared(b)
    finally:
        for g, _, _ in fleet:
            g.close()


def test_a_vehicle_flying_on_on_the_wall_clock_is_no_obstacle_where_it_left() -> None:
    """A ground station's mode (HOLD, TAKEOFF, ...) takes a vehicle off the shared clock, flying on on the wall clock:
    it is not where it left for long, so the others' gates take it as nowhere (the fleet judges its record after,
    bridge.record.wallclock), where before it stood there, an obstacle: a neighbour flying through the place it left
    ended ``collision`` with a vehicle no longer there. Its own word on where it left stays in its stats."""
    (a, ca, wa), (b, cb, wb) = fleet = gates(2)
    try:
        for g, clock, _ in fleet:
            at(g, clock, 3)
        assert [cleared(g) for g, _, _ in fleet] == [None, None]
        ca.fire(Trigger.GROUND)  # HOLD set by a ground station: flown by the vehicle on the wall clock
        a.over(3)
        assert a.stats()["left"] == {"step": 3, "position": [0.0, 0.0, 1.0]}
        cb.take()
        wb[0] = wa[0]  # through where 1 left the shared clock
        at(b, cb, 4)
        assert cleared(b) is None
        assert all(math.isnan(v) for v in b.gone[0][1]), b.gone
    finally:
        for g, _, _ in fleet:
            g.close()


def test_a_vehicle_waiting_for_its_turn_on_one_radio_says_its_word_again(tmp_path: Path) -> None:
    """A vehicle's word for step 1 goes out before the other's gate is bound. Step 1's order on the fleet's radio
    is the other vehicle, then this one: it has every position but waits for the other's turn, while the other
    waits for its word. Waiting for a turn, it says its word again every RESEND_S, so both fly, in turn order."""
    f = tmp_path / "radio"
    make_radio_file(f, 2)
    ports = (free_udp_port(), free_udp_port())

    def gate(i: int) -> tuple[Gate, Clock]:
        clock = Clock(False, 1000.0, 1.0, 0.0)
        clock.fire(Trigger.ENGAGE)
        cfg = GateConfig(i, (1, 2), (0.3, 0.3), ports, str(f))
        return Gate(cfg, clock, lambda: (0.0, 2.0 * i, 1.0), RATE, TurnRadio(f, "up", 1000.0, 0.05, i)), clock

    a, ca = gate(0)
    a.took(0)  # (its turn of step 0, the first; then step 0 flown)
    at(a, ca, 1)  # its word for step 1 goes nowhere: the other gate is not bound yet
    b, cb = gate(1)
    try:
        b.took(0)
        at(b, cb, 1)
        assert not a.clear(pytest.fail, 1) and ca.state is ClockState.GATED and a.judged == 1  # b's turn first
        assert not b.clear(pytest.fail, 1) and b.judged < 1  # a's word not heard
        flown: list[str] = []

        def serve(g: Gate, name: str) -> None:
            if g.clock.state is ClockState.GATED:
                g.serve([], time.monotonic() + 0.02, pytest.fail, pytest.fail, lambda: (g.took(1), flown.append(name)))

        wait_for(lambda: serve(b, "b") or serve(a, "a") or len(flown) == 2, 10, "both vehicles' turns of step 1")
        assert flown == ["b", "a"]
    finally:
        a.close()
        b.close()


def test_a_word_from_anywhere_but_the_vehicles_own_gate_port_is_not_heard() -> None:
    (a, ca, _), (b, cb, wb) = fleet = gates(2)
    stranger = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        at(a, ca, 1)
        word = gatemod._WIRE.pack(gatemod._MAGIC, gatemod.AT, 1, 1, *wb[0], *wb[0])  # vehicle 2's word, forged
        stranger.sendto(word, ("127.0.0.1", a.cfg.ports[0]))  # (on loopback, queued before sendto returns)
        assert not a.clear(pytest.fail) and not a.complete()
        at(b, cb, 1)
        assert cleared(a) is None  # vehicle 2's own word
    finally:
        stranger.close()
        for g, _, _ in fleet:
            g.close()


def test_a_vehicle_silent_too_long_is_taken_as_gone_and_said(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(gatemod, "SILENT_S", 0.2)
    (a, ca, _), (b, _, _) = gates(2)
    try:
        b.close()
        at(a, ca, 1)
        assert cleared(a) is None
        assert a.stats()["dropped"] and "vehicle 2 silent" in a.stats()["dropped"][0]
    finally:
        a.close()


def test_a_vehicle_whose_process_ended_is_taken_as_gone_at_once_where_it_was_last(tmp_path: Path) -> None:
    """Its fleet's word from its gate port (say_lost) drops it at once, where it was last heard, said why; one
    that left stays where it said; the fleet then holds its port; on the fleet's one radio it takes no turn after
    the ones it took (nobody waits for it there)."""
    (a, ca, _), (b, cb, wb), (c, cc, _) = fleet = gates(3)
    held = []
    try:
        for k in (1, 2):
            for g, clock, _ in fleet:
                at(g, clock, k)
            assert [cleared(g) for g, _, _ in fleet] == [None] * 3
            for _, clock, _ in fleet:
                clock.take()  # (the step flown)
        at(a, ca, 3)
        at(c, cc, 3)
        b.close()  # vehicle 2's process ends at step 2, having flown step 1: it was at wb there
        held.append(say_lost(b.cfg))
        assert held[-1] is not None and cleared(a) is None and a._where(1, 3) == wb[0]
        assert a.stats()["dropped"] == ["vehicle 2 ended (its process gone, said by the fleet) at step 3: taken as "
                                        "gone where it was last"]
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as other, pytest.raises(OSError):
            other.bind(("127.0.0.1", b.cfg.ports[1]))  # (nobody else speaks for vehicle 2 now)
        c.leave()  # vehicle 3 leaves where it is, then its process ends: where it said, nothing dropped
        c.close()
        held.append(say_lost(c.cfg))
        wait_for(lambda: a.poll() or 2 in a.gone, 10, "vehicle 3's word")
        assert len(a.stats()["dropped"]) == 1 and a._where(2, 9) == c.pos
    finally:
        for g, _, _ in fleet:
            g.close()
        for sock in held:
            sock.close()
    radio = tmp_path / "radio"
    make_radio_file(radio, 2)
    for direction, k in (("up", 7), ("down", 6)):  # user 1: its vehicle took step 7's turn, its controller 6's
        TurnRadio(radio, direction, 1000.0, 0.1, 1).took(k)
    sock = say_lost(GateConfig(1, (1, 2), (0.3, 0.3), (free_udp_port(), free_udp_port()), str(radio)))
    assert sock is not None
    sock.close()
    assert TurnRadio(radio, "up", 1000.0, 0.1, 0).rows()[1][2] == 7  # it leaves from step 7


def test_a_frozen_vehicle_is_taken_as_gone_as_an_ended_one_and_said_frozen() -> None:
    """The fleet's FROZEN word (say_lost frozen: its session killed it, its controller hearing nothing from it) drops
    it as the LOST word does, at once, where it was last heard; the record says it froze, not that it ended
    (summary.json's sitl.gate dropped: docs/swarm.md). The two words are read in one place, alike but for that."""
    (a, ca, _), (b, cb, wb) = fleet = gates(2)
    held = []
    try:
        for g, clock, _ in fleet:
            at(g, clock, 1)
        assert [cleared(g) for g, _, _ in fleet] == [None, None]
        for _, clock, _ in fleet:
            clock.take()
        at(a, ca, 2)
        b.close()  # vehicle 2 killed frozen at step 2, having flown step 1: it was at wb there
        held.append(say_lost(b.cfg, frozen=True))
        assert held[-1] is not None and cleared(a) is None and a._where(1, 2) == wb[0]
        assert a.stats()["dropped"] == ["vehicle 2 frozen (its controller heard nothing from it: killed, said by the "
                                        "fleet) at step 2: taken as gone where it was last"]
    finally:
        for g, _, _ in fleet:
            g.close()
        for sock in held:
            sock.close()


def test_a_bad_gate_file_is_named(tmp_path: Path) -> None:
    f = tmp_path / "gate.json"
    f.write_text('{"index": 3, "ids": [1, 2], "radii": [0.3, 0.3], "ports": [5000, 5001]}')
    with pytest.raises(ConfigError, match=r"--gate .*gate.json: expected index 0..N-1"):
        GateConfig.load(f)
    f.write_text("nope")
    with pytest.raises(ConfigError, match="not a fleet gate file"):
        GateConfig.load(f)


def test_a_gate_with_the_wall_clock_or_on_a_taken_port_is_refused(tmp_path: Path, capsys) -> None:
    f = tmp_path / "gate.json"
    taken = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    taken.bind(("127.0.0.1", 0))
    try:
        cfg = GateConfig(0, (1, 2), (0.3, 0.3), (taken.getsockname()[1], 9))
        cfg.dump(f)
        assert main(["vehicle", "--gate", str(f), "--realtime"]) == 2
        assert "--gate with --realtime" in capsys.readouterr().err
        with pytest.raises(ConfigError, match="--gate: cannot bind 127.0.0.1"):
            Gate(cfg, Clock(False, 1000.0, 1.0, 0.0), lambda: (0.0, 0.0, 0.0), RATE)
    finally:
        taken.close()


def test_the_trace_judge_keeps_each_vehicle_where_it_stayed() -> None:
    """Where each stayed (the shared clock's word) is the world after the last row's step: a contact there is found
    at that step, as the offline loop finds it; without it (real time) the flights are said to have gone on."""
    one = {"t": np.array([0.0, 0.004]), "x": np.zeros(2), "y": np.zeros(2), "z": np.ones(2)}
    two = {**one, "y": np.full(2, 1.0)}
    watch = Watch([1, 2], [0.3, 0.3], 0.5)
    assert judge_traces(watch, [one, two], RATE) == {}
    found = judge_traces(Watch([1, 2], [0.3, 0.3], 0.5), [one, two], RATE, [(0.0, 0.0, 1.0), (0.0, 0.5, 1.0)])
    assert found[0]["step"] == 2 and found[1]["with"] == 1 and "continued" not in found[0]
    far = {**one, "y": np.array([1.0, 0.5])}
    assert judge_traces(Watch([1, 2], [0.3, 0.3], 0.5), [one, far], RATE)[0]["continued"] == CONTINUED
    # a flight over (diverged 1 m up at step 1, staying there) touched at step 4 by one flying on: an obstacle only,
    # its own outcome kept, as the offline loop tells a contact to live flights only (SITL made both collision)
    ended = {"t": np.array([0.0]), "x": np.zeros(1), "y": np.zeros(1), "z": np.ones(1)}
    on = {"t": np.arange(5) / RATE, "x": np.zeros(5), "y": np.array([2.0, 1.5, 1.0, 0.5, 0.0]), "z": np.ones(5)}
    found = judge_traces(Watch([1, 2], [0.3, 0.3], 0.5), [ended, on], RATE, [(0.0, 0.0, 1.0), (0.0, 0.0, 1.0)])
    assert list(found) == [1] and found[1]["with"] == 1 and found[1]["step"] == 3, found


# -- whole fleets ------------------------------------------------------------------------------------------
def test_two_flights_of_one_lockstep_fleet_write_the_same_traces(tmp_path: Path) -> None:
    mission = short_sine(tmp_path, 1.0)
    runs = [sitl(mission, vehicles=3, formation="line:2", instance=None, out=tmp_path / f"run{n}", plots=False)
            for n in (1, 2)]
    for run in runs:
        assert isinstance(run, FleetRun) and run.outcome == "completed", run.summary
        assert run.summary["sitl"]["shared_clock"] is True
        gate = run.summary["sitl"]["gate"]  # the mission's 250 steps and its landing's, on the shared clock
        for g, r in zip(gate.values(), run.runs):  # (it leaves on the ground, disarmed by its landing)
            assert g["dropped"] == [] and g["left"]["step"] == 250 + r.summary["end"]["rows"] == g["steps"] + 1, g
            assert len(r.after) == r.summary["end"]["rows"] > 250 and g["left"]["position"][2] == 0.0
    for i in (1, 2, 3):
        a, b = ((tmp_path / f"run{n}" / f"vehicle-{i}" / "trace.csv").read_bytes() for n in (1, 2))
        assert a == b and a.count(b"\n") == 251


def test_a_touch_ends_both_flights_at_the_offline_step_as_offline(tmp_path: Path, capsys) -> None:
    run = sitl(TOUCH, instance=None, out=tmp_path / "touch", plots=False)
    off = simulate(TOUCH, plots=False)
    assert isinstance(run, FleetRun) and run.outcome == "collision" == off.outcome
    step = len(off.runs[0].trace["t"])  # the offline flights end at the step they touch
    for v, other, a, b in zip(run.summary["vehicles"], (2, 1), run.runs, off.runs):
        assert v["outcome"] == "collision" and not v["ok"]
        assert v["contact"]["step"] == step and v["contact"]["with"] == other and "continued" not in v["contact"]
        assert len(a.trace["t"]) == step == len(b.trace["t"])  # the flight ended there
        assert max(float(np.max(np.abs(a.trace[c] - b.trace[c]))) for c in ("x", "y", "z")) <= 1e-4
        assert a.summary["outcome"] == "collision" and a.summary["ended_by"]["who"] == "plant"
        kinds = [(e["kind"], e["source"]) for e in a.summary["events"]]
        # said as it happened, before its controller gave up on the halted clock; and, disarmed at the touch,
        # no landing to wait for (the vehicle said its events only as it exited, after an 8 s wait: a bug)
        assert kinds.index(("disarmed", "vehicle")) < kinds.index(("collision", "controller")), kinds  # (its EVENT)
        assert ("waiting", "session") not in kinds, kinds
    assert "note" not in run.summary["sitl"]
    assert run.summary["separation"]["pairs"] == off.summary["separation"]["pairs"]
    assert run.summary["policies"][0] == off.summary["policies"][0] and not run.summary["policies"][0]["ok"]
    own = json.loads((tmp_path / "touch" / "vehicle-1" / "summary.json").read_text())
    assert own["outcome"] == "collision" and own["sitl"]["gate"]["contact"]["step"] == step
    assert report_fleet(run, "sitl") == 1
    assert f"vehicle 2: collision (touched vehicle 1 at step {step}, t=6.352 s; both flights ended there)" in \
        capsys.readouterr().err


def test_a_landing_onto_another_vehicle_ends_both_at_the_offline_step_as_offline(tmp_path: Path) -> None:
    """examples/swarm-stacked.toml in lockstep: the vehicles stay on the shared clock through their end landings
    (they left it at the mission's end, unjudged after), so vehicle 2 landing onto vehicle 1 is the offline contact,
    at its step: both ``collision``, their landings, separation, closest approach and verdict the offline fleet's."""
    stacked = ROOT / "examples" / "swarm-stacked.toml"
    run = sitl(stacked, instance=None, out=tmp_path / "stacked", plots=False)
    off = simulate(stacked, plots=False)
    assert isinstance(run, FleetRun) and run.outcome == "collision" == off.outcome
    for v, other, a, b in zip(run.summary["vehicles"], (2, 1), run.runs, off.runs):
        assert v["outcome"] == "collision" and v["contact"]["step"] == 2683 and v["contact"]["with"] == other, v
        assert a.summary["end"] == b.summary["end"] and a.summary["ended_by"] == b.summary["ended_by"]
        assert max(float(np.max(np.abs(a.trace[c] - b.trace[c]))) for c in ("x", "y", "z")) == 0.0
    assert run.summary["separation"] == off.summary["separation"]
    assert run.summary["policies"] == off.summary["policies"]
