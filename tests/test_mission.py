"""Covers missions.mission: mission files load, validate and round-trip through params.dump_toml.

Each bad value raises params.ConfigError naming the file and the key; the tables owned by
other parts ([effects], [gains], [failsafe]) are validated when a run is built
(bridge.core.flight.prepare), still naming the file and the key.
"""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import pytest

from bridge import simulate
from bridge.core.flight import prepare
from bridge.record.runlog import run_dir
from missions import MISSION_DIR, Mission, Setpoint, Sine, Step, Waypoints, load_mission, mission_from_table
from missions.envelope import ENVELOPE_RADIUS_M
from params import ConfigError, dump_toml
from plant import Quadrotor, load_profile

SHIPPED = sorted(MISSION_DIR.glob("*.toml"))
STEP_TEXT = (MISSION_DIR / "step.toml").read_text()
SINE_TEXT = (MISSION_DIR / "sine.toml").read_text()


def test_shipped_missions_load_and_build() -> None:
    assert {p.stem for p in SHIPPED} >= {"step", "sine", "robust", "waypoints"}
    for path in SHIPPED:
        m = load_mission(path)
        assert m.name == path.stem and m.source == str(path)
        flight = prepare(m)  # profile, effects, gains and failsafe validated too
        assert flight.substeps == 4 and m.steps == int(round(m.duration_s * 250))


def test_the_paper_scenarios() -> None:
    step = load_mission(MISSION_DIR / "step.toml")
    assert step.duration_s == 30.0 and step.start == (0.0, 0.0, 0.0, 0.0)
    assert step.trajectory == Step((
        Setpoint(0.0, 1.0, 1.0, 1.0, math.pi / 4),
        Setpoint(10.0, -1.0, 2.0, 2.0, 0.0),
        Setpoint(20.0, 0.0, 0.0, 1.5, -math.pi / 4),
    ))
    sine = load_mission(MISSION_DIR / "sine.toml")
    assert sine.duration_s == 30.0 and sine.trajectory == Sine(1.0, 0.5, 0.1, 0.0, 0.0)
    robust = prepare(MISSION_DIR / "robust.toml")
    e = robust.effects
    assert e.drag and e.mass_scale == 1.2 and e.inertia_scale == 1.2
    assert e.disturbance.force_amp == (0.5,) * 3 and e.disturbance.torque_amp == (0.2,) * 3


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.stem)
def test_round_trip_through_dump_toml(path: Path) -> None:
    m = load_mission(path)
    again = mission_from_table(tomllib.loads(dump_toml(m.to_dict())), "again.toml")
    assert again.to_dict() == m.to_dict()
    assert again.trajectory == m.trajectory


def test_round_trip_of_a_scripted_mission() -> None:
    m = Mission(
        Waypoints((Setpoint(0.0, 0.0, 0.0, 0.0), Setpoint(4.0, 1.0, -2.0, 3.0, 1.0))),
        duration_s=6.0,
        name="scripted",
        profile="x500",
        actuation="wrench",
        controller="smc",
        rate_hz=500.0,
        physics_hz=2000.0,
        seed=7,
        start=(0.5, -0.5, 0.0, 0.25),
        gains={"z": {"c": 2.5}, "limits": {"tilt_max": 0.5}},
        effects={"drag": True, "disturbance": {"force": [0.1, 0.0, -0.2], "random_phase": True}},
        failsafe={"timeout_s": 0.2},
    )
    again = mission_from_table(tomllib.loads(dump_toml(m.to_dict())), "again.toml")
    assert again.to_dict() == m.to_dict()
    for field in ("trajectory", "duration_s", "profile", "actuation", "controller", "rate_hz", "seed", "start"):
        assert getattr(again, field) == getattr(m, field)
    prepare(again)


def _write(tmp_path: Path, text: str, name: str = "bad.toml") -> Path:
    f = tmp_path / name
    f.write_text(text)
    return f


def _fails(path: Path, key: str, words: str = "") -> str:
    with pytest.raises(ConfigError) as exc:
        prepare(path)
    msg = str(exc.value)
    assert msg.startswith(f"{path}: {key}:"), msg
    assert words in msg, msg
    return msg


@pytest.mark.parametrize(
    "old, new, key, words",
    [
        ("duration_s = 30.0", "duration_s = -5.0", "duration_s", "(0, 86400]"),
        ("duration_s = 30.0", "duration_s = 0", "duration_s", "(0, 86400]"),
        ("duration_s = 30.0", 'duration_s = "long"', "duration_s", "expected a number"),
        ("duration_s = 30.0", "", "duration_s", "is required"),
        ("rate_hz = 250", "rate_hz = 5", "rate_hz", "[50, 1000]"),
        ("rate_hz = 250", "rate_hz = 300", "rate_hz", "whole multiple"),
        ("seed = 0", "seed = -1", "seed", "[0, 2147483647]"),
        ("seed = 0", "seed = 1.5", "seed", "expected an integer"),
        ('controller = "bsst"', 'controller = "lqr"', "controller", "bsst, smc, pid"),
        ('profile = "paper"', 'profile = "f450"', "profile", "unknown profile"),
        ('profile = "paper"', "profile = 3", "profile", "expected a string"),
        ('name = "step"', 'name = "step"\nweather = 3', "weather", "unknown key"),
        ('kind = "step"', 'kind = "spiral"', "trajectory.kind", "step, sine, waypoints"),
        ("setpoints = [", "points = [", "trajectory.setpoints", "non-empty list"),
        ("{ t = 10.0,", "{ t = 40.0,", "trajectory.setpoints[1].t", "[0, 30]"),
        ("{ t = 20.0,", "{ t = 5.0,", "trajectory.setpoints[2].t", "later than"),
        ("x = -1.0,", 'x = "left",', "trajectory.setpoints[1].x", "expected a number"),
        ("y = 2.0,", "y = 2.0, w = 1,", "trajectory.setpoints[1].w", "unknown key"),
        ("z = 1.5,", "", "trajectory.setpoints[2].z", "is required"),
    ],
)
def test_bad_step_mission(tmp_path: Path, old: str, new: str, key: str, words: str) -> None:
    assert old in STEP_TEXT
    _fails(_write(tmp_path, STEP_TEXT.replace(old, new, 1)), key, words)


WAYPOINTS = '[trajectory]\nkind = "waypoints"\npoints = [{ t = 0, x = 0, y = 0, z = 0, psi = %s }, ' \
            '{ t = 5, x = 0, y = 0, z = 1, psi = %s }, { t = 10, x = 0, y = 0, z = 1, psi = %s }]\n'
FLEET = '[[vehicles]]\nid = 1\n[[vehicles]]\nid = 2\nstart = { position = [0, 2, 0], psi = %s }\n'


@pytest.mark.parametrize("text, key, said", [
    (SINE_TEXT.replace("psi = 0.0", "psi = 90"), "trajectory.psi", "[-6.2832, 6.2832] (radians; a QGC plan's yaw, "
     "param4, is degrees), got 90"),
    (SINE_TEXT + "[start]\npsi = -7\n", "start.psi", "[-2π, 2π]"),
    (SINE_TEXT + FLEET % 180, "vehicles[1].start.psi", "got 180"),
    (SINE_TEXT.split("[trajectory]")[0] + WAYPOINTS % (45, 0, 0), "trajectory.points[0].psi", "got 45"),
    (SINE_TEXT.split("[trajectory]")[0] + WAYPOINTS % (0, 90, 0), "trajectory.points[1].psi", "within 2π = 6.2832 "
     "(one turn) of the point before's 0 (radians; a QGC plan's yaw, param4, is degrees), got 90"),
])
def test_a_yaw_in_degrees_is_refused_saying_radians(tmp_path: Path, text: str, key: str, said: str) -> None:
    """A yaw is radians: ``psi = 90`` flew 90 rad, 14 turns, exit 0, until the third wave's fortieth session. One
    turn either way (a start's, a sine's, a first point's), and a point's within one turn of the one before."""
    _fails(_write(tmp_path, text), key, said)


def test_a_list_of_points_may_turn_on_one_turn_at_a_time(tmp_path: Path) -> None:
    """Points unwrapped along their way (a plan's knots in a run's mission.toml) stay flyable past 2π."""
    text = SINE_TEXT.split("[trajectory]")[0] + WAYPOINTS % (0, 6, 12)
    assert [p.psi for p in prepare(_write(tmp_path, text)).mission.trajectory.points] == [0.0, 6.0, 12.0]


@pytest.mark.parametrize(
    "old, new, key, words",
    [
        ("amplitude = 1.0", "amplitude = -1.0", "trajectory.amplitude", "[0, 10000]"),
        ("climb = 0.1", "climb = 0.1\nphase = 1.0", "trajectory.phase", "unknown key"),
        ("", "[effects]\ndrag = 1\n", "effects.drag", "true or false"),
        ("", "[effects]\nwind = true\n", "effects.wind", "unknown key"),
        ("", "[effects.mismatch]\nmass_scale = 0.0\n", "effects.mismatch.mass_scale", "[0.1, 10]"),
        ("", "[effects.disturbance]\nforce = [1.0, 2.0]\n", "effects.disturbance.force", "list of 3"),
        ("", "[effects.disturbance]\nforce_amplitude = [-1.0, 0, 0]\n", "effects.disturbance.force_amplitude",
         "element 0"),
        ("", "[gains.z]\nk1 = 1.0\n", "gains.z.k1", "eq. (23)"),
        ("", "[gains.attitude]\nalpha = 1.2\n", "gains.attitude.alpha", "(0.5, 1)"),
        ("", "[failsafe]\ntimeout_s = 0\n", "failsafe.timeout_s", "[0.01, 60]"),
        ("", "[start]\nposition = [0, 0]\n", "start.position", "list of 3"),
        ("", "effects = 3\n", "effects", "expected a table"),
    ],
)
def test_bad_sine_mission(tmp_path: Path, old: str, new: str, key: str, words: str) -> None:
    assert old in SINE_TEXT
    text = SINE_TEXT.replace(old, new, 1) if old else SINE_TEXT + new
    if new.startswith("effects = "):  # a top-level key must come before the first table
        text = new + SINE_TEXT
    _fails(_write(tmp_path, text), key, words)


def test_trajectory_shapes(tmp_path: Path) -> None:
    body = 'name = "m"\nduration_s = 10.0\n'
    _fails(_write(tmp_path, body), "trajectory", "is required")
    _fails(_write(tmp_path, body + "trajectory = 3\n"), "trajectory", "expected a table")
    _fails(_write(tmp_path, body + '[trajectory]\nkind = "step"\nsetpoints = []\n'), "trajectory.setpoints",
           "non-empty list")
    _fails(_write(tmp_path, body + '[trajectory]\nkind = "waypoints"\npoints = 5\n'), "trajectory.points",
           "non-empty list")
    _fails(_write(tmp_path, body + '[trajectory]\nkind = "step"\nsetpoints = [1, 2]\n'), "trajectory.setpoints[0]",
           "expected a table")
    _fails(_write(tmp_path, body + "[trajectory]\n"), "trajectory.kind", "is required")


def test_missing_file_and_non_toml(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"nope\.toml: no such file$"):
        load_mission(tmp_path / "nope.toml")
    with pytest.raises(ConfigError, match=r"junk\.toml: not valid TOML"):
        load_mission(_write(tmp_path, "this is not toml\n", "junk.toml"))
    with pytest.raises(ConfigError, match=r"png\.toml: not a text file"):
        p = tmp_path / "png.toml"
        p.write_bytes(b"\x89PNG\r\n\x1a\n\xff\xff")
        load_mission(p)
    with pytest.raises(ConfigError, match="is a directory"):
        load_mission(tmp_path)


def test_a_choice_and_a_long_key_read_plainly_in_the_message(tmp_path: Path) -> None:
    """The default's own choice "" is shown as '' (it read "must be one of , wrench, motors"); a key of 100 000
    characters is shown by its start, end and length, not echoed whole (a 100 kB line)."""
    body = 'name = "m"\nduration_s = 2.0\n[trajectory]\nkind = "sine"\n'
    with pytest.raises(ConfigError, match=r"actuation: must be one of '', wrench, motors; got 'jets'$"):
        load_mission(_write(tmp_path, 'actuation = "jets"\n' + body))
    with pytest.raises(ConfigError) as err:
        load_mission(_write(tmp_path, "k" * 100_000 + " = 1\n" + body))
    assert len(str(err.value)) < 500 and "(100000 characters): unknown key" in str(err.value), str(err.value)[:200]


def test_a_required_key_given_without_its_unit_is_named_as_given(tmp_path: Path) -> None:
    """``t = 1.0`` in an event, ``duration = 2`` at the top: the key as written, and the one meant (it said the
    meant key "is required", with no word of the one given)."""
    body = '[trajectory]\nkind = "sine"\n'
    with pytest.raises(ConfigError, match=r"events\[0\]\.t: unknown key in \[events\[0\]\]; did you mean 't_s' \(the "
                                          r"unit is in the name\)\?$"):
        prepare(_write(tmp_path, 'duration_s = 2.0\n' + body + '[[events]]\nt = 1.0\nkind = "wind"\n'
                                                                'speed_mps = 3.0\n'))  # (events: read by prepare)
    with pytest.raises(ConfigError, match=r": duration: unknown key at the top level; did you mean 'duration_s'"):
        load_mission(_write(tmp_path, "duration = 2.0\n" + body))


def test_scripted_missions_are_validated_too() -> None:
    with pytest.raises(ConfigError, match=r"^<python>: duration_s:"):
        Mission(Sine(), duration_s=-1.0)
    with pytest.raises(ConfigError, match=r"^<python>: rate_hz:"):
        Mission(Sine(), duration_s=10.0, rate_hz=5.0)
    with pytest.raises(ConfigError, match=r"^<python>: controller:"):
        Mission(Sine(), duration_s=10.0, controller="lqr")
    m = Mission(Sine(), duration_s=10.0)
    with pytest.raises(ConfigError, match=r"duration_s"):
        m.with_overrides(duration_s=float("nan"))
    assert m.with_overrides(rate_hz=500.0, seed=None).rate_hz == 500.0


def test_a_python_missions_physics_hz_is_named_as_its_field() -> None:
    """``Mission(..., physics_hz=...)`` from Python: a physics rate the control rate (here the default 250 Hz) is
    no whole divisor of names the field that set it, ``(physics_hz)``, in a Mission and with a ``rate_hz`` laid over
    one; a value that is no number names its field too. Until the third wave's fortieth session the first read
    ``<python>: rate_hz: the physics rate 1001 Hz must be ..., got 250``, naming only the field left alone, and text
    (or None) gave a TypeError naming none (``'<=' not supported between instances of 'float' and 'str'``)."""
    with pytest.raises(ConfigError) as e:
        Mission(Sine(), duration_s=10.0, physics_hz=1001.0)
    said = str(e.value)
    assert said.startswith("<python>: rate_hz: the physics rate 1001 Hz (physics_hz) must be a whole multiple of it "
                           "(allowed: 1001 Hz divided by a whole number, 50-1000 Hz; the whole ones 77, 91, 143)"), said
    assert said.endswith(", got 250"), said
    with pytest.raises(ConfigError, match=r"^<python>: rate_hz: the physics rate 800 Hz \(physics_hz\) must be"):
        simulate(Mission(Sine(), duration_s=1.0, physics_hz=800.0, rate_hz=200.0), rate_hz=300.0, plots=False)
    with pytest.raises(ConfigError, match=r"^<python>: physics_hz: must be in \[100, 10000\], got 50$"):
        Mission(Sine(), duration_s=10.0, physics_hz=50.0)
    for field, value, unit in (("physics_hz", "1000", "Hz"), ("physics_hz", None, "Hz"), ("physics_hz", True, "Hz"),
                               ("rate_hz", "250", "Hz"), ("duration_s", "10", "s")):
        with pytest.raises(ConfigError) as e:
            Mission(Sine(), **{"duration_s": 10.0, field: value})
        assert str(e.value) == f"<python>: {field}: expected a number ({unit}), got {value!r}", e.value


# -- issue 11: what is accepted can be flown; a name names one directory ---------------------------------
def test_the_envelope_is_the_plants() -> None:
    """The loader's envelope is where the plant's own divergence check trips, in every direction."""
    q = Quadrotor(load_profile("paper"))
    for direction in ((1.0, 0.0, 0.0), (0.0, -1.0, 0.0), (0.0, 0.0, 1.0), (0.6, 0.0, -0.8)):
        for scale, lost in ((0.999, False), (1.001, True)):
            x, y, z = (scale * ENVELOPE_RADIUS_M * c for c in direction)
            q.state = (x, 0.0, y, 0.0, z, 0.0) + (0.0,) * 6  # type: ignore[assignment]
            assert (q.diverged() == "position beyond 100 m") is lost, (direction, scale)


def test_a_set_point_at_the_envelope_flies() -> None:
    """99 m out is accepted and flown to the end (the law does not overshoot it into divergence)."""
    run = simulate(Mission(Step((Setpoint(0.0, 99.0, 0.0, 2.0),)), duration_s=30.0, name="edge"))
    assert run.outcome == "completed" and abs(run.trace["x"][-1] - 99.0) < 0.01


SINE_BODY = 'name = "m"\nduration_s = 300.0\n[trajectory]\nkind = "sine"\n'


@pytest.mark.parametrize("text, key, words", [
    ('name = "m"\nduration_s = 30.0\n[trajectory]\nkind = "step"\nsetpoints = [{ t = 0.0, x = 150.0, y = 0.0, '
     'z = 2.0 }]\n', "trajectory.setpoints[0]", "150 m from the origin"),
    ('name = "m"\nduration_s = 30.0\n[trajectory]\nkind = "step"\nsetpoints = [{ t = 0.0, x = 1.0, y = 0.0, z = 1.0 },'
     ' { t = 5.0, x = 80.0, y = 80.0, z = 2.0 }]\n', "trajectory.setpoints[1]", "113.2 m"),
    ('name = "m"\nduration_s = 30.0\n[trajectory]\nkind = "waypoints"\npoints = [{ t = 0.0, x = 0.0, y = 0.0, '
     'z = 0.0 }, { t = 9.0, x = 0.0, y = 0.0, z = 101.0 }]\n', "trajectory.points[1]", "101 m"),
    (SINE_BODY + "amplitude = 120.0\nclimb = 0.0\n", "trajectory.amplitude", "120 m"),
    (SINE_BODY + "z0 = 99.9\namplitude = 5.0\nclimb = 0.0\n", "trajectory.z0", "100 m from the origin"),
    (SINE_BODY + "climb = 0.5\n", "trajectory.climb", "at t = 300 s (z = 150 m)"),
    (SINE_BODY + "climb = -0.5\nz0 = 10.0\n", "trajectory.climb", "(z = -140 m)"),
    ('name = "m"\nduration_s = 30.0\n[start]\nposition = [0.0, 0.0, 101.0]\n[trajectory]\nkind = "sine"\n',
     "start.position", "101 m"),
])
def test_a_reference_outside_the_envelope_is_refused(tmp_path: Path, text: str, key: str, words: str) -> None:
    msg = _fails(_write(tmp_path, text), key, words)
    assert "envelope of 100 m" in msg and "diverged" in msg


def test_a_python_mission_outside_the_envelope_is_refused() -> None:
    with pytest.raises(ConfigError, match=r"^<python>: trajectory\.setpoints\[0\]: .*envelope of 100 m"):
        Mission(Step((Setpoint(0.0, 0.0, 0.0, 150.0),)), duration_s=10.0)
    with pytest.raises(ConfigError, match=r"^<python>: start\.position: "):
        Mission(Sine(), duration_s=10.0, start=(0.0, 0.0, 200.0, 0.0))
    Mission(Sine(amplitude=3.0, climb=-1.0, z0=90.0), duration_s=90.0)  # z from 90 m down to the ground: inside


_WAYPOINTS = ('name = "m"\nduration_s = 6.0\n[trajectory]\nkind = "waypoints"\n'
              'points = [{ t = 0.0, x = 0.0, y = 0.0, z = 0.0 }, ')


@pytest.mark.parametrize("text, key, words", [
    (_WAYPOINTS + '{ t = 2.0, x = 0.0, y = 0.0, z = -3.0 }]\n', "trajectory.points[1]", "(0, 0, -3) is at z = -3 m"),
    ('name = "m"\nduration_s = 6.0\n[trajectory]\nkind = "step"\nsetpoints = [{ t = 0.0, x = 0.0, y = 0.0, '
     'z = -0.5 }]\n', "trajectory.setpoints[0]", "z = -0.5 m"),
    (SINE_BODY + "z0 = -1.0\n", "trajectory.z0", "at t = 0 is at z = -1 m"),
    (SINE_BODY + "z0 = 1.0\nclimb = -0.01\n", "trajectory.climb", "at t = 300 s the reference is at z = -2 m"),
    ('name = "m"\nduration_s = 6.0\n[start]\nposition = [0.0, 0.0, -0.2]\n[trajectory]\nkind = "sine"\n',
     "start.position", "the start is at z = -0.2 m"),
])
def test_a_reference_or_start_below_the_ground_is_refused(tmp_path: Path, text: str, key: str, words: str) -> None:
    """A vehicle on the ground cannot follow a reference under it: it used to fly 'completed', exit 0, with an RMS
    of metres (the waypoints 3 m under the start: 2.38 m)."""
    assert "below the ground" in _fails(_write(tmp_path, text), key, words)
    Mission(Waypoints((Setpoint(0.0, 0.0, 0.0, 0.0), Setpoint(2.0, 0.0, 0.0, 0.0))), duration_s=4.0)  # on it: taken


@pytest.mark.parametrize("name, words", [
    ("../../escape", "must not contain /"), ("a/b", "must not contain /"), ("a\\\\b", "must not contain /"),
    ("a\\nb", "must be printable"), ("tab\\there", "must be printable"), ("   ", "must not be blank"),
    ("x" * 101, "at most 100 bytes"), ("é" * 51, "at most 100 bytes"),
])
def test_a_name_that_is_not_one_safe_directory_name_is_refused(tmp_path: Path, name: str, words: str) -> None:
    _fails(_write(tmp_path, f'name = "{name}"\nduration_s = 1.0\n[trajectory]\nkind = "sine"\n'), "name", words)


def test_a_name_with_spaces_dots_and_accents_is_one_directory(tmp_path: Path) -> None:
    m = prepare(_write(tmp_path, 'name = "..été 2 ..."\nduration_s = 1.0\n[trajectory]\nkind = "sine"\n')).mission
    assert m.name == "..été 2 ..."
    path = run_dir(None, m.name, root=tmp_path / "runs", create=False)
    assert path.parent == tmp_path / "runs" and path.name.endswith("-..été 2 ...")
    with pytest.raises(ConfigError, match="mission name: must not contain /"):
        run_dir(None, "../x", root=tmp_path / "runs", create=False)  # the one place a name becomes a path


def test_a_blackout_after_the_end_is_refused(tmp_path: Path) -> None:
    body = 'name = "m"\nduration_s = 5.0\n[trajectory]\nkind = "sine"\n'
    msg = _fails(_write(tmp_path, body + "[link]\nblackouts = [[1.0, 0.5], [5.0, 1.0]]\n"), "link.blackouts",
                 "the window [5, 6) s starts after the mission's end (duration_s = 5 s)")
    _fails(_write(tmp_path, body + "[link.down]\nblackouts = [[7.5, 1.0]]\n"), "link.down.blackouts", "[7.5, 8.5)")
    with pytest.raises(ConfigError, match=r"--blackout/--up-blackout \(link\.up\.blackouts\): the window \[40, 41\) s"):
        prepare(MISSION_DIR / "sine.toml", link={"up": {"blackouts": [[40.0, 1.0]]}})  # as --up-blackout 40:1
    profile = tmp_path / "late.toml"  # a profile's (a fitted trace's outage): its file and key, not the mission's
    profile.write_text("[link]\ndelay_ms = 3\n[link.up]\nblackouts = [[40.0, 1.0]]\n")
    with pytest.raises(ConfigError, match=rf"^{profile}: link\.up\.blackouts \(the flight's link profile\): the "
                                          r"window \[40, 41\) s starts after the mission's end"):
        prepare(MISSION_DIR / "sine.toml", link={"profile": str(profile)})  # as --link-profile FILE
    assert "never happen" in msg
    ends_late = prepare(_write(tmp_path, body + "[link]\nblackouts = [[4.0, 100.0]]\n"))  # running past the end: fine
    assert ends_late.link.up.blackouts == ((4.0, 100.0),)


def test_a_plan_file_that_is_not_there_is_named_as_the_missions_key(tmp_path: Path) -> None:
    """It said ``.../box.plan: no such file``, naming no key of the mission that gave it, until the third wave's
    fortieth session."""
    path = _write(tmp_path, 'name = "box"\n[trajectory]\nkind = "plan"\nfile = "box.plan"\n')
    with pytest.raises(ConfigError) as exc:
        load_mission(path)
    assert str(exc.value) == f"{path}: trajectory.file: {tmp_path / 'box.plan'}: no such file"
