"""The vehicle's geofence: the limits and the fence it watches, and what it does at a breach (PX4's GF_ACTION).

In:  the state X (paper frame, m), home (x, y, z m), GF_MAX_HOR_DIST and GF_MAX_VER_DIST (m; 0: none), a fence
     it holds (:class:`missions.geofence.Geofence`: the mission's, or one a ground station uploaded), GF_ACTION
Out: the limits X is beyond, each (which, why) (:func:`limits_passed`); the failsafe action a breach asks for
     (:data:`FENCE_FAILSAFE`: a ``[failsafe] action`` name by GF_ACTION; none for 0 and 1) and its event's text;
     why arming is denied where the vehicle stands (:func:`arming_refusal`), or None; why a point a ground station
     repositions it to is not flown (:func:`reposition_refusal`), or None

PX4's geofence (navigator's ``Geofence``, ``GeofenceResult.GF_ACTION_*``): armed, beyond a limit or outside the
fence, the vehicle does GF_ACTION: 0 nothing (it does not watch, but for an uploaded fence the run's record does
not hold: :func:`bridge.autopilot.vehiclechecks.check_limits`), 1 warns, 2 holds where it is (PX4's default;
here for COM_FAIL_ACT_T, then it lands, as the link-loss hold does, so that a flight ends on the ground in every
clock: PX4 holds until someone acts), 3 returns (Return mode: home or the nearest rally point), 4 terminates the
flight (motors off), 5 lands where it is. 2 to 5 take the vehicle out of offboard control as its failsafe does,
and it stays so until the flight ends. Before that, PX4's pre-arm geofence check (commander's
``HealthAndArmingChecks/checks/geofenceCheck``): with GF_ACTION > 0, a vehicle beyond a limit or outside its fence is
not armed (COMMAND_ACK TEMPORARILY_REJECTED) and says why. A DO_REPOSITION's point is judged as PX4's navigator
judges it (``Navigator::geofence_allows_position``): with GF_ACTION 2-5, a point beyond a limit or outside the fence
is not flown ("Reposition is outside geofence"); with 0 or 1 any point is.
"""

from __future__ import annotations

import math

import numpy as np

from bridge.autopilot.params import FENCE_ACTIONS
from missions.geofence import Geofence

FENCE_FAILSAFE = {2: "hold", 3: "return", 4: "disarm", 5: "land"}  # GF_ACTION -> the failsafe action flown
FENCE_ACTION_TEXT = {"hold": "hold here, then land", "return": "return home (RTL), then land",
                     "disarm": "terminate: motors off", "land": "land here"}


def limits_passed(X: tuple[float, ...], home: tuple[float, float, float], max_hor_m: float,
                  max_ver_m: float) -> list[tuple[str, str]]:
    """The GF_MAX_HOR_DIST and GF_MAX_VER_DIST limits (m; 0: none) state X (paper frame) is beyond, about ``home``
    (x, y, z m), as PX4's geofence judges them (horizontal distance from home, height above it): (which, why)."""
    out = []
    d, up = math.hypot(X[0] - home[0], X[2] - home[1]), X[4] - home[2]
    if max_hor_m > 0.0 and d > max_hor_m:
        out.append(("hor", f"{d:.2f} m from home, beyond GF_MAX_HOR_DIST = {max_hor_m:g} m"))
    if max_ver_m > 0.0 and up > max_ver_m:
        out.append(("ver", f"{up:.2f} m above home, beyond GF_MAX_VER_DIST = {max_ver_m:g} m"))
    return out


def breaches(X: tuple[float, ...], t: float, home: tuple[float, float, float], max_hor_m: float, max_ver_m: float,
             fence: Geofence | None) -> list[tuple[str, str]]:
    """The limits (:func:`limits_passed`) and the fence (if given) state X (paper frame, m) at time t (s) is beyond,
    each (which, why): which is ``hor``, ``ver`` or ``fence``."""
    passed = limits_passed(X, home, max_hor_m, max_ver_m)
    if fence is not None:
        breach = fence.first_breach(np.array((t,)), np.array((X[0],)), np.array((X[2],)))
        if breach is not None:
            passed.append(("fence", f"outside its fence: {breach[1]}"))
    return passed


def arming_refusal(passed: list[tuple[str, str]], action: int) -> str | None:
    """Why arming is denied, given the limits and fence the vehicle is beyond where it stands (``passed``, each
    (which, why)) and GF_ACTION (``action``): PX4 denies it for any breach unless GF_ACTION is 0 (unwatched, 1
    included: it only warns in flight); None: not for the geofence."""
    if action == 0 or not passed:
        return None
    return f"{'; '.join(why for _, why in passed)} (GF_ACTION = {action}: {FENCE_ACTIONS[action]})"


def reposition_refusal(to: tuple[float, float, float], t: float, home: tuple[float, float, float], max_hor_m: float,
                       max_ver_m: float, fence: Geofence | None, action: int) -> str | None:
    """Why PX4's navigator does not fly a reposition to ``to`` (x, y, z m, paper frame) at time t (s), about ``home``
    (x, y, z m): GF_ACTION (``action``) 2 to 5 and the point beyond GF_MAX_HOR_DIST or GF_MAX_VER_DIST (m; 0: none)
    or outside ``fence`` (:func:`breaches`); None: it is flown (GF_ACTION 0 and 1 judge no point, as PX4's)."""
    if action not in FENCE_FAILSAFE:
        return None
    X = (to[0], 0.0, to[1], 0.0, to[2], 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    passed = breaches(X, t, home, max_hor_m, max_ver_m, fence)
    return "; ".join(why for _, why in passed) if passed else None
