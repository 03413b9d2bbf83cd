"""Covers missions.fleet and missions.mission: several vehicles in one mission.

``[[vehicles]]`` and ``[separation]`` are read and validated on load, each bad value named by file, key and
range; ``--vehicles N --formation`` lays vehicles out (line, grid, circle); a vehicle's own mission moves the
mission's trajectory and start by its offset (a zero offset changes nothing, to the bit), draws its own seeds,
and a fleet's mission.toml reads back as the same fleet.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import replace
from pathlib import Path

import pytest

from missions import MISSION_DIR, Setpoint, Sine, Step, Waypoints, load_mission, mission_from_table
from missions.fleet import (
    DEFAULT_MIN_SEPARATION_M,
    Separation,
    VehicleSpec,
    formation,
    link_seeds_moved,
    parse_formation,
    shifted,
    vehicle_mission,
)
from missions.minsnap import Knot, Smooth
from params import ConfigError, dump_toml, load_toml


def table(**more: object) -> dict:
    base = load_toml(MISSION_DIR / "sine.toml")
    return {**base, **more}


def test_a_mission_without_vehicles_is_one_vehicle_and_writes_as_before() -> None:
    m = load_mission("missions/sine.toml")
    assert m.vehicles == () and m.separation is None
    assert "vehicles" not in m.to_dict() and "separation" not in m.to_dict()
    assert "x0" not in m.to_dict()["trajectory"]


def test_vehicles_tables_are_read_with_ids_offsets_starts_trajectories_profiles_and_laws() -> None:
    m = mission_from_table(table(vehicles=[
        {"id": 2, "offset": [0.0, 3.0, 0.0], "profile": "x500"},
        {"id": 1, "controller": "smc"},
        {"id": 3, "start": {"position": [5.0, 0.0, 0.0]},
         "trajectory": {"kind": "step", "setpoints": [{"t": 0.0, "x": 5.0, "y": 0.0, "z": 1.0}]}},
    ], separation={"min_m": 1.0, "rotor_radius_m": 0.12}), "m.toml")
    assert [v.id for v in m.vehicles] == [1, 2, 3]
    one, two, three = m.vehicles
    assert one.controller == "smc" and two.profile == "x500" and two.offset == (0.0, 3.0, 0.0)
    assert three.start == (5.0, 0.0, 0.0, 0.0) and isinstance(three.trajectory, Step)
    assert m.separation == Separation(1.0, 0.12)
    again = mission_from_table(tomllib.loads(dump_toml(m.to_dict())), "again.toml")
    assert again.vehicles == m.vehicles and again.separation == m.separation


@pytest.mark.parametrize("vehicles, key, words", [
    ([{"id": 1}, {"id": 3}], "vehicles", "ids must be 1..2"),
    ([{"id": 1}, {"id": 1}], "vehicles", "ids must be 1..2"),
    ([{"id": 0}], "vehicles[0].id", "must be in [1, 64]"),
    ([{"id": 1, "offset": [0.0, 1e6, 0.0]}], "vehicles[0].offset", "element 1 must be in [-1000, 1000]"),
    ([{"id": 1, "offset": [0.0, 1.0]}], "vehicles[0].offset", "expected a list of 3 numbers"),
    ([{"id": 1, "offset": [0.0, 1.0, 0.0], "trajectory": {"kind": "sine"}}], "vehicles[0].offset", "not both"),
    ([{"id": 1, "colour": "red"}], "vehicles[0].colour", "unknown key"),
    ([{"id": 1, "controller": "nonsense"}], "vehicles[0].controller", "must be one of"),
    ([{"id": 1, "trajectory": {"kind": "circle"}}], "vehicles[0].trajectory.kind", "must be one of"),
    ("one", "vehicles", "expected an array of tables"),
    ([], "vehicles", "an empty array"),  # (it flew one vehicle, as if the key were not there)
])
def test_a_bad_vehicle_is_named_by_file_key_and_range(vehicles: object, key: str, words: str) -> None:
    with pytest.raises(ConfigError) as exc:
        mission_from_table(table(vehicles=vehicles), "fleet.toml")
    assert str(exc.value).startswith(f"fleet.toml: {key}: ") and words in str(exc.value)


@pytest.mark.parametrize("sep, key, words", [
    ({"min_m": -1.0}, "separation.min_m", "must be in [0, 100]"),
    ({"rotor_radius_m": 0.0}, "separation.rotor_radius_m", "must be in (0, 10]"),
    ({"minimum": 1.0}, "separation.minimum", "unknown key"),
])
def test_a_bad_separation_is_named_by_file_key_and_range(sep: dict, key: str, words: str) -> None:
    with pytest.raises(ConfigError) as exc:
        mission_from_table(table(separation=sep), "fleet.toml")
    assert str(exc.value).startswith(f"fleet.toml: {key}: ") and words in str(exc.value)


def test_too_many_vehicles_are_refused() -> None:
    with pytest.raises(ConfigError, match="at most 64 vehicles"):
        mission_from_table(table(vehicles=[{"id": i + 1} for i in range(65)]), "fleet.toml")


def test_formations_lay_vehicles_out_with_ids_one_to_n() -> None:
    line = formation(4, "line:2")
    assert [v.id for v in line] == [1, 2, 3, 4]
    assert [v.offset for v in line] == [(0.0, 0.0, 0.0), (0.0, 2.0, 0.0), (0.0, 4.0, 0.0), (0.0, 6.0, 0.0)]
    grid = formation(5, "grid:3")  # rows of ceil(sqrt 5) = 3
    assert [v.offset[:2] for v in grid] == [(0.0, 0.0), (0.0, 3.0), (0.0, 6.0), (3.0, 0.0), (3.0, 3.0)]
    circle = formation(4, "circle:1.5")
    assert [v.offset[:2] for v in circle] == [(1.5, 0.0), (0.0, 1.5), (-1.5, 0.0), (0.0, -1.5)]
    assert all(math.isclose(math.hypot(*v.offset[:2]), 2.0) for v in formation(7, "circle:2"))


@pytest.mark.parametrize("text, words", [
    ("line", "expected line:SPACING"), ("ring:2", "expected line:SPACING"), ("line:x", "not a number"),
    ("line:0", "must be in (0, 1000] m"), ("circle:nan", "must be in (0, 1000] m"), ("grid:-1", "must be in"),
])
def test_a_bad_formation_names_the_flag(text: str, words: str) -> None:
    with pytest.raises(ConfigError) as exc:
        parse_formation(text)
    assert str(exc.value).startswith(f"--formation {text}: ") and words in str(exc.value)


@pytest.mark.parametrize("n, text, words", [
    (3, "line:600", "vehicle 3 would be moved 1200 m along y, past the [-1000, 1000] m an offset may be"),
    (40, "grid:200", "vehicle 7 would be moved 1200 m along y"),
])
def test_a_formation_past_the_offsets_range_names_the_flag(n: int, text: str, words: str) -> None:
    """It named the mission's file and a table it does not have (``sine.toml: vehicles[2].offset: element 1 must be
    in [-1000, 1000], got 1200``): a user's tour."""
    with pytest.raises(ConfigError) as exc:
        formation(n, text)
    assert str(exc.value).startswith(f"--formation {text}: {words}"), exc.value


@pytest.mark.parametrize("n", [0, 65, True])
def test_a_bad_vehicle_count_names_the_flag(n: object) -> None:
    with pytest.raises(ConfigError, match=r"^--vehicles .*: must be a whole number in \[1, 64\]"):
        formation(n, "line:2")  # type: ignore[arg-type]


def test_a_zero_offset_is_the_same_reference_and_others_move_it_exactly() -> None:
    sine = Sine()
    assert shifted(sine, (0.0, 0.0, 0.0)) is sine
    moved = shifted(sine, (1.0, -2.0, 0.5))
    for t in (0.0, 1.3, 7.7):
        a, b = sine.sample(t), moved.sample(t)
        assert b[0][0] == a[0][0] + 1.0 and b[1][0] == a[1][0] - 2.0 and b[2][0] == a[2][0] + 0.5
        assert b[0][1:] == a[0][1:] and b[3] == a[3]
    pts = (Setpoint(0.0, 0.0, 0.0, 1.0), Setpoint(2.0, 1.0, 0.0, 1.0))
    assert shifted(Step(pts), (0.0, 1.0, 0.0)).sample(3.0)[1][0] == 1.0
    assert shifted(Waypoints(pts), (2.0, 0.0, 0.0)).sample(2.0)[0][0] == 3.0
    smooth = Smooth((Knot(0.0, 0.0, 0.0, 1.0), Knot(4.0, 2.0, 0.0, 1.0)))
    ms = shifted(smooth, (0.0, 3.0, 0.0))
    assert isinstance(ms, Smooth) and math.isclose(ms.sample(1.0)[1][0], smooth.sample(1.0)[1][0] + 3.0)


def test_a_reference_written_in_python_cannot_be_moved() -> None:
    class Mine:
        def sample(self, t: float) -> tuple:
            return Sine().sample(t)

    with pytest.raises(ConfigError, match="cannot be moved by an offset"):
        shifted(Mine(), (1.0, 0.0, 0.0), "m.toml")  # type: ignore[arg-type]


def test_a_vehicles_mission_is_the_missions_moved_with_its_own_seed() -> None:
    m = replace(load_mission("missions/sine.toml"), vehicles=formation(3, "line:2"))
    one, two, three = (vehicle_mission(m, v) for v in m.vehicles)
    assert one.trajectory == Sine() and one.start == m.start and one.seed == m.seed and one.vehicles == ()
    assert two.trajectory == Sine(y0=2.0) and two.start == (0.0, 2.0, 0.0, 0.0) and two.seed == m.seed + 1
    assert three.seed == m.seed + 2 and three.separation is None
    own = VehicleSpec(2, start=(1.0, 1.0, 0.0, 0.5), trajectory=Step((Setpoint(0.0, 1.0, 1.0, 1.0),)),
                      profile="x500", controller="pid")
    v = vehicle_mission(m, own)
    assert v.start == (1.0, 1.0, 0.0, 0.5) and v.profile == "x500" and v.controller == "pid"


def test_a_vehicle_moved_out_of_the_envelope_is_refused() -> None:
    m = replace(load_mission("missions/sine.toml"), vehicles=(VehicleSpec(1, (0.0, 99.5, 0.0)),))
    with pytest.raises(ConfigError, match="trajectory.amplitude: .*outside the plant's envelope"):
        vehicle_mission(m, m.vehicles[0])


def test_link_seeds_named_by_the_mission_are_moved_per_vehicle() -> None:
    link = {"seed": 7, "up": {"seed": 2147483647, "loss_pct": 5.0}, "down": {"delay_ms": 3.0}}
    assert link_seeds_moved(link, 0) is link
    moved = link_seeds_moved(link, 2)
    assert moved == {"seed": 9, "up": {"seed": 1, "loss_pct": 5.0}, "down": {"delay_ms": 3.0}}
    assert link["seed"] == 7  # the mission's own table is not touched
    assert link_seeds_moved({"seed": "x"}, 1) == {"seed": "x"}  # the link's own check names it


def test_the_disc_radius_is_the_arm_and_a_rotor_half_the_arm_by_default() -> None:
    assert Separation().min_m == DEFAULT_MIN_SEPARATION_M == 0.5
    assert Separation().disc_radius(0.2) == pytest.approx(0.3)
    assert Separation(rotor_radius_m=0.127).disc_radius(0.25) == pytest.approx(0.377)


def test_the_shipped_fleet_examples_load(tmp_path: Path) -> None:
    for name in ("swarm-near-miss", "swarm-touch", "swarm-stacked", "swarm-takeover"):
        m = load_mission(Path(__file__).parents[1] / "examples" / f"{name}.toml")
        assert [v.id for v in m.vehicles] == [1, 2] and m.vehicles[1].trajectory is not None
