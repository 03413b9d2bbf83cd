"""The batch engine's flight: many cells of one mission flown at once, over a cell axis (numpy and numba).

In:  a mission (a :class:`~missions.Mission` or a TOML path) and, per cell, its
     :class:`~bridge.core.flight.Overrides` (``controller``, ``rate_hz`` Hz, ``seed``, a ``link`` table:
     what :func:`bridge.sweep.grid.cell_overrides` gives; or those fields as a mapping), or prepared
     :class:`~bridge.core.flight.Flight` s
Out: per cell the measured columns of a ``cells.csv`` row (:data:`MEASURES`: ``rms``/``max`` m,
     ``settling_s``/``flown_s`` s, ``tv_u2`` N/s, ``ripple_u2`` N, ``outcome``, packet counts, ``error``),
     the same numbers :func:`bridge.sweep.cells.row_from_run` takes from the scalar loop's run;
     :func:`batch_problem` says in one line why a set of cells cannot be flown here

The scalar loop (:func:`bridge.loop.fly`) stays the reference; this engine flies the same parts over a
cell axis: the link model, the guard and the vehicle's timeout first, as a plan of the whole flight
(:func:`bridge.link.plan.plan_links`: with no bandwidth queue and no re-arming nothing of it depends
on the flight), then the plant (:class:`bridge.batch.plant.BatchPlant`), the laws and the actuation
(:class:`bridge.batch.control.BatchController`), the prediction and the failsafe landing, step by step. The
metrics are accumulated as the flight goes (running sums and maxima, the last step outside the settling
band), with one column kept whole, u2, for the ripple of each cell's own second half; no trace is held.

Cells may differ in law (``bsst``, ``smc``, ``pid``), seed, control rate (flown as separate batches) and
every link setting but the bandwidth queue; they must share everything else (profile, effects, gains,
trajectory, duration). Not flown here (:func:`batch_problem`): a user's own law, the bandwidth
queue (``rate_bps``), a measured link ``trace``, ``[failsafe] resume``, any failsafe ``action`` but
``descend``, and parameters changed in flight (``--param-at``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from numba import njit

from bridge.autopilot.failsafe import DEFAULT_GAINS, OnboardGains
from bridge.batch import kernels as K
from bridge.batch.control import BATCH_LAWS, BatchActuation, BatchController
from bridge.batch.metrics import Metrics, measure_step, measured_rows
from bridge.batch.plant import BatchPlant
from bridge.batch.predict import BatchPredictor
from bridge.batch.wire import commands_over_wire, states_over_wire
from bridge.core.flight import Flight, Overrides, prepare
from bridge.link.model import link_from_table, merge_link_tables
from bridge.link.plan import HOLD, NONE, Clocks, LinkPlan, plan_links
from bridge.record.metrics import BANDS, RMS_FROM_S
from controller.nominal import Nominal
from missions import MISSION_DIR, Mission, Sine, load_mission

# the columns of a cells.csv row this engine measures (the cell's own axes and seed come from the cell)
MEASURES = ("rms", "max", "settling_s", "tv_u2", "ripple_u2", "outcome", "up_sent", "up_lost", "down_sent",
            "down_lost", "flown_s", "error")
CELL_STEPS = 8_000_000  # cells x control steps in one batch: bounds its memory (1000 x 7500: 457 MiB peak RSS)
Progress = Callable[[int, int], None]  # (cells done, cells in all), now and then


def batch_problem(mission: Mission | str | Path, cells: Sequence[Overrides | Mapping[str, Any]]) -> str | None:
    """Why these cells cannot fly in the batch engine, in one line; None if they can.

    ``cells``: per cell the overrides of :func:`bridge.core.flight.prepare` (a cell whose overrides are
    bad input is no reason: it becomes an ``error`` row, as in the process engine)."""
    m = mission if isinstance(mission, Mission) else load_mission(mission)
    return flights_problem([f for f in _prepare_all(m, cells) if isinstance(f, Flight)])


def flights_problem(flights: Sequence[Flight]) -> str | None:
    """:func:`batch_problem` for prepared flights."""
    first: Flight | None = None
    for f in flights:
        m = f.mission
        if m.controller not in BATCH_LAWS:
            return (f"controller {m.controller!r}: the batch engine flies only the built-in laws "
                    f"({', '.join(BATCH_LAWS)}); a law of your own needs the process engine")
        for d, cfg in (("up", f.link.up), ("down", f.link.down)):
            if cfg.rate_bps:
                return f"link {d}.rate_bps = {cfg.rate_bps:g}: the bandwidth queue is not in the batch engine"
            if cfg.trace is not None:
                return f"link {d}.trace: replaying a measured trace is not in the batch engine"
        if f.estimator != "truth":  # the batch plant has no sensors: it would fly the truth and say otherwise
            return (f"[estimator] kind = {f.estimator!r}: sensors and the on-board estimator are not in the batch "
                    f"engine; it flies only 'truth'")
        if f.param_changes:
            return ("--param-at: parameters changed during the flight are not in the batch engine; "
                    "fly it with the process engine")
        if f.failsafe.resume:
            return "[failsafe] resume = true: re-arming after a failsafe is not in the batch engine"
        if f.failsafe.action != "descend":
            return f"[failsafe] action = {f.failsafe.action!r}: the batch engine flies only the default, 'descend'"
        if m.steps > CELL_STEPS:
            return f"the mission has {m.steps} control steps: more than the batch engine holds ({CELL_STEPS})"
        if first is None:
            first = f
            continue
        why = _differs(first, f)
        if why:
            return f"the cells differ in {why}: a batch flies one mission with per-cell law, seed, rate and link"
    return None


def _differs(a: Flight, b: Flight) -> str | None:
    ma, mb = a.mission, b.mission
    for what, x, y in (("trajectory", ma.trajectory, mb.trajectory), ("duration_s", ma.duration_s, mb.duration_s),
                       ("physics_hz", ma.physics_hz, mb.physics_hz), ("start", ma.start, mb.start),
                       ("profile", a.profile, b.profile), ("effects", a.effects, b.effects),
                       ("gains", a.gains, b.gains), ("failsafe", a.failsafe, b.failsafe)):
        if x != y:
            return what
    return None


_PER_CELL = frozenset({"seed", "link"})  # what a cell may change without its own prepare()


def _prepare_all(mission: Mission, cells: Sequence[Overrides | Mapping[str, Any]]) -> list[Flight | str]:
    """Each cell's Flight, as :func:`prepare` builds it; a cell that cannot be built gives its error's text.

    prepare() parses the profile and builds the law (milliseconds each), so it runs once per distinct
    law and rate; each cell then gets what prepare() does with a seed and a ``link`` table: the mission
    with that seed and the table laid over ``[link]``, and that ``[link]`` validated (tests/test_batch.py
    checks the result equals prepare()'s, cell by cell)."""
    bases: dict[tuple[Any, ...], Flight | str] = {}
    out: list[Flight | str] = []
    for given in cells:
        try:
            over = Overrides.of(given)
            if not set(over.given()) <= _PER_CELL | {"controller", "rate_hz"}:
                out.append(prepare(mission, over))
                continue
            key = (over.controller, over.rate_hz)
            if key not in bases:
                try:
                    bases[key] = prepare(mission, Overrides(controller=key[0], rate_hz=key[1]))
                except Exception as exc:  # the cell's law or rate is bad input: every such cell says so
                    bases[key] = f"{type(exc).__name__}: {exc}"
            base = bases[key]
            if isinstance(base, str):
                out.append(base)
                continue
            out.append(_with_seed_and_link(base, mission, over.seed, over.link))
        except Exception as exc:  # a cell that cannot be built is an error row, never the end of the batch
            out.append(f"{type(exc).__name__}: {exc}")
    return out


def _with_seed_and_link(base: Flight, mission: Mission, seed: int | None, link: Mapping[str, Any] | None) -> Flight:
    """``prepare(mission, controller=…, rate_hz=…, seed=seed, link=link)`` from that prepare() without them."""
    if seed is None and not link:
        return base
    merged = merge_link_tables(mission.link, link) if link else None
    m = base.mission.with_overrides(seed=seed, link=merged)
    return replace(base, mission=m, link=link_from_table(m.link, m.source, seed=m.seed, duration_s=m.duration_s))


def fly_batch(mission: Mission | str | Path, cells: Sequence[Overrides | Mapping[str, Any]], *,
              progress: Progress | None = None) -> list[dict[str, Any]]:
    """Fly every cell (the overrides of :func:`bridge.core.flight.prepare`) and return, in order, the
    measured columns (:data:`MEASURES`) of each one's ``cells.csv`` row; a cell that cannot be built gets
    outcome ``error`` and its message. ValueError (:func:`batch_problem`'s line) if the batch cannot fly them."""
    m = mission if isinstance(mission, Mission) else load_mission(mission)
    built = _prepare_all(m, cells)
    flights = [f for f in built if isinstance(f, Flight)]
    results = iter(fly_flights(flights, progress=progress, total=len(built)))
    return [next(results) if isinstance(f, Flight) else error_measures(f) for f in built]


def compile_batch() -> None:
    """Compile, or load from numba's on-disk cache, this engine's kernels in this process, by flying a
    few steps of every kind of cell: each law, wrench (paper) and motors (x500), plant effects, a lossy
    delayed link with prediction. A first batch on a machine compiles them (~12 s here); after it, ~1 s."""
    cells = [{"controller": law} for law in ("bsst", "smc", "pid")]
    cells.append({"link": {"delay_ms": 8.0, "loss_pct": 10.0, "compensation": "predict"}})
    x500 = load_mission(MISSION_DIR / "robust-x500.toml")
    for m in (Mission(Sine(), duration_s=0.1), replace(x500, duration_s=0.1)):
        fly_batch(m, cells)


def error_measures(why: str) -> dict[str, Any]:
    """The measured columns of a cell that could not be flown (outcome ``error``)."""
    out: dict[str, Any] = {c: None for c in MEASURES}
    out.update(outcome="error", error=" ".join(why.split())[:300])
    return out


def fly_flights(flights: Sequence[Flight], *, progress: Progress | None = None,
                total: int | None = None) -> list[dict[str, Any]]:
    """Fly prepared flights (of one mission, see :func:`flights_problem`); the measured columns of each."""
    why = flights_problem(flights)
    if why:
        raise ValueError(why)
    out: list[dict[str, Any] | None] = [None] * len(flights)
    by_rate: dict[float, list[int]] = {}
    for i, f in enumerate(flights):
        by_rate.setdefault(f.mission.rate_hz, []).append(i)
    total = len(flights) if total is None else total
    done = total - len(flights)
    for idx in by_rate.values():
        size = max(1, min(len(idx), CELL_STEPS // max(1, flights[idx[0]].mission.steps), 1024))
        for a in range(0, len(idx), size):
            part = idx[a:a + size]

            def report(k: int, of: int, base: int = done, n: int = len(part)) -> None:
                if progress is not None:
                    progress(base + n * k // max(of, 1), total)

            rows = _Batch([flights[i] for i in part]).fly(report)
            for i, r in zip(part, rows, strict=True):
                out[i] = r
            done += len(part)
            if progress is not None:
                progress(done, total)
    return [r for r in out if r is not None]


class _Batch:
    """One batch: flights of one mission and one control rate, ordered backstepping laws first."""

    def __init__(self, flights: Sequence[Flight]) -> None:
        laws = [f.mission.controller for f in flights]
        self.order = BatchController.order(laws)
        self.flights = [flights[i] for i in self.order]
        f0 = self.flights[0]
        m = f0.mission
        self.mission = m
        self.n = len(self.flights)
        self.clocks = Clocks(m.rate_hz, m.physics_hz, f0.substeps, m.steps)

    def fly(self, report: Callable[[int, int], None]) -> list[dict[str, Any]]:
        fl = self.flights
        f0 = fl[0]
        m = self.mission
        n = self.n
        clocks = self.clocks
        steps, S, rate = clocks.steps, clocks.substeps, clocks.rate_hz
        plan = plan_links([f.link for f in fl], [f.guard for f in fl], f0.failsafe.timeout_s, clocks)
        x0, y0, z0, psi0 = m.start
        start = (x0, 0.0, y0, 0.0, z0, 0.0, 0.0, 0.0, 0.0, 0.0, psi0, 0.0)
        plant = BatchPlant(f0.profile, f0.effects, [f.mission.seed for f in fl], physics_hz=m.physics_hz,
                           state=start)
        ctl = BatchController([f.mission.controller for f in fl], f0.nominal, f0.gains, rate,
                              [f.mission.discretization for f in fl])
        t_all = clocks.step_t

        # the states the guard may still use, and the commands on their way up (rings by step)
        ring_X = np.zeros((plan.state_age_max + 1, 12, n))
        ring_held = np.zeros((plan.cmd_age_max + 1, 5 if not plant.lagged else 4, n))
        ptr = np.zeros(n, np.int64)
        next_check = plan.apply_check[:, 0].copy()
        pred = _Prediction(self, plan)
        land = _Landing(f0.nominal, f0.failsafe.descent_rate, n)
        fs_step = plan.failsafe_step
        fs_steps = {int(v) for v in fs_step[fs_step < steps]}  # the steps whose period starts a failsafe

        # the figures, as the flight goes
        rms_from = min(RMS_FROM_S, 0.5 * m.duration_s)
        changes = list(m.trajectory.change_times())
        seg_of = np.searchsorted(np.array(changes), t_all, side="right") - 1  # the change each step follows
        met = Metrics(np.zeros(n), np.zeros(n), np.full((max(1, len(changes)), 3, n), -1, np.int64),
                      np.zeros(n), np.zeros((steps, n)))
        band = np.array([BANDS["x"], BANDS["y"], BANDS["z"]])
        u2_now = np.zeros(n)
        alive = np.ones(n, bool)
        flown = np.full(n, steps, np.int64)
        diverged = np.zeros(n, bool)
        every = max(1, steps // 20)
        Xg = np.empty((12, n))
        last_u2 = np.zeros(n)
        actuation = f0.nominal.actuation
        with np.errstate(all="ignore"):
            for k in range(steps):
                t = k / rate
                X = plant.X
                states_over_wire(X, ring_X[k % len(ring_X)])  # what the laws read: ODOMETRY float32, as offline
                mode = plan.mode[k]
                active = mode != NONE
                if active.any():
                    _states_used(ring_X, plan.state_step[k], active, k, Xg)
                    ref = pred.prepare(k, t, active, Xg)
                    u, real, c = ctl.step(Xg, ref, mode == HOLD, active)
                    pred.sent(t, real, ctl.actuation.omega_d)
                    np.copyto(u2_now, u[1], where=active)
                    plant.held(commands_over_wire(c, actuation), out=ring_held[k % len(ring_held)])  # float32, as SITL
                measure_step(k, X, pred.ref_now[k], u2_now, last_u2, met.sq_sum, met.sq_max, met.last_out, met.tv,
                             band, int(seg_of[k]), t >= rms_from, alive)
                met.u2[k] = u2_now
                last_u2[...] = u2_now

                # the vehicle's period: commands take effect at the physics step they arrive in
                if k in fs_steps:
                    land.begin(fs_step == k)
                for i in range(S):
                    _apply_due(k * S + i, next_check, ptr, plan.apply_check, plan.apply_cmd, ring_held, plant.holding)
                    land.step(plant)
                    plant.step()

                bad = plant.diverged() & alive
                if bad.any():
                    diverged |= bad
                    alive &= ~bad
                    flown[bad] = k + 1
                    plant.X[:, bad] = np.asarray(start)[:, None]  # a resting state: no nan downstream
                    if not alive.any():
                        break
                if k % every == 0:
                    report(k, steps)
        outcome = np.where(diverged, "diverged", np.where(fs_step < flown, "failsafe", "completed"))
        rows = measured_rows(met, flown, outcome, plan.counts(flown), changes, rms_from, t_all, rate)
        back = [None] * n
        for pos_, i in enumerate(self.order):
            back[i] = rows[pos_]
        return back  # type: ignore[return-value]


class _Prediction:
    """The references each cell controls on (at t + its command lag where it predicts) and the batch
    predictor of the cells that predict (compensation ``predict``)."""

    def __init__(self, batch: _Batch, plan: LinkPlan) -> None:
        guards = [f.guard for f in batch.flights]
        m, n, rate = batch.mission, batch.n, batch.clocks.rate_hz
        self.t_all = batch.clocks.step_t
        self.plan = plan
        predict = np.array([g.compensation == "predict" for g in guards])
        self.pidx = np.nonzero(predict)[0]
        self.lags = np.array([g.lag_s for g in guards])
        self.ref_now = _references(m, self.t_all)
        self.lagged_refs = {}
        for lag in sorted({float(v) for v in self.lags[self.pidx]} - {0.0}):
            self.lagged_refs[lag] = (np.nonzero(predict & (self.lags == lag))[0], _references(m, self.t_all + lag))
        self.ref_cells = np.empty((4, 5, n)) if self.lagged_refs else None
        self.predictor = None
        if len(self.pidx):
            depth = plan.state_age_max + int(math.ceil(float(self.lags.max()) * rate)) + 4
            self.predictor = BatchPredictor(batch.flights[0].nominal, 1.0 / rate, self.lags[self.pidx], depth)
        self.pos = self.g_idx = np.zeros(0, np.int64)

    def prepare(self, k: int, t: float, active: np.ndarray, Xg: np.ndarray) -> np.ndarray:
        """The reference sample of step k for the cells ([4, 5] or [4, 5, n]); the states Xg [12, n] of the
        predicting active cells carried to t + lag, in place."""
        ref = self.ref_now[k]
        if self.ref_cells is not None:
            self.ref_cells[...] = ref[:, :, None]
            for which, table in self.lagged_refs.values():
                self.ref_cells[:, :, which] = table[k][:, :, None]
            ref = self.ref_cells
        self.pos = self.g_idx = np.zeros(0, np.int64)
        if self.predictor is not None:
            st = self.plan.state_step[k]
            self.pos = np.nonzero(active[self.pidx])[0]
            if len(self.pos):
                self.g_idx = g = self.pidx[self.pos]
                Xg[:, g] = self.predictor.predict(self.t_all[st[g]], Xg[:, g], t + self.lags[g], self.pos)
        return ref

    def sent(self, t: float, real: np.ndarray, omega_d: np.ndarray) -> None:
        """Record the commands the predicting cells of this step sent (realisable wrench [4, n], omega_d [n])."""
        if self.predictor is not None and len(self.pos):
            self.predictor.sent(t, real[:, self.g_idx], omega_d[self.g_idx], self.pos)


class _Landing:
    """The vehicle's failsafe (SimVehicle.advance) of every cell in it: on the ground it disarms (command
    zero), else the ``descend`` landing law (:func:`bridge.autopilot.failsafe.level_wrench`, compiled, with
    the on-board controller's gains) commands through the profile's actuation."""

    def __init__(self, nominal: Nominal, descent: float, n: int, gains: OnboardGains = DEFAULT_GAINS) -> None:
        no = nominal
        self.act = BatchActuation(nominal, n)
        self.constants = (-descent, no.mass, no.gravity, no.ixx / no.arm, no.iyy / no.arm, no.izz / no.arm,
                          gains.k_vel_level, gains.k_att_level, gains.d_att_level, gains.d_yaw)
        self.in_failsafe = np.zeros(n, bool)
        self.armed = np.ones(n, bool)
        self.any = False

    def begin(self, cells: np.ndarray) -> None:
        """The cells (bool [n]) whose failsafe begins this period."""
        self.in_failsafe |= cells
        self.any = True

    def step(self, plant: BatchPlant) -> None:
        """One physics step of the failsafe: what the cells in it hold until the next."""
        if not self.any:
            return
        flying = self.in_failsafe & self.armed
        if not flying.any():
            return
        down = flying & plant.on_ground
        if down.any():
            cells = np.nonzero(down)[0]
            self.armed[cells] = False
            plant.hold(plant.held(np.zeros((4, len(cells)))), cells)
            flying = flying & ~down
            if not flying.any():
                return
        cells = np.nonzero(flying)[0]
        u = np.empty((4, len(cells)))
        _level(plant.X, cells, self.constants, u)
        plant.hold(plant.held(self.act.allocate(u)[1]), cells)


@njit(cache=True)
def _level(X: np.ndarray, cells: np.ndarray, constants: tuple, out: np.ndarray) -> None:  # pragma: no cover
    """:func:`bridge.autopilot.failsafe.level_wrench` of the cells ``cells`` of X [12, n] into out [4, len(cells)]."""
    v_z, m, g, kx, ky, kz, k_vel, k_att, d_att, d_yaw = constants
    for i in range(len(cells)):
        u = K.level_wrench(K.column(X, cells[i]), v_z, m, g, kx, ky, kz, k_vel, k_att, d_att, d_yaw)
        for r in range(4):
            out[r, i] = u[r]


def _references(m: Mission, times: np.ndarray) -> np.ndarray:
    """[len(times), 4, 5]: the reference sample (x, y, z, psi; value and 4 derivatives) at each time."""
    sample = m.trajectory.sample
    return np.array([sample(float(t)) for t in times])


@njit(cache=True)
def _states_used(ring_X: np.ndarray, state_step: np.ndarray, active: np.ndarray, k: int,
                 out: np.ndarray) -> None:  # pragma: no cover
    """The state each cell's guard controls on at step k (the ring's row of step state_step, or of k where the
    cell does not act) into out [12, n]."""
    ring_n = ring_X.shape[0]
    for j in range(out.shape[1]):
        slot = (state_step[j] if active[j] else k) % ring_n
        for i in range(12):
            out[i, j] = ring_X[slot, i, j]


@njit(cache=True)
def _apply_due(check: int, next_check: np.ndarray, ptr: np.ndarray, apply_check: np.ndarray, apply_cmd: np.ndarray,
               ring_held: np.ndarray, holding: np.ndarray) -> None:  # pragma: no cover
    """The commands that take effect at physics check ``check``: each such cell's next planned one, from the
    ring of what the commands hold, into the plant's ``holding`` [rows, n]; its pointer moves on."""
    held_n = ring_held.shape[0]
    for j in range(next_check.shape[0]):
        if next_check[j] != check:
            continue
        slot = apply_cmd[j, ptr[j]] % held_n
        for i in range(holding.shape[0]):
            holding[i, j] = ring_held[slot, i, j]
        ptr[j] += 1
        next_check[j] = apply_check[j, ptr[j]]


__all__ = ["CELL_STEPS", "MEASURES", "batch_problem", "error_measures", "flights_problem", "fly_batch",
           "fly_flights"]

