"""``python -m bridge`` and the ``bsst`` command (pyproject's ``[project.scripts]``): the CLI.

In:  the command line
Out: the CLI's exit status (bridge.cli.main); a Ctrl-C while Python is still importing the CLI (about 0.15 s) is
     said in the CLI's own words and status (``bsst: interrupted``, 1), not as a KeyboardInterrupt traceback
"""

import sys


def main() -> int:
    try:
        from bridge.cli import main as cli  # imported here: a Ctrl-C during the import is caught below
    except KeyboardInterrupt:  # (1 is bridge.cli.EXIT_FAILED: importing it is what was interrupted)
        print("bsst: interrupted", file=sys.stderr)
        return 1
    return cli()


if __name__ == "__main__":
    sys.exit(main())
