"""The summary printed after a run of ``bsst sim`` or ``bsst sitl`` (one vehicle, or a fleet), and its exit status.

In:  a finished :class:`~bridge.record.runlog.Run` (its ``summary.json`` as a dict: m, s, Hz; a fleet's with its
     ``vehicles`` and ``separation`` blocks, and its runs) and the command's name (``sim``, ``sitl``)
Out: the one-screen summary on stdout (m, s, N, ms), what broke (violated policies, interventions, stalls, a
     vehicle's outcome) on stderr, one line each ``bsst <command>: ...``; the exit status: 0 a clean completion,
     1 otherwise

Split out of :mod:`bridge.cli.flying` (which parses the flying commands and flies them): how a run is told is here.
"""

from __future__ import annotations

import os
import sys
from typing import Any

from bridge.cli.flags import EXIT_FAILED, EXIT_OK
from bridge.record.asked import ended_text, not_as_asked, stalls_text, waited_text

EVENTS_SHOWN = 16  # events a run's printed summary lists (all of summary.json's beyond: its first 6 and last 10)
SHOWN_PAIRS = 12  # pairs a fleet's printed summary lists, its closest (summary.json has every pair)


def report_final(run: Any, command: str) -> int:
    """A flying command's run, on disk: Ctrl-C ignored from here on (its lines and exit status are the run's, through
    the interpreter's exit: bridge.core.interrupt.ignore_sigint; ``main`` puts an in-process caller's handler back),
    then reported (:func:`report_fleet` or :func:`report_run`); the exit status."""
    from bridge.core.interrupt import ignore_sigint  # lazy: start-up time

    ignore_sigint()
    return report_fleet(run, command) if "vehicles" in run.summary else report_run(run, command)


def report_fleet(run: Any, command: str) -> int:
    """Print a fleet's summary (a line a vehicle, the separation), name what broke on stderr; its exit status
    (0: every vehicle completed as asked and the separation held)."""
    from bridge.record.policies import run_ok, violation_text  # lazy: numpy

    s = run.summary
    try:
        w = sys.stdout.write
        n = len(s["vehicles"])
        w(f"mission {s['mission']}  {n} vehicle{'' if n == 1 else 's'}  clock {s['clock']}  rate {s['rate_hz']:g} Hz  "
          f"duration {duration_text(s)}\noutcome: {s['outcome']}\n")
        for v, r in zip(s["vehicles"], run.runs, strict=True):
            rms = "n/a" if v["rms_3d"] is None else f"{v['rms_3d']:.3e} m"
            where = "its own trajectory" if v["trajectory"] == "own" else f"offset {v['offset']} m"
            w(f"vehicle {v['id']} (sysid {v['sysid']}, {v['profile']}, {where}): {v['outcome']}, "
              f"3-D RMS {rms}\n")
            w("".join("  " + line for line in _vehicle_lines(r.summary)))
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
            said = (f"{v['outcome']} (touched vehicle {c['with']} at step {c['step']}, t={c['t']:.3f} s{went})" if c
                    else ended_text(v))
            print(f"bsst {command}: vehicle {v['id']}: {said}", file=sys.stderr)
    for v, r in zip(s["vehicles"], run.runs, strict=True):  # as one vehicle's run names them (its policies: below)
        for why in not_as_asked(r.summary):
            print(f"bsst {command}: vehicle {v['id']}: {why}", file=sys.stderr)
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


def _vehicle_lines(s: dict[str, Any]) -> list[str]:
    """What a fleet's printed summary says under a vehicle's line, as one vehicle's summary says it: why it was not
    flown as asked, its link, its events (its faults, gusts, failsafe, end), its policies."""
    return ([f"{why}\n" for why in not_as_asked(s)] + link_lines(s.get("link") or {})
            + event_lines(s.get("events") or []) + policy_lines(s.get("policies") or []))


def report_run(run: Any, command: str) -> int:
    """Print a run's summary, name on stderr a stop that ended it and each reason it was not flown as asked or
    violated policy; its exit status (0: a clean completion)."""
    from bridge.record.policies import run_ok, violation_text  # lazy: numpy

    try:
        print_summary(run.summary, run.path)
        sys.stdout.flush()
    except BrokenPipeError:  # stdout closed early (bsst sim ... | head): the run is on disk, its status stands
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    ended = ended_text(run.summary)
    if ended is not None:  # a failsafe, a divergence, a stop (Ctrl-C, SIGTERM), ...: named, as every exit-1 reason is
        print(f"bsst {command}: {ended}", file=sys.stderr)
        if (waited := waited_text(run.summary)) is not None:  # (not the mission's stall: what may have ended it)
            print(f"bsst {command}: {waited}", file=sys.stderr)
    for why in not_as_asked(run.summary):
        print(f"bsst {command}: {why}", file=sys.stderr)
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
    from bridge.record.ending import not_taken_text  # lazy: numpy
    from bridge.record.metrics import air_text  # lazy: numpy (loaded by the run this sums up)

    out = stream or sys.stdout
    w = out.write
    w(f"mission {s['mission']}  controller {s['controller']}  profile {s['profile']}  "
      f"clock {s['clock']}  rate {s['rate_hz']:g} Hz  duration {duration_text(s)}\n")
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
    if not (s.get("end") or {}).get("taken", True):  # the vehicle never took the mission's end action
        w(f"not flown as asked: {not_taken_text(s['end'])}\n")
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
    w("".join(link_lines(s.get("link", {}))))
    for line in event_lines(s.get("events", [])):
        w(line)
    w("".join(policy_lines(s.get("policies") or [])))
    if path is not None:
        w(f"run directory: {path}\n")


def duration_text(s: dict[str, Any]) -> str:
    """The header's duration: the mission's time flown (``duration_s``), and the mission's own length beside it
    when the flight was cut short (a child killed at 2.2 s of 8 s read ``duration 2.23 s`` alone until the third
    wave's forty-second session)."""
    flown, asked = s["duration_s"], s.get("mission_duration_s")
    short = asked is not None and flown < asked - 0.5 / s["rate_hz"]
    return f"{flown:.2f} s" + (f" of the mission's {asked:g} s (cut short)" if short else "")


def link_lines(link: dict[str, Any]) -> list[str]:
    """A run's link as its printed summary says it: each direction's counts and delays when the link model did
    anything (lost, duplicated, reordered, held, delayed), and each jitter it capped (docs/links.md)."""
    from bridge.link.model import jitter_capped_text  # lazy: start-up time

    lines = []
    if any(L.get("lost") or L.get("duplicated") or L.get("reordered") or L.get("in_flight")  # (held: a delay)
           or (L.get("delay_ms") or {}).get("max") or "counted" in L or "unknown" in L
           for L in (link.get("up", {}), link.get("down", {}))):
        for d in ("up", "down"):
            L = {k: "n/a" if v is None else v for k, v in link[d].items()}  # null: not known (a side killed)
            ms = {k: "n/a" if v is None else f"{v:.2f}" for k, v in link[d]["delay_ms"].items()}
            more = "".join(f" {name} {L[key]}" for key, name in (("in_flight", "in flight"), ("shed", "shed"),
                                                                  ("dropped_by_kernel", "dropped by kernel"))
                           if key in L)
            lines.append(f"link {d:4}: sent {L['sent']} delivered {L['delivered']} lost {L['lost']}{more} dup "
                         f"{L['duplicated']} reordered {L['reordered']} delay p50 {ms['p50']} ms p99 {ms['p99']} ms "
                         f"max {ms['max']} ms\n")
            for key in ("counted", "unknown"):  # a side killed: how far the counts go, or why there are none
                if key in L:
                    lines.append(f"link {d:4}: {key}: {L[key]}\n")
    return lines + [f"link {jitter_capped_text(c)}\n" for c in link.get("jitter_capped") or []]


def policy_lines(policies: list[dict[str, Any]]) -> list[str]:
    """A run's policies as its printed summary says them: that all hold, or each one violated."""
    from bridge.record.policies import violation_text  # lazy: numpy

    broken = [v for v in policies if not v.get("ok")]
    if broken:
        return [f"policy {violation_text(v)}\n" for v in broken]
    return [f"policies: all {len(policies)} hold\n"] if policies else []
