"""``bsst link extract | fit | show`` and ``bsst relay``: measured links and the real-time relay.

In:  the parsed flags (``argparse.Namespace``): a run directory or two tlogs, a trace CSV (``t_s`` s,
     ``delay_ms`` ms), ``--blackout-after`` s; the relay's addresses (HOST:PORT), ``--duration`` s and
     the link flags
Out: a trace file, a link profile (TOML), a figure (PNG), each direction's figures on stdout (delays
     ms, loss %); the relay's datagrams and its statistics (stdout, ``--stats`` JSON); the exit status:
     0 done, 1 the statistics not written, 2 bad input
"""

from __future__ import annotations

import argparse
import signal
import sys
from collections.abc import Sequence
from typing import Any

from bridge.cli.flags import (
    EXIT_OK,
    UsageError,
    _Parser,
    int_in,
    number_in,
    path_given,
)
from bridge.cli.linkflags import add_link_options, radio_of
from bridge.cli.options import checked_mission, overrides_from_args
from params import ConfigError, inputs_read


def add_link_commands(sub: Any) -> None:
    """``bsst link extract | fit | show``: a trace from a run or two tlogs, the model that fits it, its figure."""
    p = sub.add_parser("link", help="measured links: extract a trace, fit the link model to it, plot it")
    acts = p.add_subparsers(dest="link_command", metavar="ACTION", parser_class=_Parser)
    acts.required = True
    e = acts.add_parser("extract", help="per-packet delays and losses of both directions, as a trace file")
    e.add_argument("source", nargs="+", type=path_given("a source"), metavar="RUN_DIR | VEHICLE.tlog CONTROLLER.tlog",
                   help="a real-time run directory, or the tlogs of the vehicle's end and the controller's end")
    e.add_argument("--out", type=path_given("--out"),
                   metavar="FILE", help="the trace (default RUN_DIR/link-trace.csv, or ./link-trace.csv)")
    e.add_argument("--clock", choices=("same", "timesync"), default="same",
                   help="same: both tlogs stamped on one clock (one host, or hosts kept in sync); timesync: the "
                        "offset from the TIMESYNC exchanges (equal one-way delays assumed)")
    e.add_argument("--overwrite", action="store_true", help="replace an existing --out")
    e.set_defaults(func=cmd_link_extract)
    f = acts.add_parser("fit", help="the [link] table that fits a trace best, as a link profile (TOML)")
    f.add_argument("trace", metavar="TRACE", type=path_given("the trace"),
                   help="trace CSV (t_s, delay_ms, optional direction)")
    f.add_argument("--out", type=path_given("--out"), metavar="FILE", help="write the profile here (default: print it)")
    f.add_argument("--blackout-after", type=number_in("--blackout-after", 0.0, 1e6, lo_open=True), default=1.0,
                   metavar="S", help="a loss run this long or longer is a blackout, listed apart (default 1 s)")
    f.add_argument("--overwrite", action="store_true", help="replace an existing --out")
    f.set_defaults(func=cmd_link_fit)
    s = acts.add_parser("show", help="plot a trace: delay over time, loss bursts, delay histogram (PNG)")
    s.add_argument("trace", metavar="TRACE", type=path_given("the trace"),
                   help="trace CSV (t_s, delay_ms, optional direction)")
    s.add_argument("--out", type=path_given("--out"), metavar="FILE.png", help="the figure (default: TRACE with .png)")
    s.add_argument("--overwrite", action="store_true", help="replace an existing --out")
    s.set_defaults(func=cmd_link_show)



def _new_output(path: Any, flag: str, overwrite: bool, inputs: Sequence[Any] = ()) -> Any:
    """``path`` as a file this command may write: writable, new unless ``--overwrite``, and none of the
    ``inputs`` it reads (real paths compared: ``--overwrite`` would destroy it); exit 2 otherwise."""
    import os  # lazy: with the command

    from bridge.record.runlog import check_writable  # lazy: start-up time

    p = check_writable(path, flag)
    if p.exists() and not overwrite:  # (typed, source the flag and its path: as every flag's refusal)
        raise ConfigError.at(f"{flag} {p}", None, "exists; --overwrite to replace it")
    for f in inputs:
        if os.path.realpath(f) == os.path.realpath(p):
            raise ConfigError.at(f"{flag} {p}", None, f"is {f}, an input of this command, which writing would "
                                 "destroy; write the output elsewhere")
    return p



def cmd_link_extract(args: argparse.Namespace) -> int:
    """``bsst link extract``: write the trace, print each direction's figures."""
    from pathlib import Path  # lazy: with the command

    from bridge.record.linkextract import (  # lazy
        RUN_INPUTS,
        check_run_dir,
        extract_run_dir,
        extract_tlogs,
        extraction_text,
    )
    from bridge.record.runlog import write_text_atomic  # lazy: start-up time
    from bridge.record.tlogmatch import read_tlog  # lazy

    src = args.source
    if len(src) not in (1, 2):
        raise UsageError("bsst link extract", "give a run directory, or a vehicle tlog and a controller tlog")
    if len(src) == 2 and Path(src[0]).resolve() == Path(src[1]).resolve():
        raise UsageError("bsst link extract", f"{src[0]} given as both ends: the same file twice")
    if len(src) == 1:
        check_run_dir(src[0])  # before the --out it would name: what is wrong is the argument given
    read = [Path(src[0]) / f for f in RUN_INPUTS] if len(src) == 1 else src
    out = _new_output(args.out or (Path(src[0]) / "link-trace.csv" if len(src) == 1 else "link-trace.csv"),
                      "--out", args.overwrite, read)
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

    out = _new_output(args.out, "--out", args.overwrite, [args.trace]) if args.out else None
    tf = read_trace(args.trace)
    fits = fit_trace(tf, args.blackout_after)
    text = fit_toml(fits, str(Path(args.trace).absolute()))
    for d, note in ((d, n) for d, f in fits.items() for n in f.clamped()):  # what the model's ranges cut
        print(f"bsst link fit: warning: {d}: {note}", file=sys.stderr)
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
        raise ConfigError.at(f"--out {out}", None, "the figure is a PNG (name it *.png)")
    _new_output(out, "--out", args.overwrite, [args.trace])
    tf = read_trace(args.trace)
    print(f"figure: {trace_figure(tf, out)}")
    return EXIT_OK



def add_relay_command(sub: Any) -> None:
    """``bsst relay``: the real-time UDP relay applying the link model on the wall clock (bridge.nodes.relay)."""
    p = sub.add_parser("relay", help="relay UDP both ways between two endpoints through the link model", reports=True)
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
    p.add_argument("--stats", type=path_given("--stats"), metavar="FILE",
                   help="write the statistics to FILE as JSON on exit (and every 0.5 s while relaying, so that a "
                        "kill leaves them); a new file, never one the relay reads")
    p.add_argument("--overwrite", action="store_true", help="replace an existing --stats")
    p.add_argument("--mission-clock", action="store_true",
                   help="blackout times count from the flight's time 0 (when the state the first actuator target "
                        "up answers came from the vehicle) instead of the relay's start")
    p.add_argument("--radio", metavar="FILE", help="share each direction's bandwidth and queue with other relays "
                                                   "through this radio file (a fleet's one radio in real time: "
                                                   "bsst sitl --vehicles N --shared-link --realtime makes it)")
    p.add_argument("--radio-user", type=int_in("--radio-user", 0, 255), metavar="N",
                   help="this relay's user number on --radio (its vehicle's place in the fleet, from 0)")
    add_link_options(p, controller=False)  # the relay models the link; compensation and guards are the controller's
    p.set_defaults(func=cmd_relay)



def cmd_relay(args: argparse.Namespace) -> int:
    """``bsst relay``: relay until SIGINT/SIGTERM or ``--duration``; print (and ``--stats``) the figures."""
    from bridge.core.flight import Span, at_rest, prepare  # lazy: start-up time
    from bridge.link.model import jitter_capped_text  # lazy: start-up time
    from bridge.nodes.relay import Relay, client_event, forwards_to_itself, parse_address  # lazy: start-up time
    from bridge.nodes.report import to_line  # lazy: start-up time
    from bridge.record.runlog import write_json_atomic  # lazy: start-up time

    listen = parse_address(args.listen, "--listen", bind=True)  # (a ConfigError naming the flag: as every flag's)
    target = parse_address(args.to, "--to")
    client = parse_address(args.client, "--client") if args.client else None
    if forwards_to_itself(listen, target):
        raise ConfigError.at(f"--to {args.to}", None, f"is the relay's own --listen {args.listen}: it would forward "
                             "into itself", sep=" ")
    mission = checked_mission(args, args.mission or None)  # read once; a link flag that would change nothing: as
    # bsst sim refuses it. The one path from a mission and its overrides to the parts: the whole mission is checked
    # (a key of its [link] that would change nothing too), and the relay flies the link it gives
    # without a mission the relay's run is its flight: --duration, else a day (a trace must last it, a blackout start
    # in it: until the forty-fourth session a 200 s trace with --duration 30 was refused as shorter than "the mission
    # (86400 s)", and a blackout after --duration relayed, exit 0, never happening), and its refusals say so
    run = ("run without --duration" if not args.duration else "--duration" if args.duration <= 86400.0
           else "run (a day at most)")
    span = Span() if mission is not None else Span(f"the relay's {run}", "the relay's end", run)
    settings = prepare(mission if mission is not None else at_rest(args.duration or 86400.0),
                       overrides_from_args(args), span=span).link
    if args.stats is not None:  # bad input now, not a failure after relaying; and never a file it reads (its
        # mission, trace, profile: params.inputs_read; the fleet's radio it writes in place)
        read = [*inputs_read().values(), *([args.radio] if args.radio else [])]
        _new_output(args.stats, "--stats", args.overwrite, read)

    if args.radio and settings.handovers:  # (as bsst sim refuses a fleet on one radio with handovers)
        raise ConfigError.at(f"--radio {args.radio}", None, "the link has handovers (events of kind link); a shared "
                             "radio takes none: not modelled yet")

    def learned(addr: Any) -> None:  # a report (bridge.nodes.report): the session logs the event
        print(to_line(client_event(addr, args.listen_direction)), flush=True)

    try:
        relay = Relay(listen, target, settings, listen_direction=args.listen_direction,
                      mission_clock=args.mission_clock, client=client, on_client=learned,
                      back_port=args.back_port or 0, stats_path=args.stats,
                      radio=radio_of(args))
    except OSError as exc:
        where = f"--listen {args.listen}" + (f" or --back-port {args.back_port}" if args.back_port else "")
        raise ConfigError.at(where, None, f"cannot bind ({exc.strerror or exc})") from None
    stop = relay.stop
    old = {s: signal.signal(s, lambda *_: stop()) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        print(to_line(relay.ready(settings)), flush=True)
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
        drops = (summary.get("kernel_drops") or {}).get(d)
        print(f"{d:4}: sent {s['sent']} delivered {s['delivered']} lost {s['lost']} in flight {s['in_flight']} "
              f"dropped by kernel {'n/a' if drops is None else drops} dup {s['duplicated']} "
              f"reordered {s['reordered']}; added delay p50 {fmt['p50']} ms p99 {fmt['p99']} ms max {fmt['max']} ms")
    for c in settings.jitter_capped():
        print(jitter_capped_text(c))
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

