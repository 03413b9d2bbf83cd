"""The batched offline engine: many cells of one mission flown at once, over a cell axis (numpy and numba).

In:  a mission (a :class:`~missions.Mission` or a TOML path) and, per cell, the overrides
     :func:`bridge.core.flight.prepare` takes (``controller``, ``rate_hz`` Hz, ``seed``, a ``link`` table:
     what :func:`bridge.sweep.grid.cell_overrides` gives), or prepared :class:`~bridge.core.flight.Flight` s
Out: per cell the measured columns of a ``cells.csv`` row (:data:`MEASURES`: ``rms``/``max`` m,
     ``settling_s``/``flown_s`` s, ``tv_u2`` N/s, ``ripple_u2`` N, ``outcome``, packet counts, ``error``),
     the same numbers :func:`bridge.sweep.cells.row_from_run` takes from the scalar loop's run;
     :func:`batch_problem` says in one line why a set of cells cannot be flown here

The engine's names (:data:`MEASURES`, :func:`fly_batch`, ...) are imported on first use: the engine imports numba
(~0.25 CPU-s), and a sweep under ``--engine auto`` asks :func:`batch_problem` of every grid, a small one to fly
it on the process engine, which needs no numba.

The parts:

- :mod:`bridge.batch.scope`    what the batch can fly, and why not (no numba)
- :mod:`bridge.batch.engine`   the batches (the link plan, the threads)
- :mod:`bridge.batch.flight`   each cell's whole flight in one compiled call, cell by cell
- :mod:`bridge.batch.kernels`  the scalar engine's own plain-float functions, compiled (one source each)
- :mod:`bridge.batch.control`  the laws the batch flies, one cell's actuation
- :mod:`bridge.batch.plant`    the plant's start over the cell axis, one cell's physics step
- :mod:`bridge.batch.predict`  the predictor over the cell axis
- :mod:`bridge.batch.wire`     one cell's state and command over the float32 wire
- :mod:`bridge.batch.metrics`  the running figures and the cells.csv row
"""

from __future__ import annotations

from typing import Any

from bridge.batch.scope import CELL_STEPS, _prepare_all, batch_problem, flights_problem

__all__ = ["CELL_STEPS", "MEASURES", "_prepare_all", "batch_problem", "compile_batch", "error_measures",
           "flights_problem", "fly_batch", "fly_flights"]
_ENGINE = frozenset({"MEASURES", "compile_batch", "error_measures", "fly_batch", "fly_flights"})


def __getattr__(name: str) -> Any:
    if name in _ENGINE:
        from bridge.batch import engine  # lazy: numba's import, only where the batch flies (the module's docstring)

        return getattr(engine, name)
    raise AttributeError(f"module 'bridge.batch' has no attribute {name!r}")
