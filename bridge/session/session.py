"""One SITL session in a run directory: start the children, supervise them, stop them, summarise.

In:  a prepared :class:`~bridge.core.flight.Flight`, a run directory, the session's options (clock,
     instance, GCS address, speed x real time, progress, signing key file)
Out: :meth:`Session.run`: a :class:`~bridge.record.runlog.Run`; the run directory's files (see
     :mod:`bridge.session`); the children's reports (:mod:`bridge.nodes.report`) as events; progress on
     stderr with ``live``; with ``announce``, once the vehicle is up, where a ground station connects
     (:func:`bridge.session.announce.vehicle_up_line`) on stderr

The children's command lines are :mod:`bridge.session.commands`'s, their ports :meth:`Session._start`'s; the
order their reports are acted on, :mod:`bridge.session.eventorder`'s; ``summary.json`` is
:func:`bridge.record.summary.session_summary`'s, from what the session saw.
"""

from __future__ import annotations

import json
import math
import os
import selectors
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from bridge.autopilot.vehicleevents import Sender, typed_fields
from bridge.core.flight import Flight, Progress, prepare
from bridge.core.scalar import FLIES_ENV
from bridge.mavlink.endpoint import CONTROLLER_COMPID, CONTROLLER_SYSID, LINK_PORT
from bridge.nodes.report import Event, MissionLoaded, Ready, Report
from bridge.record.endedby import failsafe_not_resumed
from bridge.record.ending import end_block, end_not_taken
from bridge.record.events import RunEvent, split_at_start
from bridge.record.joiner import TraceJoiner, off_clock_time
from bridge.record.linkblock import Cut
from bridge.record.linkextract import step_records
from bridge.record.missionclock import MissionClock
from bridge.record.runlog import EventLog, Run, RunRecord
from bridge.record.summary import ChildEnd, SessionFacts, SessionSummary, controller_completed, session_summary
from bridge.record.wallclock import FLYING_ON
from bridge.session.alone import is_frozen, landing_wait_s
from bridge.session.announce import vehicle_up_line
from bridge.session.children import (
    READY_TIMEOUT_S,
    STOP_DEADLINE_S,
    Child,
    ChildError,
    catch_stop_signals,
    free_udp_port,
    stop_children,
)
from bridge.session.commands import Commands
from bridge.session.eventorder import in_cause_order


class Session:
    """One SITL session in a run directory; :meth:`run` flies it."""

    def __init__(self, flight: Flight, path: Path, *, realtime: bool, instance: int | None, gcs: str | None,
                 speed: float | None, progress: Progress | None, live: bool, key: Path | None = None,
                 await_mission: bool = False, sysid: int | None = None, gate: Path | None = None,
                 start_timeout: float | None = None, radio: tuple[Path, int] | None = None,
                 announce: bool = False, label: str | None = None) -> None:
        self.flight = flight
        self.announce = announce  # once the vehicle is up, say on stderr where a ground station connects
        self.radio = radio  # a fleet's one radio: its file, this vehicle's user (relay's or controller's --radio)
        self.gate = gate  # a lockstep fleet's shared clock: the vehicle's gate file (bridge.session.fleet)
        self.start_timeout = start_timeout  # s: the controller's --start-timeout (None: its default)
        self.who = f"{label}: " if label else ""  # a fleet's "vehicle <id>": which one its lines on stderr are about
        # --await-mission: ``flight`` holds the settings only; the mission is the controller's, once a ground
        # station has started one (its ``mission`` report: :meth:`_mission_loaded`); no trace is joined before
        self.await_mission = await_mission
        self.mission_known = not await_mission
        self.transfer: dict[str, Any] | None = None
        self.key = key  # the signing key file (its path only) both children get as --key
        self.path = path
        self.realtime = realtime
        self.instance = instance
        self.gcs = gcs
        self.speed = speed
        self.progress = progress
        self.live = live and sys.stderr.isatty()
        # a fleet's vehicle i is system i; else a mission's MAV_SYS_ID, else the instance's, as PX4 SITL's
        self.sysid = sysid if sysid is not None else \
            flight.params.sysid if "MAV_SYS_ID" in flight.mission.params else (instance or 0) + 1
        self.listen = f"127.0.0.1:{LINK_PORT + instance}" if instance is not None else "127.0.0.1:0"
        self.events: list[RunEvent] = []
        self.vehicle: Child | None = None
        self.controller: Child | None = None
        self.relay: Child | None = None  # real time with an impaired link: bsst relay between the two
        self.vehicle_armed = False
        self.diverged = False  # (a fleet's vehicle whose plant halted flies on no more: bridge.session.fleet)
        self.died: str | None = None
        self.aborted = False
        self.interrupted = False  # set by Ctrl-C / SIGTERM (see catch_stop_signals)
        self._event_log: EventLog | None = None
        self.clock = MissionClock(vehicle_first=await_mission or not realtime)  # the events' against the vehicle's
        self._early: list[tuple[Child, Report]] = []  # reports read while starting, handled once all are up
        self.flies_on: Callable[[], bool] | None = None  # a fleet's: a vehicle taken over flies on under it now?
        # a fleet's: told once the vehicle process has ended (frozen: killed by the session, bridge.session.alone)
        self.vehicle_ended: Callable[[bool], None] = lambda frozen: None
        self.flying_on = False

    # -- the whole session ---------------------------------------------------------------------
    def run(self, plots: bool, keep: bool) -> Run:
        m = self.flight.mission
        self.record = record = RunRecord(self.path, m)
        self._event_log = record.events
        self.joiner = self._joiner(self.flight)
        self.t_wall0 = time.monotonic()
        restore = catch_stop_signals([self])
        try:
            try:
                self._start()
                self._supervise()
            except KeyboardInterrupt:
                self.aborted = True
                self._handle(self._read_all(self.vehicle))  # what it said before the stop: before the stop's note
                self._note("aborted", "interrupted (Ctrl-C or SIGTERM): stopping both processes", "session")
            except ChildError:
                pass  # already said by name (_died); the outcome is "aborted", the files are kept
            finally:
                try:
                    self._stop_children()
                    self._vehicle_gone()
                finally:
                    restore()
                    self.joiner.controller_done = True
                    self._join()
                    self.joiner.close()
            done = self._summary(time.monotonic() - self.t_wall0)
            arrays, summary = done.arrays, done.summary
        finally:
            record.close()  # after the summary: events.log gets the run's end and verdicts, then is sorted
        m = self.flight.mission  # --await-mission: the ground station's
        if keep:
            title = f"{m.name} ({m.controller}, {self.flight.profile.name}, SITL {summary['clock']})"
            record.finish(arrays, summary, title, plots and not self.aborted)
        if self.live:
            sys.stderr.write("\n")
        return Run(arrays, summary, self.path if keep else None, self.joiner.after_at)

    def _summary(self, wall: float) -> SessionSummary:
        """The trace arrays and ``summary.json`` (:func:`bridge.record.summary.session_summary`, from what
        the session saw); its closing notes also go to ``events.log``."""
        joined = self.joiner.joined(delivered=self.relay is not None)  # a relay may reorder: every packet's delay
        rate = self.flight.mission.rate_hz
        facts = SessionFacts(
            clock="realtime" if self.realtime else "lockstep", wall_s=wall, aborted=self.aborted, died=self.died,
            off_clock_t=None if self.realtime else off_clock_time(self.path / "vehicle.bin", rate, joined.k0 or 0),
            sitl={"instance": self.instance, "listen": self.listen, "gcs": self.gcs, "sysid": self.sysid,
                  "speed": self.speed, "died": self.died, "signed": self.key is not None,
                  **({"flew_on": True} if self.flying_on else {}),  # taken over, it flew on (a fleet's: fleet.py)
                  **({"gate": self.vehicle.stats.get("gate") if self.vehicle else None} if self.gate else {})},
            mission_transfer=self.transfer, cut=self._cut())
        events = self.clock.on_mission_clock(self.events)
        out = session_summary(self.flight, facts, joined, events, _end(self.vehicle), _end(self.controller),
                              _end(self.relay), self._relay_stats(), (CONTROLLER_SYSID, CONTROLLER_COMPID))
        ended = [e for e in events if e.source == "vehicle" and e.t is not None]
        if any(e.kind == "end" for e in ended):  # the mission's end action, flown after its figures' rows
            shift = (joined.k0 or 0) / rate  # its rows are on the vehicle's clock, the events on the mission's
            rows = [(t - shift, z, vz) for t, z, vz in self.joiner.after]
            out.summary["end"] = end_block(self.flight.mission.end_action, rows, ended)
        for e in out.notes:  # (each at its time: bridge.record.summary.notes_time)
            self.events.append(e)
            if self._event_log is not None:
                self._event_log.event(math.nan if e.t is None else e.t, e.kind, e.text, e.by, e.source)
        return out

    def _controller_completed(self) -> bool:
        """Whether the controller flew its mission to the end (:func:`bridge.record.summary.controller_completed`),
        its vehicle not in a failsafe no arm ended (a real-time link lost over the end hid it: it is left to land)
        and, armed, flying the end action it took (its ``end`` event, or its mode taken late, after its failsafe; one
        lost on the wire leaves the vehicle to its failsafe: it is left to land, until the third wave's fortieth
        session stopped in the air)."""
        mission = split_at_start(self.events)[0]
        end = self.flight.mission.duration_s
        untaken = end_not_taken("completed", "", mission, end)  # (taken late, after its failsafe: it flies it now)
        return controller_completed(_end(self.controller)) and failsafe_not_resumed(mission, end) is None and (
            not self.vehicle_armed or untaken is None or untaken["late_t"] is not None)

    # -- children ----------------------------------------------------------------------------------
    def _start(self) -> None:
        """Start the children at once (each one's start-up, ~0.5 s of Python and imports, overlaps the
        others'), every port they need chosen first, then wait until each is ready."""
        # the controller's source port, named to the vehicle before either starts: the vehicle hears the
        # controller's ids from that address only (through a relay, from the relay's back port), so no
        # other process can claim them, not even before the controller's first message
        source = free_udp_port()
        # (a fleet's one radio is its relays', even on a perfect link: without a rate it counts the bytes only)
        relayed = self.realtime and (self.flight.link.impaired or self.radio is not None)
        back = free_udp_port() if relayed else source
        if self.listen.endswith(":0"):
            self.listen = f"127.0.0.1:{free_udp_port()}"
        port = self.listen.rpartition(":")[2]
        told = Commands(self.path, self.realtime, self.gcs, self.sysid, self.speed, self.await_mission, self.gate,
                        self.start_timeout, self.radio, self.flight.param_changes, self.key)
        env = {**os.environ, FLIES_ENV: self.flight.kernels_flown()}  # loaded by their fork server, before the fork
        self.vehicle = Child("vehicle", told.vehicle(self.listen, back), self.path / "vehicle.log", env)
        to = port
        if relayed:  # the link model on the wall clock, between the two
            to = str(free_udp_port())
            self.relay = Child("relay", told.relay(to, port, back, source), self.path / "relay.log")
        self.controller = Child("controller", told.controller(to, source), self.path / "controller.log", env)
        try:
            ready = self._wait_ready(self.vehicle)
            self._note("started", f"vehicle pid {self.vehicle.pid}: {ready.describe()}", "session")
            if self.announce:
                sys.stderr.write(vehicle_up_line(ready, self.await_mission, self.realtime, self.speed,
                                                 signed=self.key is not None) + "\n")
                sys.stderr.flush()
            if self.relay is not None:
                line = self._wait_ready(self.relay).describe()
                self._note("started", f"relay pid {self.relay.pid}: {line}", "session")
            self._wait_ready(self.controller)
            self._note("started", f"controller pid {self.controller.pid}", "session")
        finally:  # what the children said while the others started, in the order it happened
            early, self._early = self._early, []
            self._handle(early + self._read_all(self.controller, self.relay, self.vehicle))

    def _wait_ready(self, child: Child) -> Ready:
        """Block until ``child`` reports :class:`~bridge.nodes.report.Ready` (returned), or raise
        :class:`ChildError`."""
        deadline = time.monotonic() + READY_TIMEOUT_S
        sel = selectors.DefaultSelector()
        sel.register(child.fd, selectors.EVENT_READ)
        try:
            ready: Ready | None = None
            while True:
                # every line read is handled, the ones after "ready" too: the children start at once, so the
                # controller may arm the vehicle before its "ready" is read, and its "event ... armed" line
                # then comes in the same read (dropped, the session saw a flight never armed)
                for report in child.reports():
                    if isinstance(report, Ready) and ready is None:
                        ready = report
                    else:
                        self._early.append((child, report))
                if ready is not None:
                    return ready
                if child.eof or child.proc.poll() is not None:
                    child.proc.wait()
                    self._early += [(child, r) for r in child.reports()]  # what it wrote last: its refusal, if any
                    self._died(child, starting=True)
                if self.interrupted:
                    raise KeyboardInterrupt
                left = deadline - time.monotonic()
                if left <= 0:
                    self.died = child.name
                    self._note("died", f"{child.name} (pid {child.pid}) not ready within {READY_TIMEOUT_S:g} s",
                               "session")
                    raise ChildError(child.name)
                sel.select(min(left, 0.5))
        finally:
            sel.close()

    def _died(self, child: Child, starting: bool = False) -> None:
        """A child is gone: say so by name. Its refusal of its input at its start (its ``bad_input`` report,
        :attr:`~bridge.session.children.Child.refused`) is the user's: raised again from its typed fields, said as
        the child said it; anything else is ours, said with the last line of its stderr (quoted, never read: until the
        third wave's forty-fourth session a refusal was cut out of that line, and a law's own line at its exit, after
        the refusal's, was said as the refusal)."""
        if starting and child.refused is not None:
            raise child.refused.error()
        err = child.refused.text if child.refused is not None else child.last_error()
        self.died = child.name
        self._note("died", f"{child.name} (pid {child.pid}) {child.exit_text()}" + (f": {err}" if err else ""),
                   "session")
        if starting:
            raise ChildError(f"{child.name} (pid {child.pid}) {child.exit_text()}" + (f": {err}" if err else ""))

    def _supervise(self) -> None:
        veh, ctl = self.vehicle, self.controller
        assert veh is not None and ctl is not None
        sel = selectors.DefaultSelector()
        sel.register(veh.fd, selectors.EVENT_READ, veh)
        sel.register(ctl.fd, selectors.EVENT_READ, ctl)
        landing_deadline: float | None = None
        try:
            while True:
                sel.select(0.1)
                if self.interrupted:
                    raise KeyboardInterrupt
                self._handle(self._read_all(ctl, veh))
                self._join_in_flight()
                self._show_progress()
                if veh.proc.poll() is not None:
                    self._vehicle_gone()  # (a fleet's other vehicles wait for it at their gates: told first)
                    self._handle([(veh, r) for r in veh.reports()])  # its last words: events it said before it went
                    self._died(veh)
                    return
                if self.relay is not None and self.relay.proc.poll() is not None:
                    self._died(self.relay)
                    return
                if ctl.proc.poll() is not None and landing_deadline is None:
                    # its last words, and the vehicle's about the same moments, in the order they happened
                    self._handle(self._read_all(ctl, veh))
                    sel.unregister(ctl.fd)  # read to its end: a pipe at its end is always readable (select spun)
                    self.joiner.controller_done = True
                    self._join()  # all the controller wrote (the landing time below reads the rows)
                    if ctl.done is not None and ctl.done.reason:  # a controller that gave up says why
                        sys.stderr.write(("\n" if self.live else "") + f"bsst sitl: {self.who}controller: "
                                         f"{ctl.done.reason}\n")
                    taken = ctl.done is not None and ctl.done.taken_over is not None
                    if is_frozen(ctl.done, self.gate is not None):  # no landing of its own: the others wait for it
                        self._kill_frozen(veh)
                        return
                    # taken: a ground station flies it now (HOLD, LAND, ...): nothing of the mission to wait for; in a
                    # fleet it flies on under it, recorded, until the rest of the fleet is done (bridge.session.fleet)
                    self.flying_on = taken and self.vehicle_armed and self.flies_on is not None and self.flies_on()
                    if (self._controller_completed() or not self.vehicle_armed or taken) and not self.flying_on:
                        if ctl.proc.returncode not in (0, 1):
                            self._died(ctl)
                        return
                    if ctl.done is None:  # killed or crashed: a death, not an outcome
                        self._died(ctl)
                    # the vehicle is on its own: let it finish its failsafe (land and disarm), or fly on
                    wait = landing_wait_s(self.flight, self.joiner.rows[-2000:], self.speed)
                    landing_deadline = math.inf if self.flying_on else time.monotonic() + wait
                    self._note("waiting", FLYING_ON if self.flying_on else "vehicle on its own: waiting up to "
                               f"{wait:.0f} s for it to land and disarm", "session")
                if landing_deadline is not None and (not self.vehicle_armed or time.monotonic() > landing_deadline
                                                     or self.flying_on and not self.flies_on()):  # type: ignore[misc]
                    return
        finally:
            sel.close()

    def _stop_children(self) -> None:
        """Stop the controller, the relay, the vehicle (:func:`~bridge.session.children.stop_children`): what they
        said last is handled, a child killed at the deadline said so."""
        last_words, killed = stop_children([c for c in (self.controller, self.relay, self.vehicle) if c is not None])
        for c in killed:
            self._note("killed", f"{c.name} (pid {c.pid}) did not stop within {STOP_DEADLINE_S:g} s: SIGKILL",
                       "session")
        self._handle(last_words)

    @staticmethod
    def _read_all(*children: Child | None) -> list[tuple[Child, Report]]:
        """What ``children`` wrote since last read, read in the order given: the controller before the vehicle,
        so that a vehicle's event (the cause: written before it answers) is never read after the controller's
        word about it (the effect), only in the same read or an earlier one."""
        return [(c, r) for c in children if c is not None for r in c.reports()]

    def _handle(self, reports: list[tuple[Child, Report]]) -> None:
        """Reports read together from several children, acted on in the order things happened
        (:func:`~bridge.session.eventorder.in_cause_order`)."""
        if self.clock.origin_s is None and getattr(self, "joiner", None) is not None:
            self._join()  # k0 may be in a row not joined yet: the mission's clock before these are stamped
        times = self.clock.stamps([(c.name == "vehicle", r.t if isinstance(r, Event) else -math.inf)
                                   for c, r in reports])
        for child, report, t in in_cause_order(reports, times, self.clock.vehicle_said):
            self._status(child, report, t)

    # -- status lines, events, progress -------------------------------------------------------------
    def _join(self) -> None:
        """Join the rows both halves have written (none before a ground station's mission is known)."""
        if self.mission_known:
            self.joiner.update()
            self._learn_origin()

    def _joiner(self, flight: Flight) -> TraceJoiner:
        """The join of ``flight``'s halves, live (``trace.csv`` written as the flight goes) in real time and in a
        lockstep fleet, whose eight and more processes share the two cores anyway (joined at the end, the
        fleet's four traces were written one after the other in one process while the cores idled)."""
        return TraceJoiner(self.path, flight, self.record.trace, lockstep=not self.realtime,
                           live=self.realtime or self.gate is not None)

    def _join_in_flight(self) -> None:
        """Join as the flight goes (a live join, :meth:`_joiner`), or else (one lockstep session) until the
        flight's time 0 is known, then once the controller is done, or when a note needs the time: that join took
        a core's share from the two processes flying the ping-pong (issue 25; docs/figures.md, sixteenth
        session); the halves are the live record meanwhile (the progress line reads the vehicle's newest)."""
        if self.joiner.live or self.joiner.k0 is None or self.joiner.controller_done:
            self._join()

    def _mission_loaded(self, report: MissionLoaded) -> None:
        """--await-mission: the controller has the ground station's mission and wrote it as flown
        (``mission.toml``): the session's flight, record and join are that mission's from now."""
        self.flight = flight = prepare(self.path / "mission.toml")
        self.record.mission = flight.mission
        self.transfer = t = report.transfer
        # noted before its rows are joined: the download came before the flight's time 0, which may be long flown
        # by the time this is read (it was stamped at the newest row joined: t=0.468 at --speed 0)
        self._note("mission", f"the controller downloaded {report.items} items in {t.get('duration_s', 0):.2f} s "
                              f"({t.get('re_requests')} requests again): {flight.mission.duration_s:.2f} s to fly",
                   "session")
        self.joiner = self._joiner(flight)
        self.mission_known = True

    def _status(self, child: Child, report: Report, t: float) -> None:
        """Act on one report (an event at ``t``, s on the events' clock: :meth:`_handle`)."""
        if isinstance(report, MissionLoaded) and child.name == "controller" and self.await_mission:
            self._mission_loaded(report)
        if not isinstance(report, Event):
            return
        kind = report.kind
        if not math.isfinite(report.t):
            t = report.t
        if child.name == "vehicle":
            if kind == "armed":
                self.vehicle_armed = True
            elif kind == "disarmed":
                self.vehicle_armed = False
            elif kind == "diverged":
                self.diverged = True
        self._note(kind, report.text, child.name, t, report.by, result=report.result, **typed_fields(report))

    def _learn_origin(self) -> None:
        """The mission's clock (the trace's, the controller's) as soon as a join finds its time 0, the vehicle's step
        k0 (:mod:`bridge.record.missionclock`: what came before it is on the vehicle's clock until then), so that no
        event is stamped between the two clocks."""
        if self.clock.origin_s is None and self.joiner.k0 is not None and (note := self.clock.learn(
                self.joiner.k0, self.flight.mission.rate_hz, len(self.events))):
            if self._event_log is not None:  # (its lines so far on the vehicle's clock: ordered on the mission's)
                self._event_log.clock_moved(self.clock.origin_s)
            self._note("clock", note, "session", 0.0)

    def _note(self, kind: str, text: str, source: str, t: float | None = None, by: Sender | None = None,
              **fields: Any) -> None:
        """Record an event (``fields``: its typed fields, :func:`~bridge.autopilot.simvehicle.typed_fields`)."""
        if t is None and getattr(self, "joiner", None):
            self._join()  # lockstep joins only on demand during the flight (_join_in_flight)
        if t is None:  # now on the vehicle's clock: its newest state joined, or its latest event if later (a state's
            # row may wait in its half's batch; before the mission's time 0: at the vehicle's latest event)
            newest = self.joiner.newest_t() if getattr(self, "joiner", None) else None
            now = 0.0 if newest is None else max((newest, *self.clock.vehicle_said.values()))
            t = self.clock.stamps([(False, now)])[0]
        self.events.append(RunEvent.at(t, kind, text, source, by, **fields))
        if self._event_log is not None:
            self._event_log.event(t, kind, text, by, source)
        if source == "session" and kind in ("died", "killed"):
            sys.stderr.write(("\n" if self.live else "") + f"bsst sitl: {self.who}{text}\n")

    def _vehicle_gone(self, frozen: bool = False) -> None:
        """The vehicle process has ended (``frozen``: killed so): a fleet is told, once (:attr:`vehicle_ended`)."""
        told, self.vehicle_ended = self.vehicle_ended, lambda frozen: None
        told(frozen)

    def _kill_frozen(self, veh: Child) -> None:
        """A lockstep fleet's vehicle frozen (:func:`~bridge.session.alone.is_frozen`): killed and reaped now (SIGKILL:
        a stopped process holds a SIGTERM until continued), said, and the other vehicles told at once."""
        veh.proc.kill()
        veh.proc.wait()
        self._note("killed", f"vehicle (pid {veh.pid}) frozen, its controller hearing nothing from it: SIGKILL; "
                   "the other vehicles fly on without it", "session")
        self._vehicle_gone(frozen=True)

    def _show_progress(self) -> None:
        now = self.joiner.newest() if self.live or self.progress else None
        if now is None:
            return
        t, err = now
        if self.progress is not None:
            self.progress(t, self.flight.mission.duration_s, err)
        if self.live:
            first = self.joiner.first_sent
            wall = time.monotonic() - (first if first is not None else self.t_wall0)
            sys.stderr.write(f"\rsitl t {t:7.2f} / {self.flight.mission.duration_s:.2f} s   "
                             f"real-time factor {t / max(wall, 1e-9):6.1f}x   3-D error {err:.2e} m   ")
            sys.stderr.flush()

    def _cut(self) -> Cut | None:
        """The vehicle or controller that died without its stats report (killed), with the per-step messages both
        tlogs hold up to its cut: the link's counts where its own are missing (None: none died so)."""
        dead = next((c for c in (self.vehicle, self.controller) if c is not None and c.name == self.died), None)
        if dead is None or dead.stats:
            return None
        modelled = not self.realtime and (self.flight.link.impaired or self.radio is not None)
        return Cut(dead.name, dead.exit_text(), step_records(self.path), modelled)

    def _relay_stats(self) -> dict[str, Any] | None:
        """What ``bsst relay --stats`` wrote on exit (None without a relay or a readable file)."""
        if self.relay is None:
            return None
        try:
            return json.loads((self.path / "relay.json").read_text())
        except (OSError, ValueError):
            return None


def _end(child: Child | None) -> ChildEnd | None:
    """How ``child`` ended, as the summary reads it (its exit, its stats report, the controller's outcome)."""
    if child is None:
        return None
    done = child.done
    return ChildEnd(child.name, child.proc.returncode, child.exit_text(), child.stats,
                    done.outcome if done is not None else None, done.reason if done is not None else None)
