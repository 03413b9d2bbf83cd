"""Covers bridge.swarm, bridge.record.fleetplots and bridge.cli: several vehicles in one world, offline.

Real flights, in process: ``bsst sim --vehicles N --formation`` and missions with ``[[vehicles]]`` fly N
plants and N laws in one loop. Each vehicle flies exactly as it would alone (vehicle 1 of a fleet writes the
single vehicle's bytes), the separation policy is judged every step (a near miss exits 1, a touch ends both
vehicles ``collision``), the run directory holds one run per vehicle and the fleet's summary and plots, and a
mission of one vehicle flies through :func:`bridge.simulate` exactly as through :func:`bridge.loop.simulate`.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import pytest

import bridge
from bridge.cli import main
from bridge.core.flight import prepare
from bridge.loop import flying
from bridge.loop import simulate as simulate_one
from bridge.swarm import FleetRun, simulate
from missions import MISSION_DIR, Sine, load_mission
from missions.fleet import VehicleSpec, vehicle_mission
from params import ConfigError

ROOT = Path(__file__).resolve().parents[1]
NEAR_MISS = ROOT / "examples" / "swarm-near-miss.toml"
TOUCH = ROOT / "examples" / "swarm-touch.toml"
STACKED = ROOT / "examples" / "swarm-stacked.toml"
TAKEOVER = ROOT / "examples" / "swarm-takeover.toml"


def short_sine(tmp_path: Path, seconds: float = 3.0) -> Path:
    text = (MISSION_DIR / "sine.toml").read_text().replace("duration_s = 30.0", f"duration_s = {seconds}")
    f = tmp_path / "short.toml"
    f.write_text(text)
    return f


def test_four_in_a_line_fly_two_metres_apart_each_tracking_as_one_does(tmp_path: Path) -> None:
    run = simulate(short_sine(tmp_path), vehicles=4, formation="line:2", out=tmp_path / "run", plots=False)
    assert isinstance(run, FleetRun) and run.outcome == "completed"
    s = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert s["duration_s"] == s["mission_duration_s"] == 3.0  # flown whole: the header says no mission length
    assert [v["id"] for v in s["vehicles"]] == [1, 2, 3, 4] == [v["sysid"] for v in s["vehicles"]]
    assert all(v["outcome"] == "completed" and v["ok"] for v in s["vehicles"])
    one = s["vehicles"][0]["rms_3d"]  # vehicle 1 flies the single vehicle's bytes (the test below)
    assert all(abs(v["rms_3d"] - one) <= 0.1 * one for v in s["vehicles"]), [v["rms_3d"] for v in s["vehicles"]]
    assert [v["offset"] for v in s["vehicles"]] == [[0.0, 2.0 * i, 0.0] for i in range(4)]
    assert s["policies"] == [{"name": "separation", "ok": True}]
    sep = s["separation"]
    assert sep["min_m"] == 0.5 and len(sep["pairs"]) == 6 and all(p["ok"] for p in sep["pairs"])
    assert sep["closest_m"] == pytest.approx(2.0 - 2 * 0.315, abs=1e-3)  # neighbours, less two paper discs
    for i in range(1, 5):
        d = tmp_path / "run" / f"vehicle-{i}"
        assert {p.name for p in d.iterdir()} >= {"trace.csv", "summary.json", "mission.toml", "events.log"}
        assert json.loads((d / "summary.json").read_text())["outcome"] == "completed"
    flown = load_mission(tmp_path / "run" / "mission.toml")  # the fleet as flown reads back
    assert len(flown.vehicles) == 4 and flown.vehicles[3].offset == (0.0, 6.0, 0.0)
    assert load_mission(tmp_path / "run" / "vehicle-3" / "mission.toml").trajectory == Sine(y0=4.0)


def test_each_vehicle_flies_the_bytes_it_would_fly_alone(tmp_path: Path) -> None:
    mission = short_sine(tmp_path)
    simulate(mission, vehicles=2, formation="line:3", out=tmp_path / "fleet", plots=False)
    simulate_one(mission, out=tmp_path / "one", plots=False)
    fleet = tmp_path / "fleet"
    assert (fleet / "vehicle-1" / "trace.csv").read_bytes() == (tmp_path / "one" / "trace.csv").read_bytes()
    alone = replace(load_mission(mission), trajectory=Sine(y0=3.0), start=(0.0, 3.0, 0.0, 0.0), seed=1)
    simulate_one(alone, out=tmp_path / "two", plots=False)
    assert (fleet / "vehicle-2" / "trace.csv").read_bytes() == (tmp_path / "two" / "trace.csv").read_bytes()


def test_one_vehicle_flies_through_bridge_simulate_exactly_as_before(tmp_path: Path) -> None:
    mission = short_sine(tmp_path)
    a = bridge.simulate(mission, out=tmp_path / "a", plots=False, rate_hz=200.0)
    b = simulate_one(mission, out=tmp_path / "b", plots=False, rate_hz=200.0)
    assert not isinstance(a, FleetRun) and a.summary == b.summary
    assert sorted(p.name for p in (tmp_path / "a").iterdir()) == sorted(p.name for p in (tmp_path / "b").iterdir())
    for name in ("trace.csv", "summary.json", "mission.toml", "events.log"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes()


def test_a_fleet_of_one_is_printed_as_one_vehicle(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``bsst sim MISSION --vehicles 1`` heads its summary ``1 vehicle``, not ``1 vehicles`` (a tour)."""
    assert main(["sim", str(short_sine(tmp_path, 0.2)), "--vehicles", "1", "--out", str(tmp_path / "r"),
                 "--no-plots"]) == 0
    head = capsys.readouterr().out.splitlines()[0]
    assert head.startswith("mission sine  1 vehicle  clock offline"), head


def test_paths_closer_than_the_minimum_break_the_separation_policy_and_exit_1(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sim", str(NEAR_MISS), "--out", str(tmp_path / "r"), "--no-plots"]) == 1
    s = json.loads((tmp_path / "r" / "summary.json").read_text())
    assert s["outcome"] == "completed" and [v["outcome"] for v in s["vehicles"]] == ["completed", "completed"]
    (verdict,) = s["policies"]
    assert verdict["name"] == "separation" and not verdict["ok"] and "under the minimum of 0.5 m" in verdict["why"]
    (pair,) = s["separation"]["pairs"]
    assert pair["ids"] == [1, 2] and 0.0 < pair["closest_m"] < 0.5 and pair["closest_m"] == pytest.approx(0.27, 1e-2)
    assert "policy separation violated" in capsys.readouterr().err


def test_vehicles_that_touch_both_end_collision(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sim", str(TOUCH), "--out", str(tmp_path / "r"), "--no-plots"]) == 1
    s = json.loads((tmp_path / "r" / "summary.json").read_text())
    assert s["outcome"] == "collision" and [v["outcome"] for v in s["vehicles"]] == ["collision", "collision"]
    assert s["separation"]["closest_m"] <= 0.0
    for i in (1, 2):
        v = json.loads((tmp_path / "r" / f"vehicle-{i}" / "summary.json").read_text())
        assert v["outcome"] == "collision" and v["ended_by"]["who"] == "plant"
        assert "collision at t=" in v["ended_by"]["how"] and "touched" in v["ended_by"]["how"]
        assert "collision: vehicles 1 and 2 touched" in (tmp_path / "r" / f"vehicle-{i}" / "events.log").read_text()
    assert "vehicle 1: collision" in capsys.readouterr().err


def test_the_fleets_plots_show_every_vehicle(tmp_path: Path) -> None:
    """Two vehicles (three drew a third vehicle's five figures more, ~0.55 CPU-s, through the same loops)."""
    simulate(short_sine(tmp_path, 1.0), vehicles=2, formation="circle:2", out=tmp_path / "r")
    assert sorted(p.name for p in (tmp_path / "r" / "plots").iterdir()) == ["fleet-paths.png", "fleet-separation.png"]
    assert (tmp_path / "r" / "vehicle-2" / "plots" / "positions.png").is_file()


def test_a_fleet_overwrites_a_fleet_and_one_vehicle_overwrites_both(tmp_path: Path) -> None:
    mission, out = short_sine(tmp_path, 0.5), tmp_path / "r"
    simulate(mission, vehicles=3, out=out, plots=False)
    (out / "vehicle-3" / "gate.json").write_text("{}")  # a lockstep SITL fleet's gate file is its run's too
    simulate(mission, vehicles=2, out=out, overwrite=True, plots=False)
    assert sorted(p.name for p in out.iterdir()) == ["mission.toml", "summary.json", "vehicle-1", "vehicle-2"]
    simulate(mission, out=out, overwrite=True, plots=False)
    assert sorted(p.name for p in out.iterdir()) == ["events.log", "mission.toml", "summary.json", "trace.csv"]


def test_vehicles_given_from_python_and_their_bad_forms(tmp_path: Path) -> None:
    mission = short_sine(tmp_path, 0.5)
    run = simulate(mission, vehicles=[VehicleSpec(2, (3.0, 0.0, 0.0)), VehicleSpec(1)], controller="smc")
    assert isinstance(run, FleetRun) and [r.outcome for r in run.runs] == ["completed", "completed"]
    assert run.summary["vehicles"][1]["offset"] == [3.0, 0.0, 0.0] and run.path is None
    up = run.summary["vehicles"][0]["link"]["up"]
    assert {k: up[k] for k in ("sent", "delivered", "lost")} == {"sent": 125, "delivered": 125, "lost": 0}
    assert up["lost_by"]["queue"] == 0 and up["delay_ms"]["max"] == 0.0
    for bad in ("two", [VehicleSpec(2)], [{"id": 1}]):
        with pytest.raises(ConfigError, match="^vehicles: expected a number of vehicles or VehicleSpec"):
            simulate(mission, vehicles=bad)  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="^--formation line:2: lays out several vehicles"):
        simulate(mission, formation="line:2")
    with pytest.raises(ConfigError, match="has its own \\[\\[vehicles\\]\\]"):
        simulate(TOUCH, vehicles=2)


@pytest.mark.parametrize("args, words", [
    (["--formation", "line:2"], "give --vehicles N"),
    (["--vehicles", "0"], "--vehicles must be in [1, 64]"),
    (["--vehicles", "2", "--formation", "ring:2"], "--formation ring:2: expected line:SPACING"),
    (["--vehicles", "2", "--formation", "line:0"], "must be in (0, 1000] m"),
    (["--vehicles", "2", "--formation", "circle:0.1"],  # rotor discs overlapping at the start: a contact
     "--formation circle:0.1: vehicles 1 and 2 start touching: their rotor discs are -0.430 m apart"),
    (["--vehicles", "3", "--formation", "line:0.63"], "line:0.63: vehicles 1 and 2 start touching"),  # 0: a contact
])
def test_bad_fleet_flags_are_one_line_and_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                 args: list[str], words: str) -> None:
    out = tmp_path / "r"
    assert main(["sim", "missions/sine.toml", "--out", str(out), *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert words in err[-1] and "Traceback" not in "\n".join(err) and not out.exists()


def test_vehicles_of_a_file_that_start_touching_are_refused_naming_its_key(tmp_path: Path) -> None:
    f = tmp_path / "close.toml"
    f.write_text(TOUCH.read_text().replace("position = [3.0, 0.4, 0.0]", "position = [-3.0, 0.5, 0.0]"))
    with pytest.raises(ConfigError, match=r"close.toml: vehicles: vehicles 1 and 2 start touching: their rotor "
                                          r"discs are -0.130 m apart \(centres 0.500 m"):
        simulate(f, out=tmp_path / "r")
    assert not (tmp_path / "r").exists()


def test_a_bad_vehicle_is_named_with_its_id(tmp_path: Path) -> None:
    text = NEAR_MISS.read_text().replace('id = 2\n', 'id = 2\nprofile = "nonesuch"\n')
    f = tmp_path / "bad.toml"
    f.write_text(text)
    with pytest.raises(ConfigError, match=r"profile: .*\(vehicle 2\)$"):
        simulate(f, out=tmp_path / "r")
    assert not (tmp_path / "r").exists()


def test_a_fleet_mission_is_refused_where_one_vehicle_flies() -> None:
    with pytest.raises(ConfigError, match="vehicles: a mission of several vehicles is flown by bsst sim"):
        prepare(TOUCH)


@pytest.mark.parametrize("shared_by, at_by, words", [
    ("flag", "flag", "--shared-link: a fleet on one radio with link handovers (--at 2:link:lte)"),
    ("file", "flag", "{m}: link.shared: a fleet on one radio with link handovers (--at 2:link:lte)"),
    ("flag", "file", "--shared-link: a fleet on one radio with link handovers (events of kind link)"),
])
def test_a_shared_radio_with_a_handover_names_where_each_was_given(tmp_path: Path, shared_by: str, at_by: str,
                                                                   words: str) -> None:
    """One radio and a handover: refused before it flies, naming the flag or the file's key that gave each."""
    m = tmp_path / "short.toml"
    m.write_text((MISSION_DIR / "sine.toml").read_text().replace("duration_s = 30.0", "duration_s = 4.0")
                 + ('\n[link]\nshared = true\n' if shared_by == "file" else "")
                 + ('\n[[events]]\nt_s = 2.0\nkind = "link"\nprofile = "lte"\n' if at_by == "file" else ""))
    with pytest.raises(ConfigError) as exc:
        simulate(m, vehicles=2, link={"shared": True} if shared_by == "flag" else None,
                 at=("2:link:lte",) if at_by == "flag" else ())
    assert str(exc.value).startswith(words.format(m=m))


def test_a_vehicle_outside_the_fence_stays_at_its_start_and_the_others_fly(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The near miss with a fence round vehicle 1's leg only: vehicle 2 starts outside it, so PX4's pre-arm check
    denies its arm: it stays on the ground at its start, ``denied``, ended by the vehicle saying why (stderr names
    it), and that is no Ctrl-C: vehicle 1 flies its whole mission, judged against vehicle 2 standing there."""
    fenced = tmp_path / "fenced.toml"
    fenced.write_text(NEAR_MISS.read_text() + '\n[geofence]\nzones = [{ kind = "polygon", inclusion = true, points = '
                      '[[-5.0, -0.5], [5.0, -0.5], [5.0, 0.5], [-5.0, 0.5]] }]\n')
    assert main(["sim", str(fenced), "--out", str(tmp_path / "r"), "--no-plots"]) == 1
    s = json.loads((tmp_path / "r" / "summary.json").read_text())
    one, two = s["vehicles"]
    assert (one["outcome"], two["outcome"]) == ("completed", "denied") and s["outcome"] == "denied", s["vehicles"]
    assert two["ended_by"]["who"] == "vehicle" and two["ended_by"]["how"].startswith(
        "arming denied: outside its fence: at x=3.000 y=0.900 m"), two["ended_by"]
    # vehicle 1 ends its mission 1 m over (3, 0), then lands there, beside vehicle 2 at its start: 0.9 m apart
    (pair,) = s["separation"]["pairs"]  # (its landing judged as its mission: the closest approach is in it)
    assert pair["closest_m"] == pytest.approx(0.9 - 2 * 0.315, abs=0.01) and pair["t"] > 12.0, pair
    assert "vehicle 2: denied: ended by vehicle: arming denied: outside its fence" in capsys.readouterr().err


def test_ctrl_c_in_one_vehicle_stops_every_vehicle(tmp_path: Path) -> None:
    def interrupt(t: float, duration: float, err: float) -> None:
        if t >= 1.0:
            raise KeyboardInterrupt

    run = simulate(short_sine(tmp_path), vehicles=3, progress=interrupt, out=tmp_path / "r", plots=False)
    assert run.outcome == "aborted" and [r.outcome for r in run.runs] == ["aborted"] * 3
    assert all(len(r.trace["t"]) < 300 for r in run.runs)


def test_the_end_landing_is_judged_as_the_mission_one_landing_onto_another_touches_it(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """examples/swarm-stacked.toml: 1.5 m apart one over the other at the mission's end (separation held), each lands
    where it is, vehicle 2 onto vehicle 1 landed there: their landings are judged in the shared world as the mission
    was (they were each vehicle's own: ``completed``, separation held, exit 0), so the discs touch in the landing and
    both end there ``collision``, disarmed; flown alone, each lands and completes."""
    assert main(["sim", str(STACKED), "--out", str(tmp_path / "r"), "--no-plots"]) == 1
    run = simulate(STACKED, plots=False)
    assert run.outcome == "collision" and [r.outcome for r in run.runs] == ["collision"] * 2
    (pair,) = run.summary["separation"]["pairs"]
    assert pair["closest_m"] <= 0.0 and pair["t"] == 10.732, pair  # in the landing, after the mission's 8 s
    verdict = run.summary["policies"][0]
    assert verdict["name"] == "separation" and not verdict["ok"] and verdict["t"] > 8.0, verdict
    for r in run.runs:
        assert r.summary["ended_by"] == {"who": "plant", "how": "collision at t=10.732 s: vehicles 1 and 2 touched "
                                         "at t=10.732 s (centres 0.630 m apart, rotor discs -0.000 m)"}
        assert len(r.trace["t"]) == 2000 and r.summary["end"]["disarmed"]  # the mission's rows; its landing's end
    assert run.runs[1].summary["end"]["disarm_z_m"] == pytest.approx(0.633, abs=1e-3)  # on top of vehicle 1
    assert "vehicle 2: collision: ended by plant: collision at t=10.732 s" in capsys.readouterr().err
    for v in load_mission(STACKED).vehicles:
        alone = simulate_one(vehicle_mission(load_mission(STACKED), v), plots=False)
        assert alone.outcome == "completed" and alone.summary["end"]["disarm_z_m"] == 0.0


def test_a_failsafe_landing_after_the_mission_is_judged_untold_and_a_landing_onto_another_found(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """examples/swarm-takeover.toml with both links black from 12 s: each vehicle's failsafe lands it after the
    mission, vehicle 1 onto vehicle 2 landed under it. Each landing is flown alone, as by itself (every vehicle's own
    record the bytes it flies alone), but judged at every step, told nothing, as the lockstep fleet judges it on its
    record: contact at step 3954 (t=15.816 s, the lockstep fleet's), found, not prevented, both ``collision``,
    separation broken, said, exit 1 (it said separation held, closest 0.970 m, the landings unjudged and unsaid)."""
    out = tmp_path / "r"
    assert main(["sim", str(TAKEOVER), "--blackout", "12:10", "--out", str(out), "--no-plots"]) == 1
    printed = capsys.readouterr()
    s = json.loads((out / "summary.json").read_text())
    assert s["outcome"] == "collision" and [v["outcome"] for v in s["vehicles"]] == ["collision"] * 2
    for v, other in zip(s["vehicles"], (2, 1)):
        c = v["contact"]
        assert (c["step"], c["t"], c["with"]) == (3954, 15.816, other) and "failsafe's landing alone" in c["continued"]
    assert [(a["id"], a["from_t"]) for a in s["separation"]["alone"]] == [(1, 14.0), (2, 14.0)]
    assert s["separation"]["alone"][0]["to_t"] == 18.716  # vehicle 1 disarmed on top of vehicle 2
    assert s["separation"]["closest_m"] < 0.0 and s["separation"]["pairs"][0]["t"] > 14.0
    assert s["policies"][0]["name"] == "separation" and not s["policies"][0]["ok"] and s["policies"][0]["t"] > 14.0
    assert "vehicle 1 flew alone from t=14.000 s to t=18.716 s (its failsafe's landing" in printed.out
    assert ("bsst sim: vehicle 1: collision (touched vehicle 2 at step 3954, t=15.816 s; the flights went on: found "
            "afterwards, one of them in its failsafe's landing, flown alone)") in printed.err
    m = load_mission(TAKEOVER)
    for v in m.vehicles:  # every flight as flown by itself: the record, its summary and events, byte for byte
        simulate_one(vehicle_mission(m, v), link={"blackouts": [[12.0, 10.0]]}, out=tmp_path / f"alone-{v.id}",
                     plots=False)
        for f in ("trace.csv", "summary.json", "events.log"):
            assert (out / f"vehicle-{v.id}" / f).read_bytes() == (tmp_path / f"alone-{v.id}" / f).read_bytes(), f


def test_ctrl_c_in_the_end_landing_ends_the_flight_aborted_with_its_summary(tmp_path: Path) -> None:
    """The end landing is stepped as the mission (:func:`bridge.loop.flying` yields its periods): Ctrl-C in it
    ends the flight ``aborted``, its summary written (it escaped the landing: no summary.json, and a fleet's whole
    summary lost)."""
    m = load_mission(short_sine(tmp_path, 1.0))
    (tmp_path / "r").mkdir()
    steps = flying(prepare(m), tmp_path / "r", plots=False)
    for _ in range(m.steps + 10):  # the mission's steps, and ten of its landing's
        next(steps)
    with pytest.raises(StopIteration) as done:
        steps.throw(KeyboardInterrupt)
    run = done.value.value
    assert run.outcome == "aborted" and run.summary["ended_by"]["who"] == "user", run.summary["ended_by"]
    assert run.summary["end"]["rows"] == 10 and not run.summary["end"]["disarmed"]
    assert json.loads((tmp_path / "r" / "summary.json").read_text())["outcome"] == "aborted"


@pytest.mark.parametrize("link", [{"loss_pct": 30.0}, {"loss_pct": 30.0, "seed": 5}])
def test_each_vehicle_has_its_own_seeded_link(tmp_path: Path, link: dict) -> None:
    mission = short_sine(tmp_path, 1.0)
    run = simulate(mission, vehicles=3, link=link)
    lost = [(v["link"]["up"]["lost"], v["link"]["down"]["lost"]) for v in run.summary["vehicles"]]
    assert len(set(lost)) == 3, lost  # three links, three draws
    alone = simulate_one(mission, link=link)
    assert (alone.summary["link"]["up"]["lost"], alone.summary["link"]["down"]["lost"]) == lost[0]
    again = simulate(mission, vehicles=3, link=link)
    assert [(v["link"]["up"]["lost"], v["link"]["down"]["lost"]) for v in again.summary["vehicles"]] == lost


def test_a_fleet_too_long_to_keep_in_memory_is_refused_before_it_writes(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"duration_s: 64 vehicles of 7500 control steps are 480000 steps, "
                                          r"over the 100000"):
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr("bridge.swarm.MAX_TRACE_STEPS", 100_000)
            simulate("missions/sine.toml", vehicles=64, formation="grid:2", out=tmp_path / "r")
    assert not (tmp_path / "r").exists()


def test_the_fleets_mission_toml_is_the_mission_as_flown(tmp_path: Path) -> None:
    run = simulate(short_sine(tmp_path, 0.5), vehicles=2, controller="smc", seed=7, out=tmp_path / "r", plots=False)
    flown = load_mission(tmp_path / "r" / "mission.toml")
    assert flown.controller == "smc" and flown.seed == 7 and len(flown.vehicles) == 2
    assert [v["seed"] for v in run.summary["vehicles"]] == [7, 8] and run.summary["controller"] == "smc"


def test_a_formation_reaching_past_the_envelope_names_the_first_vehicle_outside(tmp_path: Path) -> None:
    """By its id and its offset: the refusal names the mission's trajectory (``trajectory.amplitude: amplitude 101
    m``), which the offset moved (it said ``(vehicle 51)`` alone: a user's tour)."""
    with pytest.raises(ConfigError, match=r"outside the plant's envelope of 100 m .*"
                                          r"\(vehicle 51, moved by \(0, 100, 0\) m\)$"):
        simulate("missions/sine.toml", vehicles=60, formation="line:2", out=tmp_path / "r")
    assert not (tmp_path / "r").exists()


def test_a_fleet_of_many_pairs_prints_its_closest_pairs_and_says_the_rest_are_in_the_summary(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Six in a line are 15 pairs: ``bsst sim`` prints the 12 closest (in id order) and says where the rest are; it
    printed the first 12 by id, which left out two of the five neighbours (4-5 and 5-6, the closest pairs)."""
    assert main(["sim", str(short_sine(tmp_path, 1.0)), "--vehicles", "6", "--out", str(tmp_path / "r"),
                 "--no-plots"]) == 0
    out = capsys.readouterr().out.splitlines()
    lines = [ln for ln in out if ln.startswith("  vehicles ")]
    shown = [ln.split(":")[0].removeprefix("  vehicles ") for ln in lines]
    assert len(shown) == 12 and {"4-5", "5-6"} <= set(shown) and not {"1-5", "1-6", "2-6"} & set(shown), lines
    assert shown == sorted(shown, key=lambda s: tuple(map(int, s.split("-"))))
    note = out[out.index(lines[-1]) + 1]
    assert note == "  (the 12 closest of 15 pairs: every pair in summary.json, separation.pairs)", out


def test_a_fleet_summary_says_each_vehicles_capped_jitter(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``bsst sim --vehicles 2 --delay 4 --jitter 10``: each vehicle's ``link`` in the fleet's summary.json says the
    cap its own summary says, and the printed summary says it under each vehicle (it said nothing)."""
    mission = short_sine(tmp_path, 1.0)
    assert main(["sim", str(mission), "--vehicles", "2", "--delay", "4", "--jitter", "10", "--no-plots", "--out",
                 str(tmp_path / "r")]) == 0
    s = json.loads((tmp_path / "r" / "summary.json").read_text())
    for v in s["vehicles"]:
        own = json.loads((tmp_path / "r" / v["dir"] / "summary.json").read_text())["link"]["jitter_capped"]
        assert v["link"]["jitter_capped"] == own and [c["bound_ms"] for c in own] == [4.0, 4.0], v["link"]
    printed = capsys.readouterr().out
    assert printed.count("  link up  : jitter 10 ms uniform capped at the delay, 4 ms: drawn within ± 4 ms") == 2


def test_each_vehicles_link_in_the_fleets_summary_adds_up(tmp_path: Path) -> None:
    """sent = delivered + lost + in flight for each vehicle's link in the fleet's own summary, as in its run's (the
    fleet's left out what was in flight, duplicated and reordered: its counts did not add up)."""
    run = simulate(short_sine(tmp_path, 1.0), vehicles=2, plots=False,
                   link={"loss_pct": 10.0, "delay_ms": 30.0, "dup_pct": 5.0, "reorder_pct": 5.0, "jitter_ms": 5.0})
    for v, alone in zip(run.summary["vehicles"], run.runs, strict=True):
        for d in ("up", "down"):
            L, own = v["link"][d], alone.summary["link"][d]
            assert L["sent"] == L["delivered"] + L["lost"] + L["in_flight"] and L["in_flight"] > 0, L
            assert {k: L[k] for k in ("duplicated", "reordered")} == {k: own[k] for k in ("duplicated", "reordered")}


def test_a_fleets_duration_is_its_time_flown_and_its_summary_lists_each_vehicles_events(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``bsst sim --vehicles 2 --profile x500 --at 1.5:motor:1=0 --at 0.5:gust:2,1,90`` of 3 s: both vehicles
    diverge before 2 s, and the fleet's ``duration_s`` (summary.json and the printed header) is the time they flew,
    as one vehicle's is, with the mission's 3 s beside it (``mission_duration_s``), as one vehicle's header says a
    flight cut short; the printed summary lists each vehicle's events (the gust, the fault, the divergence) under
    it, as one vehicle's does. Until the third wave's thirty-ninth session the fleet said the mission's 3.00 s and
    listed no event; until its forty-third the fleet's header said ``duration 1.73 s`` alone (no mission length
    in its summary.json)."""
    assert main(["sim", str(short_sine(tmp_path)), "--vehicles", "2", "--profile", "x500", "--at", "1.5:motor:1=0",
                 "--at", "0.5:gust:2,1,90", "--out", str(tmp_path / "r"), "--no-plots"]) == 1
    s = json.loads((tmp_path / "r" / "summary.json").read_text())
    flown = [json.loads((tmp_path / "r" / v["dir"] / "summary.json").read_text())["duration_s"] for v in s["vehicles"]]
    assert [v["outcome"] for v in s["vehicles"]] == ["diverged", "diverged"] and max(flown) < 2.0, flown
    out = capsys.readouterr().out
    assert out.splitlines()[0].endswith(f"duration {max(flown):.2f} s of the mission's 3 s (cut short)"), out
    assert s["duration_s"] == max(flown) and s["mission_duration_s"] == 3.0
    for said in ("  event t=0.500 wind: gust 1 m/s from 90 deg over 2 s", "  event t=1.500 fault: motor 1: off",
                 "diverged: tilt beyond 90 degrees"):
        assert out.count(said) == 2, out
