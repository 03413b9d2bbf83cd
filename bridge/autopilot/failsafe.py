"""The vehicle's own failsafe, the targets its small position controller flies, and its gains (docs/design.md,
"Failsafe"); the controller itself is :mod:`bridge.autopilot.onboard`.

In:  the ``[failsafe]`` table (``timeout_s`` s, ``descent_rate`` m/s, ``resume``, ``action``, ``hold_s`` s),
     the paper state (eq. 7, NWU: m, m/s, rad, rad/s)
Out: a :class:`FailsafeConfig`; the target a failsafe flies, and each target's velocity set-point (m/s) for a
     state (:class:`Level`, :class:`PositionHold`, :class:`Land`, :class:`Takeoff`, :class:`ReturnHome`); the
     on-board controller's gains (:class:`OnboardGains`); Return mode's heights
     (:class:`ReturnConfig`, m above home) and the auto landing's speeds (:class:`LandSlowdown`) are
     bridge.autopilot.returnland's

No valid actuator target for longer than ``timeout_s`` of vehicle time and the vehicle
leaves offboard control; what it does then is ``action`` (PX4's offboard-loss action,
``COM_OBL_RC_ACT``, for the three that PX4 has):

- ``descend`` (default; the only action before there were four): level at its heading and sink
  at ``descent_rate``, no horizontal control (it drifts with the speed it had), disarm on the ground.
- ``land``: hold the horizontal position where the failsafe began while sinking at ``descent_rate``,
  disarm on the ground (PX4 4, Land mode: "land at the position where the mode was engaged"); as PX4's
  auto landing, faster above MPC_LAND_ALT2 (MPC_Z_V_AUTO_DN above MPC_LAND_ALT1: bridge.autopilot.returnland).
- ``hold``: hold the position and height where the failsafe began for ``hold_s``, then ``land``
  there (PX4 5, Hold). PX4 waits ``COM_FAIL_ACT_T`` in Hold before it takes a failsafe action
  (default 5 s, 0-25 s: "Before entering failsafe (RTL, Land, Hold), wait COM_FAIL_ACT_T seconds
  in Hold mode for the user to realize", PX4-Autopilot's commander parameters), and Land is what
  its offboard-loss action maps to (src/modules/commander/failsafe/failsafe.cpp,
  ``fromOffboardLossActParam``: 4 Land mode, 5 Hold mode, 7 Disarm); ``hold_s`` is that wait, with
  its default and range, and the landing after it is that action.
- ``disarm``: stop the motors at once (PX4 7, Disarm); the vehicle falls.
- ``return``: Return mode from where the failsafe began (PX4 3, Return; :class:`ReturnHome`: climb to
  RTL_RETURN_ALT, or near home the lower height of PX4's cone, home, down to RTL_DESCEND_ALT, land as ``land``),
  disarm on the ground.

A failsafe that begins on the ground disarms at once, whatever the action. The vehicle returns
to offboard control only when armed again.

**The on-board controller** (:class:`~bridge.autopilot.onboard.OnboardController`: its cascade there) is the
vehicle's own, not the paper's law; it flies the targets here, with these gains.

Gains (:class:`OnboardGains`): k_pos,xy = k_pos,z = 1.5 /s, k_vel = 3 /s (in the linear range a PD
on position with kp = 4.5 /s², kd = 3 /s: 2.1 rad/s, damping 0.71, a fifth of the attitude loop's
10 rad/s), k_i,xy = 0.5 /s², k_i,z = 2 /s² (PX4's MPC_Z_VEL_I_ACC default), a_i,max = 3 m/s²
(a plant 30 % heavier than its model), v_xy,max = 2 m/s, v_up = 1.5 m/s (PX4's MPC_TKO_SPEED),
v_down = 1 m/s, tilt_max = 0.35 rad (20 deg). ``Level`` (``descend``) is the earlier landing loop
exactly: level attitude at 6 rad/s (36, 12), velocity P only with k_vel,level = 2 /s and no
integral, u1 = m (g + 2 (-descent_rate - z')) / max(cos phi cos theta, 0.5). A later HOLD,
NAV_LAND, NAV_TAKEOFF or RTL mode flies the same controller with :class:`PositionHold`, :class:`Land`,
:class:`Takeoff` or :class:`ReturnHome` (``SimVehicle.fly_onboard``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from math import hypot
from typing import Any

from bridge.autopilot.returnland import LandSlowdown, ReturnConfig, return_height
from params import Table

FAILSAFE_ACTIONS = ("descend", "land", "hold", "disarm", "return")
# PX4's COM_OBL_RC_ACT value of the actions it has (commander_params.c: 3 Return, 4 Land, 5 Hold, 7 Disarm);
# ``descend`` (level, no position) has none.
PX4_OFFBOARD_LOSS_ACTION = {"land": 4, "hold": 5, "disarm": 7, "return": 3}
HOLD_RANGE_S = (0.0, 25.0)  # PX4's COM_FAIL_ACT_T range
# the one range of each number of ``[failsafe]``, shared by the table, the flags and the parameters
# (bridge.autopilot.params: COM_OF_LOSS_T, MPC_LAND_SPEED, COM_FAIL_ACT_T)
FAILSAFE_RANGES = {"timeout_s": (0.01, 60.0), "descent_rate": (0.05, 10.0), "hold_s": HOLD_RANGE_S}
ACTION_TEXT = {  # the failsafe event says what the vehicle does
    "descend": "level and descend",
    "land": "land here",
    "hold": "hold here, then land",
    "disarm": "stop the motors",
    "return": "return home (RTL), then land",
}


@dataclass(frozen=True)
class FailsafeConfig:
    timeout_s: float = 0.5
    descent_rate: float = 0.7  # m/s (PX4's MPC_LAND_SPEED default)
    resume: bool = False  # the controller re-arms and resumes when the link returns
    action: str = "descend"  # one of FAILSAFE_ACTIONS
    hold_s: float = 5.0  # hold: how long before it lands (PX4's COM_FAIL_ACT_T default)
    # the auto landing's speed above MPC_LAND_ALT2 (MPC_Z_V_AUTO_DN, MPC_LAND_ALT1, MPC_LAND_ALT2): parameters
    # only, not [failsafe] keys; LAND, Return's landing and the failsafe's land, hold and return fly it, not descend
    slowdown: LandSlowdown = LandSlowdown()

    def time_to_land_s(self, height_m: float) -> float:
        """Vehicle time from the failsafe to a disarm on the ground from ``height_m`` (the
        descent at ``descent_rate``; ``hold`` adds its hold; ``disarm``: at once). For ``land``,
        ``hold`` and the mission's end landing an upper bound: they come down faster above
        MPC_LAND_ALT2 (:attr:`slowdown`)."""
        if self.action == "disarm":
            return 0.0
        return (self.hold_s if self.action == "hold" else 0.0) + max(height_m, 0.0) / self.descent_rate


def failsafe_from_table(data: Mapping[str, Any], source: str) -> FailsafeConfig:
    t = Table(data, source, "failsafe")
    r = FAILSAFE_RANGES
    cfg = FailsafeConfig(
        timeout_s=t.number("timeout_s", 0.5, lo=r["timeout_s"][0], hi=r["timeout_s"][1]),
        descent_rate=t.number("descent_rate", 0.7, lo=r["descent_rate"][0], hi=r["descent_rate"][1]),
        resume=t.boolean("resume", False),
        action=t.string("action", "descend", choices=FAILSAFE_ACTIONS),
        hold_s=t.number("hold_s", 5.0, lo=r["hold_s"][0], hi=r["hold_s"][1]),
    )
    t.done()
    return cfg


# -- the on-board controller ----------------------------------------------------------------------


@dataclass(frozen=True)
class OnboardGains:
    """The on-board controller's gains (module docstring): SI, per second."""

    k_pos_xy: float = 1.5  # 1/s: position error -> velocity set-point
    k_pos_z: float = 1.5
    k_vel: float = 3.0  # 1/s: velocity error -> acceleration
    k_vel_level: float = 2.0  # 1/s: the same for Level (``descend``: the earlier landing loop's gain)
    k_i_xy: float = 0.5  # 1/s^2: integral of the velocity error
    k_i_z: float = 2.0
    a_i_max: float = 3.0  # m/s^2: the most the integral may add (anti-windup)
    v_xy_max: float = 2.0  # m/s
    v_up: float = 1.5  # m/s
    v_down: float = 1.0  # m/s
    tilt_max: float = 0.35  # rad
    k_att: float = 100.0  # 1/s^2: attitude PD (10 rad/s, critically damped)
    d_att: float = 20.0  # 1/s
    k_att_level: float = 36.0  # 1/s^2: the same for Level (the earlier loop's: 6 rad/s, critically damped)
    d_att_level: float = 12.0  # 1/s
    k_yaw: float = 4.0  # 1/s^2 (2 rad/s, critically damped)
    d_yaw: float = 4.0  # 1/s


DEFAULT_GAINS = OnboardGains()


@dataclass(frozen=True)
class Setpoint:
    """What a target asks of the velocity loop: horizontal velocity (None: level attitude, no
    horizontal control), vertical velocity (m/s, z up), heading (rad; None: only damp the yaw rate).
    ``level``: the earlier level-and-descend loop (vertical P with ``k_vel_level``, no integral)."""

    v_xy: tuple[float, float] | None
    v_z: float
    psi: float | None
    level: bool = False


def _xy_velocity(x: float, y: float, X: tuple[float, ...], g: OnboardGains,
                 v_max: float | None = None) -> tuple[float, float]:
    """Toward (x, y) in m, P on the distance, at most ``g.v_xy_max`` m/s (or ``v_max``, if lower)."""
    top = g.v_xy_max if v_max is None else min(v_max, g.v_xy_max)
    vx, vy = g.k_pos_xy * (x - X[0]), g.k_pos_xy * (y - X[2])
    n = hypot(vx, vy)
    return (vx, vy) if n <= top else (vx * top / n, vy * top / n)


def _z_velocity(z: float, X: tuple[float, ...], g: OnboardGains, up: float, down: float | None = None) -> float:
    """Toward height z (m), P on the distance, at most ``up`` m/s up and ``down`` (None: ``g.v_down``) m/s down."""
    v, d = g.k_pos_z * (z - X[4]), g.v_down if down is None else down
    return up if v > up else -d if v < -d else v


class Target:
    """Where the on-board controller flies: a set-point for the state X. ``lands``: the vehicle
    disarms once it rests on the ground under this target; ``idle``: resting on the ground under it, its motors
    idle (a landed HOLD, :class:`LandedHold`)."""

    lands = False
    idle = False

    def setpoint(self, X: tuple[float, ...], g: OnboardGains) -> Setpoint:
        raise NotImplementedError


@dataclass(frozen=True)
class Level(Target):
    """``descend``: level, sink at ``rate`` m/s, no horizontal control (the earlier landing loop)."""

    rate: float
    lands = True

    def setpoint(self, X: tuple[float, ...], g: OnboardGains) -> Setpoint:
        return Setpoint(None, -self.rate, None, level=True)


@dataclass(frozen=True)
class PositionHold(Target):
    """Hold (x, y, z) in m (HOLD; ``hold`` failsafe) and the heading ``psi`` rad, or with ``psi``
    None only stop turning (the yaw rate is damped; the heading stays where that leaves it); flown to
    across at most ``speed`` m/s if given (DO_REPOSITION's ground speed), else the gains' ``v_xy_max``."""

    x: float
    y: float
    z: float
    psi: float | None = None
    speed: float | None = None

    @classmethod
    def here(cls, X: tuple[float, ...]) -> PositionHold:
        return cls(X[0], X[2], X[4])

    def setpoint(self, X: tuple[float, ...], g: OnboardGains) -> Setpoint:
        return Setpoint(_xy_velocity(self.x, self.y, X, g, self.speed), _z_velocity(self.z, X, g, g.v_up), self.psi)


@dataclass(frozen=True)
class LandedHold(PositionHold):
    """HOLD selected, or armed in, on the ground: a landed HOLD. Resting on the ground its motors idle and it stays
    there (no set-point flown: a height estimate above the ground, an EKF's at rest, lifts nothing) until a command
    sends it up (TAKEOFF, RTL: a new target); off the ground (pushed up) it holds as :class:`PositionHold`. As PX4:
    its position controller keeps a landed vehicle at idle, integrators reset, until a takeoff is wanted
    (MulticopterPositionControl, TakeoffHandling). ``lands``: selected after a flight (taken off since arming), it
    disarms on the ground after COM_DISARM_LAND as a landing does (PX4's Commander auto-disarms whatever the mode;
    never taken off, COM_DISARM_PRFLT: bridge/nodes/vehicle/prestart.py)."""

    lands: bool = False
    idle = True


@dataclass(frozen=True)
class Land(Target):
    """Hold (x, y) in m while sinking at ``rate`` m/s (NAV_LAND; ``land`` failsafe), or with a ``slowdown``
    PX4's auto landing: faster above MPC_LAND_ALT2 by the height above ``ground_z`` (m, the home's;
    :class:`~bridge.autopilot.returnland.LandSlowdown`), ``rate`` (MPC_LAND_SPEED) below it; heading as
    :class:`PositionHold`."""

    x: float
    y: float
    rate: float
    psi: float | None = None
    slowdown: LandSlowdown | None = None
    ground_z: float = 0.0
    lands = True

    @classmethod
    def here(cls, X: tuple[float, ...], rate: float, slowdown: LandSlowdown | None = None,
             ground_z: float = 0.0) -> Land:
        return cls(X[0], X[2], rate, slowdown=slowdown, ground_z=ground_z)

    def setpoint(self, X: tuple[float, ...], g: OnboardGains) -> Setpoint:
        return Setpoint(_xy_velocity(self.x, self.y, X, g), -_descent(self.slowdown, self.rate, X[4] - self.ground_z),
                        self.psi)


def _descent(slowdown: LandSlowdown | None, rate: float, height_m: float) -> float:
    """The landing's speed (m/s, down) at ``height_m`` above the ground: ``rate``, or ``slowdown``'s profile."""
    return rate if slowdown is None else slowdown.speed(height_m, rate)


@dataclass(frozen=True)
class Takeoff(Target):
    """Climb at most ``rate`` m/s to height z (m) over (x, y), then hold there (NAV_TAKEOFF);
    heading as :class:`PositionHold`."""

    x: float
    y: float
    z: float
    rate: float = DEFAULT_GAINS.v_up
    psi: float | None = None

    @classmethod
    def here(cls, X: tuple[float, ...], z: float, rate: float = DEFAULT_GAINS.v_up) -> Takeoff:
        return cls(X[0], X[2], z, rate)

    def setpoint(self, X: tuple[float, ...], g: OnboardGains) -> Setpoint:
        return Setpoint(_xy_velocity(self.x, self.y, X, g), _z_velocity(self.z, X, g, self.rate), self.psi)


RETURN_NEAR_M = 1.0  # m: home is reached within this horizontal distance (then the descent)
RETURN_Z_TOL_M = 0.3  # m: the climb is done, or the descent, this close to its height


@dataclass(frozen=True)
class ReturnHome(Target):
    """Return mode (PX4's RTL, home return type) over home (x, y) in m: below ``z_return`` and away from home,
    stop and climb to it; then fly home at that height; over home (within :data:`RETURN_NEAR_M`), come down to
    ``z_descend`` at most ``v_down`` (with a ``slowdown``, its MPC_Z_V_AUTO_DN, as PX4), then land at ``rate`` m/s
    (with a ``slowdown``, as :class:`Land`, by the
    height above ``ground_z``) and disarm on the ground. Each phase follows from the state alone (a dip below the
    return height on the way climbs again before going on)."""

    x: float
    y: float
    z_return: float
    z_descend: float
    rate: float
    slowdown: LandSlowdown | None = None
    ground_z: float = 0.0
    lands = True

    @classmethod
    def toward(cls, X: tuple[float, ...], home: tuple[float, float, float], cfg: ReturnConfig,
               rate: float, slowdown: LandSlowdown | None = None) -> ReturnHome:
        """From state X to ``home`` (x, y, z m: where it lands, on the ground): the return height is PX4's
        (:func:`~bridge.autopilot.returnland.return_height`: RTL_RETURN_ALT above it, lower within the cone near
        it, never below the height now: PX4 does not come down to return); the descent's at most that."""
        above = return_height(hypot(home[0] - X[0], home[1] - X[2]), X[4] - home[2], cfg.return_alt_m, cfg.cone_deg,
                              cfg.min_dist_m, cfg.acc_rad_m)
        z_return = max(X[4], home[2] + above)
        return cls(home[0], home[1], z_return, min(home[2] + cfg.descend_alt_m, z_return), rate, slowdown, home[2])

    def phase(self, X: tuple[float, ...]) -> str:
        """``climb``, ``return``, ``descend`` or ``land``."""
        if hypot(self.x - X[0], self.y - X[2]) > RETURN_NEAR_M:
            return "climb" if X[4] < self.z_return - RETURN_Z_TOL_M else "return"
        return "descend" if X[4] > self.z_descend + RETURN_Z_TOL_M else "land"

    def setpoint(self, X: tuple[float, ...], g: OnboardGains) -> Setpoint:
        phase = self.phase(X)
        if phase == "climb":
            return Setpoint((0.0, 0.0), _z_velocity(self.z_return, X, g, g.v_up), None)
        v_xy = _xy_velocity(self.x, self.y, X, g)
        if phase == "return":
            return Setpoint(v_xy, _z_velocity(self.z_return, X, g, g.v_up), None)
        if phase == "descend":  # PX4 comes down to RTL_DESCEND_ALT at its auto descent speed (MPC_Z_V_AUTO_DN)
            down = None if self.slowdown is None else self.slowdown.auto_down_mps
            return Setpoint(v_xy, _z_velocity(self.z_descend, X, g, g.v_up, down), None)
        return Setpoint(v_xy, -_descent(self.slowdown, self.rate, X[4] - self.ground_z), None)


def return_time_s(cfg: ReturnConfig, away_m: float, z_m: float, rate: float, g: OnboardGains = DEFAULT_GAINS,
                  slowdown: LandSlowdown | None = None) -> float:
    """Vehicle time (s) Return mode takes from ``z_m`` above home and ``away_m`` from it, at the on-board
    controller's speed limits: the climb to its return height (RTL_RETURN_ALT, or the cone's), the way home, the
    descent to RTL_DESCEND_ALT and the landing at ``rate`` m/s, or with ``slowdown`` PX4's auto landing (each
    approach's tail, where the set-point's P slows it, is the caller's margin)."""
    z_return = return_height(away_m, z_m, cfg.return_alt_m, cfg.cone_deg, cfg.min_dist_m, cfg.acc_rad_m)
    z_descend = min(cfg.descend_alt_m, z_return)
    landing = z_descend / rate if slowdown is None else slowdown.time_s(z_descend, rate)
    down = g.v_down if slowdown is None else slowdown.auto_down_mps
    return (z_return - max(z_m, 0.0)) / g.v_up + away_m / g.v_xy_max + (z_return - z_descend) / down + landing


def return_point(X: tuple[float, ...], home: tuple[float, float, float],
                 rally: tuple[tuple[float, float], ...] = ()) -> tuple[tuple[float, float, float], int | None]:
    """Where Return flies from state X, as PX4's RTL_TYPE 0: the closest, horizontally, of the home (x, y, z m)
    and the rally points (x, y m, on the ground at the home's height); (that point, None for the home, else the
    rally point's index). The home wins a tie."""
    best, index = home, None
    far = hypot(home[0] - X[0], home[1] - X[2])
    for i, (x, y) in enumerate(rally):
        d = hypot(x - X[0], y - X[2])
        if d < far:
            best, index, far = (x, y, home[2]), i, d
    return best, index


def landing_target(cfg: FailsafeConfig, X: tuple[float, ...], home: tuple[float, float, float]) -> Land:
    """PX4's auto landing where state X is (LAND, the ``land`` failsafe, ``hold``'s landing, the mission's end):
    MPC_LAND_SPEED (``descent_rate``) near the ground, faster above MPC_LAND_ALT2 (``slowdown``) by the height above
    ``home`` (x, y, z m)."""
    return Land.here(X, cfg.descent_rate, cfg.slowdown, home[2])


def failsafe_target(cfg: FailsafeConfig, X: tuple[float, ...], home: tuple[float, float, float],
                    rtl: ReturnConfig, rally: tuple[tuple[float, float], ...] = ()) -> Target:
    """What the failsafe flies first from state X (``disarm`` flies nothing: see SimVehicle); ``return`` flies
    to the closest of the home (``home``, m) and the ``rally`` points (:func:`return_point`) with ``rtl``'s
    heights."""
    if cfg.action == "return":
        return ReturnHome.toward(X, return_point(X, home, rally)[0], rtl, cfg.descent_rate, cfg.slowdown)
    if cfg.action == "land":
        return landing_target(cfg, X, home)
    if cfg.action == "hold":
        return PositionHold.here(X)
    return Level(cfg.descent_rate)
