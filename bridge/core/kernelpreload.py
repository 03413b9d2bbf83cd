"""Imported to preload: the compiled kernels loaded into a process whose children are forked from it.

In:  ``BSST_KERNELS`` (bridge.core.scalar): ``compiled`` asks for the compiled kernels in every flight; for our
     fork server, each child's command line and environment as it is asked for (KernelWarmer): the kernels its
     session's launcher says it flies (bridge.core.scalar.FLIES_ENV), and ``auto``
Out: with ``compiled``, the importing process holds the scalar engine's and the EKF's compiled kernels
     (:func:`bridge.core.flight.load_compiled_kernels`, ~1 s of CPU: numba's import and the cache's load; where
     numba has no cache on disk, the scalar engine's only, compiled, ~4 s, and the EKF's before the first session's
     child that flies one: :class:`KernelWarmer`); otherwise nothing (numba is not imported) until
     :class:`KernelWarmer` loads them before a session's child that flies them, or a third child that flies

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
from collections.abc import Mapping, Sequence

from bridge.autopilot.compiling import cache_off
from bridge.autopilot.estimator import load_ekf_kernels
from bridge.core.flight import compiled_kernels_cached, load_compiled_kernels
from bridge.core.scalar import FLIES_ENV, compiled_everywhere, compiled_loaded, kernels_choice


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
    """The fork server's rules. A session's child is forked with the compiled kernels its launcher says the session
    flies (:data:`~bridge.core.scalar.FLIES_ENV`: the EKF's, the law's and the plant's) loaded into the server first,
    from numba's cache on disk or compiled where it is cold or off (the child would compile them in its start-up
    otherwise), once: it and every later child inherit them, and the launcher, which flies nothing, loads none.
    Under ``auto`` the compiled kernels are loaded into the server, once, before the third child that flies (a
    vehicle or a controller) is forked, so that it and every later one flies them (the same bits,
    bridge.core.scalar) without paying numba's load (~1 s of CPU) itself. One session (a vehicle and its controller,
    a relay between them or not) never pays it; a fleet, or a process flying session after session (a script, the
    test suite), pays it once and saves ~36 us of CPU per control step thereafter. Only from numba's cache on disk:
    with it cold (a first run after an install) nothing is compiled on the children's behalf, and they fly plain."""

    def __init__(self, warm_after: int = WARM_AFTER) -> None:
        self.warm_after = warm_after
        self.flying = 0  # children that fly, forked so far

    def __call__(self, argv: Sequence[str], env: Mapping[str, str]) -> None:
        """Called before the server forks the child ``argv`` (the CLI's arguments) in ``env``."""
        if not argv or argv[0] not in FLYING:
            return
        self.flying += 1
        load_flown(env.get(FLIES_ENV, ""))
        if self.flying <= self.warm_after or compiled_loaded():
            return
        if kernels_choice(env) != "auto":
            return  # plain asked for; compiled: loaded at the server's start (above)
        if load_cached_kernels():
            gc.collect()
            gc.freeze()  # numba's objects too: shared with every later child, never copied into one


def load_flown(kinds: str) -> None:
    """Load the compiled kernels ``kinds`` names (:data:`~bridge.core.scalar.FLIES_ENV`'s value: ``ekf``, ``scalar``,
    comma-separated) that this process holds not yet; a failure is left to the child (it loads them itself and says
    what went wrong; a fork server must not die of it)."""
    wanted = set(kinds.split(","))
    ekf = sys.modules.get("bridge.autopilot.ekfkernels")
    try:
        loaded = False
        if "ekf" in wanted and (ekf is None or not getattr(ekf.propagate, "signatures", True)):
            load_ekf_kernels()  # (no signatures attribute: NUMBA_DISABLE_JIT, plain Python, nothing to load)
            loaded = True
        if "scalar" in wanted and not compiled_loaded():
            load_compiled_kernels(ekf=False)
            loaded = True
    except Exception:  # noqa: BLE001  (see the docstring)
        return
    if loaded:
        gc.collect()
        gc.freeze()


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
