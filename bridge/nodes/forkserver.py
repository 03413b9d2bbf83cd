"""Children started warm: a fork server that has imported the nodes once forks each ``bsst`` child.

In:  a command line for ``python -m bridge`` (``["vehicle", MISSION, ...]``), the child's stdin, stdout and stderr
     (file descriptors), its working directory and environment
Out: a running child (:class:`ForkedChild`, or a :class:`subprocess.Popen` where no server runs) with the
     ``Popen`` calls a session uses: ``pid``, ``poll``, ``wait``, ``send_signal``, ``kill``, ``returncode``

Why: a child started with ``exec`` spends ~0.35 s of CPU importing Python, numpy, pymavlink and the bridge before
it does anything (docs/figures.md, "Children started warm"). A session starts two or three children; a test
suite or a script that flies many sessions starts hundreds. The server pays the imports once per process that
flies sessions; each child is then a ``fork`` of it (a few milliseconds), the same code with the same
arguments, its own process (own pid, session, files, exit status), as PX4's and ArduPilot's SITL launchers
start theirs from a ready binary.

- :func:`start_child` forks through this process's server (started on first use, one per process, shared by
  threads), and falls back to ``exec`` when the server cannot start or answer, or when
  ``BSST_FORK_SERVER=0`` (:data:`ENV`).
- The server (``python -m bridge.cli.forkserver FD``: :func:`serve`) speaks over a Unix ``SOCK_SEQPACKET``
  pair: a request is one JSON message (``id``, ``argv``, ``cwd``, ``env``) carrying the three descriptors
  (``SCM_RIGHTS``); it answers ``{"id", "pid"}`` (or ``{"id", "error"}``), and ``{"exit": pid, "rc": rc}``
  when a child ends (``rc`` as ``Popen.returncode``: negative for a signal).
- Each child is given a connection of its own to the server that forked it: a child that starts children
  (a ``bsst sitl`` started warm) forks them there too, instead of starting (and importing) a server of its own.
- Lifetimes: the server exits when its owner's socket closes (the owning process exited, however it ended); each
  child gets SIGTERM when the server goes (``PR_SET_PDEATHSIG``), as an ``exec``'d child does when its
  launcher dies; when a child's own connection closes, the children forked for it get SIGTERM. The server
  opens a pidfd on each child as it forks it and hands it over with its answer: the owner waits and signals
  through it, so a pid reused after its child ended (a child can end, and be reaped, before the owner reads
  the answer) is never waited for nor signalled.
"""

from __future__ import annotations

import atexit
import ctypes
import gc
import importlib.util
import io
import json
import os
import select
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
import traceback
import types
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from bridge.nodes.process import die_with_parent

ENV = "BSST_FORK_SERVER"  # "0": every child exec'd (the fork server never started)
SERVER_MODULE = "bridge.cli.forkserver"
ANSWER_TIMEOUT_S = 30.0  # s for the server to answer a request: its start-up (imports) included, on a loaded machine
# CPU s a server must have spent in ANSWER_TIMEOUT_S for its client to wait that long again: it is working (compiling
# kernels with numba's cache off, ~4-11 s of CPU that a loaded machine stretches past 30 s: bridge.core.kernelpreload)
BUSY_CPU_S = 1.0
BUSY_WAIT_MAX_S = 300.0  # s: the longest a client waits for a server that keeps working (one spinning is hung too)
_MAX_MESSAGE = 1 << 20
TITLE_ROOM = 4096  # bytes the server's padding argument reserves for its children's command lines


class ServerGone(OSError):
    """The fork server did not answer (it could not start, or it died)."""


class ForkedChild:
    """A child forked by the server, with the ``Popen`` calls a session makes. Its exit status comes from the
    server (the child's parent); its exit itself is seen on a pidfd, which also carries the signals."""

    def __init__(self, server: Server, pid: int, pidfd: int) -> None:
        self.pid = pid
        self.returncode: int | None = None
        self.args = ["fork", str(pid)]
        self._server = server
        self._pidfd = pidfd  # the server's, opened as it forked: this very process, even once reaped

    def poll(self) -> int | None:
        return self.wait(0.0, raising=False)

    def wait(self, timeout: float | None = None, raising: bool = True) -> int | None:
        """The exit status once the child has ended; None (``raising=False``) or ``subprocess.TimeoutExpired``
        if it has not within ``timeout`` s (None: wait as long as it takes)."""
        if self.returncode is not None:
            return self.returncode
        ready, _, _ = select.select([self._pidfd], [], [], timeout)
        if not ready:
            if raising:
                raise subprocess.TimeoutExpired(self.args, timeout or 0.0)
            return None
        self.returncode = self._server.exit_status(self.pid)
        self._close()
        return self.returncode

    def _close(self) -> None:
        if self._pidfd >= 0:
            os.close(self._pidfd)
            self._pidfd = -1

    def __del__(self) -> None:  # one never waited for (a caller that gave up on it): its pidfd, not its process
        self._close()

    def send_signal(self, sig: int) -> None:
        if self.poll() is None:
            try:
                signal.pidfd_send_signal(self._pidfd, sig)
            except ProcessLookupError:  # it ended since poll(): as Popen, nothing to signal
                pass

    def terminate(self) -> None:
        self.send_signal(signal.SIGTERM)

    def kill(self) -> None:
        self.send_signal(signal.SIGKILL)


class Server:
    """This process's end of one fork server: requests out, answers and exit statuses in, under one lock
    (a fleet's sessions start their children from threads)."""

    def __init__(self, sock: socket.socket, proc: subprocess.Popen[bytes] | None) -> None:
        self.sock = sock
        self.proc = proc  # None: the server this process was forked by (we are one of its clients)
        self.owner = os.getpid()
        self.pid = proc.pid if proc is not None else os.getppid()  # the server's (it forked us)
        self.lock = threading.Lock()
        self.next_id = 0
        self.answers: dict[int, dict[str, Any]] = {}
        self.exits: dict[int, int] = {}
        self.children_cpu_s = 0.0  # s, user + system, of the children that have ended and been heard of
        self.gone = False

    @classmethod
    def start(cls, module: str = SERVER_MODULE) -> Server:
        """A server process of this process's own: ``python -m MODULE FD PADDING`` (the test kit runs one of its
        own for its ground-station scripts, tests/gcsfork.py)."""
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        try:
            proc = subprocess.Popen(
                [sys.executable, "-m", module, str(theirs.fileno()), " " * TITLE_ROOM],
                pass_fds=(theirs.fileno(),), stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                start_new_session=True)  # its stderr is ours: it says numba's cache-off note where it compiles first
        except BaseException:
            ours.close()
            raise
        finally:
            theirs.close()
        return cls(ours, proc)

    def alive(self) -> bool:
        return not self.gone and self.owner == os.getpid() and (self.proc is None or self.proc.poll() is None)

    def cpu_s(self) -> float:
        """CPU seconds (user + system) of the server itself (its imports; not counted for a server this process
        shares with the one that forked it) and of the children it forked for us heard to have ended."""
        own = self._own_cpu_s() if self.proc is not None else 0.0
        with self.lock:
            return own + self.children_cpu_s

    def _own_cpu_s(self) -> float:
        """CPU seconds (user + system) the server process itself has spent so far (0 where /proc cannot say)."""
        try:
            with open(f"/proc/{self.pid}/stat") as f:
                fields = f.read().rpartition(")")[2].split()
            return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")  # utime, stime (proc(5))
        except (OSError, IndexError, ValueError):
            return 0.0

    def spawn(self, argv: Sequence[str], fds: Sequence[int], cwd: str, env: dict[str, str]) -> ForkedChild:
        with self.lock:
            self.next_id += 1
            rid = self.next_id
            request = json.dumps({"id": rid, "argv": list(argv), "cwd": cwd, "env": env}).encode()
            try:
                socket.send_fds(self.sock, [request], list(fds))
            except OSError as exc:
                self.gone = True
                raise ServerGone(f"fork server: {exc}") from exc
            answer = self._until(lambda: self.answers.pop(rid, None), ANSWER_TIMEOUT_S)
        if "pid" not in answer or len(answer.get("fds", ())) != 1:
            for fd in answer.get("fds", ()):
                os.close(fd)
            raise ServerGone(f"fork server: {answer.get('error', 'no pid')}")
        return ForkedChild(self, int(answer["pid"]), answer["fds"][0])

    def exit_status(self, pid: int) -> int:
        """The exit status of ``pid``, which has ended (the server sends it on reaping it, at once); a child
        whose server died first was ended by the server's death (PR_SET_PDEATHSIG): -SIGTERM."""
        with self.lock:
            try:
                return self._until(lambda: self.exits.pop(pid, None), ANSWER_TIMEOUT_S)
            except ServerGone:
                return -signal.SIGTERM

    def _until(self, found: Callable[[], Any], timeout_s: float) -> Any:
        """Read the server's messages (holding the lock) until ``found()`` gives something, and give it. A server
        silent for ``timeout_s`` is given as long again while it spends CPU (:data:`BUSY_CPU_S`): it is working, not
        hung (a compile before it forks, on a loaded machine), up to :data:`BUSY_WAIT_MAX_S` in all."""
        deadline = time.monotonic() + timeout_s
        last = deadline - timeout_s + max(BUSY_WAIT_MAX_S, timeout_s)
        busy = self._own_cpu_s()
        while (got := found()) is None:
            left = deadline - time.monotonic()
            if left <= 0 and not self.gone and deadline < last and (spent := self._own_cpu_s()) >= busy + BUSY_CPU_S:
                deadline = min(time.monotonic() + timeout_s, last)
                busy, left = spent, deadline - time.monotonic()
            if self.gone or left <= 0:
                self.gone = True
                raise ServerGone("fork server: no answer")
            ready, _, _ = select.select([self.sock], [], [], left)
            if ready:
                self._read_one()
        return got

    def _read_one(self) -> None:
        data, fds, _, _ = socket.recv_fds(self.sock, _MAX_MESSAGE, 1)
        if not data:
            self.gone = True
            return
        msg = json.loads(data)
        msg["fds"] = fds
        if "exit" in msg:
            self.exits[int(msg["exit"])] = int(msg["rc"])
            self.children_cpu_s += float(msg["cpu_s"])
        else:
            self.answers[int(msg["id"])] = msg


_server: Server | None = None
_servers: list[Server] = []  # every one this process used (their CPU time: forked_cpu_s)
_server_lock = threading.Lock()
_inherited: tuple[int, int] | None = None  # (pid, fd): a forked child's own connection to the server that forked it


def _the_server() -> Server:
    """This process's fork server: in a child forked by one, that same server (over the connection it was
    forked with); otherwise one of its own, started on first use (again if it died, or in a forked copy of
    the owner)."""
    global _server, _inherited
    with _server_lock:
        if _server is None or not _server.alive():
            if _inherited is not None and _inherited[0] == os.getpid():
                _server = Server(socket.socket(fileno=_inherited[1]), None)
            else:
                _server = Server.start()
            _inherited = None  # used once: if it fails, a server of our own
            _servers.append(_server)
        return _server


def forked_cpu_s() -> float:
    """CPU seconds (user + system) spent by this process's fork servers and the children they forked, ended ones
    (``os.times()`` does not see them: they are the server's children, not ours). For benchmarks."""
    return sum(s.cpu_s() for s in _servers)


def drop_inherited() -> None:
    """In a forked child that forks no child of its own through its server (tests.gcsfork's scripts): close its
    connection to the server that forked it."""
    global _inherited
    if _inherited is not None:
        os.close(_inherited[1])
        _inherited = None


def forking(env: Mapping[str, str]) -> bool:
    """Whether children are forked: not with ``BSST_FORK_SERVER=0`` in ``env``, nor without pidfds (Linux 5.3+)."""
    return env.get(ENV, "1") != "0" and hasattr(os, "pidfd_open")


def warm() -> bool:
    """Start this process's fork server now, so that its imports overlap the caller's own preparation (a
    no-op when children are exec'd). Whether a server runs, to fork the caller's children."""
    if forking(os.environ):
        try:
            return _the_server().alive()
        except OSError:
            pass
    return False


def start_child(argv: Sequence[str], stdout: int, stderr: int, *, stdin: int | None = None, cwd: str | None = None,
                env: dict[str, str] | None = None) -> ForkedChild | subprocess.Popen[bytes]:
    """``python -m bridge ARGV`` as a child of its own session: stdout and stderr the descriptors given, stdin
    the one given (default: empty), in ``cwd`` with ``env`` (default: this process's); forked by the fork
    server, or exec'd if there is none (module docstring)."""
    cwd = os.getcwd() if cwd is None else os.fspath(cwd)
    env = dict(os.environ) if env is None else dict(env)
    if forking(env):
        try:
            with open(os.devnull, "rb") as null:
                fds = (null.fileno() if stdin is None else stdin, stdout, stderr)
                return _the_server().spawn(argv, fds, cwd, env)
        except OSError:
            pass  # exec'd instead: the same child, only slower to start
    return subprocess.Popen([sys.executable, "-m", "bridge", *argv], stdin=subprocess.DEVNULL if stdin is None
                            else stdin, stdout=stdout, stderr=stderr, cwd=cwd, env=env, start_new_session=True,
                            preexec_fn=die_with_parent)


# -- the server ------------------------------------------------------------------------------------------------------
def serve(fd: int, run: Callable[[list[str]], int],
          before_fork: Callable[[Sequence[str], Mapping[str, str]], None] | None = None) -> None:
    """Serve fork requests on the socket ``fd`` until it closes; each child runs ``run(argv)`` (the CLI's main)
    and exits with its status. The modules a child needs are imported by the caller first; ``before_fork(argv,
    env)``, if given, is called in the server before each child is forked (what it loads, every later child
    starts with).

    Each child is also given a connection of its own to this server, which becomes a client like the owner: a
    ``bsst sitl`` forked here forks its vehicle and controller here too, instead of starting a server of its
    own. When a client's connection closes (it ended, however), the children forked for it get SIGTERM, as
    they would from PR_SET_PDEATHSIG when a server of the client's own went with it."""
    root = socket.socket(fileno=fd)
    clients: dict[int, socket.socket] = {fd: root}
    live: dict[int, tuple[int, socket.socket | None]] = {}  # pidfd -> (pid, the client it was forked for)
    # what is here now is shared with every child, never collected (nor copied) in one; not collected first (a full
    # collection, ~0.015 CPU-s a server, found only the parser's help formatters, some 90 objects, to free)
    gc.freeze()
    while True:
        ready, _, _ = select.select([*clients, *live], [], [])
        for r in ready:
            if r in live:
                _reap(r, live.pop(r))
                continue
            sock = clients.get(r)
            if sock is None:
                continue  # dropped this round
            try:
                data, fds, _, _ = socket.recv_fds(sock, _MAX_MESSAGE, 3)
            except ConnectionError:
                data, fds = b"", []
            if not data:
                if sock is root:
                    return  # the owner is gone: so are we, and our children with us (PR_SET_PDEATHSIG)
                _drop(clients.pop(r), live)
                continue
            try:
                req = json.loads(data)
                if before_fork is not None:
                    before_fork(req.get("argv") or [], req.get("env") or {})
                _answer(req, fds, sock, run, clients, live)
            finally:
                for f in fds:
                    os.close(f)


def _answer(req: dict[str, Any], fds: list[int], sock: socket.socket, run: Callable[[list[str]], int],
            clients: dict[int, socket.socket], live: dict[int, tuple[int, socket.socket | None]]) -> None:
    """Fork the child ``req`` asks ``sock``'s client for, with a connection of its own; answer its pid and pidfd."""
    ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
    try:
        pid = _fork(req, fds, run, [*clients, *live, ours.fileno()], theirs.fileno())
    except OSError as exc:
        ours.close()
        _send(sock, {"id": req["id"], "error": str(exc)})
        return
    finally:
        theirs.close()
    pidfd = os.pidfd_open(pid)  # before the child can end and be reaped (only this loop reaps)
    clients[ours.fileno()] = ours
    live[pidfd] = (pid, sock)
    _send(sock, {"id": req["id"], "pid": pid}, pidfd)


def _reap(pidfd: int, child: tuple[int, socket.socket | None]) -> None:
    """A child has ended: reap it, tell the client it was forked for (if still connected) its status and CPU."""
    pid, client = child
    os.close(pidfd)
    _, status, usage = os.wait4(pid, 0)
    if client is not None:
        _send(client, {"exit": pid, "rc": os.waitstatus_to_exitcode(status), "cpu_s": usage.ru_utime + usage.ru_stime})


def _drop(client: socket.socket, live: dict[int, tuple[int, socket.socket | None]]) -> None:
    """A client's connection closed: SIGTERM the children forked for it (reaped as they end, told to no one)."""
    for pidfd, (pid, owner) in list(live.items()):
        if owner is client:
            live[pidfd] = (pid, None)
            try:
                signal.pidfd_send_signal(pidfd, signal.SIGTERM)
            except ProcessLookupError:
                pass
    client.close()


def child_exit() -> None:
    """What an exec'd ``python -m bridge`` runs at its end and ``os._exit`` skips: the exit handlers the command
    registered (``atexit``, last first; the server's own were cleared at the fork), such as the removal of the
    temporary folder matplotlib was given where the home is unwritable (bridge.record.mplsetup: a forked ``bsst
    sim`` left one behind each time), then multiprocessing's (:func:`_multiprocessing_exit`), registered first in a
    cold process and so run last."""
    atexit._run_exitfuncs()  # (CPython's own call at shutdown: errors are printed, and the next handler runs)
    _multiprocessing_exit()


def _multiprocessing_exit() -> None:
    """What multiprocessing's own children run before their ``os._exit`` (``BaseProcess._bootstrap``): its exit
    finalizers, registered in this process only (each runs in the process that made it). Among them the removal of
    the folder its fork server's socket lives in (``<tmp>/pymp-*``): a sweep or margin run as a forked child left
    one behind each time. Nothing where the command never imported multiprocessing."""
    util = sys.modules.get("multiprocessing.util")
    if util is not None:
        util._exit_function()


def _as_python_m_bridge() -> None:
    """Make ``__main__`` the module ``python -m bridge`` runs (not the server's), as a cold child has it: what
    looks at it (multiprocessing's start of a sweep's workers) sees the same thing either way."""
    spec = importlib.util.find_spec("bridge.__main__")
    main = types.ModuleType("__main__")
    main.__spec__, main.__package__ = spec, "bridge"
    if spec is not None:
        main.__file__, main.__loader__ = spec.origin, spec.loader
    sys.modules["__main__"] = main


def show_command_line(words: Sequence[str]) -> None:
    """Show ``words`` as this process's command line (``/proc/PID/cmdline``, ``ps``, ``pkill -f``), written over
    the area of the server's own arguments, which its padding argument (:data:`TITLE_ROOM`) made long enough; cut
    to fit. Linux; a no-op where ``/proc/self/stat`` does not say where that area is."""
    try:
        with open("/proc/self/stat") as f:
            fields = f.read().rpartition(")")[2].split()
        start, end = int(fields[45]), int(fields[46])  # arg_start, arg_end: proc(5), fields 48 and 49
    except (OSError, IndexError, ValueError):
        return
    room = end - start
    if room < 2:
        return
    title = " ".join(words).encode()[: room - 1]
    # a last byte that is not NUL tells the kernel the area was rewritten: it then reads up to the first NUL
    ctypes.memmove(start, title + b"\0" + b" " * (room - len(title) - 1), room)


def _send(sock: socket.socket, msg: dict[str, Any], fd: int | None = None) -> None:
    try:
        socket.send_fds(sock, [json.dumps(msg).encode()], [] if fd is None else [fd])
    except OSError:  # the owner is gone; the loop sees it next
        pass


def _fork(req: dict[str, Any], fds: list[int], run: Callable[[list[str]], int], close: list[int],
          connection: int) -> int:
    """Fork the child: it closes the server's descriptors ``close``, keeps ``connection`` (its own to the
    server, :func:`_the_server`), takes ``fds`` as stdin, stdout and stderr, and runs ``run(argv)``."""
    global _inherited
    if len(fds) != 3:
        raise OSError(f"a request carries stdin, stdout and stderr: {len(fds)} descriptors given")
    pid = os.fork()
    if pid:
        return pid
    rc = 1
    try:  # the child: as `python -m bridge ARGV` would start, without the imports
        os.setsid()
        atexit._clear()  # the server's exit handlers are the server's; the child runs its own at its end (child_exit)
        die_with_parent()
        for f in close:
            os.close(f)
        _inherited = (os.getpid(), connection)
        for target, f in enumerate(fds):
            os.dup2(f, target)
            os.close(f)
        os.chdir(req["cwd"])
        os.environ.clear()
        os.environ.update(req["env"])
        tempfile.tempdir = None  # the server's choice is cached: the child's own TMPDIR, as in a process exec'd
        for sig in (signal.SIGTERM, signal.SIGCHLD, signal.SIGHUP):
            signal.signal(sig, signal.SIG_DFL)
        signal.signal(signal.SIGINT, signal.default_int_handler)
        unbuffered = bool(os.environ.get("PYTHONUNBUFFERED"))
        sys.stdout = io.TextIOWrapper(io.FileIO(1, "w", closefd=False), write_through=unbuffered)
        sys.stderr = io.TextIOWrapper(io.FileIO(2, "w", closefd=False), errors="backslashreplace",
                                      line_buffering=True, write_through=unbuffered)
        sys.stdin = io.TextIOWrapper(io.FileIO(0, "r", closefd=False))
        argv = list(req["argv"])
        sys.argv = [os.path.join(os.path.dirname(os.path.dirname(__file__)), "__main__.py"), *argv]
        _as_python_m_bridge()
        show_command_line([sys.executable, "-m", "bridge", *argv])  # what ps shows for an exec'd child
        rc = run(argv)
    except SystemExit as exc:
        rc = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
        if exc.code is not None and not isinstance(exc.code, int):
            print(exc.code, file=sys.stderr)
    except BaseException:  # as Python would: the traceback on stderr, status 1
        traceback.print_exc()
        rc = 1
    finally:  # the command is over: a Ctrl-C now must not raise out of here into a copy of the server's loop
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        child_exit()
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (OSError, ValueError):
                pass
        os._exit(rc)
