"""The controller's own nominal model of the vehicle (it never reads the plant's code)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True, slots=True)
class Nominal:
    """What the law believes about the airframe: the paper's constants, SI units."""

    mass: float
    gravity: float
    ixx: float
    iyy: float
    izz: float
    arm: float
    rotor_inertia: float
    thrust_coeff: float
    drag_coeff: float
    omega_max: float
    u_max: tuple[float, float, float, float]
    actuation: str  # "wrench" or "motors"

    @classmethod
    def from_profile(cls, profile: Any) -> Nominal:
        """Copy the fields of any object that has them (a plant profile, a dict-like)."""
        return cls(**{f: getattr(profile, f) for f in cls.__slots__})  # type: ignore[attr-defined]
