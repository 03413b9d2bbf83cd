"""``bsst sim``, ``bsst sitl``, ``bsst vehicle`` and ``bsst controller``: the commands that fly, and the
summary printed after a run.

In:  the parsed flags (``argparse.Namespace``) of those commands; their overrides go to the layer that
     flies as one :class:`~bridge.core.overrides.Overrides` (:func:`bridge.cli.options.overrides_from_args`)
Out: the call of :func:`bridge.loop.simulate`, :func:`bridge.session.sitl`,
     :func:`bridge.nodes.vehicle.run_vehicle` or :func:`bridge.nodes.offboard.run_controller`; the run's
     summary on stdout (m, s, N, ms), violated policies on stderr; the exit status: 0 completed,
     1 failsafe/diverged/aborted, 2 bad input
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
from typing import Any

from bridge.cli.flags import (
    EXIT_FAILED,
    EXIT_OK,
    UsageError,
    _home,
    _ids,
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
from params import ConfigError

EVENTS_SHOWN = 16  # events a run's printed summary lists (all of summary.json's beyond: its first 6 and last 10)
SHOWN_PAIRS = 12  # pairs a fleet's printed summary lists, its closest (summary.json has every pair)


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
    from bridge.core.interrupt import ignore_sigint, sigterm_as_sigint  # lazy: start-up time
    from bridge.nodes.watched import run_watched  # lazy: start-up time
    from bridge.record.runlog import trace_cap  # lazy: start-up time
    from missions import load_mission  # lazy: start-up time

    with sigterm_as_sigint():
        mission = load_mission(args.mission, trace_cap(args.rate))  # once: a plan too long refused before it is timed
        laws = own_laws(args, mission)
        if not laws:
            return _sim(args, mission)
        ignore_sigint()  # this process only passes stops on from here (while it watches), its result the child's
        end = run_watched(lambda: _sim(args, mission), (UsageError, ConfigError))
    if end.signalled is not None:  # this command was ended (SIGHUP): its flight with it
        print(f"bsst sim: ended by signal {signal.Signals(end.signalled).name}", file=sys.stderr)
        return 128 + end.signalled
    if end.status is None:
        print(f"bsst sim: the flight's process ended before the flight did ({end.how}): a law of your own flew in "
              f"it ({', '.join(laws)}), and one that ends the process (a signal, os.abort(), a C extension's exit) "
              "leaves no summary.json; the run directory keeps what was written before", file=sys.stderr)
        return EXIT_FAILED
    return end.status


def _sim(args: argparse.Namespace, mission: Any) -> int:
    from bridge.swarm import simulate  # lazy: start-up time

    checked_mission(args, mission)  # (here: a law of the user's own is loaded in its watched process)
    run = simulate(mission, out=args.out, write=True, overwrite=args.overwrite, plots=not args.no_plots,
                   overrides=overrides_from_args(args), vehicles=args.vehicles, formation=args.formation)
    return report_final(run, "sim")


def report_final(run: Any, command: str) -> int:
    """A flying command's run, on disk: Ctrl-C ignored from here on (its lines and exit status are the run's, through
    the interpreter's exit: bridge.core.interrupt.ignore_sigint; ``main`` puts an in-process caller's handler back),
    then reported (:func:`report_fleet` or :func:`report_run`); the exit status."""
    from bridge.core.interrupt import ignore_sigint  # lazy: start-up time

    ignore_sigint()
    return report_fleet(run, command) if "vehicles" in run.summary else report_run(run, command)


def own_laws(args: argparse.Namespace, m: Any) -> list[str]:
    """The laws of the user's own a flying command flies (not bsst, smc, pid): ``--controller``'s, else the
    mission's (``m``, a :class:`missions.Mission`) and its vehicles' (as the mission names them)."""
    from controller.law import is_builtin  # lazy: start-up time

    if args.controller is not None:
        return [] if is_builtin(args.controller) else [args.controller]
    specs = {m.controller, *(v.controller for v in m.vehicles if v.controller)}
    return sorted(s for s in specs if not is_builtin(s))


def report_fleet(run: Any, command: str) -> int:
    """Print a fleet's summary (a line a vehicle, the separation), name what broke on stderr; its exit status
    (0: every vehicle completed as asked and the separation held)."""
    from bridge.record.policies import run_ok, violation_text  # lazy: numpy

    s = run.summary
    try:
        w = sys.stdout.write
        w(f"mission {s['mission']}  {len(s['vehicles'])} vehicles  clock {s['clock']}  rate {s['rate_hz']:g} Hz  "
          f"duration {s['duration_s']:.2f} s\noutcome: {s['outcome']}\n")
        for v, r in zip(s["vehicles"], run.runs, strict=True):
            rms = "n/a" if v["rms_3d"] is None else f"{v['rms_3d']:.3e} m"
            where = "its own trajectory" if v["trajectory"] == "own" else f"offset {v['offset']} m"
            w(f"vehicle {v['id']} (sysid {v['sysid']}, {v['profile']}, {where}): {v['outcome']}, "
              f"3-D RMS {rms}\n")
            w("".join("  " + line for line in event_lines(r.summary.get("events") or [])))  # its faults, gusts, end
            for c in (v.get("link") or {}).get("jitter_capped") or ():  # flown, not as asked (docs/links.md)
                from bridge.link.model import jitter_capped_text  # lazy: start-up time

                w(f"  link {jitter_capped_text(c)}\n")
        for d, r in ((d, s["radio"][d]) for d in ("up", "down") if "radio" in s):
            cap = f"of {r['rate_bps']:g} B/s (occupancy {r['occupancy']:.2f})" if r["rate_bps"] else "(no rate cap)"
            w(f"one radio, {d}: {r['share_bps']:.0f} B/s {cap}, {r['lost_queue']} queue drops; by vehicle "
              + ", ".join(f"{v['id']}: {v['share_bps']:.0f} B/s" for v in r["vehicles"]) + "\n")
        sep = s["separation"]
        least = "n/a" if sep["closest_m"] is None else f"{sep['closest_m']:.3f} m"
        w(f"separation: closest approach {least} between rotor discs (minimum {sep['min_m']:g} m)\n")
        judged = [p for p in sep["pairs"] if p["closest_m"] is not None]
        closest = sorted(judged, key=lambda p: p["closest_m"])[:SHOWN_PAIRS]  # the nearest, shown in id order
        for p in (p for p in judged if p in closest):
            w(f"  vehicles {p['ids'][0]}-{p['ids'][1]}: {p['closest_m']:.3f} m at t={p['t']:.3f} s\n")
        if len(judged) > len(closest):
            w(f"  (the {len(closest)} closest of {len(judged)} pairs: every pair in summary.json, separation.pairs)\n")
        for f in sep.get("wall_clock") or ():  # a lockstep fleet's vehicle that flew on, on the wall clock
            until = ("" if f["judged_until_t"] is None else
                     f"; judged only until t={f['judged_until_t']:.3f} s: still flying when its record ended")
            w(f"  vehicle {f['id']} flew on the wall clock from t={f['from_t']:.3f} s to t={f['to_t']:.3f} s "
              f"({f['why']}): judged on its record, matched by mission time (approximate){until}\n")
        for f in sep.get("taken_over") or ():  # a real-time fleet's vehicle that flew on under a ground station
            until = ("" if f["judged_until_t"] is None else
                     f"; judged only until t={f['judged_until_t']:.3f} s: still flying when its record ended")
            w(f"  vehicle {f['id']} {f['why']} at t={f['from_t']:.3f} s flew on under it to t={f['to_t']:.3f} s: "
              f"judged on its record, matched by step (approximate){until}\n")
        for f in sep.get("alone") or ():  # an offline fleet's vehicle landing alone after the mission (its failsafe)
            w(f"  vehicle {f['id']} flew alone from t={f['from_t']:.3f} s to t={f['to_t']:.3f} s ({f['why']}): judged "
              "at every step, told nothing (a contact there found, not prevented)\n")
        if run.path is not None:
            w(f"run directory: {run.path}\n")
        sys.stdout.flush()
    except BrokenPipeError:  # stdout closed early: the run is on disk, its status stands
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    for v in s["vehicles"]:
        if v["outcome"] != "completed":
            c = v.get("contact")  # SITL: lockstep, both flights ended there; real time, they went on past it
            went = ("; both flights ended there" if not c or not c.get("continued") else
                    "; the flights went on: in real time the vehicles share no clock" if s["clock"] == "realtime" else
                    "; the flights went on: found afterwards, one of them in its failsafe's landing, flown alone"
                    if s["clock"] == "offline" else
                    "; the flights went on: found afterwards, one of them flying on the wall clock")
            eb = v.get("ended_by") or {}
            said = (f" (touched vehicle {c['with']} at step {c['step']}, t={c['t']:.3f} s{went})" if c
                    else f": ended by {eb['who']}: {eb['how']}" if eb else "")
            print(f"bsst {command}: vehicle {v['id']}: {v['outcome']}{said}", file=sys.stderr)
    for p in s.get("policies") or []:
        if p.get("not_judged") is not None and p.get("why") == p["not_judged"]:  # held while judged, not throughout
            print(f"bsst {command}: policy {p['name']} {p['not_judged']}", file=sys.stderr)
        elif not p.get("ok"):
            print(f"bsst {command}: policy {violation_text(p)}", file=sys.stderr)
    # a lockstep fleet on one radio whose states entered out of turn (a controller waited too long for another)
    late = {i: ks for i, ks in ((s.get("radio") or {}).get("late_turns") or {}).items() if ks}
    for i, ks in late.items():
        print(f"bsst {command}: vehicle {i}: its states of steps {', '.join(map(str, ks))} entered the radio out of "
              "turn: not the offline fleet's flight", file=sys.stderr)
    ok = run_ok(s) and all(v["ok"] for v in s["vehicles"]) and not late
    return EXIT_OK if ok else EXIT_FAILED


def report_run(run: Any, command: str) -> int:
    """Print a run's summary, name each violated policy on stderr; its exit status (0: a clean completion)."""
    from bridge.record.interventions import intervention_text, unconfirmed_text  # lazy: numpy
    from bridge.record.policies import run_ok, stalls_of, violation_text  # lazy: numpy
    from bridge.record.summary import stalls_text  # lazy: numpy

    try:
        print_summary(run.summary, run.path)
        sys.stdout.flush()
    except BrokenPipeError:  # stdout closed early (bsst sim ... | head): the run is on disk, its status stands
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    lock = run.summary.get("lockstep") or {"held": True}
    if not lock.get("held", True):
        print(f"bsst {command}: not a lockstep run: the vehicle left lockstep at t={lock['left_at_s']:.3f} s "
              f"({lock['why']})", file=sys.stderr)
    for i in run.summary.get("interventions") or []:  # exit 1: the run did not fly as the command asked
        print(f"bsst {command}: not flown as asked: {intervention_text(i)}", file=sys.stderr)
    for p in run.summary.get("param_at") or []:
        if not p.get("confirmed"):
            print(f"bsst {command}: not flown as asked: {unconfirmed_text(p)}", file=sys.stderr)
    stalls = stalls_of(run.summary)
    if stalls is not None:
        print(f"bsst {command}: {stalls_text(stalls)}", file=sys.stderr)
    for v in run.summary.get("policies") or []:
        if not v.get("ok"):
            print(f"bsst {command}: policy {violation_text(v)}", file=sys.stderr)
    return EXIT_OK if run_ok(run.summary) else EXIT_FAILED



def event_lines(events: list[dict[str, Any]]) -> list[str]:
    """A run's events as its printed summary lists them: all up to :data:`EVENTS_SHOWN`; beyond, the first 6 and
    the last 10 (a session opens with five start-up events, and the end is what a user looks for) and a line
    saying how many more ``summary.json`` holds."""
    lines = [f"event t={'n/a' if e['t'] is None else format(e['t'], '.3f')} {e['kind']}: {e['text']}\n" for e in events]
    if len(lines) <= EVENTS_SHOWN:
        return lines
    return [*lines[:6], f"event … {len(lines) - EVENTS_SHOWN} more (summary.json)\n", *lines[6 - EVENTS_SHOWN:]]


def print_summary(s: dict[str, Any], path: Any, stream: Any = None) -> None:
    """The one-screen summary printed after a run."""
    from bridge.link.model import jitter_capped_text  # lazy: start-up time
    from bridge.record.metrics import air_text  # lazy: numpy (loaded by the run this sums up)
    from bridge.record.policies import violation_text  # lazy: numpy
    from bridge.record.summary import stalls_text  # lazy: numpy

    out = stream or sys.stdout
    w = out.write
    w(f"mission {s['mission']}  controller {s['controller']}  profile {s['profile']}  "
      f"clock {s['clock']}  rate {s['rate_hz']:g} Hz  duration {s['duration_s']:.2f} s\n")
    w(f"outcome: {s['outcome']}\n")
    end = s.get("ended_by")
    if end and (end.get("who"), end.get("how")) != ("mission", "completed"):
        w(f"ended by {end['who']}: {end['how']}\n")
    for late in (end or {}).get("not_reached", ()):  # scheduled, never flown: the flight had ended
        w(f"not reached: {late}\n")
    lock = s.get("lockstep")
    if lock and not lock.get("held", True):
        w(f"left lockstep at t={lock['left_at_s']:.3f} s: {lock['why']} (flown on from there on the wall clock: "
          "not a lockstep run)\n")
    elif lock and lock.get("reproducible") is False:
        w(f"lockstep held, reproducible until step {lock['reproducible_until_step']}: {lock['because']}\n")
    for i in s.get("interventions") or []:
        w(f"not flown as asked: a ground station ({i['by']}) at t={i['t']:.3f} s (step {i['step']})"
          f"{', before the start' if i.get('before_start') else ''}: "
          + (f"{i['name']} = {i['new']:g} (was {i['old']:g})\n" if "name" in i else f"{i['kind']} {i['what']}\n"))
    if (s.get("timing") or {}).get("stalls", {}).get("count"):  # a real-time run the machine stalled
        w(stalls_text(s["timing"]["stalls"]) + "\n")
    rms = s.get("rms_3d")
    w(f"3-D RMS error over t >= {s['rms_from_s']:g} s: {rms:.3e} m\n" if rms is not None else "3-D RMS: n/a\n")
    w(f"{'axis':5} {'rms':>10} {'max':>10} {'settling_s':>11} {'bound_s':>9}\n")
    for a, v in s["axes"].items():
        def f(x: Any, spec: str) -> str:
            return format(x, spec) if x is not None else format("n/a", ">" + spec.split(".")[0])
        w(f"{a:5} {f(v['rms'], '10.3e')} {f(v['max'], '10.3e')} "
          f"{f(v['settling_s'], '11.3f')} {f(v['bound_s'], '9.3f')}\n")
    inputs = [f"{u}: [{v['min']:.3g}, {v['max']:.3g}] tv/s {v['tv_per_s']:.3g}"
              + (f" p2 {v['period2']:.3g}" if v.get("period2") is not None else "")
              for u, v in s["inputs"].items() if v["min"] is not None]
    w("input  " + ("  ".join(inputs) or "n/a (nothing flew)") + "\n")
    if s.get("wind"):  # the air flown (its events are the event lines)
        w(air_text(s["wind"]) + "\n")
    link = s.get("link", {})
    if any(L.get("lost") or L.get("duplicated") or L.get("reordered") or L.get("in_flight")  # (held: a delay)
           or (L.get("delay_ms") or {}).get("max") for L in (link.get("up", {}), link.get("down", {}))):
        for d in ("up", "down"):
            L = link[d]
            ms = {k: "n/a" if v is None else f"{v:.2f}" for k, v in L["delay_ms"].items()}
            more = "".join(f" {name} {L[key]}" for key, name in (("in_flight", "in flight"), ("shed", "shed"),
                                                                  ("dropped_by_kernel", "dropped by kernel"))
                           if key in L)
            w(f"link {d:4}: sent {L['sent']} delivered {L['delivered']} lost {L['lost']}{more} dup {L['duplicated']} "
              f"reordered {L['reordered']} delay p50 {ms['p50']} ms p99 {ms['p99']} ms max {ms['max']} ms\n")
    for c in link.get("jitter_capped") or []:
        w(f"link {jitter_capped_text(c)}\n")
    for line in event_lines(s.get("events", [])):
        w(line)
    policies = s.get("policies") or []
    broken = [v for v in policies if not v.get("ok")]
    if policies:
        w(f"policies: all {len(policies)} hold\n" if not broken else
          "".join(f"policy {violation_text(v)}\n" for v in broken))
    if path is not None:
        w(f"run directory: {path}\n")



def add_sitl_commands(sub: Any) -> None:
    """``bsst vehicle``, ``bsst controller`` and ``bsst sitl``: the MAVLink SITL over UDP (bridge.session)."""
    p = sub.add_parser("vehicle", help="the simulated vehicle alone: a MAVLink 2 endpoint over UDP")
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

    p = sub.add_parser("controller", help="the offboard controller alone: fly a mission against a MAVLink vehicle")
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
        raise ConfigError(f"--listen {args.listen!r}: the controller link is bound (udpin), not udpout")
    gcs_text = f"127.0.0.1:{GCS_PORT + n}" if args.gcs is None else args.gcs
    gcs = None if gcs_text.strip().lower() == "none" else parse_address(gcs_text, "udpout", "--gcs")
    sysid, compid = args.controller_id or (CONTROLLER_SYSID, CONTROLLER_COMPID)
    pin = None
    if args.controller_from is not None:
        a = parse_address(args.controller_from, "udpout", "--controller-from")
        if a.mode != "udpout" or a.port == 0:
            raise ConfigError(f"--controller-from {args.controller_from!r}: give the controller's HOST:PORT")
        pin = (a.host, a.port)
    cfg = VehicleConfig(listen, gcs, sysid=args.sysid or own or n + 1, controller_sysid=sysid, controller_compid=compid,
                        clock="realtime" if args.realtime else "lockstep",
                        speed=lockstep_pace(args.speed, realtime=args.realtime, await_mission=args.await_mission),
                        home=Home(*args.home) if args.home else Home(), key=_key(args), controller_from=pin,
                        await_mission=args.await_mission, trace_cap=trace_cap() if args.trace_cap else None,
                        gate=GateConfig.load(args.gate) if args.gate else None,
                        **({"spin_s": args.spin} if args.spin is not None else {}))
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
        raise ConfigError(f"--vehicle {args.vehicle!r}: the controller sends to the vehicle (udpout)")
    if args.radio and args.realtime:
        raise ConfigError("--radio with --realtime: a fleet's one radio in real time is its relays' (bsst relay "
                          "--radio); the controller's is lockstep's")
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
