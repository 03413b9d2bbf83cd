"""SITL speed: the UDP ping-pong floor, the lockstep step rate, their ratio (issue 4).

Measured in one run on this machine, each the median over ``--repeats``:

(a) the bare floor: two processes over UDP loopback, ODOMETRY one way and
    HIL_ACTUATOR_CONTROLS back, in round trips per second:
    - ``naive``: pymavlink encode (``msg.pack``), blocking ``recvfrom``, ``parse_buffer``;
    - ``endpoint``: this project's :class:`bridge.mavlink.endpoint.Endpoint` (hot-path codec,
      short poll before blocking), i.e. the floor the SITL itself stands on;
(b) the lockstep SITL control-step rate of the sine mission at 250 Hz (``bsst sitl``'s
    processes, flight only: from the first to the last state the vehicle sent);
(c) (b) / (a) and the lockstep real-time factor (b) / 250 Hz.

(b) and (c) for each of ``--kernels`` (default ``plain,compiled``): the children's law and plant plain, or
compiled by numba (``BSST_KERNELS``, bridge.core.scalar; the same bits), interleaved with the floors.

Targets: (b) >= 50 % of (a) naive; stretch >= 20x real time; compiled, (b) >= 0.4 of (a) endpoint (issue 25).

``--profile DIR`` also runs the vehicle and the controller alone under cProfile for one
lockstep sine flight and prints where each spends its time.

    .venv/bin/python benchmarks/sitl.py [--repeats 3] [--trips 5000] [--kernels plain,compiled] [--profile DIR]
        [--json]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import pstats
import socket
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from pymavlink.dialects.v20 import common as mavlink  # noqa: E402

from bridge.mavlink.endpoint import HIL_ACTUATOR_CONTROLS, ODOMETRY, Endpoint, Spinner, parse_address, wait  # noqa: E402
from bridge.nodes.report import Ready, parse_line  # noqa: E402
from bridge.nodes.vehicle import VehicleConfig  # noqa: E402

RATE_HZ = 250.0
FLOOR_SHARE_TARGET = 0.4  # issue 25: a compiled lockstep step at least 0.4 of the endpoint ping-pong's round trip
LEGS = ("down_us", "controller_us", "up_us", "vehicle_us", "step_us")
WAITING = ("sched_yield", "select.select", "recvfrom", "poll", "wait")  # where a side waits for the other
SPIN = VehicleConfig.spin_s  # the endpoint ping-pong polls as long as the SITL's vehicle does
STOP = 2**64 - 1  # time_usec that tells the echo process to exit
COV = [math.nan] + [0.0] * 20


def _odometry(k: int) -> Any:
    return mavlink.MAVLink_odometry_message(k, 1, 12, 1.0, 2.0, -3.0, [1.0, 0.0, 0.0, 0.0], 0.1, 0.2, 0.3,
                                            0.01, 0.02, 0.03, COV, COV, 0, 1, 100)


# -- (a) ping-pong -------------------------------------------------------------------------------
def echo(mode: str, port_file: str) -> None:
    """The far end: answer each ODOMETRY with HIL_ACTUATOR_CONTROLS stamped with its time."""
    if mode == "naive":
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.bind(("127.0.0.1", 0))
        Path(port_file).write_text(str(sock.getsockname()[1]))
        mav = mavlink.MAVLink(None, 200, 191)
        while True:
            data, addr = sock.recvfrom(65535)
            for m in mav.parse_buffer(data) or []:
                if m.time_usec == STOP:
                    return
                reply = mavlink.MAVLink_hil_actuator_controls_message(m.time_usec, [0.5] * 4 + [0.0] * 12, 128, 1)
                sock.sendto(reply.pack(mav), addr)
                mav.seq = (mav.seq + 1) & 0xFF
    ep = Endpoint(parse_address("udpin:127.0.0.1:0"), sysid=200, compid=191)
    spinner = Spinner(ep, SPIN)
    Path(port_file).write_text(str(ep.local[1]))
    controls = (0.5,) * 4 + (0.0,) * 12
    while True:
        for _, m, _a in wait((ep,), time.monotonic() + 60.0, spinner):
            if m.time_usec == STOP:
                return
            ep.send_hot(HIL_ACTUATOR_CONTROLS, (m.time_usec, 1, *controls, 128))


def pingpong(mode: str, trips: int) -> float:
    """Round trips per second against an :func:`echo` process."""
    port_file = Path(f"/tmp/bsst-bench-{os.getpid()}-{mode}.port")
    port_file.unlink(missing_ok=True)
    proc = subprocess.Popen([sys.executable, __file__, "--echo", mode, str(port_file)])
    try:
        deadline = time.monotonic() + 20.0
        while not port_file.exists() or not port_file.read_text():
            if time.monotonic() > deadline or proc.poll() is not None:
                raise RuntimeError("echo process did not start")
            time.sleep(0.01)
        port = int(port_file.read_text())
        if mode == "naive":
            sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            sock.bind(("127.0.0.1", 0))
            mav = mavlink.MAVLink(None, 1, 1)
            dest = ("127.0.0.1", port)

            def trip(k: int) -> None:
                sock.sendto(_odometry(k).pack(mav), dest)
                mav.seq = (mav.seq + 1) & 0xFF
                while True:
                    data, _ = sock.recvfrom(65535)
                    if any(m.time_usec == k for m in mav.parse_buffer(data) or []):
                        return

            def stop() -> None:
                sock.sendto(_odometry(STOP).pack(mav), dest)
        else:
            ep = Endpoint(parse_address(f"udpout:127.0.0.1:{port}"), sysid=1, compid=1)
            spinner = Spinner(ep, SPIN)
            tail = (1.0, 2.0, -3.0, 1.0, 0.0, 0.0, 0.0, 0.1, 0.2, 0.3, 0.01, 0.02, 0.03, *COV, *COV, 1, 12, 0, 1, 100)

            def trip(k: int) -> None:
                ep.send_hot(ODOMETRY, (k, *tail))
                while True:
                    if any(m.time_usec == k for _, m, _a in wait((ep,), time.monotonic() + 5.0, spinner)):
                        return

            def stop() -> None:
                ep.send_hot(ODOMETRY, (STOP, *tail))
        for k in range(1, 200):  # warm up both ends
            trip(k)
        t0 = time.perf_counter()
        for k in range(200, 200 + trips):
            trip(k)
        rate = trips / (time.perf_counter() - t0)
        stop()
        proc.wait(timeout=10)
        return rate
    finally:
        if proc.poll() is None:
            proc.kill()
        port_file.unlink(missing_ok=True)


# -- (b) lockstep SITL -----------------------------------------------------------------------------
def lockstep_rate(mission: str, kernels: str = "plain") -> dict[str, float]:
    """Flight step rate (steps/s) of one lockstep session (its children's ``kernels``: plain or compiled), its
    session wall time, and the median step split into its four legs, from both sides' wall-clock stamps (us)."""
    import tempfile

    from bridge.core.scalar import KERNELS_ENV
    from bridge.record.halves import read_half
    from bridge.session import sitl

    os.environ[KERNELS_ENV] = kernels  # the children inherit it
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        run = sitl(mission, out=Path(tmp) / "run", instance=None, plots=False)
        wall = time.perf_counter() - t0
        if run.outcome != "completed":
            raise RuntimeError(f"lockstep session ended {run.outcome}")
        v = read_half(Path(tmp) / "run" / "vehicle.bin")
        c = read_half(Path(tmp) / "run" / "controller.bin")
    n = min(len(v["k"]), len(c["k"]))
    us = 1e6
    legs = {
        "down_us": (c["odo_recv_wall"][:n] - v["odo_sent_wall"][:n]) * us,  # ODOMETRY k on the wire + decode
        "controller_us": (c["cmd_sent_wall"][:n] - c["odo_recv_wall"][:n]) * us,  # law + actuation + encode
        "up_us": (v["cmd_recv_wall"][:n] - c["cmd_sent_wall"][:n]) * us,  # target k on the wire + decode
        "vehicle_us": (v["odo_sent_wall"][1:n] - v["cmd_recv_wall"][:n - 1]) * us,  # physics + state encode
        "step_us": (v["odo_sent_wall"][1:n] - v["odo_sent_wall"][:n - 1]) * us,
    }
    timing = run.summary["timing"]
    out = {"step_rate_hz": timing["step_rate_hz"], "session_wall_s": wall,
           "state_to_command_ms_p50": timing["state_to_command_ms"]["p50"]}
    out.update({k: float(statistics.median(x)) for k, x in legs.items()})
    out["steps_over_1ms_share_of_time"] = float(sum(x for x in legs["step_us"] if x > 1000) / sum(legs["step_us"]))
    return out


# -- profile ----------------------------------------------------------------------------------------
def profile(mission: str, out: Path) -> dict[str, list[tuple[str, float]]]:
    """Fly one lockstep mission with both sides under cProfile; top functions by own time."""
    out.mkdir(parents=True, exist_ok=True)
    port_file = out / "vehicle.out"
    with open(port_file, "wb") as f:
        veh = subprocess.Popen([sys.executable, "-m", "cProfile", "-o", str(out / "vehicle.prof"), "-m", "bridge",
                                "vehicle", mission, "--listen", "127.0.0.1:0", "--gcs", "none"], stdout=f)
    try:
        deadline = time.monotonic() + 30
        port = None
        while port is None:
            for line in port_file.read_text().splitlines():
                report = parse_line(line)
                if isinstance(report, Ready):
                    port = report.listen
            if time.monotonic() > deadline:
                raise RuntimeError("vehicle did not start")
            time.sleep(0.05)
        subprocess.run([sys.executable, "-m", "cProfile", "-o", str(out / "controller.prof"), "-m", "bridge",
                        "controller", mission, "--vehicle", port], check=True, stdout=subprocess.DEVNULL)
    finally:
        veh.terminate()
        veh.wait(timeout=10)
    tops = {}
    for side in ("vehicle", "controller"):
        st = pstats.Stats(str(out / f"{side}.prof"))
        stats = st.stats  # type: ignore[attr-defined]
        total = sum(v[2] for v in stats.values())
        waiting = sum(v[2] for (_, _, name), v in stats.items() if any(w in name for w in WAITING))
        work = {k: v for k, v in stats.items() if not any(w in k[2] for w in WAITING)}
        rows = sorted(work.items(), key=lambda kv: kv[1][2], reverse=True)[:10]
        tops[side] = [("waiting (poll, yield, select) of all", round(100 * waiting / total, 1))] + [
            (f"{Path(fn).name}:{line}({name}) of work", round(100 * v[2] / (total - waiting), 1))
            for (fn, line, name), v in rows]
    return tops


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--trips", type=int, default=5000)
    ap.add_argument("--mission", default=str(ROOT / "missions" / "sine.toml"))
    ap.add_argument("--kernels", default="plain,compiled",
                    help="the children's kernels to measure, comma-separated: plain, compiled (default both)")
    ap.add_argument("--profile", metavar="DIR", help="also profile both sides (cProfile files into DIR)")
    ap.add_argument("--json", action="store_true", help="print the figures as JSON")
    ap.add_argument("--echo", nargs=2, metavar=("MODE", "PORTFILE"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.echo:
        echo(*args.echo)
        return
    kinds = [k.strip() for k in args.kernels.split(",") if k.strip()]
    if not kinds or any(k not in ("plain", "compiled") for k in kinds):
        ap.error("--kernels: a comma-separated list of plain, compiled")
    naive, ours = [], []
    steps: dict[str, list[dict[str, float]]] = {k: [] for k in kinds}
    for _ in range(args.repeats):  # interleaved, so that a busy moment hits all of them alike
        naive.append(pingpong("naive", args.trips))
        ours.append(pingpong("endpoint", args.trips))
        for k in kinds:
            steps[k].append(lockstep_rate(args.mission, k))
    a = statistics.median(naive)
    a2 = statistics.median(ours)
    res: dict[str, Any] = {
        "machine": f"{platform.machine()} {os.cpu_count()} cpu, Python {platform.python_version()}",
        "load_1min": os.getloadavg()[0],
        "a_pingpong_naive_rt_per_s": a,
        "a_pingpong_endpoint_rt_per_s": a2,
        "repeats": args.repeats,
        "kernels": {k: _lockstep_figures(runs, a, a2) for k, runs in steps.items()},
    }
    res.update(res["kernels"][kinds[0]])  # the first kernels' figures at the top level too (as before)
    if args.profile:
        res["profile_own_time_pct"] = profile(args.mission, Path(args.profile))
    if args.json:
        print(json.dumps(res, indent=2))
        return
    print(f"machine: {res['machine']}, load {res['load_1min']:.2f}, medians of {args.repeats}")
    print(f"(a) ping-pong floor, naive pymavlink (blocking recvfrom): {a:8.0f} round trips/s")
    print(f"    ping-pong floor, bridge.mavlink.endpoint (hot codec + poll):  {a2:8.0f} round trips/s")
    for k, r in res["kernels"].items():
        b = r["b_lockstep_steps_per_s"]
        print(f"(b) lockstep SITL, sine at 250 Hz, {k} kernels:           {b:8.0f} steps/s")
        print(f"(c) (b)/(a) = {b / a:.2f} (naive), {b / a2:.2f} (endpoint);  lockstep real-time factor "
              f"{b / RATE_HZ:.1f}x")
        print(f"    whole session (start, fly 30 s, stop, summary): {r['lockstep_session_wall_s']:.2f} s wall;"
              f" state-to-command p50 {r['state_to_command_ms_p50']:.3f} ms")
        print("    median lockstep step, by leg (us): " + ", ".join(f"{x[:-3]} {r[x]:.0f}" for x in LEGS)
              + f"; steps over 1 ms take {100 * r['steps_over_1ms_share_of_time']:.0f} % of the flight's wall time")
        if k == "compiled":
            print(f"    issue 25: (b)/(a) endpoint >= {FLOOR_SHARE_TARGET}: "
                  f"{'met' if b / a2 >= FLOOR_SHARE_TARGET else 'NOT met'} ({b / a2:.2f})")
    for side, rows in res.get("profile_own_time_pct", {}).items():
        print(f"profile, {side} (own time %):")
        for name, pct in rows:
            print(f"    {pct:5.1f}  {name}")


def _lockstep_figures(steps: list[dict[str, float]], a: float, a2: float) -> dict[str, float]:
    """The medians of one kernels' lockstep sessions, and their ratios to the floors ``a`` (naive) and ``a2``."""
    b = statistics.median(s["step_rate_hz"] for s in steps)
    return {
        "b_lockstep_steps_per_s": b,
        "c_ratio_b_over_a_naive": b / a,
        "c_ratio_b_over_a_endpoint": b / a2,
        "c_lockstep_real_time_factor": b / RATE_HZ,
        "lockstep_session_wall_s": statistics.median(s["session_wall_s"] for s in steps),
        "state_to_command_ms_p50": statistics.median(s["state_to_command_ms_p50"] for s in steps),
        **{k: statistics.median(s[k] for s in steps) for k in LEGS + ("steps_over_1ms_share_of_time",)},
    }

if __name__ == "__main__":
    main()
