"""Where the test suite's CPU goes, process by process: every Python process the suite starts logs its own CPU
time (user + system, s) as it exits, and the census sums them by kind (docs/testing.md, "Where the rest of a
run's CPU goes").

In:  pytest's arguments after ``--`` (default: the suite as ``make test`` runs it, ``-n 6``); ``--report LOG`` to
     sum a census already taken; ``--keep LOG`` where the census is written (JSON lines)
Out: the wall time and the load average before and after; per kind of process (a pytest worker, a forked
     ``bsst vehicle``, ``controller``, ``sim``, ..., a ``python -c`` ground-station script, the fork servers,
     MAVProxy), how many ran, their CPU-s and the mean per process; the total logged. Processes that are not
     Python's (mavsdk_server) are not in it: the machine's CPU less the total is their share and the kernel's.

    .venv/bin/python benchmarks/suite_census.py                 # the whole suite, ~6 min on two cores
    .venv/bin/python benchmarks/suite_census.py -- -n 2 tests/test_relay.py
    .venv/bin/python benchmarks/suite_census.py --report /tmp/census.jsonl

How: a ``sitecustomize`` module on PYTHONPATH, imported by every Python process at its start, registers an exit
handler and wraps ``os._exit`` (which the fork server's children, multiprocessing's workers and pytest-xdist's
workers end with: an exit handler does not run there). A forked child inherits the wrapper, and its
``getrusage(RUSAGE_SELF)`` counts its own time only, so nothing is counted twice.
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

SITECUSTOMIZE = '''
import atexit, json, os, resource, sys, time
_LOG = os.environ["BSST_CENSUS_LOG"]
_exit = os._exit


def _log(how):
    try:
        r = resource.getrusage(resource.RUSAGE_SELF)
        line = json.dumps({"pid": os.getpid(), "cpu_s": r.ru_utime + r.ru_stime, "how": how,
                           "argv": sys.argv[:8], "t": time.time()}) + "\\n"
        fd = os.open(_LOG, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
        try:
            os.write(fd, line.encode())  # one write, O_APPEND: lines of processes ending together do not mix
        finally:
            os.close(fd)
    except Exception:  # a census must never change how a process ends
        pass


def _logged_exit(code):
    _log("_exit")
    _exit(code)


os._exit = _logged_exit
atexit.register(_log, "exit")
'''


def kind(row: dict) -> str:
    """What a logged process was, from its command line as it ended."""
    argv = row["argv"]
    head = argv[0] if argv else ""
    if head == "-c":  # execnet starts pytest-xdist's workers as `python -c`; they end with os._exit
        return "pytest worker" if row["how"] == "_exit" else "python -c script (a ground station)"
    if head.endswith(os.path.join("bridge", "__main__.py")):
        return f"bsst {argv[1] if len(argv) > 1 else ''} (forked)"
    if Path(head).name == "bsst":
        return f"bsst {argv[1] if len(argv) > 1 else ''} (started)"
    if "forkserver" in " ".join(argv):
        return "fork server"
    if "pytest" in head:
        return "pytest (the suite's main process)"
    return Path(head).name or "(no argv)"


def report(log: Path) -> None:
    rows = [json.loads(line) for line in log.read_text().splitlines() if line.strip()]
    by: dict[str, list[float]] = collections.defaultdict(list)
    for row in rows:
        by[kind(row)].append(row["cpu_s"])
    total = sum(sum(v) for v in by.values())
    print(f"{len(rows)} processes, {total:.1f} CPU-s logged")
    print(f"{'CPU-s':>8} {'share':>6} {'count':>6} {'per process':>12}  kind")
    for name, cpu in sorted(by.items(), key=lambda kv: -sum(kv[1])):
        print(f"{sum(cpu):8.1f} {sum(cpu) / total:6.1%} {len(cpu):6d} {sum(cpu) / len(cpu):12.3f}  {name}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--report", type=Path, help="sum a census already taken (JSON lines), run nothing")
    ap.add_argument("--keep", type=Path, help="write the census here (default: a temporary file)")
    ap.add_argument("pytest_args", nargs="*", help="pytest's arguments (after --)")
    args = ap.parse_args(argv)
    if args.report is not None:
        report(args.report)
        return 0
    with tempfile.TemporaryDirectory(prefix="bsst-census-") as tmp:
        (Path(tmp) / "sitecustomize.py").write_text(SITECUSTOMIZE)
        log = args.keep or Path(tmp) / "census.jsonl"
        log.unlink(missing_ok=True)
        env = {**os.environ, "BSST_CENSUS_LOG": str(log.resolve()),
               "PYTHONPATH": os.pathsep.join([tmp, str(ROOT), os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep)}
        pytest_args = args.pytest_args or ["-n", "6", "-q", "-p", "no:cacheprovider"]
        print(f"load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
        t0 = time.monotonic()
        rc = subprocess.call([sys.executable, "-m", "pytest", *pytest_args], cwd=ROOT, env=env)
        print(f"pytest exit {rc}, {time.monotonic() - t0:.1f} s wall; load average after: "
              f"{' '.join(f'{x:.2f}' for x in os.getloadavg())}")
        report(log)
    return 0


if __name__ == "__main__":
    sys.exit(main())
