"""Link files at size: the memory a large trace takes to read, and the time ``bsst link extract`` takes
over many repeated frames (issue 22, defect 7).

``trace``: a trace of ``--rows`` records (default 10^6; ``t_s,delay_ms,direction``, one in 20 lost) written
to a temporary file, then read by :func:`bridge.link.trace.read_trace` in a fresh process; printed: the
file's size, the process's peak resident memory (``ru_maxrss``) minus that of the same process importing
the module without reading, and the read time. Run it with ``PYTHONPATH`` on another checkout to compare.

``extract``: a vehicle tlog and a controller tlog of ``--frames`` HEARTBEATs each way (default 320 000),
every frame of a direction the same bytes but for its sequence number, so each frame's bytes recur every
256 frames (the worst case for matching a received frame to its sent one by bytes); printed: the time
:func:`bridge.record.linkextract.extract_tlogs` takes, and the records it gives.

    .venv/bin/python benchmarks/linkfiles.py trace [--rows 1000000]
    .venv/bin/python benchmarks/linkfiles.py extract [--frames 320000]
"""

from __future__ import annotations

import argparse
import os
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

_PEAK = """
import resource, sys, time
sys.path.remove("")  # -c puts the working directory first: the checkout PYTHONPATH names is the one measured
from bridge.link.trace import read_trace
t0 = time.perf_counter()
if sys.argv[1] != "-":
    tf = read_trace(sys.argv[1])
print(time.perf_counter() - t0, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
"""


def _peak(path: str) -> tuple[float, int]:
    """(read time s, peak RSS kB) of a fresh process reading ``path`` ("-": importing only)."""
    out = subprocess.run([sys.executable, "-c", _PEAK, path], capture_output=True, text=True, check=True,
                         env={**os.environ, "PYTHONPATH": os.environ.get("PYTHONPATH", str(ROOT))})
    t, kb = out.stdout.split()
    return float(t), int(kb)


def bench_trace(rows: int) -> int:
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "big.csv"
        with path.open("w") as f:
            f.write("t_s,delay_ms,direction\n")
            for k in range(rows):
                d = "" if k % 20 == 7 else f"{20.0 + (k % 13) * 0.25:.3f}"
                f.write(f"{k * 0.004:.6f},{d},{'up' if k % 2 else 'down'}\n")
        size = path.stat().st_size
        _, base = _peak("-")
        secs, peak = _peak(str(path))
    print(f"trace: {rows} rows, {size / 1e6:.1f} MB; read in {secs:.2f} s; peak RSS {peak / 1024:.0f} MB, "
          f"{(peak - base) / 1024:.0f} MB above the import alone ({(peak - base) * 1024 / rows:.0f} B per row)")
    return 0


def _tlogs(frames: int) -> tuple[bytes, bytes]:
    from pymavlink.dialects.v20 import common as mavlink

    veh = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    ctl = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
    vlog, clog = [], []
    for k in range(frames):
        t = 1000.0 + k * 0.004
        for mav, mine, theirs, delay in ((veh, vlog, clog, 0.010), (ctl, clog, vlog, 0.020)):
            raw = bytes(mav.heartbeat_encode(6, 8, 0, 0, 4).pack(mav))
            mav.seq = (mav.seq + 1) % 256
            mine.append((t, raw))
            if k % 10 != 3:
                theirs.append((t + delay, raw))

    def tlog(records: list[tuple[float, bytes]]) -> bytes:
        return b"".join(struct.pack(">Q", int(round(t * 1e6))) + b for t, b in sorted(records, key=lambda r: r[0]))

    return tlog(vlog), tlog(clog)


def bench_extract(frames: int) -> int:
    from bridge.record.linkextract import extract_tlogs
    from bridge.record.tlogmatch import parse_tlog

    v, c = _tlogs(frames)
    fv, fc = parse_tlog(v, "vehicle.tlog"), parse_tlog(c, "controller.tlog")
    t0 = time.perf_counter()
    ex = extract_tlogs(fv, fc, "same")
    secs = time.perf_counter() - t0
    print(f"extract: {frames} frames each way ({len(fv)} + {len(fc)} in the tlogs) in {secs:.2f} s; "
          f"up {ex.up.sent} records {ex.up.lost} lost, down {ex.down.sent} records {ex.down.lost} lost")
    return 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("what", choices=("trace", "extract"))
    ap.add_argument("--rows", type=int, default=1_000_000, help="trace: records in the trace")
    ap.add_argument("--frames", type=int, default=320_000, help="extract: frames each way")
    a = ap.parse_args()
    return bench_trace(a.rows) if a.what == "trace" else bench_extract(a.frames)


if __name__ == "__main__":
    sys.exit(main())
