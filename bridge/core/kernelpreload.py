"""Imported to preload: the compiled kernels loaded into a process whose children are forked from it.

In:  ``BSST_KERNELS`` (bridge.core.scalar): ``compiled`` asks for the compiled kernels in every flight
Out: with ``compiled``, the importing process holds the scalar engine's and the EKF's compiled kernels
     (:func:`bridge.core.flight.load_compiled_kernels`, ~1 s of CPU: numba's import and the cache's load);
     otherwise nothing (numba is not imported)

Two fork servers import it: ours, which forks the sessions' children (bridge.cli.forkserver), and
multiprocessing's, which forks a sweep's workers (bridge.sweep.executors). Each child then starts with the
kernels in its memory instead of loading them itself: with ``compiled``, a session's two children or a sweep's
N workers pay the load once, not each. A load that fails here is left to the children, which load the kernels
themselves and report a failure as any flight does (a fork server must not die of it).
"""

from __future__ import annotations

from bridge.core.flight import load_compiled_kernels
from bridge.core.scalar import compiled_everywhere

if compiled_everywhere():
    try:
        load_compiled_kernels()
    except Exception:  # noqa: BLE001  (the children load them again, and say what went wrong)
        pass
