"""Parallel speed-up of ``bsst sweep``: wall time with ``--jobs 2`` against ``--jobs 1``.

Flies the same grid twice through the local process pool (no files written) and prints both
wall times and their ratio; the target is a ratio <= 0.65 on two cores. Exit status 1 when
the ratio misses the target (or the two runs disagree), 0 otherwise.

    .venv/bin/python benchmarks/sweep.py                     # sine, delay 0,5,10,20 x loss 0,10,20,40
    .venv/bin/python benchmarks/sweep.py --seeds 3 --jobs 4  # the acceptance grid, 4 workers vs 1
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from bridge.sweep import Grid, sweep  # noqa: E402
from missions import load_mission  # noqa: E402

TARGET = 0.65


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mission", default=str(Path(__file__).resolve().parent.parent / "missions" / "sine.toml"))
    ap.add_argument("--duration", type=float, default=None, help="fly only this many seconds of the mission")
    ap.add_argument("--seeds", type=int, default=1)
    ap.add_argument("--jobs", type=int, default=2, help="workers of the parallel run (compared with 1)")
    args = ap.parse_args()
    mission = load_mission(args.mission)
    if args.duration:
        mission = mission.with_overrides(duration_s=args.duration)
    grid = Grid(delay_ms=(0, 5, 10, 20), loss_pct=(0, 10, 20, 40), seeds=args.seeds)
    n = len(grid.delay_ms) * len(grid.loss_pct) * args.seeds
    print(f"grid: {n} cells of {mission.name} ({mission.duration_s:g} s each), {os.cpu_count()} cores")
    wall = {}
    rows = {}
    for jobs in (1, args.jobs):
        t0 = time.perf_counter()
        rows[jobs] = sweep(mission, grid, jobs=jobs)
        wall[jobs] = time.perf_counter() - t0
        print(f"--jobs {jobs}: {wall[jobs]:.2f} s wall ({wall[jobs] / n * 1e3:.0f} ms per cell)")
    ratio = wall[args.jobs] / wall[1]
    same = rows[1] == rows[args.jobs]
    print(f"ratio jobs {args.jobs} / jobs 1: {ratio:.3f} (target <= {TARGET}: {'met' if ratio <= TARGET else 'MISSED'})"
          f"; rows identical: {same}")
    return 0 if ratio <= TARGET and same else 1


if __name__ == "__main__":
    sys.exit(main())
