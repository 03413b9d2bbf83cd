"""``bsst link fit`` at size: the time to parse a trace and to fit the model to it, per row.

A two-way 250 Hz trace of ``--rows`` records (default 10^5 and 10^6; ``t_s,delay_ms,direction``, times and
delays written as ``repr`` floats, as ``bsst link extract`` writes them: delays 30 ms, sigma 5 normal, lost in
Gilbert-Elliott bursts of mean 4 at 10 %, one 2 s outage each way; numpy seed 0, so the same file every run) is
written to a temporary file, then in this process :func:`bridge.link.trace.read_trace` (the parse) and
:func:`bridge.link.fit.fit_trace` with :func:`bridge.link.fit.fit_toml` (the fit) are timed, the least of
``--repeat`` runs each by CPU time (the process's; wall beside it). Printed per size: µs per row of
each, and a digest of the fitted profile (the same digest on two checkouts: the same profile, byte for byte).
The load average is printed before and after. Run it with ``PYTHONPATH`` on another checkout to compare.

    .venv/bin/python benchmarks/linkfit.py [--rows 100000 1000000] [--repeat 3]
"""

from __future__ import annotations

import argparse
import hashlib
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
# this checkout, or the one PYTHONPATH names; never benchmarks/ itself (its missions.py is not the package)
sys.path[0] = os.environ.get("PYTHONPATH", "").split(os.pathsep)[0] or str(ROOT)

RATE_HZ = 250.0


def trace_bytes(rows: int) -> bytes:
    """The benchmark's trace: ``rows`` records, up and down alternating, each direction at 250 Hz."""
    from bridge.link.trace import trace_text

    rng = np.random.default_rng(0)
    per = (rows + 1) // 2
    out = []
    for d in ("up", "down"):
        n = per if d == "up" else rows - per
        delay = np.maximum(30.0 + 5.0 * rng.standard_normal(n), 0.0)
        bad, lost = False, np.zeros(n, dtype=bool)
        u = rng.random(n)
        for k in range(n):  # Gilbert-Elliott: p = L r / (1 - L), r = 1 / burst
            bad = u[k] >= 0.25 if bad else u[k] < 0.25 * 0.1 / 0.9
            lost[k] = bad
        t = np.arange(n) / RATE_HZ
        lost[(t >= 10.0) & (t < 12.0)] = True
        out.append([(float(t[k]), None if lost[k] else float(delay[k]), d) for k in range(n)])
    rows_ = [r for pair in zip(*out, strict=False) for r in pair] + out[0][len(out[1]):]
    return trace_text(rows_, ["benchmarks/linkfit.py: generated, not measured"]).encode()


def least(f, repeat: int) -> tuple[float, float, object]:
    """(least CPU s, least wall s, the result) of ``repeat`` calls of ``f``: on a shared machine the CPU
    time is the figure, the wall time moves with the load."""
    cpu, wall, out = float("inf"), float("inf"), None
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        out = f()
        cpu, wall = min(cpu, time.process_time() - c0), min(wall, time.perf_counter() - t0)
    return cpu, wall, out


def bench(rows: int, repeat: int) -> None:
    from bridge.link.fit import fit_toml, fit_trace
    from bridge.link.trace import read_trace

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "big.csv"
        path.write_bytes(trace_bytes(rows))
        size = path.stat().st_size
        parse_s, parse_w, tf = least(lambda: read_trace(path), repeat)
        fit_s, fit_w, text = least(lambda: fit_toml(fit_trace(tf), "big.csv"), repeat)
    digest = hashlib.sha256(str(text).encode()).hexdigest()[:16]
    print(f"{rows} rows ({size / 1e6:.1f} MB): parse {parse_s * 1e6 / rows:.2f} µs/row CPU ({parse_s:.3f} s; "
          f"wall {parse_w:.3f} s), fit {fit_s * 1e6 / rows:.2f} µs/row CPU ({fit_s:.3f} s; wall {fit_w:.3f} s); "
          f"profile sha256 {digest}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rows", type=int, nargs="+", default=[100_000, 1_000_000])
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args()
    import bridge

    print(f"bridge from {Path(bridge.__file__).parent.parent}")
    print(f"load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    for rows in a.rows:
        bench(rows, a.repeat)
    print(f"load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
