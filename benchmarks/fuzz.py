"""Fuzz (issue 7): ``--datagrams`` (10^6) hostile datagrams into the vehicle's controller link
during a lockstep mission, against an undisturbed run of the same mission and seed.

The datagrams (:class:`tests.hostile.Fuzzer`, seeded): random bytes, truncated and bit-flipped
valid frames, valid targets from other systems, commands for other systems, unknown message
ids, NaN/inf and out-of-range targets with the controller's ids, stale and future targets,
MAVLink 1 frames, empty and 64 KiB datagrams; sent from ``--sources`` addresses, paced on the
vehicle's socket queue so the kernel drops nothing. Prints what was sent by kind, what the
vehicle refused by reason, whether the refusals add up to what was sent, whether the trace is
the undisturbed one byte for byte, the burst's rate and the vehicle's CPU time per datagram.

    .venv/bin/python benchmarks/fuzz.py [--datagrams 1000000] [--rate 40000] [--duration 120] [--speed 2] [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from bridge.session import sitl  # noqa: E402
from missions import Mission, Sine  # noqa: E402
from tests.hostile import fly_fuzzed  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--datagrams", type=int, default=1_000_000)
    ap.add_argument("--duration", type=float, default=120.0, help="s of the sine mission flown")
    ap.add_argument("--speed", type=float, default=2.0, help="lockstep at most this many times real time")
    ap.add_argument("--sources", type=int, default=128)
    ap.add_argument("--rate", type=float, default=40000.0,
                    help="datagrams/s at most: under the vehicle's limits for others (bridge.mavlink.receive), so that "
                         "every datagram is parsed and its reason counted")
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    mission = Mission(Sine(), duration_s=args.duration, name="fuzz")
    with tempfile.TemporaryDirectory(prefix="bsst-fuzz-") as tmp:
        sitl(mission, out=Path(tmp) / "ref", plots=False, instance=None)  # the undisturbed run
        f = fly_fuzzed(mission, Path(tmp) / "fuzz", args.datagrams, seed=args.seed, sources=args.sources,
                       speed=args.speed, rate_hz=args.rate)
        same = (Path(tmp) / "fuzz" / "trace.csv").read_bytes() == (Path(tmp) / "ref" / "trace.csv").read_bytes()
    s = f.run.summary
    link = s["link"]
    by = link["rejected_by"]["vehicle"]
    others = sum(by.values()) - link["rejected_from_peer"]["vehicle"]
    short = {r: n - by.get(r, 0) for r, n in f.fuzz.expected().items() if by.get(r, 0) < n}
    res = {
        "load_1min": os.getloadavg()[0], "datagrams": f.sent, "sent_by_kind": dict(f.fuzz.sent),
        "refused_by_reason": dict(sorted(by.items(), key=lambda kv: -kv[1])), "refused_from_others": others,
        "adds_up": others == f.sent and f.drops == 0 and not short, "kernel_drops": f.drops,
        "trace_identical": same, "outcome": s["outcome"], "died": s["sitl"]["died"],
        "exits": [s["sitl"]["vehicle_exit"], s["sitl"]["controller_exit"]],
        "fuzz_done_before_mission_end": f.flown < mission.steps, "burst_s": f.elapsed_s,
        "datagrams_per_s": f.sent / f.elapsed_s, "vehicle_cpu_us_per_datagram": 1e6 * f.vehicle_cpu_s / f.sent,
        "statustexts": len([t for t in f.texts if t.startswith("rejected ")]), "controller_refused": link[
            "rejected_by"]["controller"],
    }
    if args.json:
        print(json.dumps(res, indent=2))
    else:
        print(f"{f.sent} hostile datagrams from {args.sources} sources in {f.elapsed_s:.1f} s "
              f"({res['datagrams_per_s']:.0f}/s) during a lockstep {args.duration:g} s sine; "
              f"load {res['load_1min']:.2f}")
        print("sent by kind: " + ", ".join(f"{k} {v}" for k, v in sorted(f.fuzz.sent.items(), key=lambda kv: -kv[1])))
        print("vehicle refused: " + ", ".join(f"{k} {v}" for k, v in res["refused_by_reason"].items()))
        print(f"refusals of others' datagrams {others} = sent {f.sent}: {others == f.sent}; kernel drops {f.drops}; "
              f"each kind's least count met: {not short}{'' if not short else ' ' + str(short)}")
        print(f"trace.csv identical to the undisturbed run: {same}; outcome {s['outcome']}; vehicle "
              f"{s['sitl']['vehicle_exit']}, controller {s['sitl']['controller_exit']}; controller refused "
              f"{res['controller_refused']}")
        print(f"vehicle CPU {res['vehicle_cpu_us_per_datagram']:.1f} us per datagram (its flight included); "
              f"{res['statustexts']} STATUSTEXT reports of refusals")
    ok = res["adds_up"] and same and s["outcome"] == "completed" and res["fuzz_done_before_mission_end"]
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
