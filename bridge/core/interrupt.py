"""Ctrl-C at a safe point: the first and second SIGINT as futures that a wait on a pool's futures includes.

In:  SIGINT, while :func:`sigint_futures` is entered in the main thread; SIGTERM, within :func:`sigterm_as_sigint`
Out: :class:`Interrupts`: a :class:`~concurrent.futures.Future` completed (its result: the signal number) at the
     first SIGINT, another at the second (each exact once the block has ended); :func:`wait_or_interrupt`,
     concurrent.futures' ``wait`` that raises KeyboardInterrupt once it has returned; :func:`sigint_deferred`:
     SIGINT raised only inside :meth:`Deferred.raising` blocks (where a search flies), noted elsewhere (its
     bookkeeping); :func:`ignore_sigint`:
     a command whose result is final ignores SIGINT from there on (its write, its summary, the interpreter's exit);
     :func:`sigterm_as_sigint`: SIGTERM taken as a Ctrl-C (:func:`as_sigint`, the handler); :func:`sigint_held`: the
     KeyboardInterrupt of a SIGINT held (:class:`Held`) while work that must not be cut runs (a flight's record)

Why:
- Python raises KeyboardInterrupt between any two bytecodes of the main thread, so also inside
  concurrent.futures' ``wait()`` while it takes the futures' locks one by one (``_AcquireFutures``, not
  exception-safe): the locks taken so far stay held, and the pool's shutdown then waits for ever on a worker
  that needs one. A `bsst sweep --jobs 1` stopped with Ctrl-C just after a progress line hung 3 times in 40
  that way under load.
- Python runs its own handler only when the main thread next runs bytecode. A SIGINT that lands just before
  the main thread blocks on a lock (after its last bytecode, before the futex) is handled by the C handler,
  and the Python handler waits until the lock is released: a Ctrl-C while a sweep's first cell was starting
  was taken only when that cell ended, 27–42 s later, 5 times in 60 under load.
- So a thread here reads the bytes that CPython's C handler writes to the wakeup fd
  (:func:`signal.set_wakeup_fd`) at the very signal, whichever thread it lands on, and completes the futures:
  the waiting code wakes at once and raises where no lock is held.
- Read once the block has ended (its reader joined), both futures hold every SIGINT that came in it; inside it,
  the first may still wait for the reader (a check in the main thread just after the handler ran can miss it). A
  sweep checked it there after its last cell and lost that Ctrl-C (said by nobody; 3 in 9 runs of
  tests/test_sweep_resume.py): checked after the block now. Python's own handler does not complete the futures:
  it runs in the main thread, also inside concurrent.futures.wait while that holds the futures' (reentrant) locks
  between its look at which are done and its waiter's install, and a future completed there never woke that wait
  (a sweep's Ctrl-C held up by its longest cell). Only a SIGINT that meets it after the wakeup fd is put back, as
  the block ends, is completed by it, then.
- The two futures live for the whole block, so the second Ctrl-C is counted wherever it lands (it used to raise
  KeyboardInterrupt anywhere in the code between the first's handling and the wait for the second). From the
  second on, the previous handler is back: a third Ctrl-C interrupts at once, as Python would.

Outside the main thread, or where SIGINT is ignored (a sweep's workers), nothing is installed and the futures
never complete.

A search of many rounds (``bsst margin``) keeps its results only if Ctrl-C never lands in its bookkeeping between
two rounds: :func:`sigint_deferred` raises it only while a round flies (where a flight in this process takes it
at once, and a pool's wait takes it as above), and notes one that lands elsewhere, for the next round to raise at
its start. Once the result is final, :func:`ignore_sigint`: Python's exit restores SIGINT's default action (death
by the signal, status 130 in a shell) before it has finished, unless SIGINT is ignored (CPython's
``_PySignal_Fini`` keeps an ignored signal ignored); a ``bsst margin`` sent SIGINT just after it had written its
complete margin.json died that way.

A SIGTERM (a scheduler's, a script's ``Popen.terminate``) asks what a Ctrl-C asks, so :func:`sigterm_as_sigint`
makes it one: its handler raises SIGINT in this process, which then meets whatever SIGINT meets there (Python's
KeyboardInterrupt, the futures above, nothing once :func:`ignore_sigint` has run). Before, a ``bsst sim`` sent
SIGTERM died at once, with no summary.json.
"""

from __future__ import annotations

import _signal  # signal's C half, which signal.signal and signal.getsignal wrap (Held.released: see _swap_sigint)
import os
import signal
import threading
from collections.abc import Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, Future, InvalidStateError, wait
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

_STOP = b"\0"  # not a signal number: ends the reading thread


def _previous_handler() -> Any:
    """SIGINT's handler, to be put back after a block that installs its own; None where nothing is to be installed:
    outside the main thread, or where SIGINT is ignored (a sweep's workers). One installed from C comes back as
    Python's own (what a later Ctrl-C should meet)."""
    previous = signal.getsignal(signal.SIGINT)
    if threading.current_thread() is not threading.main_thread() or previous is signal.SIG_IGN:
        return None
    return signal.default_int_handler if previous is None else previous


@dataclass(frozen=True)
class Interrupts:
    """The first and the second SIGINT of a :func:`sigint_futures` block."""

    first: Future = field(default_factory=Future)
    second: Future = field(default_factory=Future)


@contextmanager
def sigint_futures() -> Iterator[Interrupts]:
    """Within the block, SIGINT completes ``first``, then ``second``, instead of raising KeyboardInterrupt; a
    third raises it (the previous handler is back from the second on)."""
    got = Interrupts()
    previous = _previous_handler()
    if previous is None:
        yield got
        return
    read_end, write_end = os.pipe()
    os.set_blocking(write_end, False)  # set_wakeup_fd's condition (the C handler must never block)
    handled = 0

    def on_sigint(signum: int, frame: Any) -> None:  # runs late (see Why): the futures do not wait for it
        nonlocal handled
        handled += 1  # (two SIGINTs before it runs are one call: the reader's count decides too)
        if handled >= 2 or got.second.done():
            signal.signal(signal.SIGINT, previous)

    def read() -> None:
        pending = [got.first, got.second]
        while pending:
            byte = os.read(read_end, 1)
            if byte == _STOP or not byte:
                return
            if byte[0] == signal.SIGINT:
                _complete(pending.pop(0))

    reader = threading.Thread(target=read, name="sigint-watch", daemon=True)
    reader.start()
    previous_fd = None
    try:  # the wakeup fd first: a SIGINT between the two is counted (and raises, as before the block)
        previous_fd = signal.set_wakeup_fd(write_end, warn_on_full_buffer=False)
        signal.signal(signal.SIGINT, on_sigint)
        yield got
    finally:
        if previous_fd is not None:
            signal.set_wakeup_fd(previous_fd)
        signal.signal(signal.SIGINT, previous)
        try:
            os.write(write_end, _STOP)  # ends the reader if it still reads
        except BlockingIOError:  # the pipe is full: the reader has stopped reading (both futures done)
            pass
        reader.join()
        os.close(read_end)
        os.close(write_end)
        if handled and not got.first.done():  # its handler ran after the wakeup fd was put back: no byte (Why)
            _complete(got.first)


def _complete(stop: Future) -> None:
    """``stop`` completed with SIGINT, unless it is already (the block's end completes a first the reader did not)."""
    try:
        stop.set_result(signal.SIGINT)
    except InvalidStateError:
        pass


def wait_or_interrupt(futures: Iterable[Future], interrupted: Future) -> set[Future]:
    """The futures of ``futures`` done once the first of them (or ``interrupted``) is; KeyboardInterrupt
    if ``interrupted`` is done."""
    done, _ = wait([*futures, interrupted], return_when=FIRST_COMPLETED)
    if interrupted.done():
        raise KeyboardInterrupt
    return done


@dataclass
class Deferred:
    """SIGINT within a :func:`sigint_deferred` block: KeyboardInterrupt inside :meth:`raising`, noted elsewhere
    (``pending``), and raised at the next :meth:`raising`'s start."""

    pending: bool = False
    _raising: bool = False

    @contextmanager
    def raising(self) -> Iterator[None]:
        """Within the block a SIGINT raises KeyboardInterrupt (one noted before raises it at once, here)."""
        if self.pending:
            raise KeyboardInterrupt
        self._raising = True
        try:
            yield
        finally:
            self._raising = False

    def on_sigint(self, signum: int, frame: Any) -> None:
        self.pending = True
        if self._raising:
            raise KeyboardInterrupt


@contextmanager
def sigint_deferred() -> Iterator[Deferred]:
    """Within the block, SIGINT raises only inside the yielded :class:`Deferred`'s ``raising()`` blocks; the
    previous handler is back after it. Outside the main thread, or where SIGINT is ignored, nothing is installed
    (``pending`` stays false)."""
    got = Deferred()
    previous = _previous_handler()
    if previous is None:
        yield got
        return
    signal.signal(signal.SIGINT, got.on_sigint)
    try:
        yield got
    finally:
        signal.signal(signal.SIGINT, previous)


@dataclass
class Held:
    """The stops a :func:`sigint_held` block held: ``pending`` once one came (the one who acts on it clears it)."""

    pending: bool = False
    _previous: Any = None  # the handler the block chains to (None: nothing installed)

    def on_sigint(self, signum: int, frame: Any) -> None:
        try:
            if not callable(self._previous):  # (SIG_DFL: the stop would have ended the process)
                raise KeyboardInterrupt
            self._previous(signum, frame)
        except KeyboardInterrupt:
            self.pending = True

    @contextmanager
    def released(self) -> Iterator[None]:
        """Within the block (a ``yield``: the caller's code, another flight's, runs) SIGINT meets the previous
        handler again; held again after it."""
        if self._previous is None:
            yield
            return
        _sigint_now()  # (a call: a SIGINT that came before it is handled here, held)
        _swap_sigint(self._previous)
        try:
            yield
        finally:
            _swap_sigint(self.on_sigint)


def _sigint_now() -> Any:
    """SIGINT's handler, as ``signal.getsignal(SIGINT)`` reads it but for its enum conversion; a Python call, so that a
    SIGINT already come is handled at its start by the handler installed, as at ``signal.getsignal``'s."""
    return _signal.getsignal(signal.SIGINT)


def _swap_sigint(handler: Any) -> None:
    """``signal.signal(SIGINT, handler)`` without its enum conversions of the handlers (a Python call, as that one:
    a SIGINT already come is handled at its start by the handler it replaces). :meth:`Held.released` swaps twice a
    control period of a flight's end landing: 18 us a period with ``signal``'s, 3 with these (bridge/loop.py's
    ~600 periods of a landing and its disarm wait, ~10 ms of every offline flight's CPU). ``signal.SIG_DFL`` (an enum
    that signal's half takes and its C half refuses: a caller's default handler) goes as its number."""
    _signal.signal(signal.SIGINT, int(handler) if isinstance(handler, signal.Handlers) else handler)


@contextmanager
def sigint_held(got: Held | None = None) -> Iterator[Held]:
    """Within the block (work that must not be cut; around each ``yield`` in it, :meth:`Held.released`), SIGINT
    meets the previous handler as before, but a KeyboardInterrupt it raises is held (``pending`` in ``got``, or a
    new :class:`Held`), not raised; the previous handler is back after it. Outside the main thread, or where SIGINT
    is ignored, nothing is installed. A chain, not a stand-in: a handler that passes stops on, counts them or
    ignores some (a watched flight's child) still decides what is a stop."""
    got = Held() if got is None else got
    previous = _previous_handler()
    if previous is None:
        yield got
        return
    got._previous = previous
    signal.signal(signal.SIGINT, got.on_sigint)
    try:
        yield got
    finally:
        signal.getsignal(signal.SIGINT)  # (a call: a SIGINT that came meanwhile is handled here, held, before the swap)
        signal.signal(signal.SIGINT, previous)
        got._previous = None


def ignore_sigint() -> None:
    """From here on this process ignores SIGINT (in the main thread; elsewhere nothing changes): a command's result
    is final, and neither its summary nor the interpreter's exit may be cut by a Ctrl-C (see the module's docstring).
    ``bsst``'s ``main`` puts an in-process caller's handler back when the command returns."""
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)


def as_sigint(signum: int, frame: Any) -> None:
    """A signal handler: the signal is taken as a Ctrl-C (SIGINT raised in this process, handled as SIGINT is)."""
    signal.raise_signal(signal.SIGINT)


class _TermOnly:
    """SIGINT's handler in a :func:`sigterm_as_sigint` block entered with SIGINT ignored (a script's ``bsst sim &``:
    a shell without job control starts it so): a SIGINT is a Ctrl-C (KeyboardInterrupt) only when a SIGTERM raised
    it, else ignored, as it was."""

    def __init__(self) -> None:
        self.term = False

    def on_sigterm(self, signum: int, frame: Any) -> None:
        self.term = True
        signal.raise_signal(signal.SIGINT)

    def __call__(self, signum: int, frame: Any) -> None:
        if self.term:
            self.term = False
            raise KeyboardInterrupt


@contextmanager
def sigterm_as_sigint() -> Iterator[None]:
    """Within the block SIGTERM is a Ctrl-C (:func:`as_sigint`); the previous handlers are back after it. Outside
    the main thread, or where SIGTERM is ignored, nothing is installed. Where SIGINT is ignored (a script's
    background job), a SIGTERM is a Ctrl-C all the same and a SIGINT stays ignored (:class:`_TermOnly`): SIGINT
    raised by the SIGTERM met SIG_IGN, and the flight flew on to its end, exit 0, until the third wave's forty-first
    session. Once :func:`ignore_sigint` has run in the block (the result is final) both are ignored."""
    previous = signal.getsignal(signal.SIGTERM)
    if threading.current_thread() is not threading.main_thread() or previous is signal.SIG_IGN:
        yield
        return
    term_only = _TermOnly() if signal.getsignal(signal.SIGINT) is signal.SIG_IGN else None
    if term_only is not None:
        signal.signal(signal.SIGINT, term_only)
    signal.signal(signal.SIGTERM, as_sigint if term_only is None else term_only.on_sigterm)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, signal.SIG_DFL if previous is None else previous)
        if term_only is not None and signal.getsignal(signal.SIGINT) is term_only:
            signal.signal(signal.SIGINT, signal.SIG_IGN)


__all__ = ["Deferred", "Held", "Interrupts", "as_sigint", "ignore_sigint", "sigint_deferred", "sigint_futures",
           "sigint_held", "sigterm_as_sigint", "wait_or_interrupt"]
