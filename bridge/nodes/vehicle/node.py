"""The simulated vehicle's node: :class:`Vehicle` wires its parts to two UDP links (``bsst vehicle``: :mod:`.run`).

In:  datagrams on the controller link (``--listen``) and the GCS link (``--gcs``): actuator targets
     stamped with the ``time_usec`` (us) of the state they answer, the no-target acknowledgement,
     commands, parameters, TIMESYNC, PING, ...; wall time (s, ``time.monotonic``)
Out: ODOMETRY of step k (``time_usec`` = k / rate_hz, us) to the controller; HEARTBEAT (1 Hz), the
     streams, STATUSTEXT on events, answers; ``vehicle.tlog`` and ``vehicle.bin`` (its half of the trace);
     its reports to the session (:mod:`bridge.nodes.report`: ready, event, refused, stats), all
     through :meth:`Vehicle._report`

Parts: step clock (:mod:`.clock`), who is heard (:mod:`.authority`), commands (:mod:`.commander`), events said
(:mod:`.announcer`), parameters (:mod:`.paramservice`), missions (:mod:`.mission`), telemetry (:mod:`.streams`,
sent by :mod:`.streaming`), trace rows (:mod:`.rows`). Here: the loops of the clock's states, the receive dispatch,
wall-clock housekeeping.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

from bridge.core.flight import Flight
from bridge.core.wire import command_from_wire
from bridge.link.ends import VehicleEnd
from bridge.link.turns import TurnRadio
from bridge.mavlink.endpoint import Spinner, Tlog, sweep, wait
from bridge.mavlink.receive import Rejections
from bridge.nodes.report import Ready, Refused, Report, Stats
from bridge.nodes.vehicle.announcer import Announcer
from bridge.nodes.vehicle.authority import COMMANDS, Authority
from bridge.nodes.vehicle.catchup import CatchUp
from bridge.nodes.vehicle.clock import Clock, ClockState
from bridge.nodes.vehicle.commander import Commander, CommanderPorts, engages_lockstep
from bridge.nodes.vehicle.config import CLOCKS, VehicleConfig, open_links
from bridge.nodes.vehicle.gate import SILENT_S, Gate, resting
from bridge.nodes.vehicle.mission import MissionManager
from bridge.nodes.vehicle.paramservice import ParamService
from bridge.nodes.vehicle.receiver import Receiver, ReceiverPorts, Refusals
from bridge.nodes.vehicle.rows import Rows
from bridge.nodes.vehicle.streaming import Streaming
from bridge.nodes.vehicle.streams import HEARTBEAT_S, OdometryOut, StatusTexts
from bridge.nodes.vehicle.targets import Targets
from bridge.record.metrics import plant_blocks

HOUSEKEEPING_S = 0.02  # s of wall time between looks at the GCS socket, streams, file flushes
RESEND_S = 0.05  # lockstep: resend the state nobody answered (a datagram can be dropped)
IDLE_ODOMETRY_S = 0.1  # lockstep, disarmed: time stands still; the state is still shown
_ENGAGED = (ClockState.LOCKSTEP, ClockState.ANSWERED)


class Vehicle:
    """One simulated vehicle and its MAVLink links. :meth:`run` until :meth:`stop`."""

    def __init__(self, flight: Flight, cfg: VehicleConfig, out: Path | None = None,
                 status: Callable[[Report], None] | None = None) -> None:
        if cfg.clock not in CLOCKS:
            raise ValueError(f"clock must be one of {', '.join(CLOCKS)}")
        self.flight = flight
        self.cfg = cfg
        m = flight.mission
        self.rate = m.rate_hz
        self.substeps = flight.substeps
        self.actuation = flight.profile.actuation
        self.sim = flight.make_vehicle(armed=False)
        if cfg.clock == "realtime":  # the mission's time 0 is its first target's state (SimVehicle.hold_timeline)
            self.sim.hold_timeline()
        self.plant = self.sim.plant
        self._status = status or (lambda report: None)
        self.tlog = Tlog(out / "vehicle.tlog") if out is not None else None
        self.rejected = Rejections()  # refusals of the receive path, both links, and of the up-link model's end
        self._reject = Refusals(self.rejected)
        self.authority = Authority(cfg)
        self.link, self.gcs = open_links(cfg, self.tlog, self.rejected)
        self.endpoints = [self.link] + ([self.gcs] if self.gcs is not None else [])
        self.read_until: float | None = None  # s, time.monotonic: when it stopped reading the controller link
        self.spinner = Spinner(self.link, cfg.spin_s)  # a lockstep answer is polled for before sleeping
        self.rows = Rows(out / "vehicle.bin", self.rate, lambda: self.targets.new_steps) if out is not None else None
        self.k = 0  # control step of the plant's state: t_k = k / rate_hz
        self.stopping = False
        now = time.monotonic()
        self._next_heartbeat = self._next_house = now
        self._resend_at = self._lost_at = self._idle_odo_at = now
        self.clock = Clock(cfg.clock == "realtime", m.physics_hz, cfg.speed or 1.0, now)
        self.pace = self.clock.pace  # the wall clock of physics steps
        self.catchup = CatchUp(self.pace)  # real time: the machine's stalls, and what they held back
        self._n = 0  # physics steps taken (realtime: for the wall-clock schedule)
        self._held: list[tuple[Any, Any, tuple[str, int]]] = []  # lockstep on the wall clock: to a period's start
        load_at = (now, time.process_time())
        # lockstep: the controller's targets and re-arms cross the mission's up-link model here; a lockstep fleet's
        # one radio (its gate file's) takes them at this vehicle's turn (bridge.link.turns)
        gate = cfg.gate if cfg.clock == "lockstep" else None
        self.turns = (TurnRadio(gate.radio, "up", flight.link.up.rate_bps, flight.link.up.queue_ms / 1000.0,
                                gate.index, "--gate's radio") if gate is not None and gate.radio is not None else None)
        up = flight.link.make((self.turns, None), gate.index)[0] if self.turns else flight.link.make()[0]
        # what the up-link model refuses is the controller's (Targets lets no one else's in), as on the wall clock
        self.vend = VehicleEnd(self.sim, up, self.actuation, refuse=lambda why: self.rejected.add(why, True))
        # its controller's first turns on one radio wait for the slowest vehicle and controller to start, as the
        # gate waits for a silent vehicle: the answers of steps 0 and 1 may take that long (bridge.link.turns)
        self._first_answers_s = cfg.lost_after_s
        if self.turns is not None and self.turns.ordered:  # (no rate: no turns, see TurnRadio.ordered)
            self.vend.held = []
            self._first_answers_s = max(SILENT_S, cfg.lost_after_s)
        self.odometry = OdometryOut(self.link, self.sim, self.rate, flight.estimator, flight.wire()[0])
        self.targets = Targets(self.sim, self.clock, self.authority, self.rate, self.actuation, self._reject,
                               flight.profile.name)
        self._statustext = StatusTexts()
        self.params = ParamService(self.sim, self.authority, self._statustext, self._reject, self._refused,
                                   lambda: self.announcer.report_events())  # (a change's line before its echo)
        self.missions = MissionManager(self.sim, self.authority, self._statustext, self._to_ground_stations,
                                       self._refused, flight)
        self.streaming = Streaming(self.sim, flight, cfg, self.missions, self.clock, lambda: self.t, now, load_at)
        self.announcer = Announcer(self.sim, self.authority, self.link, self.endpoints, self._report,
                                   self._statustext, self.streaming.heartbeat, self.params.value_of)
        ports = CommanderPorts(step=lambda: self.k, state_out=self._send_odometry, new_flight=self._new_flight,
                               arm_through_link=lambda acted, wanted: self.vend.receive_arm(self.t, acted, wanted),
                               target_wall=lambda: self.targets.wall,
                               controller_heard=lambda: self.link.peer is not None, message=self._requested,
                               reject=self._reject, refused=self._refused, announce=self.announcer.report_events,
                               missions=self.missions)
        tables = {"controller": self.streaming.ctl_streams, "gcs": self.streaming.streams}
        self.commander = Commander(self.sim, self.clock, self.authority, self._statustext, tables, self.substeps,
                                   ports)
        self.clocking = self.commander.clocking  # which clock the flight runs on as its modes and its end change
        self.receiver = Receiver(self.link, self.authority, self._reject, self.targets, self.commander, self.params,
                                 self.missions, ReceiverPorts(step=lambda: self.k, flight_on=self._flight_on,
                                               announce=self.announcer.drain, heartbeat=self.streaming.heartbeat,
                                               clock_ns=self._clock_ns, events=self.announcer.resend))
        self.announcer.charged = self.receiver.charged
        self._handle = self.receiver.handle  # (an attribute: one call less on the lockstep's hot path)
        # a lockstep fleet's shared clock (bsst sitl --vehicles): step by step with the other vehicles
        self.gate = (Gate(gate, self.clock, lambda: (self.plant.state[0], self.plant.state[2], self.plant.state[4]),
                          self.rate, self.turns, lambda: resting(self.plant.state, self.sim.armed))
                     if gate is not None else None)

    # -- public --------------------------------------------------------------------------
    def stop(self) -> None:
        """Ask :meth:`run` to return (safe from a signal handler)."""
        self.stopping = True

    def run(self) -> None:
        """Serve until :meth:`stop`: step the clock, answer the links, stream telemetry."""
        pinned, g = self.authority.pinned, self.gcs
        # a bound GCS link says the port it got (udpin:HOST:0 too), where a ground station sends to it
        gcs = None if g is None else g.address.hostport if g.address.mode == "udpout" else f"{g.local[0]}:{g.local[1]}"
        self._report(Ready("vehicle", listen=f"{self.link.local[0]}:{self.link.local[1]}", gcs=gcs,
                           gcs_mode=g.address.mode if g is not None else None, sysid=self.cfg.sysid,
                           clock=self.cfg.clock, profile=self.flight.profile.name,
                           controller_from=f"{pinned[0]}:{pinned[1]}" if pinned is not None else None))
        try:
            while not self.stopping:
                state = self.clock.state
                if state is ClockState.FREE_RUNNING:
                    self._freerun_period()
                elif state in _ENGAGED:
                    self._lockstep_wait()
                elif state is ClockState.GATED:
                    self.gate.serve(self.endpoints, self._next_house, self._handle,  # type: ignore[union-attr]
                                    self._collided, self._step_lockstep)
                else:  # idle, halted
                    self._idle()
                if time.monotonic() >= self._next_house:
                    self._housekeeping()
        finally:
            self.close()

    def close(self) -> None:
        """Flush and close every file and socket (idempotent)."""
        self._drain_sockets()
        self.announcer.drain()
        if self.rows is not None:
            self.rows.close()
        if self.tlog is not None:
            self.tlog.close()
        for ep in self.endpoints:
            ep.close()
        if self.gate is not None:
            self.gate.close()
        if self.turns is not None:
            self.turns.close()

    def report_stats(self) -> None:
        """The stats report: what was accepted, refused, sent and received, and the up-link model's."""
        self._report(Stats({
            "accepted": self.targets.accepted, "rejected": dict(self.rejected), "odometry_sent": self.odometry.count,
            "received": self.link.received, "overruns": self.pace.rebased, "steps": self.k,
            "stalls": self.catchup.stalls.report(),
            **({"gate": self.gate.stats()} if self.gate is not None else {}),  # a fleet's shared clock
            **({"radio": self.turns.part()} if self.turns is not None else {}),  # its part of the fleet's one radio
            "rejected_from_controller": self.rejected.from_peer, "resends": self.odometry.resends,
            "answered_again": self.targets.answered_again, "answered_wall_clock": self.targets.answered_wall_clock,
            "spin_skipped": self.spinner.skipped,
            **self.odometry.sends.stats(),  # odometry_steps, _again, _again_unlisted, _resent
            "kernel_drops": self.link.kernel_drops(), "read_until": self.read_until,
            "up": self.vend.up.stats.summary() if self.cfg.clock == "lockstep" else None,
            "plant": self.commander.plant_at_end or plant_blocks(self.plant),  # wind, battery, impact, as offline
            "mission_start": self.missions.started}))

    def _report(self, report: Report) -> None:
        """Every report of the vehicle goes out here."""
        self._status(report)

    def _refused(self, why: str) -> None:
        """A command or parameter refused, and why (its report)."""
        self._report(Refused(why))

    def _drain_sockets(self, batches: int = 64) -> None:
        """Take in what is already queued on every socket before closing, so that the final
        counts include every datagram that arrived before the stop (the others' socket is read
        lazily while the controller's is busy: see Endpoint.poll); bounded, never blocks. The controller link's
        :attr:`read_until` (``time.monotonic`` before the look that found it empty): a target the controller sent
        after it never came (``summary.json`` link.up.in_flight, docs/sitl.md)."""
        for ep in self.endpoints:
            t = ep.drain(lambda m, addr, ep=ep: self._handle(ep, m, addr), batches)
            if ep is self.link and self.read_until is None and ep.fileno >= 0:
                self.read_until = t

    @property
    def t(self) -> float:
        """Simulation time of the current step (s)."""
        return self.k / self.rate

    def _collided(self, why: str) -> None:
        """Another vehicle of the fleet touched this one: the flight ends (:meth:`Clocking.collided`), and its
        events are said at once (the session waits on the disarm to end the run)."""
        self.clocking.collided(why)
        self.announcer.drain()

    # -- lockstep --------------------------------------------------------------------------
    def _lockstep_wait(self) -> None:
        """Wait for the target of step k; step when it is here, or give the controller up."""
        deadline = min(self._next_house, self._resend_at, self._lost_at)
        for ep, m, addr in wait(self.endpoints, deadline, self.spinner):
            self._handle(ep, m, addr)
        if self.clock.state is ClockState.ANSWERED:
            # (a fleet: the others flew k - 1; on one radio, its turn of step k came, unless the mission is over)
            if self.gate is None or self.gate.clear(self._collided, None if self.clocking.end_landing else self.k):
                self._step_lockstep()
            return
        if self.clock.state is not ClockState.LOCKSTEP:
            return
        now = time.monotonic()
        if now >= self._lost_at:
            self.clocking.controller_lost(now)
        elif now >= self._resend_at:
            self._send_odometry(now, fresh=False)

    def _step_lockstep(self) -> None:
        """Step k is answered: its target (if any) enters the up-link model at t_k, what the
        model delivers by t_k acts, then one control period with mid-period deliveries."""
        answer = self.clock.take()
        wire, recv = answer.wire, answer.recv
        k = self.k
        t = k / self.rate
        sent = self.odometry.sent_at.get(k, recv)
        vend = self.vend
        if wire is not None:
            vend.receive_command(t, command_from_wire(self.actuation, wire), t)
            self.targets.applied = (k, wire, recv)
        ending = self.clocking.end_landing  # the mission's end landing, clocked as the mission (Clocking)
        if vend.held is not None and not ending:  # a fleet's one radio: its turn of step k (Gate.clear)
            vend.release()
            self.gate.took(k)  # type: ignore[union-attr]
        if not ending:  # after the mission the vehicle flies alone: the up link's statistics stay the mission's
            vend.deliver(t)
        X = self.plant.state
        est = self._estimate()
        real = self.plant.realised
        if ending:
            self.sim.advance()
        else:
            vend.advance()
        mode = self.sim.mode  # flown this period (a disarm in LAND or failsafe then takes another: flight_over)
        self.k = k + 1
        if self.cfg.speed is not None:
            self._wait_until(self.pace.due(self.k * self.substeps))
        alive = self._after_step()
        if alive:
            self._send_odometry(time.monotonic())
        if self.gate is not None:
            self.gate.after_step(self.k, alive)
            self._turns_over()
        # off the critical path: the controller is computing step k+1 meanwhile
        if self.rows is not None:
            self.rows.lockstep(k, X, mode, wire, real, t - vend.applied_state_t, recv - sent, sent, recv, est)

    # -- free run: realtime clock, or lockstep lost --------------------------------------------
    def _freerun_period(self) -> None:
        """One control period on the wall clock: state out, row, physics steps on schedule."""
        k = self.k
        if self.gate is not None:
            self.gate.over(k)
            self._turns_over()
        n0 = k * self.substeps
        if not self._wait_until(self.pace.due(n0)):
            return
        self._take_held()
        if not self.clock.free_running:  # armed into lockstep: step k's state is out, its answer flies it
            return
        now = time.monotonic()
        if self.sim.armed or self.cfg.clock == "realtime":
            self._send_odometry(now)
            self.targets.sent_on_wall_clock(k)  # (lockstep engaged again later: its answer may come after)
        X = self.plant.state
        if self.sim.armed and self.rows is not None:
            self.rows.free_running(k, X, self.sim, self.actuation, self.targets.applied, self.odometry.sent_at, now,
                                   self._estimate)
        self._n = n0
        hold = self.cfg.clock == "lockstep"
        # real time sleeps to the period's end (or a message): the steps due by a wake are flown then, and what
        # it read waits for the first one due after (CatchUp), as it did when each step woke the vehicle
        end = None if hold else self.pace.due(n0 + self.substeps)

        def deliver(_t: float) -> None:
            # called before each physics step: wait for its wall time, taking targets meanwhile
            if self._n > n0:
                self._wait_until(self.pace.due(self._n), hold=hold, until=end)
            self._n += 1

        self.sim.advance(deliver)
        self.k = k + 1
        self._after_step()
        if not self.clock.free_running:  # (halted: what it held is answered now, not never)
            self._take_held()

    def _take_mid_period(self, ep: Any, m: Any, addr: tuple[str, int]) -> None:
        """Lockstep, on the wall clock mid-period: what may engage lockstep (an arm, OFFBOARD, from either link:
        :func:`engages_lockstep`), and every command after it (in their order), waits for the next period's start,
        where lockstep engages with that step's state; the rest is taken at once. (Engaged mid-period, the state sent
        was one the period then flew on without its answer, and that answer flew the next step, recorded as its own.)"""
        if engages_lockstep(m) or (self._held and (m.get_type() in COMMANDS or m.get_type() == "SET_MODE")):
            self._held.append((ep, m, addr))
        else:
            self._handle(ep, m, addr)

    def _take_held(self) -> None:
        """What :meth:`_take_mid_period` held, acted on now (a period's start), in the order it came."""
        held, self._held = self._held, []
        for ep, m, addr in held:
            self._handle(ep, m, addr)

    def _wait_until(self, due: float, hold: bool = False, until: float | None = None) -> bool:
        """Serve the links until wall time ``due`` of the pace; False if stopping. Real time catches every stall
        up (the controller's schedule is the wall's); a paced lockstep far behind is re-based, not caught up.
        ``hold`` (lockstep, running free mid-period): the links' messages are taken by :meth:`_take_mid_period`.
        ``until`` (real time, mid-period): sleep to then, not to ``due``, unless a message comes first."""
        now = time.monotonic()
        realtime = self.cfg.clock == "realtime"
        take = self._take_mid_period if hold else self._handle
        if realtime:  # the machine may have stalled us; what a stall held back is taken when its time comes
            self.catchup.woke(due, now)
            for ep, m, addr in self.catchup.release(due):
                self._handle(ep, m, addr)
        elif self.pace.rebase_if_stalled(now, due):
            return not self.stopping
        while not self.stopping:
            if now >= due:
                return True
            self.catchup.asleep_to = deadline = min(due if until is None else until, self._next_house)
            got = wait(self.endpoints, deadline)
            now = time.monotonic()
            if not (realtime and self.catchup.overslept(due, now, got, until is not None)):
                for ep, m, addr in got:
                    take(ep, m, addr)
            elif until is not None and now >= due:  # (its duties after the steps owed: at the next wait)
                continue
            if now >= self._next_house:
                self._housekeeping(take)
        return False

    # -- idle -----------------------------------------------------------------------------------
    def _idle(self) -> None:
        """Lockstep and disarmed (or halted): time stands still; serve the links."""
        if self.gate is not None:
            self.gate.over(self.k)
            self._turns_over()
        # halted: no idle state goes out, so its time must not be waited on (it stays in the past: a busy loop)
        deadline = self._next_house if self.clock.halted else min(self._next_house, self._idle_odo_at)
        for ep, m, addr in wait(self.endpoints, deadline):
            self._handle(ep, m, addr)
        now = time.monotonic()
        if now >= self._idle_odo_at and not self.clock.halted:
            self._idle_odo_at = now + IDLE_ODOMETRY_S
            with self.receiver.charged():  # a would-be controller's: within its trial's credit
                self._send_odometry(now)
            # a copy of step k's state, as the one arming sends again: a controller that read it while arming
            # answers both, and the second answer is an answer to a copy (answered_again), not a refusal
            self.targets.resent(self.k)

    # -- after each control period -------------------------------------------------------------
    def _turns_over(self) -> None:
        """A fleet's one radio: once this vehicle has left the shared clock it takes no turns; what it held, and
        what it receives from now on, enters its up-link model at once."""
        if self.vend.held is not None and self.gate is not None and self.gate.left is not None:
            self.vend.release()
            self.vend.held = None

    def _after_step(self) -> bool:
        """Events and divergence; False when the plant is lost (nothing more to send)."""
        self.commander.flight_over()  # (its mode after a landing's disarm is said with the disarm)
        if len(self.sim.events) > self.announcer.sent:
            self.announcer.drain()
        if self.missions.watch is not None:  # a ground station's mission in flight: its items reached
            self.missions.flight_step(self.t, self.plant.state, self.sim.armed)
        if self.clocking.diverged():
            self.announcer.drain()
            return False
        return True

    # -- sending ---------------------------------------------------------------------------------
    def _send_odometry(self, now: float, fresh: bool = True) -> None:
        """ODOMETRY of step k to the controller; a ``fresh`` one (not a resend) starts the
        lockstep wait for its target."""
        if not self.odometry.send(self.k, now, fresh):
            return
        if not fresh:
            self.targets.resent(self.k)
        self._resend_at = now + RESEND_S
        if fresh:
            self._lost_at = now + (self.cfg.lost_after_s if self.k > 1 else self._first_answers_s)

    def _estimate(self) -> tuple[tuple[float, ...], float]:
        """The published estimate now and its NEES against the true state (nan under truth)."""
        E = self.sim.published()
        return E, self.sim.nees(E)

    def _housekeeping(self, take: Callable[[Any, Any, tuple[str, int]], None] | None = None) -> None:
        """Wall-clock duties: GCS commands (to ``take``, else :meth:`_handle`), heartbeat, streams, flushing files."""
        now = time.monotonic()
        if self.gcs is not None:
            if self.cfg.clock == "realtime":  # the controller's link only where a stall's catch-up holds it
                got = [(self.gcs, m, addr) for m, addr in self.gcs.poll()]
            else:  # with the controller's link first: an answer sent before a HOLD is read before it (sweep)
                got = sweep((self.link, self.gcs)) if self.gcs.queued() else []
            for ep, m, addr in got:
                (take or self._handle)(ep, m, addr)
        with self.receiver.charged():  # a re-request to a would-be controller: within its trial's credit
            self.missions.tick(now)
        self.commander.pre_start.tick(now)  # COM_DISARM_PRFLT
        if now >= self._next_heartbeat:
            self._next_heartbeat = now + HEARTBEAT_S
            self.announcer.beat()
            self.streaming.measure_load(now)
        if self.targets.mismatch.due():  # the controller flies the other actuation: said once, in words, first
            self.announcer.to_links(self._statustext(mavlink.MAV_SEVERITY_WARNING, self.targets.mismatch.text))
        refused = self.rejected.report(now)  # once per second while the receive path refuses anything
        if refused is not None:
            warning = mavlink.MAVLink_statustext_message(mavlink.MAV_SEVERITY_WARNING, refused.encode())
            self.announcer.to_links([warning])
        nxt = self.streaming.send_due(now, min(self._next_heartbeat, now + HOUSEKEEPING_S), self.gcs, self.link,
                                      self.receiver.charged)
        if self.rows is not None:
            self.rows.flush()
        if self.tlog is not None:
            self.tlog.flush()
        # a table's streams count only while its link has someone to send them to (else they are never sent, and
        # their stale due times would bring housekeeping back every millisecond, in the lockstep's way)
        self._next_house = max(nxt, now + 0.001)

    def _to_ground_stations(self, msgs: list[Any]) -> None:
        """``msgs`` to the GCS link's ground station (none without a GCS link)."""
        if self.gcs is not None:
            self.gcs.send_many(msgs)

    def _flight_on(self) -> bool:
        """Armed, or a lockstep flight on: the controller's address is held."""
        return self.sim.armed or self.clock.engaged

    def _new_flight(self, from_gcs: bool) -> None:
        """A new flight is armed: no target of the last one is in force; armed by a ground station,
        it has no controller yet (the flight's is the first to speak, :meth:`_handle`)."""
        if from_gcs:
            self.link.forget_peer()
        self.link.trial = None  # a flight on: its controller is answered freely (its arm's first state included)
        self.targets.applied = None
        if not from_gcs:
            self.missions.flight_armed()  # a ground station's started mission: flown from now

    def _requested(self, mid: int, own: bool = True) -> list[Any]:
        """What a REQUEST_MESSAGE (or GET_HOME_POSITION) of ``mid`` is answered with; a HEARTBEAT with
        CURRENT_EVENT_SEQUENCE, as the 1 Hz one (Announcer.beat): a controller that asks for it when its link is back
        learns the EVENTs it missed (a failsafe's) before it judges the vehicle by the HEARTBEAT."""
        msgs = self.streaming.message(mid, own)
        if mid == mavlink.MAVLINK_MSG_ID_HEARTBEAT:
            msgs.append(self.announcer.ring.current())
        return msgs

    def _clock_ns(self) -> int:
        """The vehicle's clock for TIMESYNC: simulation time (ns), as PX4 uses its own clock in
        lockstep; on the wall clock it runs on between physics steps. Never 0: a TIMESYNC with
        tc1 = 0 is a request, not an answer."""
        return max(int(self.clock.time_s(time.monotonic(), self.t) * 1e9), 1)
