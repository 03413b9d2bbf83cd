"""``bsst sim``, ``bsst sitl``, ``bsst vehicle`` and ``bsst controller``: the commands that fly (the summary
printed after a run, and its exit status: :mod:`bridge.cli.runreport`).

In:  the parsed flags (``argparse.Namespace``) of those commands; their overrides go to the layer that
     flies as one :class:`~bridge.core.overrides.Overrides` (:func:`bridge.cli.options.overrides_from_args`)
Out: the call of :func:`bridge.loop.simulate`, :func:`bridge.session.sitl`,
     :func:`bridge.nodes.vehicle.run_vehicle` or :func:`bridge.nodes.offboard.run_controller`; the run's
     summary on stdout (m, s, N, ms), violated policies on stderr; the exit status: 0 completed,
     1 failsafe/diverged/aborted, 2 bad input
"""

from __future__ import annotations

import argparse
import signal
import sys
from collections.abc import Callable
from typing import Any

from bridge.cli.flags import (
    EXIT_FAILED,
    UsageError,
    _home,
    _ids,
    as_config_error,
    int_in,
    mission_integer,
    mission_number,
    number_in,
    path_given,
    system_id,
    yes_no,
)
from bridge.cli.linkflags import add_link_options, radio_of
from bridge.cli.options import (
    add_failsafe_options,
    add_flight_options,
    add_key_option,
    add_param_options,
    add_port_options,
    add_sensor_options,
    checked_mission,
    overrides_from_args,
    refuse_vehicle_flags,
)
from bridge.cli.runreport import report_final
from params import ConfigError


def add_sim_command(sub: Any) -> None:
    """``bsst sim``: a mission flown offline, in one process (bridge.loop)."""
    p = sub.add_parser("sim", help="fly a mission offline, in one process")
    add_flight_options(p)
    add_sensor_options(p)
    add_link_options(p)
    add_fleet_options(p)
    p.set_defaults(func=cmd_sim)


def add_fleet_options(p: argparse.ArgumentParser) -> None:
    """``--vehicles N --formation KIND:METRES`` of ``bsst sim`` and ``bsst sitl`` (docs/swarm.md)."""
    g = p.add_argument_group("several vehicles (docs/swarm.md)")
    g.add_argument("--vehicles", type=fleet_size, metavar="N",
                   help="fly N vehicles (system ids 1..N), laid out by --formation, each with its own law and link")
    g.add_argument("--formation", metavar="KIND:METRES",
                   help="line:SPACING (along y), grid:SPACING or circle:RADIUS about the mission's trajectory "
                        "(default line:2)")
    g.add_argument("--shared-link", dest="link_shared", nargs="?", const=True, type=yes_no("--shared-link"),
                   metavar="true|false", help="every vehicle behind one radio: one bandwidth budget and queue each "
                   "way ([link] shared; bsst sim, and bsst sitl on either clock; bare: true)")


def fleet_size(text: str) -> int:
    """``--vehicles``: a whole number in the fleet's range (missions.fleet.FLEET_RANGES)."""
    from missions.fleet import FLEET_RANGES  # lazy: building the parser loads no mission code

    lo, hi = FLEET_RANGES["vehicles"]
    return int_in("--vehicles", int(lo), int(hi))(text)


def cmd_sim(args: argparse.Namespace) -> int:
    """``bsst sim``; a law of the user's own flies in a watched child process (bridge.nodes.watched): one that
    ends the process (a signal, a C extension's exit) ends the command exit 1, said, never exit 0 and silent.
    SIGTERM is a Ctrl-C (bridge.core.interrupt.sigterm_as_sigint): the flight ends ``aborted``, recorded, exit 1,
    whether the signal reached the process group or this process alone; the watched child is passed it as one."""
    from bridge.core.interrupt import sigterm_as_sigint  # lazy: start-up time
    from bridge.nodes.watched import run_watched  # lazy: start-up time
    from bridge.record.runlog import trace_cap  # lazy: start-up time
    from missions import load_mission  # lazy: start-up time

    with sigterm_as_sigint():
        mission = load_mission(args.mission, trace_cap(args.rate))  # once: a plan too long refused before it is timed
        laws = own_laws(args, mission)
        if not laws:
            return _sim(args, mission)
        # a stop until the fork is said (bsst: interrupted), passed on to the flight from there; once the child has
        # ended, ignored (its result this command's)
        end = run_watched(lambda: _typed_refusal(lambda: _sim(args, mission)), final=True)
    if end.signalled is not None:  # this command was ended (SIGHUP): its flight with it
        print(f"bsst sim: ended by signal {signal.Signals(end.signalled).name}", file=sys.stderr)
        return 128 + end.signalled
    if end.status is None:
        print(f"bsst sim: the flight's process ended before the flight did ({end.how}): a law of your own flew in "
              f"it ({', '.join(laws)}), and one that ends the process (a signal, os.abort(), a C extension's exit) "
              "leaves no summary.json; the run directory keeps what was written before", file=sys.stderr)
        return EXIT_FAILED
    return end.status


def _typed_refusal(work: Callable[[], int]) -> int:
    """``work()``, a usage error raised as the typed ConfigError it is said from (flags.as_config_error): a watched
    child's refusal goes back to this command's process by its fields (until the third wave's forty-fourth session by
    its text, said there after a second ``bsst: ``: ``bsst: bsst: --link-trace / --up-link-trace cannot be combined
    ...``)."""
    try:
        return work()
    except UsageError as exc:
        raise as_config_error(exc) from None


def _sim(args: argparse.Namespace, mission: Any) -> int:
    from bridge.swarm import simulate  # lazy: start-up time

    checked_mission(args, mission)  # (here: a law of the user's own is loaded in its watched process)
    run = simulate(mission, out=args.out, write=True, overwrite=args.overwrite, plots=not args.no_plots,
                   overrides=overrides_from_args(args), vehicles=args.vehicles, formation=args.formation)
    return report_final(run, "sim")


def own_laws(args: argparse.Namespace, m: Any) -> list[str]:
    """The laws of the user's own a flying command flies (not bsst, smc, pid): ``--controller``'s, else the
    mission's (``m``, a :class:`missions.Mission`) and its vehicles' (as the mission names them)."""
    from controller.law import is_builtin  # lazy: start-up time

    if args.controller is not None:
        return [] if is_builtin(args.controller) else [args.controller]
    specs = {m.controller, *(v.controller for v in m.vehicles if v.controller)}
    return sorted(s for s in specs if not is_builtin(s))


def add_sitl_commands(sub: Any) -> None:
    """``bsst vehicle``, ``bsst controller`` and ``bsst sitl``: the MAVLink SITL over UDP (bridge.session)."""
    p = sub.add_parser("vehicle", help="the simulated vehicle alone: a MAVLink 2 endpoint over UDP", reports=True)
    p.add_argument("mission", nargs="?", type=path_given("the mission"),
                   help="mission TOML for the start, effects, failsafe and rates (default: at rest at the origin, "
                        "250 Hz)")
    p.add_argument("--profile", metavar="NAME", help="vehicle profile: paper, x500 or a profile TOML path")
    p.add_argument("--rate", type=mission_number("--rate", "rate_hz"), metavar="HZ",
                   help="control rate, 50-1000 Hz: one lockstep step per period")
    p.add_argument("--seed", type=mission_integer("--seed", "seed"), metavar="N", help="seed of random effects")
    add_port_options(p, vehicle=True)
    p.add_argument("--sysid", type=system_id("--sysid"), metavar="N",
                   help="MAVLink system id (default: MAV_SYS_ID if set, else instance + 1)")
    p.add_argument("--controller-id", type=_ids, metavar="SYSID:COMPID",
                   help="the only sender of actuator targets (default 200:191)")
    p.add_argument("--controller-from", metavar="HOST:PORT",
                   help="the only address the controller's ids are heard from (bsst sitl pins it; default: "
                        "learned from the controller's first message)")
    p.add_argument("--home", type=_home, metavar="LAT,LON,ALT", help="home: degrees, degrees, m AMSL")
    p.add_argument("--await-mission", action="store_true",
                   help="take MISSION_START and AUTO.MISSION: a ground station's mission, flown by the controller")
    p.add_argument("--trace-cap", action="store_true",
                   help="with --await-mission: refuse at its start a mission longer than bsst sitl keeps in memory "
                        "(500 000 control steps; bsst sitl passes it)")
    p.add_argument("--gate", metavar="FILE", help="lockstep: step on a fleet's shared clock with the vehicles FILE "
                                                  "names (bsst sitl --vehicles writes it; docs/swarm.md)")
    _spin_option(p)
    add_failsafe_options(p)
    add_param_options(p, schedule_help="with --await-mission: refuse at its start a mission over before T s (the "
                                       "controller's --param-at, which sends the change; bsst sitl passes it)")
    add_sensor_options(p)
    p.add_argument("--out", type=path_given("--out"), metavar="DIR", help="write vehicle.tlog and vehicle.bin into DIR")
    p.add_argument("--overwrite", action="store_true", help="allow replacing those files")
    p.set_defaults(func=cmd_vehicle)

    p = sub.add_parser("controller", help="the offboard controller alone: fly a mission against a MAVLink vehicle",
                       reports=True)
    add_flight_options(p, vehicle=False)  # no failsafe of its own (the vehicle flies it), no run directory, no plots
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
    p.add_argument("--start-timeout", type=number_in("--start-timeout", 0.0, 3600.0, lo_open=True), metavar="S",
                   help="wait this long for the mission's second and third states (default: as --state-timeout; a "
                        "lockstep fleet's first steps wait for its slowest vehicle to start)")
    p.add_argument("--state-timeout", type=number_in("--state-timeout", 0.0, 3600.0, lo_open=True), metavar="S",
                   help="wait this long for each later state while the vehicle is heard (default 2 s; a lockstep "
                        "fleet's vehicle waits at its gate for a silent one)")
    _spin_option(p)
    p.add_argument("--radio", metavar="FILE", help="lockstep: the down link's states queue on a fleet's one radio "
                                                   "FILE with the other controllers' (bsst sitl --vehicles N "
                                                   "--shared-link makes it)")
    p.add_argument("--radio-user", type=int_in("--radio-user", 0, 255), metavar="N",
                   help="this controller's user number on --radio (its vehicle's place in the fleet, from 0)")
    p.add_argument("--await-mission", action="store_true",
                   help="the MISSION file gives the settings only: wait for a ground station to start the vehicle's "
                        "mission, download it and fly it")
    add_key_option(p)
    p.set_defaults(func=cmd_controller)

    p = sub.add_parser("sitl", help="fly a mission as SITL: vehicle and controller processes over MAVLink/UDP")
    add_flight_options(p, optional_mission=True)
    p.add_argument("--await-mission", action="store_true",
                   help="no mission file: fly the mission a ground station uploads and starts (MISSION_START, or "
                        "AUTO.MISSION then arm); docs/missions.md")
    add_sensor_options(p)
    add_port_options(p, vehicle=False)
    add_link_options(p)
    add_fleet_options(p)
    p.set_defaults(func=cmd_sitl)


def cmd_sitl(args: argparse.Namespace) -> int:
    from bridge.record.runlog import trace_cap  # lazy: start-up time
    from bridge.swarm import sitl  # lazy: start-up time

    own = args.mission is not None and not args.await_mission  # (a file with --await-mission: sitl refuses it)
    mission = checked_mission(args, args.mission if own else None, trace_cap(args.rate))  # once, capped as sim's
    run = sitl(mission if own else args.mission, out=args.out, write=True, overwrite=args.overwrite,
               plots=not args.no_plots, realtime=args.realtime, instance=args.instance, gcs=args.gcs, speed=args.speed,
               live=True, key=args.key, overrides=overrides_from_args(args), await_mission=args.await_mission,
               vehicles=args.vehicles, formation=args.formation)
    return report_final(run, "sitl")


# -- the two sides alone (bsst vehicle, bsst controller) ---------------------------------------------
def cmd_vehicle(args: argparse.Namespace) -> int:
    """``bsst vehicle``: the simulated vehicle alone."""
    from bridge.core.clock import lockstep_pace  # lazy: start-up time
    from bridge.core.flight import at_rest, prepare  # lazy: start-up time
    from bridge.mavlink.endpoint import CONTROLLER_COMPID, CONTROLLER_SYSID, GCS_PORT, LINK_PORT, parse_address  # lazy
    from bridge.mavlink.telemetry import Home  # lazy: start-up time
    from bridge.nodes.vehicle import VehicleConfig, run_vehicle  # lazy: start-up time
    from bridge.nodes.vehicle.gate import GateConfig  # lazy: start-up time
    from bridge.record.runlog import trace_cap  # lazy: start-up time

    refuse_vehicle_flags(args)
    mission = checked_mission(args, args.mission)  # read once (not capped: the vehicle streams its rows to disk)
    flight = prepare(mission if mission is not None else at_rest(), overrides_from_args(args))
    n = args.instance
    own = flight.params.sysid if "MAV_SYS_ID" in flight.mission.params else None  # [params] or --param
    if args.sysid is not None and own is not None and args.sysid != own:
        raise ConfigError(f"--sysid {args.sysid} and MAV_SYS_ID {own} set the vehicle's system id twice: give one")
    # (an empty value is refused by parse_address, not taken for the default)
    listen = parse_address(f"127.0.0.1:{LINK_PORT + n}" if args.listen is None else args.listen, "udpin", "--listen")
    if listen.mode != "udpin":
        raise ConfigError.at(f"--listen {args.listen!r}", None, "the controller link is bound (udpin), not udpout")
    gcs_text = f"127.0.0.1:{GCS_PORT + n}" if args.gcs is None else args.gcs
    gcs = None if gcs_text.strip().lower() == "none" else parse_address(gcs_text, "udpout", "--gcs")
    sysid, compid = args.controller_id or (CONTROLLER_SYSID, CONTROLLER_COMPID)
    pin = None
    if args.controller_from is not None:
        a = parse_address(args.controller_from, "udpout", "--controller-from")
        if a.mode != "udpout" or a.port == 0:
            raise ConfigError.at(f"--controller-from {args.controller_from!r}", None,
                                 "give the controller's HOST:PORT")
        pin = (a.host, a.port)
    cfg = VehicleConfig(listen, gcs, sysid=args.sysid or own or n + 1, controller_sysid=sysid, controller_compid=compid,
                        clock="realtime" if args.realtime else "lockstep",
                        speed=lockstep_pace(args.speed, realtime=args.realtime, await_mission=args.await_mission),
                        home=Home(*args.home) if args.home else Home(), key=_key(args), controller_from=pin,
                        await_mission=args.await_mission, trace_cap=trace_cap() if args.trace_cap else None,
                        gate=GateConfig.load(args.gate) if args.gate else None,
                        **({"spin_s": args.spin} if args.spin is not None else {}))
    if args.listen is not None and args.gcs is not None:  # no port of instance N's (a session's vehicle)
        return run_vehicle(flight, cfg, args.out, args.overwrite)
    from bridge.session.children import hold_instances  # lazy, only here: ~0.08 s a session's vehicle never pays

    # instance N's ports: its lock held while it serves; another session's refused before --out is written
    with hold_instances((n,), lambda k: f"--instance {k}"):
        return run_vehicle(flight, cfg, args.out, args.overwrite)


def cmd_controller(args: argparse.Namespace) -> int:
    """``bsst controller``: the offboard controller alone."""
    from bridge.core.flight import prepare  # lazy: start-up time
    from bridge.mavlink.endpoint import LINK_PORT, parse_address  # lazy: start-up time
    from bridge.nodes.offboard import OffboardConfig, run_controller  # lazy: start-up time

    mission = checked_mission(args, args.mission)  # read once (not capped: it streams its rows, as the vehicle)
    flight = prepare(mission, overrides_from_args(args))
    vehicle = parse_address(f"127.0.0.1:{LINK_PORT + args.instance}" if args.vehicle is None else args.vehicle,
                            "udpout", "--vehicle")
    if vehicle.mode != "udpout":
        raise ConfigError.at(f"--vehicle {args.vehicle!r}", None, "the controller sends to the vehicle (udpout)")
    if args.radio and args.realtime:
        raise ConfigError.at("--radio", None, "with --realtime: a fleet's one radio in real time is its relays' (bsst "
                             "relay --radio); the controller's is lockstep's", sep=" ")
    cfg = OffboardConfig(vehicle, sysid=args.sysid, clock="realtime" if args.realtime else "lockstep",
                         target_sysid=args.target_sysid, connect_timeout_s=args.timeout, key=_key(args),
                         source_port=args.source_port or 0, await_mission=args.await_mission,
                         start_timeout_s=args.start_timeout, state_timeout_s=args.state_timeout,
                         radio=radio_of(args),
                         **({"spin_s": args.spin} if args.spin is not None else {}))
    return run_controller(flight, cfg, args.out, args.overwrite)


def _spin_option(p: argparse.ArgumentParser) -> None:
    p.add_argument("--spin", type=number_in("--spin", 0.0, 0.01), metavar="S",
                   help="lockstep: poll this long (s) before sleeping while the other side's message is due, "
                        "while no runnable task waits for a core (default 0.0002; a bsst sitl fleet gives 0)")


def _key(args: argparse.Namespace) -> bytes | None:
    """The signing key of ``--key FILE``, if given (ConfigError: exit 2, naming the file)."""
    from bridge.mavlink.signing import key_from_file  # lazy: start-up time

    return key_from_file(args.key) if getattr(args, "key", None) else None
