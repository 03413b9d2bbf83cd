"""The simulated vehicle without its radio: plant, arming, command timeout and failsafe.

In:  normalised paper-frame commands (``wrench``: u / u_max; ``motors``: omega / omega_max), arm and
     disarm, and a delivery callback called with the plant time (s) before each physics step
Out: the plant's state (eq. 7, NWU: m, m/s, rad, rad/s) after each control period, the mode
     (offboard, failsafe, landed) and the events (t s, kind, text)

Shared by the in-process loop and the MAVLink vehicle so that both fly, time out and land
the same way. Time advances in control periods of ``physics_hz / rate_hz`` physics steps;
the command is held over the period (zero-order hold).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from bridge.core.failsafe import FailsafeConfig, LandingController
from controller.nominal import Nominal
from plant import Quadrotor

OFFBOARD = "offboard"
FAILSAFE = "failsafe"
LANDED = "landed"


@dataclass
class Event:
    t: float
    kind: str
    text: str


@dataclass
class SimVehicle:
    plant: Quadrotor
    substeps: int
    failsafe: FailsafeConfig = field(default_factory=FailsafeConfig)
    armed: bool = False
    mode: str = OFFBOARD
    events: list[Event] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.landing = LandingController(Nominal.from_profile(self.plant.profile), self.failsafe.descent_rate)
        self.last_command_t = 0.0
        self._zero = (0.0, 0.0, 0.0, 0.0)

    @property
    def t(self) -> float:
        return self.plant.t

    def event(self, kind: str, text: str) -> Event:
        e = Event(self.plant.t, kind, text)
        self.events.append(e)
        return e

    def arm(self) -> None:
        """Arm and take offboard commands (from failsafe or landed too)."""
        if not self.armed or self.mode != OFFBOARD:
            self.armed = True
            self.mode = OFFBOARD
            self.last_command_t = self.plant.t
            self.event("armed", "armed, offboard control")

    def disarm(self, why: str = "disarmed") -> None:
        if self.armed:
            self.armed = False
            self.plant.command(self._zero)
            self.event("disarmed", why)

    def command(self, c: tuple[float, float, float, float]) -> bool:
        """A valid actuator target (normalised, paper frame). Ignored unless armed offboard."""
        if not self.armed or self.mode != OFFBOARD:
            return False
        self.plant.command(c)
        self.last_command_t = self.plant.t
        return True

    def advance(self, deliver: Callable[[float], None] | None = None) -> None:
        """One control period: failsafe check, then the physics substeps.

        ``deliver(t)``, if given, is called with the plant time (s) before the check and
        before each substep, so that messages an impaired link delivers in the middle of
        the period (see :mod:`bridge.core.link`) act at the physics step they arrive in.
        """
        p = self.plant
        if deliver is not None:
            deliver(p.t)
        if self.armed and self.mode == OFFBOARD and p.t - self.last_command_t > self.failsafe.timeout_s + 1e-9:
            self.mode = FAILSAFE
            self.event("failsafe", f"no actuator target for {p.t - self.last_command_t:.3f} s: level and descend")
        for i in range(self.substeps):
            if deliver is not None and i:
                deliver(p.t)
            if self.mode == FAILSAFE and self.armed:
                if p.on_ground:
                    self.mode = LANDED
                    self.disarm("landed: disarmed")
                else:
                    p.command(self.landing.command(p.state))
            p.step()
