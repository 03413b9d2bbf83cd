"""Helpers for the tests that start real processes: read their status lines with deadlines.

No sleeps to hope something happened: every wait is on an event (a line, a file row, a
process exit) with a deadline, and fails with what was seen so far.
"""

from __future__ import annotations

import os
import selectors
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
ENV = {**os.environ, "MAVLINK20": "1"}


class Proc:
    """A child process whose stdout is read line by line without blocking."""

    def __init__(self, argv: list[str], cwd: Path | None = None, stdin: int | None = subprocess.DEVNULL) -> None:
        self.argv = argv
        self.p = subprocess.Popen(argv, cwd=cwd, stdin=stdin, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                  env=ENV, start_new_session=True)
        os.set_blocking(self.p.stdout.fileno(), False)  # type: ignore[union-attr]
        self._buf = b""
        self.lines: list[str] = []

    @classmethod
    def bsst(cls, *args: str, cwd: Path | None = None) -> Proc:
        return cls([sys.executable, "-m", "bridge", *args], cwd=cwd)

    def _read(self) -> None:
        while True:
            try:
                data = os.read(self.p.stdout.fileno(), 65536)  # type: ignore[union-attr]
            except BlockingIOError:
                return
            if not data:
                return
            self._buf += data
            *full, self._buf = self._buf.split(b"\n")
            self.lines += [ln.decode(errors="replace") for ln in full]

    def wait_line(self, pred: Callable[[str], bool], timeout: float = 20.0) -> str:
        """The first line (seen so far or to come) that satisfies ``pred``."""
        deadline = time.monotonic() + timeout
        sel = selectors.DefaultSelector()
        sel.register(self.p.stdout, selectors.EVENT_READ)  # type: ignore[arg-type]
        seen = 0
        try:
            while True:
                self._read()
                for line in self.lines[seen:]:
                    if pred(line):
                        return line
                seen = len(self.lines)
                left = deadline - time.monotonic()
                if left <= 0 or (self.p.poll() is not None and not sel.select(0)):
                    raise AssertionError(f"no such line within {timeout} s from {self.argv[-3:]}; "
                                         f"exit {self.p.poll()}; got:\n" + "\n".join(self.lines[-30:]))
                sel.select(min(left, 0.2))
        finally:
            sel.close()

    def stop(self, timeout: float = 5.0) -> int:
        """SIGTERM, wait (SIGKILL after ``timeout``), read what is left; the exit status."""
        if self.p.poll() is None:
            self.p.send_signal(signal.SIGTERM)
        try:
            self.p.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.p.kill()
            self.p.wait()
        self._read()
        return self.p.returncode


def csv_rows(path: Path) -> int:
    """Complete data rows of a part file so far (0 if it does not exist yet)."""
    try:
        return max(path.read_bytes().count(b"\n") - 1, 0)
    except FileNotFoundError:
        return 0


def shown(line: str) -> str:
    """A child's event line as a person reads it, ``kind: text [by ...]``, whether the line is JSON or text
    (bridge.nodes.report); any other line as it is."""
    from bridge.nodes.report import Event, parse_line  # lazy: only the tests that read events need it

    report = parse_line(line)
    if not isinstance(report, Event):
        return line
    return f"{report.kind}: {report.text}" + (report.by.suffix if report.by is not None else "")
