"""Controller gains: frozen dataclasses read from a mission's ``[gains]`` table.

Defaults are the set of docs/law.md, "Gains", known to fly both scenarios on the paper and
x500 profiles. The super-twisting gains are checked against eq. (23) on construction.

In:  a mission's ``[gains]`` table (c 1/s-ish, alpha, eps in each loop's units, k1, k2, L, PID gains)
Out: a frozen :class:`Gains`, eq. (23) checked
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from controller.supertwisting import super_twisting_bound
from params import ConfigError, Table

# Cascaded PID baseline (controller.pid): position, altitude, attitude and yaw loops.
PID_DEFAULTS = {
    "kp_pos": 4.0,
    "kd_pos": 4.0,
    "ki_pos": 0.5,
    "kp_z": 4.0,
    "kd_z": 4.0,
    "ki_z": 1.0,
    "kp_att": 100.0,
    "kd_att": 20.0,
    "kp_yaw": 16.0,
    "kd_yaw": 8.0,
    "i_max": 2.0,
}


@dataclass(frozen=True)
class Twisting:
    """Super-twisting gains of one loop: k1, k2 of eq. (22), L bounds |d'| (eq. 21/23)."""

    k1: float
    k2: float
    L: float
    xi_max: float = 20.0  # anti-windup clamp on the integrator (acceleration units)


@dataclass(frozen=True)
class Backstep:
    """One finite-time backstepping step: V' = -c V^alpha (eq. 10), regularised below eps."""

    c: float
    alpha: float
    eps: float


@dataclass(frozen=True)
class Gains:
    z: Backstep = field(default_factory=lambda: Backstep(2.0, 0.8, 0.05))
    z_st: Twisting = field(default_factory=lambda: Twisting(3.5, 2.0, 1.0))
    position: Backstep = field(default_factory=lambda: Backstep(1.5, 0.8, 0.05))
    velocity: Backstep = field(default_factory=lambda: Backstep(3.0, 0.8, 0.02))
    attitude: Backstep = field(default_factory=lambda: Backstep(8.0, 0.8, 0.01))
    attitude_st: Twisting = field(default_factory=lambda: Twisting(5.0, 4.0, 2.0))
    yaw: Backstep = field(default_factory=lambda: Backstep(3.0, 0.8, 0.01))
    yaw_st: Twisting = field(default_factory=lambda: Twisting(3.5, 2.0, 1.0))
    tilt_max: float = 0.6  # rad, on the desired roll and pitch
    tilt_rate_max: float = 6.0  # rad/s, on the desired roll/pitch rates
    feedforward_max: float = 200.0  # rad/s^2, on phi23-dot and phi33-dot
    smc_scale: float = 1.0  # SMC baseline: k = smc_scale * k1 in each loop
    pid: Mapping[str, float] = field(default_factory=lambda: dict(PID_DEFAULTS))

    def __post_init__(self) -> None:
        for name in ("z_st", "attitude_st", "yaw_st"):
            check_twisting(getattr(self, name), f"gains.{name.removesuffix('_st')}")


def check_twisting(st: Twisting, where: str = "gains") -> None:
    """Eq. (23): k2 > L and k1 > sqrt(4 L (k2 + L) / (k2 - L)); ConfigError otherwise."""
    if st.L <= 0.0:
        raise ConfigError(f"{where}.L: must be positive, got {st.L:g}")
    if st.k2 <= st.L:
        raise ConfigError(f"{where}.k2: eq. (23) needs k2 > L = {st.L:g}, got {st.k2:g}")
    bound = super_twisting_bound(st.k2, st.L)
    if st.k1 <= bound:
        raise ConfigError(
            f"{where}.k1: eq. (23) needs k1 > sqrt(4L(k2+L)/(k2-L)) = {bound:.4g} "
            f"(k2 = {st.k2:g}, L = {st.L:g}), got {st.k1:g}"
        )


def gains_from_table(data: Mapping[str, Any], source: str) -> Gains:
    """Validate a mission's ``[gains]`` table into :class:`Gains` (unknown keys rejected)."""
    t = Table(data, source, "gains")
    d = Gains()
    kw: dict[str, Any] = {}

    def backstep(tab: Table, base: Backstep, c: str = "c", eps: str = "eps") -> Backstep:
        return Backstep(
            tab.number(c, base.c, lo=0.0, lo_open=True, hi=1e4),
            tab.number("alpha", base.alpha, lo=0.5, hi=1.0, lo_open=True, hi_open=True),
            tab.number(eps, base.eps, lo=0.0, lo_open=True, hi=10.0),
        )

    def twisting(tab: Table, base: Twisting) -> Twisting:
        return Twisting(
            tab.number("k1", base.k1, lo=0.0, lo_open=True, hi=1e4),
            tab.number("k2", base.k2, lo=0.0, lo_open=True, hi=1e4),
            tab.number("L", base.L, lo=0.0, lo_open=True, hi=1e4),
            tab.number("xi_max", base.xi_max, lo=0.0, lo_open=True, hi=1e4),
        )

    for loop in ("z", "attitude", "yaw"):
        tab = t.table(loop)
        kw[loop] = backstep(tab, getattr(d, loop))
        kw[f"{loop}_st"] = twisting(tab, getattr(d, f"{loop}_st"))
        tab.done()
        try:
            check_twisting(kw[f"{loop}_st"], f"gains.{loop}")
        except ConfigError as exc:
            raise ConfigError(f"{source}: {exc}") from None
    xy = t.table("xy")
    alpha = xy.number("alpha", d.position.alpha, lo=0.5, hi=1.0, lo_open=True, hi_open=True)
    kw["position"] = Backstep(xy.number("c_p", d.position.c, lo=0.0, lo_open=True, hi=1e4), alpha,
                              xy.number("eps_p", d.position.eps, lo=0.0, lo_open=True, hi=10.0))
    kw["velocity"] = Backstep(xy.number("c_v", d.velocity.c, lo=0.0, lo_open=True, hi=1e4), alpha,
                              xy.number("eps_v", d.velocity.eps, lo=0.0, lo_open=True, hi=10.0))
    xy.done()
    lim = t.table("limits")
    kw["tilt_max"] = lim.number("tilt_max", d.tilt_max, lo=0.05, hi=1.4)
    kw["tilt_rate_max"] = lim.number("tilt_rate_max", d.tilt_rate_max, lo=0.1, hi=100.0)
    kw["feedforward_max"] = lim.number("feedforward_max", d.feedforward_max, lo=1.0, hi=1e5)
    lim.done()
    kw["smc_scale"] = t.number("smc_scale", d.smc_scale, lo=0.0, lo_open=True, hi=100.0)
    pid = t.table("pid")
    kw["pid"] = {k: pid.number(k, v, lo=0.0, hi=1e5) for k, v in PID_DEFAULTS.items()}
    pid.done()
    t.done()
    return Gains(**kw)
