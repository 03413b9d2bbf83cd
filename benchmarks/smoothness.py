"""Issue 24's table: the explicit and the implicit super-twisting step side by side.

Every flight is the product's offline loop (``bridge.simulate``, what ``bsst sim MISSION --discretization D``
flies), paper profile, seed 0, one flight per cell (the figures are the same every time):

- ``sine`` (missions/sine.toml) at 250 Hz, 100 Hz and 1 kHz: the period-2 component of u2, u3, u4
  (``summary.json`` ``inputs.uN.period2``: mean of |u[k] - 2u[k+1] + u[k+2]| / 4 over t >= 10 s, N), their
  total variation per second (``tv_per_s``, whole flight, N/s) and the 3-D RMS over t >= 10 s (m);
- ``step``: per axis the settling time (the largest over the 3 changes, ``settling_s``) and the steady error
  (the largest |e| over the last 2 s of each segment, m or rad): the acceptance of tests/test_scenarios.py;
- ``robust`` and ``robust-x500``: the 3-D RMS;
- smoothness against SMC (``--controller smc``, whose sign reaching has no super-twisting step: the same in
  both columns): on the step mission the total variation per second of u2 and u3 over the last 5 s of each
  segment (tests/test_scenarios.py's measure, docs/figures.md's "smoothness against SMC"), SMC's over
  BS-ST's, the smallest of the 6 ratios;
- sensors (docs/sensors.md's table, benchmarks/estimation.py's flight): the sine with ``mocap`` sensors and
  the ``raw`` and ``ekf`` estimators: the 3-D RMS and the u2 ripple (0.1 s window);
- ``bsst margin missions/sine.toml --over delay_ms --until rms=0.1`` with and without
  ``--compensation predict`` (a real ``bsst`` process each, margin.json read back), ms.

``--scan`` prints instead the sine's 3-D RMS at every whole millisecond of one-way delay (both directions, as
``bsst margin`` flies it; the link delivers on the 1 kHz physics clock, so a delay flies as the next whole
millisecond and this is the whole curve), 30-40 ms without and 50-60 ms with ``--compensation predict``, both
schemes: the bisection of ``bsst margin`` assumes the RMS grows with the delay, and it does not (docs/law.md,
"The delay margin, scanned"). ``--scan --implicit-virtual-controls`` scans the implicit scheme with its virtual
controls stepped implicitly too (:func:`implicit_virtual_controls`: an experiment patched into the scalar loop
here, not a scheme of the product). ``--implicit-horizon LAM`` flies the implicit scheme with its step solved over
LAM periods (:func:`implicit_horizon`, the same kind of experiment), the scan or the table (its margins by
``bsst margin``'s bisection in this process, without the check below). ``--two-step-deadbeat`` flies the implicit
scheme with its integrator stepped on the measured s_k first (:func:`two_step_deadbeat`, the same kind).

``--ensemble`` runs ``bsst margin``'s search (with its check below) on the sine with its centre moved along x by
-10 to +10 mm (the vehicle starts that far off its path), both schemes, and counts at 33-37 ms how many of those
flights hold (:func:`ensemble`; docs/law.md, "One initial condition"): a margin of one flight is one draw.

Acceptance (issue 24): implicit sine 250 Hz period-2 <= 0.01 N (u2, u3, u4), TV <= 35 /s (u2, u3), RMS <= 1e-5
m, 100 Hz period-2 <= 0.02 N; step settling <= 5 s and steady error <= 1 mm; robust <= 6 cm; smoothness
against SMC >= 20x; the delay margin at least the explicit law's.

``--figure PATH`` draws docs/u2-explicit-vs-implicit.png instead: u2 of the sine at 250 Hz over
t in [20, 20.1) s, both schemes.

    .venv/bin/python benchmarks/smoothness.py [--no-margin] [--json]
    .venv/bin/python benchmarks/smoothness.py --figure docs/u2-explicit-vs-implicit.png
    .venv/bin/python benchmarks/smoothness.py --scan [--implicit-virtual-controls]
    .venv/bin/python benchmarks/smoothness.py [--scan] --implicit-horizon 4
    .venv/bin/python benchmarks/smoothness.py [--scan] --two-step-deadbeat
    .venv/bin/python benchmarks/smoothness.py --ensemble
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from estimation import flight  # noqa: E402  (the sensors table's own flight)

from bridge.loop import simulate  # noqa: E402
from bridge.record.metrics import errors  # noqa: E402
from controller import bsst  # noqa: E402
from controller.power import sig_derivs  # noqa: E402
from missions import DISCRETIZATIONS, Mission, load_mission  # noqa: E402

STEP_CHANGES = (0.0, 10.0, 20.0, 30.0)  # missions/step.toml's set-point times (s), as tests/test_scenarios.py
SMC_LAST_S = 5.0
STEADY_LAST_S = 2.0


def mission(name: str, d: str) -> Mission:
    return load_mission(ROOT / "missions" / f"{name}.toml").with_overrides(discretization=d)


def segment(t: np.ndarray, i: int, last_s: float) -> np.ndarray:
    return (t >= STEP_CHANGES[i + 1] - last_s) & (t < STEP_CHANGES[i + 1])


def sine(d: str, rate: float) -> dict[str, Any]:
    s = simulate(mission("sine", d), rate_hz=rate, plots=False).summary
    out: dict[str, Any] = {"rms_3d": s["rms_3d"], "outcome": s["outcome"]}
    for u in ("u2", "u3", "u4"):
        out[f"p2_{u}"] = s["inputs"][u]["period2"]
        out[f"tv_{u}"] = s["inputs"][u]["tv_per_s"]
    return out


def step(d: str, law: str = "bsst") -> tuple[dict[str, Any], dict[str, Any]]:
    run = simulate(mission("step", d), controller=law, plots=False)
    t, e = run.trace["t"], errors(run.trace)
    axes = {a: {"settling_s": v["settling_s"],
                "steady": max(float(np.max(np.abs(e[a][segment(t, i, STEADY_LAST_S)]))) for i in range(3))}
            for a, v in run.summary["axes"].items()}
    tv = {(u, i): float(np.abs(np.diff(run.trace[u][segment(t, i, SMC_LAST_S)])).sum() / SMC_LAST_S)
          for u in ("u2", "u3") for i in range(3)}
    return axes, tv


SCATTER = ("--seeds", "16", "--scatter", "0.01")  # the margin over initial conditions: 16 starts within 1 cm


def margin(d: str, predict: bool, scatter: bool = False) -> dict[str, Any]:
    """``bsst margin``'s margin.json: ``margin`` (the bisection's), ``holds_below``, ``monotone``, ``failed_below``;
    with ``scatter`` every one of :data:`SCATTER`'s starts must hold."""
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [sys.executable, "-m", "bridge", "margin", "missions/sine.toml", "--over", "delay_ms", "--until",
               "rms=0.1", "--discretization", d, "--out", tmp, "--overwrite", *(SCATTER if scatter else ())]
        if predict:
            cmd += ["--compensation", "predict"]
        subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=3600, check=False)
        f = Path(tmp) / "margin.json"
        found = json.loads(f.read_text()) if f.exists() else {}
        # one law: its entry; an interrupted search's (margin.json's "interrupted") is no figure
        res = found["controllers"][0] if found and not found["interrupted"] else {}
        return {k: res.get(k) for k in ("margin", "holds_below", "monotone", "failed_below")}


PATCHED: list[str] = []  # the experiment patched into this process's scalar loop (the margins then bisect here)
SCANS = {"none": range(30, 41), "predict": range(50, 61)}  # one-way delays (ms) around each margin


def delay_rms(d: str, delay_ms: float, predict: bool) -> float:
    """The sine's 3-D RMS (m) with ``delay_ms`` each way: the cell ``bsst margin --over delay_ms`` flies."""
    link: dict[str, Any] = {"up": {"delay_ms": delay_ms}, "down": {"delay_ms": delay_ms}}
    if predict:
        link["compensation"] = "predict"
    return simulate(mission("sine", d), link=link, plots=False).summary["rms_3d"]


def implicit_sig(e: float, P: tuple) -> tuple[float, float, float, float]:
    """F(e) = sig_beta(z(e)) and its three derivatives, z the backward-Euler step of e' = -c sig_beta(e) over h:
    z + a sig_beta(z) = e, a = h c (``P[10]``; a plain table without it: sig_beta itself). Newton from e, kept
    between 0 and e (z + a sig(z) - e is increasing in z), then the implicit function theorem:
    z1 = 1 / (1 + a sig1), z2 = -a sig2 z1^3, z3 = -a (sig3 z1^4 + 3 sig2 z1^2 z2) (zN the N-th derivative)."""
    if len(P) < 11:
        return sig_derivs(e, P)
    a, z = P[10], e
    for _ in range(60):
        f0, f1, _, _ = sig_derivs(z, P)
        zn = z - (z + a * f0 - e) / (1.0 + a * f1)
        if (zn < 0.0 or zn > e) if e >= 0.0 else (zn > 0.0 or zn < e):
            zn = 0.5 * z
        done = abs(zn - z) <= 1e-15 * (1.0 + abs(z))
        z = zn
        if done:
            break
    s0, s1, s2, s3 = sig_derivs(z, P)
    z1 = 1.0 / (1.0 + a * s1)
    z2 = -a * s2 * z1**3
    z3 = -a * (s3 * z1**4 + 3.0 * s2 * z1 * z1 * z2)
    return (s0, s1 * z1, s2 * z1 * z1 + s1 * z2, s3 * z1**3 + 3.0 * s2 * z1 * z2 + s1 * z3)


def implicit_virtual_controls() -> None:
    """Patch the scalar loop (this process only): an implicit law's five sig_beta tables carry a = h c of their
    step (yaw, z, position, velocity, attitude), and the law reads :func:`implicit_sig` for them."""
    init = bsst.BacksteppingSuperTwisting.__init__

    def patched(self: Any, *a: Any, **k: Any) -> None:
        init(self, *a, **k)
        if self.implicit:
            K = self.constants
            cs = (K.c_yaw, K.c_z, K.c_p, K.c_v, K.c_a)
            self.tables = tuple((*T, self.dt * c) for T, c in zip(self.tables, cs, strict=True))

    bsst.sig_derivs = implicit_sig
    bsst.BacksteppingSuperTwisting.__init__ = patched


def implicit_horizon(lam: float) -> None:
    """Patch the scalar loop (this process only): the implicit step solved over lam control periods H = lam h
    instead of one. The command is (s~ - s_k) / H, s~ the backward-Euler step of the super-twisting law over H
    (the dead zone's gain 1 / H: s shrinks by 1 - 1/lam a step there instead of reaching 0 in one), and xi moves
    by 1/lam of the step over H (outside the dead zone: -h k2 sign(w), as the scheme's own). lam = 1 is the
    product's scheme. An experiment, not a scheme of the product (docs/law.md, "The delay margin, scanned")."""
    from controller import supertwisting

    step = supertwisting.implicit_twisting

    def twisting(s: float, xi: float, k1: float, k2: float, h: float) -> tuple[float, float]:
        u, xi_h = step(s, xi, k1, k2, lam * h)
        return u, xi + (xi_h - xi) / lam

    def advance(xi: float, s: float, k1: float, k2: float, h: float, xi_max: float, hold: bool) -> float:
        x = xi if hold else twisting(s, xi, k1, k2, h)[1]
        return xi_max if x > xi_max else -xi_max if x < -xi_max else x

    bsst.implicit_twisting, bsst.advance_xi_implicit = twisting, advance


def two_step_deadbeat() -> None:
    """Patch the scalar loop (this process only): the integrator stepped implicitly on the measured s_k, then the
    root term implicitly on s alone, as if xi cancelled the disturbance exactly:
        xi_{k+1} = xi_k - h k2 Sign(q),  q + h^2 k2 Sign(q) contains s_k   (dead zone |s_k| <= h^2 k2: xi_k - s_k/h)
        u_k = -k1 |s~|^1/2 sign(s~) + xi_{k+1},  s~ + h k1 |s~|^1/2 sign(s~) = s_k
    Near s = 0 it is u_k = xi_k - 2 s_k/h, xi_{k+1} = xi_k - s_k/h: both poles of the nominal loop at 0 (deadbeat
    in two steps, s then left at h^2 times the disturbance's change over a step, the O(h^2) band of the
    explicit law without its cycle). An experiment, not a scheme of the product (docs/law.md, "The delay margin,
    scanned")."""

    def twisting(s: float, xi: float, k1: float, k2: float, h: float) -> tuple[float, float]:
        dz = h * h * k2
        xi1 = xi - s / h if -dz <= s <= dz else xi - h * k2 if s > 0.0 else xi + h * k2
        b, a = h * k1, abs(s)
        r = 2.0 * a / (b + np.sqrt(b * b + 4.0 * a)) if a > 0.0 else 0.0
        return (xi1 - k1 * r if s >= 0.0 else xi1 + k1 * r), xi1

    def advance(xi: float, s: float, k1: float, k2: float, h: float, xi_max: float, hold: bool) -> float:
        x = xi if hold else twisting(s, xi, k1, k2, h)[1]
        return xi_max if x > xi_max else -xi_max if x < -xi_max else x

    bsst.implicit_twisting, bsst.advance_xi_implicit = twisting, advance


def bisect(d: str, predict: bool) -> dict[str, Any]:
    """``bsst margin``'s bisection in this process (the process engine flies a round of one cell here: a
    patched scalar loop flies it), without the check below: the scan gives it."""
    from bridge.sweep.margin import margin as search
    from bridge.sweep.margin import parse_until

    m = mission("sine", d)
    if predict:
        m = m.with_overrides(link={"compensation": "predict"})
    r = search(m, "delay_ms", parse_until("rms=0.1"), engine="process", below=0.0)["controllers"][0]  # one law
    return {"margin": r["margin"], "holds_below": None, "monotone": None, "failed_below": None}


CENTRE_OFFSETS_M = (-0.01, -0.005, -0.002, 0.0, 0.002, 0.005, 0.01)  # --ensemble: the sine's centre moved along x
BAND_MS = (33, 34, 35, 36, 37)  # --ensemble: the one-way delays around the margins whose outcomes it counts


def ensemble(limit_m: float = 0.1, schemes: tuple[str, ...] = DISCRETIZATIONS) -> str:
    """``bsst margin``'s search (bisection, then its check below) on the sine with its centre moved along x by each
    of :data:`CENTRE_OFFSETS_M` (the vehicle starts that far off its path; 0 is the mission as it stands), both
    schemes, and at each delay of :data:`BAND_MS` how many of those flights hold: is one scheme's margin above the
    other's for the sine, or for one initial condition of it? With an experiment patched in, the searches fly
    in this process (its scalar loop), as :func:`bisect`'s, without the check below (``holds_below`` nan)."""
    from bridge.sweep.margin import margin as search
    from bridge.sweep.margin import parse_until

    heads = " | ".join(f"{x * 1e3:+g}" if x else "0" for x in CENTRE_OFFSETS_M)
    lines = [f"| centre moved (mm) | {heads} | mean |", "|---|" + "---|" * (len(CENTRE_OFFSETS_M) + 1)]
    held: dict[str, list[int]] = {}
    for d in schemes:
        found: dict[str, list[float]] = {"margin": [], "holds_below": []}
        held[d] = [0] * len(BAND_MS)
        for x0 in CENTRE_OFFSETS_M:
            m = mission("sine", d)
            m = replace(m, trajectory=replace(m.trajectory, x0=x0))
            # patched: one cell a round flies here, so no check below (a round of many flies in other processes)
            r = search(m, "delay_ms", parse_until(f"rms={limit_m:g}"), engine="process" if PATCHED else "auto",
                       below=0.0 if PATCHED else None)["controllers"][0]  # one law: its entry
            for k in found:  # patched: holds_below unchecked (nan)
                v = None if PATCHED and k == "holds_below" else r.get(k)
                found[k].append(np.nan if v is None else v)
            for i, v in enumerate(BAND_MS):
                link = {"up": {"delay_ms": float(v)}, "down": {"delay_ms": float(v)}}
                held[d][i] += simulate(m, link=link, plots=False).summary["rms_3d"] <= limit_m
        for k, vals in found.items():
            what = "margin (bisection)" if k == "margin" else k
            lines.append(f"| {d}: {what} (ms) | {' | '.join(f'{v:g}' for v in vals)} | {np.mean(vals):.2f} |")
    n = len(CENTRE_OFFSETS_M)
    lines += ["", f"| one-way delay (ms) | {' | '.join(str(v) for v in BAND_MS)} |", "|---|" + "---|" * len(BAND_MS)]
    lines += [f"| {d}: flights that hold (of {n}) | {' | '.join(str(c) for c in held[d])} |" for d in schemes]
    return "\n".join(lines)


def scan_table(limit_m: float = 0.1, schemes: tuple[str, ...] = DISCRETIZATIONS) -> str:
    """The delay scans of both schemes as markdown (RMS in mm; over ``limit_m`` in bold), and for each the
    largest delay up to which every delay of the scan holds."""
    lines = []
    for comp, delays in SCANS.items():
        lines += [f"| delay (ms), compensation {comp} | {' | '.join(str(v) for v in delays)} | every delay holds to |",
                  "|---|" + "---|" * (len(delays) + 1)]
        for d in schemes:
            rms = [delay_rms(d, float(v), comp == "predict") for v in delays]
            cells = [f"**{r * 1e3:.1f}**" if r > limit_m else f"{r * 1e3:.1f}" for r in rms]
            first_fail = next((v for v, r in zip(delays, rms, strict=True) if r > limit_m), None)
            held = "all" if first_fail is None else f"{first_fail - 1} ms"
            lines.append(f"| {d}: 3-D RMS (mm) | {' | '.join(cells)} | {held} |")
        lines.append("")
    return "\n".join(lines)


def measure(d: str, with_margin: bool) -> dict[str, Any]:
    r: dict[str, Any] = {f"sine_{int(rate)}": sine(d, rate) for rate in (250.0, 100.0, 1000.0)}
    r["step"], tv_bsst = step(d)
    _, tv_smc = step(d, "smc")
    r["smc_ratio"] = min(tv_smc[k] / tv_bsst[k] for k in tv_bsst)
    r["tv_last5_bsst_max"] = max(tv_bsst.values())
    r["tv_last5_smc_min"] = min(tv_smc.values())
    for name in ("robust", "robust-x500"):
        r[name] = simulate(mission(name, d), plots=False).summary["rms_3d"]
    for kind in ("raw", "ekf"):
        f = flight(mission("sine", d), kind=kind)  # type: ignore[arg-type]
        r[f"mocap_{kind}"] = {"rms_3d": f["rms_3d_m"], "ripple_u2": f["ripple_u2_n"]}
    if with_margin:
        find = bisect if PATCHED else margin
        r["margin_ms"] = {"none": find(d, False), "predict": find(d, True)}
        if not PATCHED:  # over initial conditions (docs/law.md, "One initial condition")
            r["margin_ms"] |= {"scatter": margin(d, False, True), "scatter_predict": margin(d, True, True)}
    return r


def table(res: dict[str, dict[str, Any]]) -> str:
    ds = list(res)
    lines = [f"| | {' | '.join(ds)} |", "|---|" + "---|" * len(ds)]

    def row(label: str, get: Any, fmt: str = ".3g") -> None:
        vals = []
        for d in ds:
            try:
                v = get(res[d])
            except KeyError:
                v = None
            vals.append("n/a" if v is None else format(v, fmt))
        lines.append(f"| {label} | {' | '.join(vals)} |")

    for rate in ("250", "100", "1000"):
        k = f"sine_{rate}"
        row(f"sine {rate} Hz: 3-D RMS (m)", lambda r, k=k: r[k]["rms_3d"])
        for u in ("u2", "u3", "u4"):
            row(f"sine {rate} Hz: period-2 {u} (N)", lambda r, k=k, u=u: r[k][f"p2_{u}"])
        for u in ("u2", "u3", "u4"):
            row(f"sine {rate} Hz: TV {u} (/s)", lambda r, k=k, u=u: r[k][f"tv_{u}"])
    for a in ("x", "y", "z", "psi"):
        row(f"step: settling {a} (s)", lambda r, a=a: r["step"][a]["settling_s"], ".3f")
        row(f"step: steady error {a} (m, rad)", lambda r, a=a: r["step"][a]["steady"], ".2e")
    row("robust: 3-D RMS (m)", lambda r: r["robust"])
    row("robust-x500: 3-D RMS (m)", lambda r: r["robust-x500"])
    row("step: TV u2/u3 last 5 s, BS-ST worst (/s)", lambda r: r["tv_last5_bsst_max"])
    row("step: TV u2/u3 last 5 s, SMC least (/s)", lambda r: r["tv_last5_smc_min"])
    row("smoothness against SMC (x, least of 6)", lambda r: r["smc_ratio"], ".1f")
    for kind in ("raw", "ekf"):
        row(f"mocap {kind}: 3-D RMS (m)", lambda r, kind=kind: r[f"mocap_{kind}"]["rms_3d"])
        row(f"mocap {kind}: u2 ripple (N)", lambda r, kind=kind: r[f"mocap_{kind}"]["ripple_u2"])
    for comp in ("none", "predict"):
        what = "margin delay_ms, rms=0.1" + (", predict" if comp == "predict" else "")
        row(f"{what} (ms, bisection)", lambda r, c=comp: r["margin_ms"][c]["margin"], "g")
        row(f"{what}: holds_below (ms)", lambda r, c=comp: r["margin_ms"][c]["holds_below"], "g")
        row(f"{what}: monotone below", lambda r, c=comp: str(r["margin_ms"][c]["monotone"]), "s")
        c = "scatter" + ("_predict" if comp == "predict" else "")
        row(f"{what}, 16 starts within 1 cm (ms)", lambda r, c=c: r["margin_ms"][c]["margin"], "g")
    return "\n".join(lines)


def acceptance(res: dict[str, dict[str, Any]]) -> list[str]:
    """Issue 24's "What must be true" of the implicit scheme, each with the figure that decides it."""
    imp, exp = res["implicit"], res["explicit"]
    s250, s100, step_ = imp["sine_250"], imp["sine_100"], imp["step"]
    checks = [
        ("period-2 of u2, u3, u4 at 250 Hz <= 0.01 N", max(s250[f"p2_{u}"] for u in ("u2", "u3", "u4")), 0.01),
        ("TV of u2, u3 at 250 Hz <= 35 /s", max(s250["tv_u2"], s250["tv_u3"]), 35.0),
        ("sine 3-D RMS at 250 Hz <= 1e-5 m", s250["rms_3d"], 1e-5),
        ("period-2 of u2, u3, u4 at 100 Hz <= 0.02 N", max(s100[f"p2_{u}"] for u in ("u2", "u3", "u4")), 0.02),
        ("step settling, every axis <= 5 s", max(v["settling_s"] for v in step_.values()), 5.0),
        ("step steady error <= 1 mm", max(step_[a]["steady"] for a in ("x", "y", "z")), 1e-3),
        ("robust <= 6 cm", imp["robust"], 0.06),
        ("robust-x500 <= 6 cm", imp["robust-x500"], 0.06),
    ]
    out = [f"{'holds' if v <= top else 'FAILS'}: {what} ({v:.3g})" for what, v, top in checks]
    if "margin_ms" in imp:
        for comp in ("none", "predict"):
            i, e = imp["margin_ms"][comp], exp["margin_ms"][comp]
            ok = None not in (i["margin"], e["margin"]) and i["margin"] >= e["margin"]
            out.append(f"{'holds' if ok else 'FAILS'}: bsst margin (compensation {comp}) implicit >= explicit "
                       f"({i['margin']} against {e['margin']} ms; holds_below {i['holds_below']} against "
                       f"{e['holds_below']} ms)")
            c = "scatter" + ("_predict" if comp == "predict" else "")
            if c in imp["margin_ms"]:  # not issue 24's figure: the same search over 16 starts within 1 cm
                i, e = imp["margin_ms"][c], exp["margin_ms"][c]
                out.append(f"  (over {' '.join(SCATTER)}: implicit {i['margin']} against explicit {e['margin']} ms)")
    return out


def figure(path: Path, t0: float = 20.0, span: float = 0.1) -> None:
    import matplotlib  # lazy: only the figure needs it

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # lazy: after the backend

    fig, ax = plt.subplots(figsize=(7.0, 3.2), dpi=120)
    for d, style in zip(DISCRETIZATIONS, ("o-", "s-"), strict=True):
        tr = simulate(mission("sine", d), plots=False).trace
        w = (tr["t"] >= t0) & (tr["t"] < t0 + span)
        ax.plot(tr["t"][w], tr["u2"][w], style, ms=3, lw=1, label=d)
    ax.set_xlabel("t (s)")
    ax.set_ylabel("u2 (N)")
    ax.set_title("sine mission, 250 Hz: u2 stepped explicitly and implicitly")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--no-margin", action="store_true", help="skip the four bsst margin searches (minutes)")
    ap.add_argument("--json", action="store_true", help="print the figures as JSON too")
    ap.add_argument("--figure", type=Path, metavar="PATH", help="draw u2 of both schemes over 0.1 s into PATH")
    ap.add_argument("--scan", action="store_true", help="the sine's RMS at every whole ms of delay, both schemes")
    ap.add_argument("--ensemble", action="store_true",
                    help="bsst margin's search on the sine with its centre moved by -10..10 mm, both schemes")
    ap.add_argument("--implicit-horizon", type=float, metavar="LAM",
                    help="the implicit scheme only, its step solved over LAM periods (an experiment: see "
                         "implicit_horizon); with --scan or the table (its margins by bisection, no check below)")
    ap.add_argument("--two-step-deadbeat", action="store_true",
                    help="the implicit scheme only, its integrator stepped on s_k first (an experiment: see "
                         "two_step_deadbeat); with --scan or the table (its margins by bisection, no check below)")
    ap.add_argument("--implicit-virtual-controls", action="store_true",
                    help="with --scan: the implicit scheme only, its virtual controls stepped implicitly too")
    args = ap.parse_args(argv)
    if args.figure:
        figure(args.figure)
        return 0
    t0 = time.perf_counter()
    schemes = DISCRETIZATIONS
    if args.implicit_horizon:
        implicit_horizon(args.implicit_horizon)
        PATCHED.append("implicit-horizon")
        schemes = ("implicit",)
    if args.two_step_deadbeat:
        two_step_deadbeat()
        PATCHED.append("two-step-deadbeat")
        schemes = ("implicit",)
    if args.ensemble:
        print(ensemble(schemes=schemes))
        print(f"load average {' '.join(f'{v:.2f}' for v in os.getloadavg())}; {os.cpu_count()} cores; "
              f"{time.perf_counter() - t0:.0f} s")
        return 0
    if args.scan:
        if args.implicit_virtual_controls:
            implicit_virtual_controls()
        print(scan_table(schemes=("implicit",) if args.implicit_virtual_controls else schemes))
        print(f"load average {' '.join(f'{v:.2f}' for v in os.getloadavg())}; {os.cpu_count()} cores; "
              f"{time.perf_counter() - t0:.0f} s")
        return 0
    res = {d: measure(d, not args.no_margin) for d in schemes}
    print(table(res))
    if "explicit" in res:
        print("\n" + "\n".join(acceptance(res)))
    print(f"\nload average {' '.join(f'{v:.2f}' for v in os.getloadavg())}; {os.cpu_count()} cores; "
          f"{time.perf_counter() - t0:.0f} s")
    if args.json:
        print(json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
