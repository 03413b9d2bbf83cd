"""Each side's work in one lockstep step, alone in one process: what the machine's load moves least.

In:  trees to compare (``--tree PATH``, repeatable; default this one), ``--kernels`` (plain, compiled), rounds,
     steps per run
Out: per tree, side and kernels: the median over rounds of the median wall time (us) and the CPU time (us,
     ``time.process_time``) per step, and each tree's ratio to the first; the load average

The two legs of ``benchmarks/sitl.py`` that are work, without the waits between the processes:

- vehicle: the controller's target for step k is put in the vehicle's socket (127.0.0.1), then the vehicle's
  own lockstep wait takes it (receive path, authority, the clock) and flies the step (up-link model, four RK4
  physics steps, failsafe and divergence checks) until the ODOMETRY of step k + 1 is out; the plant is put
  back at hover each step (benchmarks/vehicle_step.py's vehicle);
- controller: the vehicle's ODOMETRY of step k is put in the controller's socket, then one pass of the
  controller's lockstep loop (wait, checks, the down-link model, the guard, the law, the target out).

Each run is a fresh process with the tree on ``PYTHONPATH`` (so the commit before issue 21 is measured by the
same code), and the trees' runs are interleaved round by round so that a busy moment hits them alike. CPU time
includes the two system calls a step makes on loopback (send, receive). Instructions per step, which no load
moves (valgrind, ~1 min a run)::

    PYTHONHASHSEED=0 valgrind --tool=cachegrind --cache-sim=no python benchmarks/step_work.py --child vehicle plain N

for N = 100 and 1100: (difference) / 1000.

    .venv/bin/python benchmarks/step_work.py [--tree /path/to/other/tree] [--tree .] [--kernels plain,compiled]
        [--rounds 5] [--steps 3000]
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import math
import os
import socket
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
if sys.path and Path(sys.path[0] or ".").resolve() == ROOT / "benchmarks":
    sys.path.pop(0)  # not this folder: its missions.py would stand for the package
WARM = 300  # steps before measuring


def _frames(n: int, rate: float, build: Callable[[int], Any], sysid: int, compid: int) -> list[bytes]:
    """n frames of one message per step k (``build(time_usec)``), encoded by pymavlink as a peer would."""
    from pymavlink.dialects.v20 import common as mavlink

    mav = mavlink.MAVLink(None, sysid, compid)
    out = []
    for k in range(n):
        out.append(build(int(round(k * 1e6 / rate))).pack(mav))
        mav.seq = (mav.seq + 1) & 0xFF
    return out


def vehicle_side(n: int) -> Callable[[], tuple[int, bool]]:
    """One step of the vehicle's work (module docstring): returns (its wall time ns, whether it stepped)."""
    from pymavlink.dialects.v20 import common as mavlink

    spec = importlib.util.spec_from_file_location("vehicle_step", Path(__file__).with_name("vehicle_step.py"))
    assert spec is not None and spec.loader is not None
    vs = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(vs)
    v, w, _ = vs.make_vehicle()
    ctl = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    ctl.bind(("127.0.0.1", 0))
    ctl.setblocking(False)
    v.link.peer = ctl.getsockname()
    v.link.prioritise(v.link.peer)
    if v.actuation == "motors":
        def build(us: int) -> Any:
            return mavlink.MAVLink_hil_actuator_controls_message(us, [*w, *(0.0,) * 12], 128, 1)
    else:
        def build(us: int) -> Any:
            return mavlink.MAVLink_set_actuator_control_target_message(us, 0, 1, 1, [*w, *(0.0,) * 4])
    frames = _frames(n + 2 * WARM, v.rate, build, v.cfg.controller_sysid, v.cfg.controller_compid)
    v._next_house = v._resend_at = v._lost_at = time.monotonic() + 1e9  # no housekeeping, resend, loss
    X0 = v.plant.state
    dest = v.link.local

    def step() -> tuple[int, bool]:
        v.plant.state = X0
        k = v.k
        t0 = time.perf_counter_ns()
        ctl.sendto(frames[k], dest)
        v._lockstep_wait()
        t1 = time.perf_counter_ns()
        _drain(ctl)
        return t1 - t0, v.k == k + 1

    return step


def controller_side(n: int) -> Callable[[], tuple[int, bool]]:
    """One pass of the controller's lockstep loop (module docstring): (its wall time ns, whether it answered)."""
    from pymavlink.dialects.v20 import common as mavlink

    from bridge.core.flight import prepare
    from bridge.core.wire import step_of_usec
    from bridge.mavlink.endpoint import parse_address, wait
    from bridge.nodes.offboard import Offboard, OffboardConfig
    from missions import MISSION_DIR

    veh = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    veh.bind(("127.0.0.1", 0))
    veh.setblocking(False)
    o = Offboard(prepare(MISSION_DIR / "sine.toml"),
                 OffboardConfig(parse_address(f"udpout:127.0.0.1:{veh.getsockname()[1]}")), None)
    o.vsys, o.vcomp = 1, 1  # as after its HEARTBEAT: armed, in OFFBOARD
    o.vehicle_armed = o.armed_seen = True
    o.vehicle_state = mavlink.MAV_STATE_ACTIVE
    cov = [math.nan] + [0.0] * 20
    frames = _frames(n + 2 * WARM, o.rate, lambda us: mavlink.MAVLink_odometry_message(
        us, 1, 12, 0.0, 0.0, -1.0, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, cov, cov, 0, 1, 100), 1, 1)
    o._next_house = o._last_rx = time.monotonic() + 1e9
    ep, rate, dest = o.ep, o.rate, o.ep.local
    k = [0]

    def step() -> tuple[int, bool]:
        sent = o.commands
        t0 = time.perf_counter_ns()
        veh.sendto(frames[k[0]], dest)
        k[0] += 1
        for _, m, _a in wait((ep,), time.monotonic() + 1.0, o.spinner):  # as Offboard._fly_lockstep
            o._on(m)
        odo, o._odo = o._odo, None
        if odo is not None:
            recv = o._odo_recv
            kk = step_of_usec(odo.time_usec, rate)
            o._observe(odo, kk / rate, recv)
            o._decide(kk / rate, kk, odo.time_usec, recv, math.nan)
        t1 = time.perf_counter_ns()
        _drain(veh)
        return t1 - t0, o.commands == sent + 1

    return step


def _drain(sock: socket.socket) -> None:
    try:
        while True:
            sock.recv(65535)
    except BlockingIOError:
        pass


def child(side: str, kernels: str, n: int) -> dict[str, Any]:
    """Measure one side in this process (``BSST_KERNELS`` = ``kernels``): median wall and CPU per step (us)."""
    os.environ["BSST_KERNELS"] = kernels
    if kernels == "compiled" and importlib.util.find_spec("bridge.core.scalar") is None:
        raise SystemExit("no compiled kernels in this tree")  # (the tree before issue 21's kernels)
    step = vehicle_side(n) if side == "vehicle" else controller_side(n)
    for _ in range(WARM):
        step()
    c0 = time.process_time()
    runs = [step() for _ in range(n)]
    cpu = (time.process_time() - c0) / n * 1e6
    if not all(ok for _, ok in runs):
        raise SystemExit(f"{side}: not every step was flown")
    return {"wall_us": statistics.median(t for t, _ in runs) / 1e3, "cpu_us": cpu}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--tree", action="append", help="a tree to measure (repeatable; default this one)")
    ap.add_argument("--kernels", default="plain,compiled")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--steps", type=int, default=3000)
    ap.add_argument("--child", nargs=3, metavar=("SIDE", "KERNELS", "STEPS"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        side, kernels, steps = args.child
        print(json.dumps(child(side, kernels, int(steps))))
        return 0
    trees = [str(Path(t).resolve()) for t in (args.tree or [str(ROOT)])]
    kinds = [k.strip() for k in args.kernels.split(",") if k.strip()]
    cases = [(t, s, k) for t in trees for s in ("vehicle", "controller") for k in kinds]
    got: dict[tuple[str, str, str], list[dict[str, float]]] = {c: [] for c in cases}
    for _ in range(args.rounds):
        for t, s, k in cases:
            env = dict(os.environ, PYTHONPATH=t, BSST_KERNELS=k)
            p = subprocess.run([sys.executable, __file__, "--child", s, k, str(args.steps)], env=env, cwd=t,
                               capture_output=True, text=True)
            if p.returncode == 0:
                got[(t, s, k)].append(json.loads(p.stdout.strip().splitlines()[-1]))
    print(f"load {os.getloadavg()[0]:.2f} (1 min) after {args.rounds} rounds of {args.steps} steps; medians of the "
          "rounds' medians (wall) and means (CPU), us a step")
    first: dict[tuple[str, str], float] = {}
    for t, s, k in cases:
        runs = got[(t, s, k)]
        if not runs:  # e.g. compiled kernels in a tree without them
            print(f"{t}  {s:10s} {k:8s}  (no run)")
            continue
        wall = statistics.median(r["wall_us"] for r in runs)
        cpu = statistics.median(r["cpu_us"] for r in runs)
        base = first.setdefault((s, k), cpu)
        print(f"{t}  {s:10s} {k:8s}  wall {wall:6.1f}  cpu {cpu:6.1f}  cpu / first tree's {cpu / base:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
