"""Say so when numba is about to compile: the first EKF or batch run after an install spends 7-24 s
compiling kernels, which without a word looks like a hang.

In:  the name of a package or module whose numba kernels (``@njit(cache=True)``) are about to be first
     called in this process, already imported (:data:`KERNELS`: what they are, in words; how long
     compiling them takes, s)
Out: one line on stderr, ``bsst: compiling the EKF's kernels (first run after an install, ~7 s; cached on
     disk after) ...``, once per process and only when numba's on-disk cache of those kernels is cold:
     for at least half of them, the index file (``<module>.<function>-<line>.py311.nbi`` in the source's
     ``__pycache__``, or under ``NUMBA_CACHE_DIR``) absent, of another numba version, or stale (a
     source it compiles in changed since: bridge.autopilot.kernelcache); where numba found no writable place
     for that cache (kernelcache.enable_cache), always: ``... (~7 s, in each process: numba's cache is off) ...``

The check asks each kernel's own numba cache object where its index is and whether it is fresh (what
numba itself will decide), so that it never disagrees with numba's naming or its cache directory rules.
Half, not any: a kernel or two is compiled only when first needed (the batch's failsafe landing, when
a cell first lands), and inlined kernels (``inline="always"``) are never cached on their own; a first
run after an install, an upgrade or another numba finds them all cold.
"""

from __future__ import annotations

import pickle
import sys
from collections.abc import Iterator
from typing import Any, TextIO

from bridge.autopilot import kernelcache  # (numba is imported only where a kernel is made)

KERNELS = {  # package of kernels: what they are, in words, and how long compiling them takes on the 2-core VM, s
    "bridge.autopilot.ekfkernels": ("the EKF's kernels", 7.0),  # 6.6 s of CPU (docs/figures.md, eighteenth session)
    "bridge.batch": ("the batch engine's kernels", 24.0),  # 23.1 s
    "bridge.core.scalarkernels": ("the controller's and the plant's kernels", 4.0),  # 3.3 s
}

_checked: set[str] = set()  # packages looked at in this process: each is announced at most once


def announce_compiling(package: str, stream: TextIO | None = None) -> bool:
    """Print the compiling line for the kernels of ``package`` (a key of :data:`KERNELS`: that module, or
    that package and its loaded submodules) if numba's cache of them is cold; once per process (later calls
    return at once). Whether it printed."""
    if package in _checked:
        return False
    _checked.add(package)
    if not cold(package):
        return False
    out = stream or sys.stderr
    out.write(compiling_line(package, _uncached(package)) + "\n")
    out.flush()
    return True


def compiling_line(package: str, uncached: bool = False) -> str:
    """The line :func:`announce_compiling` says for ``package`` (a key of :data:`KERNELS`): with numba's cache on disk
    (``uncached`` False), or without one (each process compiles)."""
    what, seconds = KERNELS[package]
    when = (f"~{seconds:g} s, in each process: numba's cache is off" if uncached
            else f"first run after an install, ~{seconds:g} s; cached on disk after")
    return f"bsst: compiling {what} ({when}) ..."


def cold(package: str) -> bool:
    """Whether numba's on-disk cache of ``package``'s kernels (a key of :data:`KERNELS`, imported) is cold: for at
    least half of them, numba would compile rather than load (module docstring)."""
    kernels = [d for d in _kernels(package) if getattr(d, "targetoptions", {}).get("inline") != "always"]
    return bool(kernels) and 2 * sum(_cold(d) for d in kernels) >= len(kernels)


def _kernels(package: str) -> Iterator[Any]:
    """The numba dispatchers made to cache on disk among the attributes of ``package``'s loaded modules: with
    their cache, or without where numba found no place for it (kernelcache.UNCACHED)."""
    for name, module in list(sys.modules.items()):
        if name == package or name.startswith(package + "."):
            for obj in vars(module).values():
                if getattr(getattr(obj, "_cache", None), "_cache_file", None) is not None or _uncached_kernel(obj):
                    yield obj


def cache_off(package: str) -> bool:
    """Whether numba found no writable place to cache ``package``'s kernels (a key of :data:`KERNELS`, imported: any
    of them made to cache without one, kernelcache.UNCACHED): each process that flies them compiles them, so a
    launcher compiling them ahead of its children would only compile them once more (bridge.session.sitl)."""
    return _uncached(package)


def _uncached(package: str) -> bool:
    """Whether any of ``package``'s kernels was made to cache where numba found no place for it."""
    return any(_uncached_kernel(d) for d in _kernels(package))


def _uncached_kernel(obj: Any) -> bool:
    func = getattr(obj, "py_func", None)  # a numba dispatcher's
    return func is not None and f"{func.__module__}.{func.__qualname__}" in kernelcache.UNCACHED


def _cold(dispatcher: Any) -> bool:
    """Whether numba will compile this kernel rather than load it: no index, or one numba will not use
    (another numba version; a source changed since: numba's own test, ``_load_index``, gives {} for both)."""
    if _uncached_kernel(dispatcher):
        return not dispatcher.overloads  # no cache: compiled in every process
    try:
        cache_file = dispatcher._cache._cache_file  # numba's: where its index is, and its freshness test
        return not dispatcher.overloads and not cache_file._load_index()
    except (AttributeError, OSError, EOFError, ValueError, pickle.UnpicklingError):  # another numba's layout, a
        return False  # damaged index: say nothing rather than guess
