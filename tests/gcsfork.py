"""The test kit's ground-station scripts started warm: a fork server that has imported pymavlink, MAVProxy and MAVSDK
once forks each ``python -c SCRIPT ARGS`` or ``python FILE ARGS`` (docs/testing.md, "Ground stations started warm").

In:  (client, :func:`start_script`) a Python command line without the interpreter (``["-c", SCRIPT, *ARGS]`` or
     ``[FILE, *ARGS]``), the script's stdin, stdout and stderr (file descriptors), its working directory and
     environment; (server, ``python -m tests.gcsfork FD PADDING``) the socket its owner made, open as FD
Out: a running script (:class:`bridge.nodes.forkserver.ForkedChild`, or a :class:`subprocess.Popen` where it is
     started cold) with the ``Popen`` calls the tests make: ``pid``, ``poll``, ``wait``, ``send_signal``, ``kill``

Why: a cold ground station spends its first ~0.3 CPU-s importing pymavlink (a MAVProxy ~0.57, a MAVSDK script
~0.08) before it sends a byte; the suite starts dozens. The product's fork server (bridge.nodes.forkserver) does
the forking, the descriptors, the exit status and the lifetimes; this module gives it what to import and how to
run a script, as CPython would: ``sys.argv``, ``sys.path[0]``, a fresh ``__main__``, the non-daemon threads
waited for at the end, an uncaught Ctrl-C ending the process by SIGINT (status -2). Each script is its own process
(own pid, session, sockets, exit status). Started cold instead (exec'd, as before) where ``BSST_FORK_SERVER=0``,
where the command line is neither ``-c SCRIPT`` nor a file (``-m MODULE``, ``-u``, any other interpreter option:
:func:`warm_enough`), where any of the script's ``PYTHON*`` variables (``PYTHONPATH``, ``PYTHONIOENCODING``,
``PYTHONDONTWRITEBYTECODE``, ...) is not this process's (the server's interpreter read its own at its start: its
``sys.path``, its streams' encoding would not be the script's), or where the server cannot start or answer.
"""

from __future__ import annotations

import builtins
import gc
import os
import runpy
import signal
import subprocess
import sys
import threading
import traceback
import types
from collections.abc import Sequence

from bridge.nodes import forkserver as fs
from bridge.nodes.process import die_with_parent

SERVER = "tests.gcsfork"
_server: fs.Server | None = None
_lock = threading.Lock()


def _the_server() -> fs.Server:
    """This process's ground-station server, started on first use (again if it died, or in a fork of its owner)."""
    global _server
    with _lock:
        if _server is None or not _server.alive():
            _server = fs.Server.start(SERVER)
        return _server


def start_script(args: Sequence[str], stdout: int, stderr: int, *, stdin: int | None = None,
                 cwd: str | None = None, env: dict[str, str] | None = None,
                 ) -> fs.ForkedChild | subprocess.Popen[bytes]:
    """``python ARGS`` as a child of its own session (``start_new_session``): stdout and stderr the descriptors
    given, stdin the one given (default: empty), in ``cwd`` with ``env`` (default: this process's); forked warm,
    or exec'd as :class:`subprocess.Popen` would (module docstring)."""
    cwd = os.getcwd() if cwd is None else os.fspath(cwd)
    env = dict(os.environ) if env is None else dict(env)
    if fs.forking(env) and warm_enough(args, env):
        try:
            with open(os.devnull, "rb") as null:
                fds = (null.fileno() if stdin is None else stdin, stdout, stderr)
                return _the_server().spawn(list(args), fds, cwd, env)
        except OSError:
            pass  # exec'd instead: the same script, only slower to start
    return subprocess.Popen([sys.executable, *args], stdin=subprocess.DEVNULL if stdin is None else stdin,
                            stdout=stdout, stderr=stderr, cwd=cwd, env=env, start_new_session=True,
                            preexec_fn=die_with_parent)


def _python_vars(env: dict[str, str] | os._Environ[str]) -> dict[str, str]:
    return {k: v for k, v in env.items() if k.startswith("PYTHON")}


def warm_enough(args: Sequence[str], env: dict[str, str]) -> bool:
    """Whether ``python ARGS`` in ``env`` runs forked as it would exec'd: a ``-c`` script or a file (another option,
    ``-m``, ``-u``, ..., or none at all, is the interpreter's own to read), and the interpreter's start-up
    environment (every ``PYTHON*`` variable: PYTHONPATH, PYTHONIOENCODING, PYTHONDONTWRITEBYTECODE, ...) this
    process's, the server's, which read its own at its start and would not read the script's."""
    runs = args[:1] == ["-c"] or bool(args) and not args[0].startswith("-")
    return runs and _python_vars(env) == _python_vars(os.environ)


# -- the server ------------------------------------------------------------------------------------------------------
PYMAVLINK = ("pymavlink.mavutil", "pymavlink.mavwp", "pymavlink.mavparm", "pymavlink.dialects.v20.common",
             "pymavlink.dialects.v20.ardupilotmega", "pymavlink.dialects.v20.all")
MAVSDK = ("mavsdk", *(f"mavsdk.plugins.{p}" for p in ("action", "telemetry", "mission_raw", "mission", "param",
                                                      "geofence", "failure", "info")))
MAVPROXY = (*PYMAVLINK, "pymavlink.dialects.v10.all", "MAVProxy.mavproxy", *(f"MAVProxy.modules.mavproxy_{m}" for m in (
    "link", "log", "signing", "wp", "rally", "fence", "ftp", "param", "relay", "tuneopt", "arm", "mode",
    "calibration", "rc", "auxopt", "misc", "cmdlong", "battery", "terrain", "output", "adsb", "layout")))


def kinds(argv: Sequence[str]) -> list[tuple[str, ...]]:
    """What the script ``python ARGV`` imports at its start, as far as its command line tells: MAVProxy (its
    ``mavproxy.py``); pymavlink where a ``-c`` script's text names it or a ``mavlogdump.py`` is run; MAVSDK where a
    ``-c`` script's text names it."""
    if argv and os.path.basename(argv[0]) == "mavproxy.py":
        return [MAVPROXY]
    text = " ".join(argv[:2]) if argv[:1] == ["-c"] else ""
    named = [os.path.basename(a) for a in argv[:3]]
    return [k for k, said in ((PYMAVLINK, "pymavlink" in text or "mavlogdump.py" in named), (MAVSDK, "mavsdk" in text))
            if said]


class Warmer:
    """Before the server forks a script: the imports of its kind (:func:`kinds`), the first time one comes (a
    worker that never starts a MAVProxy never pays for it), shared with every later child."""

    def __init__(self) -> None:
        self.imported: set[tuple[str, ...]] = set()

    def __call__(self, argv: Sequence[str], env: object) -> None:
        for kind in kinds(argv):
            if kind not in self.imported:
                self.imported.add(kind)
                for name in kind:
                    try:
                        __import__(name)
                    except Exception:  # noqa: BLE001  (a script that needs it fails in its own process, as cold)
                        pass
                gc.freeze()  # shared with every later child, never copied into one (bridge.cli.forkserver)


def _print_traceback(exc: BaseException) -> None:
    """The traceback CPython prints for ``exc``: from the script's frame on (not this module's)."""
    tb = exc.__traceback__.tb_next if exc.__traceback__ is not None else None
    traceback.print_exception(type(exc), exc, tb)


def run_child(argv: list[str]) -> int:
    """In the forked child: run ``python ARGV`` as CPython would (module docstring); its exit status."""
    fs.drop_inherited()  # the child's own connection to this server: a script forks no bsst child here
    mavutil = sys.modules.get("pymavlink.mavutil")
    if mavutil is not None:  # what its import does with this environment (the server imported it with its own)
        os.environ.setdefault("MAVLINK_DIALECT", "all")
        mavutil.set_dialect(os.environ["MAVLINK_DIALECT"])
    main = types.ModuleType("__main__")
    main.__builtins__ = builtins  # type: ignore[attr-defined]
    sys.modules["__main__"] = main
    fs.show_command_line([sys.executable, *argv])
    try:
        if argv[:1] == ["-c"]:
            sys.argv, sys.path[0] = ["-c", *argv[2:]], ""
            exec(compile(argv[1], "<string>", "exec"), main.__dict__)  # noqa: S102  (the script, as ``python -c``)
        else:
            sys.argv, sys.path[0] = list(argv), os.path.dirname(os.path.abspath(argv[0]))
            runpy.run_path(argv[0], run_name="__main__")
    except SystemExit:
        threading._shutdown()  # type: ignore[attr-defined]  (CPython's own wait for non-daemon threads at its end)
        raise
    except KeyboardInterrupt as exc:  # CPython: the traceback, its end, and then SIGINT to itself (status -2)
        _print_traceback(exc)
        threading._shutdown()  # type: ignore[attr-defined]
        fs.child_exit()
        for stream in (sys.stdout, sys.stderr):
            stream.flush()
        signal.signal(signal.SIGINT, signal.SIG_DFL)
        os.kill(os.getpid(), signal.SIGINT)
        raise
    except BaseException as exc:  # noqa: BLE001  (as CPython: the traceback on stderr, status 1)
        _print_traceback(exc)
        threading._shutdown()  # type: ignore[attr-defined]
        return 1
    threading._shutdown()  # type: ignore[attr-defined]
    return 0


if __name__ == "__main__":
    fs.show_command_line([sys.executable, "-m", SERVER, sys.argv[1]])  # not the padding
    fs.serve(int(sys.argv[1]), run_child, Warmer())
