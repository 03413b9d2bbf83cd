"""Covers missions.route, missions.steps and missions.mission: a plan too long is refused before it is timed, and
a command reads its plan once.

A 3 000-item plan took ~30 s to time (and was timed three times by ``bsst sim``) before it was refused for its
7.5 hours (docs/missions.md, "Loading a long plan"). Its least length, each leg straight at its speed limits plus
the holds (:func:`missions.route.least_duration_s`), costs milliseconds and is never more than the timed one: a
plan over the command's cap (``bridge.record.runlog.trace_cap``) or the mission's longest duration even so is
refused first, saying "at least". Pure: plans in the test's directory, one short flight in this process.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

import missions.mission as mission_module
import missions.trajectories as trajectories_module
from bridge.cli import main
from bridge.record.runlog import trace_cap
from missions import load_mission, mission_from_table
from missions.envelope import ENVELOPE_RADIUS_M
from missions.planfiles import read_plan_text
from missions.route import Limits, least_duration_s, smooth_from_plan
from params import ConfigError
from tests.plans import BOX_PLAN, ROOT, box_repeated, l_plan, write_plan


def _held(data: dict[str, Any]) -> None:
    """The box with a 5 s hold at its second corner, and a climb to 15 m at its third."""
    items = data["mission"]["items"]
    items[3]["params"][0] = 5
    items[4]["params"][6] = 15


def test_the_least_duration_is_never_more_than_the_timed_trajectory(tmp_path: Path) -> None:
    plans = [BOX_PLAN, ROOT / "examples" / "box.waypoints", l_plan(tmp_path), box_repeated(tmp_path, 40),
             write_plan(tmp_path, _held, "held.plan")]
    for path in plans:
        plan = read_plan_text(path.read_text(), str(path))
        for limits in (Limits(), Limits(MPC_XY_CRUISE=2.0, MPC_ACC_HOR=1.0),
                       Limits(MPC_Z_V_AUTO_UP=1.0, MPC_Z_V_AUTO_DN=0.5, MPC_YAWRAUTO_MAX=20.0)):
            least = least_duration_s(plan, limits, ENVELOPE_RADIUS_M)
            timed = smooth_from_plan(plan, limits, ENVELOPE_RADIUS_M)[0].end_s
            assert least <= timed, (path.name, limits, least, timed)
    plan = read_plan_text(plans[3].read_text(), "40 items")  # on long legs it comes near: it refuses what is far over
    assert least_duration_s(plan, Limits(), ENVELOPE_RADIUS_M) >= 0.6 * smooth_from_plan(plan, Limits(),
                                                                                        ENVELOPE_RADIUS_M)[0].end_s


def test_a_plan_too_long_for_the_trace_is_refused_before_it_is_timed(tmp_path: Path, capsys: Any) -> None:
    long = box_repeated(tmp_path, 3000)
    with pytest.raises(ConfigError) as refused:
        load_mission(long, trace_cap())
    said = str(refused.value)
    assert said.startswith(f"{long}: duration_s: at least 19") and said.endswith(
        " s (3000 items at their speed limits) at 250 Hz is at least 4799900 control steps, over the 500000 a run "
        "keeps in memory for its summary (2000 s at this rate); fly longer with bsst vehicle and bsst controller, "
        "which stream their rows to disk"), said
    out = tmp_path / "run"
    assert main(["sim", str(long), "--out", str(out), "--no-plots"]) == 2
    assert capsys.readouterr().err == f"bsst: {said}\n" and not out.exists()
    # named in a mission file that flies the plan for its own length; and a mission longer than the cap, given
    toml = {"trajectory": {"kind": "plan", "file": str(long)}}
    with pytest.raises(ConfigError, match=r"long\.plan: duration_s: at least 19\d+\.\d s \(3000 items"):
        mission_from_table(toml, "<m>", cap=trace_cap())  # (named by the plan, whose length it is)
    with pytest.raises(ConfigError, match=r"^<m>: duration_s: 3000 s at 250 Hz is 750000 control steps, over"):
        mission_from_table({**toml, "duration_s": 3000.0}, "<m>", cap=trace_cap())


def test_the_cap_is_at_the_rate_the_command_flies(tmp_path: Path) -> None:
    """100 items fly at least 640 s: 160 000 steps at 250 Hz, within the cap; 640 000 at --rate 1000, over it."""
    plan = box_repeated(tmp_path, 100)
    with pytest.raises(ConfigError, match=r"duration_s: at least 6\d\d\.\d s \(100 items at their speed limits\) "
                                          r"at 1000 Hz is at least 6\d{5} control steps, over the 500000"):
        load_mission(plan, trace_cap(1000.0))
    assert load_mission(plan, trace_cap()).duration_s * 250 <= 500_000


def test_a_plan_longer_than_a_mission_may_last_is_refused_before_it_is_timed(tmp_path: Path) -> None:
    """30 holds of an hour: over the 86 400 s of duration_s whatever flies it (bsst vehicle keeps no trace)."""
    def hours(data: dict[str, Any]) -> None:
        box = data["mission"]["items"]
        data["mission"]["items"] = [box[0], box[1], *(dict(box[2], command=19, params=[3600, 0, 0, None,
                                                                                         *box[2]["params"][4:]])
                                                      for _ in range(30)), box[7]]
    plan = write_plan(tmp_path, hours, "hours.plan")
    with pytest.raises(ConfigError, match=r"hours\.plan: mission\.items: 33 items fly at least 10\d{4} s at their "
                                          r"speed limits, over the 86400 s a mission may last \(duration_s\)"):
        load_mission(plan)


@pytest.mark.parametrize("kind", ["plan", "toml"])
def test_bsst_sim_reads_its_plan_once(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, kind: str) -> None:
    """The plan is read and timed once a command: it was three times (the laws looked for, the fleet looked
    for, the flight), and a mission file's plan twice each (its trajectory, then its fence and rally points).
    The box cut to an L (every kind of item the box has, and its fence and rally tables: 20 s of flight, not 90)."""
    plan = l_plan(tmp_path)
    read: list[str] = []

    def counted(text: str, source: str) -> Any:
        read.append(source)
        return read_plan_text(text, source)

    monkeypatch.setattr(mission_module, "read_plan_text", counted)  # a plan file given as the mission
    monkeypatch.setattr(trajectories_module, "read_plan_text", counted)  # a mission file's [trajectory] plan
    mission = plan
    if kind == "toml":
        mission = tmp_path / "boxed.toml"
        mission.write_text(f'name = "boxed"\n[trajectory]\nkind = "plan"\nfile = "{plan}"\n')
    assert main(["sim", str(mission), "--out", str(tmp_path / "run"), "--no-plots"]) == 0
    assert read == [str(plan)]


@pytest.mark.parametrize("kind", ["smooth", "waypoints", "step"])
def test_a_trajectory_of_more_points_than_a_plan_may_have_items_is_refused_before_they_are_read(
        tmp_path: Path, kind: str) -> None:
    """A ``[trajectory]``'s points are held to a plan's item limit (missions.planfiles.MAX_ITEMS), checked before
    any point is read: 19 000 zigzag knots of a smooth trajectory took 39 s to be refused for their thrust."""
    key = "setpoints" if kind == "step" else "points"
    points = ",".join(f"{{t={k * 0.1:.1f},x={k % 2},y=0,z=1}}" for k in range(10_001))
    path = tmp_path / "many.toml"
    path.write_text(f'name = "many"\nduration_s = 1100.0\n[trajectory]\nkind = "{kind}"\n{key} = [{points}]\n')
    with pytest.raises(ConfigError, match=rf"^{path}: trajectory\.{key}: 10001 points, more than 10000$"):
        load_mission(path)
