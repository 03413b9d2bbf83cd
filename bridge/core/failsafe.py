"""The vehicle's own failsafe: level, descend, disarm on the ground (docs/design.md, "Failsafe").

In:  the ``[failsafe]`` table (``timeout_s`` s, ``descent_rate`` m/s, ``resume``), the controller's
     nominal model (the profile's numbers), the paper state (eq. 7, NWU: m, m/s, rad, rad/s)
Out: a :class:`FailsafeConfig`; the landing loop's wrench demand (u1..u4, N) and the normalised
     paper-frame command the profile's actuation makes of it

No valid actuator target for longer than ``timeout_s`` of vehicle time and the vehicle
leaves offboard control. A small PD loop of its own then holds it level at its heading and
sinks it at ``descent_rate`` m/s until it rests on the ground, where it disarms. It
returns to offboard control only when armed again.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from math import cos
from typing import Any

from controller.actuation import make_actuation
from controller.nominal import Nominal
from params import Table


@dataclass(frozen=True)
class FailsafeConfig:
    timeout_s: float = 0.5
    descent_rate: float = 0.7  # m/s
    resume: bool = False  # the controller re-arms and resumes when the link returns


def failsafe_from_table(data: Mapping[str, Any], source: str) -> FailsafeConfig:
    t = Table(data, source, "failsafe")
    cfg = FailsafeConfig(
        timeout_s=t.number("timeout_s", 0.5, lo=0.01, hi=60.0),
        descent_rate=t.number("descent_rate", 0.7, lo=0.05, hi=10.0),
        resume=t.boolean("resume", False),
    )
    t.done()
    return cfg


class LandingController:
    """Level-and-descend: the vehicle's own PD loop, used only in failsafe."""

    def __init__(self, nominal: Nominal, descent_rate: float) -> None:
        self.n = nominal
        self.descent_rate = descent_rate
        self.actuation = make_actuation(nominal)

    def demand(self, X: tuple[float, ...]) -> tuple[float, float, float, float]:
        """The wrench (u1..u4, N) this loop asks for in state X, before the actuation's limits."""
        n = self.n
        _, _, _, _, _, vz, phi, dphi, th, dth, _, dpsi = X
        tilt = max(cos(phi) * cos(th), 0.5)
        u1 = n.mass * (n.gravity + 2.0 * (-self.descent_rate - vz)) / tilt
        u2 = n.ixx / n.arm * (-36.0 * phi - 12.0 * dphi)
        u3 = n.iyy / n.arm * (-36.0 * th - 12.0 * dth)
        u4 = n.izz / n.arm * (-4.0 * dpsi)
        return (u1, u2, u3, u4)

    def command(self, X: tuple[float, ...]) -> tuple[float, float, float, float]:
        """Normalised paper-frame command for state X."""
        return self.actuation.allocate(self.demand(X))[1]
