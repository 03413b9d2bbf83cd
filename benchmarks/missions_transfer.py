"""A 100-item mission uploaded to ``bsst vehicle`` through ``bsst relay``, against loss and delay (issue 26).

For each cell of loss (0, 10, 20, 40 %, both directions) x one-way delay (0, 100, 600 ms, both directions):
a ``bsst relay`` between the vehicle's GCS link and a pymavlink ground station, which uploads 100 items
(MISSION_COUNT, each requested item, the final MISSION_ACK) as a plain ground station does: it answers
every request and, when nothing comes for ``max(1 s, 3 x round trip)``, sends its last message again (the
count, or the last item when the ACK is lost). Then the held mission is downloaded over the vehicle's
controller link (unimpaired: the controller may read the mission) and compared item by item, and the
vehicle's tlog is read for its MISSION_REQUEST_INTs and the totals of its MISSION_CURRENT.

Printed per cell: upload wall time (s), the vehicle's requests (100 at best) and how many were requests
again, the items and counts the ground station sent, the relay's losses, whether the held mission is the
uploaded one, and whether the vehicle ever held a mission other than none or all 100 items (MISSION_CURRENT
totals). A cell is bounded by ``--cell-timeout`` (s).

    .venv/bin/python benchmarks/missions_transfer.py [--items 100] [--cell-timeout 300] [--json]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

os.environ["MAVLINK20"] = "1"
from pymavlink import mavutil  # noqa: E402
from pymavlink.dialects.v20 import common as mavlink  # noqa: E402

from bridge.mavlink.endpoint import CONTROLLER_COMPID, CONTROLLER_SYSID, GCS_PORT, LINK_PORT  # noqa: E402
from bridge.nodes.report import Ready, parse_line  # noqa: E402
from bridge.session import instance_slot  # noqa: E402

LOSSES = (0, 10, 20, 40)
DELAYS = (0, 100, 600)
HOME = (473977420, 85455940)
ENV = {**os.environ, "PYTHONPATH": str(ROOT), "PYTHONUNBUFFERED": "1"}


def items(n: int) -> list[Any]:
    """``n`` MISSION_ITEM_INTs: a takeoff, waypoints on a grid, a landing (target set when sent)."""
    out = []
    for seq in range(n):
        cmd = (mavlink.MAV_CMD_NAV_TAKEOFF if seq == 0 else mavlink.MAV_CMD_NAV_LAND if seq == n - 1
               else mavlink.MAV_CMD_NAV_WAYPOINT)
        out.append(mavlink.MAVLink_mission_item_int_message(
            0, 0, seq, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, cmd, int(seq == 0), 1, 0.0, 1.0, 0.0, math.nan,
            HOME[0] + 900 * (seq % 10), HOME[1] + 1300 * (seq // 10), 5.0 + seq % 7, 0))
    return out


def fields(m: Any) -> tuple[Any, ...]:
    vals = (m.seq, m.frame, m.command, m.param1, m.param2, m.param3, m.param4, m.x, m.y, m.z, m.autocontinue)
    return tuple("nan" if isinstance(v, float) and math.isnan(v) else v for v in vals)


def start(argv: list[str], ready: str, log: Path, timeout: float = 20.0) -> tuple[subprocess.Popen, str]:
    """A ``bsst`` process (its output to ``log``, so that no pipe fills) and its first line containing ``ready``."""
    with log.open("w") as f:
        p = subprocess.Popen([sys.executable, "-m", "bridge", *argv], cwd=ROOT, env=ENV, stdout=f,
                             stderr=subprocess.STDOUT, text=True)
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        line = next((ln for ln in log.read_text().splitlines() if ready in ln), None)
        if line is not None:
            return p, line
        if p.poll() is not None:
            break
        time.sleep(0.05)
    p.kill()
    raise RuntimeError(f"bsst {argv[0]} did not start ({ready!r} never came):\n{log.read_text()[-2000:]}")


def stop(p: subprocess.Popen) -> None:
    p.terminate()
    try:
        p.wait(timeout=10)
    except subprocess.TimeoutExpired:
        p.kill()
        p.wait()


def upload(gcs: Any, mission: list[Any], target: tuple[int, int], patience_s: float,
           timeout_s: float) -> dict[str, Any]:
    """Upload ``mission`` as a plain ground station; its figures."""
    sent = {"items": 0, "counts": 1, "requests_seen": 0}
    last: Any = mavlink.MAVLink_mission_count_message(*target, len(mission), 0)
    gcs.mav.send(last)
    t0 = time.monotonic()
    heard = t0
    while True:
        now = time.monotonic()
        if now - t0 > timeout_s:
            return {**sent, "result": "timeout", "upload_s": now - t0}
        m = gcs.recv_match(type=["MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK"], blocking=True,
                           timeout=0.05)
        if m is None:
            if time.monotonic() - heard > patience_s:  # nothing for a while: say the last thing again
                gcs.mav.send(last)
                sent["counts" if last.get_type() == "MISSION_COUNT" else "items"] += 1
                heard = time.monotonic()
            continue
        heard = time.monotonic()
        if m.get_type() == "MISSION_ACK":
            result = mavlink.enums["MAV_MISSION_RESULT"][m.type].name
            return {**sent, "result": result, "upload_s": heard - t0}
        sent["requests_seen"] += 1
        last = mission[m.seq]
        last.target_system, last.target_component = target
        gcs.mav.send(last)
        sent["items"] += 1


def controller_end(n: int) -> Any:
    """The configured controller's end, bound to a port of its own (the vehicle is told it: --controller-from, as
    ``bsst sitl`` pins it; an unpinned vehicle would answer a would-be controller within its trial's credit only)."""
    ctl = mavutil.mavlink_connection(f"udpout:127.0.0.1:{LINK_PORT + n}", source_system=CONTROLLER_SYSID,
                                     source_component=CONTROLLER_COMPID, dialect="common")
    ctl.port.bind(("127.0.0.1", 0))
    return ctl


def held_mission(ctl: Any, n: int) -> list[Any]:
    """The vehicle's mission, downloaded over its controller link as the configured controller."""
    try:
        ctl.mav.mission_request_list_send(n + 1, 1, 0)
        count = ctl.recv_match(type="MISSION_COUNT", blocking=True, timeout=5)
        got = []
        for seq in range(count.count if count is not None else 0):
            ctl.mav.mission_request_int_send(n + 1, 1, seq, 0)
            got.append(ctl.recv_match(type="MISSION_ITEM_INT", blocking=True, timeout=5,
                                      condition=f"MISSION_ITEM_INT.seq=={seq}"))
        ctl.mav.mission_ack_send(n + 1, 1, 0, 0)
        return got
    finally:
        ctl.close()


def vehicle_log(tlog: Path, sysid: int) -> tuple[int, set[int]]:
    """From the vehicle's tlog: the MISSION_REQUEST_INTs it sent, and the totals its MISSION_CURRENTs named."""
    log = mavutil.mavlink_connection(str(tlog), dialect="common")
    requests, totals = 0, set()
    while (m := log.recv_match(type=["MISSION_REQUEST_INT", "MISSION_CURRENT"])) is not None:
        if m.get_srcSystem() != sysid:
            continue
        if m.get_type() == "MISSION_CURRENT":
            totals.add(m.total)
        else:
            requests += 1
    return requests, totals


def cell(loss: int, delay: int, n_items: int, timeout_s: float, seed: int) -> dict[str, Any]:
    """One upload through a relay of ``loss`` % and ``delay`` ms each way; its figures."""
    mission = items(n_items)
    with instance_slot() as n, tempfile.TemporaryDirectory(prefix="bsst-mt-") as tmp:
        relay, line = start(["relay", "--listen", "127.0.0.1:0", "--to", f"127.0.0.1:{GCS_PORT + n}",
                             "--listen-direction", "down", "--loss", str(loss), "--delay", str(delay),
                             "--link-seed", str(seed), "--stats", f"{tmp}/relay.json"], '"report":"ready"',
                            Path(tmp) / "relay.log")
        ready = parse_line(line)
        assert isinstance(ready, Ready) and ready.listen is not None, line
        port = int(ready.listen.rsplit(":", 1)[1])
        ctl = controller_end(n)
        vehicle, _ = start(["vehicle", "--instance", str(n), "--gcs", f"udpout:127.0.0.1:{port}", "--out", tmp,
                            "--controller-from", f"127.0.0.1:{ctl.port.getsockname()[1]}"], "ready",
                           Path(tmp) / "vehicle.log")
        gcs = mavutil.mavlink_connection(f"udpin:127.0.0.1:{GCS_PORT + n}", source_system=255,
                                         source_component=190, dialect="common")
        try:
            if gcs.wait_heartbeat(timeout=30) is None:
                raise RuntimeError("no heartbeat through the relay")
            out = upload(gcs, mission, (n + 1, 1), max(1.0, 3 * 2 * delay / 1000), timeout_s)
            held = held_mission(ctl, n)
        finally:
            gcs.close()
            ctl.close()
            stop(vehicle)
            stop(relay)
        requests, totals = vehicle_log(Path(tmp) / "vehicle.tlog", n + 1)
        relay_stats = json.loads((Path(tmp) / "relay.json").read_text())
    return {"loss_pct": loss, "delay_ms": delay, **out, "vehicle_requests": requests,
            "requested_again": requests - n_items, "lost_up": relay_stats["up"]["lost"],
            "lost_down": relay_stats["down"]["lost"],
            "held_is_uploaded": [fields(m) for m in held if m is not None] == [fields(m) for m in mission],
            "held_totals": sorted(totals)}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--items", type=int, default=100)
    ap.add_argument("--cell-timeout", type=float, default=300.0)
    ap.add_argument("--json", action="store_true", help="print the cells as JSON lines")
    args = ap.parse_args()
    rows = []
    print("| loss % | delay ms | upload s | result | vehicle requests (again) | items sent | counts sent "
          "| lost up/down | held = uploaded | MISSION_CURRENT totals |")
    print("|---:|---:|---:|---|---:|---:|---:|---:|---|---|")
    for delay in DELAYS:
        for loss in LOSSES:
            r = cell(loss, delay, args.items, args.cell_timeout, seed=1000 + loss + delay)
            rows.append(r)
            print(f"| {loss} | {delay} | {r['upload_s']:.1f} | {r['result']} | {r['vehicle_requests']} "
                  f"({r['requested_again']}) | {r['items']} | {r['counts']} | {r['lost_up']}/{r['lost_down']} | "
                  f"{'yes' if r['held_is_uploaded'] else 'NO'} | {r['held_totals']} |", flush=True)
    if args.json:
        for r in rows:
            print(json.dumps(r))
    return 0


if __name__ == "__main__":
    sys.exit(main())
