"""The link model, the link guard and the prediction for N cells at once (the batch engine).

In:  per cell a :class:`~bridge.link.model.LinkSettings` (delays ms, loss %, burst length packets, blackouts s,
     dup and reorder %) and its guard (``stale_s``, ``stop_s`` s, compensation, ``lag_s`` s), the vehicle's
     ``timeout_s`` (s), the clocks (``rate_hz``, ``substeps`` physics steps per control step, ``physics_hz``)
     and the number of control steps
Out: a :class:`LinkPlan`: per control step and cell the guard's decision (track, hold, nothing) and the
     index of the state it controls on; per cell the physics steps at which a newer command takes effect on
     the vehicle (and which), the step whose period starts the vehicle's failsafe, and what was sent and
     lost (the engine that flies along it, its predictor and its wire: :mod:`bridge.batch`)

Why a plan: with no bandwidth queue and no ``resume``, nothing the link, the guard or the vehicle's
timeout decides depends on the flight itself. A packet's fate is a pure function of its seed, direction
and number (the counter-based SplitMix64 draws of :mod:`bridge.link.model`, reproduced bit for bit by
:mod:`bridge.link.fates`); when a packet is sent is decided by the guard, which looks only at the ages
of the states it received; and the vehicle's failsafe looks only at when commands arrived. So the whole
flight's packet traffic is worked out first, cell by cell and step by step in compiled code
(:mod:`bridge.link.plan_cell`), exactly as :class:`~bridge.link.model.LinkImpairment`,
:class:`~bridge.link.ends.VehicleEnd`, :class:`~bridge.link.ends.ControllerEnd` and
:class:`~controller.link_guard.LinkGuard` would do it, and the engine then flies the plant and the laws
along it.
"""

from __future__ import annotations

from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from bridge.link.fates import fate_params
from bridge.link.model import LinkSettings
from bridge.link.plan_cell import NEVER, NONE, plan_cells
from controller.link_guard import GuardConfig

PLAN_CHUNK = 32  # cells planned in one compiled call (a thread's share; its records: 2 x 32 x steps int64)


# -- the plan ------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Clocks:
    """The clocks every cell of a batch shares: control steps, physics steps and their check thresholds (s)."""

    rate_hz: float
    physics_hz: float
    substeps: int
    steps: int

    @property
    def step_t(self) -> np.ndarray:
        """t_k = k / rate_hz of every control step (s), as the loop computes it."""
        return np.arange(self.steps, dtype=np.float64) / self.rate_hz

    @property
    def plant_t(self) -> np.ndarray:
        """The plant's clock before each physics step and after the last (s): a running sum of 1/physics_hz,
        as :class:`plant.Quadrotor` keeps it."""
        n = self.steps * self.substeps
        h = 1.0 / self.physics_hz
        out = np.empty(n + 1)
        t = 0.0
        for i in range(n + 1):  # sequential on purpose: the plant's own rounding
            out[i] = t
            t = t + h
        return out


@dataclass
class LinkPlan:
    """What the link, the guard and the vehicle's timeout decide for a batch of cells (see the module doc).

    Arrays are [cells, steps] (cell-major: the engine flies each cell's steps in order) unless said otherwise."""

    mode: np.ndarray  # int8: NONE, TRACK or HOLD
    state_step: np.ndarray  # int32: the step whose state the guard controls on (-1: none)
    failsafe_step: np.ndarray  # [cells] int64: the step whose period starts in failsafe (NEVER: none)
    apply_check: np.ndarray  # [cells, slots] int64: physics checks where a newer command takes effect (sorted)
    apply_cmd: np.ndarray  # [cells, slots] int32: the step whose command that is
    up_lost: np.ndarray  # bool: the command sent at this step was lost
    down_lost: np.ndarray  # bool: the state sent at this step was lost
    cmd_age_max: int  # most control steps between a command's send and its taking effect
    state_age_max: int  # most control steps between a state's send and the guard's last use of it

    def counts(self, flown: np.ndarray) -> dict[str, np.ndarray]:
        """up_sent, up_lost, down_sent, down_lost per cell over its first ``flown`` steps."""
        steps = self.mode.shape[1]
        alive = np.arange(steps)[None, :] < flown[:, None]
        sent = (self.mode != NONE) & alive
        return {"up_sent": sent.sum(1), "up_lost": (self.up_lost & alive).sum(1),
                "down_sent": flown.astype(np.int64), "down_lost": (self.down_lost & alive).sum(1)}


def plan_links(links: Sequence[LinkSettings], guards: Sequence[GuardConfig], timeout_s: float,
               clocks: Clocks, jobs: int = 1) -> LinkPlan:
    """The :class:`LinkPlan` of a batch (one entry of ``links`` and ``guards`` per cell): each cell planned
    alone by the compiled :func:`bridge.link.plan_cell.plan_cells`, chunks of :data:`PLAN_CHUNK` cells on
    ``jobs`` threads (without the GIL), so the plan does not depend on ``jobs``."""
    n = len(links)
    steps = clocks.steps
    mode = np.zeros((n, steps), np.int8)
    state_step = np.full((n, steps), -1, np.int32)
    up_lost = np.zeros((n, steps), bool)
    down_lost = np.zeros((n, steps), bool)
    failsafe = np.full(n, NEVER, np.int64)
    count = np.zeros(n, np.int64)
    ages = np.zeros((n, 2), np.int64)
    params = [fate_params([ln.down for ln in links], "down"), fate_params([ln.up for ln in links], "up")]
    keys, ints, fps = (np.stack([params[0][i], params[1][i]]) for i in range(3))
    width_b = max(params[0][3].shape[1], params[1][3].shape[1])
    bos = np.zeros((2, n, width_b, 2))
    for d in (0, 1):
        bos[d, :, :params[d][3].shape[1]] = params[d][3]
    nbos = np.stack([params[0][4], params[1][4]])
    guard = np.array([[g.stale_s, g.stop_s] for g in guards], dtype=np.float64).reshape(n, 2)
    t, pt = clocks.step_t, clocks.plant_t
    spans = [(a, min(n, a + PLAN_CHUNK)) for a in range(0, n, PLAN_CHUNK)]

    def plan(span: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
        lo, hi = span
        rec_check = np.empty((hi - lo, steps), np.int64)
        rec_cmd = np.empty((hi - lo, steps), np.int64)
        plan_cells(lo, hi, keys, ints, fps, bos, nbos, guard, float(timeout_s), t, pt, clocks.substeps,
                   float(clocks.rate_hz), float(clocks.physics_hz), mode, state_step, up_lost, down_lost, failsafe,
                   rec_check, rec_cmd, count, ages)
        width = int(count[lo:hi].max()) if hi > lo else 0
        return rec_check[:, :width].copy(), rec_cmd[:, :width].copy()

    if jobs > 1 and len(spans) > 1:
        with ThreadPoolExecutor(min(jobs, len(spans))) as pool:
            parts = list(pool.map(plan, spans))
    else:
        parts = [plan(span) for span in spans]
    width = max([c.shape[1] for c, _ in parts] + [1]) + 1
    apply_check = np.full((n, width), NEVER, np.int64)
    apply_cmd = np.zeros((n, width), np.int32)
    for (a, b), (c, k) in zip(spans, parts, strict=True):
        apply_check[a:b, :c.shape[1]] = c
        apply_cmd[a:b, :k.shape[1]] = k
    age_max = int(ages[:, 0].max()) + 1 if n else 1
    state_age = int(ages[:, 1].max()) if n else 0
    return LinkPlan(mode, state_step, failsafe, apply_check, apply_cmd, up_lost, down_lost, age_max, state_age)
