"""The figure of a link trace (``bsst link show``): delay over time, loss bursts, the delay histogram.

In:  a validated trace (:class:`bridge.link.trace.TraceFile`: per direction send times s, one-way
     delays s, nan lost), a PNG path, a title
Out: the PNG: (1) each record's delay (ms) against its send time (s), lost records as ticks along the
     top; (2) each loss run as a bar at its start, as tall as its length (packets), or a line saying there
     were none; (3) the histogram of the delivered delays (ms), with each direction's median; legends above
     their panels, off the data
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from bridge.link.trace import Records, TraceFile
from bridge.record.mplsetup import pyplot
from bridge.record.plots import DPI, legend_above

COLOURS = {"both": "C0", "up": "C0", "down": "C1"}


def _loss_runs(rec: Records) -> tuple[np.ndarray, np.ndarray]:
    """(start time s, length in records) of each run of lost records."""
    lost = np.isnan(np.asarray(rec.delay_s, dtype=float))
    edges = np.diff(np.concatenate(([0], lost.astype(np.int8), [0])))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    return np.asarray(rec.t_s, dtype=float)[starts], ends - starts


def trace_figure(trace: TraceFile, out: str | Path, title: str = "") -> Path:
    """Write the three-panel figure of ``trace`` to ``out`` (PNG); returns its path."""
    plt = pyplot()
    fig = link_trace_figure(trace, title)
    out = Path(out)
    fig.savefig(out, dpi="figure")
    plt.close(fig)
    return out


def link_trace_figure(trace: TraceFile, title: str = "") -> Any:
    """The three-panel figure of ``trace`` (matplotlib, Agg, :data:`~bridge.record.plots.DPI`); the caller closes it."""
    plt = pyplot()
    parts = [("both", trace.both)] if trace.both is not None else [(d, r) for d, r in (("up", trace.up),
                                                                                      ("down", trace.down)) if r]
    fig, (ax_d, ax_l, ax_h) = plt.subplots(3, 1, figsize=(9, 9), dpi=DPI)
    ax_l.sharex(ax_d)  # one time axis: a loss run lines up with the delays around it
    top = 0.0
    for _, rec in parts:  # one height for the lost ticks of every direction: above the highest delay
        assert rec is not None
        d = np.asarray(rec.delay_s, dtype=float) * 1000.0
        ok = ~np.isnan(d)
        if ok.any():
            top = max(top, float(d[ok].max()))
    for name, rec in parts:
        assert rec is not None
        c = COLOURS[name]
        t = np.asarray(rec.t_s, dtype=float)
        d = np.asarray(rec.delay_s, dtype=float) * 1000.0
        ok = ~np.isnan(d)
        label = f"{name}: {rec.n} records, {100.0 * (~ok).sum() / rec.n:.2f} % lost"
        ax_d.plot(t[ok], d[ok], ".", ms=1.5, color=c, label=label)
        ax_d.plot(t[~ok], np.full((~ok).sum(), top * 1.05 if top else 1.0), "|", ms=6, color=c, alpha=0.6)
        starts, lengths = _loss_runs(rec)
        if len(starts):
            ax_l.vlines(starts, 0, lengths, color=c, lw=1.0,
                        label=f"{name}: {len(starts)} loss runs, mean {lengths.mean():.2f}, longest {lengths.max()}")
        if ok.any():
            med = float(np.median(d[ok]))
            ax_h.hist(d[ok], bins=100, histtype="step", color=c, label=f"{name}: median {med:.2f} ms")
            ax_h.axvline(med, color=c, ls="--", lw=0.8)
    if not ax_l.collections:  # nothing lost: say so, rather than leave empty axes
        ax_l.text(0.5, 0.5, "no loss runs: every record was delivered", transform=ax_l.transAxes, ha="center",
                  va="center", fontsize=11, color="0.3")
        ax_l.set_yticks([])
    ax_d.set(xlabel="send time t_s (s)", ylabel="one-way delay (ms)")
    ax_l.set(xlabel="send time t_s (s)", ylabel="loss run (packets)")
    ax_h.set(xlabel="one-way delay (ms)", ylabel="records (count)")
    for ax, name in ((ax_d, "delay over time (ticks at the top: lost)"), (ax_l, "loss bursts"),
                     (ax_h, "delay histogram (delivered)")):
        ax.set_title(name, loc="left", fontsize=10)
        legend_above(ax, markerscale=4)  # the delay dots are 1.5 points: too small to see in the legend
        ax.grid(alpha=0.3)
    fig.suptitle(title or Path(trace.path).name)
    fig.tight_layout()
    return fig
