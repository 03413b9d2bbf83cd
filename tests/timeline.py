"""Where the suite's wall time goes, worker by worker: a pytest plug-in and its report (docs/testing.md).

In:  (plug-in) each test's start and end as pytest-xdist's workers run it: the wall clock, s; the CPU time the
     worker and the processes it has reaped have used, s; the whole machine's CPU time so far (its root cgroup's
     count, or that of the cgroup v1 ``cpuacct`` folder ``BSST_TIMELINE_CGROUP`` names: the suite run inside it), s;
     ``BSST_TIMELINE_DIR``, the directory to write to; (report) that directory
Out: (plug-in) one file per worker, ``<worker>.txt``, a line per test start (``S <t> <cpu> <machine> <test id>``)
     and end (``E ...``); (report) each worker's span and busy time, whether they ended together (a tail that
     ordering could cut), the worker-seconds and CPU-seconds by file and the slowest and costliest tests.
     On a loaded machine wall time measures the load as much as the test; CPU time is the test's own cost, but
     the worker's count misses what it does not reap (a session's children forked by the fork server). Run with
     ``-n 0`` (one worker, nothing else running) and the machine's CPU time during each test is its whole cost:
     the report then ranks files and tests by that

    BSST_TIMELINE_DIR=/tmp/tl .venv/bin/python -m pytest -p tests.timeline   # make test's suite, timed
    BSST_TIMELINE_DIR=/tmp/tl1 .venv/bin/python -m pytest -n 0 -p tests.timeline   # each test's whole CPU cost
    .venv/bin/python -m tests.timeline /tmp/tl
"""

from __future__ import annotations

import os
import resource
import sys
import time
from collections import Counter
from pathlib import Path
from typing import TextIO

import pytest

_out: TextIO | None = None


def _machine_busy() -> float:
    """The CPU time the whole machine has run tasks, s: the root cgroup's scheduler count (cgroup v1's cpuacct or
    v2's cpu.stat; 0 where neither is). Not /proc/stat: its tick samples miss a process that runs in short bursts
    between ticks, as a lockstep vehicle does (a four-vehicle test read 1.1 CPU-s there, 6.4 here: docs/testing.md)."""
    try:
        return int(Path(os.environ.get("BSST_TIMELINE_CGROUP", "/sys/fs/cgroup/cpuacct"), "cpuacct.usage")
                   .read_text()) / 1e9
    except (OSError, ValueError):
        pass
    try:
        stat = dict(line.split() for line in Path("/sys/fs/cgroup/cpu.stat").read_text().splitlines())
        return int(stat["usage_usec"]) / 1e6
    except (OSError, ValueError, KeyError):
        return 0.0


def _log(kind: str, nodeid: str) -> None:
    global _out
    where = os.environ.get("BSST_TIMELINE_DIR")
    if where is None:
        return
    if _out is None:
        Path(where).mkdir(parents=True, exist_ok=True)
        _out = open(Path(where) / f"{os.environ.get('PYTEST_XDIST_WORKER', 'main')}.txt", "a")  # noqa: SIM115
    me, reaped = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = me.ru_utime + me.ru_stime + reaped.ru_utime + reaped.ru_stime
    _out.write(f"{kind} {time.time():.3f} {cpu:.3f} {_machine_busy():.2f} {nodeid}\n")
    _out.flush()


@pytest.hookimpl(wrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None) -> object:
    """Around each test where it runs (a worker; not pytest-xdist's controller, which hears of it after)."""
    _log("S", item.nodeid)
    try:
        return (yield)
    finally:
        _log("E", item.nodeid)


def report(where: Path, slowest: int = 20) -> str:
    """The timeline's figures (module docstring), as text."""
    spans, per_file, cpu_per_file, machine_per_file, tests = [], Counter(), Counter(), Counter(), []
    for f in sorted(where.glob("*.txt")):
        started: dict[str, tuple[float, float, float]] = {}  # test id: its start's wall, worker and machine s
        first = last = busy = None
        for line in f.read_text().splitlines():
            kind, t_text, cpu_text, machine_text, nodeid = line.split(" ", 4)
            t, cpu, machine = float(t_text), float(cpu_text), float(machine_text)
            if kind == "S":
                started[nodeid] = (t, cpu, machine)
                first = t if first is None else first
            elif nodeid in started:
                t0, cpu0, machine0 = started.pop(nodeid)
                d, file = t - t0, nodeid.split("::")[0]
                busy = (busy or 0.0) + d
                last = t
                per_file[file] += d
                cpu_per_file[file] += cpu - cpu0
                machine_per_file[file] += machine - machine0
                tests.append((d, cpu - cpu0, machine - machine0, nodeid))
        if first is not None and last is not None:
            spans.append((f.stem, first, last, busy or 0.0))
    if not spans:
        return f"no timeline in {where}"
    t0 = min(s[1] for s in spans)
    out = [f"{name}: first test at +{a - t0:.1f} s, last ended at +{b - t0:.1f} s, busy {busy:.1f} s"
           for name, a, b, busy in spans]
    ends = [s[2] for s in spans]
    out.append(f"workers ended within {max(ends) - min(ends):.1f} s of each other; "
               f"{sum(per_file.values()):.1f} worker-seconds in all, {sum(cpu_per_file.values()):.1f} CPU-seconds")
    out += ["worker-seconds by file:"] + [f"  {d:7.1f} {name}" for name, d in per_file.most_common(15)]
    out += ["CPU-seconds by file:"] + [f"  {c:7.1f} {name}" for name, c in cpu_per_file.most_common(15)]
    if len(spans) == 1:  # one worker (-n 0): the machine's busy time while a test ran is that test's whole cost
        out += ["machine CPU-seconds by file:"]
        out += [f"  {c:7.1f} {name}" for name, c in machine_per_file.most_common(40)]
    out += ["slowest tests (setup included; wall s, CPU s):"]
    out += [f"  {d:6.1f} {c:6.1f} {n}" for d, c, _, n in sorted(tests, reverse=True)[:slowest]]
    cost = 2 if len(spans) == 1 else 1  # the machine's CPU if one worker ran, else the worker's own
    out += ["costliest tests (CPU s, wall s):"]
    out += [f"  {t[cost]:6.1f} {t[0]:6.1f} {t[3]}" for t in sorted(tests, key=lambda t: -t[cost])[:slowest]]
    return "\n".join(out)


if __name__ == "__main__":
    if len(sys.argv) != 2:
        print("usage: python -m tests.timeline DIR (written by pytest -p tests.timeline, BSST_TIMELINE_DIR=DIR)",
              file=sys.stderr)
        sys.exit(2)
    print(report(Path(sys.argv[1])))
