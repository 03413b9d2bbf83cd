"""Weather and faults (issue 27, docs/weather.md): the acceptance figures, printed as tables.

Every flight is the product's own loop, ``bridge.simulate`` (``bsst sim``), with the overrides ``wind``,
``turbulence``, ``at``, ``controller``, ``link``, ``profile``, ``sensors``, ``estimator``: exactly what
``bsst sim MISSION --wind S:FROM --turbulence L --at T:KIND:ARGS ...`` flies.

``wind``: ``missions/sine.toml --wind 5:270 --turbulence moderate`` for seeds 0..N-1: outcome, RMS, the mean
wind along its direction and the turbulence's std per axis over the flight against MIL-HDBK-1797's σ, with the
default record scaled to σ (and its scale per axis) and with ``--turbulence-scaling none`` (each with the
expected sampling error of a 30 s sample: summary.json's ``sampling``), the free figures pooled over the seeds,
and the free filters over 3600 s (``plant.wind.long_run``: the configuration and seed the flight flew).
The same for 200 30 s series of the free filters (``long_run(duration_s=30)``): how many meet the issue's two
checks. ``long``: one long flight through the same air (missions/step.toml held at 1.5 m, ``--long-s``
seconds, ``--turbulence-scaling none``): its own ``wind`` block.
``table``: BS-ST, SMC, PID on the sine, 3-D RMS (m, t >= 10 s) and u2 ripple (N, summary.json's), in still
air, 5 m/s moderate and 10 m/s severe, on a perfect link and with 20 ms each way (``--delay 20``).
``faults``: the x500 with ``--at 10:motor:1=E`` for each law, with the default gains (``missions/sine.toml
--profile x500``) and with attitude gains sized for the fault (``examples/x500-motor-fault.toml``); ``--sensors
gnss --estimator ekf --at 10:gps:off --at 14:gps:on`` and ``--at 20:gps:on`` (past EKF2_NOAID_TOUT: a failsafe):
the drift during the outage and the NEES after; the x500 held at 5 m by a ground station (HOLD), GPS off at 6 s,
on again at 12 s or never: PX4's Descend and HOLD again, where it lands.
``margin``: ``bsst margin missions/sine.toml --over wind_mps --until rms=0.1`` per law, on a perfect link and
with ``--delay 20`` (``bridge.sweep.margin.margin``, what the command calls).
``batch``: the batch engine against the process engine: ``bsst sweep missions/sine.toml`` (ending in a hold: the
batch flies no end landing) ``--controller bsst,smc,pid --wind 0,5,10 --turbulence none,moderate,severe
--delay 0,20`` flown by each (``--engine batch``, ``--engine process``), the largest relative RMS difference
per law, the outcomes that differ and each engine's wall time; then the x500's motor faults (``--at
10:motor:1=E``, fault-sized gains) flown by the batch (``bridge.batch.fly_batch``) against ``bsst sim``.

    python benchmarks/weather.py [wind|long|table|faults|margin|batch|all] [--seeds N] [--jobs N] [--long-s S]
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # missions/ is the repository's, not benchmarks/

from bridge import simulate  # noqa: E402
from bridge.autopilot.intention import UserModeIntention  # noqa: E402
from bridge.autopilot.modes import HOLD, TAKEOFF  # noqa: E402
from bridge.core.flight import prepare  # noqa: E402
from bridge.sweep.margin import margin, parse_until  # noqa: E402
from missions import Mission, load_mission  # noqa: E402
from missions.references import Setpoint, Step  # noqa: E402
from plant.wind import WindConfig, long_run  # noqa: E402

MISSION = "missions/sine.toml"
WEATHERS = (("still", {}), ("5 m/s moderate", {"wind": (5.0, 270.0), "turbulence": "moderate"}),
            ("10 m/s severe", {"wind": (10.0, 270.0), "turbulence": "severe"}))
LINKS = (("perfect", None), ("20 ms each way", {"delay_ms": 20.0}))
LAWS = ("bsst", "smc", "pid")
SERIES = 200  # 30 s series for the chance of one flight meeting the issue's wording


def wind_table(seeds: int) -> None:
    print("## --wind 5:270 --turbulence moderate, sine, per seed (30 s): the default record scaled to σ "
          "(exact), and the filters free-running (--turbulence-scaling none, ± the expected sampling error)\n")
    print("| seed | outcome | RMS m | mean along m/s | std u, v, w / σ | record's scale u, v, w "
          "| none: outcome | RMS m | mean along m/s | std u / σ_u | std v / σ_v | std w / σ_w |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    pooled = [0.0, 0.0, 0.0]
    means = []
    w: dict = {}
    for seed in range(seeds):
        s = simulate(MISSION, wind=(5.0, 270.0), turbulence="moderate", seed=seed).summary
        x = s["wind"]
        sig = x["dryden"]["sigma_mps"]
        exact = (f"| {seed} | {s['outcome']} | {s['rms_3d']:.4f} | {x['mean_mps']['along']:.2f} | "
                 + ", ".join(f"{x['turbulence_std_mps'][k] / sig[k]:.2f}" for k in "uvw") + " | "
                 + ", ".join(f"{x['record']['scale'][k]:.2f}" for k in "uvw") + " | ")
        s = simulate(MISSION, wind={"speed_mps": 5.0, "from_deg": 270.0, "turbulence": "moderate",
                                    "turbulence_scaling": "none"}, seed=seed).summary
        w = s["wind"]
        std, se = w["turbulence_std_mps"], w["sampling"]
        means.append(w["mean_mps"]["along"])
        for i, k in enumerate("uvw"):
            pooled[i] += std[k] ** 2
        print(exact + f"{s['outcome']} | {s['rms_3d']:.4f} | {w['mean_mps']['along']:.2f} ± "
              f"{se['mean_along_se_mps']:.2f} | "
              + " | ".join(f"{std[k] / sig[k]:.2f} ± {se['std_rel_se'][k]:.2f}" for k in "uvw") + " |")
    sig = w["dryden"]["sigma_mps"]
    print(f"| pooled | | | | | | | | {sum(means) / len(means):.2f} | "
          + " | ".join(f"{math.sqrt(pooled[i] / seeds) / sig[k]:.2f}" for i, k in enumerate("uvw")) + " |")
    config = WindConfig(w["speed_mps"], w["from_deg"], w["turbulence"], w["altitude_m"])
    lr = long_run(config, seed=0)
    se = lr["sampling"]
    print(f"| 3600 s, seed 0 | | | | | | | | {lr['mean_along_mps']:.2f} ± {se['mean_along_se_mps']:.2f} | "
          + " | ".join(f"{lr['turbulence_std_mps'][k] / sig[k]:.3f} ± {se['std_rel_se'][k]:.3f}" for k in "uvw")
          + " |")
    print(f"\nσ (MIL-HDBK-1797, moderate, h = {w['dryden']['model_altitude_m']:.3f} m): "
          + ", ".join(f"{k} {sig[k]:.3f} m/s" for k in "uvw") + "\n")
    hits = [0, 0, 0]
    for seed in range(SERIES):  # the issue's two checks on 30 s series of the free-running filters
        lr = long_run(config, seed=seed, duration_s=30.0)
        mean_ok = abs(lr["mean_along_mps"] - 5.0) <= 0.5
        sigma_ok = all(abs(lr["turbulence_std_mps"][k] / sig[k] - 1.0) <= 0.2 for k in "uvw")
        hits[0], hits[1], hits[2] = hits[0] + mean_ok, hits[1] + sigma_ok, hits[2] + (mean_ok and sigma_ok)
    print(f"Of {SERIES} 30 s series of the free-running filters (plant.wind.long_run, duration_s=30, seeds "
          f"0..{SERIES - 1}): mean along within 0.5 m/s of 5 in {hits[0]}, every σ within 20 % in {hits[1]}, both "
          f"in {hits[2]}; a record scaled to σ meets both in every flight.\n")


def long_flight(duration_s: float) -> None:
    print(f"## a long flight: missions/step.toml held at its last set-point (1.5 m: the sine's h = 10 ft, the same σ "
          f"and L) for {duration_s:g} s, --wind 5:270 --turbulence moderate --turbulence-scaling none, seed 0\n")
    m = replace(load_mission("missions/step.toml"), duration_s=duration_s)
    s = simulate(m, wind={"speed_mps": 5.0, "from_deg": 270.0, "turbulence": "moderate",
                          "turbulence_scaling": "none"}).summary  # free: the filters' own statistics, converging
    w = s["wind"]
    sig, std, se = w["dryden"]["sigma_mps"], w["turbulence_std_mps"], w["sampling"]
    print(f"outcome {s['outcome']}; mean along {w['mean_mps']['along']:.3f} ± {se['mean_along_se_mps']:.3f} m/s; "
          + ", ".join(f"std {k} / σ_{k} {std[k] / sig[k]:.3f} ± {se['std_rel_se'][k]:.3f}" for k in "uvw") + "\n")


def law_table() -> None:
    print("## sine: 3-D RMS (m) / u2 ripple (N)\n")
    print("| law | link | " + " | ".join(n for n, _ in WEATHERS) + " |")
    print("|---|---|" + "---|" * len(WEATHERS))
    for law in LAWS:
        for lname, link in LINKS:
            cells = []
            for _, over in WEATHERS:
                s = simulate(MISSION, controller=law, link=link, **over).summary
                cell = f"{s['rms_3d']:.3g} / {s['inputs']['u2']['ripple']:.3g}"
                cells.append(cell if s["outcome"] == "completed" else f"{s['outcome']} ({cell})")
            print(f"| {law} | {lname} | " + " | ".join(cells) + " |")
    print()


def fault_table() -> None:
    print("## x500, sine, --at 10:motor:1=E\n")
    print("| law | attitude gains | E | outcome | RMS m | ended by |")
    print("|---|---|---|---|---|---|")
    for law in LAWS:
        for eff in (0.9, 0.75, 0.6, 0.0):
            for gains, mission in (("default", MISSION), ("fault-sized", "examples/x500-motor-fault.toml")):
                s = simulate(mission, profile="x500", controller=law, at=(f"10:motor:1={eff:g}",)).summary
                print(f"| {law} | {gains} | {eff:g} | {s['outcome']} | {s['rms_3d']:.4g} | {s['ended_by']['how']} |")
    for on in (14, 20):  # under EKF2_NOAID_TOUT (5 s), and over it: PX4's failsafe descends at its timeout
        print(f"\n## GPS loss: sine, --sensors gnss --estimator ekf --at 10:gps:off --at {on}:gps:on\n")
        s = simulate(MISSION, sensors={"set": "gnss"}, estimator="ekf", at=("10:gps:off", f"{on}:gps:on")).summary
        (o,) = s["gps_outages"]
        print(f"outcome {s['outcome']} ({s['ended_by']['how']}), RMS {s['rms_3d']:.3f} m; drift during the outage max "
              f"{o['drift_max_m']:.3f} m, {o['drift_at_end_m']:.3f} m at its end; after it: NEES mean "
              f"{o['nees_mean_after']:.2f} (9 dof), position error RMS {o['drift_rms_after_m']:.3f} m\n")


def gps_hold_table() -> None:
    """The x500 (gnss, EKF) taken off by a ground station to 5 m and held (HOLD), GPS off at 6 s and on again at
    12 s, or never: the vehicle core offline, as a session's vehicle flies it (SimVehicle's TAKEOFF and HOLD)."""
    print("## x500 held at 5 m by a ground station, GPS off at 6 s\n")
    print("| GPS on | event (s: what) | at the end: true x, y, z m | from the hold point m | estimate's error m |")
    print("|---|---|---|---|---|")
    ground = Mission(Step((Setpoint(0.0, 0.0, 0.0, 0.0, 0.0),)), duration_s=60.0, name="hold", profile="x500")
    for on in ("12:gps:on", None):
        sim = prepare(ground, at=("6:gps:off",) + ((on,) if on else ()), sensors={"set": "gnss"},
                      estimator="ekf").make_vehicle()
        sim.set_mode(TAKEOFF, 5.0)
        sim.arm_in_mode()
        intention = UserModeIntention(sim)  # the mode its failsafe's disarm leaves, as a session's vehicle takes it
        held = None
        while sim.armed and sim.t < 30.0:
            sim.advance()
            intention.after_period()
            held = sim.plant.state if held is None and sim.mode == HOLD else held
        X, E = sim.plant.state, sim.published()
        said = "; ".join(f"{e.t:.3f}: {e.kind}: {e.text.split(' (')[0]}" for e in sim.events if e.t > 5.0)
        print(f"| {on or 'never'} | {said} | {X[0]:.2f}, {X[2]:.2f}, {X[4]:.2f} | "
              f"{math.hypot(X[0] - held[0], X[2] - held[2]):.2f} | {math.hypot(X[0] - E[0], X[2] - E[2]):.2f} |")
    print()


def margin_table(jobs: int | None) -> None:
    print("## bsst margin missions/sine.toml --over wind_mps --until rms=0.1\n")
    print("| law | link | margin m/s | bracket | cells |")
    print("|---|---|---|---|---|")
    for law in LAWS:
        for lname, link in LINKS:
            m = prepare(MISSION, link=link).mission
            e = margin(m, "wind_mps", parse_until("rms=0.1"), controllers=(law,), jobs=jobs)
            row = e["controllers"][0]  # one law: its entry
            print(f"| {law} | {lname} | {row['margin']} | {row['bracket']} | {e['cells_flown']} |")
    print()


def batch_table(jobs: int | None) -> None:
    import tempfile
    import time

    from bridge.batch import fly_batch
    from bridge.sweep import Grid, sweep

    grid = Grid(controller=LAWS, wind_mps=(0.0, 5.0, 10.0), turbulence=("none", "moderate", "severe"),
                delay_ms=(0.0, 20.0))
    # the batch flies no end action and refuses a landing in wind (which may crash, and it cannot judge): the two
    # engines are compared on the flight itself, the mission ending in a hold
    print("## batch against process: sine ending in a hold ([end] action = hold), --controller bsst,smc,pid "
          "--wind 0,5,10 --turbulence none,moderate,severe --delay 0,20 (54 cells, 30 s)\n")
    rows, wall = {}, {}
    held = replace(load_mission(MISSION), end_action="hold")
    with tempfile.TemporaryDirectory() as tmp:
        for engine in ("batch", "process"):
            t0 = time.perf_counter()
            rows[engine] = sweep(held, grid, engine=engine, jobs=jobs, out=Path(tmp) / engine, report=False)
            wall[engine] = time.perf_counter() - t0
    worst: dict[str, float] = {}
    differ = 0
    for a, b in zip(rows["batch"], rows["process"], strict=True):
        differ += a["outcome"] != b["outcome"]
        rel = abs(a["rms"] - b["rms"]) / max(abs(b["rms"]), 1e-300)
        worst[a["controller"]] = max(worst.get(a["controller"], 0.0), rel)
    print("| law | largest relative RMS difference |\n|---|---|")
    for law in LAWS:
        print(f"| {law} | {worst[law]:.2e} |")
    print(f"\noutcomes that differ: {differ} of {len(rows['batch'])}; wall time: batch {wall['batch']:.1f} s "
          f"(its kernels compiled or loaded included), process {wall['process']:.1f} s "
          f"(--jobs {jobs or os.cpu_count()})\n")
    # the batch refuses a motor fault before an end landing (a landing on a weak rotor may crash, which it cannot
    # judge): the two engines are compared on the flight itself, the mission ending in a hold
    print("## x500 motor faults (examples/x500-motor-fault.toml --at 10:motor:1=E, [end] action = hold): batch "
          "against bsst sim\n")
    print("| law | E | batch outcome / RMS m | bsst sim outcome / RMS m | bsst sim with its end landing |\n"
          "|---|---|---|---|---|")
    fault = "examples/x500-motor-fault.toml"
    held = replace(load_mission(fault), end_action="hold")  # (the same rule)
    cells = [{"controller": law, "at": (f"10:motor:1={e:g}",)} for law in LAWS for e in (0.9, 0.75, 0.6, 0.0)]
    for c, got in zip(cells, fly_batch(held, cells), strict=True):
        s = simulate(held, **c).summary
        landed = simulate(fault, **c).summary["outcome"]
        print(f"| {c['controller']} | {c['at'][0].rsplit('=', 1)[1]} | {got['outcome']} / {got['rms']:.6g} | "
              f"{s['outcome']} / {s['rms_3d']:.6g} | {landed} |")
    print()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("what", nargs="?", default="all",
                    choices=("wind", "long", "table", "faults", "margin", "batch", "all"))
    ap.add_argument("--long-s", type=float, default=1200.0, help="the long flight's duration (s)")
    ap.add_argument("--seeds", type=int, default=8)
    ap.add_argument("--jobs", type=int, default=None, help="margin's and batch's workers (default: all cores)")
    a = ap.parse_args()
    print("load average (1, 5, 15 min) at the start: {:.2f} {:.2f} {:.2f}\n".format(*os.getloadavg()))
    if a.what in ("wind", "all"):
        wind_table(a.seeds)
    if a.what in ("long", "all"):
        long_flight(a.long_s)
    if a.what in ("table", "all"):
        law_table()
    if a.what in ("faults", "all"):
        fault_table()
        gps_hold_table()
    if a.what in ("margin", "all"):
        margin_table(a.jobs)
    if a.what in ("batch", "all"):
        batch_table(a.jobs)
    print("load average (1, 5, 15 min) at the end: {:.2f} {:.2f} {:.2f}".format(*os.getloadavg()))


if __name__ == "__main__":
    main()
