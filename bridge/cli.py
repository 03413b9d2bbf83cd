"""``bsst``: the command line (DESIGN.md section 7). ``python -m bridge`` is the same.

Exit status: 0 the mission completed; 1 it ended in failsafe, divergence or abort; 2 bad
input, with one line on stderr naming the file, key or flag, and no traceback.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence
from typing import Any, NoReturn

from params import ConfigError

EXIT_OK, EXIT_FAILED, EXIT_BAD_INPUT = 0, 1, 2


class UsageError(Exception):
    """Bad command-line input (exit 2)."""


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:  # one line, no usage dump
        raise UsageError(f"{self.prog}: {message}")


def int_in(name: str, lo: int, hi: int) -> Callable[[str], int]:
    def conv(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be an integer, got {text!r}") from None
        if not lo <= v <= hi:
            raise argparse.ArgumentTypeError(f"{name} must be in [{lo}, {hi}], got {v}")
        return v

    return conv


def add_flight_options(p: argparse.ArgumentParser) -> None:
    """Options every flying command shares: overrides of the mission's own values."""
    p.add_argument("mission", help="mission TOML file (see missions/)")
    p.add_argument("--out", metavar="DIR", help="run directory (default runs/<UTC time>-<mission>)")
    p.add_argument("--overwrite", action="store_true", help="allow writing into a non-empty --out")
    p.add_argument("--rate", type=number_in("--rate", 50.0, 1000.0), metavar="HZ",
                   help="control rate, 50-1000 Hz (default: the mission's, 250)")
    p.add_argument("--profile", metavar="NAME", help="vehicle profile: paper, x500 or a profile TOML path")
    p.add_argument("--controller", choices=("bsst", "smc", "pid"), help="control law")
    p.add_argument("--seed", type=int_in("--seed", 0, 2**31 - 1), metavar="N", help="seed of random effects")
    p.add_argument("--no-plots", action="store_true", help="skip the PNG figures")


# -- link impairment flags (bridge.link): both directions, or one with --up-/--down- -----------
LINK_FLAGS = (  # flag stem, [link] key, metavar, help; the ranges are bridge.link.NUMBER_RANGES
    ("delay", "delay_ms", "MS", "one-way delay"),
    ("jitter", "jitter_ms", "MS", "delay jitter (uniform half-width or normal sigma)"),
    ("loss", "loss_pct", "PCT", "packet loss"),
    ("burst", "burst_len", "LEN", "mean loss burst length in packets (Gilbert-Elliott; 0 Bernoulli)"),
    ("dup", "dup_pct", "PCT", "duplicated packets"),
    ("reorder", "reorder_pct", "PCT", "packets held back past their successor"),
    ("bandwidth", "rate_bps", "BYTES_PER_S", "bandwidth cap in bytes/s (0: none)"),
)


def number_in(name: str, lo: float, hi: float, *, lo_open: bool = False) -> Callable[[str], float]:
    """An argparse type: a finite number in [lo, hi] (or (lo, hi] with ``lo_open``), named in the error."""
    left = "(" if lo_open else "["

    def conv(text: str) -> float:
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be a number, got {text!r}") from None
        if not (lo < v if lo_open else lo <= v) or not v <= hi:  # also refuses nan
            raise argparse.ArgumentTypeError(f"{name} must be in {left}{lo:g}, {hi:g}], got {text}")
        return v

    return conv


def link_number(flag: str, key: str | None = None) -> Callable[[str], float]:
    """An argparse type for a ``[link]`` number: in the range the mission file allows for
    ``key`` (bridge.link, looked up when a flag is given, so that building the parser does
    not load the link model; ``None``: the command lag)."""
    def conv(text: str) -> float:
        from bridge.link import COMMAND_LAG_RANGE_MS, NUMBER_RANGES

        return number_in(flag, *(NUMBER_RANGES[key] if key else COMMAND_LAG_RANGE_MS))(text)

    return conv


def blackout_window(name: str) -> Callable[[str], tuple[float, float]]:
    """``START:DURATION`` in seconds of mission time."""
    def conv(text: str) -> tuple[float, float]:
        a, sep, b = text.partition(":")
        try:
            start, dur = float(a), float(b)
        except ValueError:
            start = dur = float("nan")
        if not sep or not (0.0 <= start <= 1e6 and 0.0 < dur <= 1e6):
            raise argparse.ArgumentTypeError(f"{name} must be START:DURATION in seconds (start >= 0, "
                                             f"duration > 0), got {text!r}")
        return start, dur

    return conv


def add_link_options(p: argparse.ArgumentParser, skip: Sequence[str] = ()) -> None:
    """The link-impairment flags (``--delay MS`` … for both directions, ``--up-delay``,
    ``--down-loss`` … for one) and the controller's compensation; ``skip`` omits flag
    stems a command defines otherwise. :func:`link_table_from_args` reads them back."""
    g = p.add_argument_group("link impairment", "override the mission's [link] tables; every flag for both "
                             "directions also exists as --up-FLAG (controller -> vehicle) and --down-FLAG")
    for stem, key, meta, text in LINK_FLAGS:
        for pre in ("", "up-", "down-"):
            if stem in skip and not pre:
                continue
            flag = f"--{pre}{stem}"
            g.add_argument(flag, dest=f"link_{pre.replace('-', '_')}{key}", type=link_number(flag, key),
                           metavar=meta, help=argparse.SUPPRESS if pre else text)
    for pre in ("", "up-", "down-"):
        flag = f"--{pre}blackout"
        g.add_argument(flag, dest=f"link_{pre.replace('-', '_')}blackouts", action="append",
                       type=blackout_window(flag), metavar="START:DURATION",
                       help=argparse.SUPPRESS if pre else "no packets from START for DURATION s (repeatable)")
    g.add_argument("--jitter-dist", dest="link_jitter", choices=("uniform", "normal"), help="jitter distribution")
    g.add_argument("--link-seed", dest="link_seed", type=int_in("--link-seed", 0, 2**31 - 1), metavar="N",
                   help="seed of the link's fates (default: the mission's seed)")
    g.add_argument("--compensation", dest="link_compensation", choices=("none", "predict"),
                   help="predict: control on the state carried forward over its age (nominal model)")
    g.add_argument("--command-lag", dest="link_command_lag_ms", type=link_number("--command-lag"),
                   metavar="MS", help="with --compensation predict: assumed command delay it also covers")


def link_table_from_args(args: argparse.Namespace) -> dict[str, Any]:
    """The ``[link]`` overrides the flags of :func:`add_link_options` ask for ({} if none).

    Flags for both directions write both ``up`` and ``down``; ``--up-*`` / ``--down-*`` win."""
    out: dict[str, Any] = {}
    keys = [key for _, key, *_ in LINK_FLAGS] + ["blackouts"]
    for d in ("up", "down"):
        side: dict[str, Any] = {}
        for key in keys:
            for dest in (f"link_{key}", f"link_{d}_{key}"):
                v = getattr(args, dest, None)
                if v is not None:
                    side[key] = [list(w) for w in v] if key == "blackouts" else v
        for key in ("jitter", "seed"):
            v = getattr(args, f"link_{key}", None)
            if v is not None:
                side[key] = v
        if side:
            out[d] = side
        if "burst_len" in side and "loss_pct" in side:
            from bridge.link import burst_problem

            why = burst_problem(side["loss_pct"], side["burst_len"])
            if why:
                raise UsageError(f"bsst: --burst / --{d}-burst: {why}")
    for key in ("compensation", "command_lag_ms"):
        v = getattr(args, f"link_{key}", None)
        if v is not None:
            out[key] = v
    return out


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
    """``bsst relay``: the real-time UDP relay applying the link model on the wall clock (bridge.relay)."""
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
    from bridge.relay import relay_from_args

    return relay_from_args(args)


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
    from bridge.loop import simulate

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


def value_list(name: str, lo: float, hi: float) -> Callable[[str], tuple[float, ...]]:
    """``--delay 0,5,10``: comma-separated numbers in [lo, hi], no repeats."""
    def conv(text: str) -> tuple[float, ...]:
        parts = [x.strip() for x in text.split(",")]
        try:
            vals = tuple(float(x) for x in parts)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} takes numbers separated by commas, got {text!r}") from None
        bad = [v for v in vals if not lo <= v <= hi]  # also catches nan
        if bad or not vals:
            raise argparse.ArgumentTypeError(f"{name} values must be in [{lo:g}, {hi:g}], got {text}")
        if len(set(vals)) != len(vals):
            raise argparse.ArgumentTypeError(f"{name}: repeated value in {text}")
        return vals

    return conv


def name_list(name: str, choices: Sequence[str]) -> Callable[[str], tuple[str, ...]]:
    def conv(text: str) -> tuple[str, ...]:
        vals = tuple(x.strip() for x in text.split(","))
        bad = [v for v in vals if v not in choices]
        if bad or len(set(vals)) != len(vals):
            raise argparse.ArgumentTypeError(f"{name} takes distinct names among {','.join(choices)}, got {text!r}")
        return vals

    return conv


def add_sweep_commands(sub: Any) -> None:
    """``bsst sweep`` (latency/dropout campaigns) and ``bsst report`` (rebuild a sweep's report)."""
    from bridge.sweep import RANGES

    p = sub.add_parser("sweep", help="fly a grid of link impairments, laws and rates; report stability maps")
    p.add_argument("mission", help="mission TOML, or a sweep TOML (with mission = ... and [grid])")
    for flag, axis, unit in (("--delay", "delay_ms", "MS"), ("--jitter", "jitter_ms", "MS"),
                             ("--loss", "loss_pct", "PCT"), ("--burst", "burst_len", "LEN"),
                             ("--rate", "rate_hz", "HZ")):
        lo, hi = RANGES[axis]
        p.add_argument(flag, dest=axis, type=value_list(flag, lo, hi), metavar=f"{unit},...",
                       help=f"values of {axis} (link values apply to both directions)")
    p.add_argument("--controller", type=name_list("--controller", ("bsst", "smc", "pid")), metavar="NAME,...",
                   help="control laws to compare (bsst, smc, pid)")
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
    from dataclasses import replace

    from bridge.sweep import AXES, Grid, Sweep, is_sweep_file, load_sweep, run_sweep
    from missions import load_mission

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
    if fixed:
        from bridge.link import merge_link_tables

        spec = replace(spec, mission=spec.mission.with_overrides(link=merge_link_tables(spec.mission.link, fixed)))
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
        from distributed import Client
    except ImportError:
        raise ConfigError("--dask: needs Dask distributed (pip install 'bsst-sitl[cluster]')") from None
    try:
        return Client(address, timeout="10s")
    except (OSError, TimeoutError, ValueError) as exc:
        raise ConfigError(f"--dask {address}: cannot connect ({' '.join(str(exc).split())[:200]})") from None


def cmd_report(args: argparse.Namespace) -> int:
    from bridge.report import rebuild

    print(f"report: {rebuild(args.dir, plots=not args.no_plots)}")
    return EXIT_OK


def add_sitl_commands(sub: Any) -> None:
    """``bsst vehicle``, ``bsst controller`` and ``bsst sitl``: the MAVLink SITL over UDP (bridge.session)."""
    p = sub.add_parser("vehicle", help="the simulated vehicle alone: a MAVLink 2 endpoint over UDP")
    p.add_argument("mission", nargs="?", help="mission TOML for the start, effects, failsafe and rates "
                                              "(default: at rest at the origin, 250 Hz)")
    p.add_argument("--profile", metavar="NAME", help="vehicle profile: paper, x500 or a profile TOML path")
    p.add_argument("--rate", type=number_in("--rate", 50.0, 1000.0), metavar="HZ",
                   help="control rate, 50-1000 Hz: one lockstep step per period")
    p.add_argument("--seed", type=int_in("--seed", 0, 2**31 - 1), metavar="N", help="seed of random effects")
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


def _add_port_options(p: argparse.ArgumentParser, vehicle: bool) -> None:
    if vehicle:
        p.add_argument("--listen", metavar="HOST:PORT",
                       help="controller link, bound (default 127.0.0.1:14560 + instance)")
    p.add_argument("--gcs", metavar="HOST:PORT", help="ground station link: telemetry goes there "
                                                       "(default 127.0.0.1:14550 + instance; 'none': no GCS link)")
    p.add_argument("--instance", type=int_in("--instance", 0, 9), default=0, metavar="N",
                   help="PX4-style instance 0-9: ports 14560 + N and 14550 + N, sysid N + 1")
    clock = p.add_mutually_exclusive_group()
    if vehicle:
        clock.add_argument("--lockstep", dest="realtime", action="store_false", help="lockstep clock (default)")
    clock.add_argument("--realtime", action="store_true", help="run on the wall clock (default lockstep)")
    p.set_defaults(realtime=False)
    p.add_argument("--speed", type=number_in("--speed", 0.0, 1000.0, lo_open=True), metavar="X",
                   help="lockstep: at most X times real time; also the pace after the controller is lost (default 1)")
    add_key_option(p)


def add_key_option(p: argparse.ArgumentParser) -> None:
    """``--key FILE``: MAVLink 2 signing (bridge.signing); the key is read from the file, never given on
    the command line, so it never shows in ``ps``."""
    p.add_argument("--key", metavar="FILE", help="sign every frame and accept only frames signed with this key: "
                                                 "a 32-byte file or a passphrase (hashed with SHA-256, as "
                                                 "MAVProxy does); not readable by others")


def _ids(text: str) -> tuple[int, int]:
    a, sep, b = text.partition(":")
    try:
        ids = (int(a), int(b))
    except ValueError:
        ids = (-1, -1)
    if not sep or not (1 <= ids[0] <= 255 and 0 <= ids[1] <= 255):
        raise argparse.ArgumentTypeError(f"--controller-id must be SYSID:COMPID (1-255:0-255), got {text!r}")
    return ids


def _home(text: str) -> tuple[float, float, float]:
    try:
        lat, lon, alt = (float(x) for x in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--home must be LAT,LON,ALT in degrees and metres, got {text!r}") from None
    if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0 and -1000.0 <= alt <= 10000.0):
        raise argparse.ArgumentTypeError(f"--home out of range (lat [-90, 90], lon [-180, 180], alt [-1000, 10000]), "
                                         f"got {text!r}")
    return lat, lon, alt


def cmd_vehicle(args: argparse.Namespace) -> int:
    from bridge.session import vehicle_from_args

    return vehicle_from_args(args)


def cmd_controller(args: argparse.Namespace) -> int:
    from bridge.session import controller_from_args

    return controller_from_args(args)


def cmd_sitl(args: argparse.Namespace) -> int:
    from bridge.session import sitl

    run = sitl(args.mission, out=args.out, write=True, overwrite=args.overwrite, plots=not args.no_plots,
               profile=args.profile, controller=args.controller, rate_hz=args.rate, seed=args.seed,
               realtime=args.realtime, instance=args.instance, gcs=args.gcs, speed=args.speed, live=True,
               link=link_table_from_args(args), key=args.key)
    print_summary(run.summary, run.path)
    return EXIT_OK if run.outcome == "completed" else EXIT_FAILED


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
        return args.func(args)
    except (UsageError, ConfigError) as exc:
        print(f"bsst: {exc}" if not str(exc).startswith("bsst") else str(exc), file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("bsst: interrupted", file=sys.stderr)
        return EXIT_FAILED


if __name__ == "__main__":
    sys.exit(main())
