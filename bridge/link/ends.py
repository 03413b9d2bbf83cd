"""The two ends of an impaired link in simulation time (the offline loop and the lockstep SITL).

In:  the controller's actuator targets (normalised paper-frame command, with the time stamp of the
     state they answer, s) and arm requests, and the vehicle's states (eq. 7: m, m/s, rad, rad/s,
     with its offboard bit), each at the step time (s) it crossed the socket
Out: the newest target applied to the :class:`~bridge.autopilot.simvehicle.SimVehicle` at the physics step
     it is delivered in (older ones refused and counted by reason); each control step's
     :class:`~controller.link_guard.Decision` of the guard, made on the newest state delivered

Each end owns the model of the direction it *receives* (docs/design.md, "Link model": the model acts
on messages after they cross the socket, so a lost packet never stalls a step):

- :class:`VehicleEnd` (vehicle side, direction ``up``): every actuator target or arm
  request the controller sends enters the model at its step time; during the vehicle's
  control period the model releases what is due, at the physics step it is due in; the
  newest command is applied, one older than the newest applied (reordered, duplicated) is
  rejected and counted. A lost command leaves the last one in force; the vehicle's own
  timeout and failsafe (:class:`bridge.autopilot.simvehicle.SimVehicle`) do the rest.
- :class:`ControllerEnd` (controller side, direction ``down``): every state the vehicle
  publishes enters the model; at each control step the states due are handed to the
  :class:`controller.link_guard.LinkGuard`, which controls on the newest one.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, NamedTuple

from bridge.autopilot.simvehicle import SimVehicle
from bridge.link.model import FRAME_BYTES, LinkImpairment
from controller.link_guard import Decision, LinkGuard
from missions.references import Sample

Quad = tuple[float, float, float, float]
EPS_T = 1e-9  # s: the plant's clock is a sum of physics steps; compare times with this slack


class CommandMsg(NamedTuple):
    """An actuator target as it travels up: normalised paper-frame command and the time
    stamp of the state it answers (s)."""

    c: Quad
    state_t: float


@dataclass(frozen=True, slots=True)
class ArmMsg:
    """COMMAND_LONG ARM_DISARM(1) as it travels up; ``acted``: called once it has been acted on (the MAVLink
    vehicle's final COMMAND_ACK after its IN_PROGRESS), None offline; ``wanted``: whether it is still to be acted on
    when delivered (the MAVLink vehicle's: not a resend of an arm a copy of which was, bridge.nodes.vehicle.armretry),
    None: always (offline)."""

    acted: Callable[[], None] | None = None
    wanted: Callable[[], bool] | None = None


class StateMsg(NamedTuple):
    """ODOMETRY (+ the armed/offboard bit of HEARTBEAT) as it travels down."""

    t: float
    X: tuple[float, ...]
    offboard: bool


def command_frame_bytes(actuation: str) -> int:
    """MAVLink 2 size of one actuator target in this actuation mode (docs/design.md, "Frames and units")."""
    return FRAME_BYTES["SET_ACTUATOR_CONTROL_TARGET" if actuation == "wrench" else "HIL_ACTUATOR_CONTROLS"]


class VehicleEnd:
    """The vehicle's side: commands through the ``up`` model into a :class:`SimVehicle`."""

    def __init__(self, vehicle: SimVehicle, up: LinkImpairment, actuation: str,
                 refuse: Callable[[str], None] | None = None) -> None:
        self.vehicle = vehicle
        self.up = up
        self.frame_bytes = command_frame_bytes(actuation)
        self.newest_sent_t = float("-inf")  # send time of the newest command applied
        self.applied_state_t = float("nan")  # state time stamp of the command in force
        # refusals (duplicate, out_of_order, not_offboard) by reason; the MAVLink vehicle counts them with its
        # socket-level reasons instead (``refuse``), as its controller's: every command here is the controller's
        self.rejected: dict[str, int] = {}
        self._refuse = refuse if refuse is not None else self._count
        self._deliver = self.deliver  # bound once, handed to SimVehicle.advance
        self._next_due = up.next_due
        # a fleet's one radio in lockstep (bridge.link.turns): what crossed the socket waits for the vehicle's turn
        self.held: list[tuple[float, int, Any]] | None = None

    def receive_command(self, t: float, c: Quad, state_t: float) -> None:
        """The controller's actuator target crossed the socket at step time t (s)."""
        self._send(t, self.frame_bytes, CommandMsg(c, state_t))

    def receive_arm(self, t: float, acted: Callable[[], None] | None = None,
                    wanted: Callable[[], bool] | None = None) -> None:
        """An arm request crossed the socket at step time t (s); ``acted`` is called once the model delivers it
        and the vehicle has acted on it, or not (``wanted`` said no), never if the model loses it."""
        self._send(t, FRAME_BYTES["COMMAND_LONG"], ArmMsg(acted, wanted))

    def _send(self, t: float, size: int, msg: Any) -> None:
        if self.held is None:
            self.up.send(t, size, msg)
        else:
            self.held.append((t, size, msg))

    def release(self) -> None:
        """Held (:attr:`held`, a list): what crossed the socket since the last release enters the model now, in
        the order it came."""
        held, self.held = self.held or [], []
        for t, size, msg in held:
            self.up.send(t, size, msg)

    def deliver(self, t: float) -> None:
        """Apply what the link delivers by plant time t (s)."""
        for d in self.up.deliver(t + EPS_T):
            msg = d.payload
            if isinstance(msg, ArmMsg):
                if msg.wanted is None or msg.wanted():
                    self.vehicle.arm()
                if msg.acted is not None:
                    msg.acted()
            elif d.sent_t <= self.newest_sent_t:
                self._refuse("duplicate" if d.sent_t == self.newest_sent_t else "out_of_order")
            elif self.vehicle.command(msg.c):
                self.newest_sent_t = d.sent_t
                self.applied_state_t = msg.state_t
            else:
                self._refuse("not_offboard")

    def _count(self, why: str) -> None:
        self.rejected[why] = self.rejected.get(why, 0) + 1

    def advance(self) -> None:
        """One control period of the vehicle, delivering commands as they arrive."""
        self.vehicle.advance(self._deliver, self._next_due)


class ControllerEnd:
    """The controller's side: states through the ``down`` model into a :class:`LinkGuard`."""

    def __init__(self, guard: LinkGuard, down: LinkImpairment) -> None:
        self.guard = guard
        self.down = down
        self.frame_bytes = FRAME_BYTES["ODOMETRY"]

    def receive_state(self, t: float, X: tuple[float, ...], offboard: bool) -> None:
        """The vehicle's state at time t (s) crossed the socket."""
        self.down.send(t, self.frame_bytes, StateMsg(t, tuple(X), offboard))

    def step(self, t: float, reference: Callable[[float], Sample]) -> Decision:
        """Hand the states due by t to the guard, then decide this step's command."""
        for d in self.down.deliver(t + EPS_T):
            m: Any = d.payload
            self.guard.observe(m.t, m.X, m.offboard)
        return self.guard.step(t, reference)
