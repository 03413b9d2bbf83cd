"""The garbage collector paused while long-lived objects are made (parse trees, imported modules).

In:  nothing
Out: :func:`collector_off`, a context in which the collector does not run (restored as it was after)

Why: each collection of the oldest generation walks every object alive; made in one go and kept (a project's
parse trees, a worker's collected test modules), each collection meanwhile walked all those made before them: a
whole project's parse took 1.2 CPU-s with the collector on, 0.31 off.
"""

from __future__ import annotations

import contextlib
import gc
from collections.abc import Iterator


@contextlib.contextmanager
def collector_off() -> Iterator[None]:
    """No garbage collection inside; the collector on again after, if it was on before."""
    was = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was:
            gc.enable()
