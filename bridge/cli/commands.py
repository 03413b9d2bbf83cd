"""The ``bsst`` parser: one sub-command per thing ``bsst`` does, each from the module of its family.

In:  argv, parsed by :func:`build_parser` into an ``argparse.Namespace`` whose ``func`` is the command
Out: that command's call (:mod:`bridge.cli.flying`: sim, sitl, vehicle, controller;
     :mod:`bridge.cli.campaigns`: sweep, report, margin; :mod:`bridge.cli.linktools`: link, relay);
     its exit status: 0 completed, 1 failsafe/diverged/aborted (or a failed or interrupted sweep),
     2 bad input

Heavy imports happen inside the command that needs them, so that ``bsst --help`` and a refused
flag stay fast.
"""

from __future__ import annotations

import argparse
import tomllib
from pathlib import Path
from typing import Any, NoReturn

from bridge.cli.campaigns import add_margin_command, add_sweep_commands
from bridge.cli.flags import EXIT_BAD_INPUT, EXIT_FAILED, EXIT_OK, _Parser
from bridge.cli.flying import add_sim_command, add_sitl_commands
from bridge.cli.linktools import add_link_commands, add_relay_command
from bridge.cli.runreport import print_summary, report_run

__all__ = ["EXIT_BAD_INPUT", "EXIT_FAILED", "EXIT_OK", "build_parser", "package_version", "print_summary",
           "report_run"]

DISTRIBUTION = "bsst-sitl"  # pyproject.toml's [project] name
PYPROJECT = Path(__file__).resolve().parents[2] / "pyproject.toml"  # beside the packages in a checkout


def package_version() -> str:
    """This bsst's version: the installed distribution's metadata, else (a checkout run from its source,
    never installed) ``pyproject.toml``'s ``[project] version``; ``unknown`` if neither says."""
    import importlib.metadata  # only when asked: with its email and zipfile imports, ~50 ms of every bsst's start

    try:
        return importlib.metadata.version(DISTRIBUTION)
    except importlib.metadata.PackageNotFoundError:
        pass
    try:
        return str(tomllib.loads(PYPROJECT.read_text(encoding="utf-8"))["project"]["version"])
    except (OSError, ValueError, KeyError, TypeError):
        return "unknown"


class _Version(argparse.Action):
    """``--version``: print ``bsst X.Y.Z`` on stdout and exit 0 (the version looked up only when asked)."""

    def __init__(self, option_strings: list[str], dest: str = argparse.SUPPRESS, **kw: Any) -> None:
        super().__init__(option_strings, dest, nargs=0, default=argparse.SUPPRESS, **kw)

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: Any,
                 option_string: str | None = None) -> NoReturn:
        print(f"bsst {package_version()}")
        parser.exit(0)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="bsst", description="MAVLink SITL bridge for a BS-ST-controlled quadrotor")
    parser.add_argument("--version", action=_Version, help="print bsst's version and exit")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True
    add_sim_command(sub)
    add_sweep_commands(sub)
    add_margin_command(sub)
    add_sitl_commands(sub)
    add_relay_command(sub)
    add_link_commands(sub)
    return parser
