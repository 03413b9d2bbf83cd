"""Latency and dropout campaigns (``bsst sweep``): a grid of link impairments, flown in parallel.

In:  a mission (or a sweep TOML file) and a :class:`Grid`: laws, control rates (Hz), one-way delays
     (ms), jitters (ms), losses (%), mean loss-burst lengths (packets), the vehicle's estimator kinds,
     noise scales of its sensor set (x every sigma), seeds per point
Out: one ``cells.csv`` row per cell, in grid order (3-D RMS and max error m, settling s, ``tv_u2``
     N/s, ``ripple_u2`` N, class, packet counts); with ``out``, the sweep directory (``cells.csv``,
     ``sweep.json``, ``mission.toml``, ``report.md``, heat maps)

- :mod:`bridge.sweep.grid`       axes, their ranges, :class:`Grid`, :class:`Cell`
- :mod:`bridge.sweep.spec`       :class:`Sweep` and the sweep TOML file
- :mod:`bridge.sweep.cells`      ``cells.csv``: columns, rows, the file
- :mod:`bridge.sweep.classes`    :class:`Classes` and :func:`classify`
- :mod:`bridge.sweep.executors`  process pool, Dask, the batch engine
- :mod:`bridge.sweep.progress`   the progress bar and its ETA
- :mod:`bridge.sweep.campaign`   :func:`sweep` and :func:`run_sweep`
- :mod:`bridge.sweep.report`     ``report.md`` and the heat maps (``bsst report``)
- :mod:`bridge.sweep.margin`     ``bsst margin``: one axis's boundary by bisection

A sweep flies one mission over the product of a few lists (the *grid*): control law, control
rate, link delay, jitter, loss and mean loss-burst length, the vehicle's estimator kind and
the noise scale of its sensor set, each grid point with several seeds. One grid point flown
with one seed is a *cell*: one run, one row of ``cells.csv``. A law without a super-twisting step (``smc``,
``pid``, one's own) has no discretization to step: its points of each scheme are one cell, its discretization
empty (:data:`~bridge.sweep.grid.NO_SCHEME`).

Delay, jitter, loss and burst length apply to **both** link directions (``[link.up]``,
controller -> vehicle, and ``[link.down]``, vehicle -> controller) with the same values; the
mission's other link keys (blackouts, duplication, a direction's own seed, ...) are kept. An
axis that is not swept keeps the mission's own value and is not overridden.

Cells run in a local process pool (``jobs`` workers), or on a Dask distributed cluster
(``client``). Each finished cell is appended to ``cells.csv`` at once as one whole line, so a
sweep killed at any point resumes with only its missing cells (``resume=True``); at the end
the file is rewritten in grid order, so a resumed sweep's file equals an uninterrupted one's.
A cell that raises (or whose worker process dies) is recorded with outcome ``error`` and
never stops the sweep; a sweep whose every cell failed raises :class:`SweepFailed` from
:func:`sweep` (:func:`run_sweep`'s :class:`Outcome` says ``status == "all failed"``; ``bsst sweep``
exits 1 naming the first error).

Worker processes import the main script again: a script starts a sweep under
``if __name__ == "__main__":``, and one that does not is refused at once (a ConfigError naming the line).

Scripting::

    from bridge.sweep import Grid, sweep
    rows = sweep("missions/sine.toml", Grid(delay_ms=(0, 10), loss_pct=(0, 20), seeds=2), jobs=2)
"""

from bridge.sweep.campaign import STATUSES, Outcome, SweepFailed, run_sweep, sweep
from bridge.sweep.cells import CELLS_CSV, COLUMNS, SWEEP_JSON, read_cells, row_from_run
from bridge.sweep.classes import CLASSES, Classes, classify
from bridge.sweep.grid import AXES, LINK_AXES, RANGES, SENSING_AXES, Cell, Grid, cells
from bridge.sweep.spec import Sweep, is_sweep_file, load_sweep

__all__ = ["AXES", "CELLS_CSV", "CLASSES", "COLUMNS", "LINK_AXES", "RANGES", "SENSING_AXES", "STATUSES",
           "SWEEP_JSON", "Cell", "Classes", "Grid", "Outcome", "Sweep", "SweepFailed", "cells", "classify",
           "is_sweep_file", "load_sweep", "read_cells", "row_from_run", "run_sweep", "sweep"]
