"""Covers bridge.session.fleet, bridge.swarm, bridge.record.separation and bridge.cli: fleets as SITL (bsst sitl).

Real processes: one ``bsst vehicle`` and one ``bsst controller`` per vehicle, over UDP on 127.0.0.1 (free ports,
``instance=None``, so the tests run beside other sessions). In lockstep the vehicles share one step clock
(its own tests: tests/test_swarm_clock.py), so each vehicle's trace equals the offline fleet's for that vehicle
(≤ 1e-4 m) and the separation judged on the traces is the offline loop's; the trace judge alone (as real time
uses it) is the offline loop's too. The records have the offline fleet's layout.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as M

from bridge.cli import main
from bridge.cli.runreport import report_fleet
from bridge.mavlink.endpoint import GCS_PORT
from bridge.record.halves import count_records
from bridge.record.interventions import intervention_text
from bridge.record.separation import Watch, judge_traces
from bridge.session import instance_slot
from bridge.swarm import FleetRun, simulate, sitl
from missions import MISSION_DIR
from params import ConfigError
from tests.sitlkit import ENV, Bsst, Proc, csv_rows
from tests.waiting import wait_for

pytestmark = pytest.mark.process  # starts processes

ROOT = Path(__file__).resolve().parents[1]


def short_sine(tmp_path: Path, seconds: float = 2.0) -> Path:
    text = (MISSION_DIR / "sine.toml").read_text().replace("duration_s = 30.0", f"duration_s = {seconds}")
    f = tmp_path / "short.toml"
    f.write_text(text)
    return f


def worst_gap(a: dict, b: dict) -> float:
    assert len(a["t"]) == len(b["t"])
    return max(float(np.max(np.abs(np.asarray(a[c]) - np.asarray(b[c])))) for c in ("x", "y", "z"))


def test_four_in_a_line_fly_in_sitl_as_offline_vehicle_by_vehicle(tmp_path: Path) -> None:
    """The sine cut to 2 s, its end held: the end landing (~2.3 s, more than the mission's 500 rows, of four lockstep
    pairs) is flown and judged as offline's by tests/test_swarm_clock.py's landing onto another vehicle."""
    mission = short_sine(tmp_path)
    mission.write_text(mission.read_text() + '\n[end]\naction = "hold"\n')
    run = sitl(mission, vehicles=4, formation="line:2", instance=None, out=tmp_path / "sitl", plots=False)
    off = simulate(mission, vehicles=4, formation="line:2", plots=False)
    assert isinstance(run, FleetRun) and run.outcome == "completed", run.summary
    s = run.summary
    assert s["clock"] == "lockstep" and s["sitl"]["sysids"] == [1, 2, 3, 4] and s["sitl"]["shared_clock"] is True
    for a, b in zip(run.runs, off.runs):
        assert a.summary["clock"] == "lockstep" and a.summary["lockstep"] == {"held": True}
        assert worst_gap(a.trace, b.trace) <= 1e-4
    # the separation judged on the traces is the offline loop's, pair by pair
    for p, q in zip(s["separation"]["pairs"], off.summary["separation"]["pairs"]):
        assert p["ids"] == q["ids"] and abs(p["closest_m"] - q["closest_m"]) <= 1e-4 and p["ok"] and q["ok"]
    assert [p["ok"] for p in s["policies"]] == [True]
    # the records: the offline fleet's layout, each vehicle with its session's files
    root = tmp_path / "sitl"
    top = json.loads((root / "summary.json").read_text())
    assert [v["dir"] for v in top["vehicles"]] == [f"vehicle-{i}" for i in range(1, 5)]
    for i in range(1, 5):
        d = root / f"vehicle-{i}"
        assert all((d / f).is_file() for f in ("trace.csv", "vehicle.tlog", "controller.tlog", "summary.json"))
        assert json.loads((d / "summary.json").read_text())["sitl"]["sysid"] == i
        # its gate file is the run's own (each events.log said it was "kept, not written by a run")
        assert (d / "gate.json").is_file() and "not written by a run" not in (d / "events.log").read_text()
    assert report_fleet(run, "sitl") == 0


def test_the_trace_judge_is_the_offline_watch() -> None:
    """A near miss flown offline, its traces judged afterwards (as SITL's are): the offline loop's verdict and
    closest approach (the loop also judges the state after the last step, which no trace row holds)."""
    off = simulate(ROOT / "examples" / "swarm-near-miss.toml", plots=False)
    sep = off.summary["separation"]
    watch = Watch([1, 2], list(sep["disc_radius_m"].values()), sep["min_m"])
    assert judge_traces(watch, [r.trace for r in off.runs], off.summary["rate_hz"]) == {}
    assert watch.verdict() == off.summary["policies"][0] and not watch.verdict()["ok"]
    assert watch.summary()["pairs"] == sep["pairs"]


def test_a_vehicle_that_flew_no_step_touches_no_one_in_the_trace_judge() -> None:
    """A SITL fleet whose vehicle was disarmed before its first row (seen under load: the judge raised
    IndexError and the fleet had no summary): its empty trace is nowhere; the others are judged as before. Given
    the starts, it stands at its own."""
    empty = {c: np.array([]) for c in ("t", "x", "y", "z")}
    flown = {"t": np.array([0.0, 0.004]), "x": np.zeros(2), "y": np.zeros(2), "z": np.zeros(2)}
    beside = {**flown, "y": np.full(2, 0.5)}  # centres 0.5 m apart: rotor discs overlap
    watch = Watch([1, 2, 3], [0.3, 0.3, 0.3], 0.5)
    contacts = judge_traces(watch, [flown, empty, beside], 250.0)
    assert sorted(contacts) == [0, 2] and contacts[0]["with"] == 3
    # a lockstep fleet gives the starts: one never armed (its arm denied) stands at its own, as offline
    at_start = judge_traces(watch, [flown, empty, beside], 250.0, starts=[(0.0, 0.0, 0.0), (0.0, -0.4, 0.0)] * 2)
    assert sorted(at_start) == [0, 1, 2] and at_start[1]["with"] == 1, at_start


def test_a_fleet_past_the_last_instance_is_refused_before_anything_starts(tmp_path: Path, capsys) -> None:
    with pytest.raises(ConfigError, match="up to instance 10; instances are 0-9"):
        sitl(short_sine(tmp_path), vehicles=3, instance=8, out=tmp_path / "no")
    assert not (tmp_path / "no").exists()
    # a system id of its own: each vehicle's process refused it (naming a --sysid never given), files written
    with pytest.raises(ConfigError, match=r"^--param MAV_SYS_ID: a fleet's vehicles take PX4's system ids from"):
        sitl(short_sine(tmp_path), vehicles=2, instance=0, params={"MAV_SYS_ID": 5}, out=tmp_path / "no")
    assert not (tmp_path / "no").exists()
    assert main(["sitl", str(short_sine(tmp_path)), "--vehicles", "4", "--instance", "7", "--out",
                 str(tmp_path / "no")]) == 2
    assert "instances are 0-9" in capsys.readouterr().err and not (tmp_path / "no").exists()
    with pytest.raises(ConfigError, match="fly at most 1 vehicle from this instance$"):  # one, not "1 vehicles"
        sitl(short_sine(tmp_path), vehicles=2, instance=9, out=tmp_path / "no")


def test_a_fleet_from_instance_n_takes_px4s_system_ids_from_n_plus_one(tmp_path: Path) -> None:
    """Vehicle i of a fleet from ``--instance B`` is PX4's instance B + i - 1, so its MAV_SYS_ID is B + i, as
    PX4's ``px4 -i N`` sets N + 1 and a single ``bsst sitl --instance N`` does (it was i whatever B: instance 7
    was system 8 alone and system 1 in a fleet); the wire says so (the vehicle's tlog)."""
    from pymavlink import mavutil

    with instance_slot() as n:
        run = sitl(short_sine(tmp_path, 0.5), vehicles=1, instance=n, out=tmp_path / "r", plots=False)
    assert isinstance(run, FleetRun) and run.outcome == "completed"
    assert run.summary["sitl"]["instances"] == [n] and run.summary["sitl"]["sysids"] == [n + 1]
    assert run.summary["vehicles"][0]["sysid"] == n + 1 and run.summary["vehicles"][0]["id"] == 1
    assert json.loads((tmp_path / "r" / "vehicle-1" / "summary.json").read_text())["sitl"]["sysid"] == n + 1
    tlog = mavutil.mavlink_connection(str(tmp_path / "r" / "vehicle-1" / "vehicle.tlog"))
    odometry = tlog.recv_match(type="ODOMETRY")
    assert odometry is not None and odometry.get_srcSystem() == n + 1


@contextlib.contextmanager
def _two_instances() -> Iterator[int]:
    """Instances B and B + 1 both held (:func:`instance_slot`, each taken the highest free first), for a fleet of
    two flown by ``bsst sitl --vehicles 2 --instance B``."""
    with contextlib.ExitStack() as held:
        taken: set[int] = set()
        for _ in range(10):
            n = held.enter_context(instance_slot())
            taken.add(n)
            if n + 1 in taken or n - 1 in taken:
                yield n if n + 1 in taken else n - 1
                return
    raise AssertionError("no two adjacent SITL instances free")


def test_ctrl_c_stops_every_pair_and_each_summary_says_aborted(tmp_path: Path) -> None:
    """``bsst sitl --vehicles 2`` forked warm by the fork server (a cold ``python -c`` flying ``bridge.swarm.sitl``
    started its own fork server too: ~1.9 CPU-s of imports for a second of flight), SIGINT after a second of flight
    of both vehicles. Its printed header says the mission's 30 s beside the time flown (until the third wave's
    forty-third session it said the time flown alone)."""
    run = tmp_path / "run"
    with _two_instances() as b:
        p = Proc.bsst("sitl", str(short_sine(tmp_path, 30.0)), "--vehicles", "2", "--instance", str(b), "--out",
                      str(run), "--no-plots", cwd=ROOT)
        try:
            # in lockstep the halves are the live record (trace.csv is written once the flight is over)
            wait_for(lambda: all(count_records(run / f"vehicle-{i}" / "vehicle.bin") > 250 for i in (1, 2)), 90,
                     "a second of flight of both vehicles")
            p.p.send_signal(signal.SIGINT)
            p.p.wait(timeout=30)
        finally:
            p.stop()
    assert p.p.returncode == 1, p.lines[-20:]
    s = json.loads((run / "summary.json").read_text())
    assert s["outcome"] == "aborted" and [v["outcome"] for v in s["vehicles"]] == ["aborted", "aborted"]
    # its header gives the time flown with the mission's length beside it, as one vehicle's does
    head = f"mission sine  2 vehicles  clock lockstep  rate 250 Hz  duration {s['duration_s']:.2f} s"
    assert f"{head} of the mission's 30 s (cut short)" in p.lines, p.lines[:3]
    for i in (1, 2):
        own = json.loads((run / f"vehicle-{i}" / "summary.json").read_text())
        assert own["ended_by"]["who"] == "user"
        assert csv_rows(run / f"vehicle-{i}" / "trace.csv") < 30 * 250


def _pid_naming(path: Path) -> int | None:
    """The process whose command line names ``path`` (a vehicle forked by the fork server shows its own, the words
    joined by spaces), if any."""
    for d in Path("/proc").iterdir():
        try:
            if d.name.isdigit() and str(path).encode() in (d / "cmdline").read_bytes().replace(b"\0", b" ").split():
                return int(d.name)
        except OSError:
            continue  # (a process gone meanwhile)
    return None


def _started(pid: int) -> str | None:
    """Process ``pid``'s start time (clock ticks since boot, /proc/PID/stat), None once it is gone (reaped)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rpartition(")")[2].split()[19]
    except OSError:
        return None


@pytest.mark.parametrize(("sig", "how", "said", "dropped"), [
    (signal.SIGKILL, "died (killed by SIGKILL)", "vehicle (pid {pid}) killed by SIGKILL", "ended (its process gone"),
    # frozen: its own controller gives up on it after 2 s, and its session kills it at once
    (signal.SIGSTOP, "vehicle silent for 2 s", "vehicle (pid {pid}) frozen, its controller hearing nothing from it: "
     "SIGKILL; the other vehicles fly on without it", "frozen (its controller heard nothing from it: killed")],
    ids=["killed", "frozen"])
def test_a_vehicle_killed_or_frozen_in_flight_is_dropped_and_the_other_flies_on(tmp_path: Path, capsys, sig: int,
                                                                                how: str, said: str,
                                                                                dropped: str) -> None:
    """A lockstep pair at real time's pace, vehicle 2's process killed (or frozen) after a second of flight: once its
    process is gone its fleet tells vehicle 1's gate at once (no 30 s of silence), and vehicle 1 flies its mission to
    the end, its controller not giving up on its vehicle waiting at the gate meanwhile (until the third wave's
    thirty-sixth session it aborted 2 s after: "no new state from the vehicle for 2 s"); vehicle 2 is aborted,
    said by name, and the fleet with it. Frozen (SIGSTOP), its controller hears nothing from it for 2 s and its
    session kills and reaps it then, and vehicle 1 flies on within seconds (until the third wave's thirty-seventh
    session its session waited for a landing that never came, then 8 s for a SIGTERM it never took: vehicle 1 flew
    on 17 s after the freeze)."""
    mission = short_sine(tmp_path, 4.0)
    mission.write_text(mission.read_text() + '\n[end]\naction = "hold"\n')  # (no landing to fly: cheaper)
    out, result = tmp_path / "run", {}

    def fly(result: dict[str, Any] = result) -> None:
        try:
            result["run"] = sitl(mission, vehicles=2, instance=None, speed=1.0, out=out, plots=False)
        except BaseException as exc:  # noqa: BLE001  (named by the assertion below)
            result["error"] = exc

    flight = threading.Thread(target=fly, daemon=True)
    flight.start()
    try:
        wait_for(lambda: count_records(out / "vehicle-2" / "vehicle.bin") > 250, 90, "a second of vehicle 2's flight")
        pid = _pid_naming(out / "vehicle-2" / "gate.json")
        assert pid is not None, "vehicle 2's process"
        born, one = _started(pid), out / "vehicle-1" / "vehicle.bin"
        os.kill(pid, sig)
        waited = count_records(one)  # vehicle 1 at its gate, waiting for vehicle 2's step
        wait_for(lambda: count_records(one) > waited + 50, 10, "vehicle 1 flying on after vehicle 2's end")
    finally:
        flight.join(120)
    assert not flight.is_alive() and "error" not in result, result
    run = result["run"]
    one, two = run.summary["vehicles"]
    assert one["outcome"] == "completed" and one["ok"], one
    assert len(run.runs[0].trace["t"]) == 4 * 250  # its whole mission
    assert two["outcome"] == "aborted" and not two["ok"] and two["ended_by"]["how"] == how, two
    gate = run.summary["sitl"]["gate"]
    assert gate["2"] is None and len(gate["1"]["dropped"]) == 1, gate  # (its process said nothing more)
    assert gate["1"]["dropped"][0].startswith(f"vehicle 2 {dropped}"), gate
    assert _started(pid) != born  # killed and reaped, never left stopped (a pid taken again starts later)
    assert run.outcome == "aborted" and report_fleet(run, "sitl") == 1
    err = capsys.readouterr().err
    assert "bsst sitl: vehicle 2: " + said.format(pid=pid) in err, err
    assert "vehicle 1: aborted" not in err and "no new state" not in err, err


def test_a_fleet_awaiting_a_ground_stations_mission_is_refused() -> None:
    """Named by the flag given: ``--formation line:2`` alone was said as ``--vehicles`` (a user's tour)."""
    with pytest.raises(ConfigError, match="^--vehicles 2 with --await-mission"):
        sitl(None, vehicles=2, await_mission=True)
    with pytest.raises(ConfigError, match="^--formation line:2 with --await-mission: a ground station's mission flies"):
        sitl(None, formation="line:2", await_mission=True)


def _from(gcs: Any, kind: str, sysid: int, fleet: Bsst) -> Any:
    """The next message of ``kind`` from system ``sysid`` (30 s for each), the fleet's output if none comes."""
    while (m := gcs.recv_match(type=kind, blocking=True, timeout=30)) is None or m.get_srcSystem() != sysid:
        assert m is not None, fleet.communicate(timeout=60)
    return m


def test_a_fleet_not_flown_as_asked_names_why_for_that_vehicle_on_stderr_and_under_its_line(tmp_path: Path,
                                                                                          monkeypatch) -> None:
    """A lockstep fleet of two (2 s of sine at 2x real time) whose vehicle 1 a ground station changes a parameter of
    (COM_DISARM_LAND, harmless: the landing after the mission): both complete, the separation holds, exit 1, and
    stderr says why as one vehicle's run does, for that vehicle (``bsst sitl: vehicle 1: not flown as asked: ...``),
    the printed summary under its line, with each vehicle's policies. Until the third wave's fortieth session a
    fleet said nothing of it (a real-time fleet the machine stalled: exit 1, its reason only in the events)."""
    mission = short_sine(tmp_path, 2.0)
    out = tmp_path / "run"
    monkeypatch.setenv("MAVLINK20", "1")
    with _two_instances() as n:
        gcs = mavutil.mavlink_connection(f"udpin:127.0.0.1:{GCS_PORT + n}", source_system=255, source_component=190,
                                         dialect="common")  # the fleet's one ground-station port
        s = Bsst("sitl", mission, "--vehicles", "2", "--formation", "line:2", "--instance", n, "--speed", "2",
                 "--out", out, "--no-plots", env=ENV)
        try:
            _from(gcs, "HEARTBEAT", n + 1, s)
            gcs.mav.param_set_send(n + 1, 1, b"COM_DISARM_LAND", 1.0, M.MAV_PARAM_TYPE_REAL32)
            m = _from(gcs, "PARAM_VALUE", n + 1, s)
            assert m.param_id == "COM_DISARM_LAND" and m.param_value == 1.0, m
            stdout, err = s.communicate(timeout=120)
        finally:
            if s.poll() is None:
                s.kill()
            gcs.close()
    fleet = json.loads((out / "summary.json").read_text())
    assert s.returncode == 1 and fleet["outcome"] == "completed" and fleet["policies"][0]["ok"], (stdout, err)
    [change] = json.loads((out / "vehicle-1" / "summary.json").read_text())["interventions"]
    assert not json.loads((out / "vehicle-2" / "summary.json").read_text()).get("interventions")
    said = f"not flown as asked: {intervention_text(change)}"
    assert [ln for ln in err.splitlines() if not ln.startswith("bsst sitl: vehicle up")] == \
        [f"bsst sitl: vehicle 1: {said}"], err
    one, two = stdout.split("\nvehicle 2 ")
    assert f"\n  {said}\n" in one and said not in two, stdout
    assert "\n  policies: all " in one and "\n  policies: all " in two, stdout
