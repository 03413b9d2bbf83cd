"""``bsst``: the command line. ``python -m bridge`` is the same.

In:  argv (``sys.argv[1:]`` by default), and the mission, sweep and key files it names
Out: the command's work and its summary on stdout; an exit status; bad input as one line
     ``bsst: ...`` on stderr, and from a command whose stdout is its reports, a session's children (``bsst vehicle``,
     ``controller``, ``relay``, as their parsers declare: bridge.cli.flags.REPORTS), as its ``bad_input`` report on
     stdout too (:class:`bridge.nodes.report.BadInput`: the session reads that, typed)

- :mod:`bridge.cli.flags`      flag types with their ranges
- :mod:`bridge.cli.linkflags`  the link flags and their ``[link]`` overrides
- :mod:`bridge.cli.options`    the options the flying commands share, and the :class:`~bridge.core.overrides.Overrides`
  their flags make
- :mod:`bridge.cli.commands`   the parser: one sub-command each, from the modules of their families
- :mod:`bridge.cli.flying`     ``sim``, ``sitl``, ``vehicle``, ``controller``, and the summary printed after a run
- :mod:`bridge.cli.campaigns`  ``sweep``, ``report``, ``margin``
- :mod:`bridge.cli.linktools`  ``link extract | fit | show``, ``relay``

Exit status: 0 the mission completed; 1 it ended in failsafe, divergence or abort; 2 bad
input, with one line on stderr naming the file, key or flag, and no traceback. A command whose result is final
may ignore SIGINT from there on (bridge.core.interrupt.ignore_sigint: its status is the result's, even through
the interpreter's exit); called with ``argv`` (in-process), ``main`` puts the caller's SIGINT handler back.
Nothing imports this package: it is the top of the layers (tests/test_layers.py).
"""

from __future__ import annotations

import argparse
import functools
import os
import signal
import sys
import threading
from collections.abc import Sequence

# Every bsst process is single-threaded by design (parallel work is --jobs processes), so numpy's BLAS gets
# one thread unless the user says otherwise: OpenBLAS's pool cost each process 0.1-0.4 s of CPU (a 10 s
# bsst sim: 1.0 CPU-s with it, 0.55 without) and its idle threads only contend with the other processes of
# a session or sweep. Set before numpy loads.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from bridge.cli.commands import EXIT_BAD_INPUT, EXIT_FAILED, build_parser, print_summary
from bridge.cli.flags import UsageError, as_config_error, refusal_line, reports
from bridge.cli.linkflags import link_table_from_args
from params import ConfigError, input_scope

__all__ = ["build_parser", "link_table_from_args", "main", "print_summary"]


@functools.cache
def _parser() -> argparse.ArgumentParser:
    """The parser, built once per process (parsing changes nothing in it; in-process callers such as
    the test suite call :func:`main` thousands of times)."""
    return build_parser()


def main(argv: Sequence[str] | None = None) -> int:
    own = threading.current_thread() is threading.main_thread() and argv is not None  # an in-process caller's
    handler = signal.getsignal(signal.SIGINT) if own else None
    args = None
    try:
        args = _parser().parse_args(argv)  # (building it imports ~0.1 s: a Ctrl-C there is said below, not traced)
        with input_scope():  # the files this command reads: --overwrite never replaces one (params.inputs_read)
            return args.func(args)
    except (UsageError, ConfigError) as exc:  # a usage error's line opens with its command (bsst, bsst sim) already
        refused = as_config_error(exc)
        print(refusal_line(refused), file=sys.stderr)
        if reports(args, exc):  # a command whose stdout is reports (its parser says): the refusal is one too, the
            # session's to read (never the line)
            from bridge.nodes.process import report_printer  # lazy: a refusal's only (the report's modules)
            from bridge.nodes.report import BadInput  # lazy: as above

            report_printer()(BadInput.of(refused))
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("bsst: interrupted", file=sys.stderr)
        return EXIT_FAILED
    finally:
        if handler is not None and signal.getsignal(signal.SIGINT) is not handler:  # (a command may ignore it)
            signal.signal(signal.SIGINT, handler)


if __name__ == "__main__":
    sys.exit(main())
