"""The controller's own nominal model of the vehicle (it never reads the plant's code).

In:  a plant profile (or anything with its fields: kg, m/s^2, kg m^2, m, N s^2, N m s^2, rad/s, N)
Out: the law's :class:`Nominal` model and eq. (6)'s constant factors (:class:`Coefficients`)
"""

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


@dataclass(frozen=True, slots=True)
class Coefficients:
    """The constant factors of eq. (6), corrected (errata 1-3 of docs/law.md), from a :class:`Nominal`.

    i1..i3 are the paper's shorthands (I_y - I_z)/I_x, (I_z - I_x)/I_y, (I_x - I_y)/I_z
    (dimensionless); jr_x, jr_y = J_r/I_x, J_r/I_y (dimensionless, the gyroscopic factors);
    l_x, l_y, l_z = l/I_x, l/I_y, l/I_z in 1/(kg m). The law and the predictor share them.
    """

    i1: float
    i2: float
    i3: float
    jr_x: float
    jr_y: float
    l_x: float
    l_y: float
    l_z: float

    @classmethod
    def of(cls, n: Nominal) -> Coefficients:
        ix, iy, iz, jr, arm = n.ixx, n.iyy, n.izz, n.rotor_inertia, n.arm
        return cls((iy - iz) / ix, (iz - ix) / iy, (ix - iy) / iz, jr / ix, jr / iy, arm / ix, arm / iy, arm / iz)
