"""``bsst controller``: one offboard controller's flight from its start to its exit status.

In:  the :class:`~bridge.core.flight.Flight`, the controller's settings (:class:`OffboardConfig`), the run
     directory (or None), whether to overwrite it
Out: the ``stats`` and ``done`` reports on stdout (JSON lines, :mod:`bridge.nodes.report`), what did not go as
     asked on stderr (``not flown as asked: ...`` in ``bsst sitl``'s words, :mod:`bridge.record.asked`), and the exit
     status: 0 the mission completed in lockstep (or on the wall clock) with every scheduled change confirmed, its
     end action answered as taken and (real time) none of its ticks in the mission stalled by the machine, else 1
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

from pymavlink.dialects.v20.common import MAV_SEVERITY_WARNING

from bridge.core.flight import Flight
from bridge.nodes.offboard.config import OffboardConfig
from bridge.nodes.offboard.flight import Offboard
from bridge.nodes.process import on_stop_signals, report_printer
from bridge.nodes.report import Done, Stats, StatusText
from bridge.record.asked import not_as_asked, waiting_stalls_text
from bridge.record.runlog import side_dir

WARNED = 3  # the vehicle's first distinct warnings a failed end repeats on stderr


def run_controller(flight: Flight, cfg: OffboardConfig, out: str | Path | None = None,
                   overwrite: bool = False) -> int:
    """``bsst controller``: fly, then exit 0 if the mission completed (in lockstep: without the vehicle
    leaving it) as asked, else 1 (failsafe, diverged, aborted, lockstep left, a scheduled change unconfirmed, the
    end action not answered as taken, a tick the machine stalled)."""
    path = side_dir(out, ("controller.tlog", "controller.bin"), overwrite) if out is not None else None
    warned: list[str] = []  # the vehicle's first few distinct WARNING-or-worse STATUSTEXTs, said on a failed end
    printed = report_printer()

    def emit(report: Any) -> None:
        if isinstance(report, StatusText) and report.severity <= MAV_SEVERITY_WARNING and len(warned) < WARNED \
                and report.text not in warned:
            warned.append(report.text)
        printed(report)

    transfer = vehicle = None
    if cfg.await_mission:  # a ground station's mission: waited for, downloaded, flown (bridge.nodes.offboard.mission)
        from bridge.nodes.offboard.mission import mission_flight  # lazy: only for --await-mission

        got, transfer, vehicle = mission_flight(flight, cfg, path, emit)
        if got is None:
            return 1
        flight = got
    node = Offboard(flight, cfg, path, emit, vehicle)
    on_stop_signals(node.stop)
    outcome = node.run()
    unconfirmed = node.unconfirmed_params()
    emit(Stats({"param_at": [p.as_dict() for p in node.param_sets],
                "commands": node.commands, "targets_left": [list(t) for t in node.targets_left],  # their sends' times
                "states": node.states, "received": node.ep.received,
                "sent": node.ep.sent, "stale_ticks": node.stale_ticks, "overruns": node.overruns,
                "stalls": node.stalls.report(),
                "stalls_waiting": node.stalls_waiting.report(),  # before the mission's first state: not its own
                "way_down": node.way_down,  # real time: the states' way down counted in their ages, ms (or None)
                "spin_skipped": node.spinner.skipped,
                "down": node.cend.down.stats.summary() if cfg.clock == "lockstep" else None,
                **({"radio": node.turns.stats()} if node.turns is not None else {}),  # its part of the fleet's radio
                "rejected": dict(node.rejected), "rejected_from_vehicle": node.rejected.from_peer,
                "states_refused": node.states_refused, "state_window": node.state_window, "read_until": node.read_until,
                "kernel_drops": node.ep.kernel_drops(), "mission_transfer": transfer,
                "events": node.event_seq.counts.as_dict()}))  # the vehicle's EVENTs missed, asked for, recovered
    left = bool(node.left_lockstep)
    emit(Done(outcome, left, node.reason or None, node.taken_over if node.ended_taken_over else None,
              node.vehicle_silent))
    if outcome != "completed":
        sys.stderr.write(f"bsst controller: {outcome}" + (f": {node.reason}" if node.reason else "") + "\n")
        if node.disarmed_early is not None:  # (real time: it ended there, not at the mission's end)
            sys.stderr.write(f"bsst controller: the vehicle's failsafe disarmed it by t={node.disarmed_early:.3f} s of "
                             f"the mission's {flight.mission.duration_s:g} s, no [failsafe] resume to arm it again: "
                             f"nothing left to fly, so the controller ended there (not flown as asked)\n")
        sys.stderr.writelines(f"bsst controller: the vehicle warned: {text}\n" for text in warned)
        if node.stalls_waiting.count:  # not the mission's, but what may have ended it (the vehicle's failsafe)
            sys.stderr.write(f"bsst controller: {waiting_stalls_text(node.stalls_waiting.report())}\n")
    elif left:
        sys.stderr.write(f"bsst controller: completed, but not in lockstep: said by {node.left_lockstep}\n")
    # what it alone knows of sitl's "not flown as asked" (bridge.record.asked), said in the same words: a scheduled
    # change unconfirmed, an end action not seen taken (lost on the wire: the vehicle left to its failsafe), its own
    # ticks the machine stalled in the mission (real time)
    stalls = own_stalls(flight, node.stalls.report())
    said = (not_as_asked({"param_at": [p.as_dict() for p in unconfirmed], "end": node.end_unanswered,
                          "timing": {"stalls": stalls}})
            if unconfirmed or node.end_unanswered or stalls else [])  # (a clean end imports none of its readers)
    for why in said:
        sys.stderr.write(f"bsst controller: {why}\n")
    return 0 if outcome == "completed" and not left and not said else 1


def own_stalls(flight: Flight, stalls: dict[str, Any]) -> dict[str, Any] | None:
    """The controller's own stalls (its ``stats``' ``stalls``, real time) in the mission (0 <= t < its duration), as
    ``bsst sitl``'s ``timing.stalls`` counts the controller's side (:func:`bridge.record.summary.stalls_block`);
    None when it met none."""
    if not stalls.get("count"):
        return None
    from bridge.record.summary import stalls_block  # lazy: the session's summary, only for a stalled controller

    m = flight.mission
    return stalls_block({}, {"stalls": stalls}, None, m.rate_hz, m.duration_s)
