"""The horizontal position estimate lost (a GPS that stopped) and found again, and PX4's failsafe on it.

In:  simulation time (s), when the vehicle's estimator last took in a reading that constrains the horizontal
     position (``aided_t`` s: a GNSS fix or a motion-capture pose fused; bridge.autopilot.estimator), EKF2_NOAID_TOUT
     (us), and, armed, the vehicle's mode, its on-board controller's target and its offboard-loss action; a ground
     station's mode asked for while the position is invalid
Out: whether the horizontal position is valid, as EKF2 says it (:func:`ekf_valid`: the telemetry) and as the
     commander judges it (:class:`PositionWatch`, after its probation: the failsafe), the ``position`` event's words,
     and what the vehicle flies while it is lost (:func:`fallback`: the failsafe's action, and what flies again once
     it is valid, a :class:`Resume`), whether a mode asked for meanwhile is taken (:func:`taken_without_position`);
     the estimate's health as ESTIMATOR_STATUS tells it (:func:`estimate_health`:
     valid, aided now, by GNSS, horizontal and vertical accuracy m)

As PX4 v1.14 and v1.15 do it, the LAND below as PX4 main does since 2024 (docs/sensors.md, "When the GPS is lost"):

- **EKF2** (src/modules/ekf2/EKF/ekf_helper.cpp, ``updateHorizontalDeadReckoningstatus``): while no measurement
  that constrains the horizontal position or velocity is fused, the filter dead-reckons on the IMU (the estimate
  drifts); once that has lasted ``EKF2_NOAID_TOUT`` (``valid_timeout_max``: INT32 us, 500 000 to 10 000 000,
  default 5 000 000; src/modules/ekf2/module.yaml) since the last one, its horizontal position is invalid
  (``isLocalHorizontalPositionValid``: ``vehicle_local_position.xy_valid``), until one is fused again.
- **The commander** (HealthAndArmingChecks/checks/estimatorCheck.cpp, ``checkPosVelValidity``): the position is
  invalid (``local_position_invalid``) as soon as EKF2 says so, and valid again only once EKF2 has said so for
  1 s (:data:`PROBATION_S`).
- **The failsafe** (failsafe/failsafe.cpp ``checkModeFallback``, failsafe/framework.cpp ``getSelectedAction``,
  ModeUtil/mode_requirements.cpp): a mode that needs the position (Hold, Return, Land in v1.14, Takeoff, Mission)
  cannot run; it falls back to Return, which cannot either, to Land, which cannot, to Descend: level, sink at
  MPC_LAND_SPEED, no horizontal control (the vehicle's ``descend``), disarmed on the ground. Offboard with
  position set-points loses its offboard signal (offboardCheck.cpp) and flies the offboard-loss action
  (COM_OBL_RC_ACT), which falls back the same way: Descend, or Disarm. The fallback clears with its cause
  (``ClearCondition::WhenConditionClears``): once the position is valid again, the mode the user chose flies again
  (a failsafe its own action). Here, out of OFFBOARD as every failsafe of this vehicle (docs/design.md, "Failsafe"),
  the vehicle returns to offboard control only when armed again: the descent goes on to the ground.
- **A mode asked for meanwhile** (:func:`taken_without_position`; Commander.cpp, UserModeIntention.cpp
  ``change``): armed, PX4 takes a mode only if it can run (``canRun``). Every mode this vehicle flies needs the
  horizontal position (mode_requirements.cpp, a multicopter: Hold, Return and Mission a global and a local one,
  Takeoff a local one, Land the relaxed local one, valid at any accuracy, which EKF2's ``xy_valid`` false takes
  away as well; Offboard its offboard signal, lost with the position for position set-points), so each is
  TEMPORARILY_REJECTED, but LAND: since PX4 pull request 23580 (UserModeIntention::change's ``force``) a LAND
  (DO_SET_MODE AUTO.LAND, NAV_LAND) is always taken, "if that means to switch to DESCEND it is fine": it cannot run,
  so the failsafe's Descend flies on, and LAND flies, from where the vehicle is, once the position is valid again.

Not modelled: the accuracy test (COM_POS_FS_EPH: PX4 also calls the position invalid once its eph passes 2.5 times
it), EKF2's stop of GNSS fusion after 10 s without data.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from bridge.autopilot.estimator import Estimator
from bridge.autopilot.failsafe import Land, PositionHold, ReturnHome, Target
from bridge.autopilot.modes import FAILSAFE, GROUND_MODES, LAND, OFFBOARD

NOAID_TIMEOUT_US = 5_000_000  # EKF2_NOAID_TOUT's default (us)
NOAID_TIMEOUT_RANGE_US = (500_000, 10_000_000)  # and its range
PROBATION_S = 1.0  # s the commander waits, EKF2's position valid again, before it calls it valid (estimatorCheck.cpp)
AIDING_ACTIVE_S = 1.0  # s a fused reading counts as aiding now (EKF2's no_aid_timeout_max): ESTIMATOR_STATUS's flags


def ekf_valid(t: float, aided_t: float, timeout_us: int) -> bool:
    """Whether EKF2 calls its horizontal position valid at ``t`` (s): aided no longer than EKF2_NOAID_TOUT
    (``timeout_us``) ago (``aided_t``, s; PX4's ``isTimedOut``: invalid once strictly longer, here by over 1 ns, so
    that a step's float sum lands on the same side of the bound in every flight)."""
    return t - aided_t <= timeout_us * 1e-6 + 1e-9


@dataclass(frozen=True)
class Resume:
    """What flies again once the position is valid: a ground station's ``mode`` (HOLD, LAND, RTL, TAKEOFF), from
    where the vehicle is then; or, ``mode`` FAILSAFE, the failsafe's own ``action`` (hold, land, return)."""

    mode: str
    action: str | None = None


@dataclass
class PositionWatch:
    """The horizontal position's validity, updated once a control period (:meth:`update`): ``ekf_valid``, EKF2's own
    (what the telemetry says); ``valid``, the commander's (what the failsafe acts on); ``resume``, what the vehicle
    flies again once ``valid`` (None: nothing)."""

    ekf_valid: bool = True
    valid: bool = True
    resume: Resume | None = None
    last_fail_t: float = -math.inf  # s: the last time EKF2 said invalid

    def update(self, t: float, aided_t: float, timeout_us: int) -> str | None:
        """Both views at ``t`` (s), aided last at ``aided_t`` (s), EKF2_NOAID_TOUT ``timeout_us``: the ``position``
        event's text when the commander's changes, else None."""
        self.ekf_valid = ekf_valid(t, aided_t, timeout_us)
        if not self.ekf_valid:
            self.last_fail_t = t
            if self.valid:
                self.valid = False
                return (f"horizontal position estimate invalid: no position fix fused for {t - aided_t:.3f} s "
                        f"(EKF2_NOAID_TOUT = {timeout_us * 1e-6:g} s)")
        elif not self.valid and t > self.last_fail_t + PROBATION_S:
            self.valid = True
            return f"horizontal position estimate valid again (fused again for {PROBATION_S:g} s)"
        return None


def fallback(mode: str, target: Target | None, offboard_action: str) -> tuple[str, Resume | None] | None:
    """What an armed vehicle in ``mode``, its on-board controller flying ``target`` (None: none), flies when its
    position is lost, as PX4's failsafe: (the failsafe action, ``descend`` or ``disarm``; what flies again once the
    position is valid, or None); None when it flies nothing that needs a position (descending already, landed)."""
    if mode == OFFBOARD:  # the offboard-loss action (``offboard_action``), which needs a position unless it disarms
        return ("disarm" if offboard_action == "disarm" else "descend"), None
    if mode in GROUND_MODES:
        return "descend", Resume(mode)
    if mode != FAILSAFE:
        return None
    for kind, action in ((PositionHold, "hold"), (Land, "land"), (ReturnHome, "return")):
        if isinstance(target, kind):
            return "descend", Resume(FAILSAFE, action)
    return None


def taken_without_position(mode: str, watch: PositionWatch) -> bool:
    """Whether PX4's commander takes a ground station's ``mode`` asked for while the vehicle is armed and ``watch``
    says the position is invalid: LAND only (forced, PX4 pull request 23580), which then flies once the position is
    valid (``watch.resume``; the failsafe's Descend flies until then); any other mode needs the position and is
    refused (False), as a mode that cannot run is."""
    if mode != LAND:
        return False
    watch.resume = Resume(LAND)
    return True


@dataclass(frozen=True)
class EstimateHealth:
    """What ESTIMATOR_STATUS says of the estimate (bridge.mavlink.telemetry.estimator_status): its horizontal
    position ``valid`` (EKF2's view), ``aiding`` (a horizontal reading fused within :data:`AIDING_ACTIVE_S`),
    by ``gnss`` (a GNSS receiver, not a pose), and its 1-sigma horizontal and vertical accuracy (m; NaN unknown)."""

    valid: bool
    aiding: bool
    gnss: bool
    eph_m: float
    epv_m: float


def estimate_health(estimator: Estimator, watch: PositionWatch, t: float, gnss: bool) -> EstimateHealth:
    """The :class:`EstimateHealth` of ``estimator`` at ``t`` (s), its validity as ``watch`` last judged it; the
    accuracies from its covariance: sqrt(var x + var y), sqrt(var z), as EKF2's eph and epv."""
    s = estimator.covariance().state
    return EstimateHealth(watch.ekf_valid, t - estimator.aided_t <= AIDING_ACTIVE_S, gnss, _root(s[0] + s[10]),
                          _root(s[20]))


def _root(variance: float) -> float:
    return math.sqrt(variance) if variance >= 0.0 else math.nan  # (NaN, unknown, stays NaN)
