"""Imported to load the compiled kernels now: a sweep pool's fork server, for a grid worth them.

In:  ``BSST_KERNELS`` (bridge.core.scalar): anything but ``plain``
Out: the importing process holds the scalar engine's and the EKF's compiled kernels
     (:func:`bridge.core.flight.load_compiled_kernels`, ~1 s of CPU: numba's import and the cache's load), so that
     every worker forked from it flies them (``auto`` takes kernels already loaded); with ``plain``, nothing

The sweep's process pool (bridge.sweep.executors) names this module in its fork server's preload list under
``auto`` when it flies at least :data:`bridge.sweep.executors.WARM_CELLS` cells offline: a 30 s sine cell costs
~1.2 s of CPU plain and ~0.75 s compiled, so the load pays back from the third cell. Only from numba's cache on
disk (a cold one is not compiled here), and a load that fails leaves the workers plain (a fork server must not
die of it).
"""

from __future__ import annotations

from bridge.core.kernelpreload import load_cached_kernels
from bridge.core.scalar import kernels_choice

if kernels_choice() != "plain":  # (the pool names this module under ``auto`` only)
    load_cached_kernels()
