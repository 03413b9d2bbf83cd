"""The ``bsst`` commands: the parser, and one function per command that turns parsed flags
into a call of the layer that does the work (:mod:`bridge.loop`, :mod:`bridge.session`,
:mod:`bridge.nodes`, :mod:`bridge.sweep`).

In:  argv, parsed by :func:`build_parser` into an ``argparse.Namespace``
Out: that call; the run's summary (or the relay's and the sweep's figures) on stdout, ``--stats``
     JSON for the relay; an exit status: 0 completed, 1 failsafe/diverged/aborted (or a failed or
     interrupted sweep), 2 bad input

Heavy imports happen inside the command that needs them, so that ``bsst --help`` and a refused
flag stay fast.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
from dataclasses import replace
from typing import Any

from bridge.cli.flags import (
    UsageError,
    _add_port_options,
    _home,
    _ids,
    _Parser,
    add_discretization_option,
    add_failsafe_options,
    add_flight_options,
    add_key_option,
    add_link_options,
    add_param_options,
    add_sensor_axes,
    add_sensor_options,
    axis_values,
    failsafe_table_from_args,
    int_in,
    law_list,
    link_table_from_args,
    mission_from_args,
    mission_integer,
    mission_number,
    number_in,
    param_overrides_from_args,
    sensor_overrides_from_args,
    system_id,
)
from params import ConfigError

EXIT_OK, EXIT_FAILED, EXIT_BAD_INPUT = 0, 1, 2

def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="bsst", description="MAVLink SITL bridge for a BS-ST-controlled quadrotor")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True
    p = sub.add_parser("sim", help="fly a mission offline, in one process")
    add_flight_options(p)
    add_sensor_options(p)
    add_link_options(p)
    p.set_defaults(func=cmd_sim)
    add_sweep_commands(sub)
    add_margin_command(sub)
    add_sitl_commands(sub)
    add_relay_command(sub)
    add_link_commands(sub)
    return parser


# -- bsst link: measured links (bridge.record.linkextract, bridge.link.fit, bridge.record.linkplots) ---------
def add_link_commands(sub: Any) -> None:
    """``bsst link extract | fit | show``: a trace from a run or two tlogs, the model that fits it, its figure."""
    p = sub.add_parser("link", help="measured links: extract a trace, fit the link model to it, plot it")
    acts = p.add_subparsers(dest="link_command", metavar="ACTION", parser_class=_Parser)
    acts.required = True
    e = acts.add_parser("extract", help="per-packet delays and losses of both directions, as a trace file")
    e.add_argument("source", nargs="+", metavar="RUN_DIR | VEHICLE.tlog CONTROLLER.tlog",
                   help="a real-time run directory, or the tlogs of the vehicle's end and the controller's end")
    e.add_argument("--out", metavar="FILE", help="the trace (default RUN_DIR/link-trace.csv, or ./link-trace.csv)")
    e.add_argument("--clock", choices=("same", "timesync"), default="same",
                   help="same: both tlogs stamped on one clock (one host, or hosts kept in sync); timesync: the "
                        "offset from the TIMESYNC exchanges (equal one-way delays assumed)")
    e.add_argument("--overwrite", action="store_true", help="replace an existing --out")
    e.set_defaults(func=cmd_link_extract)
    f = acts.add_parser("fit", help="the [link] table that fits a trace best, as a link profile (TOML)")
    f.add_argument("trace", metavar="TRACE", help="trace CSV (t_s, delay_ms, optional direction)")
    f.add_argument("--out", metavar="FILE", help="write the profile here (default: print it)")
    f.add_argument("--blackout-after", type=number_in("--blackout-after", 0.0, 1e6, lo_open=True), default=1.0,
                   metavar="S", help="a loss run this long or longer is a blackout, listed apart (default 1 s)")
    f.add_argument("--overwrite", action="store_true", help="replace an existing --out")
    f.set_defaults(func=cmd_link_fit)
    s = acts.add_parser("show", help="plot a trace: delay over time, loss bursts, delay histogram (PNG)")
    s.add_argument("trace", metavar="TRACE", help="trace CSV (t_s, delay_ms, optional direction)")
    s.add_argument("--out", metavar="FILE.png", help="the figure (default: TRACE with .png)")
    s.add_argument("--overwrite", action="store_true", help="replace an existing --out")
    s.set_defaults(func=cmd_link_show)


def _new_output(path: Any, flag: str, overwrite: bool) -> Any:
    """``path`` as a file this command may write: writable, and new unless ``--overwrite`` (exit 2 otherwise)."""
    from bridge.record.runlog import check_writable  # lazy: start-up time

    p = check_writable(path, flag)
    if p.exists() and not overwrite:
        raise ConfigError(f"{flag} {p}: exists; --overwrite to replace it")
    return p


def cmd_link_extract(args: argparse.Namespace) -> int:
    """``bsst link extract``: write the trace, print each direction's figures."""
    from pathlib import Path  # lazy: with the command

    from bridge.record.linkextract import extract_run_dir, extract_tlogs, extraction_text, read_tlog  # lazy
    from bridge.record.runlog import write_text_atomic  # lazy: start-up time

    src = args.source
    if len(src) not in (1, 2):
        raise UsageError("bsst link extract: give a run directory, or a vehicle tlog and a controller tlog")
    if len(src) == 2 and Path(src[0]).resolve() == Path(src[1]).resolve():
        raise UsageError(f"bsst link extract: {src[0]} given as both ends: the same file twice")
    out = _new_output(args.out or (Path(src[0]) / "link-trace.csv" if len(src) == 1 else "link-trace.csv"),
                      "--out", args.overwrite)
    if len(src) == 1:
        ex = extract_run_dir(src[0], args.clock)
    else:
        ex = extract_tlogs(read_tlog(src[0]), read_tlog(src[1]), args.clock, inputs=tuple(src))
    write_text_atomic(out, extraction_text(ex))
    for d in ("up", "down"):
        s = getattr(ex, d).figures()
        ms = {k: "n/a" if v is None else f"{v:.2f}" for k, v in s["delay_ms"].items()}
        loss = "n/a" if s["loss_pct"] is None else f"{s['loss_pct']:.2f} %"
        print(f"{d:4}: sent {s['sent']} delivered {s['delivered']} lost {s['lost']} ({loss}); delay p50 {ms['p50']} "
              f"ms p95 {ms['p95']} ms p99 {ms['p99']} ms max {ms['max']} ms; duplicates {s['duplicates']}")
    if ex.timesync is not None:
        print(f"timesync: vehicle clock {ex.timesync[0] * 1e3:+.3f} ms from the controller's (round trip "
              f"{ex.timesync[1] * 1e3:.2f} ms); clock used: {ex.clock}")
    for n in ex.notes:
        print(f"note: {n}")
    print(f"trace: {out} (t_s = 0 at {ex.origin})")
    return EXIT_OK


def cmd_link_fit(args: argparse.Namespace) -> int:
    """``bsst link fit``: the fitted table as a link profile, on stdout or in ``--out``."""
    from pathlib import Path  # lazy: with the command

    from bridge.link.fit import fit_toml, fit_trace  # lazy: numpy
    from bridge.link.trace import read_trace  # lazy: start-up time
    from bridge.record.runlog import write_text_atomic  # lazy: start-up time

    out = _new_output(args.out, "--out", args.overwrite) if args.out else None
    tf = read_trace(args.trace)
    fits = fit_trace(tf, args.blackout_after)
    text = fit_toml(fits, str(Path(args.trace).absolute()))
    if out is None:
        sys.stdout.write(text)
        return EXIT_OK
    write_text_atomic(out, text)
    for d, f in fits.items():
        dl, ls = f.delay, f.loss
        jitter = "" if dl is None or dl.jitter == "none" else \
            f" jitter {dl.jitter_ms:.2f} ms {dl.jitter} (KS D {dl.ks[dl.jitter]:.4f})"
        delay = "nothing delivered" if dl is None else f"delay {dl.delay_ms:.2f} ms{jitter}"
        loss = f"loss {ls.loss_pct:.3g} % {ls.model}" + (f" bursts of {ls.burst_len:.3g}" if ls.burst_len else "")
        print(f"{d:4}: {delay}; {loss}; {len(f.blackouts)} blackouts of {f.blackout_after_s:g} s or more")
    print(f"profile: {out} (fly it: bsst sim MISSION --link-profile {out})")
    return EXIT_OK


def cmd_link_show(args: argparse.Namespace) -> int:
    """``bsst link show``: the trace's figure as PNG."""
    from pathlib import Path  # lazy: with the command

    from bridge.link.trace import read_trace  # lazy: start-up time
    from bridge.record.linkplots import trace_figure  # lazy: matplotlib

    out = Path(args.out) if args.out else Path(args.trace).with_suffix(".png")
    if out.suffix.lower() != ".png":
        raise UsageError(f"bsst link show: --out {out}: the figure is a PNG (name it *.png)")
    _new_output(out, "--out", args.overwrite)
    tf = read_trace(args.trace)
    print(f"figure: {trace_figure(tf, out)}")
    return EXIT_OK


def add_relay_command(sub: Any) -> None:
    """``bsst relay``: the real-time UDP relay applying the link model on the wall clock (bridge.nodes.relay)."""
    p = sub.add_parser("relay", help="relay UDP both ways between two endpoints through the link model")
    p.add_argument("--listen", required=True, metavar="HOST:PORT", help="bind here; the controller sends here")
    p.add_argument("--to", required=True, metavar="HOST:PORT",
                   help="forward to here (the vehicle's link); only datagrams from exactly here go back")
    p.add_argument("--client", metavar="HOST:PORT",
                   help="the controller side's address: only its datagrams go on (default: the first sender "
                        "to --listen, learned once)")
    p.add_argument("--back-port", type=int_in("--back-port", 1, 65535), metavar="PORT",
                   help="send to --to from this local port (a vehicle run with --controller-from hears only it; "
                        "default: any free one)")
    p.add_argument("--listen-direction", choices=("up", "down"), default="up",
                   help="direction of what arrives on --listen (default up: controller -> vehicle)")
    p.add_argument("--mission", metavar="FILE", help="take the [link] tables (and seed) from this mission")
    p.add_argument("--duration", type=number_in("--duration", 0.0, 1e7, lo_open=True), metavar="S",
                   help="stop after S seconds (default: until SIGINT/SIGTERM)")
    p.add_argument("--stats", metavar="FILE", help="write the statistics to FILE as JSON on exit")
    p.add_argument("--mission-clock", action="store_true",
                   help="blackout times count from the flight's time 0 (the first actuator target up, less the "
                        "down delay) instead of the relay's start")
    add_link_options(p)
    p.set_defaults(func=cmd_relay)


def cmd_relay(args: argparse.Namespace) -> int:
    """``bsst relay``: relay until SIGINT/SIGTERM or ``--duration``; print (and ``--stats``) the figures."""
    from bridge.core.flight import at_rest, prepare  # lazy: start-up time
    from bridge.nodes.relay import Relay, parse_address  # lazy: start-up time
    from bridge.record.runlog import check_writable, write_json_atomic  # lazy: start-up time
    from missions import load_mission  # lazy: start-up time

    try:
        listen = parse_address(args.listen, "--listen", bind=True)
        target = parse_address(args.to, "--to")
        client = parse_address(args.client, "--client") if args.client else None
    except ValueError as exc:
        raise UsageError(f"bsst relay: {exc}") from None
    if args.stats:
        check_writable(args.stats, "--stats")  # bad input now, not a failure after relaying
    # the one path from a mission and its overrides to the parts: the whole mission is checked,
    # and the relay flies the link it gives
    settings = prepare(load_mission(args.mission) if args.mission else at_rest(), link=link_table_from_args(args)).link

    def learned(addr: Any) -> None:  # a status line (bridge.nodes.process): the session logs the event
        print(f"event t=0.000 client: {addr[0]}:{addr[1]} is the controller side (the first sender to "
              f"--listen); any other sender is refused", flush=True)

    try:
        relay = Relay(listen, target, settings, listen_direction=args.listen_direction,
                      mission_clock=args.mission_clock, client=client, on_client=learned,
                      back_port=args.back_port or 0)
    except OSError as exc:
        where = f"--listen {args.listen}" + (f" or --back-port {args.back_port}" if args.back_port else "")
        raise ConfigError(f"{where}: cannot bind ({exc.strerror or exc})") from None
    stop = relay.stop
    old = {s: signal.signal(s, lambda *_: stop()) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        h, p = relay.address
        bh, bp = relay.back_address
        ends = f"client {client[0]}:{client[1]}" if client else "client: the first sender"
        print(f"relay: listening on {h}:{p} -> {target[0]}:{target[1]} from {bh}:{bp} ({ends}); "
              f"up: {settings.up.describe()}; down: {settings.down.describe()}", flush=True)
        relay.serve(args.duration)
    finally:
        for s, handler in old.items():
            signal.signal(s, handler)
        relay.close()
    summary = relay.summary()
    for d in ("up", "down"):
        s = summary[d]
        m_ms = s["measured_ms"]
        fmt = {k: "n/a" if v is None else f"{v:.3f}" for k, v in m_ms.items()}
        print(f"{d:4}: sent {s['sent']} delivered {s['delivered']} lost {s['lost']} dup {s['duplicated']} "
              f"reordered {s['reordered']}; added delay p50 {fmt['p50']} ms p99 {fmt['p99']} ms max {fmt['max']} ms")
    refused = summary["refused"]
    print(f"refused {sum(refused.values())}: " + ", ".join(f"{r} {n}" for r, n in refused.items())
          + f" (client {summary['client'] or 'none'}, target {summary['target']})")
    cpu = summary["cpu_us_per_packet"]
    print(f"cpu {summary['cpu_user_s']:.3f} s user + {summary['cpu_sys_s']:.3f} s system"
          + (f", {cpu:.1f} us per packet" if cpu is not None else ""))
    if args.stats:
        try:
            write_json_atomic(args.stats, summary)
        except OSError as exc:
            print(f"bsst: --stats {args.stats}: cannot write ({exc.strerror or exc})", file=sys.stderr)
            return 1
    return 0


def print_summary(s: dict[str, Any], path: Any, stream: Any = None) -> None:
    """The one-screen summary printed after a run."""
    out = stream or sys.stdout
    w = out.write
    w(f"mission {s['mission']}  controller {s['controller']}  profile {s['profile']}  "
      f"clock {s['clock']}  rate {s['rate_hz']:g} Hz  duration {s['duration_s']:.2f} s\n")
    w(f"outcome: {s['outcome']}\n")
    end = s.get("ended_by")
    if end and (end.get("who"), end.get("how")) != ("mission", "completed"):
        w(f"ended by {end['who']}: {end['how']}\n")
    lock = s.get("lockstep")
    if lock and not lock.get("held", True):
        w(f"left lockstep at t={lock['left_at_s']:.3f} s: {lock['why']} (flown on from there on the wall clock: "
          "not a lockstep run)\n")
    rms = s.get("rms_3d")
    w(f"3-D RMS error over t >= {s['rms_from_s']:g} s: {rms:.3e} m\n" if rms is not None else "3-D RMS: n/a\n")
    w(f"{'axis':5} {'rms':>10} {'max':>10} {'settling_s':>11} {'bound_s':>9}\n")
    for a, v in s["axes"].items():
        def f(x: Any, spec: str) -> str:
            return format(x, spec) if x is not None else "n/a"
        w(f"{a:5} {f(v['rms'], '10.3e')} {f(v['max'], '10.3e')} "
          f"{f(v['settling_s'], '11.3f')} {f(v['bound_s'], '9.3f')}\n")
    w("input  " + "  ".join(f"{u}: [{v['min']:.3g}, {v['max']:.3g}] tv/s {v['tv_per_s']:.3g}"
                            + (f" p2 {v['period2']:.3g}" if v.get("period2") is not None else "")
                            for u, v in s["inputs"].items() if v["min"] is not None) + "\n")
    link = s.get("link", {})
    if any(L.get("lost") or L.get("duplicated") or L.get("reordered") or (L.get("delay_ms") or {}).get("max")
           for L in (link.get("up", {}), link.get("down", {}))):
        for d in ("up", "down"):
            L = link[d]
            ms = {k: "n/a" if v is None else f"{v:.2f}" for k, v in L["delay_ms"].items()}
            w(f"link {d:4}: sent {L['sent']} delivered {L['delivered']} lost {L['lost']} dup {L['duplicated']} "
              f"reordered {L['reordered']} delay p50 {ms['p50']} ms p99 {ms['p99']} ms max {ms['max']} ms\n")
    for e in s.get("events", [])[:8]:
        w(f"event t={e['t']:.3f} {e['kind']}: {e['text']}\n")
    policies = s.get("policies") or []
    broken = [v for v in policies if not v.get("ok")]
    if policies:
        from bridge.record.policies import violation_text  # lazy: numpy

        w(f"policies: all {len(policies)} hold\n" if not broken else
          "".join(f"policy {violation_text(v)}\n" for v in broken))
    if path is not None:
        w(f"run directory: {path}\n")


def cmd_sim(args: argparse.Namespace) -> int:
    from bridge.loop import simulate  # lazy: start-up time

    run = simulate(
        mission_from_args(args),
        out=args.out,
        write=True,
        overwrite=args.overwrite,
        plots=not args.no_plots,
        profile=args.profile,
        controller=args.controller,
        rate_hz=args.rate,
        seed=args.seed,
        link=link_table_from_args(args),
        failsafe=failsafe_table_from_args(args),
        **sensor_overrides_from_args(args),
        **param_overrides_from_args(args),
    )
    return report_run(run, "sim")


def report_run(run: Any, command: str) -> int:
    """Print a run's summary, name each violated policy on stderr; its exit status (0: a clean completion)."""
    from bridge.record.policies import run_ok, violation_text  # lazy: numpy

    try:
        print_summary(run.summary, run.path)
        sys.stdout.flush()
    except BrokenPipeError:  # stdout closed early (bsst sim ... | head): the run is on disk, its status stands
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    lock = run.summary.get("lockstep") or {"held": True}
    if not lock.get("held", True):
        print(f"bsst {command}: not a lockstep run: the vehicle left lockstep at t={lock['left_at_s']:.3f} s "
              f"({lock['why']})", file=sys.stderr)
    for v in run.summary.get("policies") or []:
        if not v.get("ok"):
            print(f"bsst {command}: policy {violation_text(v)}", file=sys.stderr)
    return EXIT_OK if run_ok(run.summary) else EXIT_FAILED


def add_sweep_commands(sub: Any) -> None:
    """``bsst sweep`` (latency/dropout campaigns) and ``bsst report`` (rebuild a sweep's report)."""
    p = sub.add_parser("sweep", help="fly a grid of link impairments, laws and rates; report stability maps")
    p.add_argument("mission", help="mission TOML, or a sweep TOML (with mission = ... and [grid])")
    for flag, axis, unit in (("--delay", "delay_ms", "MS"), ("--jitter", "jitter_ms", "MS"),
                             ("--loss", "loss_pct", "PCT"), ("--burst", "burst_len", "LEN"),
                             ("--rate", "rate_hz", "HZ")):
        p.add_argument(flag, dest=axis, type=axis_values(flag, axis), metavar=f"{unit},...",
                       help=f"values of {axis} (link values apply to both directions)")
    p.add_argument("--controller", type=law_list("--controller"), metavar="LAW,...",
                   help="control laws to compare (bsst, smc, pid, or your own file.py:ClassName)")
    add_discretization_option(p)
    p.add_argument("--seeds", type=int_in("--seeds", 1, 10000), metavar="N",
                   help="seeds per grid point: the mission's seed, +1, ... (default 1)")
    mode = p.add_mutually_exclusive_group()
    mode.add_argument("--offline", dest="mode", action="store_const", const="offline",
                      help="fly each cell in-process (default)")
    mode.add_argument("--lockstep", dest="mode", action="store_const", const="lockstep",
                      help="fly each cell as a lockstep SITL session (vehicle + controller processes)")
    p.add_argument("--engine", choices=("auto", "batch", "process"), default="auto",
                   help="batch: fly the cells together in one numpy loop; process: one by one in worker processes; "
                        "auto (default): batch where the grid allows it")
    p.add_argument("--jobs", type=int_in("--jobs", 1, 1024), metavar="N", help="worker processes (default: all cores)")
    p.add_argument("--max-cells", type=int_in("--max-cells", 1, 10**9), metavar="N",
                   help="fly a grid of up to N cells (default 10000: a bigger one is refused as a likely mistake)")
    p.add_argument("--dask", metavar="ADDRESS", help="run the cells on this Dask scheduler (e.g. tcp://host:8786)")
    p.add_argument("--out", metavar="DIR", help="sweep directory (default sweeps/<UTC time>-<mission>)")
    p.add_argument("--resume", action="store_true", help="fly only the cells missing from --out DIR")
    p.add_argument("--overwrite", action="store_true", help="allow writing into a non-empty --out")
    p.add_argument("--no-plots", action="store_true", help="skip the heat maps")
    add_link_options(p, skip=("delay", "jitter", "loss", "burst"))  # fixed for every cell: --up-delay, --dup ...
    add_sensor_axes(p)  # --sensors fixed for every cell; --estimator and --noise are axes
    p.set_defaults(func=cmd_sweep)
    p = sub.add_parser("report", help="rebuild a sweep's report.md and heat maps from its cells.csv")
    p.add_argument("dir", metavar="DIR", help="sweep directory")
    p.add_argument("--no-plots", action="store_true", help="skip the heat maps")
    p.set_defaults(func=cmd_report)


def cmd_sweep(args: argparse.Namespace) -> int:
    from bridge.core.flight import prepare  # lazy: start-up time
    from bridge.sweep import AXES, Grid, Sweep, is_sweep_file, load_sweep, run_sweep  # lazy: start-up time
    from missions import load_mission  # lazy: start-up time

    spec = load_sweep(args.mission) if is_sweep_file(args.mission) else Sweep(load_mission(args.mission), Grid())
    if args.discretization is not None:
        spec = replace(spec, mission=spec.mission.with_overrides(discretization=args.discretization))
    axes = {a: getattr(args, a) for a in AXES if getattr(args, a) is not None}
    if args.seeds is not None:
        axes["seeds"] = args.seeds
    spec = replace(spec, grid=replace(spec.grid, **axes), mode=args.mode or spec.mode,
                   max_cells=args.max_cells or spec.max_cells)
    fixed = link_table_from_args(args)
    for d in ("up", "down"):
        clash = [a for a in spec.grid.swept() if a in fixed.get(d, {})]
        if clash:
            raise UsageError(f"bsst sweep: --{d}-{clash[0].split('_')[0]} conflicts with the swept {clash[0]} "
                             f"(a swept value applies to both directions)")
    sensing = {"sensors": {"set": args.sensors}} if args.sensors is not None else {}
    if fixed or sensing:  # the flags fixed for every cell, laid over the mission by the one path to its parts
        spec = replace(spec, mission=prepare(spec.mission, link=fixed or None, **sensing).mission)
    if args.resume and args.out is None:
        raise UsageError("bsst sweep: --resume needs --out DIR (the sweep to resume)")
    client = connect_dask(args.dask) if args.dask else None
    try:
        res = run_sweep(spec, jobs=args.jobs, client=client, out=args.out, write=True, resume=args.resume,
                        overwrite=args.overwrite, progress=True, plots=not args.no_plots, engine=args.engine)
    finally:
        if client is not None:
            client.close()
    print(f"sweep {spec.mission.name}: {len(res.rows)} cells, {res.ran} flown, {res.reused} kept from before, "
          f"{res.failed} failed, {res.wall_s:.1f} s; engine {res.engine} ({res.engine_why})")
    if res.interrupted:
        print(f"bsst: interrupted; continue with --resume --out {res.path}", file=sys.stderr)
        return EXIT_FAILED
    print(f"sweep directory: {res.path}")
    return EXIT_FAILED if res.failed else EXIT_OK


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
    p = sub.add_parser("margin", help="find how much delay, loss, jitter, burst or sensor noise a law takes "
                                      "(bisection)")
    p.add_argument("mission", help="mission TOML file")
    p.add_argument("--over", required=True, choices=("delay_ms", "loss_pct", "jitter_ms", "burst_len", "noise"),
                   help="the impairment searched (link values: both directions, as a sweep's axes; noise: the scale "
                        "of every sigma of the sensor set, with --sensors and --estimator raw|ekf)")
    p.add_argument("--until", required=True, metavar="rms=M|class=NAME",
                   help="failure: the 3-D RMS passes M metres, or the class is NAME or worse")
    p.add_argument("--controller", type=law_list("--controller"), metavar="LAW,...", help="laws to search")
    add_discretization_option(p)
    p.add_argument("--seeds", type=int_in("--seeds", 1, 1000), default=1, metavar="N",
                   help="seeds per value: a value fails when any seed fails (default 1)")
    p.add_argument("--resolution", type=number_in("--resolution", 0.0, 1e6, lo_open=True), default=0.25,
                   metavar="X", help="stop when the bracket is this narrow, in the axis's unit (default 0.25)")
    p.add_argument("--require", type=number_in("--require", 0.0, 1e9), metavar="X",
                   help="exit 1 when a law's margin is below X (for a user's CI)")
    p.add_argument("--engine", choices=("auto", "batch", "process"), default="auto",
                   help="batch: each round's cells together in one numpy loop (default where it can)")
    p.add_argument("--jobs", type=int_in("--jobs", 1, 1024), default=2, metavar="N",
                   help="worker processes for the process engine (default 2)")
    p.add_argument("--out", metavar="DIR", help="write margin.json into DIR (default runs/<UTC>-<mission>-margin)")
    p.add_argument("--overwrite", action="store_true", help="allow writing into a non-empty --out")
    add_link_options(p)
    add_sensor_options(p)  # fixed for every probe; --noise conflicts with --over noise
    p.set_defaults(func=cmd_margin)


def cmd_margin(args: argparse.Namespace) -> int:
    from bridge.core.flight import prepare  # lazy: start-up time
    from bridge.record.runlog import run_dir  # lazy: start-up time
    from bridge.sweep.margin import margin, parse_until, write_margin  # lazy: start-up time
    from missions import load_mission  # lazy: start-up time

    until = parse_until(args.until)
    fixed = link_table_from_args(args)
    for d in ("up", "down"):
        if args.over in fixed.get(d, {}):
            raise UsageError(f"bsst margin: a {args.over} flag conflicts with --over {args.over}")
    sensing = sensor_overrides_from_args(args)
    if args.over == "noise" and sensing["noise"] is not None:
        raise UsageError("bsst margin: --noise conflicts with --over noise (the noise scale is what is searched)")
    mission = prepare(load_mission(args.mission).with_overrides(discretization=args.discretization),
                      link=fixed or None, **sensing).mission
    run_dir(args.out, f"{mission.name}-margin", args.overwrite, create=False)  # a refused --out before any flight
    live = sys.stderr.isatty()

    def show(text: str) -> None:
        if live:
            sys.stderr.write(f"\rmargin over {args.over}: {text}   ")
            sys.stderr.flush()

    res = margin(mission, args.over, until, controllers=args.controller, seeds=args.seeds,
                 resolution=args.resolution, jobs=args.jobs, engine=args.engine, progress=show)
    if live:
        sys.stderr.write("\n")
    path = write_margin(res, args.out, mission.name, args.overwrite)
    entries = res.get("controllers") or [res]
    low = []
    for e in entries:
        lo, hi = e["bracket"]
        what = f" x the sigmas of {res['sensors']}, estimator {res['estimator']}" if args.over == "noise" else ""
        if e["margin"] is None:  # no value held, the range's low end included
            print(f"margin {e['controller']}: {args.over}: none{what} (fails at every value flown, down to {hi:g}, "
                  f"the low end of its range; until {res['until']})")
        else:
            tail = f"fails at {hi:g}" if hi is not None else "held over the whole range"
            print(f"margin {e['controller']}: {args.over} {e['margin']:g}{what} (bracket [{lo:g}, "
                  f"{'-' if hi is None else f'{hi:g}'}], {tail}; until {res['until']})")
        if args.require is not None and (e["margin"] is None or e["margin"] < args.require):
            low.append(e["controller"])
    print(f"{res['cells_flown']} cells flown; margin.json: {path / 'margin.json'}")
    if low:
        print(f"bsst margin: below --require {args.require:g}: {', '.join(low)}", file=sys.stderr)
        return EXIT_FAILED
    return EXIT_OK


def cmd_report(args: argparse.Namespace) -> int:
    from bridge.sweep.report import rebuild  # lazy: start-up time

    print(f"report: {rebuild(args.dir, plots=not args.no_plots)}")
    return EXIT_OK


def add_sitl_commands(sub: Any) -> None:
    """``bsst vehicle``, ``bsst controller`` and ``bsst sitl``: the MAVLink SITL over UDP (bridge.session)."""
    p = sub.add_parser("vehicle", help="the simulated vehicle alone: a MAVLink 2 endpoint over UDP")
    p.add_argument("mission", nargs="?", help="mission TOML for the start, effects, failsafe and rates "
                                              "(default: at rest at the origin, 250 Hz)")
    p.add_argument("--profile", metavar="NAME", help="vehicle profile: paper, x500 or a profile TOML path")
    p.add_argument("--rate", type=mission_number("--rate", "rate_hz"), metavar="HZ",
                   help="control rate, 50-1000 Hz: one lockstep step per period")
    p.add_argument("--seed", type=mission_integer("--seed", "seed"), metavar="N", help="seed of random effects")
    _add_port_options(p, vehicle=True)
    p.add_argument("--sysid", type=system_id("--sysid"), metavar="N",
                   help="MAVLink system id (default: MAV_SYS_ID if set, else instance + 1)")
    p.add_argument("--controller-id", type=_ids, metavar="SYSID:COMPID",
                   help="the only sender of actuator targets (default 200:191)")
    p.add_argument("--controller-from", metavar="HOST:PORT",
                   help="the only address the controller's ids are heard from (bsst sitl pins it; default: "
                        "learned from the controller's first message)")
    p.add_argument("--home", type=_home, metavar="LAT,LON,ALT", help="home: degrees, degrees, m AMSL")
    add_failsafe_options(p)
    add_param_options(p, schedule=False)  # a change at a mission time is the controller's to send (--param-at)
    add_sensor_options(p)
    p.add_argument("--out", metavar="DIR", help="write vehicle.tlog and vehicle.csv into DIR")
    p.add_argument("--overwrite", action="store_true", help="allow replacing those files")
    p.set_defaults(func=cmd_vehicle)

    p = sub.add_parser("controller", help="the offboard controller alone: fly a mission against a MAVLink vehicle")
    add_flight_options(p, failsafe=False)  # the vehicle flies its failsafe: the controller has no say in it
    p.add_argument("--vehicle", metavar="HOST:PORT",
                   help="the vehicle's controller link (default 127.0.0.1:14560 + instance)")
    p.add_argument("--instance", type=int_in("--instance", 0, 9), default=0, metavar="N",
                   help="vehicle instance N: port 14560 + N")
    p.add_argument("--realtime", action="store_true", help="fixed-rate schedule on the wall clock (default lockstep)")
    p.add_argument("--source-port", type=int_in("--source-port", 1, 65535), metavar="PORT",
                   help="send from this local UDP port (a vehicle run with --controller-from hears only it; "
                        "default: any free one)")
    p.add_argument("--sysid", type=int_in("--sysid", 1, 254), default=200, metavar="N", help="own system id")
    p.add_argument("--target-sysid", type=int_in("--target-sysid", 1, 254), metavar="N",
                   help="fly only this vehicle (default: the first autopilot heard)")
    p.add_argument("--timeout", type=number_in("--timeout", 0.0, 3600.0, lo_open=True), default=10.0, metavar="S",
                   help="wait this long for the vehicle's heartbeat (default 10 s)")
    add_key_option(p)
    p.set_defaults(func=cmd_controller)

    p = sub.add_parser("sitl", help="fly a mission as SITL: vehicle and controller processes over MAVLink/UDP")
    add_flight_options(p)
    add_sensor_options(p)
    _add_port_options(p, vehicle=False)
    add_link_options(p)
    p.set_defaults(func=cmd_sitl)


def cmd_sitl(args: argparse.Namespace) -> int:
    from bridge.session import sitl  # lazy: start-up time

    run = sitl(mission_from_args(args), out=args.out, write=True, overwrite=args.overwrite, plots=not args.no_plots,
               profile=args.profile, controller=args.controller, rate_hz=args.rate, seed=args.seed,
               realtime=args.realtime, instance=args.instance, gcs=args.gcs, speed=args.speed, live=True,
               link=link_table_from_args(args), key=args.key, failsafe=failsafe_table_from_args(args),
               **sensor_overrides_from_args(args), **param_overrides_from_args(args))
    return report_run(run, "sitl")


# -- the two sides alone (bsst vehicle, bsst controller) ---------------------------------------------
def cmd_vehicle(args: argparse.Namespace) -> int:
    """``bsst vehicle``: the simulated vehicle alone."""
    from bridge.core.flight import at_rest, prepare  # lazy: start-up time
    from bridge.mavlink.endpoint import CONTROLLER_COMPID, CONTROLLER_SYSID, GCS_PORT, LINK_PORT, parse_address  # lazy
    from bridge.mavlink.telemetry import Home  # lazy: start-up time
    from bridge.nodes.vehicle import VehicleConfig, run_vehicle  # lazy: start-up time

    flight = prepare(args.mission or at_rest(), profile=args.profile, rate_hz=args.rate, seed=args.seed,
                     failsafe=failsafe_table_from_args(args), **sensor_overrides_from_args(args),
                     **param_overrides_from_args(args))
    n = args.instance
    own = flight.params.sysid if "MAV_SYS_ID" in flight.mission.params else None  # [params] or --param
    if args.sysid is not None and own is not None and args.sysid != own:
        raise ConfigError(f"--sysid {args.sysid} and MAV_SYS_ID {own} set the vehicle's system id twice: give one")
    listen = parse_address(args.listen or f"127.0.0.1:{LINK_PORT + n}", "udpin", "--listen")
    if listen.mode != "udpin":
        raise ConfigError(f"--listen {args.listen!r}: the controller link is bound (udpin), not udpout")
    gcs_text = args.gcs or f"127.0.0.1:{GCS_PORT + n}"
    gcs = None if gcs_text.strip().lower() == "none" else parse_address(gcs_text, "udpout", "--gcs")
    sysid, compid = args.controller_id or (CONTROLLER_SYSID, CONTROLLER_COMPID)
    pin = None
    if args.controller_from is not None:
        a = parse_address(args.controller_from, "udpout", "--controller-from")
        if a.mode != "udpout" or a.port == 0:
            raise ConfigError(f"--controller-from {args.controller_from!r}: give the controller's HOST:PORT")
        pin = (a.host, a.port)
    cfg = VehicleConfig(listen, gcs, sysid=args.sysid or own or n + 1, controller_sysid=sysid, controller_compid=compid,
                        clock="realtime" if args.realtime else "lockstep", speed=args.speed,
                        home=Home(*args.home) if args.home else Home(), key=_key(args), controller_from=pin)
    return run_vehicle(flight, cfg, args.out, args.overwrite)


def cmd_controller(args: argparse.Namespace) -> int:
    """``bsst controller``: the offboard controller alone."""
    from bridge.core.flight import prepare  # lazy: start-up time
    from bridge.mavlink.endpoint import LINK_PORT, parse_address  # lazy: start-up time
    from bridge.nodes.offboard import OffboardConfig, run_controller  # lazy: start-up time

    flight = prepare(mission_from_args(args), profile=args.profile, controller=args.controller, rate_hz=args.rate,
                     seed=args.seed, **param_overrides_from_args(args))
    vehicle = parse_address(args.vehicle or f"127.0.0.1:{LINK_PORT + args.instance}", "udpout", "--vehicle")
    if vehicle.mode != "udpout":
        raise ConfigError(f"--vehicle {args.vehicle!r}: the controller sends to the vehicle (udpout)")
    cfg = OffboardConfig(vehicle, sysid=args.sysid, clock="realtime" if args.realtime else "lockstep",
                         target_sysid=args.target_sysid, connect_timeout_s=args.timeout, key=_key(args),
                         source_port=args.source_port or 0)
    return run_controller(flight, cfg, args.out, args.overwrite)


def _key(args: argparse.Namespace) -> bytes | None:
    """The signing key of ``--key FILE``, if given (ConfigError: exit 2, naming the file)."""
    from bridge.mavlink.signing import key_from_file  # lazy: start-up time

    return key_from_file(args.key) if getattr(args, "key", None) else None
