"""``python -m bridge`` and the ``bsst`` command (pyproject's ``[project.scripts]``): the CLI.

In:  the command line
Out: the CLI's exit status (bridge.cli.main); a Ctrl-C while Python is still importing the CLI (about 0.15 s) is
     said in the CLI's own words and status (``bsst: interrupted``, 1), not as a KeyboardInterrupt traceback; run as
     ``python -m bridge``, that status is the process's too (:func:`_forget_caught_interrupt`)
"""

import sys


def main() -> int:
    try:
        from bridge.cli import main as cli  # imported here: a Ctrl-C during the import is caught below
    except KeyboardInterrupt:  # (1 is bridge.cli.EXIT_FAILED: importing it is what was interrupted)
        print("bsst: interrupted", file=sys.stderr)
        return 1
    return cli()


def _forget_caught_interrupt() -> None:
    """CPython remembers a KeyboardInterrupt that ended code run from a string by ``exec`` or ``eval`` (a dataclass's
    generated ``__init__``, built as a command imports its modules) even once it was caught, and at the end of a
    ``python -m`` run it then kills its own process by SIGINT (status 130 in a shell, -2 to ``subprocess``), after
    ``bsst: interrupted`` had been said: 4 of 30 random Ctrl-Cs in a ``python -m bridge sim``'s first 0.45 s, where
    the ``bsst`` script, which exits by its SystemExit, gave 1. The next such run forgets it (pythonrun.c's
    ``run_eval_code_obj`` clears ``_Py_UnhandledKeyboardInterrupt`` first): one of nothing."""
    eval("None")  # (a string: a code object would not go through it)


if __name__ == "__main__":
    status = main()
    _forget_caught_interrupt()
    sys.exit(status)
