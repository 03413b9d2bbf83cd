"""The vehicle's flight modes and what a ground station's mode flies (PX4's names: bridge/mavlink/modes.py).

In:  a mode a ground station selected, the vehicle's state X (paper frame: m, m/s, rad, rad/s), its home and rally
     points (m), Return's heights, the landing speed (m/s) and its slow-down near the ground, the start's height and
     a takeoff altitude (m), or a point to hold (DO_REPOSITION); whether it rests on the ground (a landed HOLD)
Out: the on-board controller's target for the mode and the ``mode`` event's text (:func:`mode_target`); the
     mission's end action's target, mode and ``end`` event's text (:func:`end_target`)
"""

from __future__ import annotations

from bridge.autopilot.failsafe import (
    FailsafeConfig,
    Land,
    LandedHold,
    PositionHold,
    ReturnConfig,
    ReturnHome,
    Takeoff,
    Target,
    landing_target,
    return_point,
)
from bridge.autopilot.returnland import LandSlowdown

OFFBOARD = "offboard"
FAILSAFE = "failsafe"
LANDED = "landed"  # the period its failsafe disarmed it in (landed, motors stopped); then the user's (intention.py)
HOLD = "hold"  # the modes a ground station selects (bridge/nodes/vehicle.py, PX4's names)
LAND = "land"
TAKEOFF = "takeoff"
RTL = "rtl"  # Return: home at RTL_RETURN_ALT (lower in the cone), down to RTL_DESCEND_ALT, land (armed only, as PX4)
GROUND_MODES = (HOLD, LAND, TAKEOFF, RTL)  # flown by the on-board controller, set by a ground station
TERMINATION = "termination"  # a ground station's flight termination: motors off, disarmed, latched (nodes/vehicle)
MODES = (OFFBOARD, FAILSAFE, LANDED, *GROUND_MODES, TERMINATION)  # every mode the vehicle can be in


def mode_target(mode: str, X: tuple[float, ...], *, takeoff_z: float, alt: float, descent_rate: float,
                home: tuple[float, float, float], rally: tuple[tuple[float, float], ...], rtl: ReturnConfig,
                hold_at: PositionHold | None = None, slowdown: LandSlowdown | None = None,
                landed: bool = False, flew: bool = False) -> tuple[Target, str]:
    """What ``mode`` (HOLD, LAND, RTL, TAKEOFF) flies from state X, and its event's text: HOLD holds where it is (or
    flies to ``hold_at`` and holds there; ``landed``, resting on the ground, a landed HOLD: motors idle on the
    ground until a command sends it up, :class:`~bridge.autopilot.failsafe.LandedHold`; ``flew``, taken off since
    arming: it disarms after COM_DISARM_LAND as a landing), LAND lands where it is at
    ``descent_rate`` (with ``slowdown``, faster above MPC_LAND_ALT2 by the height above home, as PX4), RTL returns
    to home or the nearest rally point (and lands so), TAKEOFF climbs to ``takeoff_z`` (the start's height plus
    ``alt``, m) over where it is."""
    if mode == HOLD and hold_at is not None:
        extra = "" if hold_at.psi is None else f", heading {hold_at.psi:.3f} rad"
        extra += "" if hold_at.speed is None else f", at most {hold_at.speed:g} m/s across"
        return hold_at, (f"HOLD, repositioned: from x={X[0]:.3f} y={X[2]:.3f} z={X[4]:.3f} m to x={hold_at.x:.3f} "
                         f"y={hold_at.y:.3f} z={hold_at.z:.3f} m{extra}")
    if mode == HOLD:
        return hold_here(X, landed, flew)
    if mode == LAND:
        faster = "" if slowdown is None else (f" below {slowdown.alt2_m:g} m, {slowdown.auto_down_mps:g} m/s above "
                                              f"{max(slowdown.alt1_m, slowdown.alt2_m):g} m")
        return Land.here(X, descent_rate, slowdown, home[2]), (f"LAND at x={X[0]:.3f} y={X[2]:.3f} m, "
                                                               f"{descent_rate:g} m/s{faster}")
    if mode == RTL:
        to, which = return_point(X, home, rally)
        target = ReturnHome.toward(X, to, rtl, descent_rate, slowdown)
        where = "home" if which is None else f"rally point {which}"
        return target, (f"RTL from x={X[0]:.3f} y={X[2]:.3f} z={X[4]:.3f} m: {where} x={to[0]:.3f} "
                        f"y={to[1]:.3f} m at z={target.z_return:.3f} m, down to {target.z_descend:.3f} m, land")
    return Takeoff.here(X, takeoff_z), f"TAKEOFF to {alt:g} m over x={X[0]:.3f} y={X[2]:.3f} m"


def hold_here(X: tuple[float, ...], landed: bool, flew: bool) -> tuple[Target, str]:
    """HOLD where state X is, and its text: the one way to make a HOLD here. ``landed`` (resting on the ground): a
    landed HOLD (:class:`~bridge.autopilot.failsafe.LandedHold`), idle until a takeoff; ``flew`` (taken off since
    arming) it disarms after COM_DISARM_LAND as a landing does."""
    at = f"HOLD at x={X[0]:.3f} y={X[2]:.3f} z={X[4]:.3f} m"
    if not landed:
        return PositionHold.here(X), at
    if flew:
        return LandedHold(X[0], X[2], X[4], lands=True), f"{at}: landed, disarms as a landing (COM_DISARM_LAND)"
    return LandedHold.here(X), f"{at}: landed, idle until a takeoff"


def end_target(action: str, X: tuple[float, ...], cfg: FailsafeConfig, home: tuple[float, float, float],
               landed: bool = False, flew: bool = False) -> tuple[Target, str, str]:
    """The mission's end action (``[end] action``, :data:`missions.mission.END_ACTIONS`) from state X: ``hold`` holds
    the position (HOLD, made as a selected one, :func:`hold_here`: on the ground, ``landed``, a landed HOLD), ``land``
    lands where it is as PX4's auto landing (LAND: ``cfg``'s speeds by the height above ``home``, m) and disarms
    on the ground; (the target, its mode, the ``end`` event's text)."""
    if action == "hold":
        target, text = hold_here(X, landed, flew)
        return target, HOLD, f"mission over: {text}"
    return landing_target(cfg, X, home), LAND, (f"mission over: LAND at x={X[0]:.3f} y={X[2]:.3f} m from "
                                                f"z={X[4]:.3f} m, {cfg.descent_rate:g} m/s")
