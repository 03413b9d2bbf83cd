"""Benchmark: issue 26's MAVSDK acceptance at its full size, too long for the suite (which does 30 items).

In:  ``--items`` (100), ``--loss`` % and ``--delay`` ms each way (20, 100), ``--seed`` (the relay's), ``--runs``
Out: printed per run: MAVSDK MissionRaw's upload attempts and the last one's wall time (s), its download
     attempts, whether the download is the upload item by item, the vehicle's ``mission`` events (each an
     upload it accepted), the totals its MISSION_CURRENTs named (never a mission shorter than acknowledged),
     the relay's losses; and the load average

The run is tests/test_mission_protocol.py's (:func:`mavsdk_through_relay`: ``bsst vehicle``, ``bsst relay``,
MAVSDK in its own process), so the suite's test and this figure are one code path.

    python benchmarks/missions_mavsdk.py [--items 100] [--loss 20] [--delay 100] [--runs 1]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
os.environ["MAVLINK20"] = "1"

from tests.test_mission_protocol import mavsdk_through_relay  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--items", type=int, default=100)
    ap.add_argument("--loss", type=int, default=20)
    ap.add_argument("--delay", type=int, default=100)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--runs", type=int, default=1)
    args = ap.parse_args()
    ok = True
    for k in range(args.runs):
        with tempfile.TemporaryDirectory(prefix="bsst-mm-") as tmp:
            out, events, relay, totals = mavsdk_through_relay(Path(tmp), args.items, args.loss, args.delay,
                                                              args.seed + k)
        same = out.get("downloaded") == out.get("uploaded")
        ok &= same and out["upload_attempts"][-1] == "SUCCESS"
        print(f"run {k + 1}: {args.items} items, loss {args.loss} %, delay {args.delay} ms each way: upload "
              f"{out['upload_attempts']} (last {out['upload_s']:.1f} s), download {out['download_attempts']}, "
              f"downloaded = uploaded: {same}; vehicle accepted {len(events)} upload(s); MISSION_CURRENT totals "
              f"{sorted(totals)}; relay lost up {relay['up']['lost']} down {relay['down']['lost']}", flush=True)
    print(f"load average {os.getloadavg()[0]:.1f} {os.getloadavg()[1]:.1f} {os.getloadavg()[2]:.1f}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
