"""Control laws of the ground-side offboard controller: pure maths, no sockets.

- :mod:`controller.bsst`         the paper's finite-time backstepping super-twisting law
- :mod:`controller.supertwisting` super-twisting (eq. 22) and first-order SMC reaching laws
- :mod:`controller.power`        the regularised finite-time power sig_beta
- :mod:`controller.jets`         exact time derivatives by the chain rule
- :mod:`controller.pid`          cascaded PID baseline
- :mod:`controller.actuation`    wrench clamp or rotor allocation (inverse of eq. 4)
- :mod:`controller.kernel`       the built-in BS-ST law's whole step (law, actuation, integrators) in one call
- :mod:`controller.gains`        gains from TOML, eq. (23) check
- :mod:`controller.nominal`      the law's nominal vehicle model
- :mod:`controller.link_guard`   what to do with a state of a given age (track, hold, stop, re-arm)
- :mod:`controller.predict`      latency compensation through the nominal model

:class:`Controller` ties a law to an actuation: ``step(t, state, ref)`` returns a
:class:`Command`. See ``docs/law.md`` for the law as implemented and every deviation from the paper.

In:  a law name or factory, the nominal model, the gains, the control rate (Hz); each step the time (s), the
     state (eq. 7: m, m/s, rad, rad/s), the reference sample (m, rad and derivatives)
Out: a :class:`Command`: the demanded and realisable wrench (N) and the normalised command
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from controller.actuation import MotorActuation, WrenchActuation, make_actuation
from controller.bsst import BacksteppingSuperTwisting
from controller.gains import Gains, gains_from_table
from controller.kernel import Step, control_step
from controller.law import BUILTIN, Law, LawFactory, make_law, resolve_law
from controller.nominal import Nominal
from controller.pid import CascadedPid
from missions import DEFAULT_DISCRETIZATION
from missions.references import Sample

Quad = tuple[float, float, float, float]
LAWS = tuple(BUILTIN)  # the built-in laws; a user's own is a path or module and a class name


@dataclass(frozen=True, slots=True)
class Command:
    """One control step's output: what the law demanded, what the actuation can realise,
    and the normalised command for the wire (paper frame, see controller.actuation)."""

    demanded: Quad
    realisable: Quad
    normalised: Quad


class Controller:
    """A law and its actuation, stepped at the control rate."""

    def __init__(self, law: str | LawFactory, nominal: Nominal, gains: Gains | None = None,
                 rate_hz: float = 250.0, discretization: str = DEFAULT_DISCRETIZATION) -> None:
        """``law``: a built-in name, ``file.py:Class`` / ``module:Class``, or a factory (controller.law);
        ``discretization``: how ``bsst`` steps its super-twisting step (controller.bsst.DISCRETIZATIONS)."""
        self.law: Law = make_law(law, nominal, gains or Gains(), rate_hz, discretization)
        self.nominal = nominal
        self.actuation = make_actuation(nominal)
        self.rate_hz = rate_hz
        # the built-in BS-ST and SMC laws: the whole step in one call (controller.kernel), plain until
        # :meth:`use_kernel` gives its compiled twin; the others: law.update, allocate, law.advance
        self._kernel: Callable[..., Step] | None = None
        self._args: tuple[Any, ...] = ()
        law_ = self.law
        if isinstance(law_, BacksteppingSuperTwisting):
            n = nominal
            alloc = _floats((*n.u_max, n.thrust_coeff, n.drag_coeff, n.omega_max, n.omega_max**2))
            self._kernel = control_step
            # floats throughout (a TOML integer would otherwise ask numba for a signature of its own; the plain
            # arithmetic is the same either way)
            self._args = (law_.sign, _floats(law_.constants), tuple(_floats(t) for t in law_.tables),
                          _floats(law_._k2), _floats(law_._xi_max), float(law_.dt),
                          isinstance(self.actuation, MotorActuation), alloc)

    @property
    def kernel_args(self) -> tuple[Any, ...]:
        """The arguments of :attr:`kernel` after the state, reference, omega_d, xi and hold: the law's constants."""
        return self._args

    @property
    def kernel(self) -> Callable[..., Step] | None:
        """The one-call step of a built-in BS-ST law (:func:`controller.kernel.control_step` or its compiled
        twin), or None (the generic path)."""
        return self._kernel

    def use_kernel(self, kernel: Callable[..., Step], args: tuple[Any, ...] | None = None) -> None:
        """Step with ``kernel``, the compiled twin of :func:`controller.kernel.control_step` (bit for bit the
        same results: bridge.core.scalarkernels), given ``args`` for :attr:`kernel_args` (the same values in the
        types it takes; None: as they are); only where the law has the one-call step."""
        if self._kernel is not None:
            self._kernel = kernel
            if args is not None:
                self._args = args

    def step(self, t: float, state: tuple[float, ...], ref: Sample, hold: bool = False) -> Command:
        """Compute the command for ``state`` at time t; ``hold`` freezes the integrators."""
        kernel = self._kernel
        if kernel is not None:
            law, act = self.law, self.actuation
            u, real, c, act.omega_d, law.xi, law.s, law.desired = kernel(  # type: ignore[attr-defined]
                state, ref, act.omega_d, law.xi, hold, *self._args)  # type: ignore[attr-defined]
            return Command(u, real, c)
        u = self.law.update(t, state, ref, self.actuation.omega_d)
        real, c, sat = self.actuation.allocate(u)
        self.law.advance(sat, hold)
        return Command(u, real, c)

    def reset(self) -> None:
        self.law.reset()


def _floats(values: tuple[Any, ...]) -> tuple[float, ...]:
    return tuple(float(v) for v in values)


__all__ = [
    "LAWS",
    "BacksteppingSuperTwisting",
    "CascadedPid",
    "Command",
    "Controller",
    "Gains",
    "Law",
    "MotorActuation",
    "Nominal",
    "WrenchActuation",
    "gains_from_table",
    "make_law",
    "resolve_law",
]
