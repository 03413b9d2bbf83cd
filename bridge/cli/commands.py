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
    add_flight_options,
    add_key_option,
    add_link_options,
    axis_values,
    int_in,
    law_list,
    link_table_from_args,
    mission_integer,
    mission_number,
    number_in,
)
from params import ConfigError

EXIT_OK, EXIT_FAILED, EXIT_BAD_INPUT = 0, 1, 2

def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="bsst", description="MAVLink SITL bridge for a BS-ST-controlled quadrotor")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True
    p = sub.add_parser("sim", help="fly a mission offline, in one process")
    add_flight_options(p)
    add_link_options(p)
    p.set_defaults(func=cmd_sim)
    add_sweep_commands(sub)
    add_sitl_commands(sub)
    add_relay_command(sub)
    return parser


def add_relay_command(sub: Any) -> None:
    """``bsst relay``: the real-time UDP relay applying the link model on the wall clock (bridge.nodes.relay)."""
    p = sub.add_parser("relay", help="relay UDP both ways between two endpoints through the link model")
    p.add_argument("--listen", required=True, metavar="HOST:PORT", help="bind here; the controller sends here")
    p.add_argument("--to", required=True, metavar="HOST:PORT", help="forward to here (the vehicle's link)")
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
    except ValueError as exc:
        raise UsageError(f"bsst relay: {exc}") from None
    if args.stats:
        check_writable(args.stats, "--stats")  # bad input now, not a failure after relaying
    # the one path from a mission and its overrides to the parts: the whole mission is checked,
    # and the relay flies the link it gives
    settings = prepare(load_mission(args.mission) if args.mission else at_rest(), link=link_table_from_args(args)).link
    try:
        relay = Relay(listen, target, settings, listen_direction=args.listen_direction,
                      mission_clock=args.mission_clock)
    except OSError as exc:
        raise ConfigError(f"--listen {args.listen}: cannot bind ({exc.strerror or exc})") from None
    stop = relay.stop
    old = {s: signal.signal(s, lambda *_: stop()) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        h, p = relay.address
        print(f"relay: listening on {h}:{p} -> {target[0]}:{target[1]}; up: {settings.up.describe()}; "
              f"down: {settings.down.describe()}", flush=True)
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
    rms = s.get("rms_3d")
    w(f"3-D RMS error over t >= {s['rms_from_s']:g} s: {rms:.3e} m\n" if rms is not None else "3-D RMS: n/a\n")
    w(f"{'axis':5} {'rms':>10} {'max':>10} {'settling_s':>11} {'bound_s':>9}\n")
    for a, v in s["axes"].items():
        def f(x: Any, spec: str) -> str:
            return format(x, spec) if x is not None else "n/a"
        w(f"{a:5} {f(v['rms'], '10.3e')} {f(v['max'], '10.3e')} "
          f"{f(v['settling_s'], '11.3f')} {f(v['bound_s'], '9.3f')}\n")
    w("input  " + "  ".join(f"{u}: [{v['min']:.3g}, {v['max']:.3g}] tv/s {v['tv_per_s']:.3g}"
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
    if path is not None:
        w(f"run directory: {path}\n")


def cmd_sim(args: argparse.Namespace) -> int:
    from bridge.loop import simulate  # lazy: start-up time

    run = simulate(
        args.mission,
        out=args.out,
        write=True,
        overwrite=args.overwrite,
        plots=not args.no_plots,
        profile=args.profile,
        controller=args.controller,
        rate_hz=args.rate,
        seed=args.seed,
        link=link_table_from_args(args),
    )
    print_summary(run.summary, run.path)
    return EXIT_OK if run.outcome == "completed" else EXIT_FAILED


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
    p.add_argument("--seeds", type=int_in("--seeds", 1, 10000), metavar="N",
                   help="seeds per grid point: the mission's seed, +1, ... (default 1)")
    mode = p.add_mutually_exclusive_group()
    mode.add_argument("--offline", dest="mode", action="store_const", const="offline",
                      help="fly each cell in-process (default)")
    mode.add_argument("--lockstep", dest="mode", action="store_const", const="lockstep",
                      help="fly each cell as a lockstep SITL session (vehicle + controller processes)")
    p.add_argument("--jobs", type=int_in("--jobs", 1, 1024), metavar="N", help="worker processes (default: all cores)")
    p.add_argument("--dask", metavar="ADDRESS", help="run the cells on this Dask scheduler (e.g. tcp://host:8786)")
    p.add_argument("--out", metavar="DIR", help="sweep directory (default sweeps/<UTC time>-<mission>)")
    p.add_argument("--resume", action="store_true", help="fly only the cells missing from --out DIR")
    p.add_argument("--overwrite", action="store_true", help="allow writing into a non-empty --out")
    p.add_argument("--no-plots", action="store_true", help="skip the heat maps")
    add_link_options(p, skip=("delay", "jitter", "loss", "burst"))  # fixed for every cell: --up-delay, --dup ...
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
    axes = {a: getattr(args, a) for a in AXES if getattr(args, a) is not None}
    if args.seeds is not None:
        axes["seeds"] = args.seeds
    spec = replace(spec, grid=replace(spec.grid, **axes), mode=args.mode or spec.mode)
    fixed = link_table_from_args(args)
    for d in ("up", "down"):
        clash = [a for a in spec.grid.swept() if a in fixed.get(d, {})]
        if clash:
            raise UsageError(f"bsst sweep: --{d}-{clash[0].split('_')[0]} conflicts with the swept {clash[0]} "
                             f"(a swept value applies to both directions)")
    if fixed:  # the flags fixed for every cell, laid over the mission by the one path to its parts
        spec = replace(spec, mission=prepare(spec.mission, link=fixed).mission)
    if args.resume and args.out is None:
        raise UsageError("bsst sweep: --resume needs --out DIR (the sweep to resume)")
    client = connect_dask(args.dask) if args.dask else None
    try:
        res = run_sweep(spec, jobs=args.jobs, client=client, out=args.out, write=True, resume=args.resume,
                        overwrite=args.overwrite, progress=True, plots=not args.no_plots)
    finally:
        if client is not None:
            client.close()
    print(f"sweep {spec.mission.name}: {len(res.rows)} cells, {res.ran} flown, {res.reused} kept from before, "
          f"{res.failed} failed, {res.wall_s:.1f} s")
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
    p.add_argument("--sysid", type=int_in("--sysid", 1, 254), metavar="N",
                   help="MAVLink system id (default instance + 1)")
    p.add_argument("--controller-id", type=_ids, metavar="SYSID:COMPID",
                   help="the only sender of actuator targets (default 200:191)")
    p.add_argument("--home", type=_home, metavar="LAT,LON,ALT", help="home: degrees, degrees, m AMSL")
    p.add_argument("--out", metavar="DIR", help="write vehicle.tlog and vehicle.csv into DIR")
    p.add_argument("--overwrite", action="store_true", help="allow replacing those files")
    p.set_defaults(func=cmd_vehicle)

    p = sub.add_parser("controller", help="the offboard controller alone: fly a mission against a MAVLink vehicle")
    add_flight_options(p)
    p.add_argument("--vehicle", metavar="HOST:PORT",
                   help="the vehicle's controller link (default 127.0.0.1:14560 + instance)")
    p.add_argument("--instance", type=int_in("--instance", 0, 9), default=0, metavar="N",
                   help="vehicle instance N: port 14560 + N")
    p.add_argument("--realtime", action="store_true", help="fixed-rate schedule on the wall clock (default lockstep)")
    p.add_argument("--sysid", type=int_in("--sysid", 1, 254), default=200, metavar="N", help="own system id")
    p.add_argument("--target-sysid", type=int_in("--target-sysid", 1, 254), metavar="N",
                   help="fly only this vehicle (default: the first autopilot heard)")
    p.add_argument("--timeout", type=number_in("--timeout", 0.0, 3600.0, lo_open=True), default=10.0, metavar="S",
                   help="wait this long for the vehicle's heartbeat (default 10 s)")
    add_key_option(p)
    p.set_defaults(func=cmd_controller)

    p = sub.add_parser("sitl", help="fly a mission as SITL: vehicle and controller processes over MAVLink/UDP")
    add_flight_options(p)
    _add_port_options(p, vehicle=False)
    add_link_options(p)
    p.set_defaults(func=cmd_sitl)


def cmd_sitl(args: argparse.Namespace) -> int:
    from bridge.session import sitl  # lazy: start-up time

    run = sitl(args.mission, out=args.out, write=True, overwrite=args.overwrite, plots=not args.no_plots,
               profile=args.profile, controller=args.controller, rate_hz=args.rate, seed=args.seed,
               realtime=args.realtime, instance=args.instance, gcs=args.gcs, speed=args.speed, live=True,
               link=link_table_from_args(args), key=args.key)
    print_summary(run.summary, run.path)
    return EXIT_OK if run.outcome == "completed" else EXIT_FAILED


# -- the two sides alone (bsst vehicle, bsst controller) ---------------------------------------------
def cmd_vehicle(args: argparse.Namespace) -> int:
    """``bsst vehicle``: the simulated vehicle alone."""
    from bridge.core.flight import at_rest, prepare  # lazy: start-up time
    from bridge.mavlink.endpoint import CONTROLLER_COMPID, CONTROLLER_SYSID, GCS_PORT, LINK_PORT, parse_address  # lazy
    from bridge.mavlink.telemetry import Home  # lazy: start-up time
    from bridge.nodes.vehicle import VehicleConfig, run_vehicle  # lazy: start-up time

    flight = prepare(args.mission or at_rest(), profile=args.profile, rate_hz=args.rate, seed=args.seed)
    n = args.instance
    listen = parse_address(args.listen or f"127.0.0.1:{LINK_PORT + n}", "udpin", "--listen")
    if listen.mode != "udpin":
        raise ConfigError(f"--listen {args.listen!r}: the controller link is bound (udpin), not udpout")
    gcs_text = args.gcs or f"127.0.0.1:{GCS_PORT + n}"
    gcs = None if gcs_text.strip().lower() == "none" else parse_address(gcs_text, "udpout", "--gcs")
    sysid, compid = args.controller_id or (CONTROLLER_SYSID, CONTROLLER_COMPID)
    cfg = VehicleConfig(listen, gcs, sysid=args.sysid or n + 1, controller_sysid=sysid, controller_compid=compid,
                        clock="realtime" if args.realtime else "lockstep", speed=args.speed,
                        home=Home(*args.home) if args.home else Home(), key=_key(args))
    return run_vehicle(flight, cfg, args.out, args.overwrite)


def cmd_controller(args: argparse.Namespace) -> int:
    """``bsst controller``: the offboard controller alone."""
    from bridge.core.flight import prepare  # lazy: start-up time
    from bridge.mavlink.endpoint import LINK_PORT, parse_address  # lazy: start-up time
    from bridge.nodes.offboard import OffboardConfig, run_controller  # lazy: start-up time

    flight = prepare(args.mission, profile=args.profile, controller=args.controller, rate_hz=args.rate,
                     seed=args.seed)
    vehicle = parse_address(args.vehicle or f"127.0.0.1:{LINK_PORT + args.instance}", "udpout", "--vehicle")
    if vehicle.mode != "udpout":
        raise ConfigError(f"--vehicle {args.vehicle!r}: the controller sends to the vehicle (udpout)")
    cfg = OffboardConfig(vehicle, sysid=args.sysid, clock="realtime" if args.realtime else "lockstep",
                         target_sysid=args.target_sysid, connect_timeout_s=args.timeout, key=_key(args))
    return run_controller(flight, cfg, args.out, args.overwrite)


def _key(args: argparse.Namespace) -> bytes | None:
    """The signing key of ``--key FILE``, if given (ConfigError: exit 2, naming the file)."""
    from bridge.mavlink.signing import key_from_file  # lazy: start-up time

    return key_from_file(args.key) if getattr(args, "key", None) else None
