"""Covers bridge.autopilot.estimator, bridge.loop and bridge.session.

Sensors and the on-board estimator in the flights: offline (``bsst sim``) and lockstep (``bsst sitl``),
with ``truth`` (the default) unchanged, real processes over real UDP, the tlog read with pymavlink."""

from __future__ import annotations

import csv
import json
import math
import subprocess
from pathlib import Path

import numpy as np
import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from bridge.autopilot.estimator import ESTIMATOR_KINDS
from bridge.batch import batch_problem
from bridge.cli import main
from bridge.cli.commands import build_parser
from bridge.loop import simulate
from bridge.record.columns import ESTIMATE_COLUMNS, TRACE_COLUMNS
from bridge.record.runlog import read_trace
from bridge.session import instance_slot, sitl
from missions import MISSION_DIR, load_mission
from tests.sitlkit import ENV, ROOT, run_bsst

# starts processes or opens sockets (not in make test-fast); flies the batch engine (its kernels loaded first)
pytestmark = [pytest.mark.process, pytest.mark.usefixtures("batch_kernels")]

SINE = MISSION_DIR / "sine.toml"
EKF_MOCAP = {"sensors": {"set": "mocap"}, "estimator": "ekf"}
SINE_EKF = 'name = "sine6"\nduration_s = {seconds}\nseed = {seed}\n[trajectory]\nkind = "sine"\n' \
          '[sensors]\nset = "mocap"\n[estimator]\nkind = "ekf"\n'
# a short session's end: held (its end landing, 2.6 s after a 2 s sine with COM_DISARM_LAND, more than doubled what
# was flown, and the tests that fly it read the mission's rows or its first message only)
HOLD_AT_END = '[end]\naction = "hold"\n'


def _bsst(*argv: object, timeout: float = 300.0) -> subprocess.CompletedProcess:
    return run_bsst(*map(str, argv), cwd=ROOT, env=ENV, timeout=timeout)


def test_truth_and_ideal_sensors_leave_the_sine_unchanged():
    """The paper's figure stays: no sensors sampled, the controller on the true state (as ODOMETRY's float32
    carries it, as in SITL: 2.41e-6 m with the paper's explicit step, asked for by name), bit for bit."""
    base = simulate(SINE, plots=False, discretization="explicit")
    assert 2.3e-6 < base.summary["rms_3d"] < 2.5e-6 and "estimation" not in base.summary
    sine = load_mission(SINE)
    # a mission's own [sensors] under truth (a caller's sensors= or noise= there is refused: it changes nothing)
    for m, kw in ((sine.with_overrides(sensors={"set": "ideal"}), {}), (sine, {"estimator": "truth"}),
                  (sine.with_overrides(sensors={"set": "mocap", "noise_scale": 2.0}), {})):
        run = simulate(m, plots=False, discretization="explicit", **kw)  # truth: the sensor set is not sampled
        assert run.summary["rms_3d"] == base.summary["rms_3d"], kw
        assert all(np.array_equal(run.trace[c], base.trace[c], equal_nan=True) for c in TRACE_COLUMNS), kw
    for c, e in zip(("x", "vx", "psi", "dpsi"), ("x_est", "vx_est", "psi_est", "dpsi_est"), strict=True):
        assert np.array_equal(base.trace[c], base.trace[e])  # truth's estimate is the truth
    assert np.all(base.trace["nees"] == 0.0)


def test_the_ekf_starts_where_the_vehicle_stands(tmp_path):
    """An EKF starts from its readings at rest (plant.alignment: the gnss set's barometer over 10 s on the pad, height
    σ 9 mm), as EKF2 has them by take-off: its height at the first step, and over the first half second, within 5 cm
    of the truth for every seed (in flight it is 3-8 cm off, the barometer's 0.2 m filtered); horizontally where it
    stands. Until the forty-fifth session P0's height was one GNSS fix's σ (2 m): the first fix pulled the exact
    start half way to itself, 0.294 m up at t = 0 on seed 0, and the barometer took seconds to bring it back."""
    for seed in (0, 1, 2):
        mission = tmp_path / f"sine{seed}.toml"
        mission.write_text(SINE_EKF.format(seconds=1.0, seed=seed).replace('"mocap"', '"gnss"') + HOLD_AT_END)
        run = simulate(mission, plots=False)
        t, z, z_est = run.trace["t"], run.trace["z"], run.trace["z_est"]
        assert t[0] == 0.0 and z[0] == 0.0
        first = abs(z_est[0] - z[0])
        worst = float(np.max(np.abs(z_est - z)[t <= 0.5]))
        assert first < 0.05 and worst < 0.05, f"seed {seed}: height {first:.3f} m off at t = 0, {worst:.3f} m at most"
        horizontal = math.hypot(run.trace["x_est"][0] - run.trace["x"][0], run.trace["y_est"][0] - run.trace["y"][0])
        assert horizontal < 0.05, f"seed {seed}: {horizontal:.3f} m off horizontally at t = 0"


@pytest.fixture(scope="module")
def ekf_sim(tmp_path_factory: pytest.TempPathFactory) -> tuple[int, Path]:
    """``bsst sim missions/sine.toml --sensors mocap --estimator ekf``, bsst's ``main`` in this process (a forked
    ``bsst`` child loaded numba and the EKF's kernels itself: 2.8 against 1.6 CPU-s): its exit status and run
    directory (the EKF's flight of both tests below, flown once)."""
    out = tmp_path_factory.mktemp("ekf_sim") / "run"
    return main(["sim", str(SINE), "--sensors", "mocap", "--estimator", "ekf", "--out", str(out), "--no-plots"]), out


def test_sim_with_mocap_and_ekf_flies_and_reports_its_estimation(ekf_sim):
    rc, out = ekf_sim
    assert rc == 0
    s = json.loads((out / "summary.json").read_text())
    assert s["outcome"] == "completed" and s["rms_3d"] < 5e-3
    est = s["estimation"]
    assert est["estimator"] == "ekf" and est["sensors"] == "mocap"
    assert 0 < est["position_rms_m"] < 2e-3 and 0 < est["velocity_rms_mps"] < 0.02
    assert 0 < est["attitude_rms_rad"] < 0.01
    assert 3.0 < est["nees_mean"] < 30.0 and est["nees_samples"] == 750  # ~9 (dof) if consistent; every 10th step
    assert all(s["inputs"][u]["ripple"] > 0 for u in ("u2", "u3", "u4"))
    trace = read_trace(out / "trace.csv")
    assert list(trace) == list(TRACE_COLUMNS) and list(TRACE_COLUMNS[-13:-1]) == list(ESTIMATE_COLUMNS)
    err = np.abs(trace["x"] - trace["x_est"])
    assert 0 < err.max() < 0.01  # an estimate, not the truth
    mission = (out / "mission.toml").read_text()
    assert "[sensors]" in mission and "[estimator]" in mission  # as flown: a rerun of it flies the same


def test_raw_passes_noise_on_and_the_ekf_removes_it(ekf_sim):
    """The same sine, sensors and seed flown with ``raw`` (offline) against the EKF's flight (``bsst sim``'s)."""
    raw = simulate(SINE, plots=False, sensors={"set": "mocap"}, estimator="raw").summary
    rc, out = ekf_sim
    assert rc == 0
    ekf = json.loads((out / "summary.json").read_text())
    ripple = {k: s["inputs"]["u2"]["ripple"] for k, s in (("raw", raw), ("ekf", ekf))}
    assert ripple["ekf"] * 5 < ripple["raw"], ripple
    assert ekf["rms_3d"] < raw["rms_3d"]


@pytest.fixture(scope="module")
def ekf_session(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, object]:
    """A lockstep session of 2 s on the estimate (seed 0, the mission's end held), its figures drawn: its run
    directory and run. The seed test reads its trace, the plots test its figures (each flew its own before)."""
    d = tmp_path_factory.mktemp("ekf_session")
    m = d / "a.toml"
    m.write_text(SINE_EKF.format(seed=0, seconds=2.0) + HOLD_AT_END)
    return d / "a", sitl(m, out=d / "a", instance=None)


def test_a_seed_gives_the_same_lockstep_trace_twice_and_another_seed_another(ekf_session, tmp_path):
    """Three lockstep sessions of 2 s, the mission's end held (the sensors' noise differs from the first sample:
    the 6 s and end landing flown before added 6.6 s to each that the test does not read); the first is
    :func:`ekf_session` (its figures drawn: they do not touch the trace)."""
    runs = {"a": ekf_session}
    for name, seed in (("b", 0), ("c", 2)):
        m = tmp_path / f"{name}.toml"
        m.write_text(SINE_EKF.format(seed=seed, seconds=2.0) + HOLD_AT_END)
        runs[name] = tmp_path / name, sitl(m, out=tmp_path / name, plots=False, instance=None)
    for _, run in runs.values():
        assert run.outcome == "completed" and "estimation" in run.summary
    a, b, c = ((out / "trace.csv").read_bytes() for out, _ in runs.values())
    assert a == b
    assert a != c


def test_lockstep_matches_offline_and_odometry_carries_the_covariance(tmp_path):
    """A real ``bsst sitl`` process against the offline loop (the sine cut to 12 s); ODOMETRY in the vehicle's
    tlog."""
    sine = tmp_path / "sine12.toml"
    # its end held: the rows, the summary's estimation and ODOMETRY read are the mission's (its end landing, 3.5 s
    # more in each twin, flew for nobody)
    sine.write_text(SINE.read_text().replace("duration_s = 30.0", "duration_s = 12.0") + HOLD_AT_END)
    off = simulate(sine, plots=False, **EKF_MOCAP)
    assert len(off.trace["t"]) == 3000
    out = tmp_path / "run"
    with instance_slot() as n:
        r = _bsst("sitl", sine, "--sensors", "mocap", "--estimator", "ekf", "--instance", n, "--out", out,
                  "--no-plots")
    assert r.returncode == 0, r.stderr
    trace = read_trace(out / "trace.csv")
    assert np.array_equal(trace["t"], off.trace["t"])
    for c in ("x", "y", "z", "x_est", "y_est", "z_est"):
        worst = float(np.max(np.abs(trace[c] - off.trace[c])))
        assert worst < 1e-4, f"{c}: lockstep and offline differ by {worst:.3e} m"
    s = json.loads((out / "summary.json").read_text())
    assert s["clock"] == "lockstep" and s["estimation"]["position_rms_m"] == pytest.approx(
        off.summary["estimation"]["position_rms_m"], rel=1e-3)
    log = mavutil.mavlink_connection(str(out / "vehicle.tlog"), dialect="common")
    odometry = []
    while (m := log.recv_match(type="ODOMETRY")) is not None:
        odometry.append(m)
    assert len(odometry) > 3000
    for m in odometry[1:]:
        assert all(math.isfinite(v) for v in (*m.pose_covariance, *m.velocity_covariance))
        assert m.estimator_type == mavlink.MAV_ESTIMATOR_TYPE_AUTOPILOT
    late = odometry[-1]
    sigma_x = math.sqrt(late.pose_covariance[0])  # x of the upper triangle: element (0, 0)
    assert 1e-5 < sigma_x < 5e-3  # millimetre-class from motion capture


def test_truth_odometry_keeps_its_unknown_covariance(tmp_path):
    """Under truth the wire is as it was: covariance unknown (NaN first), estimator type naive. (The first ODOMETRY
    is read: a 1 s session, its end held.)"""
    mission = _mission(tmp_path, "truth", seconds=1.0)
    mission.write_text(mission.read_text() + HOLD_AT_END)
    run = sitl(mission, out=tmp_path / "t", plots=False, instance=None)
    assert run.outcome == "completed"
    log = mavutil.mavlink_connection(str(tmp_path / "t" / "vehicle.tlog"), dialect="common")
    m = log.recv_match(type="ODOMETRY")
    assert m is not None and math.isnan(m.pose_covariance[0]) and m.estimator_type == mavlink.MAV_ESTIMATOR_TYPE_NAIVE


def _mission(tmp_path: Path, kind: str, seconds: float = 6.0) -> Path:
    p = tmp_path / f"{kind}.toml"
    p.write_text(SINE_EKF.replace('kind = "ekf"', f'kind = "{kind}"').format(seed=0, seconds=seconds))
    return p


BAD = [
    (["--sensors", "bogus"], "--sensors"),
    (["--sensors", "mo.cap"], "--sensors"),
    (["--estimator", "kf"], "--estimator"),
    (["--noise", "-1"], "--noise"),
    (["--noise", "nan"], "--noise"),
]
BAD_TABLES = [
    ('[sensors]\nset = "mocap"\nposition_noise_m = -1\n', "sensors.position_noise_m"),
    ('[sensors]\nset = "nosuch"\n', "sensors.set"),
    ('[sensors]\nnoise_scale = "big"\n', "sensors.noise_scale"),
    ('[sensors]\nwhatever_hz = 3\n', "whatever_hz"),
    ('[sensors]\nset = "mocap"\nvelocity_noise_mps = 0.1\n', "velocity_noise_mps"),
    ('[estimator]\nkind = "kf"\n', "estimator.kind"),
    ('[estimator]\nkind = "ekf"\ngain = 2\n', "estimator.gain"),
]


def _refused(capsys, argv: list[str], names: tuple[str, ...], out: Path) -> None:
    """``bsst argv`` in this process: exit 2, one line on stderr naming every one of ``names``, nothing written."""
    rc = main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and all(n in err[0] for n in names), (argv, rc, err)
    assert "unrecognized" not in err[0]  # refused by the flag's own check, not unknown
    assert not out.exists()


@pytest.mark.parametrize("cmd", ["sim", "sitl", "vehicle"])
@pytest.mark.parametrize("flags, name", BAD)
def test_bad_sensor_flags_exit_2_with_one_line(capsys, tmp_path, cmd, flags, name):
    _refused(capsys, [cmd, str(SINE), *flags, "--out", str(tmp_path / "out")], (name, flags[1]), tmp_path / "out")


@pytest.mark.parametrize("cmd", ["sim", "sitl", "vehicle"])
@pytest.mark.parametrize("flags, said", [
    (["--noise", "5"], "--noise 5: the estimator is 'truth' (the true state: the sensors are not read), so noise "
                       "changes nothing; give --estimator raw or ekf"),
    (["--noise", "0", "--estimator", "raw"], "--noise 0: the sensor set 'ideal' has no noise (every sigma is 0), so "
                                             "its scale changes nothing; choose one with --sensors mocap or gnss"),
    (["--noise", "5", "--vehicles", "2"], "--noise 5: the estimator is 'truth'"),  # every vehicle of a fleet
])
def test_a_noise_that_changes_nothing_is_refused_as_the_sweep_refuses_it(capsys, tmp_path, cmd, flags, said):
    """Under truth the vehicle has no sensors (none sampled, none streamed: no HIGHRES_IMU, no GPS_RAW_INT), and
    the ideal set has no noise: --noise changed nothing there and said nothing, exit 0 (a sweep refused it)."""
    if cmd == "vehicle" and "--vehicles" in flags:
        flags = flags[:-2]  # bsst vehicle is one vehicle
    _refused(capsys, [cmd, str(SINE), *flags, "--out", str(tmp_path / "out")], (said,), tmp_path / "out")


def test_a_noise_that_changes_something_flies(tmp_path):
    """--noise 0 on a noisy set: exact sensors, a different flight (the set's own sigmas are what is judged)."""
    m = _mission(tmp_path, "raw", seconds=2.0)
    rms = []
    for noise in ("0", "1"):
        assert main(["sim", str(m), "--noise", noise, "--no-plots", "--out", str(tmp_path / noise)]) == 0
        rms.append(json.loads((tmp_path / noise / "summary.json").read_text())["rms_3d"])
    assert rms[0] != rms[1], rms


@pytest.mark.parametrize("table, name", BAD_TABLES)
def test_bad_sensors_and_estimator_tables_exit_2_with_one_line(capsys, tmp_path, table, name):
    m = tmp_path / "bad.toml"
    m.write_text(SINE.read_text() + "\n" + table)
    _refused(capsys, ["sim", str(m), "--out", str(tmp_path / "out")], (str(m), name), tmp_path / "out")


def test_estimator_flag_choices_are_the_estimator_kinds():
    sub = next(a for a in build_parser()._actions if a.dest == "command")
    for cmd in ("sim", "sitl", "vehicle"):
        action = next(a for a in sub.choices[cmd]._actions if "--estimator" in a.option_strings)
        assert sorted(action.choices) == sorted(ESTIMATOR_KINDS)


def test_plots_show_the_estimate_against_truth_only_when_flown_on_an_estimate(ekf_session, tmp_path):
    """``plots/estimate.png`` from ``bsst sim`` and ``bsst sitl`` under ekf; none under truth (nothing to show)."""
    for kind in ("ekf", "truth"):
        mission = _mission(tmp_path, kind)  # the figures show the mission's rows: its end landing flew for nobody
        mission.write_text(mission.read_text() + HOLD_AT_END)
        simulate(mission, out=tmp_path / kind)
        assert (tmp_path / kind / "plots" / "positions.png").stat().st_size > 10_000
    assert (tmp_path / "ekf" / "plots" / "estimate.png").stat().st_size > 10_000
    assert not (tmp_path / "truth" / "plots" / "estimate.png").exists()
    out, run = ekf_session  # the figure read, not the flight: 2 s, its end held
    assert run.outcome == "completed"
    assert (out / "plots" / "estimate.png").stat().st_size > 10_000


def test_the_failsafe_lands_on_the_estimate(tmp_path):
    """The on-board controller flies the estimate too: a blackout hands it the vehicle, which lands and disarms."""
    run = simulate(_mission(tmp_path, "ekf"), plots=False, link={"up": {"blackouts": [[2.0, 10.0]]}})
    kinds = [e["kind"] for e in run.summary["events"]]
    assert run.summary["outcome"] == "failsafe" and "failsafe" in kinds and kinds[-2:] == ["disarmed", "mode"]
    assert abs(run.trace["z"][-1]) < 0.01 and run.summary["estimation"]["position_rms_m"] < 0.01


def test_the_batch_engine_refuses_an_estimator_it_does_not_fly(tmp_path):
    why = batch_problem(_mission(tmp_path, "ekf"), [{}])
    assert why is not None and "estimator" in why and "'ekf'" in why
    assert batch_problem(_mission(tmp_path, "truth"), [{}]) is None


def test_sweep_flies_every_cell_on_the_estimate(tmp_path, capsys):
    """``bsst sweep --sensors --estimator`` (bsst's ``main`` in this process): fixed for every cell; the batch engine
    (no sensors) says so."""
    m = str(_mission(tmp_path, "truth"))
    capsys.readouterr()
    rc = main(["sweep", m, "--sensors", "mocap", "--estimator", "ekf", "--engine", "batch", "--out",
               str(tmp_path / "b")])
    err = capsys.readouterr().err
    assert rc == 2 and "estimator" in err and not (tmp_path / "b").exists(), err
    rows = {}
    for kind in ("truth", "ekf"):  # (--sensors under truth is refused: it reads none, so the set changes nothing)
        sensing = ["--sensors", "mocap", "--estimator", kind] if kind != "truth" else ["--estimator", kind]
        rc = main(["sweep", m, *sensing, "--engine", "process", "--jobs", "1", "--out", str(tmp_path / kind),
                   "--no-plots"])
        assert rc == 0, capsys.readouterr().err
        with open(tmp_path / kind / "cells.csv", newline="") as f:
            rows[kind] = next(csv.DictReader(f))
    ripple = {k: float(v["ripple_u2"]) for k, v in rows.items()}  # N
    assert ripple["ekf"] > 5 * ripple["truth"], ripple
