"""The run directory a run writes, held for the run's life: one writer per ``--out DIR`` at a time.

In:  the ``--out`` path a command was given (None: an automatic ``runs/<UTC time>-<name>``, new, never shared)
Out: the directory held while the block runs (an ``flock`` on ``/tmp/bsst-out-<hash of its real path>.lock``,
     removed after; none where no temporary directory is writable), or a :class:`params.ConfigError` naming the
     flag, the path and the run holding it (its pid; another thread's of this process by name)

Two runs given one ``--out`` (``--overwrite`` on both) wrote into it at once: the second cleared the first's
files and the directory ended up mixing the two runs' files (a user's tour: the first's summary.json and
events.log, the second's mission.toml and trace.csv). Now the second is refused before it clears anything.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import os
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, TypeVar

from bridge.core.locks import Claims, take_flock
from bridge.record.runlog import check_out_dir
from params import ConfigError

R = TypeVar("R")
OUT_LOCK = "bsst-out-{}.lock"  # in the temporary directory, by the sha256 of the run directory's real path
_WRITING = Claims()  # the run directories this process's runs write (another thread's run is refused)


def lock_dir() -> str | None:
    """Where the run directories' lock files are: ``/tmp`` (one place whatever ``TMPDIR`` says, so that every run on
    the machine meets there), else the temporary directory if it is not the working directory (Python's last
    resort, which differs between runs); None if there is none (then no hold is taken)."""
    if os.path.isdir("/tmp") and os.access("/tmp", os.W_OK | os.X_OK):
        return "/tmp"
    try:
        d = tempfile.gettempdir()
    except (OSError, FileNotFoundError):
        return None
    return None if os.path.realpath(d) == os.path.realpath(os.getcwd()) else d


def out_lock_path(real: str, where: str) -> str:
    """The lock file, in directory ``where`` (:func:`lock_dir`), of the run directory whose real path is ``real``."""
    return os.path.join(where, OUT_LOCK.format(hashlib.sha256(real.encode()).hexdigest()[:24]))


@contextlib.contextmanager
def out_held(out: str | Path | None, flag: str = "--out") -> Iterator[None]:
    """Hold run directory ``out`` while the block runs (nothing for None): another run writing it is refused,
    before anything is cleared or written. Released, and its lock file removed, when the block ends (by the kernel
    if the process dies: the file is then left, empty, for the next run to take)."""
    if out is None:
        yield
        return
    if not isinstance(out, str | os.PathLike):  # a Python caller's out=5: named, not os.fspath's bare TypeError
        raise TypeError(f"out: expected a directory's path, got {out!r}"[:200])
    check_out_dir(Path(out))  # (a path that cannot be a run directory: said as run_dir says it, not traced)
    try:
        real = str(Path(out).resolve())
    except (OSError, RuntimeError, ValueError) as exc:
        raise ConfigError(f"{flag} {out}: cannot reach it ({exc})") from None
    where = lock_dir()
    if where is None:  # no writable temporary directory: the run goes on unheld, as before there was a hold
        yield
        return
    _WRITING.claim([real], lambda _k, thread: f"{flag} {out}: in use by another run of this process (pid "
                                              f"{os.getpid()}, thread {thread!r}); give another directory")
    try:
        path = out_lock_path(real, where)
        fd = _take(path, flag, out)
        sweep_stale(where)
        try:
            yield
        finally:
            with contextlib.suppress(OSError):
                os.unlink(path)  # unlinked while held: a run that opened it before sees it gone
            os.close(fd)
    finally:
        _WRITING.release([real])


def holding_out(run: Callable[..., R]) -> Callable[..., R]:
    """``run`` (a command's whole run, given its directory as the keyword ``out``) with that directory held
    (:func:`out_held`) for as long as it runs."""
    @functools.wraps(run)
    def held(*args: Any, out: str | Path | None = None, **keywords: Any) -> R:
        with out_held(out):
            return run(*args, out=out, **keywords)
    return held


STALE_S = 3600.0  # s: a lock file this old that nobody holds is a killed run's, removed by the next run
STALE_SWEPT = 16  # at most this many removed by one run (each a lock tried, never waited for)


def sweep_stale(where: str, now: float | None = None) -> int:
    """Remove the lock files of run directories left by runs killed (SIGKILL ends a run before it removes its own),
    older than :data:`STALE_S` and held by nobody (each taken first, then unlinked while held: a run that opened it
    meanwhile sees it gone and takes a new one, :func:`_take`); how many were removed. Best effort, never raises."""
    now = time.time() if now is None else now
    removed = 0
    try:
        names = [n for n in os.listdir(where) if n.startswith("bsst-out-") and n.endswith(".lock")]
    except OSError:
        return 0
    for name in names:
        if removed >= STALE_SWEPT:
            break
        path = os.path.join(where, name)
        try:
            if now - os.stat(path).st_mtime < STALE_S:
                continue
            fd, _ = take_flock(path, "a stale run directory lock")
        except (OSError, ConfigError):
            continue
        if fd is None:
            continue  # held: a live run's
        try:
            if os.stat(path).st_ino == os.fstat(fd).st_ino:
                os.unlink(path)
                removed += 1
        except OSError:
            pass
        finally:
            os.close(fd)
    return removed


def check_out_free(out: str | Path | None, flag: str = "--out") -> None:
    """Refuse ``out`` if another run writes it now (a command's check before it starts anything)."""
    with out_held(out, flag):
        pass


def _take(path: str, flag: str, out: str | Path) -> int:
    """The lock of file ``path``, held (its descriptor), or ConfigError naming its holder."""
    for _ in range(8):  # (its file removed by the run that held it, between our open and our lock: take the new one)
        fd, holder = take_flock(path, f"{flag} {out}")
        if fd is None:
            by = f" (pid {holder})" if holder is not None else ""
            raise ConfigError(f"{flag} {out}: in use by another run{by}; give another directory, or wait for it to "
                              "end")
        try:
            if os.stat(path).st_ino == os.fstat(fd).st_ino:
                return fd
        except FileNotFoundError:
            pass
        os.close(fd)
    raise ConfigError(f"{flag} {out}: its lock file {path} keeps being replaced; give another directory")
