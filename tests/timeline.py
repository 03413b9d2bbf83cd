"""Where the suite's wall time goes, worker by worker: a pytest plug-in and its report (docs/testing.md).

In:  (plug-in) each test's start and end as pytest-xdist's workers run it, wall clock s; ``BSST_TIMELINE_DIR``,
     the directory to write to; (report) that directory
Out: (plug-in) one file per worker, ``<worker>.txt``, a line per test start (``S <t> <test id>``) and end
     (``E <t> <test id>``); (report) each worker's span and busy time, whether they ended together (a tail
     that ordering could cut), the worker-seconds by file and the slowest tests

    BSST_TIMELINE_DIR=/tmp/tl .venv/bin/python -m pytest -p tests.timeline   # make test's suite, timed
    .venv/bin/python -m tests.timeline /tmp/tl
"""

from __future__ import annotations

import os
import sys
import time
from collections import Counter
from pathlib import Path
from typing import TextIO

import pytest

_out: TextIO | None = None


def _log(kind: str, nodeid: str) -> None:
    global _out
    where = os.environ.get("BSST_TIMELINE_DIR")
    if where is None:
        return
    if _out is None:
        Path(where).mkdir(parents=True, exist_ok=True)
        _out = open(Path(where) / f"{os.environ.get('PYTEST_XDIST_WORKER', 'main')}.txt", "a")  # noqa: SIM115
    _out.write(f"{kind} {time.time():.3f} {nodeid}\n")
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
    spans, per_file, tests = [], Counter(), []
    for f in sorted(where.glob("*.txt")):
        started: dict[str, float] = {}
        first = last = busy = None
        for line in f.read_text().splitlines():
            kind, t_text, nodeid = line.split(" ", 2)
            t = float(t_text)
            if kind == "S":
                started[nodeid] = t
                first = t if first is None else first
            elif nodeid in started:
                d = t - started.pop(nodeid)
                busy = (busy or 0.0) + d
                last = t
                per_file[nodeid.split("::")[0]] += d
                tests.append((d, nodeid))
        if first is not None and last is not None:
            spans.append((f.stem, first, last, busy or 0.0))
    if not spans:
        return f"no timeline in {where}"
    t0 = min(s[1] for s in spans)
    out = [f"{name}: first test at +{a - t0:.1f} s, last ended at +{b - t0:.1f} s, busy {busy:.1f} s"
           for name, a, b, busy in spans]
    ends = [s[2] for s in spans]
    out.append(f"workers ended within {max(ends) - min(ends):.1f} s of each other; "
               f"{sum(per_file.values()):.1f} worker-seconds in all")
    out += ["worker-seconds by file:"] + [f"  {d:7.1f} {name}" for name, d in per_file.most_common(15)]
    out += ["slowest tests (setup included):"] + [f"  {d:6.1f} {n}" for d, n in sorted(tests, reverse=True)[:slowest]]
    return "\n".join(out)


if __name__ == "__main__":
    if len(sys.argv) != 2:
        print("usage: python -m tests.timeline DIR (written by pytest -p tests.timeline, BSST_TIMELINE_DIR=DIR)",
              file=sys.stderr)
        sys.exit(2)
    print(report(Path(sys.argv[1])))
