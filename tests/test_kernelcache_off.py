"""Covers bridge.autopilot.kernelcache and bridge.autopilot.compiling: with no writable place for numba's cache, the
kernels are compiled in memory, said once on stderr, and fly the same bits.

The case (a new-user audit): ``pip install .`` as root into a system site-packages, run by another user whose HOME
is unset or read-only, or a read-only container. numba's ``cache=True`` then found no cache locator (not
``NUMBA_CACHE_DIR``, not the source's ``__pycache__``, not ``~/.cache/numba``) and raised "cannot cache function
...: no locator available" at import: ``BSST_KERNELS=compiled bsst sim`` died with a traceback. Each ``bsst`` here
without a cache is a real ``python -m bridge`` process (exec'd, not forked: the suite's fork server holds kernels with
a cache); the flight it is compared with is flown in the test's own process, on the kernels the suite loaded from
numba's cache (tests/conftest.py): the same bytes as a ``python -m bridge`` of its own with the cache, for a tenth
of its CPU (~0.05 s against 0.6 s).
Two ways to take every locator away, both as root:

- numba's own switch: its locators narrowed to ``NUMBA_CACHE_DIR`` (``NUMBA_CACHE_LOCATOR_CLASSES``), pointed at
  a path under ``/proc/self``, where no process, root included, may create a directory (any user);
- the real case: the source tree bind-mounted read-only in a mount namespace of the test's own (``unshare -m``,
  root only: skipped elsewhere), ``HOME`` under ``/proc/self``, no ``NUMBA_CACHE_DIR``.

Before the fix the read-only tree's flight failed with numba's "no locator available" traceback, the warmer at
import. The first way's flight (a ``bsst sim`` here until the third wave's thirty-eighth session, which failed so
too) is tests/test_no_home.py's first compiled session: a ``bsst sitl`` whose fork server compiles the same kernels
in the same branch of kernelcache.enable_cache, its lockstep trace.csv compared with the cached kernels' ``bsst sim``
to the byte (the ``bsst sim`` here compiled them once more: 4.8 CPU-s).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from bridge.autopilot import kernelcache
from bridge.autopilot.kernelcache import CACHE_OFF_NOTE
from bridge.cli import main

pytestmark = pytest.mark.process  # real bsst processes

ROOT = Path(__file__).resolve().parent.parent
NOWHERE = "/proc/self/no-cache"  # no process may create it
SHORT = 'name = "short"\nduration_s = 2.0\n[trajectory]\nkind = "sine"\n'
# the second way flies the PID law: its kernels compiled without a cache too, where it compiled the bsst law's again
# (the first way's; 2.9 against 1.1 CPU-s): both ways end in the one branch of kernelcache.enable_cache
SHORT_PID = SHORT.replace("[trajectory]", 'controller = "pid"\n[trajectory]')
TIMEOUT_S = 600.0  # s: a compile of the scalar kernels is ~4 s of CPU; a loaded machine stretches it
OUTPUTS = ("trace.csv", "summary.json", "events.log")


def _env(**extra: str) -> dict[str, str]:
    mine = {k: v for k, v in os.environ.items() if not k.startswith(("NUMBA_CACHE", "XDG_CACHE", "BSST_KERNELS"))}
    paths = [str(ROOT), *filter(None, os.environ.get("PYTHONPATH", "").split(os.pathsep))]
    return {**mine, "PYTHONPATH": os.pathsep.join(paths), "BSST_FORK_SERVER": "0", **extra}


LOCATOR_GONE = {"NUMBA_CACHE_LOCATOR_CLASSES": "UserProvidedCacheLocator", "NUMBA_CACHE_DIR": NOWHERE,
                "HOME": NOWHERE}


def _sim(tmp_path: Path, out: str, env: dict[str, str], prefix: tuple[str, ...] = (),
         mission: str = SHORT) -> subprocess.CompletedProcess:
    (tmp_path / "short.toml").write_text(mission)
    return subprocess.run([*prefix, sys.executable, "-m", "bridge", "sim", "short.toml", "--no-plots", "--out", out],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=TIMEOUT_S,
                          stdin=subprocess.DEVNULL)


def _flew_uncached(r: subprocess.CompletedProcess, tmp_path: Path, out: str, capsys: pytest.CaptureFixture[str],
                   monkeypatch: pytest.MonkeyPatch) -> None:
    """It flew, said the cache is off once (no traceback), and flew what the cached kernels fly, bit for bit: the
    same ``bsst sim`` in this process, every kernel of which has its cache (none said the note)."""
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr[-3000:]
    assert [ln for ln in r.stderr.splitlines() if ln.startswith("bsst: note:")] == [CACHE_OFF_NOTE]
    assert "in each process: numba's cache is off" in r.stderr
    monkeypatch.setenv("BSST_KERNELS", "compiled")
    capsys.readouterr()
    assert main(["sim", str(tmp_path / "short.toml"), "--no-plots", "--out", str(tmp_path / "cached")]) == 0
    said = capsys.readouterr().err
    assert "bsst: note:" not in said and not kernelcache.UNCACHED, (said[-3000:], kernelcache.UNCACHED)
    for name in OUTPUTS:
        assert (tmp_path / out / name).read_bytes() == (tmp_path / "cached" / name).read_bytes(), name


def test_the_fork_servers_warmer_compiles_nothing_without_a_cache(tmp_path: Path) -> None:
    """``auto``'s fork server loads kernels for its children only from numba's cache: with none, nothing (a compile
    there would keep a session's child waiting ~11 s), and it says once why."""
    code = "from bridge.core.kernelpreload import load_cached_kernels; print(load_cached_kernels())"
    r = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=_env(**LOCATOR_GONE), capture_output=True,
                       text=True, timeout=TIMEOUT_S, stdin=subprocess.DEVNULL)
    assert r.returncode == 0 and r.stdout == "False\n", r.stderr[-3000:]
    assert r.stderr.splitlines() == [CACHE_OFF_NOTE]


def _unshare_works() -> bool:
    if os.geteuid() != 0 or shutil.which("unshare") is None:
        return False
    probe = subprocess.run(["unshare", "-m", "true"], capture_output=True, timeout=60)
    return probe.returncode == 0


@pytest.mark.skipif(not _unshare_works(), reason="needs root and unshare -m (a read-only bind mount of the tree)")
def test_a_read_only_tree_and_no_home(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                      monkeypatch: pytest.MonkeyPatch) -> None:
    """The source tree read-only (its ``__pycache__`` unwritable, root too), no writable home: as a read-only
    install run by a user without a home, flying the PID law (the first way flies the bsst law)."""
    mount = f'mount --bind -o ro "{ROOT}" "{ROOT}" && exec "$@"'
    env = _env(BSST_KERNELS="compiled", HOME=NOWHERE)
    r = _sim(tmp_path, "off", env, prefix=("unshare", "-m", "sh", "-c", mount, "sh"), mission=SHORT_PID)
    _flew_uncached(r, tmp_path, "off", capsys, monkeypatch)
    assert 'controller = "pid"' in (tmp_path / "off" / "mission.toml").read_text()
