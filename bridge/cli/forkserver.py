"""``python -m bridge.cli.forkserver FD``: the fork server's process (bridge.nodes.forkserver).

In:  FD, this process's end of the socket its owner made (passed to it open); PADDING, room for the children's
     command lines (bridge.nodes.forkserver.show_command_line)
Out: children forked on request, each running the CLI's ``main`` on its argv; nothing on stdout

It imports, once, what the session's children (``bsst vehicle``, ``bsst controller``, ``bsst relay``) import
when they start, then serves until its owner closes the socket; before it forks a session's child it loads the
compiled kernels the session flies, as its launcher says, and under ``BSST_KERNELS=auto`` the compiled kernels
before the third child that flies (bridge.core.kernelpreload.KernelWarmer).
"""

from __future__ import annotations

import sys

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


if __name__ == "__main__":
    if len(sys.argv) not in (2, 3) or not sys.argv[1].isdigit():
        print("usage: python -m bridge.cli.forkserver FD [PADDING] (started by bridge.nodes.forkserver)",
              file=sys.stderr)
        sys.exit(2)
    show_command_line([sys.executable, "-m", "bridge.cli.forkserver", sys.argv[1]])  # not the padding
    preload()
    serve(int(sys.argv[1]), main, KernelWarmer())
