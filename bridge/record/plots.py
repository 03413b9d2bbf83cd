"""The run's figures, like the paper's Figs. 1-10: positions with references, tracking
errors, angles (with the desired roll and pitch), inputs, and the 3-D path.

In:  trace arrays by column (t s, positions m, angles rad, inputs demanded and realised N), a
     directory, a title
Out: ``positions.png``, ``errors.png``, ``angles.png``, ``inputs.png``, ``path3d.png`` in it, and
     their paths; when the vehicle flew on an estimate (an estimator other than ``truth``: the
     ``*_est`` columns differ from the truth) also ``estimate.png``: x, y, z, φ, θ, ψ true and
     estimated, the estimate's error (true − estimated, ψ wrapped), and its NEES against the χ²(9)
     band (the covariance itself is not in the trace, only this consistency figure)
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from bridge.record.metrics import errors

ESTIMATED = (("x", "m"), ("y", "m"), ("z", "m"), ("phi", "rad"), ("theta", "rad"), ("psi", "rad"))
NEES_DOF = 9  # position, velocity, attitude: bridge.autopilot.estimator.nees
NEES_BAND = (2.70, 19.02)  # the chi-square(9) 2.5 % and 97.5 % quantiles: 95 % of a consistent filter's NEES


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


def make_plots(trace: dict[str, np.ndarray], out: str | Path, title: str = "") -> list[Path]:
    """Write ``positions.png, errors.png, angles.png, inputs.png, path3d.png`` into ``out``."""
    import matplotlib  # lazy: matplotlib costs start-up time and is needed only for figures

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # lazy: as matplotlib

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t = trace["t"]
    written: list[Path] = []

    def save(fig, name: str) -> None:
        fig.suptitle(f"{title} — {name}" if title else name)
        if name != "path3d":  # fixed margins: tight_layout's measuring pass cost a third of the figures' time
            fig.subplots_adjust(left=0.11, right=0.97, bottom=0.07, top=0.93, hspace=0.22, wspace=0.28)
        p = out / f"{name}.png"
        fig.savefig(p, dpi=90, pil_kwargs={"compress_level": 1})
        plt.close(fig)
        written.append(p)

    fig, axs = plt.subplots(4, 1, figsize=(8, 8), sharex=True)
    for ax, a, unit in zip(axs, ("x", "y", "z", "psi"), ("m", "m", "m", "rad"), strict=True):
        ax.plot(t, trace[a], label=a)
        ax.plot(t, trace[a + "_ref"], "--", label=a + " ref")
        ax.set_ylabel(f"{a} [{unit}]")
        ax.legend(loc="upper right", fontsize=8)
        ax.grid(alpha=0.3)
    axs[-1].set_xlabel("t [s]")
    save(fig, "positions")

    e = errors(trace)
    fig, axs = plt.subplots(4, 1, figsize=(8, 8), sharex=True)
    for ax, a in zip(axs, ("x", "y", "z", "psi"), strict=True):
        ax.plot(t, e[a])
        ax.set_ylabel(f"e_{a}")
        ax.grid(alpha=0.3)
    axs[-1].set_xlabel("t [s]")
    save(fig, "errors")

    fig, axs = plt.subplots(3, 1, figsize=(8, 7), sharex=True)
    for ax, a, d in zip(axs, ("phi", "theta", "psi"), ("phi_d", "theta_d", "psi_ref"), strict=True):
        ax.plot(t, trace[a], label=a)
        if d in trace:
            ax.plot(t, trace[d], "--", label=d)
        ax.set_ylabel(f"{a} [rad]")
        ax.legend(loc="upper right", fontsize=8)
        ax.grid(alpha=0.3)
    axs[-1].set_xlabel("t [s]")
    save(fig, "angles")

    fig, axs = plt.subplots(4, 1, figsize=(8, 8), sharex=True)
    for ax, u in zip(axs, ("u1", "u2", "u3", "u4"), strict=True):
        ax.plot(t, trace[u], label=f"{u} demanded")
        ax.plot(t, trace[u + "_act"], "--", label=f"{u} realised")
        ax.set_ylabel(u)
        ax.legend(loc="upper right", fontsize=8)
        ax.grid(alpha=0.3)
    axs[-1].set_xlabel("t [s]")
    save(fig, "inputs")

    fig = plt.figure(figsize=(7, 6))
    ax = fig.add_subplot(projection="3d")
    ax.plot(trace["x"], trace["y"], trace["z"], label="flown")
    ax.plot(trace["x_ref"], trace["y_ref"], trace["z_ref"], "--", label="reference")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_zlabel("z [m]")
    ax.legend()
    save(fig, "path3d")

    if has_estimate(trace):
        save(_estimate_figure(plt, trace), "estimate")
    return written


def _estimate_figure(plt, trace: dict[str, np.ndarray]):
    """The estimate against the truth: one row per quantity (left: both; right: the error), NEES below."""
    t = trace["t"]
    e = estimation_errors(trace)
    fig = plt.figure(figsize=(11, 13))
    grid = fig.add_gridspec(len(ESTIMATED) + 1, 2)
    first = None
    for i, (a, unit) in enumerate(ESTIMATED):
        ax = fig.add_subplot(grid[i, 0], sharex=first)
        first = first or ax
        ax.plot(t, trace[a], label=f"{a} true")
        ax.plot(t, trace[a + "_est"], "--", label=f"{a} estimated")
        ax.set_ylabel(f"{a} [{unit}]")
        ax.legend(loc="upper right", fontsize=8)
        ax.grid(alpha=0.3)
        ax = fig.add_subplot(grid[i, 1], sharex=first)
        rms = float(np.sqrt(np.nanmean(e[a] ** 2))) if np.any(np.isfinite(e[a])) else float("nan")
        ax.plot(t, e[a], color="C3", lw=0.8, label=f"true - estimated (RMS {rms:.3g} {unit})")
        ax.set_ylabel(f"error {a} [{unit}]")
        ax.legend(loc="upper right", fontsize=8)
        ax.grid(alpha=0.3)
    ax = fig.add_subplot(grid[len(ESTIMATED), :], sharex=first)
    nees = np.asarray(trace.get("nees", np.full(len(t), np.nan)))
    sampled = np.isfinite(nees)
    ax.set_yscale("log")
    if sampled.any():
        mean = float(nees[sampled].mean())
        ax.plot(t[sampled], np.maximum(nees[sampled], 1e-3), ".", ms=2, label=f"NEES (mean {mean:.3g})")
    for q in NEES_BAND:
        ax.axhline(q, color="k", ls="--", lw=0.8)
    ax.axhline(NEES_DOF, color="k", lw=0.8, label=f"chi-square({NEES_DOF}): mean {NEES_DOF}, 95 % band dashed")
    ax.set_ylabel("NEES")
    ax.set_xlabel("t [s]")
    ax.legend(loc="upper right", fontsize=8)
    ax.grid(alpha=0.3)
    return fig
