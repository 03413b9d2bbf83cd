"""Covers bridge.autopilot.kernelcache: every kernel of the project is made with its ``njit``, and stamped.

Walks the package: no module takes ``njit`` from numba directly, every cached kernel's stamp carries its closure's
digest, and a constant a kernel module imports by name comes from a module the closure reaches. The end-to-end
case (a callee changed, a new process) is tests/test_kernelcache_stale.py.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

from bridge.autopilot import kernelcache

ROOT = Path(__file__).resolve().parents[1]


def _project_files() -> list[Path]:
    return [f for pkg in kernelcache.PROJECT_PACKAGES for f in sorted((ROOT / pkg).rglob("*.py"))]


def test_every_kernel_is_made_with_the_projects_njit() -> None:
    """No module but kernelcache takes ``njit`` or ``jit`` from numba: a kernel made with numba's own would be
    judged by its own file only."""
    offenders = []
    for f in [*_project_files(), *sorted((ROOT / "benchmarks").glob("*.py"))]:
        if f.name == "kernelcache.py":
            continue
        for node in ast.walk(ast.parse(f.read_text())):
            taken = isinstance(node, ast.ImportFrom) and node.module == "numba" and any(
                a.name in ("njit", "jit") for a in node.names)
            called = isinstance(node, ast.Attribute) and node.attr in ("njit", "jit") and getattr(
                node.value, "id", None) == "numba"
            if taken or called:
                offenders.append(f"{f.relative_to(ROOT)}:{node.lineno}")
    assert offenders == []


def _kernels() -> list:
    import bridge.autopilot.ekfkernels  # noqa: F401  (imported: its kernels are walked)
    import bridge.batch.flight  # noqa: F401  (as above)
    import bridge.core.scalarkernels  # noqa: F401  (as above)
    import bridge.link.plan_cell  # noqa: F401  (as above)

    return [v for name, m in list(sys.modules.items()) if kernelcache._ours(name) and m is not None
            for v in vars(m).values() if getattr(getattr(v, "_cache", None), "_cache_file", None) is not None]


def test_every_kernels_stamp_carries_its_closures_digest() -> None:
    kernels = _kernels()
    assert len(kernels) > 50
    for k in kernels:
        stamp = k._cache._cache_file._source_stamp
        assert stamp[1] == kernelcache.closure_digest(k.py_func.__module__), k


def _constants_imported_by_name(module: str) -> dict[str, str]:
    """``{name: module it was imported from}`` for each module-level ``from Y import name`` of ``module`` whose
    value numba would freeze into a kernel (a number, a tuple of numbers, an array)."""
    import numpy as np

    mod = sys.modules[module]
    out = {}
    for node in ast.parse(Path(mod.__file__).read_text()).body:
        if isinstance(node, ast.ImportFrom) and node.module and not node.level and kernelcache._ours(node.module):
            for a in node.names:
                value = vars(mod).get(a.asname or a.name)
                numeric = (int, float, complex, np.generic)
                if isinstance(value, (*numeric, np.ndarray)) or (isinstance(value, tuple) and all(
                        isinstance(v, numeric) for v in value)):
                    out[a.asname or a.name] = node.module
    return out


def test_a_constant_imported_by_name_is_in_the_closure() -> None:
    """numba freezes a global number or array into the kernel; one imported by name from a module the closure does
    not otherwise reach would leave the cache fresh when it changes. Each is reached: where one was not, the
    module is imported as a module and the constant named through it (``plan_cell.HOLD``)."""
    missing = []
    for module in sorted({k.py_func.__module__ for k in _kernels()}):
        closure = kernelcache.source_closure(module)
        for m in sorted(closure):
            for name, source in _constants_imported_by_name(m).items():
                if source not in closure:
                    missing.append(f"{m}.{name} from {source} (kernels of {module})")
    assert missing == []


def test_the_python_only_modules_hold_no_kernel_and_are_in_no_closure() -> None:
    """numba compiles no function of :data:`~bridge.autopilot.kernelcache.PYTHON_ONLY` (the input readers, the wind's
    samples): none is a dispatcher or registered with numba once every kernel module is imported, so no kernel's
    closure holds them. Before, the batch engine's held them all (through bridge.link.trace's and plant.events'
    readers, bridge.batch.weather's wind samples), and an error message's new wording in ``params/text.py`` compiled
    its kernel afresh (~24 s of CPU) in the next ``make test`` and a user's next sweep."""
    import importlib
    from types import FunctionType

    from numba.core.typing.templates import builtin_registry

    kernels = _kernels()
    files = [f for p in kernelcache.PYTHON_ONLY for f in [ROOT / f"{p.replace('.', '/')}.py",
                                                             *(ROOT / p.replace(".", "/")).rglob("*.py")] if f.exists()]
    names = {".".join(f.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__") for f in files}
    assert {"params", "params.text", "plant.events", "plant.wind", "bridge.link.trace"} <= names
    modules = [importlib.import_module(n) for n in sorted(names)]  # every one, imported or not
    compiled = [f"{m.__name__}.{k}" for m in modules for k, v in vars(m).items() if hasattr(v, "py_func")]
    registered = [f"{v.__module__}.{v.__name__}" for v, _ in builtin_registry.globals
                  if isinstance(v, FunctionType) and kernelcache.python_only(v.__module__)]
    assert compiled == registered == []
    held = {m for k in kernels for m in kernelcache.source_closure(k.py_func.__module__) if kernelcache.python_only(m)}
    assert held == set()
