"""The run's figures, like the paper's Figs. 1-10: positions with references, tracking
errors, angles (with the desired roll and pitch), inputs, and the 3-D path.

In:  trace arrays by column (t s, positions m, angles rad, inputs demanded and realised N), a
     directory, a title
Out: ``positions.png``, ``errors.png``, ``angles.png``, ``inputs.png``, ``path3d.png`` in it, and
     their paths
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from bridge.record.metrics import errors


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
        fig.tight_layout()
        p = out / f"{name}.png"
        fig.savefig(p, dpi=90)
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
    return written
