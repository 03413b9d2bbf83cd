"""Offline speed: controller step time and the real-time factor of the sine mission.

For each law (bsst, smc, pid) at 250 Hz control and 1 kHz physics:

- controller step: the median wall time of one ``Controller.step`` (law + actuation), in
  microseconds, replaying the states and references of a sine flight through a fresh
  controller (its integrators evolve as in flight);
- plant step: the median wall time of one 1 kHz ``Quadrotor.step`` (RK4 of eq. 6);
- offline real-time factor: simulated seconds per wall second of the whole sine mission
  through ``bridge.loop.simulate`` (no plots, nothing written), beside the plant's alone (its
  physics steps and nothing else). Simulated seconds are the steps flown: the mission's, and the
  landing after its end (``[end] action = "land"``, summary.json's ``end.rows``: 1076 steps, 4.3 s on the
  sine), which a run before that landing did not fly;

each with the plain kernels and with their numba-compiled twins (bridge.core.scalar: the law's
one-call step and the RK4 step; the same bits; ``pid`` has its plant compiled, its law plain),
and the one-time cost of the compiled ones: a fresh process's numba import and cached-kernel
load, which a flight pays before its first step.

Every figure is the median over ``--repeats`` repeats, and the laws and kernels are measured in
the same process, interleaved, so their ratios are comparable. Targets: controller step <= 100
us median, offline >= 50x real time (issue 3); the BS-ST step <= 5 us (issue 25).

    .venv/bin/python benchmarks/offline.py [--repeats 7] [--mission missions/sine.toml] [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from bridge.core.flight import prepare  # noqa: E402
from bridge.core.scalar import KERNELS_ENV  # noqa: E402
from bridge.loop import simulate  # noqa: E402
from missions import Mission, load_mission  # noqa: E402

LAWS = ("bsst", "smc", "pid")
RATE_HZ = 250.0
PHYSICS_HZ = 1000.0
TARGET_STEP_US = 100.0
TARGET_RTF = 50.0
TARGET_BSST_US = 5.0
KERNELS = ("plain", "compiled")


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


def controller_step_us(mission: Mission, law: str, flight: list, kernels: str = "plain") -> float:
    """Median wall time of one controller step (law + actuation), microseconds."""
    os.environ[KERNELS_ENV] = kernels
    ctl = prepare(mission, controller=law).make_controller()
    step = ctl.step
    clock = time.perf_counter_ns
    times = []
    for t, X, ref in flight:
        t0 = clock()
        step(t, X, ref)
        times.append(clock() - t0)
    return statistics.median(times) / 1e3


def plant_step_us(mission: Mission, kernels: str = "plain", steps: int = 5000) -> float:
    """Median wall time of one physics step of the plant near hover, microseconds."""
    os.environ[KERNELS_ENV] = kernels
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


def real_time_factor(mission: Mission, law: str, kernels: str = "plain") -> tuple[float, float, float]:
    """(simulated s per wall s, simulated s per CPU s of this process, 3-D RMS) of the whole
    mission flown offline with ``kernels`` (this process's compiled kernels already loaded: the
    one-time load is :func:`compiled_load_s`). The CPU figure is what the loop costs when it has
    a core to itself; on a busy machine the wall figure is lower."""
    os.environ[KERNELS_ENV] = kernels
    c0 = time.process_time()
    t0 = time.perf_counter()
    run = simulate(mission, controller=law, plots=False)
    wall = time.perf_counter() - t0
    cpu = time.process_time() - c0
    flown_s = (len(run.trace["t"]) + (run.summary.get("end") or {}).get("rows", 0)) / mission.rate_hz
    return flown_s / wall, flown_s / cpu, run.rms


def compiled_load_s(mission: str) -> float:
    """Wall time (s) a fresh process spends importing numba and loading the compiled kernels from the
    cache on disk (warm: they were compiled in this run), before a compiled flight's first step."""
    code = ("import sys, time; sys.path.insert(0, sys.argv[1]); from bridge.core.flight import prepare; "
            "f = prepare(sys.argv[2]); c, p = f.make_controller(), f.make_plant(); t = time.perf_counter(); "
            "from bridge.core.scalar import compile_for; compile_for(c, p); print(time.perf_counter() - t)")
    out = subprocess.run([sys.executable, "-c", code, str(ROOT), mission], capture_output=True, text=True, check=True,
                         env={**os.environ, KERNELS_ENV: "plain"})
    return float(out.stdout.split()[-1])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--mission", default=str(ROOT / "missions" / "sine.toml"))
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--json", action="store_true", help="print the figures as JSON")
    args = ap.parse_args(argv)

    base = load_mission(args.mission).with_overrides(rate_hz=RATE_HZ, physics_hz=PHYSICS_HZ)
    flight = recorded_flight(base)
    for kernels in KERNELS:  # warm up imports and caches (the compiled kernels compiled or loaded here)
        os.environ[KERNELS_ENV] = kernels
        simulate(base, plots=False)
    samples = {k: {law: {"step_us": [], "rtf": [], "rtf_cpu": [], "rms": []} for law in LAWS} for k in KERNELS}
    plant_us: dict[str, list[float]] = {k: [] for k in KERNELS}
    load_s = []
    for _ in range(args.repeats):
        load_s.append(compiled_load_s(args.mission))
        for k in KERNELS:
            plant_us[k].append(plant_step_us(base, k))
        for law in LAWS:  # interleaved, so that drifts in machine load hit every law and kernels alike
            for k in KERNELS:
                s = samples[k][law]
                s["step_us"].append(controller_step_us(base, law, flight, k))
                rtf, rtf_cpu, rms = real_time_factor(base, law, k)
                s["rtf"].append(rtf)
                s["rtf_cpu"].append(rtf_cpu)
                s["rms"].append(rms)
    os.environ.pop(KERNELS_ENV, None)
    res = _figures(base, args.repeats, samples, plant_us, load_s)
    if args.json:
        print(json.dumps(res, indent=2))
        return 0
    _print(res)
    return 0


def _figures(base: Mission, repeats: int, samples: dict, plant_us: dict[str, list[float]],
             load_s: list[float]) -> dict[str, Any]:
    """The medians (and ranges) of the samples, per kernels and law."""
    med = statistics.median
    res: dict[str, Any] = {
        "mission": base.name, "rate_hz": RATE_HZ, "physics_hz": PHYSICS_HZ, "repeats": repeats,
        "python": platform.python_version(), "machine": platform.machine(),
        "load_average_1min": os.getloadavg()[0],
        "compiled_load_s": med(load_s), "compiled_load_s_range": [min(load_s), max(load_s)],
        "kernels": {},
    }
    for k in KERNELS:
        pu = med(plant_us[k])
        out: dict[str, Any] = {"plant_step_us": pu, "plant_alone_real_time_factor": 1e6 / (pu * PHYSICS_HZ),
                               "laws": {}}
        for law in LAWS:
            s = samples[k][law]
            out["laws"][law] = {
                "controller_step_us": med(s["step_us"]),
                "controller_step_us_range": [min(s["step_us"]), max(s["step_us"])],
                "real_time_factor": med(s["rtf"]),
                "real_time_factor_range": [min(s["rtf"]), max(s["rtf"])],
                "real_time_factor_cpu": med(s["rtf_cpu"]),
                "control_step_total_us": 1e6 / (RATE_HZ * med(s["rtf_cpu"])),
                "rms_3d_m": s["rms"][-1],
            }
        res["kernels"][k] = out
    res["plant_step_us"] = res["kernels"]["plain"]["plant_step_us"]  # (as before: the plain figures on top)
    res["laws"] = res["kernels"]["plain"]["laws"]
    return res


def _print(res: dict[str, Any]) -> None:
    print(f"offline benchmark: mission {res['mission']}, {RATE_HZ:g} Hz control, {PHYSICS_HZ:g} Hz physics, "
          f"median of {res['repeats']} repeats (Python {res['python']}, {res['machine']}, "
          f"load average {res['load_average_1min']:.2f})")
    ref = res["kernels"]["plain"]["laws"]["bsst"]
    for k in KERNELS:
        kr = res["kernels"][k]
        print(f"{k} kernels: plant step (RK4 of eq. 6, 1 kHz) {kr['plant_step_us']:.1f} us, the plant alone "
              f"{kr['plant_alone_real_time_factor']:.0f}x real time")
        print(f"  {'law':5} {'step us':>8} {'range':>13} {'vs plain bsst':>13}  {'offline x':>9} {'range':>11}"
              f"  {'cpu x':>6}  {'loop us':>8}  {'rms m':>9}")
        for law in LAWS:
            r = kr["laws"][law]
            lo, hi = r["controller_step_us_range"]
            rlo, rhi = r["real_time_factor_range"]
            print(f"  {law:5} {r['controller_step_us']:8.1f} {f'[{lo:.1f}, {hi:.1f}]':>13} "
                  f"{r['controller_step_us'] / ref['controller_step_us']:13.2f}  {r['real_time_factor']:9.1f} "
                  f"{f'[{rlo:.0f}, {rhi:.0f}]':>11}  {r['real_time_factor_cpu']:6.1f}  "
                  f"{r['control_step_total_us']:8.1f}  {r['rms_3d_m']:9.2e}")
    lo, hi = res["compiled_load_s_range"]
    print(f"compiled kernels' one-time cost in a fresh process (numba import + cached load): "
          f"{res['compiled_load_s']:.2f} s [{lo:.2f}, {hi:.2f}]")
    print("step us: one controller step (law + actuation); offline x: simulated s per wall s (the compiled")
    print("kernels already loaded); cpu x: per CPU s; loop us: CPU per control step of the whole loop (controller,")
    print(f"{PHYSICS_HZ / RATE_HZ:g} plant steps, link model, trace); the plant alone: its physics steps only")
    laws = [r for kr in res["kernels"].values() for r in kr["laws"].values()]
    ok_step = all(r["controller_step_us"] <= TARGET_STEP_US for r in laws)
    ok_rtf = all(r["real_time_factor"] >= TARGET_RTF for r in laws)
    bsst_us = res["kernels"]["compiled"]["laws"]["bsst"]["controller_step_us"]
    print(f"targets: controller step <= {TARGET_STEP_US:g} us: {'met' if ok_step else 'NOT met'}; "
          f"offline >= {TARGET_RTF:g}x real time: {'met' if ok_rtf else 'NOT met'}; compiled BS-ST step <= "
          f"{TARGET_BSST_US:g} us: {'met' if bsst_us <= TARGET_BSST_US else 'NOT met'} ({bsst_us:.1f} us)")


if __name__ == "__main__":
    sys.exit(main())
