"""Several vehicles in one world, offline (issue 28): the figures of its acceptance list that ``bsst sim`` can give.

- four in a line: ``bsst sim missions/sine.toml --vehicles 4 --formation line:2``: each vehicle's 3-D RMS
  (target <= 1e-4 m, as the single vehicle), every pair's closest approach between rotor discs (m), the
  separation policy (must hold), the exit status (0);
- a near miss: ``bsst sim examples/swarm-near-miss.toml`` (paths 0.9 m apart): the closest approach (under the
  0.5 m minimum), the policy (broken), the exit status (1);
- a touch: ``bsst sim examples/swarm-touch.toml`` (paths 0.4 m apart): each vehicle's outcome (``collision``),
  the exit status (1);
- speed: the wall time of one vehicle's sine and of the four, in the same process, interleaved, their ratio
  (4 vehicles' steps cost about 4 single ones: the loop adds only the separation check), and the real-time
  factor of the four; with the load average, since other work on the machine slows every figure alike.

Each run goes through ``bridge.cli.main`` (the command's own exit status), into a temporary directory.

    .venv/bin/python benchmarks/swarm.py [--repeats 3] [--json]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from bridge.cli import main  # noqa: E402

TARGET_RMS_M = 1e-4


def bsst_sim(*args: str) -> tuple[int, dict[str, Any], float]:
    """Run ``bsst sim ARGS --no-plots`` into a fresh directory: exit status, summary.json, wall seconds."""
    with tempfile.TemporaryDirectory() as d:
        out = Path(d) / "run"
        t0 = time.perf_counter()
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            code = main(["sim", *args, "--out", str(out), "--no-plots"])
        wall = time.perf_counter() - t0
        return code, json.loads((out / "summary.json").read_text()), wall


def figures(repeats: int) -> dict[str, Any]:
    os.chdir(ROOT)
    line_code, line, _ = bsst_sim("missions/sine.toml", "--vehicles", "4", "--formation", "line:2")
    near_code, near, _ = bsst_sim("examples/swarm-near-miss.toml")
    touch_code, touch, _ = bsst_sim("examples/swarm-touch.toml")
    one_s, four_s = [], []
    for _ in range(repeats):  # interleaved: both see the same load
        one_s.append(bsst_sim("missions/sine.toml")[2])
        four_s.append(bsst_sim("missions/sine.toml", "--vehicles", "4", "--formation", "line:2")[2])
    one, four = statistics.median(one_s), statistics.median(four_s)
    return {
        "line": {"exit": line_code, "outcome": line["outcome"],
                 "rms_3d": {v["id"]: v["rms_3d"] for v in line["vehicles"]},
                 "closest_m": {f"{p['ids'][0]}-{p['ids'][1]}": p["closest_m"] for p in line["separation"]["pairs"]},
                 "separation_ok": line["policies"][0]["ok"]},
        "near_miss": {"exit": near_code, "closest_m": near["separation"]["closest_m"],
                      "separation_ok": near["policies"][0]["ok"], "outcomes": [v["outcome"] for v in near["vehicles"]]},
        "touch": {"exit": touch_code, "closest_m": touch["separation"]["closest_m"],
                  "outcomes": [v["outcome"] for v in touch["vehicles"]]},
        "speed": {"one_vehicle_s": one, "four_vehicles_s": four, "ratio": four / one,
                  "four_real_time_factor": line["duration_s"] / four, "repeats": repeats},
        "loadavg": os.getloadavg(),
    }


def main_() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    f = figures(a.repeats)
    if a.json:
        print(json.dumps(f, indent=2))
        return 0
    ln, nm, tc, sp = f["line"], f["near_miss"], f["touch"], f["speed"]
    print("bsst sim missions/sine.toml --vehicles 4 --formation line:2")
    for i, r in ln["rms_3d"].items():
        print(f"  vehicle {i}: 3-D RMS {r:.3e} m ({'<=' if r <= TARGET_RMS_M else '>'} {TARGET_RMS_M:g} m)")
    print("  closest approach between rotor discs: " + ", ".join(f"{k} {v:.3f} m" for k, v in ln["closest_m"].items()))
    print(f"  separation policy {'holds' if ln['separation_ok'] else 'BROKEN'}; outcome {ln['outcome']}; "
          f"exit {ln['exit']} (want 0)")
    print(f"bsst sim examples/swarm-near-miss.toml: closest {nm['closest_m']:.3f} m, separation policy "
          f"{'holds' if nm['separation_ok'] else 'broken'}, outcomes {nm['outcomes']}, exit {nm['exit']} (want 1)")
    print(f"bsst sim examples/swarm-touch.toml: closest {tc['closest_m']:.3f} m, outcomes {tc['outcomes']}, "
          f"exit {tc['exit']} (want 1)")
    print(f"speed (median of {sp['repeats']}, interleaved): one vehicle {sp['one_vehicle_s']:.2f} s, four "
          f"{sp['four_vehicles_s']:.2f} s, ratio {sp['ratio']:.2f}; four fly {sp['four_real_time_factor']:.1f}x "
          "real time")
    print("load average: " + " ".join(f"{x:.2f}" for x in f["loadavg"]))
    return 0


if __name__ == "__main__":
    sys.exit(main_())
