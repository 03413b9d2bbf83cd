"""Covers bridge.record.plots, bridge.record.linkplots and bridge.sweep.report: the figures.

Read as matplotlib objects (not pixels): every axis label has its unit, legends sit inside the figure and
off the data (checked in display coordinates after a draw), the dpi and size are the stated ones,
blackouts and failsafes are marked, the inputs' close-up shows each control step, the 3-D path's tick labels
do not overlap, the estimate's NEES axis is not stretched by its t = 0 sample, a lossless link trace says so,
heat maps have readable text and a colour scale per law (a sweep with a plug-in law writing its maps, as
real processes, is in test_sweep.py).
"""

from __future__ import annotations

import gc
import os
import struct
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from bridge import simulate
from bridge.core.flight import prepare
from bridge.link.trace import read_trace
from bridge.record.linkplots import link_trace_figure
from bridge.record.plots import DPI, ZOOM_S, Span, figures, heap_frozen, make_plots, run_spans
from bridge.record.runlog import blackout_windows
from bridge.sweep.report import HEAT_DPI, HEAT_TEXT_PT, controller_files, heat_map_figure, pair_title
from missions import Mission, Sine


@pytest.fixture(scope="module", autouse=True)
def _agg() -> None:
    """matplotlib on its file backend, imported by the worker that runs these tests only (~0.7 s of each
    worker's collection otherwise)."""
    import matplotlib  # lazy: see the docstring

    matplotlib.use("Agg")


def _close(fig: object) -> None:
    import matplotlib.pyplot as plt  # lazy: as _agg

    plt.close(fig)

ROOT = Path(__file__).resolve().parent.parent
# the paper's explicit step, asked for by name: its u4 alternates every step (the implicit default's does not),
# which the inputs' close-up must show as it is
SHORT = Mission(Sine(), duration_s=8.0, name="short", discretization="explicit")
BLACKOUT = (3.0, 2.0)  # s: long enough for the vehicle's failsafe (0.5 s without targets)
UNIT = ("[m]", "[rad]", "[N]", "[s]", "[-]")


@pytest.fixture(scope="module")
def clean() -> dict:
    return simulate(SHORT, plots=False).trace


@pytest.fixture(scope="module")
def cut() -> tuple[dict, list[Span]]:
    """A flight through a link blackout that ends in the vehicle's failsafe: its trace and spans."""
    link = {"up": {"blackouts": [list(BLACKOUT)]}, "down": {"blackouts": [list(BLACKOUT)]}}
    run = simulate(SHORT, plots=False, link=link)
    assert run.outcome == "failsafe"
    windows = blackout_windows(prepare(SHORT, link=link).mission)
    return run.trace, run_spans(run.summary["events"], windows, float(run.trace["t"][-1]))


@pytest.fixture(scope="module")
def estimated() -> dict:
    return simulate(SHORT, plots=False, sensors={"set": "mocap"}, estimator="ekf").trace


def _drawn(figs: dict) -> Iterator[dict]:
    """``figs``, each drawn once (the legends laid out, the 3-D projection made: extents are final), for the module's
    tests to read (none changes a figure); closed after the module's last test. Each set was built and drawn by
    every test that read it (the clean flight's five times, the estimate's three: half of the module's 6.5 CPU-s)."""
    try:
        for fig in figs.values():
            fig.canvas.draw()
        yield figs
    finally:
        for fig in figs.values():
            _close(fig)


@pytest.fixture(scope="module")
def clean_figs(clean: dict) -> Iterator[dict]:
    """The clean flight's figures, by name, drawn."""
    yield from _drawn(figures(clean))


@pytest.fixture(scope="module")
def cut_figs(cut: tuple) -> Iterator[dict]:
    """The figures of the flight through the blackout, its spans marked, by name, drawn."""
    trace, spans = cut
    yield from _drawn(figures(trace, "cut", spans))


@pytest.fixture(scope="module")
def estimate_fig(estimated: dict) -> Iterator[object]:
    """The estimated flight's ``estimate`` figure, drawn (its other figures closed at once)."""
    figs = figures(estimated)
    keep = figs.pop("estimate")
    for fig in figs.values():
        _close(fig)
    for drawn in _drawn({"estimate": keep}):
        yield drawn["estimate"]


def _data_axes(fig) -> list:
    return [ax for ax in fig.axes if ax.lines or ax.images or ax.collections]


def _display_points(ax) -> np.ndarray:
    """Every vertex of every line and collection of ``ax``, in display pixels."""
    pts = [line.get_xydata() for line in ax.lines]
    pts += [path.vertices for c in ax.collections for path in c.get_paths()]
    xy = np.concatenate([p for p in pts if len(p)]) if pts else np.empty((0, 2))
    xy = xy[np.all(np.isfinite(xy), axis=1)]
    return ax.transData.transform(xy) if len(xy) else xy


def _texts(fig) -> list:
    """The visible, non-empty text of a figure: titles, axis labels, tick labels."""
    out = [fig._suptitle] if fig._suptitle is not None else []
    for ax in fig.axes:
        out += [ax.title, ax._left_title, ax._right_title]
        axes = [ax.xaxis, ax.yaxis] + ([ax.zaxis] if hasattr(ax, "zaxis") else [])
        for axis in axes:
            out += [axis.label] + [t.label1 for t in axis.get_major_ticks()]
    return [t for t in out if t.get_visible() and t.get_text()]


def _legends(fig) -> list:
    return [ax.get_legend() for ax in fig.axes if ax.get_legend() is not None] + list(fig.legends)


def _check_legends(name: str, fig) -> int:
    r = fig.canvas.get_renderer()
    whole = fig.bbox
    legends = _legends(fig)
    if not legends:
        return 0
    points = [(ax, _display_points(ax)) for ax in fig.axes]  # once per figure: the same for every legend
    texts = [(t.get_text(), t.get_window_extent(r)) for t in _texts(fig)]
    for leg in legends:
        box = leg.get_window_extent(r)
        assert whole.x0 <= box.x0 and box.x1 <= whole.x1 and whole.y0 <= box.y0 and box.y1 <= whole.y1, name
        for ax, xy in points:
            inside = (xy[:, 0] > box.x0) & (xy[:, 0] < box.x1) & (xy[:, 1] > box.y0) & (xy[:, 1] < box.y1)
            assert not inside.any(), f"{name}: legend {[t.get_text() for t in leg.texts]} covers data of {ax}"
        for text, extent in texts:
            assert not box.overlaps(extent), f"{name}: legend over the text {text!r}"
    return len(legends)


def test_every_axis_label_carries_its_unit(clean_figs: dict, estimate_fig: object) -> None:
    for name, fig in (clean_figs | {"estimate": estimate_fig}).items():  # 6 at once
        for ax in _data_axes(fig):
            assert any(u in ax.get_ylabel() for u in UNIT), (name, ax.get_ylabel())
            if ax.name != "3d" and any(t.get_visible() and t.get_text() for t in ax.get_xticklabels()):
                assert ax.get_xlabel() == "t [s]", (name, ax.get_ylabel())
        if name == "inputs":  # u2..u4 are N like u1: the plant applies l·u N·m
            labels = [ax.get_ylabel() for ax in fig.axes]
            assert labels[0] == "u1 [N]" and all(f"{u} [N]" in s and "N·m" in s for u, s in
                                                 zip(("u2", "u3", "u4"), labels[2::2], strict=True))
        if name == "errors":
            assert [ax.get_ylabel() for ax in fig.axes] == [
                "x - x_ref [m]", "y - y_ref [m]", "z - z_ref [m]", "psi - psi_ref [rad]"]
        if name == "path3d":
            ax = fig.axes[0]
            assert (ax.get_xlabel(), ax.get_ylabel(), ax.get_zlabel()) == ("x [m]", "y [m]", "z [m]")


def test_legends_are_inside_the_figure_and_off_the_data(clean_figs: dict, cut_figs: dict,
                                                       estimate_fig: object) -> None:
    n = 0
    for figs in (clean_figs, {f"{k} (cut)": f for k, f in cut_figs.items()}, {"estimate": estimate_fig}):
        for name, fig in figs.items():
            n += _check_legends(name, fig)
    assert n >= 20  # positions, errors (cut), angles x3, inputs, path3d, estimate x7, ...


@pytest.fixture(scope="module")
def written(clean: dict, tmp_path_factory: pytest.TempPathFactory) -> tuple[list[Path], list[int], int, int]:
    """The clean flight's figures written by make_plots (one set, ~1 CPU-s, for the two tests that read it: their
    files, and the heap's freeze count at each collection the drawing set off), and the freeze count before and
    after. Each collection's count walks the whole frozen heap (~35 ms in a test worker): at the default threshold's
    ~170 young collections that was 6 CPU-s, so the drawing sets off a tenth as many here (a young collection every
    7 000 allocations, not 700), each of them still checked."""
    seen: list[int] = []

    def note(phase: str, info: dict) -> None:
        if phase == "start":
            seen.append(gc.get_freeze_count())

    before = gc.get_freeze_count()
    thresholds = gc.get_threshold()
    gc.set_threshold(7000, *thresholds[1:])
    gc.callbacks.append(note)
    try:
        paths = make_plots(clean, tmp_path_factory.mktemp("plots"), "short")
    finally:
        gc.callbacks.remove(note)
        gc.set_threshold(*thresholds)
    return paths, seen, before, gc.get_freeze_count()


def test_the_figures_are_written_at_their_dpi(clean_figs: dict, written: tuple) -> None:
    sizes = {name: fig.get_size_inches() for name, fig in clean_figs.items()}
    assert all(fig.dpi == DPI for fig in clean_figs.values())
    paths = written[0]
    assert sorted(p.stem for p in paths) == sorted(clean_figs)
    for p in paths:
        head = p.read_bytes()[:24]
        assert head[:8] == b"\x89PNG\r\n\x1a\n"
        w, h = struct.unpack(">II", head[16:24])
        want = sizes[p.stem] * DPI
        assert (w, h) == (round(want[0]), round(want[1])), p.name


def test_figures_are_drawn_with_the_heap_before_them_frozen(written: tuple) -> None:
    """The collections matplotlib sets off while drawing skip the heap that was there before (frozen, then given
    back); a heap frozen already, as a fork server's child has it, stays frozen (heap_frozen, which make_plots
    draws in: the figures of ``written``)."""
    _, seen, before, after = written
    assert before == 0  # a test worker freezes nothing
    assert len(seen) >= 5, seen  # (collections while drawing: not one by chance)
    assert seen and min(seen) > 0
    assert after == 0
    assert gc.get_freeze_count() == 0
    gc.freeze()  # as bridge.nodes.forkserver before it forks a child
    frozen = gc.get_freeze_count()
    try:
        with heap_frozen() as freeze_more:
            made = [[i] for i in range(1000)]  # (objects a gc tracks, made inside: left unfrozen)
            freeze_more()
            assert gc.get_freeze_count() <= frozen  # the block's own objects not frozen with the server's
        assert gc.get_freeze_count() > frozen // 2 and made  # not thawed (a thaw empties it; a few frozen objects die)
    finally:
        gc.unfreeze()


def test_inputs_show_each_step_of_the_last_tenth_of_a_second(clean: dict, clean_figs: dict) -> None:
    """A sign that alternates every step fills the whole-flight panel; the close-up has one demanded point per
    control step, and the realised input held (a step line) in another style."""
    t = clean["t"]
    last = t >= t[-1] - ZOOM_S
    fig = clean_figs["inputs"]
    zooms = fig.axes[1::2]
    assert len(zooms) == 4
    for ax, u in zip(zooms, ("u1", "u2", "u3", "u4"), strict=True):
        demanded, realised = ax.lines
        assert np.array_equal(demanded.get_ydata(), clean[u][last])  # every step's value, none skipped
        assert demanded.get_linestyle() == "None" and demanded.get_marker() == "o"
        assert realised.get_drawstyle() == "steps-post" and np.array_equal(realised.get_ydata(),
                                                                           clean[u + "_act"][last])
        lo, hi = ax.get_xlim()
        assert hi - lo < 1.5 * ZOOM_S
    # the law's u4 does alternate here: the close-up shows it as it is
    assert np.all(np.diff(np.sign(clean["u4"][last])) != 0)


def _columns(ax, x: np.ndarray) -> np.ndarray:
    """The pixel column each time ``x`` falls in, on ``ax`` as drawn."""
    x0, x1 = ax.get_xlim()
    return np.floor(ax.bbox.x0 + (x - x0) * (ax.bbox.width / (x1 - x0))).astype(np.int64)


def test_long_lines_are_thinned_to_what_each_pixel_column_shows(clean: dict, clean_figs: dict) -> None:
    """A time axis's solid line keeps, of each pixel column's samples, the first, lowest, highest and last: the same
    extent in every column (the law's u4, alternating every step, still fills its band), the same ends, fewer
    points than rows where the columns hold several samples. A dashed line keeps every row (cut, its dash gaps
    would show the line under it where it fills a band)."""
    t = clean["t"]
    shown = {"positions": [(a, a + "_ref") for a in ("x", "y", "z", "psi")],
             "angles": [("phi", "phi_d"), ("theta", "theta_d"), ("psi", "psi_ref")],
             "inputs": [(u, u + "_act") for u in ("u1", "u2", "u3", "u4")]}
    thinned = 0
    for name, columns in shown.items():
        axes = clean_figs[name].axes[::2] if name == "inputs" else clean_figs[name].axes
        for ax, keys in zip(axes, columns, strict=True):
            for line, key in zip(ax.lines, keys, strict=True):
                x, y = np.asarray(line.get_xdata()), np.asarray(line.get_ydata())
                assert x[0] == t[0] and x[-1] == t[-1] and y[0] == clean[key][0] and y[-1] == clean[key][-1]
                full, drawn = _columns(ax, t), _columns(ax, x)
                for agg in (np.minimum, np.maximum):
                    cut = np.flatnonzero(np.r_[True, drawn[1:] != drawn[:-1]])
                    whole = np.flatnonzero(np.r_[True, full[1:] != full[:-1]])
                    assert np.array_equal(drawn[cut], full[whole]), (name, key)  # no column lost
                    assert np.array_equal(agg.reduceat(y, cut), agg.reduceat(clean[key], whole)), (name, key)
                if line.get_linestyle() != "-":
                    assert len(x) == len(t), (name, key)
                thinned += len(x) < len(t)
    assert thinned >= 7  # positions' and angles' flown lines at least: two samples a column where they held ~3.5


def test_path3d_tick_labels_do_not_overlap(clean_figs: dict) -> None:
    fig = clean_figs["path3d"]
    r = fig.canvas.get_renderer()
    ax = fig.axes[0]
    for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
        boxes = [t.label1.get_window_extent(r) for t in axis.get_major_ticks()
                 if t.label1.get_visible() and t.label1.get_text()]
        assert len(boxes) >= 3
        for i, b in enumerate(boxes):
            assert not any(b.overlaps(c) for c in boxes[i + 1:]), axis.get_label_text()


def test_blackout_and_failsafe_are_marked(cut: tuple, cut_figs: dict) -> None:
    trace, spans = cut
    kinds = [s.kind for s in spans]
    assert kinds == ["blackout", "failsafe"]
    blackout, failsafe = spans
    assert (blackout.start_s, blackout.end_s) == (BLACKOUT[0], BLACKOUT[0] + BLACKOUT[1])
    assert BLACKOUT[0] < failsafe.start_s < BLACKOUT[0] + 1.0 and failsafe.end_s > failsafe.start_s
    for name, fig in ((k, f) for k, f in cut_figs.items() if k != "path3d"):
        time_axes = [ax for ax in fig.axes if ax.get_xlabel() == "t [s]" or ax.get_shared_x_axes().joined(
            ax, fig.axes[0])]
        for ax in time_axes:
            lo, hi = ax.get_xlim()  # the inputs' close-ups shade what falls in their last 0.1 s
            shaded = sorted((round(p.get_x(), 6), round(p.get_x() + p.get_width(), 6)) for p in ax.patches)
            assert shaded == [(max(s.start_s, lo), s.end_s) for s in spans if s.end_s > lo], (name, ax.get_ylabel())
        labels = [t.get_text() for leg in _legends(fig) for t in leg.texts]
        assert "link blackout" in labels and "failsafe" in labels, name


def test_run_spans_end_a_failsafe_where_the_vehicle_leaves_it() -> None:
    ev = [{"t": 5.0, "kind": "failsafe", "text": ""}, {"t": 6.0, "kind": "policy", "text": ""},
          {"t": 7.5, "kind": "armed", "text": ""}, {"t": 9.0, "kind": "failsafe", "text": ""}]
    assert run_spans(ev, [(4.0, 1.0), (4.0, 1.0), (12.0, 5.0)], 10.0) == [
        Span("blackout", 4.0, 5.0), Span("failsafe", 5.0, 7.5), Span("failsafe", 9.0, 10.0)]


def test_estimate_error_panels_have_time_and_nees_skips_t0(estimate_fig: object) -> None:
    fig = estimate_fig
    errors = [ax for ax in fig.axes if ax.get_ylabel().startswith("error ")]
    assert len(errors) == 6 and errors[-1].get_xlabel() == "t [s]"
    assert all(ax.get_shared_x_axes().joined(ax, errors[-1]) for ax in errors)
    nees = next(ax for ax in fig.axes if ax.get_ylabel() == "NEES [-]")
    assert nees.get_xlabel() == "t [s]"
    points = nees.lines[0]
    assert np.all(points.get_xdata() > 0.0)
    lo, hi = nees.get_ylim()
    assert lo > 0.5 and hi < 200.0  # the t = 0 sample (~0.005) no longer sets the axis


def test_a_lossless_trace_says_it_lost_nothing(tmp_path: Path) -> None:
    f = tmp_path / "clean.csv"
    f.write_text("t_s,delay_ms\n" + "".join(f"{k / 100:g},{30 + k % 7}\n" for k in range(500)))
    fig = link_trace_figure(read_trace(f))
    try:
        fig.canvas.draw()
        loss = fig.axes[1]
        assert not loss.collections and any("no loss" in t.get_text() for t in loss.texts)
        assert loss.get_xlim() == fig.axes[0].get_xlim()
        assert _check_legends("link trace", fig) == 2 and fig.dpi == DPI
    finally:
        _close(fig)


def _row(controller: str, delay: float, loss: float, rms: float) -> dict:
    return {"controller": controller, "rate_hz": 250.0, "delay_ms": delay, "jitter_ms": 0.0, "loss_pct": loss,
            "burst_len": 0.0, "estimator": "truth", "noise": 1.0, "seed": 0, "rms": rms, "ripple_u2": 0.1,
            "outcome": "completed"}


def test_heat_maps_are_readable_with_a_colour_scale_per_law() -> None:
    from bridge.sweep.classes import Classes

    scale = {"bsst": 1e-5, "smc": 1e-3, "pid": 0.021}
    rows = [_row(c, d, p, s * (1 + 0.1 * i)) for c, s in scale.items()
            for i, (d, p) in enumerate((d, p) for d in (0.0, 10.0, 20.0) for p in (0.0, 5.0))]
    fig = heat_map_figure(rows, "delay_ms", "loss_pct", list(scale), Classes())
    try:
        fig.canvas.draw()
        w, h = fig.get_size_inches() * fig.dpi
        assert fig.dpi == HEAT_DPI >= 100 and w > 3 * 480 and h > 328
        panels = [ax for ax in fig.axes if ax.images]
        assert [ax.get_title() for ax in panels] == list(scale)
        for ax, s in zip(panels, scale.values(), strict=True):
            norm = ax.images[0].norm  # the law's own scale: from its best to its worst cell
            assert (norm.vmin, norm.vmax) == pytest.approx((s, s * 1.5))
            assert len(ax.texts) == 6 and all(t.get_fontsize() >= HEAT_TEXT_PT >= 9 for t in ax.texts)
        bars = [ax for ax in fig.axes if not ax.images]
        assert len(bars) == 3 and all("[m]" in ax.get_ylabel() for ax in bars)
        assert fig._suptitle.get_text().startswith("delay_ms x loss_pct")
    finally:
        _close(fig)


def test_a_one_axis_sweep_is_titled_by_its_axis() -> None:
    rows = [_row("bsst", d, 0.0, 1e-3) for d in (0.0, 10.0)]
    assert pair_title(rows, "delay_ms", "loss_pct") == "delay_ms (at loss_pct = 0 %)"
    assert pair_title(rows + [_row("bsst", 0.0, 5.0, 1e-3)], "delay_ms", "loss_pct") == "delay_ms x loss_pct"


def test_file_names_of_laws_are_safe_and_unique() -> None:
    names = controller_files(["bsst", "examples/my_law.py:MyLaw", "a/b:C", "a_b:C", "a-b:C", "..", "a:b/c"])
    assert names["bsst"] == "bsst" and names["examples/my_law.py:MyLaw"] == "examples-my_law-py-MyLaw"
    assert len(set(names.values())) == len(names)
    for v in names.values():
        assert v and "/" not in v and not v.startswith(".") and v == os.path.basename(v)
