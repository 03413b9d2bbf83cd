"""The per-step records of a SITL session: what writing and reading each row costs, as text and as binary.

Flies one lockstep sine (``bsst sitl missions/sine.toml``, through ``bridge.session.sitl``, into a temporary
directory), then, on its own ``vehicle.bin`` rows (45 columns), the best of ``--repeats`` passes of:

- a vehicle row written as CSV text (``repr`` of each value, joined: how the halves were written before) and as a
  binary record (``struct.pack``: how :class:`bridge.record.halves.HalfWriter` writes it), in µs a row;
- that row read back from text (``float`` per field) and from the records (:class:`bridge.record.halves.HalfReader`,
  named rows), in µs a row;
- the launcher's join of both halves (:class:`bridge.record.joiner.TraceJoiner`, no writing), and ``trace.csv``'s
  own row (45 floats as ``repr``, :class:`bridge.record.runlog.TraceWriter`), in µs a row;

with the load average, since other work on the machine slows every figure alike.

    .venv/bin/python benchmarks/records.py [--repeats 3]
"""

from __future__ import annotations

import argparse
import os
import struct
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bridge.core.flight import prepare  # noqa: E402
from bridge.record.columns import VEHICLE_COLUMNS, VehicleRow  # noqa: E402
from bridge.record.halves import HalfReader, read_half  # noqa: E402
from bridge.record.joiner import TraceJoiner  # noqa: E402
from bridge.record.runlog import TraceWriter  # noqa: E402
from bridge.session import sitl  # noqa: E402


def per_row(work: Callable[[], object], rows: int, repeats: int) -> float:
    """The best of ``repeats`` passes of ``work`` over ``rows`` rows, in µs a row."""
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        work()
        best = min(best, time.perf_counter() - t0)
    return 1e6 * best / rows


def measure(run: Path, repeats: int) -> dict[str, float]:
    half = read_half(run / "vehicle.bin")
    rows = [tuple(float(half[c][i]) for c in VEHICLE_COLUMNS) for i in range(len(half["k"]))]
    n = len(rows)
    pack = struct.Struct(f"<{len(VEHICLE_COLUMNS)}d").pack
    lines = [",".join(map(repr, r)).encode() for r in rows]
    flight = prepare(run / "mission.toml")

    def join() -> TraceJoiner:
        j = TraceJoiner(run, flight, None, lockstep=True)
        j.update()
        j.controller_done = True
        j.update()
        return j

    joined = join().rows

    def write_trace() -> None:
        out = TraceWriter(run / "rewritten.csv")
        for r in joined:
            out.row(r)
        out.close()

    return {
        "rows": n,
        "write_text_us": per_row(lambda: [",".join(map(repr, r)) for r in rows], n, repeats),
        "write_record_us": per_row(lambda: [pack(*r) for r in rows], n, repeats),
        "read_text_us": per_row(lambda: [[float(x) for x in line.split(b",")] for line in lines], n, repeats),
        "read_records_us": per_row(lambda: HalfReader(run / "vehicle.bin", VehicleRow).read(), n, repeats),
        "join_us": per_row(join, n, repeats),
        "trace_row_us": per_row(write_trace, n, repeats),
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    load = os.getloadavg()
    with tempfile.TemporaryDirectory() as tmp:
        run = sitl(ROOT / "missions" / "sine.toml", out=Path(tmp) / "run", instance=None, plots=False)
        if run.outcome != "completed":
            print(f"the lockstep sine ended {run.outcome}", file=sys.stderr)
            return 1
        f = measure(Path(tmp) / "run", args.repeats)
    print(f"{f['rows']} vehicle rows of {len(VEHICLE_COLUMNS)} columns (a lockstep sine), best of {args.repeats}, "
          f"load {load[0]:.2f}")
    print(f"  the vehicle writes a row: text {f['write_text_us']:.1f} us, record {f['write_record_us']:.2f} us "
          f"({f['write_text_us'] / f['write_record_us']:.0f}x)")
    print(f"  the launcher reads it:    text {f['read_text_us']:.1f} us, record {f['read_records_us']:.2f} us "
          f"({f['read_text_us'] / f['read_records_us']:.1f}x)")
    print(f"  the join of both halves: {f['join_us']:.1f} us a row; trace.csv's row: {f['trace_row_us']:.1f} us")
    return 0


if __name__ == "__main__":
    sys.exit(main())
