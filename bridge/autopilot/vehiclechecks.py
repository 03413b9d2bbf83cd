"""The vehicle's health and arming checks, as PX4's commander runs them each cycle: the geofence's limits, the
battery's levels, the horizontal position's validity, and the pre-arm checks made of them.

In:  a :class:`~bridge.autopilot.simvehicle.SimVehicle` after a control period: its estimate (NWU m), its home (m),
     its fence and GF_MAX_* limits (m), its battery's charge left (0..1), its estimator's last aided time (s)
Out: events on the vehicle (``geofence``, ``battery``, ``position``), the failsafe each names flown through
     :meth:`SimVehicle.fly_failsafe <bridge.autopilot.simvehicle.SimVehicle.fly_failsafe>`; :func:`prearm_refusal`,
     why arming is denied now (or None)

The watchers that keep each check's state are their own parts (:mod:`bridge.autopilot.fencewatch`,
:mod:`bridge.autopilot.batterywatch`, :mod:`bridge.autopilot.positionloss`); these functions are where a watcher's
verdict meets the vehicle's modes.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol

from bridge.autopilot.batterywatch import BatteryWatch
from bridge.autopilot.estimator import Estimator
from bridge.autopilot.failsafe import ACTION_TEXT, FailsafeConfig
from bridge.autopilot.fencewatch import FENCE_ACTION_TEXT, FENCE_FAILSAFE, arming_refusal, breaches
from bridge.autopilot.modes import FAILSAFE, LANDED
from bridge.autopilot.onboard import OnboardController
from bridge.autopilot.params import FENCE_ACTIONS
from bridge.autopilot.positionloss import PositionWatch, fallback
from missions.geofence import Geofence
from plant import Quadrotor
from plant.sensors import SensorSuite


class CheckedVehicle(Protocol):
    """What the checks read of :class:`bridge.autopilot.simvehicle.SimVehicle` and call on it (that module imports
    this one, so the contract is named here)."""

    plant: Quadrotor
    sensors: SensorSuite | None
    estimator: Estimator | None
    armed: bool
    mode: str
    home: tuple[float, float, float]  # m
    fence: Geofence | None
    fence_action: int
    fence_recorded: bool  # the run's record holds the fence (its trace check judges it)
    max_hor_m: float  # m
    max_ver_m: float  # m
    beyond: set[str]
    battery_watch: BatteryWatch
    position: PositionWatch
    noaid_timeout_us: int
    onboard: OnboardController
    failsafe: FailsafeConfig
    event: Callable[..., Any]

    def published(self) -> tuple[float, ...]: ...

    def fly_failsafe(self, action: str, text: str, stopped: str) -> None: ...

    def set_mode(self, mode: str) -> None: ...


def check_limits(v: CheckedVehicle) -> None:
    """The first time the vehicle is beyond GF_MAX_HOR_DIST or GF_MAX_VER_DIST, or outside the fence it holds, a
    ``geofence`` event says so (the run's geofence policy then fails), and GF_ACTION 2-5 fly the failsafe it
    names (:mod:`bridge.autopilot.fencewatch`), unless a failsafe already flies. GF_ACTION 0 watches nothing, as
    PX4's, but a fence the run's record does not hold (``fence_recorded`` false: uploaded after the controller's
    download) is still judged, its first breach said and not acted on: nothing else can judge it for the record."""
    known = "" if v.sensors is None else " (by its estimate)"  # PX4's geofence reads the estimate too
    if v.fence_action:
        passed = breaches_now(v, "fence" in v.beyond)
        said = f"GF_ACTION = {v.fence_action}: {FENCE_ACTIONS[v.fence_action]}"
    else:
        passed = [] if v.fence_recorded or "fence" in v.beyond else breaches_now(v, limits=False)
        said = "GF_ACTION = 0: not acted on; said for the run's record, which does not hold this fence"
    new = [(w, why + known) for w, why in passed if w not in v.beyond]
    for which, why in new:
        v.beyond.add(which)
        v.event("geofence", f"{why} ({said})")
    action = FENCE_FAILSAFE.get(v.fence_action)  # None: 0 none, 1 warning (it flies on)
    if new and action is not None and v.mode not in (FAILSAFE, LANDED):
        v.fly_failsafe(action, f"geofence: {new[0][1]}: {FENCE_ACTION_TEXT[action]}",
                   "geofence: flight terminated, motors stopped")


def breaches_now(v: CheckedVehicle, fence_known: bool = False, limits: bool = True) -> list[tuple[str, str]]:
    """:func:`~bridge.autopilot.fencewatch.breaches` of the state the vehicle knows (its estimate, as PX4's
    geofence reads it; the true state under truth) now: not the fence if ``fence_known``, nor GF_MAX_HOR_DIST and
    GF_MAX_VER_DIST unless ``limits``."""
    fence = None if fence_known else v.fence
    hor, ver = (v.max_hor_m, v.max_ver_m) if limits else (0.0, 0.0)
    return breaches(v.published(), v.plant.t, v.home, hor, ver, fence)


def prearm_refusal(v: CheckedVehicle) -> str | None:
    """Why PX4's pre-arm checks deny arming now, or None: the geofence's (fencewatch.arming_refusal) and the
    battery's (:meth:`~bridge.autopilot.batterywatch.BatteryWatch.arming_refusal`)."""
    pack = v.plant.battery
    why = [w for w in (arming_refusal(breaches_now(v) if v.fence_action else [], v.fence_action),
                       None if pack is None else v.battery_watch.arming_refusal(pack.remaining),
                       None if v.position.valid else "no valid horizontal position estimate") if w]
    return f"arming denied: {'; '.join(why)}" if why else None


def check_battery(v: CheckedVehicle, remaining: float) -> None:
    """Each battery level the charge left (0..1) passes, said once (a ``battery`` event), and COM_LOW_BAT_ACT's
    action flown (:mod:`bridge.autopilot.batterywatch`): over any mode but a failsafe, or over its own Return."""
    b = v.battery_watch
    for _, text, act in b.passed(remaining):
        v.event("battery", text)
        if act is not None and (v.mode not in (FAILSAFE, LANDED) or (b.returning and v.mode == FAILSAFE)):
            b.returning = act == "return"
            v.fly_failsafe(act, f"battery {text}: {act}", "battery: motors stopped")


def check_position(v: CheckedVehicle) -> None:
    """The horizontal position estimate's validity (bridge.autopilot.positionloss): a ``position`` event when
    the commander's view of it changes; armed and lost, PX4's fallback (descend, or the offboard-loss action's
    disarm) over what needs a position; valid again, what flew before it (a ground station's mode, a failsafe's
    action) from here."""
    w = v.position
    said = w.update(v.plant.t, v.estimator.aided_t, v.noaid_timeout_us)
    if said is not None:
        v.event("position", said)
    if not v.armed:
        w.resume = None
    elif not w.valid and (step := fallback(v.mode, v.onboard.target, v.failsafe.action)) is not None:
        action, w.resume = step
        v.fly_failsafe(action, f"position lost: {ACTION_TEXT[action]}", "position lost: motors stopped")
    elif w.valid and w.resume is not None and v.mode == FAILSAFE:
        r, w.resume = w.resume, None
        if r.action is None:
            v.set_mode(r.mode)
        else:
            v.fly_failsafe(r.action, f"position valid again: {ACTION_TEXT[r.action]}", "motors stopped")
