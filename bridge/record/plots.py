"""The run's figures, like the paper's Figs. 1-10: positions with references, tracking
errors, angles (with the desired roll and pitch), inputs, and the 3-D path.

In:  trace arrays by column (t s, positions m, angles rad, inputs demanded and realised N), a
     directory, a title, and the stretches of the flight to mark (:class:`Span`: link blackouts and
     failsafes, s; :func:`run_spans` makes them from the run's events and its blackout windows)
Out: ``positions.png``, ``errors.png``, ``angles.png``, ``inputs.png``, ``path3d.png`` in it, and
     their paths; when the vehicle flew on an estimate (an estimator other than ``truth``: the
     ``*_est`` columns differ from the truth) also ``estimate.png``: x, y, z, φ, θ, ψ true and
     estimated, the estimate's error (true − estimated, ψ wrapped), and its NEES against the χ²(9)
     band (the covariance itself is not in the trace, only this consistency figure)

Every axis label carries its unit; u2..u4 are in N like u1 (the plant applies the torques l·u2..l·u4
in N·m, docs/law.md). Legends sit above their panel, outside the data. :func:`figures` builds the
figures (tests read them), :func:`make_plots` writes them; fixed margins, not ``tight_layout``, whose
measuring pass cost a third of the figures' time. A time axis's line keeps, of the samples falling in each pixel
column, the first, lowest, highest and last (:func:`thin_lines`; solid lines): drawn the same, every peak kept, a
sign that alternates every step still filling its band, in less time and memory on a long flight.
"""

from __future__ import annotations

import gc
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from bridge.record.metrics import errors
from bridge.record.mplsetup import pyplot

ESTIMATED = (("x", "m"), ("y", "m"), ("z", "m"), ("phi", "rad"), ("theta", "rad"), ("psi", "rad"))
TRACKED = (("x", "m"), ("y", "m"), ("z", "m"), ("psi", "rad"))
INPUTS = ("u1", "u2", "u3", "u4")
NEES_DOF = 9  # position, velocity, attitude: bridge.autopilot.estimator.nees
NEES_BAND = (2.70, 19.02)  # the chi-square(9) 2.5 % and 97.5 % quantiles: 95 % of a consistent filter's NEES
DPI = 90
ZOOM_S = 0.1  # the inputs' close-up: the last 0.1 s, where a sign that alternates every step shows as such
MARGINS = {"left": 0.11, "right": 0.97, "bottom": 0.07, "top": 0.91, "hspace": 0.3, "wspace": 0.28}
SPAN_STYLE = {"blackout": {"color": "0.45", "alpha": 0.25, "label": "link blackout"},
              "failsafe": {"color": "C3", "alpha": 0.15, "label": "failsafe"}}
FAILSAFE_ENDS = ("armed", "mode", "disarmed")  # events after which the failsafe no longer flies the vehicle


@dataclass(frozen=True)
class Span:
    """A stretch of the flight every time axis shades: ``kind`` (a key of :data:`SPAN_STYLE`), from
    ``start_s`` to ``end_s`` (s of mission time)."""

    kind: str
    start_s: float
    end_s: float


def run_spans(events: Iterable[Mapping[str, Any]], blackouts: Iterable[tuple[float, float]],
              t_end: float) -> list[Span]:
    """The link blackouts (``(start s, duration s)`` windows, either direction, merged when equal) and the
    failsafes: from each ``failsafe`` event to the next event that ends it (re-armed, a ground station's mode,
    disarmed), else to ``t_end`` (s)."""
    spans = [Span("blackout", s, min(s + d, t_end)) for s, d in sorted(set(blackouts)) if s < t_end]
    ev = sorted(events, key=lambda e: e["t"])
    for i, e in enumerate(ev):
        if e["kind"] != "failsafe" or any(s.kind == "failsafe" and s.start_s <= e["t"] < s.end_s for s in spans):
            continue
        end = next((f["t"] for f in ev[i + 1:] if f["kind"] in FAILSAFE_ENDS), t_end)
        spans.append(Span("failsafe", float(e["t"]), float(max(end, e["t"]))))
    return spans


def has_estimate(trace: dict[str, np.ndarray]) -> bool:
    """Whether the vehicle flew on an estimate: its ``*_est`` columns are there and differ from the
    truth somewhere (under ``truth`` they are the truth itself, bit for bit)."""
    for a, _ in ESTIMATED:
        est = trace.get(a + "_est")
        if est is None:
            return False
        d = np.asarray(trace[a]) - np.asarray(est)
        if np.any(d[np.isfinite(d)] != 0.0):
            return True
    return False


def estimation_errors(trace: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """True minus estimated of each of x, y, z (m) and phi, theta, psi (rad; psi wrapped to [-pi, pi))."""
    out = {}
    for a, _ in ESTIMATED:
        d = np.asarray(trace[a]) - np.asarray(trace[a + "_est"])
        out[a] = (d + np.pi) % (2.0 * np.pi) - np.pi if a == "psi" else d
    return out


def legend_above(ax: Any, handles: Sequence[Any] | None = None, labels: Sequence[str] | None = None,
                 **kw: Any) -> Any:
    """The legend in one row just above ``ax``, right-aligned: outside the data, inside the figure (``kw``: more
    of :meth:`matplotlib.axes.Axes.legend`'s options)."""
    if handles is None:
        handles, labels = ax.get_legend_handles_labels()
    if not handles:
        return None
    return ax.legend(handles, labels, loc="lower right", bbox_to_anchor=(1.0, 1.0), ncols=len(handles), fontsize=8,
                     frameon=False, borderaxespad=0.1, handlelength=1.8, columnspacing=1.2, **kw)


def mark_spans(ax: Any, spans: Sequence[Span], label: bool = False) -> None:
    """Shade ``spans`` on a time axis; with ``label``, one legend entry per kind."""
    seen: set[str] = set()
    for s in spans:
        style = dict(SPAN_STYLE[s.kind])
        name = style.pop("label")
        ax.axvspan(s.start_s, s.end_s, lw=0, zorder=0, label=name if label and s.kind not in seen else None, **style)
        seen.add(s.kind)


def make_plots(trace: dict[str, np.ndarray], out: str | Path, title: str = "",
               spans: Sequence[Span] = ()) -> list[Path]:
    """Write ``positions.png, errors.png, angles.png, inputs.png, path3d.png`` (and ``estimate.png``) into ``out``."""
    with heap_frozen() as freeze_more:
        plt = pyplot()
        freeze_more()  # matplotlib's modules too, imported just now
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        written: list[Path] = []
        for name, fig in figures(trace, title, spans).items():
            p = out / f"{name}.png"
            fig.savefig(p, dpi="figure", pil_kwargs={"compress_level": 1})
            plt.close(fig)
            written.append(p)
    return written


@contextmanager
def heap_frozen() -> Iterator[Callable[[], None]]:
    """The process's heap frozen (``gc.freeze``) while the block runs, given back after; the block may freeze what it
    made since (the callable it gets). Why: matplotlib's import and figures make tens of thousands of objects, and the
    full collections they set off would each walk the process's whole heap (the flight's, numpy's, matplotlib's
    modules) again, none of it garbage (~6 % of the figures' CPU). A heap frozen already (a fork server's child:
    bridge.nodes.forkserver) is left as it is, the callable doing nothing: thawing it would thaw the server's too."""
    ours = gc.get_freeze_count() == 0
    if ours:
        gc.freeze()
    try:
        yield gc.freeze if ours else lambda: None
    finally:
        if ours:
            gc.unfreeze()


def figures(trace: dict[str, np.ndarray], title: str = "", spans: Sequence[Span] = ()) -> dict[str, Any]:
    """The run's figures by name (matplotlib figures, Agg, :data:`DPI`); the caller closes them."""
    plt = pyplot()
    figs = {"positions": _positions(plt, trace, spans), "errors": _errors(plt, trace, spans),
            "angles": _angles(plt, trace, spans), "inputs": _inputs(plt, trace, spans), "path3d": _path3d(plt, trace)}
    if has_estimate(trace):
        figs["estimate"] = _estimate_figure(plt, trace, spans)
    for name, fig in figs.items():
        fig.suptitle(f"{title} — {name}" if title else name)
        if name != "path3d":
            fig.subplots_adjust(**(MARGINS | ({"top": 0.94} if name == "estimate" else {})))
            thin_lines(fig)
    return figs


def thin_lines(fig: Any) -> None:
    """Cut each solid line of ``fig``'s 2-D axes (time or any increasing x on a linear scale, every value finite) to
    the first, lowest, highest and last of its samples in each pixel column, once the layout and limits are final. A
    line so cut is drawn with the same extent in every column and the same joins between columns (M4: Jugel et al.,
    "M4: A Visualization-Oriented Time Series Data Aggregation", VLDB 2014): what it drops lies inside what is
    drawn. Left whole: markers and steps (each marker is a sample the figure shows), 3-D axes, and dashed lines: a
    dashed line that fills a band (a realised input alternating every step) is solid there only through its many
    segments' overlapping dashes; cut to four samples a column its gaps would show the line under it."""
    for ax in fig.axes:
        if ax.name != "rectilinear" or ax.get_xscale() != "linear":
            continue
        x0, x1 = ax.get_xlim()  # autoscaled now, from the whole lines: cutting them keeps the limits
        left, width = ax.bbox.x0, ax.bbox.width
        if x1 <= x0 or width <= 0:
            continue
        for line in ax.lines:
            if (line.get_linestyle() != "-" or line.get_marker() not in ("None", "", None)
                    or line.get_drawstyle() != "default"):
                continue
            x, y = np.asarray(line.get_xdata(), float), np.asarray(line.get_ydata(), float)
            if len(x) < 8 or not (np.all(np.isfinite(x)) and np.all(np.isfinite(y)) and np.all(np.diff(x) >= 0)):
                continue
            keep = _m4(np.floor(left + (x - x0) * (width / (x1 - x0))).astype(np.int64), y)
            if len(keep) < len(x):
                line.set_data(x[keep], y[keep])


def _m4(column: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Indices, in order, of the first, lowest, highest and last sample of each run of equal ``column`` (pixel
    columns, non-decreasing)."""
    n = len(y)
    starts = np.flatnonzero(np.r_[True, column[1:] != column[:-1]])
    lengths = np.diff(np.r_[starts, n])
    run = np.repeat(np.arange(len(starts)), lengths)
    picked = [starts, starts + lengths - 1]
    for extreme in (np.minimum, np.maximum):
        at = np.flatnonzero(y == extreme.reduceat(y, starts)[run])
        picked.append(at[np.r_[True, run[at[1:]] != run[at[:-1]]]])  # the first of equal extremes in a column
    return np.unique(np.concatenate(picked))


def _time_panels(plt: Any, rows: int, height: float, spans: Sequence[Span]) -> tuple[Any, Any]:
    """A figure of ``rows`` panels over one time axis (labelled at the bottom), the spans shaded on each
    (in the first panel's legend)."""
    fig, axs = plt.subplots(rows, 1, figsize=(8, height), sharex=True, dpi=DPI)
    for i, ax in enumerate(axs):
        mark_spans(ax, spans, label=i == 0)
        ax.grid(alpha=0.3)
    axs[-1].set_xlabel("t [s]")
    return fig, axs


def _positions(plt: Any, trace: dict[str, np.ndarray], spans: Sequence[Span]) -> Any:
    t = trace["t"]
    fig, axs = _time_panels(plt, 4, 8, spans)
    for i, (ax, (a, unit)) in enumerate(zip(axs, TRACKED, strict=True)):
        ax.plot(t, trace[a], label="flown")
        ax.plot(t, trace[a + "_ref"], "--", label="reference")
        ax.set_ylabel(f"{a} [{unit}]")
        if i == 0:
            legend_above(ax)
    return fig


def _errors(plt: Any, trace: dict[str, np.ndarray], spans: Sequence[Span]) -> Any:
    t = trace["t"]
    e = errors(trace)
    fig, axs = _time_panels(plt, 4, 8, spans)
    for ax, (a, unit) in zip(axs, TRACKED, strict=True):
        ax.plot(t, e[a], lw=0.9)
        ax.set_ylabel(f"{a} - {a}_ref [{unit}]")
    legend_above(axs[0])  # the spans', if any
    return fig


def _angles(plt: Any, trace: dict[str, np.ndarray], spans: Sequence[Span]) -> Any:
    t = trace["t"]
    fig, axs = _time_panels(plt, 3, 7, spans)
    for ax, a, d in zip(axs, ("phi", "theta", "psi"), ("phi_d", "theta_d", "psi_ref"), strict=True):
        ax.plot(t, trace[a], label="flown")
        if d in trace:
            ax.plot(t, trace[d], "--", label="desired" if d.endswith("_d") else "reference")
        ax.set_ylabel(f"{a} [rad]")
        legend_above(ax)
    return fig


def _input_label(u: str) -> str:
    return f"{u} [N]" if u == "u1" else f"{u} [N]\n(torque l·{u} N·m)"


def _inputs(plt: Any, trace: dict[str, np.ndarray], spans: Sequence[Span]) -> Any:
    """Demanded (thin) and realised (dashed) inputs over the flight, and the last :data:`ZOOM_S` s step by step:
    demanded as a dot per control step, realised as held until the next."""
    t = trace["t"]
    fig, axs = plt.subplots(4, 2, figsize=(10, 8), sharex="col", dpi=DPI, width_ratios=(3, 1))
    last = t >= t[-1] - ZOOM_S
    near = [Span(s.kind, max(s.start_s, t[last][0]), s.end_s) for s in spans if s.end_s > t[last][0]]
    for i, u in enumerate(INPUTS):
        ax, zoom = axs[i]
        mark_spans(ax, spans, label=i == 0)
        ax.plot(t, trace[u], lw=0.6, color="C0", label="demanded")
        ax.plot(t, trace[u + "_act"], "--", lw=0.9, color="C1", label="realised")
        ax.set_ylabel(_input_label(u))
        zoom.plot(t[last], trace[u][last], "o", ms=3, mfc="none", color="C0", label="demanded (each step)")
        zoom.step(t[last], trace[u + "_act"][last], where="post", lw=0.9, color="C1", label="realised (held)")
        mark_spans(zoom, near)
        zoom.set_ylabel(f"{u} [N]")
        for a in (ax, zoom):
            a.grid(alpha=0.3)
    legend_above(axs[0, 0])
    axs[0, 1].set_title(f"last {ZOOM_S:g} s, step by step", fontsize=9, loc="left")
    axs[-1, 0].set_xlabel("t [s]")
    axs[-1, 1].set_xlabel("t [s]")
    axs[-1, 1].xaxis.set_major_locator(plt.MaxNLocator(3))
    return fig


def _path3d(plt: Any, trace: dict[str, np.ndarray]) -> Any:
    fig = plt.figure(figsize=(7, 6), dpi=DPI)
    ax = fig.add_subplot(projection="3d")
    ax.plot(trace["x"], trace["y"], trace["z"], label="flown")
    ax.plot(trace["x_ref"], trace["y_ref"], trace["z_ref"], "--", label="reference")
    for axis, name in ((ax.xaxis, "x"), (ax.yaxis, "y"), (ax.zaxis, "z")):
        axis.set_major_locator(plt.MaxNLocator(5))  # the default's 9 ticks of 0.25 m overlap on a 2 m span
        axis.set_tick_params(labelsize=8)
        axis.set_label_text(f"{name} [m]")
    # the 3-D box fills the axes; the figure's top-left corner is clear of it
    fig.legend(*ax.get_legend_handles_labels(), loc="upper left", bbox_to_anchor=(0.02, 0.95), fontsize=9,
               frameon=False)
    return fig


def _estimate_figure(plt: Any, trace: dict[str, np.ndarray], spans: Sequence[Span]) -> Any:
    """The estimate against the truth: one row per quantity (left: both; right: the error), NEES below."""
    t = trace["t"]
    e = estimation_errors(trace)
    fig = plt.figure(figsize=(11, 13.5), dpi=DPI)
    n = len(ESTIMATED)  # rows 0..n-1 the quantities, n a spacer (the time labels above, the NEES legend below)
    grid = fig.add_gridspec(n + 2, 2, height_ratios=(1,) * n + (0.15, 1.4))
    first = None
    for i, (a, unit) in enumerate(ESTIMATED):
        bottom = i == n - 1
        ax = fig.add_subplot(grid[i, 0], sharex=first)
        first = first or ax
        mark_spans(ax, spans, label=i == 0)
        ax.plot(t, trace[a], label="true")
        ax.plot(t, trace[a + "_est"], "--", label="estimated")
        ax.set_ylabel(f"{a} [{unit}]")
        if i == 0:
            legend_above(ax)
        err = fig.add_subplot(grid[i, 1], sharex=first)
        mark_spans(err, spans)
        rms = float(np.sqrt(np.nanmean(e[a] ** 2))) if np.any(np.isfinite(e[a])) else float("nan")
        err.plot(t, e[a], color="C3", lw=0.8, label=f"true - estimated (RMS {rms:.3g} {unit})")
        err.set_ylabel(f"error {a} [{unit}]")
        legend_above(err)
        for p in (ax, err):
            p.grid(alpha=0.3)
            p.tick_params(labelbottom=bottom)
            if bottom:
                p.set_xlabel("t [s]")
    _nees_panel(fig.add_subplot(grid[n + 1, :], sharex=first), trace, spans)
    return fig


def _nees_panel(ax: Any, trace: dict[str, np.ndarray], spans: Sequence[Span]) -> None:
    """NEES samples after t = 0 (the filter starts on the truth: its first NEES is ~0 and says nothing), on a
    log axis clipped to the band widened to the 1st..99th percentiles (the samples beyond it are counted)."""
    t = trace["t"]
    nees = np.asarray(trace.get("nees", np.full(len(t), np.nan)))
    sampled = np.isfinite(nees) & (t > t[0])
    ax.set_yscale("log")
    mark_spans(ax, spans)
    handles = []
    if sampled.any():
        v = np.maximum(nees[sampled], 1e-3)
        lo = min(NEES_BAND[0] / 2.0, float(np.percentile(v, 1.0)))
        hi = max(NEES_BAND[1] * 2.0, float(np.percentile(v, 99.0)))
        off = int(((v < lo) | (v > hi)).sum())
        note = f", {off} beyond the axis" if off else ""
        handles += ax.plot(t[sampled], np.clip(v, lo, hi), ".", ms=2,
                           label=f"NEES after t = 0 (mean {float(nees[sampled].mean()):.3g}{note})")
        ax.set_ylim(lo / 1.1, hi * 1.1)
        ticks = [v for v in (0.01, 0.1, 1.0, NEES_BAND[0], NEES_DOF, NEES_BAND[1], 100.0, 1000.0) if lo <= v <= hi]
        ax.set_yticks(ticks, [f"{v:g}" for v in ticks])
        ax.yaxis.set_minor_formatter("")
    for q in NEES_BAND:
        ax.axhline(q, color="k", ls="--", lw=0.8)
    handles.append(ax.axhline(NEES_DOF, color="k", lw=0.8,
                              label=f"chi-square({NEES_DOF}): mean {NEES_DOF}, 95 % band dashed"))
    ax.set_ylabel("NEES [-]")
    ax.set_xlabel("t [s]")
    legend_above(ax, handles, [h.get_label() for h in handles])
    ax.grid(alpha=0.3)
