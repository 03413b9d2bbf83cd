"""Work in a forked child process, watched: its end known even when the code it ran ended the process.

In:  the work (a callable giving an exit status), the exceptions that are bad input (its one line goes back);
     SIGINT and SIGTERM (stops), SIGHUP, sent to this process
Out: :class:`Watched`: the work's exit status, or how the child ended before its work did (an exit status, a
     signal); bad input raised again here as :class:`~params.ConfigError`, Ctrl-C as KeyboardInterrupt

Why: ``bsst sim`` flies a law of the user's own in its process. The law's raise, ``SystemExit`` and
``os._exit()`` end the flight ``law_failed``, recorded (controller.law.CheckedLaw); but a law can still end the
process where Python cannot stop it: a signal (``os.kill(os.getpid(), ...)``), ``os.abort()``, a C extension's
``exit()`` or crash. In one process that would be the command's end, silent (exit 0 for an ``exit(0)``). As
``bsst sitl`` watches its controller child, the CLI then runs the flight in a child of its own and says how it
ended. The child inherits this process (its imports, stdout, stderr).

A stop (SIGINT, SIGTERM) sent to this process is passed on to the child as one SIGINT, and its flight ends on it,
recorded, while this process waits: as a Ctrl-C, whether it reached the whole process group (a terminal's Ctrl-C)
or this process alone (``kill -INT PID``, a script's ``Popen.send_signal``). Each stop passed on is a byte on a pipe
to the child, written before its SIGINT: the child takes a SIGINT (or SIGTERM) as a stop only when it finds such a
byte, so a Ctrl-C that reached both processes is one stop, not two (a second, raised while the first was being
recorded, would have cut the record); once this process has gone (the pipe's end), the child takes its own. Before,
this process ignored SIGINT, so one sent to it alone was never answered, and passed SIGTERM on as SIGTERM, which
killed the child with no summary.json. SIGHUP is passed on as it is: the child ends as this process would have.
"""

from __future__ import annotations

import json
import os
import signal
import sys
import threading
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, NoReturn

from bridge.core.interrupt import as_sigint
from bridge.nodes.process import exit_text
from bridge.nodes.report import BadInput, parse_line, to_line
from params import ConfigError

STOPS = (signal.SIGINT, signal.SIGTERM)  # passed on to the child as a Ctrl-C: its flight ends aborted, recorded
FORWARDED = (signal.SIGHUP,)  # passed on to the child as it is: it ends as this process would have


@dataclass(frozen=True)
class Watched:
    """How watched work ended: ``status`` its exit status (None: the child ended before its work did, ``how``:
    ``exited with status N`` or ``killed by NAME``: :func:`bridge.nodes.process.exit_text`), ``signalled`` a signal
    this process was sent and passed on."""

    status: int | None
    how: str = ""
    signalled: int | None = None


def run_watched(work: Callable[[], int], bad_input: tuple[type[BaseException], ...] = (ConfigError,), *,
                final: bool = False) -> Watched:
    """Run ``work`` in a forked child and wait for it (see the module docstring). ``final``: the child's result is
    the caller's, so once the child has ended this process ignores SIGINT (bridge.core.interrupt.ignore_sigint), set
    while the stops are still passed on: a stop is never lost before the fork (SIGINT ignored by the caller before
    this call lost one: the flight then flew to its end) nor raised after the child's end."""
    sys.stdout.flush()
    sys.stderr.flush()
    r, w = os.pipe()
    asked_r, asked_w = os.pipe()  # the stops passed on (see the module docstring)
    passes = threading.current_thread() is threading.main_thread()  # (only there can its handlers be set)
    # held from before the fork until each process has its handlers: a signal meanwhile waits for them, never lost
    mask = signal.pthread_sigmask(signal.SIG_BLOCK, {*STOPS, *FORWARDED}) if passes else None
    pid = os.fork()
    if pid == 0:
        os.close(r)
        os.close(asked_w)
        _child(work, bad_input, w, None if mask is None else (asked_r, mask))
    os.close(w)
    os.close(asked_r)
    os.set_blocking(asked_w, False)  # (a full pipe: stops enough are already unread)
    signalled: list[int] = []

    def forward(signum: int, frame: object) -> None:
        signalled.append(signum)
        os.kill(pid, signum)

    def stop(signum: int, frame: object) -> None:
        try:
            os.write(asked_w, b"\0")
        except OSError:  # full (stops enough unread), or the child has ended
            pass
        try:
            os.kill(pid, signal.SIGINT)
        except ProcessLookupError:  # waited for already (the handlers are put back just after): its end is known
            pass

    saved = {}
    if passes:
        saved = {s: signal.signal(s, forward) for s in FORWARDED} | {s: signal.signal(s, stop) for s in STOPS}
    try:
        if mask is not None:
            signal.pthread_sigmask(signal.SIG_SETMASK, mask)
        chunks = []
        while chunk := os.read(r, 1 << 16):
            chunks.append(chunk)
        _, status = os.waitpid(pid, 0)
    finally:
        for s, handler in saved.items():
            signal.signal(s, signal.SIG_IGN if final and s == signal.SIGINT else handler)
        os.close(r)
        os.close(asked_w)
    ended = _ended(b"".join(chunks))
    if isinstance(ended.get("bad_input"), BadInput):  # its refusal again, typed: said as it would have been here
        raise ended["bad_input"].error()
    if ended.get("interrupted"):
        raise KeyboardInterrupt
    if "status" in ended:
        return Watched(ended["status"])
    code = os.waitstatus_to_exitcode(status)
    return Watched(None, exit_text(code), signalled[0] if signalled else None)


def _ended(data: bytes) -> dict[str, Any]:
    """The child's end as it wrote it (:func:`_child`): ``{"status": N}``, ``{"interrupted": true}`` or ``{"bad_input":
    BadInput}`` (from its :class:`~bridge.nodes.report.BadInput` report, as a session's child writes it); ``{}`` when it
    wrote nothing whole (it ended before its work did)."""
    refused = parse_line(data.decode(errors="replace"))
    if isinstance(refused, BadInput):
        return {"bad_input": refused}
    try:
        ended = json.loads(data)
    except ValueError:
        return {}
    if not isinstance(ended, dict):
        return {}
    return ended


def _take_passed_stops(asked: int, mask: set[signal.Signals]) -> None:
    """In the child: SIGINT (and SIGTERM, taken as SIGINT) raise KeyboardInterrupt only when the parent has passed a
    stop on (a byte on ``asked``; all read: stops that arrived together are one), or once the parent has gone; then
    the signals held since the fork are let through (``mask``, the one before)."""
    os.set_blocking(asked, False)

    def on_sigint(signum: int, frame: object) -> None:
        try:
            os.read(asked, 4096)
        except BlockingIOError:  # not passed on: the signal reached this process itself; the parent's pass counts
            return
        raise KeyboardInterrupt  # a stop passed on, or the pipe's end (the parent has gone: its own stops count)

    signal.signal(signal.SIGINT, on_sigint)
    signal.signal(signal.SIGTERM, as_sigint)
    signal.pthread_sigmask(signal.SIG_SETMASK, mask)


def _child(work: Callable[[], int], bad_input: tuple[type[BaseException], ...], fd: int,
           asked: tuple[int, set[signal.Signals]] | None) -> NoReturn:
    """The child: the work, then its end to the parent as one JSON object (:func:`_ended`: its status; its bad input,
    its :class:`~bridge.nodes.report.BadInput` report's line; or a Ctrl-C); ``asked``: the pipe of the stops the parent
    passes on and the signal mask to put back (None: it passes none, this process takes its own)."""
    report: dict[str, Any] | str = {"status": 1}
    try:
        if asked is not None:
            _take_passed_stops(*asked)
        report = {"status": int(work())}
    except bad_input as exc:
        refused = exc if isinstance(exc, ConfigError) else ConfigError(str(exc))
        report = to_line(BadInput.of(refused))  # the report a session's child writes (bridge.cli.main): one way
    except KeyboardInterrupt:
        report = {"interrupted": True}
    except BaseException:  # a fault of bsst's own: its traceback, as one process would show it; exit 1
        traceback.print_exc()
    finally:
        try:
            sys.stdout.flush()
            sys.stderr.flush()
        except BaseException:  # (a closed stdout: the status stands)
            pass
        os.write(fd, (report if isinstance(report, str) else json.dumps(report)).encode())
        os._exit(0)

