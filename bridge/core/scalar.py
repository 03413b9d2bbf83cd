"""Which kernels the scalar engine flies: the plain-float functions, or their numba-compiled twins.

In:  the number of control steps a flight has (its mission's duration s times its rate Hz); the environment
     variable ``BSST_KERNELS``: ``plain``, ``compiled`` or ``auto`` (unset: ``auto``); whether this process
     holds the compiled kernels already
Out: whether to compile (:func:`compiled_wanted`; :func:`compiled_needed`: whatever the process holds), and a
     controller and a plant given their compiled twins (:func:`compile_for`: bridge.core.scalarkernels, imported
     only then, numba with it); whether every flight
     asks for them (:func:`compiled_everywhere`: the fork server then loads them once for all its children)

Both give the same bits (tests/test_kernels.py). A compiled call is faster (the BS-ST controller step ~2.8 us
against ~18 us plain; an RK4 step ~1.2 us against ~4.6 us: ``benchmarks/offline.py``), but a process that uses
them first pays numba's import and the cached kernels' load, ~1-2.5 s (docs/figures.md, "Compiled or plain"):
~36 us saved per control step of a lockstep flight (controller and vehicle) pays that back only after about
:data:`AUTO_STEPS` steps. So ``auto`` compiles for flights at least that long, and for any flight in a process
that already holds the kernels (:func:`compiled_loaded`: it flew compiled before, or its fork server loaded them,
bridge.core.kernelpreload), and otherwise flies the short ones (every shipped mission, ``make demo``) plain;
``compiled`` always (the SITL speed benchmark), ``plain`` never. Only the built-in BS-ST and SMC laws have the
one-call compiled step; ``pid`` and a user's own law stay plain (their plant is compiled all the same).
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable, Mapping

from bridge.autopilot.compiling import cache_off
from bridge.core.wire import odometry_fields, state_from_odometry_fields
from controller import Controller
from params import ConfigError
from plant import Quadrotor

KERNELS_ENV = "BSST_KERNELS"
CHOICES = ("plain", "compiled", "auto")
AUTO_STEPS = 60_000  # control steps from which ``auto`` compiles: 240 s at 250 Hz
# set by a session's launcher on the children it starts: the compiled kernels they fly ("ekf", "scalar": the law's
# and the plant's), comma-separated, which their fork server loads before it forks them (bridge.core.kernelpreload)
FLIES_ENV = "BSST_SESSION_KERNELS"


def compiled_wanted(steps: float) -> bool:
    """Whether a flight of ``steps`` control steps flies the compiled kernels (module docstring); a
    ``BSST_KERNELS`` that is none of :data:`CHOICES` is a ConfigError naming it."""
    return compiled_needed(steps) or (checked_choice() == "auto" and compiled_loaded())


def compiled_needed(steps: float) -> bool:
    """Whether a flight of ``steps`` control steps flies the compiled kernels in any process, whether it holds them
    or not (``compiled``, or ``auto``'s long flight): what a session's fork server loads before it forks the
    session's children (bridge.core.kernelpreload, :data:`FLIES_ENV`)."""
    choice = checked_choice()
    return choice == "compiled" or (choice == "auto" and steps >= AUTO_STEPS)


def checked_choice() -> str:
    """This process's ``BSST_KERNELS`` (:func:`kernels_choice`); one that is none of :data:`CHOICES` is a
    ConfigError naming it."""
    choice = kernels_choice()
    if choice not in CHOICES:
        raise ConfigError(f"{KERNELS_ENV}={choice!r} (environment): must be one of {', '.join(CHOICES)}")
    return choice


def compiled_loaded() -> bool:
    """Whether this process already holds the compiled kernels (loaded by an earlier flight, or by the fork server
    it was forked from): then they cost nothing more, and ``auto`` flies them."""
    kernels = sys.modules.get("bridge.core.scalarkernels")
    return kernels is not None and bool(kernels.rk4_held.signatures)


def compile_for(ctl: Controller | None = None, plant: Quadrotor | None = None) -> None:
    """Give ``ctl`` and ``plant`` their compiled kernels (:func:`bridge.core.scalarkernels.compile_scalar`)."""
    from bridge.core.scalarkernels import compile_scalar  # numba's import (~1 s): only where compiled kernels fly

    compile_scalar(ctl, plant)


def kernel_cache_on() -> bool:
    """Whether numba caches the compiled kernels on disk here (imports them, and numba: ~1 s). Where it found no
    writable place (bridge.autopilot.kernelcache.enable_cache) each process compiles what it flies (~4 s), and a
    launcher compiling them ahead of its children would compile them once more (bridge.session.sitl)."""
    from bridge.core import scalarkernels  # numba's import (~1 s): only where compiled kernels fly

    return not cache_off(scalarkernels.__name__)


def wire_for(compiled: bool) -> tuple[Callable[..., tuple[float, ...]], Callable[..., tuple[float, ...]]]:
    """:func:`bridge.core.wire.odometry_fields` and :func:`~bridge.core.wire.state_from_odometry_fields` as a flight
    with ``compiled`` kernels calls them: their compiled twins (bridge.core.scalarkernels.wire_twins), or plain."""
    if not compiled:
        return odometry_fields, state_from_odometry_fields
    from bridge.core.scalarkernels import wire_twins  # numba's import (~1 s): only where compiled kernels fly

    return wire_twins()


def compiled_everywhere() -> bool:
    """Whether ``BSST_KERNELS`` asks for the compiled kernels for every flight (``compiled``)."""
    return kernels_choice() == "compiled"


def kernels_choice(env: Mapping[str, str] | None = None) -> str:
    """``BSST_KERNELS`` as set in ``env`` (default: this process's environment), lower case; unset: ``auto``
    (not checked: :func:`compiled_wanted` refuses a value that is none of :data:`CHOICES`)."""
    return (os.environ if env is None else env).get(KERNELS_ENV, "auto").strip().lower() or "auto"
