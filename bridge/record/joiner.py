"""The SITL trace joiner: the vehicle's and the controller's halves -> ``trace.csv`` rows.

In:  ``vehicle.bin`` (:data:`~bridge.record.columns.VEHICLE_COLUMNS`) and ``controller.bin``
     (:data:`~bridge.record.columns.CONTROLLER_COLUMNS`), appended by the two processes as they fly
Out: rows (:class:`~bridge.record.columns.TraceRow`, units as there), also appended to ``trace.csv``, and
     the per-packet times (ms: up, down, round trip, state to command, tick lateness) the session's
     ``link`` and ``timing`` blocks are made of, together as :class:`Joined` (up and down through a relay: from
     the run's tlogs, :func:`~bridge.record.linkextract.step_delays`); the first step of the mission (its time, s)
     a lockstep vehicle flew off the step clock (:func:`off_clock_time`)

Each file's rows are read into named rows (:class:`~bridge.record.columns.VehicleRow`,
:class:`~bridge.record.columns.ControllerRow`) by the file's own header, so a file without a column is an
error that names it, and the join reads every value by name.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from operator import attrgetter
from pathlib import Path

from bridge.core.flight import Flight
from bridge.record.columns import (
    DESIRED_COLUMNS,
    ESTIMATE_COLUMNS,
    INPUT_COLUMNS,
    REALISED_COLUMNS,
    STATE_COLUMNS,
    WIRE_COLUMNS,
    ControllerRow,
    TraceRow,
    VehicleRow,
    trace_row,
)
from bridge.record.halves import HalfReader, read_half
from bridge.record.linkextract import step_delays
from bridge.record.runlog import TraceWriter

# groups of columns of a half, by name
_STATE = attrgetter(*STATE_COLUMNS)
_ESTIMATE = attrgetter(*ESTIMATE_COLUMNS)
_INPUT = attrgetter(*INPUT_COLUMNS)
_WIRE = attrgetter(*WIRE_COLUMNS)
_REALISED = attrgetter(*REALISED_COLUMNS)
_DESIRED = attrgetter(*DESIRED_COLUMNS)


def _recorded_ref(c: ControllerRow) -> tuple[tuple[float], ...]:
    """The reference a controller's row recorded, shaped as a sample's values (x, y, z, psi; each (value,))."""
    return ((c.x_ref,), (c.y_ref,), (c.z_ref,), (c.psi_ref,))


@dataclass(frozen=True)
class Joined:
    """The trace as the session joined it, and what the join measured (:class:`bridge.record.joiner.TraceJoiner`):
    per-packet ``up_ms``, ``down_ms`` (one-way, ms: of the message each step used; through a relay, of every one
    delivered, :meth:`TraceJoiner.joined`), ``rtt_ms`` (vehicle's round trip), ``s2c_ms`` (state to
    command by TIMESYNC), ``late_ms`` (tick lateness); ``commands``: controller rows read (``controller_steps``:
    the first and last step they answer); ``k0``: the vehicle's step of the trace's t = 0;
    ``first_sent``/``last_sent``: wall s of the first and last joined state's send; ``missing``: rows without their
    controller half."""

    rows: Sequence[TraceRow] = ()
    k0: int | None = None
    missing: int = 0
    first_sent: float | None = None
    last_sent: float = math.nan
    commands: int = 0
    up_ms: Sequence[float] = ()
    down_ms: Sequence[float] = ()
    rtt_ms: Sequence[float] = ()
    s2c_ms: Sequence[float] = ()
    late_ms: Sequence[float] = ()
    controller_steps: tuple[int, int] | None = None  # [first, last] step of the controller's rows (None: none)


class TraceJoiner:
    """Joins the vehicle's and the controller's halves into trace rows (live, append-only).

    Vehicle row k holds the true state at t_k, the command in force (the target answering
    state ``cmd_k``, as it arrived on the wire) and what the plant realised; the controller's
    row for ``cmd_k`` holds what the law demanded (u1..u4, phi_d, theta_d). A vehicle row
    waits for its other half (the controller writes it just after sending the command);
    once the controller is gone, a row whose half never came (the command it sent last, and
    every step the vehicle held it before its failsafe) is kept, with the law's demand and
    desired attitude unknown (NaN), and counted (``missing``): the trace never skips a step.
    Rows flown by the vehicle's own failsafe (no controller command) take the landing
    loop's demand, and its desired attitude (level); a step flown re-armed (``[failsafe] resume``) before
    the re-arm's first target came (real time: the ARM and that target are two datagrams) is kept with no demand
    (NaN), where it was once dropped as a step before the flight's first target (a gap the ``time_steady`` policy
    broke on). ``t`` counts from the first state the
    controller answered. In ``lockstep`` a step the controller answered (``cmd_k`` = k) takes
    ``c1..c4`` and ``state_age_s`` from the controller's row, as the offline loop writes them:
    the last command sent, and the age of the state this step's command was computed from
    (nan when the guard sent none). A step's reference columns are those of the controller's row of its state
    when that row is at the step's time t (lockstep: every step it answered): the reference it recorded for that t,
    sampled by the mission's code as offline samples it; else (real time's ticks, a step it never answered) the
    mission's reference is sampled here (until the third wave's thirty-ninth session every row's was: 0.1-0.4 CPU-s
    of a 20 s lockstep session's parent, docs/figures.md).

    ``trace.csv`` is appended as rows are joined when ``live`` (real time, and a lockstep fleet's sessions, whose
    processes share the cores anyway); else (a lockstep session) once the controller is done: writing a row's 45 floats
    as text is most of the join's cost, and during a lockstep flight it took a core's share from the two
    processes flying (issue 25: 0.25-0.29 of the endpoint floor with it, 0.39-0.40 without, and the
    whole session no slower, docs/figures.md). The halves are the live record of a lockstep flight.
    """

    def __init__(self, path: Path, flight: Flight, trace: TraceWriter | None, lockstep: bool = False,
                 live: bool | None = None) -> None:
        self.path = path
        self.v = HalfReader(path / "vehicle.bin", VehicleRow)
        self.c = HalfReader(path / "controller.bin", ControllerRow)
        self.lockstep = lockstep
        self.live = not lockstep if live is None else live  # trace.csv written as the flight goes
        self.trace = trace
        self.rate = flight.mission.rate_hz
        self.steps = flight.mission.steps
        self.sample = flight.mission.trajectory.sample
        self.ctl: dict[int, ControllerRow] = {}
        self.pending: deque[VehicleRow] = deque()
        self.k0: int | None = None
        self.rows: list[TraceRow] = []
        self.controller_done = False
        self.up_ms: list[float] = []
        self.down_ms: list[float] = []
        self.rtt_ms: list[float] = []
        self.s2c_ms: list[float] = []
        self.late_ms: list[float] = []
        self._up_seen: set[int] = set()
        self.missing = 0  # rows without their controller half (never written): demand NaN
        self.after: list[tuple[float, float, float]] = []  # rows of the end action, after the mission (_after_end)
        self.after_at: list[tuple[float, float, float]] = []  # their true positions (m, x y z): a fleet judges them
        self._written = 0  # rows already appended to trace.csv
        self.first_sent: float | None = None  # wall time the first / last joined state was sent
        self.last_sent = math.nan

    def update(self) -> int:
        """Join what both files hold now; returns the number of new trace rows."""
        vrows = self.v.read()  # first: see the class docstring
        for c in self.c.read():
            k = int(c.k)
            self.ctl[k] = c
            if self.k0 is None:
                self.k0 = k
            if math.isfinite(c.state_to_cmd_s):
                self.s2c_ms.append(1e3 * c.state_to_cmd_s)
            if math.isfinite(c.period_error_s):
                self.late_ms.append(1e3 * c.period_error_s)
        self.pending.extend(vrows)
        n0 = len(self.rows)
        while self.pending:
            v = self.pending[0]
            if self._after_end(v):
                self.pending.popleft()
                continue
            key = int(v.cmd_k)
            c = self.ctl.get(key) if key >= 0 else None
            if key >= 0 and c is None and not self.controller_done:
                break  # its row is on its way (written just after the send)
            self.pending.popleft()
            self._join(v, key, c)
        if self.trace is not None and (self.live or self.controller_done):
            self._write()
        return len(self.rows) - n0

    def _write(self) -> None:
        """Append the rows not yet in ``trace.csv`` (see the class docstring for when)."""
        assert self.trace is not None
        if self._written < len(self.rows):
            for row in self.rows[self._written:]:
                self.trace.row(row)
            self._written = len(self.rows)
            self.trace.flush()

    def _after_end(self, v: VehicleRow) -> bool:
        """Whether ``v`` was flown after the mission's last step by the vehicle itself (its end action, HOLD or LAND,
        and on from there: a failsafe that takes the end action over, as a position lost, flies on in it; a failsafe's
        landing still going at the mission's end, or its wait to disarm; a ground station's mode): not the trace's,
        as offline's trace ends at that step for every outcome (the mission's figures stay the mission's; until the
        third wave's thirty-ninth session a failsafe's rows past it were the trace's, its RMS and duration too).
        Kept in :attr:`after` as (t s on the vehicle's clock, z m, vz m/s) for ``summary.json["end"]``
        (:func:`bridge.record.ending.end_block`, which reads them from the end action's ``end`` event), and its
        position (x, y, z m) in :attr:`after_at`, for a fleet's judgement of the world through its landing
        (:mod:`bridge.swarm`). An OFFBOARD row past it before any of those is the state that ended the mission in
        real time (:meth:`_join` drops it)."""
        if self.k0 is None or int(v.k) - self.k0 < self.steps or (int(v.mode) == 0 and not self.after):
            return False
        self.after.append((v.t, v.z, v.vz))
        self.after_at.append((v.x, v.y, v.z))
        return True

    def _join(self, v: VehicleRow, key: int, c: ControllerRow | None) -> None:
        k = int(v.k)
        mode = int(v.mode)
        if self.k0 is None or k < self.k0 or (key < 0 and mode == 0 and not self.rows):
            return  # not flying the mission yet (armed, its first target not in)
        if mode == 0 and k - self.k0 >= self.steps:
            return  # realtime: the state that ended the mission, flown while the disarm was on its way
        t = (k - self.k0) / self.rate
        own = self.ctl.get(k)  # the controller's row of this step's state, if it answered it
        # at this t its recorded reference is the mission's, sampled by the same code: taken, not sampled again
        ref = _recorded_ref(own) if own is not None and own.t == t else self.sample(t)
        if c is not None:
            u = _INPUT(c)
            desired = _DESIRED(c)
            if key not in self._up_seen and math.isfinite(v.cmd_recv_wall):
                self._up_seen.add(key)
                self.up_ms.append(1e3 * (v.cmd_recv_wall - c.cmd_sent_wall))
                if math.isfinite(v.rtt_s):
                    self.rtt_ms.append(1e3 * v.rtt_s)
        elif key >= 0:  # a controller killed between sending this command and writing its row
            self.missing += 1
            u, desired = (math.nan,) * 4, (math.nan, math.nan)  # what the law demanded was never recorded
        elif mode == 0:  # re-armed (``resume``), its first target not in yet: no demand in force, a step flown
            u, desired = _INPUT(v), (math.nan, math.nan)  # (the vehicle's NaN)
        else:
            u = _INPUT(v)
            desired = (0.0, 0.0)  # the landing loop holds the vehicle level
        if own is not None:
            self.down_ms.append(1e3 * (own.odo_recv_wall - v.odo_sent_wall))
        if self.first_sent is None:
            self.first_sent = v.odo_sent_wall
        self.last_sent = v.odo_sent_wall
        wire, age = _WIRE(v), v.state_age_s
        if self.lockstep and c is not None and key == k:
            wire, age = _WIRE(c), c.state_age_s
        self.rows.append(trace_row(t, _STATE(v), ref, u, wire, _REALISED(v), age, desired, _ESTIMATE(v), v.nees))

    def newest(self) -> tuple[float, float] | None:
        """(t s, 3-D position error m) of the newest step flown, for a progress line: the last joined row, or,
        while the controller flies a flight not joined ``live`` (rows joined at the end), the vehicle's newest
        record; None before the flight's time 0 and after the mission's last step."""
        v = self.v.last() if not self.live and not self.controller_done else None
        if v is not None:
            if self.k0 is None or not 0 <= int(v.k) - self.k0 < self.steps:
                return None  # before the flight's time 0, or flying the end action after the mission
            t = (int(v.k) - self.k0) / self.rate
            ref = self.sample(t)
            return t, math.sqrt((v.x - ref[0][0]) ** 2 + (v.y - ref[1][0]) ** 2 + (v.z - ref[2][0]) ** 2)
        if not self.rows:
            return None
        r = self.rows[-1]
        return r.t, math.sqrt((r.x - r.x_ref) ** 2 + (r.y - r.y_ref) ** 2 + (r.z - r.z_ref) ** 2)

    def newest_t(self) -> float | None:
        """The mission time (s) of the vehicle's newest state joined: the trace's last row, or its end action's last
        row after it (:attr:`after`); None before the flight's time 0."""
        if self.k0 is None or not self.rows:
            return None
        return max((self.rows[-1].t, *(t - self.k0 / self.rate for t, _, _ in self.after[-1:])))

    def joined(self, delivered: bool = False) -> Joined:
        """The rows joined so far and what the join measured. ``delivered`` (real time through a relay, which may
        reorder): the one-way delays are every per-step message's that arrived, from the tlogs (the halves time
        only the one each step used, and leave out the late ones it refused: 8 ms low on an LTE link, until the
        third wave's thirty-seventh session); without the tlogs, the halves'. The tlogs are their one source: the
        relay's own figure (relay.json's ``measured_ms``, the link block's ``relay_added_ms``) is what it added,
        arrival to forward, to every datagram, not the two sockets' hops, nor only the per-step messages."""
        up, down = (step_delays(self.path) if delivered else None) or (self.up_ms, self.down_ms)
        return Joined(self.rows, self.k0, self.missing, self.first_sent, self.last_sent, len(self.ctl), up,
                      down, self.rtt_ms, self.s2c_ms, self.late_ms,
                      (min(self.ctl), max(self.ctl)) if self.ctl else None)

    def close(self) -> None:
        self.v.close()
        self.c.close()


def off_clock_time(path: Path, rate_hz: float, k0: int = 0) -> float | None:
    """Lockstep: the mission's time (s; its time 0 the vehicle's step ``k0``) of the first record of ``vehicle.bin``
    (at ``path``) from step k0 on not flown on the step clock (the command in force answers another step, or none),
    or None (also for a file that cannot be read). Before k0 a ground station may have flown the vehicle on the wall
    clock before an awaited mission's start: not the mission's steps."""
    try:
        half = read_half(path)
    except (OSError, ValueError):
        return None
    k = half["k"]
    off = ((k != half["cmd_k"]) & (k >= k0)).nonzero()[0]
    return float(k[off[0]] - k0) / rate_hz if len(off) else None
