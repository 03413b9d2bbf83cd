"""Sensors and the on-board estimator: the cost of one estimator step, and what the EKF buys.

``step``: the median wall time of one estimator step (``Ekf.step`` and ``RawEstimator.step``,
microseconds), replaying the measurements of a sine flight (paper profile, 250 Hz control, 1 kHz
physics, ``mocap`` sensors) into a fresh estimator. The estimator is called once per physics step;
most calls carry nothing (the IMU runs at 250 Hz), so the median of all calls says little: the
figures are the median of the calls that carry a measurement, the median of each mix of
measurements, and the mean cost per physics step and per control step.

``table``: the sine mission (missions/sine.toml, paper profile, 250 Hz) flown OFFLINE with the
``mocap`` sensor set and the estimators ``raw`` and ``ekf`` (``truth`` beside them), for the laws
bsst, smc and pid: the 3-D RMS tracking error over t >= 10 s (``bridge.record.metrics.rms_3d``)
and the ripple of u2 (the demanded roll input's RMS about its centred 0.1 s moving average over
the second half, ``bridge.sweep.cells.ripple_rms``), and the real-time factor of the whole flight
(simulated s per wall s, and per CPU s of this process). The loop is
``bridge.core.estimator.fly_closed_loop`` (plant, sensors, estimator, ``controller.Controller`` fed
the estimate), not yet the product's loop, which has no estimator yet.

Every figure is the median over ``--repeats`` repeats (the flights are the same every repeat: one
seed; only the times vary). Targets (issue 12): with ``ekf`` BS-ST's u2 ripple at least 5x lower
than with ``raw`` and its RMS no worse; one estimator step <= 50 us median; the offline sine with
``ekf`` >= 30x real time.

    .venv/bin/python benchmarks/estimation.py [--repeats 3] [--seed 0] [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from bridge.core.estimator import Ekf, RawEstimator, fly_closed_loop, make_estimator  # noqa: E402
from bridge.core.flight import prepare  # noqa: E402
from bridge.record.metrics import rms_3d  # noqa: E402
from bridge.sweep.cells import ripple_rms  # noqa: E402
from plant.sensors import SensorSuite  # noqa: E402

MISSION = str(ROOT / "missions" / "sine.toml")
SENSORS = "mocap"
LAWS = ("bsst", "smc", "pid")
KINDS = ("raw", "ekf", "truth")
RIPPLE_WINDOW_S = 0.1
TARGET_STEP_US = 50.0
TARGET_RTF = 30.0
TARGET_RIPPLE_RATIO = 5.0


def flight(law: str, kind: str, seed: int) -> dict[str, Any]:
    """One offline sine flight with sensors and an estimator; its figures and times."""
    w0, c0 = time.perf_counter(), time.process_time()
    f = prepare(MISSION, controller=law, seed=seed)
    m = f.mission
    plant = f.make_plant()
    cfg = f.profile.sensor_set(SENSORS)
    suite = SensorSuite(cfg, m.seed, m.physics_hz, f.profile.gravity)
    est = make_estimator(kind, cfg, plant.state, f.profile.gravity, lambda: plant.state)
    rec = fly_closed_loop(plant, f.make_controller(), m.trajectory.sample, suite, est, steps=m.steps,
                          rate_hz=m.rate_hz)
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    trace = {"t": rec.t, "x": rec.truth[:, 0], "y": rec.truth[:, 2], "z": rec.truth[:, 4],
             "psi": rec.truth[:, 10], "x_ref": rec.reference[:, 0], "y_ref": rec.reference[:, 1],
             "z_ref": rec.reference[:, 2], "psi_ref": rec.reference[:, 3]}
    flown = float(rec.t[-1]) + 1.0 / m.rate_hz if len(rec.t) else 0.0
    return {"outcome": rec.outcome, "rms_3d_m": rms_3d(trace, 10.0),
            "ripple_u2_n": ripple_rms(rec.t, rec.demanded[:, 1], m.rate_hz, RIPPLE_WINDOW_S),
            "rtf": flown / wall, "rtf_cpu": flown / cpu}


def recorded_stream(seed: int) -> tuple[list[tuple[float, list]], Any, Any]:
    """(t, measurements) of every physics step of a BS-ST sine flight on the true state."""
    f = prepare(MISSION, seed=seed)
    m = f.mission
    plant = f.make_plant()
    ctl = f.make_controller()
    cfg = f.profile.sensor_set(SENSORS)
    suite = SensorSuite(cfg, m.seed, m.physics_hz, f.profile.gravity)
    stream = [(plant.t, suite.sample(plant.t, plant.state))]
    for k in range(m.steps):
        t = k / m.rate_hz
        plant.command(ctl.step(t, plant.state, m.trajectory.sample(t)).normalised)
        for _ in range(f.substeps):
            plant.step()
            stream.append((plant.t, suite.sample(plant.t, plant.state)))
    return stream, cfg, f


def step_times(make: Any, stream: list[tuple[float, list]]) -> dict[str, Any]:
    """Wall time of each ``step`` of a fresh estimator fed the stream: medians by mix, means."""
    est = make()
    clock = time.perf_counter_ns
    by_mix: dict[str, list[int]] = defaultdict(list)
    loaded: list[int] = []
    total = 0
    for t, ms in stream:
        t0 = clock()
        est.step(t, ms)
        dt = clock() - t0
        total += dt
        if ms:
            loaded.append(dt)
            by_mix["+".join(sorted(m.kind for m in ms))].append(dt)
    n = len(stream)
    return {"median_loaded_us": statistics.median(loaded) / 1e3,
            "mean_per_physics_step_us": total / n / 1e3,
            "by_mix_us": {k: statistics.median(v) / 1e3 for k, v in by_mix.items()},
            "by_mix_count": {k: len(v) for k, v in by_mix.items()}}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", action="store_true", help="print the figures as JSON")
    args = ap.parse_args(argv)
    med = statistics.median

    stream, cfg, f = recorded_stream(args.seed)
    start = f.make_plant().state
    makers = {"ekf": lambda: Ekf(cfg, start, f.profile.gravity), "raw": lambda: RawEstimator(cfg, start)}
    steps: dict[str, list[dict[str, Any]]] = {k: [] for k in makers}
    flights: dict[tuple[str, str], list[dict[str, Any]]] = defaultdict(list)
    flight("bsst", "ekf", args.seed)  # warm up imports and caches
    for _ in range(args.repeats):
        for kind, make in makers.items():
            steps[kind].append(step_times(make, stream))
        for law in LAWS:  # interleaved, so that drifts in machine load hit every estimator alike
            for kind in KINDS:
                flights[(law, kind)].append(flight(law, kind, args.seed))

    res: dict[str, Any] = {
        "mission": "sine", "profile": f.profile.name, "sensors": SENSORS, "rate_hz": f.mission.rate_hz,
        "physics_hz": f.mission.physics_hz, "seed": args.seed, "repeats": args.repeats,
        "python": platform.python_version(), "machine": platform.machine(),
        "load_average_1min": os.getloadavg()[0], "step": {}, "table": {},
    }
    control_steps = f.mission.steps
    for kind, runs in steps.items():
        res["step"][kind] = {
            "median_loaded_us": med(r["median_loaded_us"] for r in runs),
            "mean_per_physics_step_us": med(r["mean_per_physics_step_us"] for r in runs),
            "mean_per_control_step_us": med(r["mean_per_physics_step_us"] for r in runs) * len(stream) / control_steps,
            "by_mix_us": {k: med(r["by_mix_us"][k] for r in runs) for k in runs[0]["by_mix_us"]},
            "by_mix_count": runs[0]["by_mix_count"],
        }
    for (law, kind), runs in flights.items():
        last = runs[-1]
        res["table"].setdefault(law, {})[kind] = {
            "outcome": last["outcome"], "rms_3d_m": last["rms_3d_m"], "ripple_u2_n": last["ripple_u2_n"],
            "rtf": med(r["rtf"] for r in runs), "rtf_range": [min(r["rtf"] for r in runs), max(r["rtf"] for r in runs)],
            "rtf_cpu": med(r["rtf_cpu"] for r in runs),
        }
    for row in res["table"].values():
        row["ripple_ratio_raw_over_ekf"] = row["raw"]["ripple_u2_n"] / row["ekf"]["ripple_u2_n"]
        row["rms_ratio_ekf_over_raw"] = row["ekf"]["rms_3d_m"] / row["raw"]["rms_3d_m"]
    bsst = res["table"]["bsst"]
    res["targets"] = {
        "bsst_ripple_ratio_at_least_5": bsst["ripple_ratio_raw_over_ekf"] >= TARGET_RIPPLE_RATIO,
        "bsst_rms_ekf_no_worse": bsst["ekf"]["rms_3d_m"] <= bsst["raw"]["rms_3d_m"],
        "ekf_step_median_at_most_50us": res["step"]["ekf"]["median_loaded_us"] <= TARGET_STEP_US,
        "ekf_sine_at_least_30x": bsst["ekf"]["rtf"] >= TARGET_RTF,
    }
    if args.json:
        print(json.dumps(res, indent=2))
        return 0

    print(f"estimation benchmark: sine, paper profile, {res['rate_hz']:g} Hz control, "
          f"{res['physics_hz']:g} Hz physics, sensors {SENSORS}, seed {args.seed}, median of {args.repeats} repeats "
          f"(Python {res['python']}, {res['machine']}, load average {res['load_average_1min']:.2f})")
    print()
    print("one estimator step (wall us; called every physics step, most calls carry nothing):")
    for kind, s in res["step"].items():
        mixes = ", ".join(f"{k} {v:.1f} (x{s['by_mix_count'][k]})" for k, v in
                          sorted(s["by_mix_us"].items(), key=lambda kv: -s["by_mix_count"][kv[0]]))
        print(f"  {kind:4} median of the calls with a measurement {s['median_loaded_us']:6.1f} us; "
              f"mean per physics step {s['mean_per_physics_step_us']:5.1f} us, "
              f"per control step {s['mean_per_control_step_us']:5.1f} us")
        print(f"       by mix: {mixes}")
    print()
    print(f"{'law':5} {'estimator':9} {'outcome':10} {'rms 3-D m':>10} {'u2 ripple N':>12} {'offline x':>10} "
          f"{'range':>11} {'cpu x':>6}")
    for law in LAWS:
        row = res["table"][law]
        for kind in KINDS:
            r = row[kind]
            lo, hi = r["rtf_range"]
            print(f"{law:5} {kind:9} {r['outcome'][:10]:10} {r['rms_3d_m']:10.3e} {r['ripple_u2_n']:12.3f} "
                  f"{r['rtf']:10.1f} {f'[{lo:.0f}, {hi:.0f}]':>11} {r['rtf_cpu']:6.1f}")
        print(f"{'':5} raw/ekf u2 ripple {row['ripple_ratio_raw_over_ekf']:.1f}x, ekf/raw rms "
              f"{row['rms_ratio_ekf_over_raw']:.3f}")
    print("rms 3-D: over t >= 10 s; u2 ripple: RMS about the centred 0.1 s moving average, second half;")
    print("offline x: simulated s per wall s of the whole flight (prepare, plant, sensors, estimator, law); "
          "cpu x: per CPU s")
    t = res["targets"]
    ok = {True: "met", False: "NOT met"}
    print(f"targets: BS-ST ripple raw/ekf >= {TARGET_RIPPLE_RATIO:g}x: {ok[t['bsst_ripple_ratio_at_least_5']]}; "
          f"BS-ST rms ekf <= raw: {ok[t['bsst_rms_ekf_no_worse']]}; "
          f"ekf step median <= {TARGET_STEP_US:g} us: {ok[t['ekf_step_median_at_most_50us']]}; "
          f"offline sine with ekf >= {TARGET_RTF:g}x real time: {ok[t['ekf_sine_at_least_30x']]}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
