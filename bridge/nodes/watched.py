"""Work in a forked child process, watched: its end known even when the code it ran ended the process.

In:  the work (a callable giving an exit status), the exceptions that are bad input (its one line goes back)
Out: :class:`Watched`: the work's exit status, or how the child ended before its work did (an exit status, a
     signal); bad input raised again here as :class:`~params.ConfigError`, Ctrl-C as KeyboardInterrupt

Why: ``bsst sim`` flies a law of the user's own in its process. The law's raise, ``SystemExit`` and
``os._exit()`` end the flight ``law_failed``, recorded (controller.law.CheckedLaw); but a law can still end the
process where Python cannot stop it: a signal (``os.kill(os.getpid(), ...)``), ``os.abort()``, a C extension's
``exit()`` or crash. In one process that would be the command's end, silent (exit 0 for an ``exit(0)``). As
``bsst sitl`` watches its controller child, the CLI then runs the flight in a child of its own and says how it
ended. The child inherits this process (its imports, stdout, stderr); Ctrl-C reaches both, and the child's
flight ends on it, recorded, while this process waits; SIGTERM and SIGHUP are passed on to the child.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from typing import NoReturn

from params import ConfigError

FORWARDED = (signal.SIGTERM, signal.SIGHUP)  # passed on to the child: it ends as this process would have


@dataclass(frozen=True)
class Watched:
    """How watched work ended: ``status`` its exit status (None: the child ended before its work did, ``how``:
    ``exit status N`` or ``killed by signal NAME``), ``signalled`` a signal this process was sent and passed on."""

    status: int | None
    how: str = ""
    signalled: int | None = None


def run_watched(work: Callable[[], int], bad_input: tuple[type[BaseException], ...] = (ConfigError,)) -> Watched:
    """Run ``work`` in a forked child and wait for it (see the module docstring)."""
    sys.stdout.flush()
    sys.stderr.flush()
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:
        os.close(r)
        _child(work, bad_input, w)
    os.close(w)
    signalled: list[int] = []

    def forward(signum: int, frame: object) -> None:
        signalled.append(signum)
        os.kill(pid, signum)

    saved = {}
    if threading.current_thread() is threading.main_thread():  # (only its handlers can be set)
        saved = {s: signal.signal(s, forward) for s in FORWARDED}
        saved[signal.SIGINT] = signal.signal(signal.SIGINT, signal.SIG_IGN)  # the child's to answer
    try:
        chunks = []
        while chunk := os.read(r, 1 << 16):
            chunks.append(chunk)
        _, status = os.waitpid(pid, 0)
    finally:
        os.close(r)
        for s, handler in saved.items():
            signal.signal(s, handler)
    report = b"".join(chunks).decode("utf-8", "replace")
    if report.startswith("E"):
        raise ConfigError(report[1:])
    if report == "I":
        raise KeyboardInterrupt
    if report:
        return Watched(int(report))
    code = os.waitstatus_to_exitcode(status)
    how = f"killed by signal {_signal_name(-code)}" if code < 0 else f"exit status {code}"
    return Watched(None, how, signalled[0] if signalled else None)


def _child(work: Callable[[], int], bad_input: tuple[type[BaseException], ...], fd: int) -> NoReturn:
    """The child: the work, then its status (``E`` and its bad input's line, ``I`` for Ctrl-C) to the parent."""
    report = "1"
    try:
        report = str(int(work()))
    except bad_input as exc:
        report = f"E{exc}"
    except KeyboardInterrupt:
        report = "I"
    except BaseException:  # a fault of bsst's own: its traceback, as one process would show it; exit 1
        traceback.print_exc()
    finally:
        try:
            sys.stdout.flush()
            sys.stderr.flush()
        except BaseException:  # (a closed stdout: the status stands)
            pass
        os.write(fd, report.encode())
        os._exit(0)


def _signal_name(signum: int) -> str:
    try:
        return signal.Signals(signum).name
    except ValueError:
        return str(signum)
