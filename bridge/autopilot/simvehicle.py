"""The simulated vehicle without its radio: plant, arming, command timeout and failsafe.

In:  normalised paper-frame commands (``wrench``: u / u_max; ``motors``: omega / omega_max), arm and
     disarm, a delivery callback called with the plant time (s) before each physics step, and a timeline of
     faults and weather changes (:mod:`plant.events`, mission times s) acted on at the start of their period
Out: what the vehicle publishes after each control period (:meth:`SimVehicle.published`: its
     on-board estimate of the state, eq. 7, NWU: m, m/s, rad, rad/s; the true state under the
     ``truth`` estimator), the mode (offboard, failsafe, landed) and the events
     (:class:`~bridge.autopilot.vehicleevents.Event`: t s, kind, text, and who caused it)

Shared by the in-process loop and the MAVLink vehicle so that both fly, time out and land the same way. Time
advances in control periods of ``physics_hz / rate_hz`` physics steps; the command is held over the period
(zero-order hold).

Out of offboard control and armed, the vehicle's own :class:`~bridge.autopilot.onboard.OnboardController` flies its
target at every physics step (:meth:`SimVehicle.fly_onboard`): the failsafe's action (``[failsafe] action``), and
whatever a later mode hands it. Under a target that lands, resting on the ground, it disarms after COM_DISARM_LAND
(mode ``landed``). Mode changes happen at the start of a control period, the same step in every clock.

The vehicle owns its sensors (:class:`plant.sensors.SensorSuite`) and its estimator
(:mod:`bridge.autopilot.estimator`): the suite samples the true state once at t = 0 and after every physics step,
the estimator takes what arrived, and both the controller (through what is published) and the on-board controller
fly on the estimate. Under ``truth`` there is no suite: the estimate is the plant's state itself, read directly, so
truth flights are the same to the bit and as fast.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

from bridge.autopilot.batterywatch import BatteryWatch
from bridge.autopilot.estimator import Estimator, TruthEstimator, estimator_nees
from bridge.autopilot.failsafe import (
    ACTION_TEXT,
    FailsafeConfig,
    PositionHold,
    ReturnConfig,
    Takeoff,
    Target,
    failsafe_target,
    landing_target,
)
from bridge.autopilot.impactwatch import ImpactWatch
from bridge.autopilot.landdisarm import LandDisarm
from bridge.autopilot.modes import (  # noqa: F401  (the modes: imported from here by the rest of the bridge)
    FAILSAFE,
    GROUND_MODES,
    HOLD,
    LAND,
    LANDED,
    OFFBOARD,
    RTL,
    TAKEOFF,
    end_target,
    mode_target,
)
from bridge.autopilot.onboard import OnboardController
from bridge.autopilot.params import VehicleParams, change_param, read_param, shown_value
from bridge.autopilot.positionloss import NOAID_TIMEOUT_US, PositionWatch
from bridge.autopilot.timeline import act_on, changes_nothing
from bridge.autopilot.touchdownwatch import TouchdownWatch
from bridge.autopilot.vehiclechecks import check_battery, check_limits, check_position, prearm_refusal
from bridge.autopilot.vehicleevents import Event, ParamChanged, Sender
from controller.nominal import Nominal
from missions.geofence import Geofence
from plant import Quadrotor
from plant.events import TimedEvent
from plant.sensors import SensorSuite

NEES_EVERY = 10  # control steps between NEES samples (its solve costs a fifth of an EKF flight if every step)
TAKEOFF_DONE_M = 0.1  # m from its height: a takeoff is done and the vehicle holds there (PX4: HOLD after TAKEOFF)


@dataclass
class SimVehicle:
    plant: Quadrotor
    substeps: int
    failsafe: FailsafeConfig = field(default_factory=FailsafeConfig)
    armed: bool = False
    mode: str = OFFBOARD
    events: list[Event] = field(default_factory=list)
    sensors: SensorSuite | None = None  # None: the estimator is truth (nothing to sample)
    estimator: Estimator | None = None  # None: truth, reading the plant
    takeoff_alt_m: float = 2.5  # m above the start: NAV_TAKEOFF's altitude when it gives none (MIS_TAKEOFF_ALT)
    timeline: tuple[TimedEvent, ...] = ()  # faults and weather changes (plant/events.py), in time order
    # the [wind] gusts' (mission time s, text), in time order (WindConfig.gust_notes): the plant flies them, the
    # vehicle says each at its control step as it says an --at gust (a wind event)
    gust_notes: tuple[tuple[float, str], ...] = ()
    failure_injection: int = 0  # SYS_FAILURE_EN: a ground station's MAV_CMD_INJECT_FAILURE is acted on (1) or not
    rtl: ReturnConfig = field(default_factory=ReturnConfig)  # Return mode's heights (RTL_RETURN_ALT, RTL_DESCEND_ALT)
    preflight_disarm_s: float = 10.0  # COM_DISARM_PRFLT (s): a ground station's arm on the ground times out
    rally: tuple[tuple[float, float], ...] = ()  # m: rally points, where Return may land instead (missions.rally)
    max_hor_m: float = 0.0  # GF_MAX_HOR_DIST (m): the farthest from home it may fly, horizontally; 0: any
    max_ver_m: float = 0.0  # GF_MAX_VER_DIST (m): the highest above home it may fly; 0: any
    fence: Geofence | None = None  # the fence it holds (the mission's, or a ground station's upload), watched as these
    fence_action: int = 2  # GF_ACTION: at a breach 0 nothing (unwatched), 1 warn, 2 hold, 3 return, 4 terminate, 5 land
    # the run's record (its mission.toml) holds the fence, so its trace check judges it; an upload's is not, unless
    # the controller downloads it before the flight: with GF_ACTION 0 that one's first breach is still said, for the
    # record alone (vehiclechecks.check_limits). Decided by bridge.nodes.vehicle.zones.HeldZones alone (the uploads
    # and the downloads are there); the mission's own fence, the start's, is the record's
    fence_recorded: bool = True
    battery_watch: BatteryWatch = field(default_factory=BatteryWatch)  # BAT_*_THR, COM_LOW_BAT_ACT
    land_disarm: LandDisarm = field(default_factory=LandDisarm)  # COM_DISARM_LAND: landed, it disarms after it
    reference_z: Callable[[float], float] | None = None  # m at mission time s: judges touchdowns (touchdownwatch)
    noaid_timeout_us: int = NOAID_TIMEOUT_US  # EKF2_NOAID_TOUT: unaided this long, the position is lost (positionloss)

    def __post_init__(self) -> None:
        if self.estimator is None:
            self.estimator = TruthEstimator(lambda: self.plant.state)
        if self.sensors is not None:
            self.estimator.step(self.plant.t, self.sensors.sample(self.plant.t, self.plant.state))
        self.onboard = OnboardController(Nominal.from_profile(self.plant.profile))
        self.last_command_t = 0.0
        self.land_at: float | None = None  # hold: the plant time its hold ends and it lands
        self.took_off = False  # off the ground since arming (PX4's auto-disarm: COM_DISARM_LAND, else _PRFLT)
        X0 = self.plant.state
        self._start_z = X0[4]  # m: TAKEOFF's altitude is above the start
        self.home = (X0[0], X0[2], X0[4])  # m: where Return mode flies back to (the start: the ground station's home)
        self._takeoff_alt = self.takeoff_alt_m  # m: the altitude the selected TAKEOFF climbs to
        self._zero = (0.0, 0.0, 0.0, 0.0)
        self._pending_events = list(self.timeline)
        self._pending_notes = list(self.gust_notes)
        self._mission_t0: float | None = 0.0  # plant time (s) of the mission's time 0 (None: not known yet)
        self._injected: list[tuple[TimedEvent, Sender]] = []  # a ground station's, acted on next period (schedule)
        self._impact = ImpactWatch()  # the hard touchdown's verdict: armed as it touched down or not (plant_verdict)
        self._touchdown = TouchdownWatch()  # a soft one armed in OFFBOARD, mid-mission: a touchdown (plant_verdict)
        self._period_s = self.plant.dt * self.substeps
        self.beyond: set[str] = set()  # limits said to be passed: GF_MAX_* and the fence (once each, until changed)
        self.arming_refused: str | None = None  # why the last arm was denied (arming_denied), until it arms
        self.position = PositionWatch()  # the horizontal position estimate's validity (vehiclechecks.check_position)
        if self.armed and self.arming_denied():  # offline: armed at the start, if its pre-arm check passes
            self.armed = False

    @property
    def t(self) -> float:
        return self.plant.t

    def published(self) -> tuple[float, ...]:
        """The state the vehicle knows now: its estimate at the plant time (the true state under truth)."""
        if self.sensors is None:
            return self.plant.state
        assert self.estimator is not None
        return self.estimator.estimate(self.plant.t)

    def nees(self, estimate: tuple[float, ...]) -> float:
        """NEES of ``estimate`` (the one published now) against the estimator's covariance at every
        :data:`NEES_EVERY` th control step (nan between: the same steps in every clock); 0 under truth
        (the estimate is the state: no error to weigh)."""
        if self.sensors is None:
            return 0.0
        if round(self.plant.t / (self.plant.dt * self.substeps)) % NEES_EVERY:
            return math.nan
        assert self.estimator is not None
        return estimator_nees(self.estimator, self.plant.state, estimate)

    def event(self, kind: str, text: str, **fields: Any) -> Event:
        """Record an event now; ``fields``: its typed fields (:class:`Event`)."""
        e = Event(self.plant.t, kind, text, **fields)
        self.events.append(e)
        return e

    def hold_timeline(self) -> None:
        """Real time: the vehicle's plant runs before the flight, whose time 0 is not known yet; the timeline
        waits for :meth:`start_mission_clock`, and so does the plant's disturbance (it acts on the flight's time, as
        offline: counted from the vehicle's start, a controller that came 1.66 s late flew its phase turned by half a
        period, and a vehicle held on the ground by a downward push it never had offline)."""
        self._mission_t0 = None
        self.plant.disturbance_t0 = None

    def start_mission_clock(self, t0: float) -> None:
        """The mission's time 0 is plant time ``t0`` (s; real time: the state the flight's first target answers):
        from now the timeline and the wind's gusts count from it (once per vehicle)."""
        if self._mission_t0 is not None:
            return
        self._mission_t0 = t0
        self.plant.disturbance_t0 = t0
        wind = self.plant.wind
        if wind is not None:
            wind.gusts = [replace(g, t_s=g.t_s + t0) for g in wind.gusts]

    @property
    def mission_t0(self) -> float | None:
        """Plant time (s) of the mission's time 0: 0 offline and in lockstep; real time, None until it is known."""
        return self._mission_t0

    def start_mission_clock_now(self) -> None:
        """A flight with no target yet begins now (a ground station's, flown by the on-board controller): the
        mission's time 0 is the control step that begins at or after now, the first it flies whole (once per
        vehicle, as :meth:`start_mission_clock`: a controller's first target later moves it no more)."""
        n = math.ceil(self.plant.t / self._period_s - 1e-9)
        self.start_mission_clock(n * self._period_s)

    def not_reached(self) -> list[str]:
        """The timeline's events and the ``[wind]`` gusts never acted on (``t=T s: what``, mission time, in order):
        the flight ended, or the vehicle stopped, before their time, or its time 0 never came."""
        late = sorted([*((e.t_s, e.text()) for e in self._pending_events), *self._pending_notes], key=lambda n: n[0])
        return [f"t={t:.3f} s: {text}" for t, text in late]

    def arm(self, from_hold: bool = False) -> None:
        """Arm and take offboard commands (from failsafe or landed too). Not while armed in a mode a
        ground station chose (HOLD, LAND, TAKEOFF): the vehicle is the ground station's until it
        selects OFFBOARD again (:meth:`set_mode`), or (``from_hold``) it started a mission armed in HOLD."""
        if self.armed and self.mode in GROUND_MODES and not from_hold:
            return
        if not self.armed and self.arming_denied():
            return
        if not self.armed or self.mode != OFFBOARD:
            self.armed = True
            self.mode = OFFBOARD
            self.last_command_t = self.plant.t
            self._onboard_off()
            self.event("armed", "armed, offboard control")

    def arm_in_mode(self) -> None:
        """A ground station's arm: in the mode it selected (HOLD, LAND, TAKEOFF: flown by the on-board
        controller from now), else as :meth:`arm` (offboard control)."""
        if self.armed or self.mode not in GROUND_MODES:
            self.arm()
            return
        if self.arming_denied():
            return
        self.armed = True
        self.event("armed", f"armed, {self.mode.upper()}")
        self._engage(self.mode, self._takeoff_alt)

    def set_mode(self, mode: str, takeoff_alt_m: float | None = None, hold_at: PositionHold | None = None) -> None:
        """A ground station's mode (OFFBOARD, HOLD, LAND, RTL, TAKEOFF to ``takeoff_alt_m`` above the start,
        :attr:`takeoff_alt_m` if None), at the start of a control period. Armed, the vehicle flies it from this
        step: HOLD holds where it is (or flies to ``hold_at`` and holds there: DO_REPOSITION), LAND lands where it
        is, TAKEOFF climbs over where it is, OFFBOARD takes the controller's targets again (its timeout counts from
        now). Disarmed, it is the mode the next arm from a ground station arms in. A request that changes nothing
        (OFFBOARD in OFFBOARD; disarmed, the mode already selected; HOLD in HOLD, armed, as PX4's navigation state
        stays: a reposition under way goes on) is no event: the flight is the same."""
        alt = self.takeoff_alt_m if takeoff_alt_m is None else takeoff_alt_m
        if self.mode == mode and (mode == OFFBOARD or (not self.armed and alt == self._takeoff_alt)
                                  or (mode == HOLD and hold_at is None)):
            return
        if mode == OFFBOARD:
            if self.armed and self.mode != OFFBOARD:
                self._onboard_off()
                self.last_command_t = self.plant.t
            self.mode = OFFBOARD
            self.event("mode", "OFFBOARD" if self.armed else "OFFBOARD (disarmed: armed in it next)", mode=OFFBOARD,
                       armed=self.armed)
            return
        self._takeoff_alt = alt
        if not self.armed:
            self.mode = mode
            self.event("mode", f"{mode.upper()} (disarmed: armed in it next)", mode=mode, armed=False)
            return
        if mode == TAKEOFF and not self.plant.on_ground and self.published()[4] >= self._start_z + alt:
            mode = HOLD  # already above it: PX4 refuses nothing here, it holds
        self.land_at = None
        self.mode = mode
        self._engage(mode, alt, hold_at)

    def _engage(self, mode: str, alt: float, hold_at: PositionHold | None = None) -> None:
        target, text = mode_target(mode, self.published(), takeoff_z=self._start_z + alt, alt=alt, home=self.home,
                                   descent_rate=self.failsafe.descent_rate, rally=self.rally, rtl=self.rtl,
                                   hold_at=hold_at, slowdown=self.failsafe.slowdown, landed=self.plant.on_ground,
                                   flew=self.took_off)
        if target.lands and self.land_disarm.waits_under(self.onboard.target):
            self.land_disarm.target = target  # landed: its COM_DISARM_LAND wait goes on, whatever the mode (PX4)
        self.fly_onboard(target, mode)
        self.event("mode", text, mode=mode, armed=True)

    def end_mission(self, action: str) -> None:
        """The mission's time is flown (``[end] action``): :func:`~bridge.autopilot.modes.end_target` flown by the
        on-board controller from this control period, in every clock, an ``end`` event saying which (at the
        mission's end, on the vehicle's clock). Only armed under offboard control (a failsafe keeps its action)."""
        if self.armed and self.mode == OFFBOARD:
            target, mode, text = end_target(action, self.published(), self.failsafe, self.home,
                                            self.plant.on_ground, self.took_off)
            self.fly_onboard(target, mode)
            self.event("end", text)

    def disarm(self, why: str = "disarmed") -> None:
        if self.armed:
            self._impact.disarming(self.plant)
            self.armed = self.took_off = False
            self.plant.command(self._zero)
            self._onboard_off()
            self.event("disarmed", why)

    def _onboard_off(self) -> None:
        self.onboard.disengage()
        self.land_at = None

    def params(self, sysid: int = 1) -> VehicleParams:
        """The settings the parameters read (:mod:`bridge.autopilot.params`), as they are now."""
        b = self.battery_watch
        return VehicleParams(self.failsafe, self.takeoff_alt_m, sysid, self.failure_injection, self.rtl,
                             self.preflight_disarm_s, self.max_hor_m, self.max_ver_m, self.fence_action, b.low,
                             b.critical, b.emergency, b.action, self.noaid_timeout_us,
                             self.land_disarm.delay_s)

    def change_param(self, name: str, value: float, sysid: int = 1) -> Event | None:
        """Set parameter ``name`` (PX4's name, :mod:`bridge.autopilot.params`) to ``value``, checked
        (:class:`~bridge.autopilot.params.ParamRefused` if it cannot be): it acts from the next control
        period on (a failsafe already flying keeps the action it began with). A ``param`` event says it
        (returned); a set that leaves every setting as it was is no change: no event, None."""
        before = self.params(sysid)
        after = change_param(before, name, value)
        if after == before:
            return None
        self.failsafe, self.takeoff_alt_m = after.failsafe, after.takeoff_alt_m
        self.failure_injection, self.rtl = after.failure_injection, after.rtl
        self.preflight_disarm_s, self.fence_action = after.preflight_disarm_s, after.fence_action
        self.noaid_timeout_us = after.noaid_timeout_us
        self.land_disarm.delay_s = after.land_disarm_s
        b = self.battery_watch
        b.low, b.critical, b.emergency, b.action = (after.battery_low, after.battery_critical,
                                                    after.battery_emergency, after.low_battery_action)
        if (self.max_hor_m, self.max_ver_m) != (after.max_hor_m, after.max_ver_m):
            self.max_hor_m, self.max_ver_m = after.max_hor_m, after.max_ver_m
            self.beyond.clear()  # a new limit is watched afresh
        old, new = read_param(before, name), read_param(after, name)
        return self.event("param", f"{name} = {shown_value(new)} (was {shown_value(old)})",
                          param=ParamChanged(name, float(old), float(new)))

    def watch_fence(self, fence: Geofence | None) -> None:
        """Watch ``fence`` (a ground station's; None: none) from now on, afresh (whether the run's record holds it,
        :attr:`fence_recorded`, is its uploader's to say)."""
        self.fence = fence
        self.beyond.discard("fence")

    def prearm_refusal(self) -> str | None:
        """Why PX4's pre-arm checks deny arming now, or None (:func:`bridge.autopilot.vehiclechecks.prearm_refusal`)."""
        return prearm_refusal(self)

    def arming_denied(self) -> bool:
        """Whether arming is denied now (:meth:`prearm_refusal`); if so a ``preflight`` event says why, and
        :attr:`arming_refused` keeps it until the vehicle arms."""
        self.arming_refused = self.prearm_refusal()
        if self.arming_refused is not None:
            self.event("preflight", self.arming_refused)
        return self.arming_refused is not None

    def fly_onboard(self, target: Target, mode: str) -> None:
        """Hand the motors to the on-board controller flying ``target`` under ``mode`` (not
        offboard): from the next physics step on, until armed (offboard) again or disarmed."""
        self.mode = mode
        self.onboard.engage(target)

    def _enter_failsafe(self, silent_s: float) -> None:
        """No target for ``silent_s``: the failsafe's action, from the state it began in."""
        action = self.failsafe.action
        self.fly_failsafe(action, f"no actuator target for {silent_s:.3f} s: {ACTION_TEXT[action]}",
                           "failsafe: motors stopped")

    def fly_failsafe(self, action: str, text: str, stopped: str) -> None:
        """Mode failsafe, a ``failsafe`` event saying ``text``, and ``action`` (a ``[failsafe] action``) flown from
        here (``hold``: for COM_FAIL_ACT_T, then it lands); on the ground, or ``disarm``, the motors stop now
        (``stopped``: why)."""
        p = self.plant
        self.mode = FAILSAFE
        self.event("failsafe", text)
        landed = p.on_ground and action in ("descend", "land") and self.land_disarm.waits_under(self.onboard.target)
        if (p.on_ground and not landed) or action == "disarm":  # nothing to fly: motors off now, in this control step
            self.mode = LANDED
            self.disarm("landed: disarmed" if p.on_ground else stopped)
            return
        self.fly_onboard(failsafe_target(replace(self.failsafe, action=action), self.published(), self.home, self.rtl,
                                         self.rally), FAILSAFE)
        if landed:  # its COM_DISARM_LAND wait goes on under the failsafe's landing (LandDisarm.waits_under)
            self.land_disarm.target = self.onboard.target
        self.land_at = p.t + self.failsafe.hold_s if action == "hold" else None

    def _rest(self, target: Target) -> None:
        """On the ground under ``target``, a landing: motors off, a ``landed`` event, disarmed after COM_DISARM_LAND
        (:mod:`bridge.autopilot.landdisarm`; the failsafe's landing: mode ``landed``)."""
        first = target is not self.land_disarm.target
        if self.land_disarm.due(self.plant.t, target):
            self.mode = LANDED if self.mode == FAILSAFE else self.mode
            self.disarm("landed: disarmed")
        else:
            self.plant.command(self._zero)
            if first and self.plant.impact is None:  # a hard touchdown is no landing: the period's verdict is a crash
                self.event("landed", self.land_disarm.landed_text(self.published()))

    def _end_hold(self) -> None:
        """``hold``: its time is up; land where it held."""
        self.land_at = None
        X = self.published()
        self.fly_onboard(landing_target(self.failsafe, X, self.home), self.mode)
        self.event("landing", f"held {self.failsafe.hold_s:.3f} s: landing at x={X[0]:.3f} y={X[2]:.3f} m")

    def schedule(self, e: TimedEvent, by: Sender) -> None:
        """A ground station's injected fault (MAV_CMD_INJECT_FAILURE, checked by its handler): acted on by
        :meth:`inject` at the start of the next control period (lockstep: the step after it arrived), its
        event naming ``by``. When it acts depends on when it arrived, as a ground station's parameter does."""
        self._injected.append((e, by))

    def inject(self, e: TimedEvent, by: Sender | None = None) -> None:
        """Act on one event of the timeline now (:func:`~bridge.autopilot.timeline.act_on`); an event says it
        (``fault``, ``wind`` for the weather's, ``link``), naming ``by`` (a ground station's injection; None: the
        mission's timeline)."""
        gps = e.get("state") == "on" if e.kind == "gps" and e.get("state") is not None else None
        self.event(act_on(e, self.plant, self.sensors), e.text(), gps=gps).by = by

    def plant_verdict(self) -> str | None:
        """After a control period: ``diverged`` or ``crashed`` when the plant ends the flight now (its event
        logged), else None: a hard touchdown armed is ``crashed``, disarmed an ``impact`` (:mod:`.impactwatch`); a
        soft one armed in OFFBOARD mid-mission a ``touchdown`` (:mod:`.touchdownwatch`). The same in every clock."""
        verdict, said = self._impact.judge(self.plant, self.armed)
        if said is not None:
            self.event(*said)
        down = None if verdict else self._touchdown.judge(self.plant, self.armed and self.mode == OFFBOARD,
                                                          self.reference_z, self._mission_t0, self._period_s)
        if down is not None:
            self.event("touchdown", down)
        return verdict

    def _due(self, t_s: float, t0: float) -> bool:
        """Whether mission time ``t_s`` (s; mission time 0 at plant time ``t0``) is due: its control step, the first
        that begins at or after it, has begun."""
        p = self.plant
        return math.ceil(t_s / self._period_s - 1e-9) * self._period_s + t0 <= p.t + 0.25 * p.dt

    def command(self, c: tuple[float, float, float, float]) -> bool:
        """A valid actuator target (normalised, paper frame). Ignored unless armed offboard."""
        if not self.armed or self.mode != OFFBOARD:
            return False
        self.plant.command(c)
        self.last_command_t = self.plant.t
        return True

    def advance(self, deliver: Callable[[float], None] | None = None,
                next_due: Callable[[], float | None] | None = None) -> None:
        """One control period: failsafe check, then the physics substeps. ``deliver(t)``, if given, is called with the
        plant time (s) before the check and before each substep, so that messages an impaired link delivers in the
        middle of the period (:mod:`bridge.link.model`) act at the physics step they arrive in. ``next_due()``, if
        given, says when ``deliver`` has its next message (s; None: none in flight): with none due within the
        period, no sensors and the offboard command in force, the substeps are one call (the same bits)."""
        p = self.plant
        self.took_off = self.took_off or (self.armed and not p.on_ground)
        if self.armed and (self.max_hor_m or self.max_ver_m or self.fence is not None) and (
                self.fence_action or not self.fence_recorded):
            check_limits(self)
        if self.armed and p.battery is not None:
            check_battery(self, p.battery.remaining)
        pending, notes = self._pending_events, self._pending_notes
        t0 = self._mission_t0  # (0.0 offline and in lockstep: the same bits as plant time)
        while pending and t0 is not None and self._due(pending[0].t_s, t0):
            self.inject(pending.pop(0))
        while notes and t0 is not None and self._due(notes[0][0], t0):
            self.event("wind", notes.pop(0)[1])
        if self._injected:
            for e, by in self._injected:
                if not changes_nothing(e, p, self.sensors):  # an OK of a working unit: no change, no event
                    self.inject(e, by)
            self._injected.clear()
        if deliver is not None:
            deliver(p.t)
        if self.sensors is not None:  # (under truth the estimate is the state: never lost)
            check_position(self)
        if self.armed and self.mode == OFFBOARD and p.t - self.last_command_t > self.failsafe.timeout_s + 1e-9:
            self._enter_failsafe(p.t - self.last_command_t)
        if self.land_at is not None and p.t >= self.land_at - 1e-9:
            self._end_hold()
        if self.mode == TAKEOFF and self.armed:
            target = self.onboard.target
            if isinstance(target, Takeoff) and abs(self.published()[4] - target.z) < TAKEOFF_DONE_M:
                self.fly_onboard(PositionHold(target.x, target.y, target.z), HOLD)
                self.event("mode", f"HOLD: takeoff done at z={target.z:.3f} m", mode=HOLD, armed=True)
        onboard = self.onboard
        sensors, estimator = self.sensors, self.estimator
        if sensors is None and not (self.armed and self.mode != OFFBOARD and onboard.target is not None) and (
                deliver is None or (next_due is not None and _none_before(next_due(), p.t + self._period_s))):
            p.steps(self.substeps)  # nothing can happen between the physics steps: one call
            return
        for i in range(self.substeps):
            if deliver is not None and i:
                deliver(p.t)
            if self.armed and self.mode != OFFBOARD and onboard.target is not None:
                if onboard.target.lands and p.on_ground:
                    self._rest(onboard.target)
                elif onboard.target.idle and p.on_ground:  # a landed HOLD: idle on the ground, nothing flown
                    p.command(self._zero)
                else:
                    p.command(onboard.step(p.state if sensors is None else estimator.estimate(p.t), p.dt))
            p.step()
            # most physics steps bring nothing (IMU 250 Hz against 1 kHz physics): sample's own quiet test first
            if sensors is not None and p.t + sensors.eps >= sensors.next_event:
                arrived = sensors.sample(p.t, p.state)
                if arrived:
                    estimator.step(p.t, arrived)


def _none_before(due: float | None, end: float) -> bool:
    """Whether nothing is due (``due`` s, None: nothing in flight) before the period's ``end`` (s)."""
    return due is None or due > end
