"""The batch engine against the machine's ceiling and against the process engine, measured in one run
(issue 25's and issue 13's acceptance figures).

- the ceiling: this machine's scalar multiply-add rate (GFLOP/s a core) and the cost of a libm sin or
  cos call (ns), each measured with a small compiled loop in thread CPU time; the engine's work per cell
  and control step (:data:`WORK`, counted from the code) turned into the cells/s one core, and two,
  could fly at best; the fraction of it the sweep below reaches (target >= 50 % on 2 cores), in wall
  time and per CPU-second (the latter not moved by other load on the machine);
- jobs: the 1000-cell sweep flown with ``jobs=1`` and ``jobs=2`` (threads), each in a fresh process
  (wall and CPU time of the flight, the process's peak memory, a digest of the rows), interleaved with
  the ceiling's loops and with how many cores this process gets now (``--rounds`` rounds, alternating
  which goes first; the best round of each kept, each round's ratio printed): the speed-up (target
  >= 1.7x), whether every run gave the same rows, peak memory (target <= 1 GiB);
- batch: a 1000-cell sweep of the 30 s sine — delay 10 values x loss 10 values x 10 seeds, both link
  directions, BS-ST — flown by ``bridge.batch.fly_batch`` in this process: wall time, cells/s, and the
  peak resident memory of the process (``resource.getrusage``, measured right after it, before anything
  else runs here);
- process: a 32-cell subset of the same grid flown by ``bridge.sweep.sweep(..., jobs=2)`` (worker
  processes, today's engine): wall time and cells/s;
- the ratios to the process engine (target: >= 20 for the batch in one process), the load average
  before and after, and the median time of one batch control step (plant, law, link plan) at N = 1000
  over ``--repeats`` repeats;
- with prediction (``compensation = "predict"``, 0-57 ms each way, where the predictor integrates up to
  15 segments a step): a batch of 1 cell and of 100, against the scalar loop's CPU time per cell.

    .venv/bin/python benchmarks/batch_engine.py [--repeats 3] [--cells 1000] [--json]
    .venv/bin/python benchmarks/batch_engine.py --ceiling-only [--rounds 2]   # the ceiling and the jobs figures alone
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import os
import resource
import statistics
import subprocess
import sys
import threading
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from bridge.autopilot.kernelcache import njit  # noqa: E402
from bridge.batch import fly_batch  # noqa: E402
from bridge.batch.engine import _references  # noqa: E402
from bridge.batch.flight import batch_arrays, fly_cells  # noqa: E402
from bridge.core.flight import prepare  # noqa: E402
from bridge.link.plan import NONE, Clocks, plan_links  # noqa: E402
from bridge.loop import fly  # noqa: E402
from bridge.sweep import Grid, sweep  # noqa: E402
from bridge.sweep.grid import cell_overrides, cells  # noqa: E402
from missions import load_mission  # noqa: E402

DELAYS = tuple(float(d) for d in range(0, 20, 2))  # ms, 10 values
LOSSES = tuple(float(v) for v in range(0, 50, 5))  # %, 10 values
SUBSET = Grid(delay_ms=(0.0, 6.0, 12.0, 18.0), loss_pct=(0.0, 15.0, 30.0, 45.0), seeds=2)  # 32 cells
SCALAR_PROBE = 2  # cells of the subset flown by the scalar loop in this process, for its CPU time
TARGET_RATIO = 20.0
LIMIT_GIB = 1.0
TARGET_CEILING = 0.5  # of the 2-core ceiling
TARGET_SPEEDUP = 1.7  # jobs 2 against jobs 1

# The engine's work per cell and control step (the 30 s sine at 250 Hz, 4 physics steps a control step),
# counted from the code: flops (multiplies, adds, divides, square roots), libm calls (sin, cos, tan, atan2,
# pow, exp, log) and sin-cos pairs of one angle (the compiler makes each one sincos call).
WORK = {
    # plant.model.rk4_held: 4 stages of ~100 flops and the sin and cos of phi, theta, psi, + ~80 to combine
    "plant (4 RK4 steps)": (4 * 500, 0, 4 * 12),
    "law (controller.bsst.backstepping and the actuation)": (600, 12, 0),
    "wire (state and command through float32: quaternion, body rates)": (150, 20, 0),
    "figures and rings": (30, 0, 0),
}


@njit(cache=True)
def _multiply_adds(n: int, a: float) -> float:  # pragma: no cover
    """8 independent chains of x = x * a + b (2 flops each), n times: the scalar multiply-add throughput."""
    x0 = x1 = x2 = x3 = x4 = x5 = x6 = x7 = 1.0
    b = 1e-9
    for _ in range(n):
        x0 = x0 * a + b
        x1 = x1 * a + b
        x2 = x2 * a + b
        x3 = x3 * a + b
        x4 = x4 * a + b
        x5 = x5 * a + b
        x6 = x6 * a + b
        x7 = x7 * a + b
    return x0 + x1 + x2 + x3 + x4 + x5 + x6 + x7


@njit(cache=True)
def _libm_calls(n: int, step: float) -> float:  # pragma: no cover
    """n sin and n cos calls of different angles (0..3 rad, as the engine's attitudes and phases)."""
    s = 0.0
    v = 0.1
    for _ in range(n):
        s += math.sin(v) + math.cos(v * 1.0001)
        v += step
        if v > 3.0:
            v -= 3.0
    return s


@njit(cache=True)
def _sincos_pairs(n: int, step: float) -> float:  # pragma: no cover
    """n sin-cos pairs of one angle each (one sincos call), as plant.model.rk4_held takes them."""
    s = 0.0
    v = 0.1
    for _ in range(n):
        s += math.sin(v) * math.cos(v)
        v += step
        if v > 3.0:
            v -= 3.0
    return s


@njit(cache=True, nogil=True)
def _spin(n: int) -> float:  # pragma: no cover
    x = 1.0
    for _ in range(n):
        x = x * 0.9999999 + 1e-9
    return x


def machine_rates(repeats: int = 5) -> dict[str, float]:
    """Multiply-add GFLOP/s on one core and ns per libm sin or cos call, in this thread's CPU time (other
    load on the machine takes the core away between time slices, not within them), the best of ``repeats``."""
    _multiply_adds(10, 0.999999)
    _libm_calls(10, 1e-3)
    _sincos_pairs(10, 1e-3)
    n = 20_000_000
    flops, calls, pairs = [], [], []
    for _ in range(repeats):
        t0 = time.thread_time()
        _sincos_pairs(n // 4, 1e-3)
        pairs.append((time.thread_time() - t0) / (n // 4) * 1e9)
        t0 = time.thread_time()
        _multiply_adds(n, 0.999999)
        flops.append(16 * n / (time.thread_time() - t0) / 1e9)
        t0 = time.thread_time()
        _libm_calls(n // 4, 1e-3)
        calls.append((time.thread_time() - t0) / (2 * (n // 4)) * 1e9)
    return {"gflops": max(flops), "ns_per_call": min(calls), "ns_per_pair": min(pairs)}


def cores_available(threads: int = 2, n: int = 100_000_000) -> float:
    """How many cores this process gets now: CPU seconds over wall seconds of ``threads`` compiled loops
    running without the GIL (2.0 on an idle 2-core machine; less while other work shares it)."""
    _spin(10)
    workers = [threading.Thread(target=_spin, args=(n,)) for _ in range(threads)]
    t0, c0 = time.perf_counter(), time.process_time()
    for w in workers:
        w.start()
    for w in workers:
        w.join()
    return (time.process_time() - c0) / (time.perf_counter() - t0)


ISSUE_WORK = (2800, 35, 0)  # issue 25's count per cell-step (2.1e7 flops, 2.6e5 calls a 30 s cell): no plant trig


def ceiling(rates: dict[str, float], steps: int, work: tuple[int, int, int] | None = None) -> dict[str, float]:
    """The cells/s one core could fly at best: :data:`WORK` (or ``work``: flops, calls, sin-cos pairs) per
    cell-step at the measured rates."""
    flops, calls, pairs = (sum(w[i] for w in WORK.values()) for i in range(3)) if work is None else work
    per_step_s = (flops / (rates["gflops"] * 1e9) + calls * rates["ns_per_call"] * 1e-9
                  + pairs * rates["ns_per_pair"] * 1e-9)
    return {"flops_per_step": flops, "calls_per_step": calls, "pairs_per_step": pairs,
            "us_per_cell_step": per_step_s * 1e6, "cells_per_s_core": 1.0 / (per_step_s * steps)}


def sweep_child(n_cells: int, jobs: int) -> dict[str, Any]:
    """The 1000-cell sweep (:data:`DELAYS` x :data:`LOSSES` x 10 seeds, the 30 s sine) flown by
    ``fly_batch(..., jobs=jobs)`` in a fresh process (this script with ``--child CELLS JOBS``): its wall
    and CPU time around the flight alone (imports and numba's cache loaded before the clock starts), its
    peak resident memory (the whole process: what a ``bsst sweep --engine batch`` of these cells needs)
    and a digest of the rows."""
    out = subprocess.run([sys.executable, __file__, "--child", str(n_cells), str(jobs)], capture_output=True,
                         text=True, check=True, cwd=ROOT)
    return json.loads(out.stdout.strip().splitlines()[-1])


def _child(n_cells: int, jobs: int) -> None:
    sine = load_mission(ROOT / "missions" / "sine.toml")
    over = [cell_overrides(c) for c in cells(sine, Grid(delay_ms=DELAYS, loss_pct=LOSSES, seeds=10))[:n_cells]]
    fly_batch(sine.with_overrides(duration_s=0.2), over[:4], jobs=jobs)  # kernels compiled or loaded first
    load = os.getloadavg()[0]
    t0, c0 = time.perf_counter(), time.process_time()
    rows = fly_batch(sine, over, jobs=jobs)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    digest = hashlib.sha256(json.dumps(rows, sort_keys=True, default=str).encode()).hexdigest()[:16]
    print(json.dumps({"wall_s": wall, "cpu_s": cpu, "cells_per_s": n_cells / wall, "cells_per_cpu_s": n_cells / cpu,
                      "peak_rss_mib": peak_rss_mib(), "digest": digest, "load": max(load, os.getloadavg()[0])}))


def ceiling_figures(n_cells: int, rounds: int = 2) -> dict[str, Any]:
    """Issue 25's figures (see the module doc), interleaved: each round measures the machine's rates and
    the cores this process gets, then flies the sweep with --jobs 1 and --jobs 2 (alternating which goes
    first); the best round of each is kept, and each round's own ratio beside it."""
    sine = load_mission(ROOT / "missions" / "sine.toml")
    load_before = os.getloadavg()
    sweep_child(8, 1)  # numba's cache filled (compiled once after a checkout) before anything is timed
    runs: dict[int, list[dict[str, Any]]] = {1: [], 2: []}
    rates, cores = [], []
    for r in range(rounds):
        cores.append(cores_available())
        rates.append(machine_rates(3))
        for j in ((1, 2) if r % 2 == 0 else (2, 1)):
            runs[j].append(sweep_child(n_cells, j))
    cores.append(cores_available())
    best_rates = {"gflops": max(x["gflops"] for x in rates), "ns_per_call": min(x["ns_per_call"] for x in rates),
                  "ns_per_pair": min(x["ns_per_pair"] for x in rates)}
    top = ceiling(best_rates, sine.steps)
    one, two = (min(runs[j], key=lambda x: x["wall_s"]) for j in (1, 2))
    out = {"rates": rates, "best_rates": best_rates, "ceiling": top, "runs": runs, "one": one, "two": two,
           "cpus": os.cpu_count(), "issue_ceiling": ceiling(best_rates, sine.steps, ISSUE_WORK), "cores": cores,
           "load_before": load_before, "load_after": os.getloadavg(),
           "fraction_2_cores": two["cells_per_s"] / (2 * top["cells_per_s_core"]),
           "fraction_cpu": max(x["cells_per_cpu_s"] for x in runs[1] + runs[2]) / top["cells_per_s_core"],
           "speedup": one["wall_s"] / two["wall_s"],
           "round_speedups": [a["wall_s"] / b["wall_s"] for a, b in zip(runs[1], runs[2], strict=True)],
           "same_rows": len({x["digest"] for x in runs[1] + runs[2]}) == 1,
           "peak_rss_mib": max(x["peak_rss_mib"] for x in runs[1] + runs[2])}
    out["ok"] = (out["fraction_2_cores"] >= TARGET_CEILING and out["speedup"] >= TARGET_SPEEDUP
                 and out["same_rows"] and out["peak_rss_mib"] <= LIMIT_GIB * 1024)
    return out


def print_ceiling(out: dict[str, Any]) -> None:
    """The figures of :func:`ceiling_figures`, one line each, then PASS or FAIL."""
    lb, la, r, top = out["load_before"], out["load_after"], out["best_rates"], out["ceiling"]
    issue = out["issue_ceiling"]["cells_per_s_core"]
    print(f"load average before {lb[0]:.2f} {lb[1]:.2f} {lb[2]:.2f}, after {la[0]:.2f} {la[1]:.2f} {la[2]:.2f} "
          f"({out['cpus']} cpus)")
    print("cores this process gets (2 compiled threads' CPU-s per wall-s), before each round and after: "
          + ", ".join(f"{c:.2f}" for c in out["cores"]) + " (--jobs 2 can be at most that much faster than --jobs 1)")
    print(f"machine (thread CPU time, best of the rounds): multiply-add {r['gflops']:.2f} GFLOP/s a core, libm "
          f"sin/cos {r['ns_per_call']:.2f} ns a call, a sin-cos pair {r['ns_per_pair']:.2f} ns (each round: "
          + ", ".join(f"{x['gflops']:.2f}/{x['ns_per_call']:.2f}/{x['ns_per_pair']:.2f}" for x in out["rates"]) + ")")
    print(f"work per cell-step: {top['flops_per_step']} flops + {top['calls_per_step']} libm calls + "
          f"{top['pairs_per_step']} sin-cos pairs = "
          f"{top['us_per_cell_step']:.3f} us at best: ceiling {top['cells_per_s_core']:.0f} cells/s a core, "
          f"{2 * top['cells_per_s_core']:.0f} on 2 (with issue 25's count, {ISSUE_WORK[0]} flops + {ISSUE_WORK[1]} "
          f"calls, no plant trig: {out['issue_ceiling']['cells_per_s_core']:.0f} a core)")
    for j in (1, 2):
        for i, f in enumerate(out["runs"][j]):
            print(f"--jobs {j} round {i + 1}: {f['wall_s']:.1f} s wall, {f['cpu_s']:.1f} s CPU: {f['cells_per_s']:.1f} "
                  f"cells/s, {f['cells_per_cpu_s']:.1f} cells per CPU-s, peak {f['peak_rss_mib']:.0f} MiB "
                  f"(load {f['load']:.2f})")
    print(f"--jobs 2 against --jobs 1: {out['speedup']:.2f}x best against best (target >= {TARGET_SPEEDUP}; each "
          f"round: {', '.join(f'{v:.2f}x' for v in out['round_speedups'])}); rows identical: {out['same_rows']}; "
          f"peak memory {out['peak_rss_mib']:.0f} MiB (limit {LIMIT_GIB * 1024:.0f})")
    print(f"fraction of the 2-core ceiling: {100 * out['fraction_2_cores']:.0f} % in wall time (target >= "
          f"{100 * TARGET_CEILING:.0f} %); per CPU-second, of one core's: {100 * out['fraction_cpu']:.0f} % "
          f"(issue 25's count: {100 * out['fraction_cpu'] * top['cells_per_s_core'] / issue:.0f} %)")
    print("PASS" if out["ok"] else "FAIL")


def peak_rss_mib() -> float:
    """Peak resident memory of this process so far, MiB (Linux reports KiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def batch_sweep(mission: Any, n_cells: int) -> dict[str, Any]:
    grid = Grid(delay_ms=DELAYS, loss_pct=LOSSES, seeds=10)
    todo = cells(mission, grid)[:n_cells]
    t0, c0 = time.perf_counter(), time.process_time()
    rows = fly_batch(mission, [cell_overrides(c) for c in todo])
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    outcomes: dict[str, int] = {}
    for r in rows:
        outcomes[r["outcome"]] = outcomes.get(r["outcome"], 0) + 1
    return {"cells": len(rows), "wall_s": wall, "cells_per_s": len(rows) / wall, "peak_rss_mib": peak_rss_mib(),
            "outcomes": outcomes, "cpu_s": cpu, "cells_per_cpu_s": len(rows) / cpu}


def process_sweep(mission: Any) -> dict[str, Any]:
    t0 = time.perf_counter()
    rows = sweep(mission, SUBSET, jobs=2, report=False, plots=False, engine="process")  # auto would take the batch
    wall = time.perf_counter() - t0
    # the scalar loop a worker runs per cell, timed in this process's CPU (the workers' is not visible here:
    # they are the forkserver's children): what the process engine could do on two idle cores at best
    c0 = time.process_time()
    probe = cells(mission, SUBSET)[:SCALAR_PROBE]
    for c in probe:
        fly(prepare(mission, cell_overrides(c)), plots=False)
    per_cell = (time.process_time() - c0) / len(probe)
    return {"cells": len(rows), "wall_s": wall, "cells_per_s": len(rows) / wall, "scalar_cpu_s_per_cell": per_cell}


def step_parts_ms(mission: Any, n: int, repeats: int) -> dict[str, float]:
    """Median CPU time (ms, this thread's) of one control step for n cells of a 6 s stretch of the mission on
    the grid's links, flown by the flight's kernel on one thread: the whole step, the step with the law
    left out (every cell idle: the plant's physics steps, the wire, the figures), and planning the link
    traffic, per control step."""
    short = replace(mission, duration_s=6.0)
    fl = [prepare(short, seed=i, link={"delay_ms": DELAYS[i % 10], "loss_pct": LOSSES[i // 10 % 10]})
          for i in range(n)]
    clocks = Clocks(short.rate_hz, short.physics_hz, fl[0].substeps, short.steps)
    whole, idle, plan_ms = [], [], []
    for _ in range(repeats):
        t0 = time.thread_time()
        plan = plan_links([x.link for x in fl], [x.guard for x in fl], fl[0].failsafe.timeout_s, clocks)
        plan_ms.append((time.thread_time() - t0) / short.steps * 1e3)
        for out, law in ((whole, True), (idle, False)):
            refs = _references(short, clocks.step_t)
            c, a = batch_arrays(fl, plan, clocks, refs, lambda lag: _references(short, clocks.step_t + lag))
            if not law:
                a.mode.fill(NONE)
            fly_cells(0, 1, 0, 1, c, a)  # compiled or loaded before the clock starts
            t0 = time.thread_time()
            fly_cells(0, n, 0, short.steps, c, a)
            out.append((time.thread_time() - t0) / short.steps * 1e3)
    return {"step_ms": statistics.median(whole), "idle_ms": statistics.median(idle),
            "plan_ms": statistics.median(plan_ms)}


def predict_cells(mission: Any) -> dict[str, Any]:
    """The batch with prediction: 1 cell at 57 ms, then 100 cells at 0-57 ms; the scalar loop's CPU per cell."""
    one = [{"link": {"delay_ms": 57.0, "compensation": "predict"}}]
    many = [{"link": {"delay_ms": 57.0 * i / 99, "compensation": "predict"}} for i in range(100)]
    out: dict[str, Any] = {}
    for name, over in (("one", one), ("hundred", many)):
        t0 = time.process_time()
        fly_batch(mission, over)
        out[f"{name}_cpu_s"] = time.process_time() - t0
    c0 = time.process_time()
    fly(prepare(mission, **one[0]), plots=False)
    out["scalar_cpu_s_per_cell"] = time.process_time() - c0
    out["ratio_hundred"] = out["scalar_cpu_s_per_cell"] * 100 / out["hundred_cpu_s"]
    return out


def acceptance(mission: Any, n_cells: int = 1000, repeats: int = 3) -> dict[str, Any]:
    """Issue 13's acceptance figures, measured in this process now (see the module doc)."""
    load_before = os.getloadavg()
    batch = batch_sweep(mission, n_cells)  # first: the peak memory is this process's before anything else
    process = process_sweep(mission)
    parts = step_parts_ms(mission, 1000, repeats) if repeats else None
    predict = predict_cells(mission)
    load_after = os.getloadavg()
    ratio = batch["cells_per_s"] / process["cells_per_s"]
    # the same comparison in CPU time, which other load on the machine does not move: the batch's cells per
    # CPU second against two cores' worth of the scalar loop (pool overhead left out: in the process's favour)
    ratio_cpu = batch["cells_per_cpu_s"] * process["scalar_cpu_s_per_cell"] / 2.0
    ok = ratio >= TARGET_RATIO and batch["peak_rss_mib"] <= LIMIT_GIB * 1024
    return {"batch": batch, "process": process, "ratio": ratio, "ratio_cpu": ratio_cpu, "step_parts_n1000": parts,
            "predict": predict,
            "load_before": load_before, "load_after": load_after, "cpus": os.cpu_count(), "ok": ok}


def print_acceptance(out: dict[str, Any]) -> None:
    """The figures of :func:`acceptance`, one line each, then PASS or FAIL."""
    lb, la = out["load_before"], out["load_after"]
    batch, process, parts = out["batch"], out["process"], out["step_parts_n1000"]
    print(f"load average before {lb[0]:.2f} {lb[1]:.2f} {lb[2]:.2f}, "
          f"after {la[0]:.2f} {la[1]:.2f} {la[2]:.2f} ({out['cpus']} cpus)")
    print(f"batch:   {batch['cells']} cells of the 30 s sine in {batch['wall_s']:.1f} s = "
          f"{batch['cells_per_s']:.1f} cells/s, peak memory {batch['peak_rss_mib']:.0f} MiB "
          f"(limit {LIMIT_GIB * 1024:.0f}), outcomes {batch['outcomes']}")
    print(f"process: {process['cells']} cells with --engine process --jobs 2 in {process['wall_s']:.1f} s = "
          f"{process['cells_per_s']:.2f} cells/s")
    print(f"ratio:   {out['ratio']:.1f}x (target >= {TARGET_RATIO:g}x)")
    print(f"in CPU time: batch {batch['cells_per_cpu_s']:.1f} cells per CPU-s ({batch['cpu_s']:.1f} s), scalar loop "
          f"{process['scalar_cpu_s_per_cell']:.2f} CPU-s per cell: {out['ratio_cpu']:.1f}x two idle cores of it "
          f"(not moved by other load)")
    if parts:
        print(f"one control step at N=1000 (median, CPU): {parts['step_ms']:.2f} ms, of which plant, wire and "
              f"figures {parts['idle_ms']:.2f} ms, law and actuation {parts['step_ms'] - parts['idle_ms']:.2f} ms; "
              f"link plan {parts['plan_ms']:.3f} ms")
    pr = out["predict"]
    print(f"with prediction (CPU time): 1 cell at 57 ms {pr['one_cpu_s']:.2f} s, 100 cells at 0-57 ms "
          f"{pr['hundred_cpu_s']:.1f} s; the scalar loop {pr['scalar_cpu_s_per_cell']:.2f} s a cell: "
          f"{pr['ratio_hundred']:.1f}x")
    print("PASS" if out["ok"] else "FAIL")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=3, help="repeats of the per-step figures (median)")
    ap.add_argument("--cells", type=int, default=1000, help="cells of the batch sweep (default 1000)")
    ap.add_argument("--json", action="store_true", help="print the figures as JSON")
    ap.add_argument("--rounds", type=int, default=2, help="rounds of the ceiling, --jobs 1 and --jobs 2 (default 2)")
    ap.add_argument("--ceiling-only", action="store_true",
                    help="only issue 25's figures: the ceiling, --jobs 1 and 2 (not the process engine's)")
    ap.add_argument("--child", type=int, nargs=2, metavar=("CELLS", "JOBS"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        _child(*args.child)
        return 0
    sine = load_mission(ROOT / "missions" / "sine.toml")
    out = {"ceiling": ceiling_figures(args.cells, args.rounds)}
    if not args.ceiling_only:
        out["acceptance"] = acceptance(sine, args.cells, args.repeats)
    if args.json:
        print(json.dumps(out, indent=2, default=str))
    else:
        print_ceiling(out["ceiling"])
        if "acceptance" in out:
            print_acceptance(out["acceptance"])
    return 0 if all(v["ok"] for v in out.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
