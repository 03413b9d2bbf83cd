"""numba's on-disk cache, judged fresh by every source a kernel compiles in: the project's one ``njit``.

In:  a plain Python function and numba's ``njit`` options (``cache=True``, ``inline``, ``nogil``, ...)
Out: its numba dispatcher, whose on-disk cache (``cache=True``) is fresh only while every project source file
     it could compile in is unchanged: :func:`source_closure` names those modules, :func:`closure_digest`
     folds their contents (SHA-256) into the cache's source stamp

Why: numba compiles a kernel's callees into it and caches the whole, but judges the cache fresh by the
kernel's *own* source file only. A change to a callee in another file (``plant/battery.py`` under the batch
engine's cell kernel in ``bridge/batch/flight.py``) left the caller's cache flying the old callee, silently,
until the cache was removed by hand. Here the stamp numba compares (its index file's ``source_stamp``)
becomes ``(numba's own stamp, digest of the closure)``, so numba itself finds such a cache stale and
compiles afresh, once, after a pull, an upgrade or an edit.

The closure is what numba can reach by name from the kernel: the module of its Python function, and every
project module (``bridge``, ``controller``, ``plant``, ``missions``, ``params``) that module's globals
lead to (a module; a function or dispatcher, its module; a named tuple or enum, or an instance of one, its
class's module), and so on; not a plain function of the modules numba compiles nothing of (:data:`PYTHON_ONLY`). It
over-reaches (a whole module, not the functions used): a change anywhere in the closure compiles the kernel again.
It does not follow a package's submodules through the package (the import system binds them there in whatever
order a process imports them: the stamp would differ between processes) nor see where a bare number came from: a
kernel module names such a constant through its module (``plan_cell.HOLD``). tests/test_kernelcache.py walks the
package for both, checks that every kernel is made with this ``njit``, and that :data:`PYTHON_ONLY` holds none.
"""

from __future__ import annotations

import enum
import hashlib
import os
import sys
from collections.abc import Callable
from types import FunctionType, ModuleType
from typing import Any

PROJECT_PACKAGES = ("bridge", "controller", "plant", "missions", "params")
# Python's alone: the input readers (files, text, their error messages: params, a link trace's parser, the timeline's
# events) and the wind's samples (computed before a flight, flown as arrays). numba compiles none of their functions
# into a kernel (none is a dispatcher or registered with numba: tests/test_kernelcache.py), so a function of theirs
# that a kernel module's plain Python calls (to read or check its input, to sample the wind) brings them into no
# closure. Through such calls they were all in the batch engine's: an error message's new wording compiled its
# kernel afresh (~24 s of CPU) in the next ``make test`` and a user's next sweep (15 of the 26 commits of a day that
# made it compile)
PYTHON_ONLY = ("params", "plant.events", "plant.wind", "bridge.link.trace")

CACHE_OFF_NOTE = ("bsst: note: numba kernel cache off: no writable cache location (set NUMBA_CACHE_DIR to a "
                  "writable directory); kernels are compiled in each process")
NOTE_SAID_ENV = "BSST_NUMBA_CACHE_OFF_SAID"  # set once the note is said: a child of the command says it no more
UNCACHED: set[str] = set()  # kernels asked to cache that numba could not (module.qualname): compiled in memory only
_file_digests: dict[str, bytes] = {}  # source path -> SHA-256 of its bytes, once per process
_references: dict[tuple[str, int], frozenset[str]] = {}  # (module, size of its namespace) -> modules it names


def njit(func: Callable[..., Any] | None = None, **options: Any) -> Any:
    """``numba.njit(**options)(func)`` (or the decorator, without ``func``); with ``cache=True`` its cache's
    source stamp also carries :func:`closure_digest` of the function's module (module docstring). Where numba
    finds no writable cache location it compiles the kernel in memory only (:func:`enable_cache`)."""
    if func is None:
        return lambda f: njit(f, **options)
    import numba  # here, not at the top: the constants below are read by processes that never compile

    cache = options.pop("cache", False)
    dispatcher = numba.njit(**options)(func)
    if cache and enable_cache(dispatcher):
        restamp(dispatcher)
    return dispatcher


def enable_cache(dispatcher: Any) -> bool:
    """Turn on ``dispatcher``'s on-disk cache (what ``numba.njit(cache=True)`` does) where numba finds a writable
    place for it: ``NUMBA_CACHE_DIR``, the source's ``__pycache__``, the user's cache folder (``~/.cache/numba``).
    Where it finds none (a read-only install run by a user without a writable home, a read-only container),
    numba's own ``cache=True`` raises "no locator available" at import; here the kernel is compiled in memory
    instead, the same bits, each process again (:data:`UNCACHED` names it; ``bridge.autopilot.compiling`` counts
    it as cold), and the first such kernel says so in one line on stderr (:data:`CACHE_OFF_NOTE`), once per
    command: a process it starts later (a fork server, a vehicle) inherits :data:`NOTE_SAID_ENV` and says no more.
    Whether the cache is on."""
    if not hasattr(dispatcher, "enable_caching"):
        return False  # NUMBA_DISABLE_JIT: the plain function
    try:
        dispatcher.enable_caching()
    except RuntimeError:  # numba's CacheImpl: no locator could make or write its cache directory
        if not UNCACHED and not os.environ.get(NOTE_SAID_ENV):
            sys.stderr.write(CACHE_OFF_NOTE + "\n")
            sys.stderr.flush()
            os.environ[NOTE_SAID_ENV] = "1"  # inherited by the processes this one starts: said once per command
        UNCACHED.add(f"{dispatcher.py_func.__module__}.{dispatcher.py_func.__qualname__}")
        return False
    return True


def restamp(dispatcher: Any) -> None:
    """Fold the closure's digest into ``dispatcher``'s on-disk cache stamp (numba's ``IndexDataCacheFile``:
    the stamp it writes into the index and compares on load). Done once, at the dispatcher's making."""
    cache_file = getattr(getattr(dispatcher, "_cache", None), "_cache_file", None)
    if cache_file is None or not hasattr(cache_file, "_source_stamp"):
        return  # no on-disk cache here (NUMBA_DISABLE_JIT, another numba's layout): numba's own judgement
    cache_file._source_stamp = (cache_file._source_stamp, closure_digest(dispatcher.py_func.__module__))


def closure_digest(module: str) -> str:
    """SHA-256 (hex) over the names and source contents of :func:`source_closure` of ``module``."""
    h = hashlib.sha256()
    for name in sorted(source_closure(module)):
        path = getattr(sys.modules[name], "__file__", None)
        if path:
            h.update(name.encode() + b"\0" + _file_digest(path))
    return h.hexdigest()


def source_closure(module: str) -> frozenset[str]:
    """The project modules a kernel of ``module`` (imported) can compile in: it, and every project module its
    globals lead to, transitively (module docstring)."""
    seen: set[str] = set()
    todo = [module]
    while todo:
        name = todo.pop()
        if name in seen or name not in sys.modules:
            continue
        seen.add(name)
        todo.extend(_named_modules(sys.modules[name]) - seen)
    return frozenset(seen)


def _named_modules(module: ModuleType) -> frozenset[str]:
    """The project modules ``module``'s globals name, remembered per module and size of its namespace (a module
    still being imported grows; one imported does not change). A package's submodules are left out: the import
    system binds each one in its package's namespace when anyone imports it, so following them would make the
    closure hang on what this process happened to import first."""
    space = vars(module)
    key = (module.__name__, len(space))
    if key not in _references:
        homes = {home for value in list(space.values()) if (home := _origin(value))}
        _references[key] = frozenset(m for m in homes if m != module.__name__ and not _bound_submodule(module, m))
    return _references[key]


def _bound_submodule(module: ModuleType, name: str) -> bool:
    """Whether ``name`` is a submodule of package ``module`` that the import system bound in its namespace."""
    parent, _, leaf = name.rpartition(".")
    return hasattr(module, "__path__") and parent == module.__name__ and vars(module).get(leaf) is sys.modules.get(name)


def _origin(value: Any) -> str | None:
    """The project module one global can bring into a kernel: a module is itself; a function or dispatcher, its
    defining module; a class numba compiles (a named tuple, an enum) or an instance of one, its class's. Other
    classes (a dataclass, a session) are Python's alone: numba cannot compile them into a kernel."""
    if isinstance(value, ModuleType):
        home = value.__name__
    elif isinstance(value, FunctionType) or hasattr(value, "py_func"):
        home = getattr(value, "py_func", value).__module__
        if not hasattr(value, "py_func") and isinstance(home, str) and python_only(home):
            return None  # a plain function of a module whose functions are never compiled (PYTHON_ONLY)
    else:
        kind = value if isinstance(value, type) else type(value)
        home = kind.__module__ if issubclass(kind, (tuple, enum.Enum)) else None
    return home if isinstance(home, str) and _ours(home) else None


def python_only(module: str) -> bool:
    """Whether ``module`` is one of :data:`PYTHON_ONLY` or in one of them."""
    return any(module == p or module.startswith(p + ".") for p in PYTHON_ONLY)


def _ours(module: str) -> bool:
    return module.partition(".")[0] in PROJECT_PACKAGES


def _file_digest(path: str) -> bytes:
    if path not in _file_digests:
        try:
            with open(path, "rb") as f:
                _file_digests[path] = hashlib.sha256(f.read()).digest()
        except OSError:  # not a file on disk (a zip import): no digest, numba's own stamp still judges
            _file_digests[path] = b""
    return _file_digests[path]
