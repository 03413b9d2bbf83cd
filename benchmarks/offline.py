"""Offline speed: controller step time and the real-time factor of the sine mission.

For each law (bsst, smc, pid) at 250 Hz control and 1 kHz physics:

- controller step: the median wall time of one ``Controller.step`` (law + actuation), in
  microseconds, replaying the states and references of a sine flight through a fresh
  controller (its integrators evolve as in flight);
- plant step: the median wall time of one 1 kHz ``Quadrotor.step`` (RK4 of eq. 6);
- offline real-time factor: simulated seconds per wall second of the whole sine mission
  through ``bridge.loop.simulate`` (no plots, nothing written).

Every figure is the median over ``--repeats`` repeats, and the laws are measured in the
same process, interleaved, so their ratios are comparable. Targets (issue 3): controller
step <= 100 us median, offline >= 50x real time.

    .venv/bin/python benchmarks/offline.py [--repeats 7] [--mission missions/sine.toml] [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from bridge.core.flight import prepare  # noqa: E402
from bridge.loop import simulate  # noqa: E402
from missions import Mission, load_mission  # noqa: E402

LAWS = ("bsst", "smc", "pid")
RATE_HZ = 250.0
PHYSICS_HZ = 1000.0
TARGET_STEP_US = 100.0
TARGET_RTF = 50.0


def recorded_flight(mission: Mission) -> list[tuple[float, tuple[float, ...], Any]]:
    """(t, state, reference sample) of every control step of a BS-ST flight of the mission."""
    run = simulate(mission, plots=False)
    tr = run.trace
    out = []
    for k in range(len(tr["t"])):
        t = float(tr["t"][k])
        X = (tr["x"][k], tr["vx"][k], tr["y"][k], tr["vy"][k], tr["z"][k], tr["vz"][k],
             tr["phi"][k], tr["dphi"][k], tr["theta"][k], tr["dtheta"][k], tr["psi"][k], tr["dpsi"][k])
        out.append((t, tuple(float(v) for v in X), mission.trajectory.sample(t)))
    return out


def controller_step_us(mission: Mission, law: str, flight: list) -> float:
    """Median wall time of one controller step (law + actuation), microseconds."""
    ctl = prepare(mission, controller=law).make_controller()
    step = ctl.step
    clock = time.perf_counter_ns
    times = []
    for t, X, ref in flight:
        t0 = clock()
        step(t, X, ref)
        times.append(clock() - t0)
    return statistics.median(times) / 1e3


def plant_step_us(mission: Mission, steps: int = 5000) -> float:
    """Median wall time of one physics step of the plant near hover, microseconds."""
    f = prepare(mission)
    plant = f.make_plant()
    p = f.profile
    plant.state = (0.0, 0.1, 0.0, -0.1, 1.0, 0.05, 0.01, 0.02, -0.01, 0.03, 0.2, 0.01)  # type: ignore[assignment]
    plant.ground = False
    hover = (p.mass * p.gravity / p.u_max[0], 0.001, -0.001, 0.0) if p.actuation == "wrench" else \
        (p.hover_omega / p.omega_max,) * 4
    plant.command(hover)
    step = plant.step
    clock = time.perf_counter_ns
    times = []
    for _ in range(steps):
        t0 = clock()
        step()
        times.append(clock() - t0)
    return statistics.median(times) / 1e3


def real_time_factor(mission: Mission, law: str) -> tuple[float, float, float]:
    """(simulated s per wall s, simulated s per CPU s of this process, 3-D RMS) of the whole
    mission flown offline. The CPU figure is what the loop costs when it has a core to
    itself; on a busy machine the wall figure is lower."""
    c0 = time.process_time()
    t0 = time.perf_counter()
    run = simulate(mission, controller=law, plots=False)
    wall = time.perf_counter() - t0
    cpu = time.process_time() - c0
    return mission.duration_s / wall, mission.duration_s / cpu, run.rms


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--mission", default=str(ROOT / "missions" / "sine.toml"))
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--json", action="store_true", help="print the figures as JSON")
    args = ap.parse_args(argv)

    base = load_mission(args.mission).with_overrides(rate_hz=RATE_HZ, physics_hz=PHYSICS_HZ)
    flight = recorded_flight(base)
    simulate(base, plots=False)  # warm up imports and caches
    samples: dict[str, dict[str, list[float]]] = {law: {"step_us": [], "rtf": [], "rtf_cpu": [], "rms": []}
                                                  for law in LAWS}
    plant_us: list[float] = []
    for _ in range(args.repeats):
        plant_us.append(plant_step_us(base))
        for law in LAWS:  # interleaved, so that drifts in machine load hit every law alike
            s = samples[law]
            s["step_us"].append(controller_step_us(base, law, flight))
            rtf, rtf_cpu, rms = real_time_factor(base, law)
            s["rtf"].append(rtf)
            s["rtf_cpu"].append(rtf_cpu)
            s["rms"].append(rms)

    med = statistics.median
    res: dict[str, Any] = {
        "mission": base.name,
        "rate_hz": RATE_HZ,
        "physics_hz": PHYSICS_HZ,
        "repeats": args.repeats,
        "python": platform.python_version(),
        "machine": platform.machine(),
        "load_average_1min": os.getloadavg()[0],
        "plant_step_us": med(plant_us),
        "laws": {},
    }
    for law in LAWS:
        s = samples[law]
        res["laws"][law] = {
            "controller_step_us": med(s["step_us"]),
            "controller_step_us_range": [min(s["step_us"]), max(s["step_us"])],
            "real_time_factor": med(s["rtf"]),
            "real_time_factor_range": [min(s["rtf"]), max(s["rtf"])],
            "real_time_factor_cpu": med(s["rtf_cpu"]),
            "control_step_total_us": 1e6 / (RATE_HZ * med(s["rtf_cpu"])),
            "rms_3d_m": s["rms"][-1],
        }
    if args.json:
        print(json.dumps(res, indent=2))
        return 0

    print(f"offline benchmark: mission {res['mission']}, {RATE_HZ:g} Hz control, {PHYSICS_HZ:g} Hz physics, "
          f"median of {args.repeats} repeats (Python {res['python']}, {res['machine']}, "
          f"load average {res['load_average_1min']:.2f})")
    print(f"plant step (RK4 of eq. 6, 1 kHz): {res['plant_step_us']:.1f} us")
    print(f"{'law':5} {'step us':>8} {'range':>13} {'vs bsst':>8}  {'offline x':>9} {'range':>11} {'vs bsst':>8}"
          f"  {'cpu x':>6}  {'loop us':>8}  {'rms m':>9}")
    ref = res["laws"]["bsst"]
    for law in LAWS:
        r = res["laws"][law]
        lo, hi = r["controller_step_us_range"]
        rlo, rhi = r["real_time_factor_range"]
        print(f"{law:5} {r['controller_step_us']:8.1f} {f'[{lo:.1f}, {hi:.1f}]':>13} "
              f"{r['controller_step_us'] / ref['controller_step_us']:8.2f}  {r['real_time_factor']:9.1f} "
              f"{f'[{rlo:.0f}, {rhi:.0f}]':>11} {r['real_time_factor'] / ref['real_time_factor']:8.2f}  "
              f"{r['real_time_factor_cpu']:6.1f}  {r['control_step_total_us']:8.1f}  {r['rms_3d_m']:9.2e}")
    print("step us: one controller step (law + actuation); offline x: simulated s per wall s; cpu x: per CPU s;")
    print(f"loop us: CPU per control step of the whole loop (controller, {PHYSICS_HZ / RATE_HZ:g} plant steps, "
          "link model, trace)")
    ok_step = all(r["controller_step_us"] <= TARGET_STEP_US for r in res["laws"].values())
    ok_rtf = all(r["real_time_factor"] >= TARGET_RTF for r in res["laws"].values())
    print(f"targets: controller step <= {TARGET_STEP_US:g} us: {'met' if ok_step else 'NOT met'}; "
          f"offline >= {TARGET_RTF:g}x real time: {'met' if ok_rtf else 'NOT met'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
