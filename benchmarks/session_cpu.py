"""CPU a lockstep step costs each child of a real session, its recording, streams and wake-ups included.

In:  trees to compare (``--tree PATH``, repeatable; default this one), ``--rounds``, the mission (default the
     sine), the vehicle's ``--gcs`` (default none, as a session with no instance), ``--realtime``
Out: per tree and side (vehicle, controller): the CPU of one lockstep step (us: user + system, and system
     alone), the median over rounds of (the mission's CPU - the CPU of the same mission cut to 2 s) / (its
     steps - 500); with ``--realtime``, both sides on the wall clock, that as CPU ms per second of flight; the load
     average

``benchmarks/step_work.py`` measures each side's own work with the other side's message already waiting;
this flies both sides as ``bsst sitl`` does in lockstep (``bsst vehicle --lockstep --speed 0`` and ``bsst
controller``, each exec'd from the tree on ``PYTHONPATH``, both recording with ``--out``), so each step also
pays its sleep in ``select``, its wake-up and the caches the other process used (docs/figures.md, the
forty-first session: ~55-75 us a step a side at load 2-4). Each child's CPU is its own ``wait4`` rusage;
the 2 s flight cancels the start-up, the take-off and the landing. The trees' runs alternate round by round.
``--realtime`` flies them as ``bsst sitl --realtime`` does (``--realtime`` on both): what a second of a real-time
flight costs each side (docs/figures.md, the forty-third session).

    .venv/bin/python benchmarks/session_cpu.py [--tree /path/to/other/tree] [--tree .] [--rounds 3]
        [--mission missions/sine.toml] [--gcs none] [--realtime]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
if sys.path and Path(sys.path[0] or ".").resolve() == ROOT / "benchmarks":
    sys.path.pop(0)  # not this folder: its missions.py would stand for the package
sys.path.insert(0, str(ROOT))
SHORT_S = 2.0  # s: the cut flight, whose CPU is subtracted
READY_S = 30.0  # s: the vehicle's start


def _ready_port(out: Path, proc: subprocess.Popen[bytes]) -> str:
    """The vehicle's listening address, from its READY line (``bridge.nodes.report``)."""
    from bridge.nodes.report import Ready, parse_line  # (imported when flying: --help needs none of it)

    deadline = time.monotonic() + READY_S
    while time.monotonic() < deadline:
        for line in out.read_text().splitlines():
            report = parse_line(line)
            if isinstance(report, Ready):
                return report.listen
        if proc.poll() is not None:
            raise SystemExit(f"the vehicle ended before it was ready ({out})")
        time.sleep(0.02)
    raise SystemExit(f"the vehicle was not ready within {READY_S:g} s ({out})")


def _rusage(proc: subprocess.Popen[bytes]) -> tuple[float, float]:
    """Wait for ``proc``; its (user + system, system) CPU seconds."""
    _, status, ru = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    return ru.ru_utime + ru.ru_stime, ru.ru_stime


def fly(tree: str, mission: Path, gcs: str, realtime: bool = False) -> dict[str, tuple[float, float]]:
    """One lockstep (or real-time) flight of ``mission`` by ``tree``'s children: each side's (CPU s, system CPU s)."""
    clock = ["--realtime"] if realtime else ["--lockstep", "--speed", "0"]
    env = dict(os.environ, PYTHONPATH=tree)
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    py = [sys.executable, "-m", "bridge"]
    with tempfile.TemporaryDirectory(prefix="session-cpu-") as tmp:
        t = Path(tmp)
        with open(t / "vehicle.out", "wb") as f:
            veh = subprocess.Popen([*py, "vehicle", str(mission), "--listen", "127.0.0.1:0", "--gcs", gcs,
                                    *clock, "--out", str(t / "v")], stdout=f,
                                   stderr=subprocess.DEVNULL, env=env, cwd=tree)
        try:
            port = _ready_port(t / "vehicle.out", veh)
            ctl = subprocess.Popen([*py, "controller", str(mission), "--vehicle", port, "--out", str(t / "c"),
                                    *clock[:1 if realtime else 0]],
                                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env, cwd=tree)
            c = _rusage(ctl)
            veh.terminate()  # (the controller saw it land: its flight is over)
            v = _rusage(veh)
        finally:
            if veh.returncode is None:
                veh.kill()
                veh.wait()
    return {"vehicle": v, "controller": c}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--tree", action="append", help="a tree to measure (repeatable; default this one)")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--mission", default=str(ROOT / "missions" / "sine.toml"))
    ap.add_argument("--gcs", default="none", help="the vehicle's --gcs (default none)")
    ap.add_argument("--realtime", action="store_true", help="fly on the wall clock: CPU ms per second of flight")
    args = ap.parse_args()
    trees = [str(Path(t).resolve()) for t in (args.tree or [str(ROOT)])]
    mission = Path(args.mission).resolve()
    text = mission.read_text()
    spec = tomllib.loads(text)
    rate, duration = float(spec.get("rate_hz", 250)), float(spec["duration_s"])
    steps = round((duration - SHORT_S) * rate)
    if steps <= 0:
        raise SystemExit(f"{mission}: duration_s {duration:g} is not over the cut flight's {SHORT_S:g} s")
    sides = ("vehicle", "controller")
    got: dict[tuple[str, str], list[tuple[float, float]]] = {(t, s): [] for t in trees for s in sides}
    with tempfile.TemporaryDirectory(prefix="session-cpu-") as tmp:
        short = Path(tmp) / "short.toml"
        short.write_text(text.replace(f"duration_s = {spec['duration_s']!r}", f"duration_s = {SHORT_S!r}", 1))
        if tomllib.loads(short.read_text())["duration_s"] != SHORT_S:
            raise SystemExit(f"{mission}: could not cut its duration_s line to {SHORT_S:g} s")
        for _ in range(args.rounds):
            for t in trees:
                long, cut = fly(t, mission, args.gcs, args.realtime), fly(t, short, args.gcs, args.realtime)
                for side in sides:
                    got[(t, side)].append(((long[side][0] - cut[side][0]) / steps * 1e6,
                                           (long[side][1] - cut[side][1]) / steps * 1e6))
    scale, unit = (rate / 1000.0, "CPU ms a second of real-time flight") if args.realtime else \
        (1.0, "CPU a lockstep step (us)")
    print(f"load {os.getloadavg()[0]:.2f} (1 min) after {args.rounds} rounds; {unit}, "
          f"{mission.name} ({duration:g} s) - the same cut to {SHORT_S:g} s, over {steps} steps")
    for (t, side), runs in got.items():
        every = ", ".join(f"{a * scale:.0f}" for a, _ in runs)
        print(f"{t}  {side:10s} median {statistics.median(a for a, _ in runs) * scale:6.1f} (system "
              f"{statistics.median(s for _, s in runs) * scale:5.1f})  rounds: {every}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
