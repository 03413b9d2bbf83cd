"""Advisory locks between bsst processes (``flock`` on a file in the temporary directory), and the claims of one
process's threads.

In:  a lock file's path; the keys a session flies or writes (an instance number, a run directory's real path)
Out: a held lock's descriptor, or the pid holding it (from /proc/locks); this process's lineage (pids); a refusal
     (:class:`params.ConfigError`) of a key another thread of this process holds

A ``flock`` is the process's: the kernel releases it when the process ends, however it ends (SIGKILL, a crash), so
no stale lock is left to remove; and every thread of the process holds it alike, so which thread of a process
claimed what is kept here (:class:`Claims`). Used by the instances a session flies (bridge.session.children) and by
the run directory a run writes (bridge.record.outlock).
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import threading
from collections.abc import Callable, Hashable, Iterable

from params import ConfigError


def take_flock(path: str, what: str) -> tuple[int | None, int | None]:
    """Take the lock of file ``path`` (created if need be; never waits): (its descriptor, None), or (None, the pid
    holding it: None where unknown). Closing the descriptor releases it. ``what`` names it in an error."""
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        with contextlib.suppress(OSError):  # (a umask of 077 made it 0600: no other user could open it to lock)
            os.fchmod(fd, 0o644)
    except PermissionError:  # another user's file (0644, or a sticky /tmp's protected_regular): read-only locks too
        try:
            fd = os.open(path, os.O_RDONLY)
        except OSError as exc:
            raise ConfigError(f"{what}: cannot open its lock file {path} ({exc.strerror})") from None
    except OSError as exc:
        raise ConfigError(f"{what}: cannot open its lock file {path} ({exc.strerror})") from None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        holder = lock_holder(fd)
        os.close(fd)
        return None, holder
    return fd, None


def lock_holder(fd: int) -> int | None:
    """The pid holding a ``flock`` on ``fd``'s file, as /proc/locks lists it (None: not listed, no /proc)."""
    st = os.fstat(fd)
    try:
        with open("/proc/locks") as locks:
            return lock_holder_in(locks, st.st_dev, st.st_ino)
    except OSError:
        return None


def lock_holder_in(lines: Iterable[str], dev: int, ino: int) -> int | None:
    """The pid holding a ``flock`` on the file of device ``dev`` and inode ``ino`` (its ``fstat``'s) in the
    ``lines`` of /proc/locks (``N: FLOCK ADVISORY WRITE pid maj:min:inode start end``, hex device), None if none
    does. Where no lock is listed on that device (btrfs: a subvolume's files stat on a device of their own, not the
    one /proc/locks lists), the inode alone, if one process alone holds a ``flock`` on an inode of that number."""
    device = f"{os.major(dev):02x}:{os.minor(dev):02x}"
    by_inode: set[int] = set()
    for line in lines:
        fields = line.split()
        if len(fields) < 6 or fields[1] != "FLOCK":  # ("->" lines: waiters)
            continue
        on, _, inode = fields[5].rpartition(":")
        if inode != str(ino) or not fields[4].isdigit():
            continue
        if on == device:
            return int(fields[4])
        by_inode.add(int(fields[4]))
    return by_inode.pop() if len(by_inode) == 1 else None


def lineage() -> set[int]:
    """This process's pid and its ancestors' (their parents' from /proc/PID/stat, up to init)."""
    pids, pid = {os.getpid()}, os.getppid()
    while pid > 1 and pid not in pids:
        pids.add(pid)
        try:
            with open(f"/proc/{pid}/stat") as stat:
                pid = int(stat.read().rpartition(")")[2].split()[1])
        except (OSError, ValueError, IndexError):
            break
    return pids


class Claims:
    """What this process's threads hold (key -> pid, the thread's name; a forked child's copy is not its own): a
    ``flock`` stands for the whole process, so a second claim of a key in it (another thread's session) is refused
    here."""

    def __init__(self) -> None:
        self._held: dict[Hashable, tuple[int, str]] = {}
        self._lock = threading.Lock()

    def claim(self, keys: Iterable[Hashable], refusal: Callable[[Hashable, str], str]) -> None:
        """Claim ``keys`` for the calling thread, or ConfigError ``refusal(key, holder thread's name)`` for the
        first one another claim of this process holds (then none is claimed)."""
        keys = list(keys)
        pid = os.getpid()
        with self._lock:
            for k in keys:
                held = self._held.get(k)
                if held is not None and held[0] == pid:
                    raise ConfigError(refusal(k, held[1]))
            self._held.update((k, (pid, threading.current_thread().name)) for k in keys)

    def release(self, keys: Iterable[Hashable]) -> None:
        with self._lock:
            for k in keys:
                self._held.pop(k, None)
