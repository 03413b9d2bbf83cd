"""Effects outside the paper's model, each off by default: drag, motor lag, an external
disturbance and parameter mismatch. The controller never sees them: they are what its
super-twisting terms must reject.

In:  a mission's ``[effects]`` table (drag on/off, motor lag on/off, battery on/off and its start charge %,
     disturbance N and N m, Hz;
     mass and inertia scales), a seed
Out: :class:`Effects`, the disturbance force (N) and torque (N m) at a time (s)
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass, field

from params import Table

Vec3 = tuple[float, float, float]
_ZERO3: Vec3 = (0.0, 0.0, 0.0)


@dataclass(frozen=True, slots=True)
class Disturbance:
    """External force (inertial frame, N) and torque (body axes, N m): constant + sinusoid.

    Each axis i gets ``const[i] + amp[i] * sin(2 pi freq_hz t + phase[i])``. With
    ``random_phase`` the six phases are drawn from the run's seed, else they are 0.
    """

    force_const: Vec3 = _ZERO3
    force_amp: Vec3 = _ZERO3
    torque_const: Vec3 = _ZERO3
    torque_amp: Vec3 = _ZERO3
    freq_hz: float = 0.5
    random_phase: bool = False

    @property
    def active(self) -> bool:
        return any(self.force_const + self.force_amp + self.torque_const + self.torque_amp)

    def phases(self, seed: int) -> tuple[float, ...]:
        if not self.random_phase:
            return (0.0,) * 6
        rng = random.Random(f"disturbance:{seed}")
        return tuple(rng.uniform(0.0, 2.0 * math.pi) for _ in range(6))


def disturbance_at(d: Disturbance, phases: tuple[float, ...], t: float) -> tuple[float, ...]:
    """(fx, fy, fz, tx, ty, tz) of the disturbance at time t."""
    w = 2.0 * math.pi * d.freq_hz * t
    const = d.force_const + d.torque_const
    amp = d.force_amp + d.torque_amp
    return tuple(c + a * math.sin(w + p) for c, a, p in zip(const, amp, phases, strict=True))


@dataclass(frozen=True, slots=True)
class Effects:
    """Which effects are on. ``mass_scale``/``inertia_scale`` scale the plant only."""

    drag: bool = False
    motor_lag: bool = False
    disturbance: Disturbance = field(default_factory=Disturbance)
    mass_scale: float = 1.0
    inertia_scale: float = 1.0
    battery: bool = False  # the profile's [battery]: its voltage sags under load and caps the rotors' speed
    battery_start_pct: float = 100.0  # the pack's charge at the start, % of its capacity



def effects_from_table(t: Table) -> Effects:
    """Validate a mission's ``[effects]`` table (errors name the file and key)."""
    drag = t.boolean("drag", False)
    motor_lag = t.boolean("motor_lag", False)
    battery = t.boolean("battery", False)
    start_pct = t.number("battery_start_pct", 100.0, lo=1.0, hi=100.0)
    d = t.table("disturbance")
    dist = Disturbance(
        force_const=d.vector("force", 3, _ZERO3, lo=-1e4, hi=1e4),
        force_amp=d.vector("force_amplitude", 3, _ZERO3, lo=0.0, hi=1e4),
        torque_const=d.vector("torque", 3, _ZERO3, lo=-1e4, hi=1e4),
        torque_amp=d.vector("torque_amplitude", 3, _ZERO3, lo=0.0, hi=1e4),
        freq_hz=d.number("freq_hz", 0.5, lo=0.0, hi=100.0),
        random_phase=d.boolean("random_phase", False),
    )
    d.done()
    m = t.table("mismatch")
    mass_scale = m.number("mass_scale", 1.0, lo=0.1, hi=10.0)
    inertia_scale = m.number("inertia_scale", 1.0, lo=0.1, hi=10.0)
    m.done()
    t.done()
    return Effects(drag, motor_lag, dist, mass_scale, inertia_scale, battery, start_pct)
