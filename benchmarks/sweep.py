"""Speed of ``bsst sweep``: the batch engine against the process engine, and the process engine's
parallel speed-up.

First issue 13's acceptance figures (benchmarks/batch_engine.py's measurement, without its per-step
and 2-worker parts): a 1000-cell sweep of the 30 s sine with the batch engine (wall time, cells/s,
peak memory) against ``--engine process --jobs 2`` on a 32-cell subset of the same grid, their ratio
(target >= 20) and the load average. Then the process engine's ``--jobs 2`` against ``--jobs 1``:
the same grid flown twice through the local process pool (no files written), both wall times and
their ratio (target <= 0.65 on two cores). Exit status 1 when a target is missed (or the two runs
disagree), 0 otherwise.

    .venv/bin/python benchmarks/sweep.py                     # sine, delay 0,5,10,20 x loss 0,10,20,40
    .venv/bin/python benchmarks/sweep.py --seeds 3 --jobs 4  # the acceptance grid, 4 workers vs 1
    .venv/bin/python benchmarks/sweep.py --no-batch          # the process engine's speed-up only
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from batch_engine import acceptance, print_acceptance  # noqa: E402  (benchmarks/ is this script's directory)

from bridge.sweep import Grid, sweep  # noqa: E402
from missions import load_mission  # noqa: E402

TARGET = 0.65


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mission", default=str(Path(__file__).resolve().parent.parent / "missions" / "sine.toml"))
    ap.add_argument("--duration", type=float, default=None, help="fly only this many seconds of the mission")
    ap.add_argument("--seeds", type=int, default=1)
    ap.add_argument("--jobs", type=int, default=2, help="workers of the parallel run (compared with 1)")
    ap.add_argument("--repeat", type=int, default=2,
                    help="alternate the two runs this many times and keep each one's fastest (other load on the "
                         "machine only ever slows a run down)")
    ap.add_argument("--no-batch", action="store_true", help="leave out issue 13's batch against process figures")
    args = ap.parse_args()
    batch_ok = True
    if not args.no_batch:
        sine = load_mission(Path(__file__).resolve().parent.parent / "missions" / "sine.toml")
        figures = acceptance(sine, 1000, repeats=0)
        print_acceptance(figures)
        batch_ok = figures["ok"]
    mission = load_mission(args.mission)
    if args.duration:
        mission = mission.with_overrides(duration_s=args.duration)
    grid = Grid(delay_ms=(0, 5, 10, 20), loss_pct=(0, 10, 20, 40), seeds=args.seeds)
    n = len(grid.delay_ms) * len(grid.loss_pct) * args.seeds
    print(f"grid: {n} cells of {mission.name} ({mission.duration_s:g} s each), {os.cpu_count()} cores, "
          f"load average {os.getloadavg()[0]:.2f}")
    wall: dict[int, float] = {}
    rows = {}
    for i in range(args.repeat):
        for jobs in (1, args.jobs):
            t0 = time.perf_counter()
            rows[jobs] = sweep(mission, grid, jobs=jobs, engine="process")  # auto takes the batch from 32 cells
            w = time.perf_counter() - t0
            wall[jobs] = min(w, wall.get(jobs, w))
            print(f"run {i + 1}: --jobs {jobs}: {w:.2f} s wall ({w / n * 1e3:.0f} ms per cell)")
    print(f"fastest: --jobs 1 {wall[1]:.2f} s, --jobs {args.jobs} {wall[args.jobs]:.2f} s; "
          f"load average now {os.getloadavg()[0]:.2f}")
    ratio = wall[args.jobs] / wall[1]
    same = rows[1] == rows[args.jobs]
    print(f"ratio jobs {args.jobs} / jobs 1: {ratio:.3f} (target <= {TARGET}: {'met' if ratio <= TARGET else 'MISSED'})"
          f"; rows identical: {same}")
    return 0 if ratio <= TARGET and same and batch_ok else 1


if __name__ == "__main__":
    sys.exit(main())
