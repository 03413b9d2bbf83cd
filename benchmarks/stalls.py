"""How late this machine wakes a real-time loop: a 4 ms periodic sleeper, the product's stall rule, with and
without busy loops on the cores (docs/sitl.md, "Stalls").

In:  --seconds S (each case), --busy N,... (busy loops started for a case: 0,1,2 by default), --fifo (the sleeper
     asks SCHED_FIFO priority 1, as a flight stack's rate loop may; needs CAP_SYS_NICE)
Out: per case, the wake-ups' lateness (ms: p50, p99, max), how many were over the stall threshold, and the stalls
     as bridge.core.clock.Stalls records them ([t s, ms]); the load average before and after

    .venv/bin/python benchmarks/stalls.py --seconds 10 --busy 0,1,2
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time

from bridge.core.clock import STALL_S, Stalls

PERIOD_S = 0.004  # the control period at 250 Hz


def sleeper(seconds: float) -> tuple[list[float], Stalls]:
    """Sleep to each 4 ms tick for ``seconds``: every wake-up's lateness (s), and the stalls among them."""
    n = int(seconds / PERIOD_S)
    stalls = Stalls()
    late = []
    t0 = due = time.monotonic()
    for _ in range(n):
        due += PERIOD_S
        wait = due - time.monotonic()
        if wait > 0:
            time.sleep(wait)
        lateness = time.monotonic() - due
        late.append(lateness)
        stalls.note(due - t0, lateness)
    return late, stalls


def _normal_priority() -> None:
    """In a busy loop's child: the normal policy (a child inherits SCHED_FIFO, and a loop at it starves the
    machine)."""
    os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))


def busy_loops(n: int) -> list[subprocess.Popen]:
    return [subprocess.Popen(["sh", "-c", "while :; do :; done"], preexec_fn=_normal_priority) for _ in range(n)]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--busy", default="0,1,2", help="busy loops per case, comma-separated")
    ap.add_argument("--fifo", action="store_true", help="the sleeper at SCHED_FIFO priority 1")
    args = ap.parse_args()
    if args.fifo:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
        except PermissionError:
            print("SCHED_FIFO refused (no CAP_SYS_NICE): the sleeper runs at its normal priority", file=sys.stderr)
            return 1
    print(f"load average {os.getloadavg()}; {os.cpu_count()} cores; stall: a wake-up over {1e3 * STALL_S:g} ms late; "
          f"{'SCHED_FIFO 1' if args.fifo else 'normal priority'}")
    for busy in (int(b) for b in args.busy.split(",")):
        loops = busy_loops(busy)
        try:
            time.sleep(0.5)  # the loops running before the measurement starts
            late, stalls = sleeper(args.seconds)
        finally:
            for p in loops:
                p.kill()
                p.wait()
        ms = sorted(1e3 * x for x in late)
        over = sum(x > 1e3 * STALL_S for x in ms)
        r = stalls.report()
        print(f"busy loops {busy}: {len(ms)} wake-ups, late p50 {ms[len(ms) // 2]:.3f} ms p99 "
              f"{ms[int(0.99 * len(ms))]:.3f} ms max {ms[-1]:.1f} ms; over {1e3 * STALL_S:g} ms: {over}; "
              f"stalls {r['count']} (worst {r['worst_ms']} ms): {r['at'][:12]}")
    print(f"load average {os.getloadavg()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
