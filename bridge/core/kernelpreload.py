"""Imported to preload: the compiled kernels loaded into a process whose children are forked from it.

In:  ``BSST_KERNELS`` (bridge.core.scalar): ``compiled`` asks for the compiled kernels in every flight; for our
     fork server under ``auto``, each child's command line and environment as it is asked for (KernelWarmer)
Out: with ``compiled``, the importing process holds the scalar engine's and the EKF's compiled kernels
     (:func:`bridge.core.flight.load_compiled_kernels`, ~1 s of CPU: numba's import and the cache's load);
     otherwise nothing (numba is not imported) until :class:`KernelWarmer` loads them before a third child that flies

Two fork servers import it: ours, which forks the sessions' children (bridge.cli.forkserver), and
multiprocessing's, which forks a sweep's workers (bridge.sweep.executors). Each child then starts with the
kernels in its memory instead of loading them itself: with ``compiled``, a session's two children or a sweep's
N workers pay the load once, not each; under ``auto``, ours loads them once it has forked one session's pair
(:class:`KernelWarmer`), and the later children fly them (``auto`` takes kernels already loaded). A load that
fails here is left to the children, which fly plain (``auto``) or load the kernels themselves and report a
failure as any flight does (``compiled``): a fork server must not die of it.
"""

from __future__ import annotations

import gc
from collections.abc import Mapping, Sequence

from bridge.core.flight import compiled_kernels_cached, load_compiled_kernels
from bridge.core.scalar import compiled_everywhere, compiled_loaded, kernels_choice

if compiled_everywhere():
    try:
        load_compiled_kernels()
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

    def __init__(self, warm_after: int = WARM_AFTER) -> None:
        self.warm_after = warm_after
        self.flying = 0  # children that fly, forked so far

    def __call__(self, argv: Sequence[str], env: Mapping[str, str]) -> None:
        """Called before the server forks the child ``argv`` (the CLI's arguments) in ``env``."""
        if not argv or argv[0] not in FLYING:
            return
        self.flying += 1
        if self.flying <= self.warm_after or compiled_loaded():
            return
        if kernels_choice(env) != "auto":
            return  # plain asked for; compiled: loaded at the server's start (above)
        if load_cached_kernels():
            gc.collect()
            gc.freeze()  # numba's objects too: shared with every later child, never copied into one


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
