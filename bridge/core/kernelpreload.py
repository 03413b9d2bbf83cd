"""Imported to preload: the compiled kernels loaded into a process whose children are forked from it.

In:  ``BSST_KERNELS`` (bridge.core.scalar): ``compiled`` asks for the compiled kernels in every flight; for our
     fork server under ``auto``, each child's command line and environment as it is asked for (KernelWarmer)
Out: with ``compiled``, the importing process holds the scalar engine's and the EKF's compiled kernels
     (:func:`bridge.core.flight.load_compiled_kernels`, ~1 s of CPU: numba's import and the cache's load; where
     numba has no cache on disk, the scalar engine's only, compiled, ~4 s, and the EKF's before the first vehicle
     that flies one: :class:`KernelWarmer`); otherwise nothing (numba is not imported) until :class:`KernelWarmer`
     loads them before a third child that flies

Two fork servers import it: ours, which forks the sessions' children (bridge.cli.forkserver), and
multiprocessing's, which forks a sweep's workers (bridge.sweep.executors). Each child then starts with the
kernels in its memory instead of loading them itself: with ``compiled``, a session's two children or a sweep's
N workers pay the load once, not each; under ``auto``, ours loads them once it has forked one session's pair
(:class:`KernelWarmer`), and the later children fly them (``auto`` takes kernels already loaded). A load that
fails here is left to the children, which fly plain (``auto``) or load the kernels themselves and report a
failure as any flight does (``compiled``): a fork server must not die of it. Where numba has no cache on disk
(no writable home, a read-only install: bridge.autopilot.kernelcache) a load is a compile: the EKF's then waits for
a vehicle that flies one (ours) or is compiled by each sweep worker whose cells fly one (multiprocessing's).
"""

from __future__ import annotations

import gc
import sys
from collections.abc import Callable, Mapping, Sequence

from bridge.autopilot.compiling import cache_off
from bridge.autopilot.estimator import load_ekf_kernels
from bridge.core.flight import compiled_kernels_cached, load_compiled_kernels
from bridge.core.scalar import compiled_everywhere, compiled_loaded, kernels_choice


def ekf_cache_on() -> bool:
    """Whether numba caches the EKF's kernels on disk here (imports them, not compiled: numba's import). Where it
    found no writable place, loading them means compiling them (~7 s): a server does so only for a child that
    flies an EKF (:class:`KernelWarmer`)."""
    from bridge.autopilot import ekfkernels  # numba's import (~0.3 s): only in a server asked for compiled kernels

    return not cache_off(ekfkernels.__name__)


if compiled_everywhere():
    try:
        load_compiled_kernels(ekf=ekf_cache_on())
    except Exception:  # noqa: BLE001  (the children load them again, and say what went wrong)
        pass


FLYING = frozenset({"vehicle", "controller"})  # the children that fly kernels (a relay, a sitl launcher do not)
WARM_AFTER = 2  # children that fly, forked plain, before a server under ``auto`` loads the kernels for the rest


class KernelWarmer:
    """The fork server's rule under ``auto``: the compiled kernels are loaded into the server, once, before the
    third child that flies (a vehicle or a controller) is forked, so that it and every later one flies them (the
    same bits, bridge.core.scalar) without paying numba's load (~1 s of CPU) itself. One session (a vehicle and
    its controller, a relay between them or not) never pays it; a fleet, or a process flying session after
    session (a script, the test suite), pays it once and saves ~36 us of CPU per control step thereafter. Only
    from numba's cache on disk: with it cold (a first run after an install) nothing is compiled on the children's
    behalf, and they fly plain."""

    def __init__(self, warm_after: int = WARM_AFTER, flies_ekf: Callable[[Sequence[str]], bool] | None = None) -> None:
        self.warm_after = warm_after
        self.flying = 0  # children that fly, forked so far
        self.flies_ekf = flies_ekf  # whether a vehicle's command line flies an EKF (bridge.cli.forkserver's)

    def __call__(self, argv: Sequence[str], env: Mapping[str, str]) -> None:
        """Called before the server forks the child ``argv`` (the CLI's arguments) in ``env``."""
        if not argv or argv[0] not in FLYING:
            return
        self.flying += 1
        if kernels_choice(env) == "compiled" and argv[0] == "vehicle":
            self._ekf_for(argv)
        if self.flying <= self.warm_after or compiled_loaded():
            return
        if kernels_choice(env) != "auto":
            return  # plain asked for; compiled: loaded at the server's start (above)
        if load_cached_kernels():
            gc.collect()
            gc.freeze()  # numba's objects too: shared with every later child, never copied into one


    def _ekf_for(self, argv: Sequence[str]) -> None:
        """``compiled`` where numba has no cache: the server's start compiled the law's and the plant's kernels but
        not the EKF's (~7 s, for flights that may not fly one); before the first vehicle that flies one, they are
        compiled here, once, and it and every later vehicle inherit them. A failure is left to the vehicle."""
        ekf = sys.modules.get("bridge.autopilot.ekfkernels")
        if self.flies_ekf is None or ekf is None or getattr(ekf.propagate, "signatures", True):
            return  # no way to tell; numba not imported (the server's start under ``auto``); compiled or loaded
        try:
            if self.flies_ekf(argv):
                load_ekf_kernels()
                gc.collect()
                gc.freeze()
        except Exception:  # noqa: BLE001  (see the docstring)
            return


def load_cached_kernels() -> bool:
    """Load the compiled kernels on behalf of children that would fly plain otherwise (``auto``), only from numba's
    cache on disk: a cold one would be compiled here (~40 s, while a session waits for its child), so then
    nothing. Whether they were loaded; a failure is not (the children fly plain; a fork server must not die of it)."""
    try:
        if not compiled_kernels_cached():
            return False
        load_compiled_kernels()
    except Exception:  # noqa: BLE001  (see the docstring)
        return False
    return True
