"""Covers bridge.autopilot.batterywatch, plant.battery and bridge.batch.engine: PX4's battery levels (BAT_LOW_THR,
BAT_CRIT_THR, BAT_EMERGEN_THR), its battery failsafe (COM_LOW_BAT_ACT) and pre-arm battery check as the vehicle
(bridge.autopilot.simvehicle) flies them offline, a pack's start charge, and the batch engine's refusal
(docs/weather.md, "Battery"). The same flight in lockstep: tests/test_sitl.py; on a ground station's link:
tests/test_inject.py."""

from __future__ import annotations

from pathlib import Path

import pytest

from bridge import simulate
from bridge.autopilot.batterywatch import BatteryWatch
from bridge.autopilot.simvehicle import FAILSAFE
from bridge.batch.scope import flights_problem
from bridge.core.flight import prepare
from params import ConfigError, Table
from plant.effects import effects_from_table
from tests.plans import battery_mission


def test_the_levels_are_judged_worst_first_and_each_said_once_in_order_with_its_action() -> None:
    w = BatteryWatch(action=3)
    assert [w.level(r) for r in (0.5, 0.15, 0.149, 0.069, 0.049, 0.0)] == [0, 0, 1, 2, 3, 3]
    assert w.passed(0.2) == []
    said = w.passed(0.06)  # low and critical at once: both said, in order, critical's Return with it
    assert [(name, act) for name, _, act in said] == [("low", None), ("critical", "return")]
    assert said[1][1] == "critical: 6.0 % left (BAT_CRIT_THR = 7 %)"
    assert w.passed(0.055) == [] and [(n, a) for n, _, a in w.passed(0.04)] == [("emergency", "land")]
    assert w.passed(0.5) == []  # said once a flight: a charge read higher again says nothing
    assert [a for _, _, a in BatteryWatch(action=2).passed(0.01)] == [None, "land", None]
    assert [a for _, _, a in BatteryWatch(action=0).passed(0.01)] == [None, None, None]
    assert BatteryWatch().arming_refusal(0.08) is None  # low: PX4 only warns
    assert BatteryWatch().arming_refusal(0.06) == "battery critical: 6.0 % left (BAT_CRIT_THR = 7 %)"
    crossed = BatteryWatch(low=0.12, critical=0.25)  # levels out of order: the worst one below which it is
    assert crossed.level(0.2) == 2 and crossed.arming_refusal(0.2) is not None


@pytest.mark.parametrize("action, outcome, then", [(0, "completed", None), (2, "failsafe", "land"),
                                                   (3, "failsafe", "return")])
def test_the_x500_below_its_critical_level_flies_com_low_bat_act(tmp_path: Path, action: int, outcome: str,
                                                                  then: str | None) -> None:
    """The x500 from 8 % of its pack, PX4's levels: low at once (a warning), critical (7 %) at 7.796 s on its way
    north; COM_LOW_BAT_ACT 0 flies on (warnings only), 2 lands there, 3 returns; the failsafe ends the run (outcome
    ``failsafe``, as any)."""
    run = simulate(battery_mission(tmp_path, 8.0), plots=False, params={"COM_LOW_BAT_ACT": action})
    s = run.summary
    assert s["outcome"] == outcome, s["ended_by"]
    said = [(e["t"], e["text"]) for e in s["events"] if e["kind"] == "battery"]
    assert said[:2] == [(0.0, "low: 8.0 % left (BAT_LOW_THR = 15 %)"),
                        (7.796, "critical: 7.0 % left (BAT_CRIT_THR = 7 %)")]
    fs = [e for e in s["events"] if e["kind"] == "failsafe"]
    if then is None:
        assert not fs and run.trace["z"].max() > 2.9
        return
    assert fs[0]["text"].endswith(f"(BAT_CRIT_THR = 7 %): {then}") and "battery critical" in s["ended_by"]["how"]
    if then == "land":  # (3: Return first climbs, to 2 x 1.6 m: the cone within NAV_ACC_RAD of home)
        assert run.trace["z"][-1] == pytest.approx(0.0, abs=1e-6)  # landed, and disarmed there
        assert any(e["kind"] == "disarmed" and e["text"] == "landed: disarmed" for e in s["events"])


def test_below_the_critical_level_the_arm_is_denied_and_nothing_flies(tmp_path: Path) -> None:
    """PX4's pre-arm battery check: from 6 % (PX4's BAT_CRIT_THR 7 %) the vehicle is not armed (``denied``, ended by
    the vehicle saying why); with BAT_CRIT_THR 5 % it arms, and flies its mission (the LiPo's rest voltage holds up
    to its last few per cent)."""
    run = simulate(battery_mission(tmp_path, 6.0), plots=False)
    assert run.summary["outcome"] == "denied" and len(run.trace["t"]) == 0
    assert run.summary["ended_by"]["how"] == ("arming denied: battery critical: 6.0 % left (BAT_CRIT_THR = 7 %) "
                                             "(t=0.000 s)")
    flown = simulate(battery_mission(tmp_path, 6.0), plots=False, params={"BAT_CRIT_THR": 0.05})
    assert flown.summary["outcome"] == "completed" and flown.summary["rms_3d"] < 1e-5, flown.summary["ended_by"]


def test_the_emergency_level_lands_over_the_batterys_own_return_only(tmp_path: Path) -> None:
    """COM_LOW_BAT_ACT 3: the critical level's Return, then the emergency level's landing takes over from it; a
    failsafe of another cause (the link's) is left to fly its own action."""
    for own in (True, False):
        sim = prepare(battery_mission(tmp_path, 100.0), params={"COM_LOW_BAT_ACT": 3}).make_vehicle(armed=True)
        sim.plant.state = (3.0, 0.0, 0.0, 0.0, 2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)  # 3 m from home, 2 m up
        pack = sim.plant.battery
        if not own:
            sim.fly_failsafe("hold", "link lost", "")
        pack.used_mah = 0.94 * pack.config.capacity_mah
        sim.advance()
        assert sim.mode == FAILSAFE and (sim.events[-1].text.endswith(": return")) is own, sim.events[-1]
        pack.used_mah = 0.96 * pack.config.capacity_mah
        sim.advance()
        last = sim.events[-1]
        assert (last.kind, last.text.endswith(": land")) == (("failsafe", True) if own else ("battery", False)), last


def test_the_batch_engine_leaves_the_batterys_levels_to_the_process_engine(tmp_path: Path) -> None:
    full = prepare(battery_mission(tmp_path, 100.0))
    assert flights_problem([full]) is None  # a full pack and PX4's default action (warnings): flown in the batch
    for f in (prepare(battery_mission(tmp_path, 50.0)), prepare(battery_mission(tmp_path, 100.0),
                                                                 params={"COM_LOW_BAT_ACT": 2})):
        assert "battery failsafe is not in the batch engine" in (flights_problem([f]) or "")


def test_a_start_charge_out_of_range_is_named() -> None:
    with pytest.raises(ConfigError) as e:
        effects_from_table(Table({"battery": True, "battery_start_pct": 0.5}, "m.toml", "effects"))
    assert str(e.value).startswith("m.toml: effects.battery_start_pct: must be in [1, 100]"), str(e.value)


def test_a_failsafe_that_took_over_at_once_is_named_with_the_one_that_ended_the_mission(tmp_path: Path) -> None:
    """An empty pack under COM_LOW_BAT_ACT 3: the critical level's Return ends the mission, and the emergency level's
    landing takes over in the same step, so Return never flew: ``ended_by`` says both, in order (it named the Return
    alone, and the vehicle landed where it was)."""
    run = simulate(battery_mission(tmp_path, 100.0), plots=False, params={"COM_LOW_BAT_ACT": 3},
                   at=("1:battery:empty",))
    fs = [e for e in run.summary["events"] if e["kind"] == "failsafe"]
    assert [e["text"].rsplit(": ", 1)[1] for e in fs] == ["return", "land"] and fs[0]["t"] == fs[1]["t"], fs
    assert run.summary["ended_by"]["how"] == (f"failsafe at t={fs[0]['t']:.3f} s: {fs[0]['text']}; "
                                              f"then at t={fs[1]['t']:.3f} s: {fs[1]['text']}")
