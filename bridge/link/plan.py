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
and number (the counter-based SplitMix64 draws of :mod:`bridge.link.model`, reproduced here bit for bit
over whole arrays); when a packet is sent is decided by the guard, which looks only at the ages of the
states it received; and the vehicle's failsafe looks only at when commands arrived. So the whole flight's
packet traffic is worked out first, with array operations along the step axis, exactly as
:class:`~bridge.link.model.LinkImpairment`, :class:`~bridge.link.ends.VehicleEnd`,
:class:`~bridge.link.ends.ControllerEnd` and :class:`~controller.link_guard.LinkGuard` would do it
step by step, and the engine then flies the plant and the laws along it.
"""

from __future__ import annotations

from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
from numba import njit

from bridge.link.ends import EPS_T
from bridge.link.fates import Fates, draw_fates
from bridge.link.model import LinkConfig, LinkSettings
from controller.link_guard import GuardConfig

NONE, TRACK, HOLD = 0, 1, 2  # the guard's decision per step: no command (stop or idle), command, command on hold
NEVER = np.iinfo(np.int64).max // 4  # a check or step index that never comes
PLAN_CHUNK = 128  # cells planned together: bounds the planner's temporary arrays to ~100 MB at 7500 steps



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


def _first_at_or_after(thresholds: np.ndarray, due: np.ndarray, per_s: float) -> np.ndarray:
    """For each due time (s), the first index i with thresholds[i] >= due (len(thresholds): none), for
    thresholds within 1e-9 s of i / per_s; ``np.searchsorted`` without its cost on millions of times."""
    n = len(thresholds)
    c = np.floor(due * per_s).astype(np.int64) - 1
    np.clip(c, 0, n, out=c)
    padded = np.append(thresholds, np.inf)
    # thresholds[i] lies within 1e-9 s of i / per_s (a running sum's rounding plus EPS_T), so the answer
    # is the guess plus 1 or 2: two passes that move it up where it is still short are exact
    c += padded[c] < due
    c += padded[c] < due
    return c


def _blackout_mask(cfgs: Sequence[LinkConfig], t: np.ndarray) -> np.ndarray:
    """[cells, len(t)]: sent inside one of the cell's blackout windows [start, start + duration)."""
    out = np.zeros((len(cfgs), len(t)), bool)
    memo: dict[tuple[tuple[float, float], ...], np.ndarray] = {}
    for i, c in enumerate(cfgs):
        if not c.blackouts:
            continue
        if c.blackouts not in memo:
            m = np.zeros(len(t), bool)
            for s, d in c.blackouts:
                m |= (t >= s) & (t < s + d)
            memo[c.blackouts] = m
        out[i] = memo[c.blackouts]
    return out


def _next_index(flag: np.ndarray) -> np.ndarray:
    """[cells, n]: for each column the first later column where ``flag`` is set (n: none)."""
    n = flag.shape[1]
    idx = np.where(flag, np.arange(n), n)
    nxt = np.minimum.accumulate(idx[:, ::-1], axis=1)[:, ::-1]
    out = np.full_like(nxt, n)
    out[:, :-1] = nxt[:, 1:]
    return out


def _arrivals(sent: np.ndarray, send_t: np.ndarray, lost: np.ndarray, fates: Fates, seq: np.ndarray,
              delay: np.ndarray, thresholds: np.ndarray, per_s: float, first_check: np.ndarray) -> np.ndarray:
    """[cells, steps]: the check at which each packet sent (one per step at most) is first delivered
    (:data:`NEVER`: lost, or held with no successor). ``seq`` numbers the packets (the fates' column),
    ``first_check`` is the first check after each step's send (a packet cannot arrive before it is sent)."""
    n_cells, steps = sent.shape
    rows = np.arange(n_cells)[:, None]
    some = fates.lost.shape[1] > 0
    s = np.clip(seq, 0, max(fates.lost.shape[1] - 1, 0)) if some and (
        fates.jittered or fates.reordered or fates.duplicated) else None
    ok = sent & ~lost
    base = send_t[None, :] + delay[:, None]  # tx + delay: LinkImpairment.send's order of operations
    due = base + fates.jitter[rows, s] if s is not None and fates.jittered else base
    if s is None or not fates.reordered:  # no packet held back: each is due at its own time
        c = np.maximum(_first_at_or_after(thresholds, due, per_s), first_check[None, :])
        c = np.where(ok, c, NEVER)
    else:
        held = fates.held[rows, s] & ok
        releaser = ok & ~held
        nxt = _next_index(releaser)  # the successor that releases a held packet
        has = nxt < steps
        nxt_c = np.minimum(nxt, steps - 1)
        due_rel = np.where(held, np.maximum(due, due[rows, nxt_c]), due)
        pushed = np.where(held, first_check[nxt_c], first_check[None, :])
        c = np.maximum(_first_at_or_after(thresholds, due_rel, per_s), pushed)
        c = np.where(ok & (~held | has), c, NEVER)
    if s is not None and fates.duplicated:
        dup = fates.dup[rows, s] & ok
        if dup.any():
            dj = fates.dup_jitter[rows, s]
            cd = np.maximum(_first_at_or_after(thresholds, base + dj, per_s), first_check[None, :])
            c = np.where(dup, np.minimum(c, cd), c)
    return c


def _newest(arrive: np.ndarray, n_checks: int) -> np.ndarray:
    """[cells, n_checks]: the highest packet index delivered by each check (-1: none yet)."""
    out = np.empty((arrive.shape[0], n_checks), np.int64)
    _newest_into(np.ascontiguousarray(arrive), out)
    return out


@njit(cache=True)
def _newest_into(arrive: np.ndarray, out: np.ndarray) -> None:  # pragma: no cover
    """:func:`_newest`: each packet's index where it arrives (the highest of those arriving together), then
    a running maximum along the checks."""
    n_checks = out.shape[1]
    for c in range(arrive.shape[0]):
        row = out[c]
        row[:] = -1
        for j in range(arrive.shape[1]):
            a = arrive[c, j]
            if a < n_checks and j > row[a]:
                row[a] = j
        for i in range(1, n_checks):
            if row[i] < row[i - 1]:
                row[i] = row[i - 1]


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
    """The :class:`LinkPlan` of a batch (one entry of ``links`` and ``guards`` per cell), its chunks of
    :data:`PLAN_CHUNK` cells planned on ``jobs`` threads (numpy's array operations run without the GIL;
    each chunk is planned alone, so the plan does not depend on ``jobs``)."""
    n = len(links)
    steps = clocks.steps
    mode = np.zeros((n, steps), np.int8)
    state_step = np.full((n, steps), -1, np.int32)
    up_lost = np.zeros((n, steps), bool)
    down_lost = np.zeros((n, steps), bool)
    failsafe = np.full(n, NEVER, np.int64)
    chunks = []
    age_max = 0
    state_age = 0
    spans = [(a, min(n, a + PLAN_CHUNK)) for a in range(0, n, PLAN_CHUNK)]

    def plan(span: tuple[int, int]) -> dict[str, np.ndarray | int]:
        return _plan_chunk(links[span[0]:span[1]], guards[span[0]:span[1]], timeout_s, clocks)

    if jobs > 1 and len(spans) > 1:
        with ThreadPoolExecutor(min(jobs, len(spans))) as pool:
            parts = list(pool.map(plan, spans))
    else:
        parts = [plan(span) for span in spans]
    for (a, b), part in zip(spans, parts, strict=True):
        mode[a:b] = part["mode"]
        state_step[a:b] = part["state"]
        up_lost[a:b] = part["up_lost"]
        down_lost[a:b] = part["down_lost"]
        failsafe[a:b] = part["failsafe"]
        chunks.append((part["apply_check"], part["apply_cmd"]))
        age_max = max(age_max, part["age_max"])
        state_age = max(state_age, part["state_age"])
    width = max([c.shape[1] for c, _ in chunks] + [1]) + 1
    apply_check = np.full((n, width), NEVER, np.int64)
    apply_cmd = np.zeros((n, width), np.int32)
    row = 0
    for c, k in chunks:
        apply_check[row:row + len(c), :c.shape[1]] = c
        apply_cmd[row:row + len(c), :k.shape[1]] = k
        row += len(c)
    return LinkPlan(mode, state_step, failsafe, apply_check, apply_cmd, up_lost, down_lost, age_max, state_age)


def _plan_chunk(links: Sequence[LinkSettings], guards: Sequence[GuardConfig], timeout_s: float,
                clocks: Clocks) -> dict[str, np.ndarray | int]:
    n = len(links)
    steps, S = clocks.steps, clocks.substeps
    t = clocks.step_t
    pt = clocks.plant_t
    rows = np.arange(n)[:, None]
    ks = np.arange(steps)

    # down: a state every step; the guard controls on the newest delivered (ControllerEnd, LinkGuard.observe)
    down = [ln.down for ln in links]
    fd = draw_fates(down, "down", steps)
    d_lost = _blackout_mask(down, t) | fd.lost
    d_delay = np.array([c.delay_ms / 1000.0 for c in down])
    everyone = np.ones((n, steps), bool)
    down_thresholds = t + EPS_T
    arrive = _arrivals(everyone, t, d_lost, fd, np.broadcast_to(ks, (n, steps)), d_delay, down_thresholds,
                       clocks.rate_hz, ks)
    newest = _newest(arrive, steps)  # [n, steps]
    has = newest >= 0
    age = t[None, :] - t[np.maximum(newest, 0)]
    stale = np.array([g.stale_s for g in guards])[:, None]
    stop = np.array([g.stop_s for g in guards])[:, None]
    acting = has & (age <= stop)
    mode0 = np.where(acting, np.where(age <= stale, TRACK, HOLD), NONE).astype(np.int8)

    # up: a command on every step the guard acts; each numbered by the cell's count (its packet number)
    sent0 = mode0 != NONE
    seq = np.cumsum(sent0, axis=1) - 1
    up = [ln.up for ln in links]
    fu = draw_fates(up, "up", int(seq[:, -1].max()) + 1 if steps else 0)
    s = np.clip(seq, 0, None)
    u_lost = sent0 & (_blackout_mask(up, t) | (fu.lost[rows, s] if fu.lost.size else False))
    u_delay = np.array([c.delay_ms / 1000.0 for c in up])
    up_thresholds = pt[:-1] + EPS_T
    up_thresholds[::S] = np.maximum(t, pt[:-1:S]) + EPS_T  # the loop's deliver(t) and the period's deliver(p.t)
    first_check = ks * S
    e = _arrivals(sent0, t, u_lost, fu, seq, u_delay, up_thresholds, clocks.physics_hz, first_check)
    # the commands in force (each the newest delivered), the vehicle's timeout, and what takes effect before it
    rec_check = np.empty((n, steps), np.int64)
    rec_cmd = np.empty((n, steps), np.int64)
    fs = np.empty(n, np.int64)
    count = np.empty(n, np.int64)
    cmd_age = np.empty(n, np.int64)
    _commands_in_force(np.ascontiguousarray(e), S, pt, timeout_s, rec_check, rec_cmd, fs, count, cmd_age)

    # after the failsafe the vehicle reports it: states newer than its step carry "not offboard" (idle)
    offboard = newest <= fs[:, None]
    mode = np.where(offboard, mode0, NONE).astype(np.int8)
    sent = mode != NONE
    width = int(count.max()) if n else 0
    apply_check = rec_check[:, :width].copy()
    apply_cmd = rec_cmd[:, :width].copy()
    age_max = int(cmd_age.max()) + 1 if width else 1
    state_age = int((ks[None, :] - newest)[sent].max()) if sent.any() else 0
    return {"mode": mode, "state": np.where(sent, newest, -1).astype(np.int32), "up_lost": u_lost & sent,
            "down_lost": d_lost, "failsafe": fs, "apply_check": apply_check, "apply_cmd": apply_cmd,
            "age_max": age_max, "state_age": state_age}


@njit(cache=True)
def _commands_in_force(e: np.ndarray, S: int, pt: np.ndarray, timeout_s: float, rec_check: np.ndarray,
                       rec_cmd: np.ndarray, fs: np.ndarray, count: np.ndarray,
                       age: np.ndarray) -> None:  # pragma: no cover
    """From the physics check each command arrives at (e [cells, steps]; NEVER: never), per cell: the commands
    that take effect — the records, a command arriving before every later one (a later command arriving no
    later wins), in increasing order of both — into rec_check / rec_cmd (the check, the command's step;
    NEVER / 0 after the last); the step whose period starts the vehicle's failsafe (fs; NEVER: none): the
    first period start more than ``timeout_s`` after the last command took effect (at the period start at
    or after its arrival) or after the start; how many take effect before it (count: commands arriving in
    failsafe are refused), and the most periods one of those took from its send (age)."""
    n, steps = e.shape
    checks = steps * S
    for c in range(n):
        # the records, found from the end: a command is one if it arrives before the earliest later arrival
        m = 0
        following = NEVER
        for k in range(steps - 1, -1, -1):
            v = e[c, k]
            if v < following and v < checks:
                rec_check[c, m] = v
                rec_cmd[c, m] = k
                m += 1
            if v < following:
                following = v
        rec_check[c, :m] = rec_check[c, :m][::-1].copy()
        rec_cmd[c, :m] = rec_cmd[c, :m][::-1].copy()
        # the timeout: at each period start p, the time since the last command took effect by then
        f = NEVER
        i = 0
        last = -1
        for p in range(steps):
            while i < m and (rec_check[c, i] + S - 1) // S <= p:
                last = rec_check[c, i]
                i += 1
            last_t = pt[last] if last >= 0 else 0.0
            if (pt[p * S] - last_t) > timeout_s + 1e-9:
                f = p
                break
        fs[c] = f
        limit = NEVER if f == NEVER else min(f, steps) * S
        kept = 0
        worst = 0
        while kept < m and rec_check[c, kept] < limit:  # the records arrive in increasing order: a prefix
            worst = max(worst, rec_check[c, kept] // S - rec_cmd[c, kept])
            kept += 1
        count[c] = kept
        age[c] = worst
        rec_check[c, kept:] = NEVER
        rec_cmd[c, kept:] = 0
