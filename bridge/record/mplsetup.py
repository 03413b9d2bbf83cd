"""matplotlib made ready to draw: the Agg backend, and a writable folder of its own where the user has none.

In:  the environment matplotlib reads for its config and cache folders (``MPLCONFIGDIR``; ``XDG_CONFIG_HOME``,
     ``XDG_CACHE_HOME``, ``HOME``)
Out: :func:`pyplot`: ``matplotlib.pyplot`` on the Agg backend. Before matplotlib's first import in the process, where
     it would find no writable config or cache folder (a container, a CI runner, a user without a writable home),
     ``MPLCONFIGDIR`` is set to a temporary folder of this process's own, removed at its exit: the figures are the
     same, its font list is built again there (~0.3 s)

Why: matplotlib then makes such a folder itself, but says so on stderr in lines of its own ("mkdir -p failed for
path ...", "Matplotlib created a temporary cache directory ... it is highly recommended to set the MPLCONFIGDIR
environment variable ..."), in the middle of a run's output and about nothing the run did wrong. The folders are
matplotlib's own rule (``matplotlib._get_config_or_cache_dir``, 3.11): ``$XDG_CONFIG_HOME/matplotlib`` (else
``~/.config/matplotlib``) and ``$XDG_CACHE_HOME/matplotlib`` (else ``~/.cache/matplotlib``) on Linux and FreeBSD,
``~/.matplotlib`` elsewhere; each made if missing, and used if it is then a writable folder.
"""

from __future__ import annotations

import atexit
import os
import shutil
import sys
import tempfile
from pathlib import Path
from typing import Any

PREFIX = "bsst-matplotlib-"  # the temporary folder's name starts so (in the system's temporary directory)


def pyplot() -> Any:
    """``matplotlib.pyplot`` with the Agg backend (imported here: matplotlib costs start-up time and is needed only for
    figures), after :func:`give_matplotlib_a_folder`."""
    give_matplotlib_a_folder()
    import matplotlib  # lazy: see the docstring

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # lazy: after the backend

    return plt


def give_matplotlib_a_folder() -> str | None:
    """Before matplotlib's first import in this process, where ``MPLCONFIGDIR`` is unset and matplotlib's own config or
    cache folder cannot be made or written (module docstring), set ``MPLCONFIGDIR`` to a new temporary folder, removed
    at the process's exit. The folder set, or None (matplotlib already imported, or its folders are fine)."""
    if "matplotlib" in sys.modules or os.environ.get("MPLCONFIGDIR") or all(_writable(d) for d in _default_folders()):
        return None
    folder = tempfile.mkdtemp(prefix=PREFIX)
    os.environ["MPLCONFIGDIR"] = folder  # the processes this one starts from now on share it (it outlives them)
    atexit.register(shutil.rmtree, folder, True)
    return folder


def _default_folders() -> list[Path | None]:
    """matplotlib's config and cache folders without ``MPLCONFIGDIR`` (None: no home to find them in)."""
    try:
        if sys.platform.startswith(("linux", "freebsd")):
            return [Path(os.environ.get("XDG_CONFIG_HOME") or Path.home() / ".config", "matplotlib"),
                    Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache", "matplotlib")]
        return [Path.home() / ".matplotlib"]
    except RuntimeError:  # Path.home(): no home directory to be found
        return [None]


def _writable(folder: Path | None) -> bool:
    """Whether ``folder`` is, once made if missing, a folder this process may write in (as matplotlib judges it)."""
    if folder is None:
        return False
    try:
        folder = folder.resolve()
        folder.mkdir(parents=True, exist_ok=True)
    except OSError:
        return False
    return os.access(folder, os.W_OK) and folder.is_dir()
