"""Crash safety loop (issue 7): SIGKILL of the vehicle, the controller, the launcher, or all
three at once, at a random moment of a lockstep ``bsst sitl`` session, ``--runs`` times.

After each kill, once every process is gone, the run directory is checked
(:func:`tests.hostile.check_run_dir`): ``trace.csv`` and both halves (``vehicle.bin``, ``controller.bin``)
read to their last complete row, both tlogs open with pymavlink's ``mavlogdump.py``, ``summary.json`` is
complete or absent. Prints one line per run and a tally; exit status 1 if any check failed.

    .venv/bin/python benchmarks/crash.py [--runs 20] [--seed 0] [--key FILE]
"""

from __future__ import annotations

import argparse
import random
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from tests.hostile import CRASH_STEPS, kill_session  # noqa: E402

VICTIMS = ("vehicle", "controller", "launcher", "all")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=20)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--key", help="fly signed (--key FILE of bsst sitl)")
    args = ap.parse_args()
    rng = random.Random(args.seed)
    tally: Counter[str] = Counter()
    failures = 0
    t0 = time.monotonic()
    for i in range(args.runs):
        victim = VICTIMS[i % len(VICTIMS)]
        at = rng.randint(1, CRASH_STEPS - 300)
        with tempfile.TemporaryDirectory(prefix="bsst-crash-") as tmp:
            try:
                rc, found = kill_session(Path(tmp), victim, at, args.key)
                ok = "ok"
            except AssertionError as exc:
                rc, found, ok = None, {}, f"FAILED: {' '.join(str(exc).split())[:300]}"
                failures += 1
        tally[f"{victim}: {'ok' if ok == 'ok' else 'failed'}"] += 1
        print(f"run {i + 1:2d}: SIGKILL {victim:10s} at step {at:4d}: exit {rc}, summary {found.get('summary')}, "
              f"trace rows {found.get('trace.csv')}, vehicle.bin {found.get('vehicle.bin')}, "
              f"controller.bin {found.get('controller.bin')}, mavlogdump vehicle.tlog {found.get('vehicle.tlog')} / "
              f"controller.tlog {found.get('controller.tlog')} lines: {ok}", flush=True)
    counts = ", ".join(f"{k} {v}" for k, v in sorted(tally.items()))
    print(f"{args.runs} runs in {time.monotonic() - t0:.0f} s: {counts}; {failures} failed")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
