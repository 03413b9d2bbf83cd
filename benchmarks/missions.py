"""Benchmark: a ground station's plan flown offline, and the figures issue 26 asks of it.

In:  a plan (``examples/box.plan`` by default; ``.plan`` or ``QGC WPL 110``), optionally a ``bsst sitl`` run
     directory of the same plan to compare with
Out: printed: completed, landed and disarmed; the distance (m) of the flight to each waypoint the plan names;
     the 3-D RMS (m) of the tracking error with BS-ST; the jump of the reference velocity (m/s) across each
     pass-through waypoint; the yaw reference's figures (:func:`yaw_figures`); with ``--sitl DIR``, the largest
     position difference (m) between it and offline

    python benchmarks/missions.py [examples/box.plan] [--sitl runs/box-sitl]
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from bridge import simulate  # noqa: E402
from missions import load_mission  # noqa: E402
from missions.minsnap import Smooth  # noqa: E402
from missions.mission import is_plan_file  # noqa: E402
from missions.planfiles import read_plan_text  # noqa: E402
from missions.route import Limits, route_of  # noqa: E402
from params import read_text_file  # noqa: E402


def yaw_figures(ref: Smooth, named: set[int], samples: int = 200) -> dict:
    """The yaw reference's figures (rad, rad/s): on the straight legs whose two guide knots (unnamed knots, the
    route's) both hold the leg's heading, the most it is off that heading between them; the most it passes its
    segment's knots' yaws anywhere; its peak rate (against MPC_YAWRAUTO_MAX)."""
    ks = ref.knots
    off = past = rate = 0.0
    legs = held = 0
    for j in range(len(ks) - 1):
        a, b = ks[j], ks[j + 1]
        heading = math.atan2(b.y - a.y, b.x - a.x)
        straight = j > 0 and j not in named and j + 1 not in named and math.hypot(b.x - a.x, b.y - a.y) > 1.0
        holds = straight and all(abs(math.remainder(k.psi - heading, 2 * math.pi)) < 1e-9 for k in (a, b))
        legs, held = legs + straight, held + holds
        for i in range(1, samples):
            p = ref.sample(a.t + (b.t - a.t) * i / samples)[3]
            past = max(past, p[0] - max(a.psi, b.psi), min(a.psi, b.psi) - p[0])
            rate = max(rate, abs(p[1]))
            if holds:
                off = max(off, abs(math.remainder(p[0] - heading, 2 * math.pi)))
    return {"straight_legs": legs, "holding_heading": held, "off_heading_rad": off, "past_knots_rad": past,
            "peak_rate_rad_s": rate}


def figures(plan: Path) -> dict:
    """Fly ``plan`` offline with BS-ST; the acceptance figures as a dict."""
    assert is_plan_file(plan), f"{plan}: not a plan file"
    mission = load_mission(plan)
    ref = mission.trajectory
    assert isinstance(ref, Smooth)
    text = read_text_file(plan, "a mission plan")
    pf = read_plan_text(text, str(plan))
    route = route_of(pf, Limits(MPC_XY_CRUISE=pf.cruise_m_s or Limits().MPC_XY_CRUISE), 100.0)
    run = simulate(mission, plots=False)
    tr = run.trace
    t, x, y, z = (tr[k] for k in ("t", "x", "y", "z"))
    passes = []
    for label, k, stop in route.waypoints:
        kn = ref.knots[k]
        d = min(math.dist((x[i], y[i], z[i]), (kn.x, kn.y, kn.z)) for i in range(len(t)))
        passes.append({"item": label, "knot": k, "stop": stop, "closest_m": d})
    jumps = []
    for label, k, stop in route.waypoints:
        if not stop:
            tk = ref.knots[k].t
            a, b = ref.sample(tk - 1e-9), ref.sample(tk + 1e-9)
            jumps.append({"item": label, "speed_m_s": math.hypot(b[0][1], b[1][1], b[2][1]),
                          "jump_m_s": math.dist([v[1] for v in a[:3]], [v[1] for v in b[:3]])})
    end = run.summary.get("end") or {}  # the end action's block: disarmed on the ground, and at what height
    return {"plan": str(plan), "outcome": run.summary["outcome"], "duration_s": mission.duration_s,
            "landed_and_disarmed": bool(end.get("disarmed")) and abs(end.get("disarm_z_m", math.inf)) <= 0.05
            and abs(float(z[-1])) <= 0.05,
            "rms_3d_all_m": math.sqrt(sum(run.summary["axes"][a]["rms_all"] ** 2 for a in "xyz")),
            "waypoints": passes, "pass_through": jumps, "trace": tr,
            "yaw": yaw_figures(ref, {k for _, k, _ in route.waypoints})}


def sitl_difference(trace: dict, run_dir: Path) -> float:
    """Largest 3-D position difference (m) between an offline trace and a SITL run's trace.csv, row by row."""
    with open(run_dir / "trace.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    n = min(len(rows), len(trace["t"]))
    return max(math.dist((float(rows[i]["x"]), float(rows[i]["y"]), float(rows[i]["z"])),
                         (trace["x"][i], trace["y"][i], trace["z"][i])) for i in range(n))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("plan", nargs="?", default=str(ROOT / "examples" / "box.plan"))
    ap.add_argument("--sitl", help="a `bsst sitl` run directory of the same plan, to compare with")
    args = ap.parse_args()
    fig = figures(Path(args.plan))
    print(f"plan {fig['plan']}: {fig['duration_s']:.2f} s, outcome {fig['outcome']}, "
          f"landed and disarmed: {fig['landed_and_disarmed']}")
    print(f"3-D RMS tracking error (BS-ST, whole flight): {fig['rms_3d_all_m']:.3e} m")
    for w in fig["waypoints"]:
        print(f"  {w['item']:<20} {'stop' if w['stop'] else 'pass'}  closest {w['closest_m']:.2e} m")
    for j in fig["pass_through"]:
        print(f"  pass-through {j['item']:<20} speed {j['speed_m_s']:.3f} m/s  velocity jump {j['jump_m_s']:.1e} m/s")
    y = fig["yaw"]
    print(f"yaw: {y['holding_heading']} of {y['straight_legs']} straight legs hold their heading at both guide knots, "
          f"off it between them by <= {math.degrees(y['off_heading_rad']):.2f} deg; past its knots by <= "
          f"{math.degrees(y['past_knots_rad']):.2f} deg; peak rate {math.degrees(y['peak_rate_rad_s']):.2f} deg/s")
    if args.sitl:
        diff = sitl_difference(fig["trace"], Path(args.sitl))
        summary = json.loads((Path(args.sitl) / "summary.json").read_text())
        print(f"lockstep SITL ({args.sitl}): outcome {summary['outcome']}, largest position difference from "
              f"offline {diff:.2e} m")


if __name__ == "__main__":
    main()
