"""A fleet's figures: every vehicle in one picture (each vehicle's own are in its ``vehicle-<id>/plots``).

In:  each vehicle's trace arrays by column (``t`` s, ``x``, ``y``, ``z`` and their ``*_ref`` m), their ids, their
     disc radii (m) and the separation policy's minimum (m), a directory, a title
Out: ``fleet-paths.png`` (every vehicle's path seen from above, against its reference) and
     ``fleet-separation.png`` (each vehicle's clearance to its nearest neighbour over time, m, with the
     minimum); :func:`nearest_clearance` the series drawn
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from bridge.record.mplsetup import pyplot

DPI = 90


def nearest_clearance(traces: Sequence[Mapping[str, Any]], radii: Sequence[float]) -> list[np.ndarray]:
    """Each vehicle's clearance (m: centres' distance less both disc radii) to its nearest neighbour at each of
    its trace's rows, against the others' rows of the same step (a vehicle that ended: where it ended)."""
    n = len(traces)
    pos = [np.column_stack([tr["x"], tr["y"], tr["z"]]) for tr in traces]
    out = []
    for a in range(n):
        best = np.full(len(pos[a]), np.inf)
        for b in range(n):
            if b == a or not len(pos[b]):
                continue
            pb = pos[b][np.minimum(np.arange(len(pos[a])), len(pos[b]) - 1)]
            best = np.minimum(best, np.linalg.norm(pos[a] - pb, axis=1) - radii[a] - radii[b])
        out.append(best)
    return out


def fleet_plots(traces: Sequence[Mapping[str, Any]], ids: Sequence[int], radii: Sequence[float], min_m: float,
                folder: Path, title: str) -> list[Path]:
    """Write the fleet's two figures into ``folder``; their paths."""
    plt = pyplot()
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    fig, ax = plt.subplots(figsize=(7, 6))
    for i, tr in zip(ids, traces):
        line, = ax.plot(tr["x"], tr["y"], lw=1.2, label=f"vehicle {i}")
        ax.plot(tr["x_ref"], tr["y_ref"], ls="--", lw=0.8, color=line.get_color())
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_title(f"{title}: paths from above (dashed: references)")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    fig.subplots_adjust(left=0.1, right=0.8, bottom=0.09, top=0.92)
    written.append(folder / "fleet-paths.png")
    fig.savefig(written[-1], dpi=DPI)
    plt.close(fig)
    if len(traces) > 1:
        fig, ax = plt.subplots(figsize=(8, 4))
        for i, tr, c in zip(ids, traces, nearest_clearance(traces, radii)):
            ax.plot(tr["t"], c, lw=1.0, label=f"vehicle {i}")
        ax.axhline(min_m, color="C3", ls="--", lw=1.0, label=f"minimum {min_m:g} m")
        ax.axhline(0.0, color="k", lw=0.8)
        ax.set_xlabel("t (s)")
        ax.set_ylabel("clearance to nearest (m)")
        ax.set_title(f"{title}: separation between rotor discs")
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
        fig.subplots_adjust(left=0.1, right=0.78, bottom=0.13, top=0.9)
        written.append(folder / "fleet-separation.png")
        fig.savefig(written[-1], dpi=DPI)
        plt.close(fig)
    return written
