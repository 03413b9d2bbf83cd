"""``bsst sweep``, ``bsst report`` and ``bsst margin``: campaigns over link impairments, laws, rates, the
law's discretization and sensor noise (bridge.sweep).

In:  the parsed flags (``argparse.Namespace``): a mission or sweep TOML, swept values (``--delay`` ms,
     ``--loss`` %, ``--rate`` Hz, ...), flags fixed for every cell, ``--until rms=M|class=NAME``
Out: the call of :func:`bridge.sweep.run_sweep`, :func:`bridge.sweep.report.rebuild` or
     :func:`bridge.sweep.margin.margin`; their figures on stdout (margins in the axis's unit); the exit
     status: 0 done, 1 a failed or interrupted sweep (``bsst report`` of an interrupted one too), a margin below
     ``--require`` or an interrupted margin (its margin.json written, ``interrupted`` true), 2 bad input
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

from bridge.cli.flags import (
    EXIT_FAILED,
    EXIT_OK,
    FlagRefusal,
    UsageError,
    axis_values,
    int_in,
    law_list,
    name_list,
    number_in,
    path_given,
    value_list,
)
from bridge.cli.linkflags import (
    add_link_options,
    guard_flag_refusal,
    idle_link_flag,
    link_flags_from_args,
    link_table_from_args,
)
from bridge.cli.options import (
    add_discretization_option,
    add_scatter_option,
    add_sensor_axes,
    add_sensor_options,
    checked_mission,
    sensor_overrides_from_args,
)
from params import ConfigError


def add_sweep_commands(sub: Any) -> None:
    """``bsst sweep`` (latency/dropout campaigns) and ``bsst report`` (rebuild a sweep's report)."""
    p = sub.add_parser("sweep", help="fly a grid of link impairments, laws and rates; report stability maps")
    p.add_argument("mission", type=path_given("the mission"),
                   help="mission (a TOML file, or a ground station's .plan or .waypoints), or a sweep TOML (with "
                        "mission = ... and [grid])")
    for flag, axis, unit in (("--delay", "delay_ms", "MS"), ("--jitter", "jitter_ms", "MS"),
                             ("--loss", "loss_pct", "PCT"), ("--burst", "burst_len", "LEN"),
                             ("--rate", "rate_hz", "HZ")):
        p.add_argument(flag, dest=axis, type=axis_values(flag, axis), metavar=f"{unit},...",
                       help="control rates (Hz) to fly" if axis == "rate_hz" else
                       f"values of the link's {axis} (each applies to both directions)")
    p.add_argument("--controller", type=law_list("--controller"), metavar="LAW,...",
                   help="control laws to compare (bsst, smc, pid, or your own file.py:ClassName)")
    # the schemes are missions.DISCRETIZATIONS, written out so that building the parser loads no mission code
    p.add_argument("--discretization", type=name_list("--discretization", ("explicit", "implicit")),
                   metavar="SCHEME,...", help="how bsst steps its super-twisting step: implicit (chattering-free, "
                                              "the default; docs/law.md), explicit (the paper as printed), or both "
                                              "to compare (default: the mission's)")
    p.add_argument("--vehicles", type=fleet_sizes, metavar="N,...",
                   help="fleet sizes: each cell flies N vehicles together, offline, in a line 2 m apart "
                        "(docs/campaigns.md; 1: the mission alone)")
    p.add_argument("--seeds", type=int_in("--seeds", 1, 10000), metavar="N",
                   help="seeds per grid point: the mission's seed, +1, ... (default 1)")
    add_scatter_option(p)  # fixed for every cell: with --seeds, N starts around the mission's
    mode = p.add_mutually_exclusive_group()
    mode.add_argument("--offline", dest="mode", action="store_const", const="offline",
                      help="fly each cell in-process (default)")
    mode.add_argument("--lockstep", dest="mode", action="store_const", const="lockstep",
                      help="fly each cell as a lockstep SITL session (vehicle + controller processes)")
    p.add_argument("--engine", choices=("auto", "batch", "process"), default="auto",
                   help="batch: fly the cells together in one numpy loop; process: one by one in worker processes; "
                        "auto (default): batch where the grid allows it")
    p.add_argument("--jobs", type=jobs_count, metavar="N",
                   help="cores: threads of the batch engine, worker processes of the process engine "
                        "(default: all cores)")
    p.add_argument("--max-cells", type=int_in("--max-cells", 1, 10**9), metavar="N",
                   help="fly a grid of up to N cells (default 10000: a bigger one is refused as a likely mistake)")
    p.add_argument("--dask", metavar="ADDRESS", help="run the cells on this Dask scheduler (e.g. tcp://host:8786)")
    p.add_argument("--out", type=path_given("--out"),
                   metavar="DIR", help="sweep directory (default sweeps/<UTC time>-<mission>)")
    p.add_argument("--resume", action="store_true", help="fly only the cells missing from --out DIR")
    p.add_argument("--overwrite", action="store_true", help="allow writing into a non-empty --out")
    p.add_argument("--no-plots", action="store_true", help="skip the heat maps")
    add_link_options(p, skip=("delay", "jitter", "loss", "burst"))  # fixed for every cell: --up-delay, --dup ...
    add_sensor_axes(p)  # --sensors fixed for every cell; --estimator and --noise are axes
    p.add_argument("--wind", dest="wind_mps", type=axis_values("--wind", "wind_mps"), metavar="MPS,...",
                   help="steady wind speeds, m/s (0-50), from the mission's [wind] from_deg (north without one)")
    # the levels are plant.wind.TURBULENCE, written out so that building the parser loads no plant code
    p.add_argument("--turbulence", type=name_list("--turbulence", ("none", "light", "moderate", "severe")),
                   metavar="LEVEL,...", help="Dryden turbulence levels: none, light, moderate, severe")
    p.set_defaults(func=cmd_sweep)
    p = sub.add_parser("report", help="rebuild a sweep's report.md and heat maps from its cells.csv")
    p.add_argument("dir", metavar="DIR", type=path_given("the sweep directory"), help="sweep directory")
    p.add_argument("--no-plots", action="store_true", help="skip the heat maps")
    p.set_defaults(func=cmd_report)



def fleet_sizes(text: str) -> tuple[int, ...]:
    """``bsst sweep --vehicles 1,2,4``: whole numbers in the fleet's range (:data:`bridge.sweep.grid.RANGES`)."""
    from bridge.sweep.grid import RANGES  # lazy: only a sweep loads the sweep

    lo, hi = RANGES["vehicles"]
    values = value_list("--vehicles", lo, hi)(text)
    if not all(v.is_integer() for v in values):
        raise FlagRefusal("--vehicles", f"expected whole numbers of vehicles, got {text!r}", sep=": ")
    return tuple(int(v) for v in values)


def jobs_count(text: str) -> int:
    """``--jobs N`` (sweep, margin): in the range a sweep file's ``jobs`` has (:data:`bridge.sweep.spec.JOBS_RANGE`)."""
    from bridge.sweep.spec import JOBS_RANGE  # lazy: only a sweep loads the sweep

    return int_in("--jobs", *JOBS_RANGE)(text)


def cmd_sweep(args: argparse.Namespace) -> int:
    """``bsst sweep``; SIGTERM is a Ctrl-C (bridge.core.interrupt.sigterm_as_sigint): sent to this process alone (a
    scheduler's, a script's terminate), it stops as a Ctrl-C does, its record kept, exit 1."""
    from bridge.core.interrupt import sigterm_as_sigint  # lazy: start-up time

    with sigterm_as_sigint():
        return _sweep(args)


def _sweep(args: argparse.Namespace) -> int:
    from bridge.core.flight import idle_link_key, prepare, unread_problem  # lazy: start-up time
    from bridge.core.interrupt import ignore_sigint  # lazy: start-up time
    from bridge.core.overrides import Overrides  # lazy: start-up time
    from bridge.sweep import AXES, Grid, Sweep, is_sweep_file, load_sweep, run_sweep  # lazy: start-up time
    from bridge.sweep.campaign import STOPS_HELD  # lazy: start-up time
    from bridge.sweep.grid import LINK_AXES, SHORT, mission_value  # lazy: start-up time
    from missions import load_mission  # lazy: start-up time

    spec = load_sweep(args.mission) if is_sweep_file(args.mission) else Sweep(load_mission(args.mission), Grid())
    axes = {a: getattr(args, a) for a in AXES if getattr(args, a) is not None}
    if args.seeds is not None:
        axes["seeds"] = args.seeds
    spec = replace(spec, grid=replace(spec.grid, **axes), mode=args.mode or spec.mode,
                   max_cells=args.max_cells or spec.max_cells)
    fixed = link_table_from_args(args)
    for d in ("up", "down"):
        clash = [a for a in spec.grid.swept() if a in fixed.get(d, {})]
        if clash:
            raise UsageError("bsst sweep", f"--{d}-{clash[0].split('_')[0]} conflicts with the swept {clash[0]} "
                             f"(a swept value applies to both directions)")
    swept = {a: getattr(spec.grid, a) for a in LINK_AXES if getattr(spec.grid, a)}  # the link axes: each cell's
    trace = trace_flag(args)
    if swept and trace:
        a = next(iter(swept))
        given = f"--{SHORT[a]}" if a in axes else f"grid.{a}"
        raise UsageError("bsst sweep", f"{given} with {trace}: the trace gives the link's {', '.join(LINK_AXES)}, so "
                         f"{a} cannot be swept over it; drop one of them")
    sensors = {"set": args.sensors} if args.sensors is not None else None
    unread = unread_problem(spec.grid.estimator or (mission_value(spec.mission, "estimator"),), "the sensor set")
    if sensors is not None and unread:  # (no cell reads the sensors: every one flies the set's truth)
        raise UsageError("bsst sweep", f"--sensors {args.sensors}: {unread}")
    laid = fixed or sensors or args.scatter is not None
    clash = guard_flag_refusal(args, spec.mission.link, spec.mission.source)  # (named as the flag, not the key)
    if clash:
        raise UsageError("bsst sweep", clash)
    # fixed for every cell, laid over by the one path to its parts, which names a bad mission, and a key of its
    # [link] or [wind] that would change nothing (a swept --loss gives a burst_len its loss, a swept --turbulence a
    # turbulence_scaling its turbulence: every axis given, as each cell lays it)
    if laid or idle_link_key(spec.mission, fixed, swept):
        flight = prepare(spec.mission, Overrides(link=fixed or None, link_flags=link_flags_from_args(args) or None,
                                                 sensors=sensors, scatter_m=args.scatter),
                         axes=spec.grid.swept(), laid_named=True)
        idle = idle_link_flag(args, [flight.link], swept, cells=True)  # (None: no such flag given)
        if idle:
            raise UsageError("bsst sweep", idle)
        spec = replace(spec, mission=flight.mission)
    if args.resume and args.out is None:
        raise UsageError("bsst sweep", "--resume needs --out DIR (the sweep to resume)")
    client = connect_dask(args.dask) if args.dask else None
    try:
        res = run_sweep(spec, jobs=args.jobs, client=client, out=args.out, write=True, resume=args.resume,
                        overwrite=args.overwrite, progress=True, plots=not args.no_plots, engine=args.engine)
    finally:
        if client is not None:
            client.close()
    ignore_sigint()  # the result is final (interrupted or not): its lines and exit status are its own
    cells = f"{len(res.rows)} of {res.total} cells flown (interrupted): {res.ran} this run" if res.interrupted else \
        f"{len(res.rows)} cells, {res.ran} flown"
    mixed = "" if len(res.engines) < 2 else f"; MIXED engines: the rows kept from before flew on {res.engines[0]}" \
        if res.engines[0] != "unrecorded" else "; the rows kept from before: their engine not recorded (an older bsst)"
    print(f"sweep {spec.mission.name}: {cells}, {res.reused} kept from before, {res.failed} failed, "
          f"{res.wall_s:.1f} s; engine {res.engine} ({res.engine_why}){mixed}")
    if res.interrupted:
        print(f"bsst: interrupted: {res.total - len(res.rows)} of {res.total} cells not flown; continue with --resume "
              f"--out {res.path} (it flies them)", file=sys.stderr)
        return EXIT_FAILED
    print(f"sweep directory: {res.path}")
    if res.stop_held:  # a Ctrl-C that stopped nothing: said, the exit status the whole sweep's (docs/campaigns.md)
        print(f"bsst sweep: interrupted {STOPS_HELD[res.stop_held]}; nothing is missing: the sweep is whole (its exit "
              f"status its cells')", file=sys.stderr)
    if res.status == "all failed":
        print(f"bsst sweep: every cell failed ({res.failed} of {len(res.rows)}): nothing was measured; the first "
              f"error: {res.first_error()}", file=sys.stderr)
    elif res.failed:
        print(f"bsst sweep: {res.failed} of {len(res.rows)} cells failed (cells.csv's error column); the first: "
              f"{res.first_error()}", file=sys.stderr)
    say_measured(res.rows, spec.grid.swept())
    return EXIT_FAILED if res.failed else EXIT_OK


def say_measured(rows: list[dict[str, Any]], swept: tuple[str, ...]) -> None:
    """On stderr, the cells of a sweep that flew but not well, or not as asked, with the first of each: measured,
    as a diverged cell is (the exit status stays the sweep's), but said: crashed ones, broken policies, a jitter the
    delay capped."""
    from bridge.sweep.cells import broke_policy  # lazy: start-up time
    from bridge.sweep.classes import CRASHED  # lazy: start-up time

    crashed = [r for r in rows if r["outcome"] in CRASHED]
    if crashed:  # a result (class crashed), not a cell that could not be flown
        at = ", ".join(f"{a} {v:g}" if isinstance(v, float) else f"{a} {v}" for a, v in
                       ((a, crashed[0][a]) for a in swept))
        print(f"bsst sweep: {len(crashed)} of {len(rows)} cells crashed (class crashed: cells.csv's outcome column, "
              f"report.md's tables); the first: {at + ', ' if at else ''}seed {crashed[0]['seed']}: "
              f"{crashed[0]['outcome']}", file=sys.stderr)
    broken = [r for r in rows if broke_policy(r)]
    if broken:  # not flown as asked
        print(f"bsst sweep: {len(broken)} of {len(rows)} cells broke a safety policy (cells.csv's policies "
              f"column, report.md's Policies); the first: {broken[0]['controller']}, seed {broken[0]['seed']}: "
              f"{broken[0]['policies']}", file=sys.stderr)
    capped = [r for r in rows if r.get("jitter_capped")]
    if capped:  # flown as documented, but not the jitter its jitter_ms asked for
        print(f"bsst sweep: {len(capped)} of {len(rows)} cells flew a jitter capped at the delay (cells.csv's "
              f"jitter_capped column, report.md's Jitter capped at the delay; docs/links.md); the first: delay "
              f"{capped[0]['delay_ms']:g} ms, jitter {capped[0]['jitter_ms']:g} ms: {capped[0]['jitter_capped']}",
              file=sys.stderr)



def trace_flag(args: argparse.Namespace) -> str | None:
    """The link-trace flag given (``--link-trace``, ``--up-link-trace``, ``--down-link-trace``; not ``none``)."""
    for dest, flag in (("link_trace", "--link-trace"), ("link_up_trace", "--up-link-trace"),
                       ("link_down_trace", "--down-link-trace")):
        if getattr(args, dest, None):
            return flag
    return None


def connect_dask(address: str) -> Any:
    """A ``distributed.Client`` for ``--dask ADDRESS`` (ConfigError if absent or unreachable)."""
    try:
        from distributed import Client  # lazy: an optional dependency
    except ImportError:
        raise ConfigError("--dask: needs Dask distributed (pip install 'bsst-sitl[cluster]')") from None
    try:
        return Client(address, timeout="10s")
    except (OSError, TimeoutError, ValueError) as exc:
        raise ConfigError(f"--dask {address}: cannot connect ({' '.join(str(exc).split())[:200]})") from None



def add_margin_command(sub: Any) -> None:
    """``bsst margin``: the boundary of one link impairment by bisection (bridge.sweep.margin)."""
    p = sub.add_parser("margin", help="find how much delay, loss, jitter, burst, sensor noise or wind a law "
                                      "takes (bisection)")
    p.add_argument("mission", type=path_given("the mission"),
                   help="mission: a TOML file or a ground station's .plan or .waypoints")
    p.add_argument("--over", required=True,
                   choices=("delay_ms", "loss_pct", "jitter_ms", "burst_len", "noise", "wind_mps"),
                   help="the impairment searched (link values: both directions, as a sweep's axes; noise: the scale "
                        "of every sigma of the sensor set, with --sensors and --estimator raw|ekf; wind_mps: the "
                        "steady wind, m/s, from the mission's [wind] from_deg)")
    p.add_argument("--until", required=True, metavar="rms=M|class=NAME",
                   help="failure: the 3-D RMS passes M metres, or the class is NAME or worse")
    p.add_argument("--controller", type=law_list("--controller"), metavar="LAW,...", help="laws to search")
    add_discretization_option(p)
    p.add_argument("--seeds", type=int_in("--seeds", 1, 1000), default=1, metavar="N",
                   help="seeds per value: a value fails when any seed fails (default 1)")
    add_scatter_option(p)  # with --seeds N: the margin every one of N starts holds
    p.add_argument("--resolution", type=number_in("--resolution", 0.0, 1e6, lo_open=True), default=0.25,
                   metavar="X", help="stop when the bracket is this narrow, in the axis's unit (default 0.25)")
    p.add_argument("--check-below", type=number_in("--check-below", 0.0, 1e9), metavar="X",
                   help="then fly every --resolution step in [margin - X, margin) to check that failing is monotone "
                        "(default 16 x --resolution; 0: no check)")
    p.add_argument("--require", type=number_in("--require", 0.0, 1e9), metavar="X",
                   help="exit 1 when a law's holds_below (the margin, or less where a value below it failed) "
                        "is below X (for a user's CI)")
    p.add_argument("--engine", choices=("auto", "batch", "process"), default="auto",
                   help="batch: each round's cells together in one numpy loop (default where it can)")
    p.add_argument("--jobs", type=jobs_count, metavar="N",
                   help="cores: threads of the batch engine, worker processes of the process engine "
                        "(default: all cores)")
    p.add_argument("--out", type=path_given("--out"),
                   metavar="DIR", help="write margin.json into DIR (default runs/<UTC>-<mission>-margin)")
    p.add_argument("--overwrite", action="store_true", help="allow writing into a non-empty --out")
    add_link_options(p)
    add_sensor_options(p)  # fixed for every probe; --noise conflicts with --over noise
    p.add_argument("--turbulence", choices=("none", "light", "moderate", "severe"),
                   help="Dryden turbulence flown with every probe (over [wind] turbulence)")
    p.set_defaults(func=cmd_margin)



def cmd_margin(args: argparse.Namespace) -> int:
    """``bsst margin``; SIGTERM is a Ctrl-C (bridge.core.interrupt.sigterm_as_sigint): sent to this process alone (a
    scheduler's, a script's terminate), it stops as a Ctrl-C does, its record kept, exit 1."""
    from bridge.core.interrupt import sigterm_as_sigint  # lazy: start-up time

    with sigterm_as_sigint():
        return _margin(args)


def _margin(args: argparse.Namespace) -> int:
    from bridge.core.flight import prepare  # lazy: start-up time
    from bridge.core.interrupt import ignore_sigint  # lazy: start-up time
    from bridge.core.overrides import Overrides  # lazy: start-up time
    from bridge.record.runlog import run_dir  # lazy: start-up time
    from bridge.sweep.grid import LINK_AXES  # lazy: start-up time
    from bridge.sweep.margin import START, MarginInterrupted, margin, parse_until  # lazy: start-up time

    until = parse_until(args.until)
    fixed = link_table_from_args(args)
    for d in ("up", "down"):
        if args.over in fixed.get(d, {}):
            raise UsageError("bsst margin", f"a {args.over} flag conflicts with --over {args.over}")
    trace = trace_flag(args)
    if args.over in LINK_AXES and trace:
        raise UsageError("bsst margin", f"--over {args.over} with {trace}: the trace gives the link's "
                         f"{', '.join(LINK_AXES)}, so {args.over} cannot be searched over it; drop {trace}, or "
                         "search --over noise or wind_mps")
    sensing = sensor_overrides_from_args(args)
    if args.over == "noise" and sensing["noise"] is not None:
        raise UsageError("bsst margin", "--noise conflicts with --over noise (the noise scale is what is searched)")
    # a fixed --noise, --discretization or link flag that would change nothing, as bsst sim's: the link flags in a
    # probe of the searched value (--burst with --over loss_pct is used)
    probe = {args.over: [START[args.over]]} if args.over in LINK_AXES else None
    m = checked_mission(args, args.mission, None, args.controller or (), probe)  # (a discretization: every law's)
    mission = prepare(m.with_overrides(discretization=args.discretization), Overrides(
        link=fixed or None, link_flags=link_flags_from_args(args) or None, turbulence=args.turbulence,
        scatter_m=args.scatter, **sensing), axes=probe or ()).mission
    run_dir(args.out, f"{mission.name}-margin", args.overwrite, create=False)  # a refused --out before any flight
    from bridge.record.outlock import out_held  # lazy: start-up time

    with out_held(args.out):  # one run writes it, for the search's whole time (and its margin.json)
        live = sys.stderr.isatty()

        def show(text: str) -> None:  # a line a round: over itself on a terminal, one after the other elsewhere
            sys.stderr.write(f"\rmargin over {args.over}: {text}   " if live else f"margin over {args.over}: {text}\n")
            sys.stderr.flush()

        try:
            res = margin(mission, args.over, until, controllers=args.controller, seeds=args.seeds,
                         resolution=args.resolution, jobs=args.jobs, engine=args.engine, progress=show,
                         below=args.check_below)
        except MarginInterrupted as stop:
            res = stop.result
        ignore_sigint()  # the result is final, complete or not: its file, its lines and the exit status are its own
        if live:
            sys.stderr.write("\n")
        return say_margin(res, args, mission.name)


def say_margin(res: dict[str, Any], args: argparse.Namespace, name: str) -> int:
    """Write ``margin.json`` (``--out``) and say what it holds: each law's lines, the warnings, the cells flown;
    the exit status (1: a law failed, one below ``--require``, or interrupted)."""
    from bridge.sweep.margin import write_margin  # lazy: start-up time

    path = write_margin(res, args.out, name, args.overwrite)
    entries = res["controllers"]
    what = f" x the sigmas of {res['sensors']}, estimator {res['estimator']}" if args.over == "noise" else ""
    for e in entries:
        for line in margin_lines(e, args.over, what, res["until"]):
            print(line)
        if e["monotone"] is False:
            print(f"bsst margin: warning: {e['controller']} is not monotone over {args.over}: it fails at "
                  f"{', '.join(f'{v:g}' for v in e['failed_below'])}, below its margin {e['margin']:g}; every value "
                  f"flown holds only up to {e['holds_below']:g}", file=sys.stderr)
    if any(e["seeds_alike"] for e in entries):  # N copies of one flight: say so, and what gives N draws
        print(f"bsst margin: warning: the {len(res['seeds'])} seeds of each value flew the same flight (the mission "
              "draws nothing at random): --seeds added nothing; --scatter M starts each seed at its own point",
              file=sys.stderr)
    capped = [c for e in entries for c in e["cells"] if c.get("jitter_capped")]
    if capped:  # the jitter flown is not the value probed (docs/links.md)
        print(f"bsst margin: warning: {len(capped)} of {sum(len(e['cells']) for e in entries)} cells flew a jitter "
              f"capped at the delay (margin.json's cells, jitter_capped; docs/links.md); the first, at {args.over} = "
              f"{capped[0][args.over]:g}: {capped[0]['jitter_capped']}", file=sys.stderr)
    starts = (f"; each value from {len(res['seeds'])} starts within {res['start_scatter_m']:g} m of the mission's"
              if res["start_scatter_m"] else "")
    stop = " (interrupted)" if res["interrupted"] else ""
    print(f"{res['cells_flown']} cells flown{stop}{starts}; margin.json: {path / 'margin.json'}")
    for e in entries:  # a law that could not be flown is no boundary: said, and the command did not complete
        if e["error"] is not None:
            err = e["error"]
            print(f"bsst margin: {e['controller']} could not be flown at {args.over} = {err[args.over]:g} (seed "
                  f"{err['seed']}, {err['outcome']}): {err['error']}", file=sys.stderr)
    if res["interrupted"]:  # what was flown is kept, and said to be all there is (--require not judged on it)
        print("bsst margin: interrupted: margin.json keeps the cells flown and each law's bracket so far (interrupted: "
              "true); no margin is claimed beyond them", file=sys.stderr)
        return EXIT_FAILED
    overstated = [e for e in entries if _capped_margin(e, args.over) is not None]
    for e in overstated:  # a margin claimed at a jitter the delay capped: that value was never flown
        print(f"bsst margin: {e['controller']}'s margin {e['margin']:g} over {args.over} was flown with its jitter "
              f"capped at the delay ({_capped_margin(e, args.over)}): not the value claimed; raise --delay or search "
              "--over delay_ms", file=sys.stderr)
    low = [e["controller"] for e in entries if args.require is not None
           and (e["holds_below"] is None or e["holds_below"] < args.require)]
    if low:
        print(f"bsst margin: below --require {args.require:g} (holds_below): {', '.join(low)}", file=sys.stderr)
    return EXIT_FAILED if low or overstated or res["laws_failed"] else EXIT_OK


def _capped_margin(entry: dict[str, Any], over: str) -> str | None:
    """What the delay capped the jitter of a held cell at the law's claimed margin to (its ``jitter_capped``), or
    None: the margin was flown as probed (or there is none)."""
    m = entry["margin"]
    if m is None:
        return None
    return next((c["jitter_capped"] for c in entry["cells"]
                 if c.get("jitter_capped") and c[over] == m and not c["failed"]), None)


def margin_lines(e: dict[str, Any], over: str, what: str, until: str) -> list[str]:
    """The console lines of one law's margin: the bisection's answer and its bracket, then the check below it;
    ``what``, the unit's words (``noise``'s), follows a number, never ``interrupted`` or ``none``."""
    lo, hi = e["bracket"]
    err = e["error"]
    if e["interrupted_in"] == "bisection":  # Ctrl-C: no margin, the bracket flown so far
        ends = ("-" if lo is None else f"{lo:g}", "-" if hi is None else f"{hi:g}")
        held = f"holds at {lo:g}" if lo is not None else "no value held yet"
        top = f"fails at {hi:g}" if hi is not None else "no value failed yet"
        return [f"margin {e['controller']}: {over}: interrupted (bracket so far [{ends[0]}, {ends[1]}]{what}: {held}, "
                f"{top}; until {until})"]
    if err is not None and err["phase"] == "bisection":  # the law failed, or its worker died: no boundary found
        held = f"; every value flown below it held, up to {lo:g}" if lo is not None else ""
        return [f"margin {e['controller']}: {over}: none (the law failed, not the criterion: {err['outcome']} at "
                f"{err[over]:g}{what}{held}; {err['error']})"]
    if e["margin"] is None:  # no value held, the range's low end included
        return [f"margin {e['controller']}: {over}: none (fails at every value flown, down to {hi:g}{what}, "
                f"the low end of its range; until {until})"]
    tail = f"fails at {hi:g}" if hi is not None else "held over the whole range"
    lines = [f"margin {e['controller']}: {over} {e['margin']:g}{what} (bracket [{lo:g}, "
             f"{'-' if hi is None else f'{hi:g}'}], {tail}; until {until})"]
    band = e["checked_below"]
    if e["interrupted_in"] == "below":  # Ctrl-C during the check: what it flew of the band
        under = e["failed_below"]
        lines.append("  below the margin: interrupted before the check ended; " + (
            f"NOT MONOTONE: fails at {', '.join(f'{v:g}' for v in under)}; " if under else "no value flown failed; ")
            + f"holds_below {e['holds_below']:g} over the values flown")
    elif band is None:
        lines.append(f"  below the margin: not checked (--check-below 0); holds_below {e['holds_below']:g} assumes "
                     "failing is monotone")
    elif e["monotone"]:
        lines.append(f"  monotone below the margin: every value flown in [{band[0]:g}, {band[1]:g}) holds; "
                     f"holds_below {e['holds_below']:g}")
    else:
        deeper = " (the band's lowest value failed: widen --check-below)" if band[0] in e["failed_below"] else ""
        lines.append(f"  NOT MONOTONE below the margin: fails at {', '.join(f'{v:g}' for v in e['failed_below'])} "
                     f"in [{band[0]:g}, {band[1]:g}); holds_below {e['holds_below']:g}: every value flown up to it "
                     f"holds{deeper}")
    return lines



def cmd_report(args: argparse.Namespace) -> int:
    from bridge.sweep.report import incomplete, load_sweep_dir, rebuild  # lazy: start-up time

    print(f"report: {rebuild(args.dir, plots=not args.no_plots)}")
    short = incomplete(Path(args.dir), *load_sweep_dir(args.dir))
    if short:  # its tables are those of the cells flown so far: said, and not a finished sweep's status
        print(f"bsst report: {short}", file=sys.stderr)
        return EXIT_FAILED
    return EXIT_OK

