"""Covers bridge.autopilot.kernelcache: a kernel's on-disk cache goes stale when a source it compiles in changes.

The end-to-end case is the bug it fixes: a kernel whose callee lives in another file, cached, the callee changed,
a new process. With numba's own ``njit`` the new process flies the old callee from the cache; with the project's
it compiles afresh and flies the new one, and a third process, nothing changed, loads from the cache again. And
the stamp does not hang on what a process imported first (else every process would find the others' caches stale
and compile again). The walks over the package are tests/test_kernelcache.py.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.process  # starts Python processes with caches of their own

ROOT = Path(__file__).resolve().parents[1]

CALLER = """
import numba
from numba.extending import register_jitable

from bridge.autopilot.kernelcache import njit
from plant import probe_callee

register_jitable(probe_callee.scale)


@njit(cache=True)
def ours(x):
    return probe_callee.scale(x)


@numba.njit(cache=True)
def numbas(x):
    return probe_callee.scale(x)
"""
RUN = """
import json
from plant import probe_caller as c
print(json.dumps({"ours": c.ours(1.0), "numbas": c.numbas(1.0),
                  "ours_loaded": sum(c.ours.stats.cache_hits.values()) > 0}))
"""


def _fly(tree: Path) -> dict:
    # no .pyc: a callee rewritten within the second its .pyc was written, at the same size, would load stale
    # (Python judges a .pyc by whole-second mtime and size), and every kernel would fly the old callee
    env = {**os.environ, "PYTHONPATH": f"{tree}{os.pathsep}{ROOT}", "NUMBA_CACHE_DIR": str(tree / "cache"),
           "PYTHONDONTWRITEBYTECODE": "1"}
    out = subprocess.run([sys.executable, "-c", RUN], env=env, cwd=tree, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-3000:]
    return json.loads(out.stdout)


def test_a_changed_callee_in_another_file_is_compiled_afresh(tmp_path: Path) -> None:
    """Callee in plant/probe_callee.py, its caller in plant/probe_caller.py (a ``plant`` of the test's own, first
    on the path): changing the callee reaches the project's kernel, not numba's plain one; unchanged, the
    project's kernel loads from the cache."""
    package = tmp_path / "plant"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "probe_caller.py").write_text(CALLER)
    callee = package / "probe_callee.py"
    callee.write_text("def scale(x):\n    return 2.0 * x\n")
    first = _fly(tmp_path)
    assert first == {"ours": 2.0, "numbas": 2.0, "ours_loaded": False}
    callee.write_text("def scale(x):\n    return 3.0 * x\n")
    second = _fly(tmp_path)
    assert second["numbas"] == 2.0, "numba's own cache flew the new callee: this module may no longer be needed"
    assert second["ours"] == 3.0 and not second["ours_loaded"]
    assert _fly(tmp_path) == {"ours": 3.0, "numbas": 2.0, "ours_loaded": True}


PROBE = """
import importlib, json, sys
for name in sys.argv[1:]:
    importlib.import_module(name)
from bridge.core import scalarkernels as s
from bridge.autopilot import ekfkernels as e
print(json.dumps([s.control_step._cache._cache_file._source_stamp[1], e.propagate._cache._cache_file._source_stamp[1]]))
"""


def test_the_stamp_does_not_hang_on_what_a_process_imported_first() -> None:
    """The scalar engine's and the EKF's kernels, stamped in a process that imports them alone and in one that
    first imports the CLI, the batch engine and the sweep: the same stamps."""
    def stamps(*first: str) -> list[str]:
        out = subprocess.run([sys.executable, "-c", PROBE, *first], capture_output=True, text=True, timeout=120,
                             cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)})
        assert out.returncode == 0, out.stderr[-3000:]
        return json.loads(out.stdout)

    alone = stamps()
    assert stamps("bridge.cli", "bridge.batch", "bridge.sweep", "bridge.session", "bridge.swarm") == alone
    assert stamps("bridge.autopilot.ekfkernels", "controller", "missions", "plant") == alone


