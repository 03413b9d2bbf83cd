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

from bridge.cli.campaigns import add_margin_command, add_sweep_commands
from bridge.cli.flags import EXIT_BAD_INPUT, EXIT_FAILED, EXIT_OK, _Parser
from bridge.cli.flying import add_sim_command, add_sitl_commands, print_summary, report_run
from bridge.cli.linktools import add_link_commands, add_relay_command

__all__ = ["EXIT_BAD_INPUT", "EXIT_FAILED", "EXIT_OK", "build_parser", "print_summary", "report_run"]


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="bsst", description="MAVLink SITL bridge for a BS-ST-controlled quadrotor")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True
    add_sim_command(sub)
    add_sweep_commands(sub)
    add_margin_command(sub)
    add_sitl_commands(sub)
    add_relay_command(sub)
    add_link_commands(sub)
    return parser
