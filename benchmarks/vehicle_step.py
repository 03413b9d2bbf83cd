"""The vehicle's lockstep step alone, in one process: from the controller's answer held to the next state out.

The vehicle leg of ``benchmarks/sitl.py`` without the sockets' waits: a :class:`Vehicle` armed in offboard
lockstep is handed the hover target of step k (as its receive path holds it) and flies the step (the up-link
model, four RK4 physics steps, the failsafe and divergence checks) until it stamps the ODOMETRY of step k + 1;
the plant is put back at hover each step, so every step flies the same. Printed: the median over ``--steps``
(us), and with ``--calls`` the Python calls a step makes (cProfile: every function called at least 0.9 times a
step), a figure the machine's load does not move.

It imports ``bridge`` from ``sys.path`` as given (``PYTHONPATH``), so the same script measures another tree,
e.g. the commit before the vehicle was split into parts (issue 21):

    PYTHONPATH=/path/to/other/tree .venv/bin/python benchmarks/vehicle_step.py [--steps 3000] [--calls]
    .venv/bin/python benchmarks/vehicle_step.py                   # this tree (BSST_KERNELS=compiled: compiled)
"""

from __future__ import annotations

import argparse
import cProfile
import os
import pstats
import socket
import statistics
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
if sys.path and Path(sys.path[0] or ".").resolve() == ROOT / "benchmarks":
    sys.path.pop(0)  # not this folder: its missions.py would stand for the package
try:
    import bridge  # noqa: F401  (the tree on PYTHONPATH, if any)
except ImportError:
    sys.path.insert(0, str(ROOT))


def make_vehicle() -> tuple[Any, Any, Any]:
    """(the vehicle, its hover target on the wire, a step function that returns the ns to the next state out)."""
    from bridge.core.flight import prepare
    from bridge.mavlink.endpoint import parse_address
    from bridge.nodes.vehicle import Vehicle, VehicleConfig
    from missions import MISSION_DIR

    try:
        from bridge.autopilot.simvehicle import OFFBOARD
    except ImportError:  # the tree before bridge/autopilot
        from bridge.core.simvehicle import OFFBOARD  # type: ignore[no-redef]
    f = prepare(MISSION_DIR / "sine.toml")
    v = Vehicle(f, VehicleConfig(parse_address("udpin:127.0.0.1:0"), None), None)
    v.sim.arm()
    v.sim.mode = OFFBOARD
    v.plant.ground = False
    v.plant.state = (0.0, 0.0, 0.0, 0.0, 5.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sink.bind(("127.0.0.1", 0))
    sink.setblocking(False)
    v.link.peer = sink.getsockname()
    stamp = [0]
    send = v._send_odometry

    def stamped(now: float, fresh: bool = True) -> None:
        stamp[0] = time.perf_counter_ns()
        send(now, fresh)

    v._send_odometry = stamped
    split = hasattr(v, "clock")  # the vehicle in parts: its step clock holds the answer
    if split:
        from bridge.nodes.vehicle.clock import Answer
        v.clock.engage(time.monotonic(), 0)
    else:
        v.engaged = True
    p = f.profile
    wire = (p.mass * p.gravity / p.u_max[0], 0.0, 0.0, 0.0)
    X0 = v.plant.state

    def step() -> int:
        v.plant.state = X0
        t0 = time.perf_counter_ns()
        if split:
            v.clock.hold(Answer(wire, time.monotonic()))
        else:
            v.pending = (wire, time.monotonic())
        v._step_lockstep()
        try:
            while True:
                sink.recv(65535)
        except BlockingIOError:
            pass
        return stamp[0] - t0

    return v, wire, step


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--steps", type=int, default=3000)
    ap.add_argument("--calls", action="store_true", help="also count the Python calls a step makes (cProfile)")
    args = ap.parse_args()
    _, _, step = make_vehicle()
    for _ in range(300):  # warm up
        step()
    times = [step() for _ in range(args.steps)]
    print(f"bridge from {Path(sys.modules['bridge'].__file__).parent.parent}; kernels "
          f"{os.environ.get('BSST_KERNELS', 'default')}; load {os.getloadavg()[0]:.2f}")
    print(f"vehicle step, answer held to next state out: median {statistics.median(times) / 1e3:.1f} us, "
          f"lower quartile {statistics.quantiles(times, n=4)[0] / 1e3:.1f} us ({args.steps} steps)")
    if args.calls:
        prof = cProfile.Profile()
        prof.enable()
        for _ in range(args.steps):
            step()
        prof.disable()
        st = pstats.Stats(prof).stats  # type: ignore[attr-defined]
        calls = sum(v[1] for v in st.values() if v[1] >= 0.9 * args.steps) / args.steps
        print(f"Python calls a step (functions called at least 0.9 times a step): {calls:.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
