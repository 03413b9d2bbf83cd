"""A fleet on one radio (issue 28, ``--shared-link``): 1, 2 and 4 vehicles of the sine on one sik-57600 radio
against each on a radio of its own, at the largest control rate that fits.

"Fits": the offered load of N vehicles, each sending a 242-byte ODOMETRY down and a command up every control
step, at most the radio's rate each way (the profile's ``rate_bps``, bytes/s). The missions take rates of
50-1000 Hz; when even 50 Hz does not fit (sik-57600: 3600 B/s each way carry 14.9 ODOMETRY a second), the
fleet flies at 50 Hz and the table says by how much the load overflows the radio. Each row:
``bsst sim missions/sine.toml --vehicles N --formation line:2 --link-profile sik-57600 --rate R [--shared-link]``
(through ``bridge.swarm.simulate``), per vehicle its outcome and 3-D RMS (m, t >= 10 s; ``n/a`` when it did not
complete, with the time it ended), and the down radio's occupancy, queue wait (p50, ms) and queue drops.
``--compensation predict`` adds the same rows with the controller's prediction (docs/links.md). ``--realtime``
flies each row as SITL on the wall clock instead (``bsst sitl ... --realtime``, through ``bridge.swarm.sitl`` on
free ports: a vehicle, a controller and a relay per vehicle, every relay on the one radio when shared), each row
taking up to the mission's 30 s; with the load average, since a real-time flight is what the machine gives it.
``--lockstep`` flies each row as SITL in lockstep (``bsst sitl ...``, vehicles and controllers taking turns on the
one radio: bridge.link.turns) and says whether it is the offline row bit for bit (every vehicle's trace, the
radio block) and its wall time.

    .venv/bin/python benchmarks/swarm_radio.py [--vehicles 1,2,4] [--predict] [--realtime | --lockstep] [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from bridge.core.flight import prepare  # noqa: E402
from bridge.link.ends import command_frame_bytes  # noqa: E402
from bridge.link.model import FRAME_BYTES, link_from_table  # noqa: E402
from bridge.swarm import simulate, sitl  # noqa: E402
from missions import load_mission  # noqa: E402
from missions.mission import MISSION_RANGES  # noqa: E402

PROFILE = "sik-57600"
MISSION = "missions/sine.toml"


def fitting_rate(n: int, up_bps: float, down_bps: float, command_bytes: int) -> float:
    """The largest control rate (Hz) at which n vehicles' states and commands fit the radio each way."""
    return min(down_bps / (n * FRAME_BYTES["ODOMETRY"]), up_bps / (n * command_bytes))


def ended_s(summary: dict[str, Any], trace_end_s: float) -> float:
    """When a vehicle's flight ended as its outcome says (s): a failsafe's first failsafe event (its trace goes on to
    the mission's end, the failsafe's descent flown: the trace's end said "failsafe at 30.00 s" of one at 0.52 s),
    else the trace's end (a divergence, a crash: the plant ended it there)."""
    if summary["outcome"] == "failsafe":
        times = [e["t"] for e in summary.get("events", []) if e.get("kind") == "failsafe"]
        if times:
            return float(times[0])
    return trace_end_s


def row(n: int, shared: bool, rate: float, predict: bool, clock: str = "offline") -> dict[str, Any]:
    link: dict[str, Any] = {"profile": PROFILE, "shared": shared}
    if predict:
        link["compensation"] = "predict"
    kw = {"vehicles": n, "formation": "line:2", "rate_hz": rate, "link": link, "plots": False}
    t0 = time.perf_counter()
    if clock == "offline":
        run = simulate(MISSION, **kw)
    else:
        run = sitl(MISSION, realtime=clock == "realtime", instance=None, **kw)
    wall = time.perf_counter() - t0
    same = None
    if clock == "lockstep":  # the offline fleet, bit for bit?
        off = simulate(MISSION, **kw)
        same = all(np.array_equal(a.trace[c], b.trace[c], equal_nan=True) for a, b in zip(off.runs, run.runs)
                   for c in ("t", "x", "y", "z", "u1_act", "u2_act"))
        same = same and off.summary.get("radio", {}).get("down") == run.summary.get("radio", {}).get("down")
    s = run.summary
    vehicles = [{"id": v["id"], "outcome": v["outcome"], "rms_3d": v["rms_3d"],
                 "ended_s": ended_s(r.summary, len(r.trace["t"]) / rate),
                 "lost": {d: v["link"][d]["lost_by"] for d in ("up", "down")}}
                for v, r in zip(s["vehicles"], run.runs)]
    out: dict[str, Any] = {"vehicles_n": n, "radio": "one shared" if shared else "one each", "rate_hz": rate,
                           "predict": predict, "vehicles": vehicles, "wall_s": wall, "clock": s["clock"],
                           "same_as_offline": same}
    if shared:
        down = s["radio"]["down"]
        out["down"] = {"occupancy": down["occupancy"], "share_bps_sum": down["share_bps"],
                       "rate_bps": down["rate_bps"], "lost_queue": down["lost_queue"],
                       "wait_p50_ms": [v["queue_wait_ms"]["p50"] for v in down["vehicles"]]}
    return out


def figures(counts: list[int], predict: bool, clock: str = "offline") -> dict[str, Any]:
    os.chdir(ROOT)
    settings = link_from_table({"profile": PROFILE}, "benchmark")
    command = command_frame_bytes(prepare(load_mission(MISSION)).profile.actuation)  # in the mission's actuation
    lo = MISSION_RANGES["rate_hz"][0]
    rows = []
    for n in counts:
        fit = fitting_rate(n, settings.up.rate_bps, settings.down.rate_bps, command)
        rate = max(lo, min(float(int(fit)), MISSION_RANGES["rate_hz"][1]))
        offered = n * rate * FRAME_BYTES["ODOMETRY"] / settings.down.rate_bps
        for shared in (False, True):
            for p in ((False, True) if predict else (False,)):
                r = row(n, shared, rate, p, clock)
                r.update(fits_hz=fit, offered_down=offered)
                rows.append(r)
    return {"profile": PROFILE, "up_bps": settings.up.rate_bps,
            "down_bps": settings.down.rate_bps, "command_bytes": command, "rows": rows, "loadavg": os.getloadavg()}


def show(v: dict[str, Any]) -> str:
    if v["rms_3d"] is not None and v["outcome"] == "completed":
        return f"{v['rms_3d']:.3g}"
    rms = "n/a" if v["rms_3d"] is None else f"{v['rms_3d']:.3g}"
    if v["ended_s"] == 0.0:  # (real time: the trace starts at the first state answered)
        return f"{rms} ({v['outcome']}, no state answered)"
    return f"{rms} ({v['outcome']} at {v['ended_s']:.2f} s)"


def print_table(f: dict[str, Any]) -> None:
    clock = f["rows"][0]["clock"] if f["rows"] else "offline"
    print(f"{f['profile']}: {f['down_bps']:g} B/s down (242-byte ODOMETRY), {f['up_bps']:g} B/s up "
          f"({f['command_bytes']}-byte command); sine, line:2 formation; clock {clock}")
    lockstep = any(r["same_as_offline"] is not None for r in f["rows"])  # (the column its rows add: a header for it)
    print("| vehicles | radio | law | rate (fits) | load down / radio | 3-D RMS per vehicle, m | down radio: occupancy,"
          " queue wait p50, queue drops |" + (" against offline, wall |" if lockstep else ""))
    print("|---|---|---|---|---|---|---|" + ("---|" if lockstep else ""))
    for r in f["rows"]:
        law = "BS-ST, predict" if r["predict"] else "BS-ST"
        rms = "; ".join(show(v) for v in r["vehicles"])
        if "down" in r:
            d = r["down"]
            waits = ", ".join("n/a" if w is None else f"{w:.0f}" for w in d["wait_p50_ms"])
            radio = f"{d['occupancy']:.2f}, {waits} ms, {d['lost_queue']}"
        else:
            drops = sum(v["lost"]["down"]["queue"] for v in r["vehicles"])
            radio = f"(each its own) queue drops {drops}"
        same = "" if r["same_as_offline"] is None else (
            f" {'offline, bit for bit' if r['same_as_offline'] else 'NOT the offline row'}, {r['wall_s']:.1f} s |")
        print(f"| {r['vehicles_n']} | {r['radio']} | {law} | {r['rate_hz']:g} Hz ({r['fits_hz']:.1f} Hz) | "
              f"{r['offered_down']:.1f}x | {rms} | {radio} |{same}")
    print("load average: " + " ".join(f"{x:.2f}" for x in f["loadavg"]))


def main_() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--vehicles", default="1,2,4", help="fleet sizes, comma-separated (default 1,2,4)")
    ap.add_argument("--predict", action="store_true", help="also fly each row with --compensation predict")
    clock = ap.add_mutually_exclusive_group()
    clock.add_argument("--realtime", action="store_true", help="fly each row as SITL on the wall clock (bsst sitl)")
    clock.add_argument("--lockstep", action="store_true", help="fly each row as SITL in lockstep, against offline")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    f = figures([int(x) for x in a.vehicles.split(",")], a.predict,
                "realtime" if a.realtime else "lockstep" if a.lockstep else "offline")
    if a.json:
        print(json.dumps(f, indent=2))
    else:
        print_table(f)
    return 0


if __name__ == "__main__":
    sys.exit(main_())
