"""A sweep's report: a class per cell, a table per pair of swept parameters, heat maps.

In:  a sweep directory's ``cells.csv`` rows (``rms`` m, ``ripple_u2`` N, ``outcome``, the axes' values
     in Hz, ms, %, packets, estimator kinds, noise scales) and its ``sweep.json`` (thresholds, axes)
Out: ``report.md`` (thresholds, an overview per law, a table per pair of swept axes, the failed cells,
     a command that reflies a row) and the heat maps ``map_<a>_<b>.png`` (median RMS m on each law's own log
     colour scale, class per cell)

``report.md`` and ``map_<param>_<param>.png`` are rebuilt from ``cells.csv`` (and the
``sweep.json`` beside it, for the thresholds and the axes) by ``bsst report DIR``.

Classes, worst first (a grid point flown with several seeds shows its worst class):

- ``error``: the cell could not be flown (its ``error`` column says why);
- ``crashed``: the flight ended on the ground or against another vehicle (outcome ``crashed``, ``collision``,
  ``terminated``);
- ``diverged``: the plant's divergence check tripped, or the 3-D RMS error exceeds
  ``diverged_rms_m``;
- ``failsafe``: the vehicle's failsafe took over (no valid command for its timeout);
- ``limit-cycling``: the ripple of u2 (its RMS about a 0.2 s moving average over the second
  half of the flight, N) exceeds ``ripple_u2``: the attitude loop oscillates;
- ``degraded``: the 3-D RMS error exceeds ``clean_rms_m``;
- ``clean``: none of these.
"""

from __future__ import annotations

import hashlib
import math
import statistics
from collections.abc import Mapping, Sequence
from itertools import combinations
from pathlib import Path
from typing import Any

from bridge.autopilot.estimator import ESTIMATOR_KINDS
from bridge.record.mplsetup import pyplot
from bridge.record.runlog import check_replaceable
from bridge.sweep.cells import (
    CELLS_CSV,
    FAILED,
    POLICIES_OK,
    SWEEP_JSON,
    UNRECORDED,
    broke_policy,
    grid_values,
    read_cells,
    read_sweep_json,
    seeds_alike,
)
from bridge.sweep.classes import CLASSES, Classes, classify, thresholds_text
from bridge.sweep.grid import AXES, FLEET_FORMATION, LINK_AXES, NAME_AXES, NO_SCHEME, SHORT, grid_size
from controller.law import discretization_problem
from params import ConfigError, unreachable
from plant.wind import TURBULENCE

NUMERIC_AXES = tuple(a for a in AXES if a not in NAME_AXES)
# what a sweep without a discretization column flew: it was written before issue 24, when bsst knew only the
# paper's explicit step (not missions.DEFAULT_DISCRETIZATION, which is what a new mission flies)
LEGACY_DISCRETIZATION = "explicit"
# the axes a table (and a heat map) may have: the numbers, the estimator kind, the turbulence (a few names, like a law;
# the laws get a table each instead)
MAP_AXES = tuple(a for a in AXES if a != "controller")
UNITS = {"rate_hz": "Hz", "delay_ms": "ms", "jitter_ms": "ms", "loss_pct": "%", "burst_len": "packets",
         "noise": "x sigma", "wind_mps": "m/s"}



class Point:
    """The runs sharing a pair of values: worst class (with how many runs share it), median RMS."""

    def __init__(self, rows: Sequence[Mapping[str, Any]], classes: Classes) -> None:
        cls = [classify(r, classes) for r in rows]
        self.worst = max(cls, key=CLASSES.index)
        self.count = cls.count(self.worst)
        self.n = len(rows)
        rms = [r["rms"] for r in rows if r.get("rms") is not None and math.isfinite(r["rms"])]
        self.rms = statistics.median(rms) if rms else None

    def text(self, sep: str = " ") -> str:
        share = f" {self.count}/{self.n}" if self.count != self.n else ""
        rms = f"{self.rms:.2g}" if self.rms is not None else "n/a"
        return f"{self.worst}{share}{sep}{rms}"


def _values(rows: Sequence[Mapping[str, Any]], axis: str) -> list[Any]:
    # names in their kind's order, the baseline first: estimator truth, ekf, raw; turbulence none to severe
    order = {"estimator": ESTIMATOR_KINDS, "turbulence": TURBULENCE}.get(axis)
    if order is not None:
        return sorted({r[axis] for r in rows}, key=lambda k: (order.index(k) if k in order else len(order), k))
    return sorted({r[axis] for r in rows})


def _fmt(v: Any) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v)


def pairs(rows: Sequence[Mapping[str, Any]], swept: Sequence[str]) -> list[tuple[str, str]]:
    """The parameter pairs to tabulate: every pair of swept axes with more than one value (numbers, and
    the estimator kind); with one such axis, that axis against a fixed one (a one-column map)."""
    varied = [a for a in MAP_AXES if a in swept and len(_values(rows, a)) > 1]
    if len(varied) >= 2:
        return list(combinations(varied, 2))
    if len(varied) == 1:
        other = next(a for a in ("loss_pct", "delay_ms", *NUMERIC_AXES) if a != varied[0])
        return [(varied[0], other)]
    return []


def _schemeless(rows: Sequence[Mapping[str, Any]]) -> str:
    """What the ``discretization`` line adds for the laws flown without a scheme (an empty ``discretization``:
    no super-twisting step, one cell per point): their names; nothing when there are none."""
    laws = _values([r for r in rows if r["discretization"] == NO_SCHEME], "controller")
    return f"none for {', '.join(laws)} (no super-twisting step: one cell per point)" if laws else ""


def _label(axis: str) -> str:
    """An axis with its unit, for a heat map's axis."""
    return f"{axis} [{UNITS[axis]}]" if axis in UNITS else axis


def legacy_values(meta: Mapping[str, Any]) -> dict[str, Any]:
    """What an older sweep's cells flew on the vehicle's and the air's axes and the discretization (its
    ``cells.csv`` has no such columns): its mission's ``[estimator] kind``, ``[sensors] noise_scale``, ``[wind]
    speed_mps`` and ``turbulence``, ``discretization``, else their defaults (:data:`LEGACY_DISCRETIZATION`, the
    only scheme before issue 24); one vehicle (before issue 28), so no worst vehicle and no closest approach; its
    policies not judged and its jitter caps not said (``""``: before the columns)."""
    mission = meta.get("mission") if isinstance(meta.get("mission"), Mapping) else {}
    est, sensors, wind = (t if isinstance(t := mission.get(k), Mapping) else {}
                          for k in ("estimator", "sensors", "wind"))
    kind, scale = est.get("kind", "truth"), sensors.get("noise_scale", 1.0)
    speed, level = wind.get("speed_mps", 0.0), wind.get("turbulence", "none")
    d = mission.get("discretization", LEGACY_DISCRETIZATION)
    return {"estimator": kind if isinstance(kind, str) else "truth", "noise": _number(scale, 1.0),
            "wind_mps": _number(speed, 0.0), "turbulence": level if isinstance(level, str) else "none",
            "discretization": d if isinstance(d, str) else LEGACY_DISCRETIZATION, "vehicles": 1, "worst_vehicle": None,
            "closest_m": None, "policies": "", "jitter_capped": ""}


def _number(v: Any, default: float) -> float:
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else default


def grid_points(rows: Sequence[Mapping[str, Any]], a: str, b: str, classes: Classes) -> dict[tuple[Any, Any], Point]:
    groups: dict[tuple[Any, Any], list[Mapping[str, Any]]] = {}
    for r in rows:
        groups.setdefault((r[a], r[b]), []).append(r)
    return {k: Point(v, classes) for k, v in groups.items()}


def load_sweep_dir(path: str | Path) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """``cells.csv`` and ``sweep.json`` of a sweep directory (the latter inferred if absent)."""
    p = Path(path)
    why = unreachable(p)
    if why:
        raise ConfigError(f"{p}: cannot read ({why})")
    if not p.is_dir():
        raise ConfigError(f"{p}: {'not a directory' if p.exists() else 'no such directory'} (give a sweep's "
                          "directory: bsst sweep ... --out DIR)")
    meta_path = p / SWEEP_JSON
    if not meta_path.exists() and not (p / CELLS_CSV).exists():
        from bridge.sweep.margin import MARGIN_JSON  # lazy: only where a directory is not a sweep's

        if (p / MARGIN_JSON).is_file():  # its whole record is margin.json (interrupted or not, it says)
            raise ConfigError(f"{p}: a `bsst margin` directory ({MARGIN_JSON}, its whole record, "
                              f"\"interrupted\" saying whether its search ended); bsst report rebuilds a sweep's "
                              f"report from its {CELLS_CSV}")
        if (p / "summary.json").is_file():  # a run's directory (bsst sim / sitl --out): said, not "no cells.csv"
            raise ConfigError(f"{p}: a run's directory (its summary.json), not a sweep's: bsst report rebuilds a "
                              f"sweep's report from its {CELLS_CSV}; a run's summary is printed by the run")
    meta = read_sweep_json(meta_path) if meta_path.exists() else {}
    rows = read_cells(p / CELLS_CSV, legacy=legacy_values(meta), meta=meta)  # an older sweep's cells.csv is read too
    if not meta:
        meta = {"mission": {"name": p.name}, "mode": "?", "swept": [a for a in AXES if len(_values(rows, a)) > 1],
                "classes": {}}
    return rows, meta


def rebuild(path: str | Path, plots: bool = True) -> Path:
    """``bsst report DIR``: write ``report.md`` and the heat maps again from ``cells.csv``."""
    rows, meta = load_sweep_dir(path)
    if not rows:
        raise ConfigError(f"{Path(path) / CELLS_CSV}: no rows")
    check_report_files(Path(path), plots, said=str(path), fix="move it away")
    return write_report(Path(path), rows, meta, plots=plots)


REPORT_MD, REPORT_TMP = "report.md", ".report.md.tmp"


def check_report_files(path: Path, plots: bool, said: str | None = None, fix: str | None = None) -> None:
    """Refuse, before anything is written, a report in sweep directory ``path`` whose ``report.md`` (or its temporary
    name, or with ``plots`` a heat map's ``map_*.png``) is taken by what no report wrote, a directory say: the check
    of ``--overwrite`` (:func:`~bridge.record.runlog.check_replaceable`; ``said`` and ``fix`` its words)."""
    taken = [p for p in sorted(path.iterdir()) if p.name in (REPORT_MD, REPORT_TMP) or (plots and p.match("map_*.png"))]
    check_replaceable(path, taken, said, fix)


def recorded_cell_count(meta: Mapping[str, Any]) -> int | None:
    """How many cells the sweep's grid has, as its ``sweep.json`` records the axes and seeds (None where it does not
    say), by the one counting rule (:func:`bridge.sweep.grid.grid_size`)."""
    grid = grid_values(meta)
    return None if grid is None else grid_size(grid)


def incomplete(path: Path, rows: Sequence[Any], meta: Mapping[str, Any]) -> str | None:
    """Why a sweep directory's rows are not its whole grid (``N of M cells flown; ...``), or None."""
    total = recorded_cell_count(meta)
    if total is None or len(rows) >= total:
        return None
    return (f"{len(rows)} of {total} cells flown; the sweep was interrupted: `bsst sweep … --resume --out {path}` "
            "(its own arguments) finishes it")


def engines_note(meta: Mapping[str, Any]) -> list[str]:
    """Which engine flew the rows (sweep.json's ``engines``; two: mixed, a resume flew some on the other)."""
    engines = meta.get("engines") or []
    if UNRECORDED in engines:
        flew = [f"`{e}`" for e in engines if e != UNRECORDED]
        return [f"- engines: not recorded for the rows kept from an older bsst's sweep; {' and '.join(flew) or 'none'} "
                "flew the others"]
    if len(engines) == 1:
        return [f"- engine: `{engines[0]}` flew every row"]
    if len(engines) > 1:
        return [f"- engines: MIXED, rows flown by {' and '.join(f'`{e}`' for e in engines)} (a resume flew the "
                "missing cells on another engine; their rows agree within 1e-6, smc 1 %, not to the bit)"]
    return []


def _seeds_note(rows: Sequence[Mapping[str, Any]], meta: Mapping[str, Any]) -> list[str]:
    """What the seeds drew: each its own start ([start] scatter_m), or, where every grid point's seeds flew the same
    flight (a mission that draws nothing at random), that they added nothing."""
    scatter = (meta.get("mission", {}).get("start") or {}).get("scatter_m")
    if scatter:
        return [f"- start: each seed's own, within {_fmt(scatter)} m of the mission's (`[start] scatter_m`)"]
    if seeds_alike(rows, lambda r: tuple(r[a] for a in AXES)):
        return ["- the seeds of every grid point flew the same flight (the mission draws nothing at random): they "
                "added nothing; `--scatter M` starts each at its own point (docs/campaigns.md)"]
    return []


def write_report(path: Path, rows: Sequence[Mapping[str, Any]], meta: Mapping[str, Any], plots: bool = True) -> Path:
    """Write ``report.md`` (and the ``map_*.png`` heat maps) into the sweep directory."""
    try:
        classes = Classes(**meta.get("classes", {}))
    except (TypeError, ConfigError) as exc:
        raise ConfigError(f"{path / SWEEP_JSON}: classes: {exc}") from None
    swept = list(meta.get("swept") or [a for a in AXES if len(_values(rows, a)) > 1])
    controllers = _values(rows, "controller")
    prs = pairs(rows, swept)
    mission = meta.get("mission", {}).get("name", "?")
    seeds = _values(rows, "seed")
    lines = [f"# Sweep report: {mission}", ""]
    short = incomplete(path, rows, meta)
    if short:
        lines += [f"**Incomplete: {short}.** The tables below hold only the cells flown so far.", ""]
    lines.append(f"Mode `{meta.get('mode', '?')}`, {len(rows)} runs: controllers {', '.join(controllers)}; "
                 f"seeds {', '.join(map(str, seeds))}.")
    lines += engines_note(meta)
    lines += _seeds_note(rows, meta)
    for a in MAP_AXES:
        vals = [v for v in _values(rows, a) if a != "discretization" or v != NO_SCHEME]
        unit = f" {UNITS[a]}" if a in UNITS else ""
        said = ", ".join(_fmt(v) for v in vals) + unit + (" (swept)" if a in swept and vals else "")
        lines.append(f"- `{a}`: " + "; ".join(filter(None, (said, _schemeless(rows) if a == "discretization" else ""))))
    if any(r["estimator"] != "truth" for r in rows):
        lines += [f"- sensor set: `{sensor_set(meta)}` (the noise scale multiplies each of its sigmas; the "
                  "estimator `truth` flies the true state and ignores them)"]
    lines += ["", "Delay, jitter, loss and burst length apply to both link directions "
              "(up: controller -> vehicle, down: vehicle -> controller).", ""]
    lines += ["## Classes", ""] + thresholds_text(classes)
    lines += ["", "A table cell gathers every run with its two values (all seeds, and every value of the "
              "parameters not in the table): it shows the worst class (with how many runs have it, when not all) "
              "and the median 3-D RMS position error (m, over the summary's RMS window).", ""]
    lines += ["## Overview", "", "| controller | runs | " + " | ".join(CLASSES) + " | median RMS (m) |",
              "|---|---:|" + "---:|" * len(CLASSES) + "---:|"]
    schemes = _values(rows, "discretization")
    for c, d in ((c, d) for c in controllers for d in schemes):  # a row per law and discretization flown
        mine = [r for r in rows if r["controller"] == c and r["discretization"] == d]
        if not mine:
            continue
        p = Point(mine, classes)
        counts = [sum(1 for r in mine if classify(r, classes) == k) for k in CLASSES]
        med = f"{p.rms:.3g}" if p.rms is not None else "n/a"
        named = len(schemes) - (NO_SCHEME in schemes) > 1  # (a law without a scheme: its name alone)
        name = f"{c} ({d})" if named and d != NO_SCHEME else c
        lines.append(f"| {name} | {len(mine)} | " + " | ".join(map(str, counts)) + f" | {med} |")
    maps: list[Path] = []
    files = controller_files(controllers)
    for a, b in prs:
        name = f"map_{SHORT[a]}_{SHORT[b]}"
        title = pair_title(rows, a, b)
        lines += ["", f"## {title}", ""]
        if len(controllers) > 1:
            lines += [f"![{title}, all controllers]({name}.png)", ""]
        for c in controllers:
            mine = [r for r in rows if r["controller"] == c]
            pts = grid_points(mine, a, b, classes)
            av, bv = _values(mine, a), _values(mine, b)
            lines += [f"### {c}", "", f"| {a} \\ {b} | " + " | ".join(_fmt(v) for v in bv) + " |",
                      "|---|" + "---|" * len(bv)]
            for x in av:
                lines.append(f"| {_fmt(x)} | " + " | ".join(pts[(x, y)].text() if (x, y) in pts else "-" for y in bv)
                             + " |")
            fname = f"{name}_{files[c]}.png" if len(controllers) > 1 else f"{name}.png"
            lines += ["", f"![{c}: {title}]({fname})", ""]
        if plots:
            maps += heat_maps(path, rows, a, b, controllers, classes)
    failed = [r for r in rows if r["outcome"] in FAILED]  # (error, law_failed, denied: each row says why)
    if failed:
        lines += ["", "## Cells that could not be flown", "", "| controller | " + " | ".join(MAP_AXES)
                  + " | seed | error |", "|---" * (len(MAP_AXES) + 3) + "|"]
        for r in failed[:50]:
            lines.append(f"| {r['controller']} | " + " | ".join(_fmt(r[a]) for a in MAP_AXES)
                         + f" | {r['seed']} | {r['error']} |")
    lines += policies_section(rows)
    lines += jitter_section(rows)
    if rows:  # (none: a sweep of no cells, or a report of an empty cells.csv)
        lines += ["", "## Reproducing a row", "",
                  "Each row of `cells.csv` is one offline flight of `mission.toml` (in this directory); for example "
                  "the first one:", "", "```sh", reproduce(rows[0], swept, mission_wind_from(meta)), "```", ""]
    out = path / REPORT_MD
    tmp = path / REPORT_TMP
    tmp.write_text("\n".join(lines), encoding="utf-8")
    tmp.replace(out)
    return out


def policies_section(rows: Sequence[Mapping[str, Any]]) -> list[str]:
    """``report.md``'s policies: how many runs kept every safety policy (bridge.record.policies), which broke one
    (each, up to 50: its cell and the names), how many were not judged (the batch engine, a cell not flown, an
    older sweep's rows: ``policies`` empty)."""
    broken = [r for r in rows if broke_policy(r)]
    kept = sum(1 for r in rows if r["policies"] == POLICIES_OK)
    unjudged = len(rows) - kept - len(broken)
    lines = ["", "## Policies", "", f"{kept} runs kept every policy, {len(broken)} broke one, {unjudged} not judged "
             "(the batch engine keeps no trace to judge by; a cell not flown; an older sweep's rows)."]
    if broken:
        lines += ["", "| controller | " + " | ".join(MAP_AXES) + " | seed | outcome | broken |",
                  "|---" * (len(MAP_AXES) + 4) + "|"]
        for r in broken[:50]:
            lines.append(f"| {r['controller']} | " + " | ".join(_fmt(r[a]) for a in MAP_AXES)
                         + f" | {r['seed']} | {r['outcome']} | {r['policies']} |")
    return lines


def jitter_section(rows: Sequence[Mapping[str, Any]]) -> list[str]:
    """``report.md``'s cells whose jitter the delay capped (``cells.csv``'s ``jitter_capped``: each capped direction
    and the half-width flown, ms; docs/links.md): how many, and each (up to 50) with its cell. None: nothing."""
    capped = [r for r in rows if r.get("jitter_capped")]
    if not capped:
        return []
    lines = ["", "## Jitter capped at the delay", "", f"{len(capped)} runs flew less jitter than their `jitter_ms` "
             "asked: the jitter is drawn within ±min(delay, jitter) (uniform) or ±min(delay, 5 sigma) (normal), so "
             "that no delay is negative (docs/links.md). `flown` is each capped direction and the half-width it flew "
             "(ms; 0: no jitter at all).", "", "| controller | " + " | ".join(MAP_AXES) + " | seed | flown |",
             "|---" * (len(MAP_AXES) + 3) + "|"]
    for r in capped[:50]:
        lines.append(f"| {r['controller']} | " + " | ".join(_fmt(r[a]) for a in MAP_AXES)
                     + f" | {r['seed']} | {r['jitter_capped']} |")
    if len(capped) > 50:
        lines.append(f"\n(the first 50 of {len(capped)}: every row in `cells.csv`, column `jitter_capped`)")
    return lines


def exact(v: float) -> str:
    """Its shortest exact text (``repr``; a whole one without ``.0``): ``:g`` said 123.457 for 123.4567891."""
    return f"{float(v):.0f}" if float(v).is_integer() and abs(float(v)) < 1e15 else repr(float(v))


def reproduce(row: Mapping[str, Any], swept: Sequence[str], wind_from_deg: float = 0.0) -> str:
    """The ``bsst sim`` command that flies one row again (a ``truth`` row without ``--noise``: it flies the same
    at any scale, and ``bsst sim`` refuses a noise that changes nothing; a row of a law without a super-twisting
    step without ``--discretization``, refused for the same reason). A swept wind keeps the mission's direction
    (``wind_from_deg``, its ``[wind] from_deg``: ``--wind S`` alone would blow from the north); a fleet's row is
    its size in the sweep's formation. Every number is said exactly (:func:`exact`): the row to the last bit."""
    flags = [f"--controller {row['controller']}", f"--rate {exact(row['rate_hz'])}"]
    flags += [f"--{SHORT[a]} {exact(row[a])}" for a in LINK_AXES if a in swept]
    flags += [f"--estimator {row['estimator']}"] if "estimator" in swept else []
    flags += [f"--noise {exact(row['noise'])}"] if "noise" in swept and row["estimator"] != "truth" else []
    flags += [f"--wind {exact(row['wind_mps'])}:{exact(wind_from_deg)}"] if "wind_mps" in swept else []
    flags += [f"--turbulence {row['turbulence']}"] if "turbulence" in swept else []
    flags += [f"--discretization {row['discretization']}"] if "discretization" in swept \
        and discretization_problem((row["controller"],)) is None else []  # bsst sim refuses it for smc, pid
    flags += [f"--vehicles {row['vehicles']} --formation {FLEET_FORMATION}"] if "vehicles" in swept \
        and row["vehicles"] > 1 else []  # (one vehicle: the mission alone, as its cell flew)
    return f"bsst sim mission.toml {' '.join(flags)} --seed {row['seed']}"


def mission_wind_from(meta: Mapping[str, Any]) -> float:
    """The direction (deg) a sweep's mission's steady wind blows from (``[wind] from_deg``; 0, north, without)."""
    mission = meta.get("mission") if isinstance(meta.get("mission"), Mapping) else {}
    wind = mission.get("wind")
    frm = wind.get("from_deg", 0.0) if isinstance(wind, Mapping) else 0.0
    return float(frm) if isinstance(frm, (int, float)) and not isinstance(frm, bool) else 0.0


def sensor_set(meta: Mapping[str, Any]) -> str:
    """The sensor set a sweep's cells flew (its mission's ``[sensors] set``; ``ideal`` without one)."""
    mission = meta.get("mission") if isinstance(meta.get("mission"), Mapping) else {}
    sensors = mission.get("sensors")
    name = sensors.get("set", "ideal") if isinstance(sensors, Mapping) else "ideal"
    return name if isinstance(name, str) else "ideal"


def controller_files(controllers: Sequence[str]) -> dict[str, str]:
    """Each law's part of a file name: its spec with every character but ASCII letters, digits, ``_`` and ``-``
    made ``-`` (a plug-in law ``examples/my_law.py:MyLaw`` is ``examples-my_law-py-MyLaw``, the built-ins keep
    their names); two specs that would share one get each a short hash of the spec, so every law has its own."""
    def part(spec: str) -> str:
        return "".join(ch if (ch.isascii() and ch.isalnum()) or ch in "_-" else "-" for ch in spec).strip("-") or "law"

    parts = {c: part(c) for c in controllers}
    taken = [parts[c] for c in controllers]
    return {c: p if taken.count(p) == 1 else f"{p}-{hashlib.sha1(c.encode()).hexdigest()[:8]}"
            for c, p in parts.items()}


def pair_title(rows: Sequence[Mapping[str, Any]], a: str, b: str) -> str:
    """What a table and its heat map show: ``a x b``, or with ``b`` not swept (one value), ``a`` at that value."""
    bv = _values(rows, b)
    if len(bv) > 1:
        return f"{a} x {b}"
    unit = f" {UNITS[b]}" if b in UNITS else ""
    return f"{a} (at {b} = {_fmt(bv[0])}{unit})"


HEAT_DPI = 110
HEAT_TEXT_PT = 9  # the class and RMS written in each cell


def heat_maps(path: Path, rows: Sequence[Mapping[str, Any]], a: str, b: str, controllers: Sequence[str],
              classes: Classes) -> list[Path]:
    """``map_<a>_<b>.png`` (one panel per controller) and, with several controllers,
    ``map_<a>_<b>_<controller>.png`` for each (:func:`controller_files`): median 3-D RMS on a log colour
    scale of each panel's own (a law's 0.021..0.027 m is not one colour beside another's 1 m), class in each cell."""
    plt = pyplot()
    name = f"map_{SHORT[a]}_{SHORT[b]}"
    files = controller_files(controllers)
    written: list[Path] = []

    def save(fig: Any, fname: str) -> None:
        p = path / fname
        fig.savefig(p, dpi="figure")
        plt.close(fig)
        written.append(p)

    save(heat_map_figure(rows, a, b, controllers, classes), f"{name}.png")
    if len(controllers) > 1:
        for c in controllers:
            save(heat_map_figure(rows, a, b, [c], classes), f"{name}_{files[c]}.png")
    return written


def heat_map_figure(rows: Sequence[Mapping[str, Any]], a: str, b: str, controllers: Sequence[str],
                    classes: Classes) -> Any:
    """The heat map of ``a`` x ``b``, a panel (and colour bar, m) per controller; the caller closes it."""
    plt = pyplot()
    import matplotlib  # lazy: imported by pyplot() (its colour maps)
    import numpy as np  # lazy: only the heat maps need arrays
    from matplotlib.colors import LogNorm  # lazy: as matplotlib

    shown = [r for r in rows if r["controller"] in controllers]  # (a law's own map: its own values, e.g. smc's one
    av, bv = _values(shown, a), _values(shown, b)  # empty discretization, not bsst's schemes too)
    cmap = matplotlib.colormaps["viridis"].with_extremes(bad="#bbbbbb")
    w, h = 2.4 + 1.5 * len(bv), 1.9 + 0.8 * len(av)
    fig, axs = plt.subplots(1, len(controllers), figsize=(w * len(controllers), h), squeeze=False,
                            layout="constrained", dpi=HEAT_DPI)
    for ax, c in zip(axs[0], controllers, strict=True):
        pts = grid_points([r for r in rows if r["controller"] == c], a, b, classes)
        z = np.full((len(av), len(bv)), np.nan)
        for (x, y), p in pts.items():
            if p.rms is not None and p.rms > 0:
                z[av.index(x), bv.index(y)] = p.rms
        have = z[np.isfinite(z)]
        vmin, vmax = (float(have.min()), float(have.max())) if have.size else (1e-6, 1.0)
        if vmax < vmin * 1.001:  # one value: a scale around it
            vmin, vmax = vmin / 1.2, vmax * 1.2
        norm = LogNorm(vmin, vmax)
        im = ax.imshow(np.ma.masked_invalid(z), origin="lower", cmap=cmap, norm=norm, aspect="auto")
        for (x, y), p in pts.items():
            i, j = av.index(x), bv.index(y)
            r, g, bl, _ = cmap(norm(z[i, j])) if np.isfinite(z[i, j]) else (0.73, 0.73, 0.73, 1.0)
            dark = 0.299 * r + 0.587 * g + 0.114 * bl < 0.5  # the cell's luminance: white text on dark cells
            ax.text(j, i, p.text("\n"), ha="center", va="center", fontsize=HEAT_TEXT_PT,
                    color="white" if dark else "black")
        ax.set_xticks(range(len(bv)), [_fmt(v) for v in bv], fontsize=10)
        ax.set_yticks(range(len(av)), [_fmt(v) for v in av], fontsize=10)
        ax.set_xlabel(_label(b), fontsize=10)
        ax.set_ylabel(_label(a), fontsize=10)
        ax.set_title(c, fontsize=11)
        bar = fig.colorbar(im, ax=ax, shrink=0.95)
        ticks = np.geomspace(vmin, vmax, 5)
        bar.set_ticks(ticks, labels=[f"{v:.3g}" for v in ticks])
        bar.minorticks_off()
        bar.set_label("median 3-D RMS error [m] (log scale)", fontsize=9)
    fig.suptitle(f"{pair_title(rows, a, b)}: median 3-D RMS and worst class per cell", fontsize=11)
    return fig
