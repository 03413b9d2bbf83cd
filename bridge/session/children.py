"""The child processes of a SITL session, and the instance lock that keeps sessions apart.

In:  a command line for ``python -m bridge`` and a log path; for :func:`instance_slot`, nothing; for
     :func:`hold_instances`, instance numbers
Out: the child's reports (its stdout, read without blocking, each line parsed by
     :func:`bridge.nodes.report.parse_line`; its refusal of its input among them), its exit, and the last line of
     its stderr (quoted to a person, never read); an instance
     number N (0-9) held exclusively (a ``flock`` on ``<tmp>/bsst-instance-N.lock``)

:func:`instance_slot` holds one of the ten PX4-style instance numbers (ports 14550 + N /
14560 + N) for as long as a block runs; :func:`hold_instances` holds the ones a session was told to fly, or
refuses them when another session holds them.
"""

from __future__ import annotations

import collections
import contextlib
import fcntl
import os
import random
import signal
import socket
import subprocess
import tempfile
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

from bridge.core.locks import Claims, lineage, take_flock
from bridge.mavlink.address import GCS_PORT, LINK_PORT
from bridge.nodes.forkserver import ForkedChild, start_child
from bridge.nodes.process import exit_text
from bridge.nodes.report import BadInput, Done, Report, Stats, parse_line
from params import ConfigError

READY_TIMEOUT_S = 30.0  # s for a child to start (Python, imports, bind) on a loaded machine
# s a child has, after SIGTERM, to close its records and exit before SIGKILL: a deadline on its exit, not a
# grace it always gets (a child exits within milliseconds of SIGTERM when it can). Generous, since a loaded
# machine delays a Python process's last writes by seconds; under a sweep worker's 10 s (WORKER_STOP_GRACE_S).
STOP_DEADLINE_S = 8.0


class ChildError(Exception):
    """A child process failed to start or died; the message names it."""


def check_port_free(port: int, flag: str) -> None:
    """ConfigError naming ``flag`` if UDP 127.0.0.1:``port`` is taken: a vehicle already runs
    there, so this session's could not start (said before any file is written)."""
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        s.bind(("127.0.0.1", port))
    except OSError as exc:
        raise ConfigError(f"{flag}: UDP 127.0.0.1:{port} is in use ({exc.strerror}); pick another instance") from None
    finally:
        s.close()


CHOSEN_PORTS_LOW = 20000  # the lowest port free_udp_port picks (above the instances' 14550 + N, 14560 + N)


def ephemeral_low() -> int:
    """The lowest port the kernel hands to sockets bound to port 0 (Linux: the first number of
    /proc/sys/net/ipv4/ip_local_port_range; its default elsewhere)."""
    try:
        return int(Path("/proc/sys/net/ipv4/ip_local_port_range").read_text().split()[0])
    except (OSError, ValueError, IndexError):
        return 32768


RECENT_PORTS = 256  # the choices of free_udp_port a process remembers (a fleet of ten takes ~40)
PORT_LOCKS = "bsst-ports.lock"  # in the temporary directory: byte N locked while a process may hand port N out
_recent: collections.deque[tuple[int, int]] = collections.deque()  # (lock file's descriptor or -1, port)
_recent_lock = threading.Lock()
_lock_files: dict[str, int] = {}  # path -> descriptor, open for the process's life (closing drops its locks)


def _port_lock_file() -> int:
    """This process's descriptor of ``<tmp>/bsst-ports.lock`` (opened once: closing any descriptor of a file drops
    every POSIX lock the process holds on it), or -1 where it cannot be opened (another user's file)."""
    path = os.path.join(tempfile.gettempdir(), PORT_LOCKS)
    fd = _lock_files.get(path)
    if fd is None:
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)
        except OSError:
            fd = -1
        _lock_files[path] = fd
    return fd


def _reserve(fd: int, port: int) -> bool:
    """Lock byte ``port`` of the port lock file (never waits): False if another process holds it."""
    if fd < 0:
        return True
    try:
        fcntl.lockf(fd, fcntl.LOCK_EX | fcntl.LOCK_NB, 1, port)
    except OSError:
        return False
    return True


def _remember(fd: int, port: int) -> None:
    """Add a choice to the recent ones; the oldest, forgotten, is released to other processes."""
    if len(_recent) >= RECENT_PORTS:
        old_fd, old = _recent.popleft()
        if old_fd >= 0:
            fcntl.lockf(old_fd, fcntl.LOCK_UN, 1, old)
    _recent.append((fd, port))


def free_udp_port() -> int:
    """A UDP port of 127.0.0.1 free now, for a child to bind next: the session names its controller's
    source port to the vehicle before either child starts.

    Picked at random below the kernel's ephemeral range and checked by binding it: a port from that range
    can be handed to any socket bound to port 0 (a ground station's, a test's, another session's) between
    this choice and the child's bind, which a full suite run met ("--source-port 56185: cannot bind (Address
    already in use)"); below it, only another explicit choice can take it. The kernel's choice where the
    range leaves no room below it.

    Never one this process handed out in its last :data:`RECENT_PORTS` choices, nor one another process on this
    machine still holds: a port chosen is free until its child binds it, so a second choice in that time, in this
    process or in another (the suite's two workers; sessions started side by side), could be the same number
    (a relay's listen and back ports once were, one session in some thousands; the CI's suite met "--source-port
    27523: cannot bind (Address already in use)" across its workers). Each choice holds byte N of
    ``<tmp>/bsst-ports.lock`` (``fcntl.lockf``: released when the process forgets the choice, or exits) and skips
    a port whose byte another process holds."""
    lo = ephemeral_low()
    with _recent_lock:  # (a fleet's sessions start in threads)
        fd = _port_lock_file()
        mine = {port for _, port in _recent}
        for _ in range(64 if lo > CHOSEN_PORTS_LOW else 0):
            port = random.randrange(CHOSEN_PORTS_LOW, lo)
            if port in mine or not _reserve(fd, port):
                continue
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
                try:
                    s.bind(("127.0.0.1", port))
                except OSError:
                    if fd >= 0:
                        fcntl.lockf(fd, fcntl.LOCK_UN, 1, port)
                    continue
            _remember(fd, port)
            return port
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Child:
    """One child process: its reports (stdout, read without blocking) and its exit."""

    def __init__(self, name: str, argv: list[str], log: Path, env: dict[str, str] | None = None) -> None:
        self.name = name
        read, write = os.pipe()
        try:
            with open(log, "wb") as err:
                self.proc: ForkedChild | subprocess.Popen[bytes] = start_child(argv, write, err.fileno(), env=env)
        except BaseException:
            os.close(read)
            raise
        finally:
            os.close(write)  # the child's now: its end of the pipe closes with it (our read then sees EOF)
        self.log = log
        self.fd = read
        os.set_blocking(self.fd, False)
        self._buf = b""
        self.eof = False
        self.stats: dict[str, Any] = {}  # its last stats report's
        self.done: Done | None = None  # the controller's outcome
        self.refused: BadInput | None = None  # its command's refusal of its input (exit 2), as it reported it

    @property
    def pid(self) -> int:
        return self.proc.pid

    def close(self) -> None:
        """Close our end of its stdout (after its last reports are read)."""
        os.close(self.fd)

    def reports(self) -> list[Report]:
        """The reports in the complete lines written since the last call (other lines are skipped)."""
        out: list[Report] = []
        while True:
            try:
                data = os.read(self.fd, 65536)
            except BlockingIOError:
                break
            if not data:
                self.eof = True
                break
            self._buf += data
        *full, self._buf = self._buf.split(b"\n")
        for raw in full:
            report = parse_line(raw.decode(errors="replace"))
            if report is None:
                continue
            if isinstance(report, Stats):
                self.stats = report.values
            elif isinstance(report, Done):
                self.done = report
            elif isinstance(report, BadInput):
                self.refused = report
            out.append(report)
        return out

    def exit_text(self) -> str:
        return exit_text(self.proc.returncode)

    def last_error(self) -> str:
        """The last line of the child's stderr (a traceback's end, or whatever it wrote last), quoted to a person as
        it is, never read: a refusal is its report (:attr:`refused`)."""
        try:
            lines = [ln for ln in self.log.read_text(errors="replace").splitlines() if ln.strip()]
        except OSError:
            return ""
        return lines[-1].strip() if lines else ""


def stop_children(children: Sequence[Child]) -> tuple[list[tuple[Child, Report]], list[Child]]:
    """SIGTERM each of ``children`` (in order), wait for each to exit (its records closed), SIGKILL whatever is left
    at the deadline (:data:`STOP_DEADLINE_S`); close them. Returns their last words (what each wrote, in the order
    given) and the children killed."""
    for c in children:
        if c.proc.poll() is None:
            try:
                c.proc.send_signal(signal.SIGTERM)
            except ProcessLookupError:
                pass
    deadline = time.monotonic() + STOP_DEADLINE_S
    last_words, killed = [], []
    for c in children:
        try:
            c.proc.wait(timeout=max(deadline - time.monotonic(), 0.01))
        except subprocess.TimeoutExpired:
            c.proc.kill()
            c.proc.wait()
            killed.append(c)
        last_words += [(c, r) for r in c.reports()]
        c.close()
    return last_words, killed


def _ports_free(n: int) -> bool:
    """Whether instance N's two UDP ports, 127.0.0.1:14550 + N (its ground station's) and 14560 + N (its
    vehicle's), can be bound now."""
    for port in (GCS_PORT + n, LINK_PORT + n):
        try:
            check_port_free(port, "instance")
        except ConfigError:
            return False
    return True


INSTANCE_LOCK = "bsst-instance-{}.lock"  # in the temporary directory: flock'ed by the session flying instance N
# the instances this process's sessions fly: a second session of it (another thread's sitl(instance=N)) is refused
_FLOWN_HERE = Claims()


def instance_lock_path(n: int) -> str:
    """``<tmp>/bsst-instance-N.lock``: the file whose ``flock`` holds instance N."""
    return os.path.join(tempfile.gettempdir(), INSTANCE_LOCK.format(n))


def _lock_instance(n: int) -> tuple[int | None, int | None]:
    """Take instance N's lock (never waits): (its descriptor, None), or (None, the pid holding it: None where
    unknown). Closing the descriptor releases it, as the process's end does, however it ends (the kernel's)."""
    return take_flock(instance_lock_path(n), f"instance {n}")


@contextlib.contextmanager
def hold_instances(numbers: Sequence[int], flag: Callable[[int], str]) -> Iterator[None]:
    """Hold instances ``numbers`` (0-9) for as long as the block runs (a session's life): the ``flock`` of
    :func:`instance_slot`, so that two sessions (two users', a user's beside the test suite's) never fly one
    instance's ports and system id at once. One held by another session is refused before anything is
    written: ConfigError naming ``flag(n)``, the instance and the holder's pid. One held by this process or by
    one that started it (a sweep's or a test's :func:`instance_slot` around the session it starts) is its own:
    flown without a second lock; but not one another session of this process flies (another thread's), refused
    as another's. Released when the block ends, or by the kernel when the process dies."""
    fds: list[int] = []
    _FLOWN_HERE.claim(numbers, lambda n, thread: f"{flag(n)}: instance {n} is in use by another session of "  # type: ignore[arg-type]
                                                 f"this process (pid {os.getpid()}, thread {thread!r}); pick another "
                                                 "instance")
    try:
        for n in numbers:
            for _ in range(2):  # (a holder gone between the lock refused and /proc/locks read: once more)
                fd, holder = _lock_instance(n)
                if fd is not None or holder is not None:
                    break
            if fd is not None:
                fds.append(fd)
            elif holder is None or holder not in lineage():
                by = f" (pid {holder})" if holder is not None else f" ({instance_lock_path(n)} is locked)"
                raise ConfigError(f"{flag(n)}: instance {n} is in use by another session{by}; pick another "
                                  "instance")
        yield
    finally:
        for fd in fds:
            os.close(fd)  # closing releases the lock
        _FLOWN_HERE.release(numbers)


@contextlib.contextmanager
def instance_slot(timeout_s: float = 600.0) -> Iterator[int]:
    """Hold instance number N (0-9) of this machine exclusively while the block runs: one whose ports are free
    too (a ground station listening on 14550 + N, or a process of an earlier holder still closing its socket, would
    take this session's telemetry or refuse its bind: that slot is passed over).

    An advisory ``flock`` on ``<tmp>/bsst-instance-N.lock``, the lock every session flying an instance holds
    (:func:`hold_instances`: ``bsst sitl --instance N``, a fleet's instances, ``bsst vehicle``'s, ``bsst
    sweep``'s), so sessions started by tests, sweeps, scripts or people side by side never share ports 14550 + N /
    14560 + N; a session this process starts in the slot (in it, or as its child) flies in it. Raises
    TimeoutError when all ten stay taken.

    The highest free number first: the low ones are those a person names (``bsst sitl`` flies instance 0 by
    default, whose 14550 is a ground station's default port; the README's example takes 1), and a session that
    names its instance is refused while an automatic pick holds it.
    """
    deadline = time.monotonic() + timeout_s
    while True:
        for n in range(9, -1, -1):
            fd, _ = _lock_instance(n)
            if fd is None:
                continue
            if not _ports_free(n):  # held by a program outside the locks (or one still closing): another slot
                os.close(fd)
                continue
            try:
                yield n
            finally:
                os.close(fd)  # closing releases the lock
            return
        if time.monotonic() > deadline:
            raise TimeoutError(f"no free SITL instance (0-9) within {timeout_s:g} s")
        time.sleep(0.05)  # all ten held by other sessions: look again shortly


def catch_stop_signals(sessions: Sequence[Any]) -> Callable[[], None]:
    """While sessions run (one, or a fleet's: :class:`bridge.session.session.Session`), Ctrl-C (SIGINT) and
    SIGTERM only set each one's ``interrupted``;
    a session checks it between whole steps, so no file is left half-written by an exception raised in the
    middle of a write. Main thread only (signals go there). Returns what restores the handlers before."""
    if threading.current_thread() is not threading.main_thread():
        return lambda: None

    def handler(signum: int, frame: Any) -> None:
        for s in sessions:
            s.interrupted = True

    old = {sig: signal.signal(sig, handler) for sig in (signal.SIGINT, signal.SIGTERM)}

    def restore() -> None:
        for sig, h in old.items():
            signal.signal(sig, h)

    return restore
