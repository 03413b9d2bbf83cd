"""Covers missions.mission, bridge.autopilot.params, bridge.core.overrides, bridge.record.outlock and params.text: a
Mission built in Python is refused where a mission file is, by the file's own readers and ranges, naming the field as
the file's key; a mission or ``out`` of the wrong type is a TypeError naming it.

``Mission(seed="x")``, ``Mission(Sine(psi=90), ...)``, a start's psi of 90, a set-point's text were taken (the seed
failed later as ``link.seed``, a key the caller never gave; text in a sine failed deep in the law with a TypeError;
a yaw in degrees flew 14 turns): each is a :class:`params.ConfigError` now, before anything flies. A ``[params]``
name in another case (``com_of_loss_t``), in a file, a Mission, ``params=`` or ``--param``, is told the name it
means, as an unknown key of a table is; a plan's PX4 limit put in ``[params]`` is told where it goes.
"""

from __future__ import annotations

import dataclasses
import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from bridge import simulate
from bridge.autopilot.params import ParamChange, parse_assignment
from bridge.core.flight import prepare
from bridge.core.overrides import Overrides
from missions import MISSION_DIR, Mission, Setpoint, Sine, Step, Waypoints, load_mission
from missions.fleet import Separation, VehicleSpec
from params import ConfigError

PSI = "must be in [-2π, 2π] = [-6.2832, 6.2832] (radians; a QGC plan's yaw, param4, is degrees), got 90"


@pytest.mark.parametrize("seed, said", [
    ("x", "seed: expected an integer, got 'x'"),
    (1.5, "seed: expected an integer, got 1.5"),
    (True, "seed: expected an integer, got True"),
    (-1, "seed: must be in [0, 2147483647], got -1"),
    (2**31, "seed: must be in [0, 2147483647], got 2147483648"),
])
def test_a_seed_is_refused_as_a_files_seed_is(tmp_path: Path, seed: object, said: str) -> None:
    """The file's message for the file's ``seed = ...``, the field's for the field (it was taken, and failed once
    flown as ``<python>: link.seed: ...``)."""
    with pytest.raises(ConfigError) as e:
        Mission(Sine(), duration_s=1.0, seed=seed)  # type: ignore[arg-type]
    assert str(e.value) == f"<python>: {said}"
    with pytest.raises(ConfigError) as e:
        Mission(Sine(), duration_s=1.0).with_overrides(seed=seed)
    assert str(e.value) == f"<python>: {said}"
    if not isinstance(seed, str):  # the file refuses the same value in the same words
        f = tmp_path / "m.toml"
        text = (MISSION_DIR / "sine.toml").read_text()
        f.write_text(re.sub(r"(?m)^seed = .*$", f"seed = {str(seed).lower()}", text))
        with pytest.raises(ConfigError) as e:
            load_mission(f)
        assert str(e.value) == f"{f}: {said}"
    assert Mission(Sine(), duration_s=1.0, seed=np.int64(7)).seed == 7  # numpy's integers are integers


@pytest.mark.parametrize("make, key", [
    (lambda: Mission(Sine(psi=90), duration_s=1.0), "trajectory.psi"),
    (lambda: Mission(Sine(), duration_s=1.0, start=(0.0, 0.0, 0.0, 90)), "start.psi"),
    (lambda: Mission(Step((Setpoint(0.0, 0.0, 0.0, 1.0, 90),)), duration_s=1.0), "trajectory.setpoints[0].psi"),
    (lambda: Mission(Waypoints((Setpoint(0.0, 0.0, 0.0, 1.0, 90),)), duration_s=1.0), "trajectory.points[0].psi"),
])
def test_a_yaw_in_degrees_is_refused_from_python_saying_radians(make, key: str) -> None:
    with pytest.raises(ConfigError) as e:
        make()
    assert str(e.value) == f"<python>: {key}: {PSI}"


def test_a_list_of_points_may_turn_on_one_turn_at_a_time_from_python_too() -> None:
    turns = tuple(Setpoint(float(i), 0.0, 0.0, 1.0, 6.0 * i) for i in range(3))  # 12 rad: past 2π, a turn at a time
    assert Mission(Waypoints(turns), duration_s=3.0).trajectory == Waypoints(turns)
    jump = (Setpoint(0.0, 0.0, 0.0, 1.0, 0.0), Setpoint(1.0, 0.0, 0.0, 1.0, 7.0))
    with pytest.raises(ConfigError, match=r"^<python>: trajectory\.points\[1\]\.psi: must be within 2π = 6\.2832 "
                                          r"\(one turn\) of the point before's 0 .*, got 7$"):
        Mission(Waypoints(jump), duration_s=3.0)


@pytest.mark.parametrize("make, said", [
    (lambda: Mission(Sine(psi="x"), duration_s=1.0), "trajectory.psi: expected a number, got 'x'"),  # type: ignore
    (lambda: Mission(Sine(omega=1000.0), duration_s=1.0), "trajectory.omega: must be in [0, 100], got 1000"),
    (lambda: Mission(Sine(amplitude=-1.0), duration_s=1.0), "trajectory.amplitude: must be in [0, 10000], got -1"),
    (lambda: Mission(Sine(z0=math.nan), duration_s=1.0), "trajectory.z0: must be finite, got nan"),
    (lambda: Mission(Step((Setpoint(-1.0, 0.0, 0.0, 1.0),)), duration_s=1.0),
     "trajectory.setpoints[0].t: must be in [0, 86400], got -1"),
    (lambda: Mission(Step((Setpoint(0.0, "a", 0.0, 1.0),)), duration_s=1.0),  # type: ignore[arg-type]
     "trajectory.setpoints[0].x: expected a number, got 'a'"),
    (lambda: Mission(Sine(), duration_s=1.0, start=(0.0, 0.0, 0.0)),  # type: ignore[arg-type]
     "start: expected (x, y, z, psi): 4 numbers (m, m, m, rad), got (0.0, 0.0, 0.0)"),
    (lambda: Mission(Sine(), duration_s=1.0, start=(0.0, "a", 0.0, 0.0)),  # type: ignore[arg-type]
     "start.position: element 1 must be a finite number, got 'a'"),
    (lambda: Mission(Sine(), duration_s=1.0, start=np.array([0.0, 0.0, 1.0])),  # type: ignore[arg-type]
     "start: expected (x, y, z, psi): 4 numbers (m, m, m, rad), got array([0., 0., 1.])"),
    (lambda: Mission(Sine(), duration_s=1.0, start="abcd"),  # type: ignore[arg-type]
     "start: expected (x, y, z, psi): 4 numbers (m, m, m, rad), got 'abcd'"),
    (lambda: Mission(Sine(), duration_s=1.0, start=np.array(["0", "0", "1", "0"])),  # type: ignore[arg-type]
     "start.position: element 0 must be a finite number, got np.str_('0')"),
    (lambda: Mission(Sine(), duration_s=1.0, vehicles=(VehicleSpec(1, start=np.zeros(3)),)),  # type: ignore
     "vehicles[0].start: expected (x, y, z, psi): 4 numbers (m, m, m, rad), got array([0., 0., 0.])"),
    (lambda: Mission(Sine(), duration_s=1.0, start_scatter_m="wide"),  # type: ignore[arg-type]
     "start.scatter_m: expected a number (m), got 'wide'"),
    (lambda: Mission(3, duration_s=1.0),  # type: ignore[arg-type]
     "trajectory: expected a reference (Sine, Step, Waypoints, or an object with sample, change_times and to_dict: "
     "missions.references.Reference), got 3"),
    (lambda: Mission(Sine(), duration_s=1.0, link=3), "link: expected a table (a mapping), got 3"),  # type: ignore
    (lambda: Mission(Sine(), duration_s=1.0, source=3),  # type: ignore[arg-type]
     "source: expected a string (the mission's file, or '<python>': its errors name it), got 3"),
    (lambda: Mission(Sine(), duration_s=1.0, actuation="rotors"),
     "actuation: must be one of '', wrench, motors; got 'rotors'"),
    (lambda: Mission(Sine(), duration_s=1.0, profile=3), "profile: expected a string, got 3"),  # type: ignore
    (lambda: Mission(Sine(), duration_s=1.0, events=3),  # type: ignore[arg-type]
     "events: expected a tuple of tables (t_s, kind and its settings), got 3"),
    (lambda: Mission(Sine(), duration_s=1.0, vehicles=3),  # type: ignore[arg-type]
     "vehicles: expected a tuple of missions.fleet.VehicleSpec, got 3"),
    (lambda: Mission(Sine(), duration_s=1.0, geofence=3), "geofence: expected a missions.geofence.Geofence, got 3"),
    (lambda: Mission(Sine(), duration_s=1.0, rally=3),  # type: ignore[arg-type]
     "rally: expected a tuple of (x, y) points (m), got 3"),
    (lambda: Mission(Sine(), duration_s=1.0, rally=((1.0,),)),  # type: ignore[arg-type]
     "rally.points: point 0: expected [x, y], finite, within 100 m of the home (the plant's envelope), got [1.0]"),
])
def test_what_a_file_refuses_is_refused_from_python_naming_the_field(make, said: str) -> None:
    """Each was taken, then failed deep inside with a TypeError or AttributeError naming no field (text in a sine:
    the law's ``unsupported operand type(s) for -``; a set-point's text: the envelope's ``can't multiply sequence``;
    ``link=3``: ``'int' object has no attribute 'items'``; ``vehicles=3``: ``'int' object is not iterable``;
    ``geofence=3`` once flown: ``'int' object has no attribute 'first_breach'``; ``source=3`` once flown, until the
    third wave's forty-second session: pathlib's ``expected str, bytes or os.PathLike object, not int``), or flew
    (omega 1000 rad/s, a nan z0, a time of -1 s, ``rally=3``, a rally point ``(1.0,)``), or failed once flown naming
    no field (``actuation must be one of wrench, motors; got 'rotors'``) or the wrong one (``profile: unknown profile
    '3'``)."""
    with pytest.raises(ConfigError) as e:
        make()
    assert str(e.value) == f"<python>: {said}"


RALLY = "within 100 m of the home (the plant's envelope)"


@pytest.mark.parametrize("make, said", [
    (lambda: Mission(Sine(), duration_s=1.0, rally=(("a", 2.0),)),  # type: ignore[arg-type]
     f"rally.points: point 0: expected [x, y], finite, {RALLY}, got ['a', 2.0]"),
    (lambda: Mission(Sine(), duration_s=1.0, rally=(1.0, 2.0)),  # type: ignore[arg-type]
     f"rally.points: point 0: expected [x, y], finite, {RALLY}, got 1.0"),
    (lambda: Mission(Sine(), duration_s=1.0, rally=((5.0, math.nan),)),
     f"rally.points: point 0: expected [x, y], finite, {RALLY}, got [5.0, nan]"),
    (lambda: Mission(Sine(), duration_s=1.0, rally="x"),  # type: ignore[arg-type]
     "rally: expected a tuple of (x, y) points (m), got 'x'"),
    (lambda: Mission(Sine(), duration_s=1.0, geofence={"x": 1}),
     "geofence: expected a missions.geofence.Geofence, got {'x': 1}"),
])
def test_a_python_missions_rally_and_geofence_are_read_as_a_files(make, said: str) -> None:
    """Each was taken: a text rally point failed once a Return flew to it (``unsupported operand type(s) for -:
    'str' and 'float'``), a bare (1, 2) with ``cannot unpack non-iterable int object``, a nan one flew, a dict as the
    geofence an ``AttributeError`` (``'dict' object has no attribute 'first_breach'``) once flown."""
    with pytest.raises(ConfigError) as e:
        make()
    assert str(e.value) == f"<python>: {said}"
    assert Mission(Sine(), duration_s=1.0, rally=((1.0, 2.0),)).rally == ((1.0, 2.0),)


def test_a_start_of_numpys_numbers_is_taken_as_a_files() -> None:
    """A start given as a numpy array (or a list of numpy numbers), the mission's or a vehicle's, is taken as the
    same numbers in a tuple, plain floats as a file's (its record's JSON writes them). The forty-first session's
    check_fields refused it (``start: expected (x, y, z, psi): 4 numbers (m, m, m, rad), got array([0, 0, 1, 0])``)
    where numpy numbers are taken elsewhere; a wrong length and text are still refused (above)."""
    m = Mission(Sine(), duration_s=1.0, start=np.array([0, 0, 1, 0]))
    assert m.start == (0.0, 0.0, 1.0, 0.0) and all(type(x) is float for x in m.start), m.start
    assert Mission(Sine(), duration_s=1.0, start=[np.float32(0.5), 0, np.int64(1), 0]).start == (0.5, 0.0, 1.0, 0.0)
    fleet = Mission(Sine(), duration_s=1.0, vehicles=(VehicleSpec(1, start=np.array([0.0, 0.0, 1.0, 0.0])),
                                                      VehicleSpec(2, offset=(0.0, 2.0, 0.0))))
    assert fleet.vehicles[0].start == (0.0, 0.0, 1.0, 0.0), fleet.vehicles[0]
    assert json.loads(json.dumps(fleet.to_dict()))["vehicles"][0]["start"] == {"position": [0.0, 0.0, 1.0], "psi": 0.0}


def test_a_files_mission_flown_shorter_from_python_keeps_its_later_points() -> None:
    """A point's time is bounded by the longest mission's from Python, not the mission's own: the step's first
    12 s (its set-point at 20 s never reached) is a mission, as tests/test_kernels.py flies it."""
    m = dataclasses.replace(load_mission(MISSION_DIR / "step.toml"), duration_s=12.0)
    assert m.trajectory.change_times() == (0.0, 10.0, 20.0)


@pytest.mark.parametrize("vehicles, separation, said", [
    ((VehicleSpec(1), VehicleSpec(5, offset=(0.0, 2.0, 0.0))), None,
     "vehicles: the ids must be 1..2, each once (they are the system ids); got 1, 5"),
    ((VehicleSpec(1), VehicleSpec(2, offset=(0.0, "a", 0.0))), None,  # type: ignore[arg-type]
     "vehicles[1].offset: element 1 must be a finite number, got 'a'"),
    ((VehicleSpec(1), 3), None, "vehicles[1]: expected a missions.fleet.VehicleSpec, got 3"),
    ((VehicleSpec(1), VehicleSpec(2, trajectory=Sine(y0=2.0, omega=1000.0))), None,
     "vehicles[1].trajectory.omega: must be in [0, 100], got 1000"),
    ((VehicleSpec(1), VehicleSpec(2, offset=(0.0, 2.0, 0.0))), Separation(min_m=-5.0),
     "separation.min_m: must be in [0, 100], got -5"),
])
def test_a_fleet_built_in_python_is_read_as_a_files_vehicles(vehicles, separation, said: str) -> None:
    """``Mission(vehicles=..., separation=...)`` as a file's ``[[vehicles]]`` and ``[separation]``: ids 1, 5 flew
    two vehicles, a text offset was a TypeError, a non-VehicleSpec an AttributeError (``'int' object has no attribute
    'controller'``), a negative separation was taken."""
    with pytest.raises(ConfigError) as e:
        Mission(Sine(), duration_s=1.0, vehicles=vehicles, separation=separation)
    assert str(e.value) == f"<python>: {said}"
    two = (VehicleSpec(1), VehicleSpec(2, offset=(0.0, 2.0, 0.0)))
    assert Mission(Sine(), duration_s=1.0, vehicles=two, separation=Separation(min_m=0.5)).vehicles == two


@pytest.mark.parametrize("name, hint", [
    ("com_of_loss_t", "; did you mean 'COM_OF_LOSS_T'?"),
    ("Com_Of_Loss_T", "; did you mean 'COM_OF_LOSS_T'?"),
    ("com_of_los_t", "; did you mean 'COM_OF_LOSS_T'?"),  # another case and one slip
    ("mpc_xy_cruise", " (a PX4 limit of a plan's trajectory: put it in a [trajectory] of kind = \"plan\" as "
                      "MPC_XY_CRUISE)"),
    ("MPC_XY_VEL_MAX", "; the vehicle has COM_OF_LOSS_T, COM_OBL_ACT, "),  # no parameter here, in any case
])
def test_a_params_name_in_another_case_is_told_the_name_it_means(tmp_path: Path, name: str, hint: str) -> None:
    """In a file's ``[params]``, a Mission's ``params``, ``params=`` and ``--param``: each said ``no such parameter;
    the vehicle has`` and all 26 names, the one meant among them in capitals."""
    f = tmp_path / "m.toml"
    f.write_text((MISSION_DIR / "sine.toml").read_text() + f"\n[params]\n{name} = 2\n")
    for build, said in ((lambda: prepare(f), f"{f}: params.{name}: no such parameter"),
                        (lambda: prepare(Mission(Sine(), duration_s=1.0, params={name: 2})),
                         f"<python>: params.{name}: no such parameter"),
                        (lambda: simulate(Mission(Sine(), duration_s=1.0), params={name: 2}, plots=False),
                         f"--param {name}=2: no such parameter"),
                        (lambda: parse_assignment(f"{name}=2"), f"{name}: no such parameter")):
        with pytest.raises(ConfigError) as e:
            build()
        assert str(e.value).startswith(said + hint), str(e.value)


@pytest.mark.parametrize("keywords, said", [
    ({"at": "2:gps:off"}, "at: expected a tuple of event tables or 'T:KIND[:ARGS]' strings, got '2:gps:off' alone"),
    ({"at": {"t_s": 2.0, "kind": "gps", "state": "off"}}, "at: expected a tuple of event tables or 'T:KIND[:ARGS]' "
     "strings, got {'t_s': 2.0, 'kind': 'gps', 'state': 'off'} alone"),
    ({"param_at": ParamChange(2.0, "COM_OF_LOSS_T", 3.0)}, "param_at: expected a tuple of ParamChange(t_s, name, "
     "value) entries, got ParamChange(t_s=2.0, name='COM_OF_LOSS_T', value=3.0) alone"),
])
def test_one_event_or_change_given_alone_is_refused_as_alone(keywords: dict, said: str) -> None:
    """``at=`` and ``param_at=`` take tuples; one entry given alone was read item by item: ``at="2:gps:off"`` was
    refused as ``--at 2: unknown event kind '' in '2'`` (its first character), a table by its keys, a ParamChange
    by its fields (the forty-first session's tour)."""
    with pytest.raises(ConfigError) as e:
        Overrides.of(**keywords)
    assert str(e.value) == said + " (a tuple of one: " + next(iter(keywords)) + "=(...,))"
    assert Overrides.of(**{k: (v,) for k, v in keywords.items()})  # a tuple of it is taken



@pytest.mark.parametrize("keywords, said", [
    ({"plots": "no"}, "plots: expected True or False, got 'no'"),
    ({"overwrite": 1}, "overwrite: expected True or False, got 1"),
    ({"vehicles": 2, "write": "yes"}, "write: expected True or False, got 'yes'"),
])
def test_a_switch_that_is_not_true_or_false_is_refused(tmp_path: Path, keywords: dict, said: str) -> None:
    """A Python caller's switch is True or False: a string is truthy (``sitl(..., realtime="no")`` flew in real time,
    the forty-second session's tour; ``sitl``'s in test_run_records). Refused before anything flies or is written."""
    with pytest.raises(ConfigError) as e:
        simulate(MISSION_DIR / "sine.toml", out=tmp_path / "run", **keywords)
    assert str(e.value) == said
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("call, said", [
    (lambda: simulate(5), "mission: expected a Mission or a path to its file, got 5"),
    (lambda: simulate(None), "mission: expected a Mission or a path to its file, got None"),
    (lambda: load_mission(["missions/sine.toml"]), "mission: expected a Mission or a path to its file, got ['missions"),
    (lambda: simulate(MISSION_DIR / "step.toml", out=5), "out: expected a directory's path, got 5"),
    (lambda: simulate(MISSION_DIR / "step.toml", out=["runs/x"]), "out: expected a directory's path, got ['runs/x']"),
])
def test_a_mission_or_out_of_the_wrong_type_is_named(call, said: str) -> None:
    """``simulate(5)``, ``sweep(None, ...)``, ``sitl(..., out=5)`` (every caller reads its mission by
    ``load_mission`` and its directory by ``run_dir`` / ``out_held``) said ``expected str, bytes or os.PathLike
    object, not int``, naming neither argument, until the third wave's forty-third session."""
    with pytest.raises(TypeError) as caught:
        call()
    assert str(caught.value).startswith(said)


def test_an_unknown_profile_laid_over_from_python_reads_as_the_flags_line() -> None:
    """``simulate(m, link={"profile": "nope"})`` said ``--link-profile unknown link profile 'nope'`` (the flag's name
    run into the message) until the third wave's forty-third session; it is the flag's own line now."""
    with pytest.raises(ConfigError, match=r"^--link-profile: unknown link profile 'nope'; shipped profiles: lte, "):
        simulate(MISSION_DIR / "step.toml", link={"profile": "nope"})


def test_a_sensor_set_given_by_name_is_told_the_table_it_means() -> None:
    """``simulate(m, sensors="mocap")`` (as ``--sensors mocap``) was refused as ``expected a table (a mapping), got
    'mocap'`` until the third wave's forty-third session, without the table it takes; it says ``{'set': 'mocap'}``."""
    with pytest.raises(ConfigError, match=r"^overrides: sensors: expected a table \(a mapping: \{'set': 'mocap'\}, "
                                          r"as --sensors mocap\), got 'mocap'$"):
        simulate(MISSION_DIR / "step.toml", sensors="mocap")


@pytest.mark.parametrize("keywords, said", [
    ({"noise": 5.0}, "noise = 5: the estimator is 'truth' (the true state: the sensors are not read), so noise "
                     "changes nothing; give estimator='raw' or 'ekf' (or [estimator] kind)"),
    ({"sensors": {"set": "gnss"}}, "sensors = {'set': 'gnss'}: the estimator is 'truth' (the true state: the sensors "
                                   "are not read), so the sensor set changes nothing"),
])
def test_noise_or_a_sensor_set_a_truth_flight_does_not_read_is_refused_from_python(keywords: dict, said: str) -> None:
    """``simulate(m, noise=5.0)`` on the true state flew byte for byte as without it, exit-free, where ``bsst sim
    --noise 5`` is refused, until the third wave's forty-third session (docs/sensors.md)."""
    with pytest.raises(ConfigError) as caught:
        simulate(MISSION_DIR / "step.toml", **keywords)
    assert str(caught.value).startswith(said)
    assert simulate(Mission(Sine(), duration_s=0.2), estimator="raw", sensors={"set": "mocap"}, noise=2.0).outcome \
        == "completed"  # read, so flown
