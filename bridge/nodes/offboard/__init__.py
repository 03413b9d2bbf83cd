"""The ground-side offboard controller as a MAVLink 2 endpoint: ``bsst controller``.

In:  ODOMETRY from the vehicle (NED position m, FRD body velocity m/s, quaternion FRD to NED, FRD rates
     rad/s; ``time_usec`` us), its HEARTBEAT (armed, system status), COMMAND_ACK, TIMESYNC, STATUSTEXT
Out: one actuator target per state answered, stamped with its ``time_usec``: HIL_ACTUATOR_CONTROLS
     (``motors``: c1..c4 = omega / omega_max, each in [0, 1]) or SET_ACTUATOR_CONTROL_TARGET group 0
     (``wrench``: roll, pitch, yaw in [-1, 1], thrust in [0, 1]), or the no-target acknowledgement;
     ARM_DISARM, HEARTBEAT at 1 Hz (10 Hz until the vehicle's is heard), TIMESYNC every 10 ms until
     8 answers are in, then every 0.5 s;
     ``controller.tlog``, ``controller.bin`` rows; reports on stdout (:mod:`bridge.nodes.report`); the outcome

It flies a mission against any vehicle that keeps the contract of docs/design.md, "The MAVLink contract": it
sends its own HEARTBEAT, waits for the vehicle's (after an awaited mission's download: none, the vehicle
it came from is armed at once), arms it (COMMAND_LONG ARM_DISARM, until ACKed), answers each ODOMETRY with
the law's actuator target stamped with the state's time_usec, and at the end of the mission disarms it
(forced: it may be in the air) and
returns its outcome: ``completed``, ``failsafe``, ``diverged`` or ``aborted``.

- **lockstep** (default): event-driven. The state of step k (t_k = k / rate_hz, k from
  time_usec) is answered once, at once; a repeated state gets the same answer again
  (the vehicle resends when a datagram is lost). Mission time is counted from the first
  state after arming, in steps, so a fresh vehicle flies exactly the offline loop's times.
  The mission's ``[link]`` model acts here on the states after they cross the socket, in
  simulation time (:class:`bridge.link.ends.ControllerEnd`, the offline loop's end): state k
  enters the ``down`` model at t_k and the guard controls on the newest one delivered.
  Every step is answered, also when the guard sends no command: then with the no-target
  acknowledgement (HIL_ACTUATOR_CONTROLS, SAFETY_ARMED clear in ``mode``), so that the
  vehicle's step clock, and its failsafe timeout, run on as offline.
- **realtime**: a drift-free fixed-rate schedule (tick j at T0 + j / rate_hz, never
  re-based on a late tick), phase-locked just after the earliest arrival of five states; each tick
  controls on the newest state (the link model, if any, is on the wire: ``bsst relay``).
  A tick whose state (k0 + j) is not in yet waits for it at most half a period, as a flight
  stack's rate loop polls for its estimate with a timeout, then controls on what it has
  (counted in ``stale_ticks``). The mission time of tick j is the vehicle's: j / rate_hz
  plus the states' way down (their arrival phase less the vehicle's clock offset from
  TIMESYNC: the middle of its bounds, right within half their width, in ``stats`` ``way_down``)
  plus the tick's PHASE_S after the arrival, so the reference is sampled at
  the vehicle's now and each state's age includes its trip, as in lockstep: the guard and
  ``compensation = "predict"`` see the whole delay.
  Each row records the tick's lateness (the period error) and the state-to-command round
  trip estimated with TIMESYNC.

A state is taken only from the vehicle's sysid, finite and in range, and with a stamp that
follows the newest one accepted (:func:`stamp_problem`): not older, and ahead by no more than
the wall time since (at up to twice real time) plus a slack. Anything else is refused and
counted (``stale``; ``stamp_jump`` for a jump of the mission's time either way), so no single
datagram, e.g. one stamped days ahead, can end the mission or make its time jump.

The law runs under a :class:`controller.link_guard.LinkGuard` (the mission's ``[link]``
``stale_ms``, ``stop_ms``, ``compensation`` and ``[failsafe] resume``): stale state freezes
the super-twisting integrators, older state stops the commands, and when the vehicle has
left offboard control (its HEARTBEAT: not armed, or system_status CRITICAL) it sends
nothing but, with ``resume``, asks it to arm again (ARM_DISARM, through the link model in
lockstep) once the state is fresh (in real time, where the HEARTBEAT saying so may have gone in the outage, it asks
for one, REQUEST_MESSAGE, when fresh state comes back). A failsafe does not end the flight: the controller keeps
answering steps to the mission's end, whose outcome is then ``failsafe`` unless the vehicle
was back under offboard control. A vehicle that a ground station switches out of OFFBOARD while
armed (its PX4 HEARTBEAT's ``custom_mode``: HOLD, LAND, TAKEOFF, RTL, not in its failsafe) is the ground
station's: no more targets are sent, the flight ends ``aborted`` with that reason, and the session
names the ground station from the vehicle's event. Parameter changes scheduled at mission times
(``--param-at``, :class:`bridge.autopilot.params.ParamChange`) go out as PARAM_SET just before the
answer of their step. Each command is sent first, then its row of
``controller.bin`` (:data:`CONTROLLER_COLUMNS`, one ``write`` each, so the file is whole
up to its last record whatever kills the process). A controller killed between the send and
the write leaves one command without its row: the session keeps the steps flown on that
command in ``trace.csv`` with the law's demand unknown (NaN; ``missing_rows``) rather than
guess it.

The parts: :mod:`~bridge.nodes.offboard.config` (settings, stamp checks), :mod:`~bridge.nodes.offboard.link`
(the endpoint and what the vehicle's messages tell), :mod:`~bridge.nodes.offboard.flight` (the flight loops,
the outcome), :mod:`~bridge.nodes.offboard.radioturn` (the down-link model, a lockstep fleet's turns on one
radio), :mod:`~bridge.nodes.offboard.run` (``bsst controller``: the reports, the exit status).
"""

from bridge.nodes.offboard.config import (
    HOUSEKEEPING_S,
    PHASE_S,
    PHASE_STATES,
    SPIN_BEFORE_TICK_S,
    STAMP_PACE,
    STAMP_SLACK_S,
    STATE_WAIT_PERIODS,
    WAY_DOWN_MAX_S,
    WAY_DOWN_SLACK_S,
    OffboardConfig,
    offset_bounds,
    stamp_problem,
    stamp_slack_s,
)
from bridge.nodes.offboard.flight import OUTCOMES, Offboard
from bridge.nodes.offboard.link import OffboardLink
from bridge.nodes.offboard.run import run_controller

__all__ = [
    "HOUSEKEEPING_S", "OUTCOMES", "PHASE_S", "PHASE_STATES", "SPIN_BEFORE_TICK_S", "STAMP_PACE", "STAMP_SLACK_S",
    "STATE_WAIT_PERIODS", "WAY_DOWN_MAX_S", "WAY_DOWN_SLACK_S", "Offboard", "OffboardConfig", "OffboardLink",
    "offset_bounds", "run_controller", "stamp_problem", "stamp_slack_s",
]
