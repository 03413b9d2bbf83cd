"""``python -m bridge.cli.forkserver FD``: the fork server's process (bridge.nodes.forkserver).

In:  FD, this process's end of the socket its owner made (passed to it open); PADDING, room for the children's
     command lines (bridge.nodes.forkserver.show_command_line)
Out: children forked on request, each running the CLI's ``main`` on its argv; nothing on stdout

It imports, once, what the session's children (``bsst vehicle``, ``bsst controller``, ``bsst relay``) import
when they start, then serves until its owner closes the socket; before it forks a session's child it loads the
compiled kernels the session flies, as its launcher says, and under ``BSST_KERNELS=auto`` the compiled kernels
before the third child that flies (bridge.core.kernelpreload.KernelWarmer). Before the first ``bsst sim`` or ``bsst
sitl`` it forks (a process flying run after run through it: a script, the test suite; a session's own server forks
none), it imports what that command imports at its start (:class:`ChildWarmer`), so that every later one starts
with it.
"""

from __future__ import annotations

import gc
import sys
from collections.abc import Mapping, Sequence

from bridge.cli import _parser, main
from bridge.core.kernelpreload import KernelWarmer
from bridge.nodes.forkserver import serve, show_command_line


def preload() -> None:
    """Import what the children import lazily at their start (bridge.cli.flying, linktools), and build the
    parser, so that a forked child starts with all of it done; with ``BSST_KERNELS=compiled``, load the compiled
    kernels too (each child would load them: bridge.core.kernelpreload)."""
    import encodings.idna  # noqa: F401  (the codec of a socket's address given as text: each child's first send)

    import numpy.ma  # noqa: F401  (np.percentile imports it, in np.unique: each child's link figures at its end)

    import bridge.core.flight  # noqa: F401  (lazy in the children: preloaded here for every child at once)
    import bridge.mavlink.signing  # noqa: F401  (lazy in the children, as above)
    import bridge.mavlink.telemetry  # noqa: F401  (lazy in the children, as above)
    import bridge.nodes.offboard  # noqa: F401  (lazy in the children, as above)
    import bridge.nodes.relay  # noqa: F401  (lazy in the children, as above)
    import bridge.nodes.vehicle  # noqa: F401  (lazy in the children, as above)
    import bridge.nodes.vehicle.gate  # noqa: F401  (lazy in the children, as above)

    _parser()


def _sim_imports() -> None:
    """What ``bsst sim`` imports at its start (bridge.cli.flying's lazy imports and theirs, ~0.005 CPU-s)."""
    import bridge.core.interrupt  # noqa: F401  (lazy in the command: imported here for every later one at once)
    import bridge.nodes.watched  # noqa: F401  (as above)
    import bridge.record.runlog  # noqa: F401  (as above)
    import bridge.record.summary  # noqa: F401  (as above: the run's record, at its end)
    import bridge.swarm  # noqa: F401  (as above)


def _sitl_imports() -> None:
    """What ``bsst sitl`` imports at its start (~0.016 CPU-s: the session's code, bridge.swarm's lazy imports)."""
    _sim_imports()
    import bridge.session  # noqa: F401  (lazy in the command: imported here for every later one at once)
    import bridge.session.fleet  # noqa: F401  (as above)


LAUNCHERS = {"sim": _sim_imports, "sitl": _sitl_imports}  # a command: what it imports at its start


class ChildWarmer:
    """What the server does before it forks a child: :class:`~bridge.core.kernelpreload.KernelWarmer`'s rules for the
    compiled kernels; and before the first child of a command in :data:`LAUNCHERS`, that command's imports, once
    (a session's launcher, which forks its children here, is never forked by its own server: it pays nothing)."""

    def __init__(self) -> None:
        self.kernels = KernelWarmer()
        self.imported: set[str] = set()  # the commands whose imports the server holds

    def __call__(self, argv: Sequence[str], env: Mapping[str, str]) -> None:
        self.kernels(argv, env)
        command = argv[0] if argv else ""
        if command in LAUNCHERS and command not in self.imported:
            self.imported.add(command)
            try:
                LAUNCHERS[command]()
            except Exception:  # noqa: BLE001  (the child imports it again, and says what went wrong)
                return
            gc.freeze()  # shared with every later child, never copied into one (as the server's start-up imports)


if __name__ == "__main__":
    if len(sys.argv) not in (2, 3) or not sys.argv[1].isdigit():
        print("usage: python -m bridge.cli.forkserver FD [PADDING] (started by bridge.nodes.forkserver)",
              file=sys.stderr)
        sys.exit(2)
    show_command_line([sys.executable, "-m", "bridge.cli.forkserver", sys.argv[1]])  # not the padding
    preload()
    serve(int(sys.argv[1]), main, ChildWarmer())
