"""A benchmark's functions for a test: one copy of the code that measures and the code that checks.

In:  a module name under ``benchmarks/`` (``fuzz``, ``missions``)
Out: the module, imported as ``benchmarks.<name>``; ``sys.path`` as it was before (a benchmark puts its checkout
     first on it, for when it runs as a script: left there, every process a worker starts after the test inherits
     it, tests/conftest.py's ``sys_path_kept``)
"""

from __future__ import annotations

import importlib
import sys
from types import ModuleType


def benchmark_module(name: str) -> ModuleType:
    """``benchmarks/<name>.py`` as a module, with ``sys.path`` left as it was."""
    before = list(sys.path)
    try:
        return importlib.import_module(f"benchmarks.{name}")
    finally:
        sys.path[:] = before
