"""Several vehicles in one world, offline (issue 28): the figures of its acceptance list that ``bsst sim`` can give.

- four in a line: ``bsst sim missions/sine.toml --vehicles 4 --formation line:2``: each vehicle's 3-D RMS
  (target <= 1e-4 m, as the single vehicle), every pair's closest approach between rotor discs (m), the
  separation policy (must hold), the exit status (0);
- a near miss: ``bsst sim examples/swarm-near-miss.toml`` (paths 0.9 m apart): the closest approach (under the
  0.5 m minimum), the policy (broken), the exit status (1);
- a touch: ``bsst sim examples/swarm-touch.toml`` (paths 0.4 m apart): each vehicle's outcome (``collision``),
  the exit status (1);
- speed: the wall time of one vehicle's sine and of the four, in the same process, interleaved, their ratio
  (4 vehicles' steps cost about 4 single ones: the loop adds only the separation check), and the real-time
  factor of the four; with the load average, since other work on the machine slows every figure alike;
- SITL in lockstep (``bsst sitl missions/sine.toml --vehicles 4 --formation line:2``, through
  ``bridge.swarm.sitl`` on free ports so that it runs beside other sessions), on the fleet's one shared step
  clock: each vehicle's largest distance from the offline fleet's trace (target <= 1e-4 m), the fleet's
  real-time factor (the mission's time over the wall time from start to the last summary: start-up included)
  and each pair's own (its ``timing`` block: the flight alone), against one vehicle's session run just before;
  target >= 4x real time on 2 cores (eight processes for four vehicles: a machine shared with other work gives
  less, and the load average says how shared it was). Since the machine is shared, also the CPU time the fleet
  used (its processes' user + system, start-up included), per vehicle and step, and the real-time factor that
  CPU time allows on two cores of its own (the mission's time over half the CPU time): what an idle 2-core
  machine would give at best. ``--no-sitl`` leaves it out.

Each run goes through ``bridge.cli.main`` (the command's own exit status), into a temporary directory.

    .venv/bin/python benchmarks/swarm.py [--repeats 3] [--json] [--no-sitl]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from bridge.cli import main  # noqa: E402
from bridge.nodes.forkserver import forked_cpu_s  # noqa: E402

TARGET_RMS_M = 1e-4


def bsst_sim(*args: str) -> tuple[int, dict[str, Any], float]:
    """Run ``bsst sim ARGS --no-plots`` into a fresh directory: exit status, summary.json, wall seconds."""
    with tempfile.TemporaryDirectory() as d:
        out = Path(d) / "run"
        t0 = time.perf_counter()
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            code = main(["sim", *args, "--out", str(out), "--no-plots"])
        wall = time.perf_counter() - t0
        return code, json.loads((out / "summary.json").read_text()), wall


def figures(repeats: int) -> dict[str, Any]:
    os.chdir(ROOT)
    line_code, line, _ = bsst_sim("missions/sine.toml", "--vehicles", "4", "--formation", "line:2")
    near_code, near, _ = bsst_sim("examples/swarm-near-miss.toml")
    touch_code, touch, _ = bsst_sim("examples/swarm-touch.toml")
    one_s, four_s = [], []
    for _ in range(repeats):  # interleaved: both see the same load
        one_s.append(bsst_sim("missions/sine.toml")[2])
        four_s.append(bsst_sim("missions/sine.toml", "--vehicles", "4", "--formation", "line:2")[2])
    one, four = statistics.median(one_s), statistics.median(four_s)
    return {
        "line": {"exit": line_code, "outcome": line["outcome"],
                 "rms_3d": {v["id"]: v["rms_3d"] for v in line["vehicles"]},
                 "closest_m": {f"{p['ids'][0]}-{p['ids'][1]}": p["closest_m"] for p in line["separation"]["pairs"]},
                 "separation_ok": line["policies"][0]["ok"]},
        "near_miss": {"exit": near_code, "closest_m": near["separation"]["closest_m"],
                      "separation_ok": near["policies"][0]["ok"], "outcomes": [v["outcome"] for v in near["vehicles"]]},
        "touch": {"exit": touch_code, "closest_m": touch["separation"]["closest_m"],
                  "outcomes": [v["outcome"] for v in touch["vehicles"]]},
        "speed": {"one_vehicle_s": one, "four_vehicles_s": four, "ratio": four / one,
                  "four_real_time_factor": line["duration_s"] / four, "repeats": repeats},
        "loadavg": os.getloadavg(),
    }


def sitl_figures() -> dict[str, Any]:
    """Four vehicles of the sine in lockstep SITL against the offline fleet, and one vehicle's session."""
    import numpy as np

    from bridge.swarm import simulate, sitl

    os.chdir(ROOT)
    mission = "missions/sine.toml"
    load0 = os.getloadavg()
    t0, c0 = time.perf_counter(), cpu_s()
    one = sitl(mission, instance=None, plots=False)
    one_wall, one_cpu = time.perf_counter() - t0, cpu_s() - c0
    t0, c0 = time.perf_counter(), cpu_s()
    four = sitl(mission, vehicles=4, formation="line:2", instance=None, plots=False)
    four_wall, four_cpu = time.perf_counter() - t0, cpu_s() - c0
    off = simulate(mission, vehicles=4, formation="line:2", plots=False)
    gaps = {}
    for v, a, b in zip(four.summary["vehicles"], four.runs, off.runs):
        n = min(len(a.trace["t"]), len(b.trace["t"]))
        gap = max(float(np.max(np.abs(a.trace[c][:n] - b.trace[c][:n]))) for c in ("x", "y", "z"))
        gaps[v["id"]] = gap if len(a.trace["t"]) == len(b.trace["t"]) else float("inf")
    duration = four.summary["duration_s"]
    return {"outcome": four.outcome, "separation_ok": four.summary["policies"][0]["ok"], "gap_m": gaps,
            "one_rtf": duration / one_wall, "one_flight_rtf": one.summary["timing"]["real_time_factor"],
            "fleet_rtf": duration / four_wall, "wall_s": four_wall, "cpu_s": four_cpu, "one_cpu_s": one_cpu,
            "steps": duration * four.summary["rate_hz"], "duration_s": duration,
            "shared_clock": four.summary["sitl"]["shared_clock"],
            "gate_wait_s": {i: (g or {}).get("wait_s") for i, g in (four.summary["sitl"].get("gate") or {}).items()},
            "pair_rtf": {v["id"]: r.summary["timing"]["real_time_factor"] for v, r in zip(four.summary["vehicles"],
                                                                                          four.runs)},
            "loadavg_before": load0, "loadavg_after": os.getloadavg()}


def cpu_s() -> float:
    """CPU seconds (user + system) of this process, of its children waited for, and of the sessions' processes
    (forked by this process's fork server: bridge.nodes.forkserver)."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system + forked_cpu_s()


def print_sitl(f: dict[str, Any]) -> None:
    print("bsst sitl missions/sine.toml --vehicles 4 --formation line:2 (lockstep, free ports)")
    for i, g in f["gap_m"].items():
        print(f"  vehicle {i}: largest distance from the offline fleet's trace {g:.3e} m "
              f"({'<=' if g <= TARGET_RMS_M else '>'} {TARGET_RMS_M:g} m)")
    print(f"  outcome {f['outcome']}; separation policy {'holds' if f['separation_ok'] else 'BROKEN'}")
    print(f"  real-time factor: the fleet {f['fleet_rtf']:.2f}x (wall {f['wall_s']:.1f} s, start-up included; "
          f"target >= 4x on 2 cores); each pair's flight " + ", ".join(f"{v:.2f}x" for v in f["pair_rtf"].values()))
    print(f"  one vehicle's session just before: {f['one_rtf']:.2f}x (its flight {f['one_flight_rtf']:.2f}x)")
    per = 1e6 * f["cpu_s"] / (4 * f["steps"])
    print(f"  CPU time (all processes, start-up included): the fleet {f['cpu_s']:.1f} s ({per:.0f} us per vehicle "
          f"and step), one vehicle's session {f['one_cpu_s']:.1f} s; on two cores of its own the fleet's CPU time "
          f"allows at best {f['duration_s'] / (f['cpu_s'] / 2):.2f}x real time")
    print(f"  shared step clock: {f['shared_clock']}; seconds each vehicle waited at its gate: "
          + ", ".join(f"{i}: {w}" for i, w in f["gate_wait_s"].items()))
    print("  load average before " + " ".join(f"{x:.2f}" for x in f["loadavg_before"]) + ", after " +
          " ".join(f"{x:.2f}" for x in f["loadavg_after"]) + " (a machine shared with other work)")


def main_() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--no-sitl", action="store_true", help="leave out the SITL fleet's figures")
    a = ap.parse_args()
    f = figures(a.repeats)
    if not a.no_sitl:
        f["sitl"] = sitl_figures()
    if a.json:
        print(json.dumps(f, indent=2))
        return 0
    ln, nm, tc, sp = f["line"], f["near_miss"], f["touch"], f["speed"]
    print("bsst sim missions/sine.toml --vehicles 4 --formation line:2")
    for i, r in ln["rms_3d"].items():
        print(f"  vehicle {i}: 3-D RMS {r:.3e} m ({'<=' if r <= TARGET_RMS_M else '>'} {TARGET_RMS_M:g} m)")
    print("  closest approach between rotor discs: " + ", ".join(f"{k} {v:.3f} m" for k, v in ln["closest_m"].items()))
    print(f"  separation policy {'holds' if ln['separation_ok'] else 'BROKEN'}; outcome {ln['outcome']}; "
          f"exit {ln['exit']} (want 0)")
    print(f"bsst sim examples/swarm-near-miss.toml: closest {nm['closest_m']:.3f} m, separation policy "
          f"{'holds' if nm['separation_ok'] else 'broken'}, outcomes {nm['outcomes']}, exit {nm['exit']} (want 1)")
    print(f"bsst sim examples/swarm-touch.toml: closest {tc['closest_m']:.3f} m, outcomes {tc['outcomes']}, "
          f"exit {tc['exit']} (want 1)")
    print(f"speed (median of {sp['repeats']}, interleaved): one vehicle {sp['one_vehicle_s']:.2f} s, four "
          f"{sp['four_vehicles_s']:.2f} s, ratio {sp['ratio']:.2f}; four fly {sp['four_real_time_factor']:.1f}x "
          "real time")
    print("load average: " + " ".join(f"{x:.2f}" for x in f["loadavg"]))
    if "sitl" in f:
        print_sitl(f["sitl"])
    return 0


if __name__ == "__main__":
    sys.exit(main_())
