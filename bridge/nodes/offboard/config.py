"""The offboard controller's settings, its check of a state's stamp and the bounds TIMESYNC puts on the vehicle's clock
(:mod:`bridge.nodes.offboard`).

In:  a state's stamp (us), the newest accepted one's (us), the wall time between their arrivals (s), the
     control period (s); a :class:`~bridge.core.flight.Flight` and its clock (for the slack); TIMESYNC answers
     (round trip, the least and the greatest clock offset each allows, ns)
Out: :func:`stamp_problem`: why a stamp cannot follow (``stale``, ``stamp_jump``) or None; the slack (s);
     :func:`offset_bounds`: the vehicle's clock offset as the answers bound it (ns);
     :class:`OffboardConfig`, where the vehicle is and how to fly it; the timing constants (s) of the flight
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

from bridge.core.flight import Flight
from bridge.mavlink.endpoint import CONTROLLER_COMPID, CONTROLLER_SYSID, Address

PHASE_S = 0.0003  # realtime: tick this long after the state's arrival (its one-way trip and decode)
PHASE_STATES = 5  # realtime: states watched to find the phase of the vehicle's clock
PHASE_RELOCKS = 10  # realtime: phase-locks begun afresh after the machine's stalls, at most (then it locks on)
# realtime: a tick whose state is not in yet waits for it at most this share of a period (a
# late wake-up of the vehicle would otherwise cost the step: the law would answer the state
# before, and its target would be two periods old when the next step begins); the rest of
# the period is the target's way back
STATE_WAIT_PERIODS = 0.5
# real time: a way down (state stamp to arrival, by TIMESYNC) outside [-slack, max] means the
# vehicle's stamps and its TIMESYNC clock differ; the ages then count from the arrivals
WAY_DOWN_SLACK_S = 0.005
WAY_DOWN_MAX_S = 2.0
# realtime: sleep until this long before a tick, then poll (select wakes late; with the 1 us timer slack the
# controller asks for, 0.1 ms: 0.3 ms polled 7.5 % of a core away; docs/figures.md, fourth session)
SPIN_BEFORE_TICK_S = 0.0001
# a state's stamp may run ahead of the newest accepted state's by one step, plus the wall time
# between their arrivals at up to STAMP_PACE x real time (a vehicle's stamps follow its steps:
# lockstep answers or the wall clock; the factor lets a stream that fell behind catch up),
# plus STAMP_SLACK_S (losses while the controller read late) and, in real time, twice the
# down link's jitter and its bandwidth queue (one state delayed more than the next). Further
# ahead, or further back than the slack, is a jump of the mission's time: stamp_jump
STAMP_PACE = 2.0
STAMP_SLACK_S = 0.5
HOUSEKEEPING_S = 0.05


def stamp_problem(usec: int, newest_usec: int, since_s: float, period_s: float, slack_s: float) -> str | None:
    """Why a state stamped ``usec`` (us) cannot follow the newest state accepted, stamped
    ``newest_usec`` (-1: none yet, nothing to compare with) and received ``since_s`` wall
    seconds ago, or None. Older is ``stale`` (reordered on the way) within ``slack_s`` and a
    jump back beyond; ahead by more than one period ``period_s`` plus :data:`STAMP_PACE` x
    ``since_s`` plus ``slack_s`` is a jump forward. Both are ``stamp_jump``: the state would
    move the mission's time (and a far-future one would end the mission at once)."""
    if newest_usec < 0:
        return None
    ahead_s = (usec - newest_usec) * 1e-6
    if ahead_s < 0.0:
        return "stamp_jump" if -ahead_s > slack_s else "stale"
    return "stamp_jump" if ahead_s > period_s + STAMP_PACE * max(since_s, 0.0) + slack_s else None


def stamp_slack_s(flight: Flight, clock: str) -> float:
    """:data:`STAMP_SLACK_S`, plus in real time what the down link (the relay's, on the wire)
    may take from one state's delay and not the next's: twice its jitter, its bandwidth queue."""
    if clock == "lockstep":  # the down model acts here, after the socket: states cross it in order
        return STAMP_SLACK_S
    d = flight.link.down
    return STAMP_SLACK_S + 2e-3 * d.jitter_ms + (1e-3 * d.queue_ms if d.rate_bps else 0.0)


def offset_bounds(answers: Sequence[tuple[int, int, int]]) -> tuple[int, int]:
    """The vehicle's clock offset (its clock less ours, ns) as TIMESYNC ``answers`` bound it, each (round trip,
    least offset, greatest offset): the vehicle read its clock (tc1) between our request's send (ts1) and its
    answer's arrival (now), so the offset lies within [tc1 - now, tc1 - ts1] whatever the two ways took. Where all
    of them agree (their intersection: the least way over and the least way back, which on a busy machine are
    seldom one exchange's); if they do not (the vehicle's clock stepped), the shortest round trip's. One at least."""
    lo, hi = max(a[1] for a in answers), min(a[2] for a in answers)
    if lo <= hi:
        return lo, hi
    best = min(answers)
    return best[1], best[2]


@dataclass(frozen=True)
class OffboardConfig:
    """Where the vehicle is and how to fly it (see the module docstring)."""

    vehicle: Address
    sysid: int = CONTROLLER_SYSID
    compid: int = CONTROLLER_COMPID
    clock: str = "lockstep"
    target_sysid: int | None = None  # None: the first autopilot that sends a heartbeat
    connect_timeout_s: float = 10.0  # s of wall time to wait for the vehicle's heartbeat
    vehicle_timeout_s: float = 2.0  # s of wall time without any message: the vehicle is lost
    # s of wall time for the mission's second and third states (a lockstep fleet's first steps wait for its slowest
    # vehicle to start: bridge.nodes.vehicle.gate); None: vehicle_timeout_s
    start_timeout_s: float | None = None
    # s of wall time for each later state, the vehicle still heard (a lockstep fleet's vehicle waits at its gate for
    # a silent one: bridge.nodes.vehicle.gate.STATE_WAIT_S); None: vehicle_timeout_s
    state_timeout_s: float | None = None
    spin_s: float = 0.0002  # as the vehicle's (bridge.nodes.vehicle.VehicleConfig.spin_s)
    timesync_s: float = 0.5
    key: bytes | None = field(default=None, repr=False)  # MAVLink 2 signing key (never shown)
    source_port: int = 0  # local UDP port it sends from (0: any free one; bsst sitl pins it for the vehicle)
    # fly a ground station's mission: wait for its start, download it (bridge.nodes.offboard.mission), fly it
    # in AUTO.MISSION (the vehicle's mode then, not a ground station's takeover)
    await_mission: bool = False
    # lockstep: a fleet's one radio (its file, this controller's user: its vehicle's place from 0; bridge.link.turns)
    radio: tuple[str, int] | None = None

