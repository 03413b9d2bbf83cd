"""One cell's link plan, compiled: its packets' fates, their arrivals, the guard's decisions, the commands in
force and the vehicle's failsafe, step by step (bridge.link.plan lays out the batch and its threads).

In:  per cell and direction its fate parameters (:func:`bridge.link.fates.fate_params`: the stream key, the
     loss kind and numbers, reorder and dup fractions, jitter bound s, the delay s, blackout windows s), the
     guard's ``stale_s`` / ``stop_s`` (s), the vehicle's ``timeout_s`` (s), the clocks (control step times
     s, the plant's clock s, physics steps per control step, rates Hz)
Out: into the plan's rows of that cell: the guard's mode (NONE / TRACK / HOLD) and the state it controls on
     per step, which states and commands were lost, the commands that take effect (the physics check, the
     command's step), the failsafe's step, how many commands took effect, the oldest command and state used

The same arithmetic, in the same order, as the numpy planner it replaced (issue 25: that took 22 % of a
1000-cell sweep's CPU and ~100 MB of temporaries per chunk), and as :class:`~bridge.link.model.LinkImpairment`,
:class:`~bridge.link.ends.VehicleEnd` and :class:`~controller.link_guard.LinkGuard` decide one packet at a
time (tests/test_batch.py: the rows against the scalar loop, the fates draw for draw).
"""

from __future__ import annotations

import math

import numpy as np

from bridge.autopilot.kernelcache import njit
from bridge.link import ends  # ends.EPS_T compiled in: the cache's closure reaches it (kernelcache)
from bridge.link.fates import BOUND_S, DELAY_S, DUP_P, HOLD_P, draw_cell

NONE, TRACK, HOLD = 0, 1, 2  # the guard's decision per step: no command (stop or idle), command, command on hold
NEVER = np.iinfo(np.int64).max // 4  # a check or step index that never comes


@njit(cache=True, inline="always")
def first_at_or_after(thresholds: np.ndarray, due: float, per_s: float) -> int:  # pragma: no cover
    """The first index i with thresholds[i] >= due (len(thresholds): none), for thresholds within 1e-9 s of
    i / per_s: the guess floor(due * per_s) - 1 is short by at most 2 (np.searchsorted's answer, exactly)."""
    n = thresholds.shape[0]
    c = np.int64(math.floor(due * per_s)) - 1
    c = 0 if c < 0 else (n if c > n else c)
    for _ in range(2):
        if c < n and thresholds[c] < due:
            c += 1
    return c


@njit(cache=True, inline="always")
def _blacked_out(bo: np.ndarray, nb: int, t: float) -> bool:  # pragma: no cover
    """Sent inside one of the nb blackout windows (start, duration s) of bo."""
    for w in range(nb):
        if t >= bo[w, 0] and t < bo[w, 0] + bo[w, 1]:
            return True
    return False


@njit(cache=True)
def _arrivals(ok: np.ndarray, seq: np.ndarray, n_sent: int, t: np.ndarray, fp: np.ndarray, jit: np.ndarray,
              held: np.ndarray, dup: np.ndarray, dup_jit: np.ndarray, thresholds: np.ndarray, per_s: float,
              per_step: int, due: np.ndarray, nxt: np.ndarray, out: np.ndarray) -> None:  # pragma: no cover
    """Per step the check at which the packet sent there (``ok``: sent and not lost; ``seq``: its number) is
    first delivered (NEVER: lost, or held with no successor), into ``out``; the packet's send is the
    step's time, its first possible check the step's first (``per_step`` checks a step). ``due`` and ``nxt``:
    scratch."""
    steps = ok.shape[0]
    delay = fp[DELAY_S]
    jittered, reordered, duplicated = fp[BOUND_S] > 0.0, fp[HOLD_P] > 0.0, fp[DUP_P] > 0.0
    top = max(n_sent - 1, 0)
    for k in range(steps):
        base = t[k] + delay  # tx + delay: LinkImpairment.send's order of operations
        due[k] = base + jit[min(max(seq[k], 0), top)] if jittered else base
    following = steps  # the next packet that releases one held back (steps: none)
    for k in range(steps - 1, -1, -1):
        nxt[k] = following
        if ok[k] and not (reordered and held[min(max(seq[k], 0), top)]):
            following = k
    for k in range(steps):
        if not ok[k]:
            out[k] = NEVER
            continue
        s = min(max(seq[k], 0), top)
        copy = duplicated and dup[s]  # its copy, held with it if it is held (LinkImpairment.send)
        if reordered and held[s]:  # released, with its copy, by its successor (NEVER: none)
            if nxt[k] >= steps:
                out[k] = NEVER
                continue
            rel, first = due[nxt[k]], nxt[k] * per_step
            c = max(first_at_or_after(thresholds, max(due[k], rel), per_s), first)
            if copy:
                c = min(c, max(first_at_or_after(thresholds, max(t[k] + delay + dup_jit[s], rel), per_s), first))
        else:
            c = max(first_at_or_after(thresholds, due[k], per_s), k * per_step)
            if copy:
                c = min(c, max(first_at_or_after(thresholds, t[k] + delay + dup_jit[s], per_s), k * per_step))
        out[k] = c


@njit(cache=True)
def commands_in_force(e: np.ndarray, S: int, pt: np.ndarray, timeout_s: float, rec_check: np.ndarray,
                      rec_cmd: np.ndarray) -> tuple[int, int, int]:  # pragma: no cover
    """From the physics check each command arrives at (e [steps]; NEVER: never): the commands that take
    effect — the records, a command arriving before every later one (a later command arriving no later
    wins), in increasing order of both — into rec_check / rec_cmd (the check, the command's step; NEVER / 0
    after the last). Returns (the step whose period starts the vehicle's failsafe, NEVER: none: the first
    period start more than ``timeout_s`` after the last command took effect, at the period start at or
    after its arrival, or after the start; how many take effect before it: commands arriving in failsafe
    are refused; the most periods one of those took from its send)."""
    steps = e.shape[0]
    checks = steps * S
    m = 0
    following = NEVER
    for k in range(steps - 1, -1, -1):  # the records, found from the end
        v = e[k]
        if v < following and v < checks:
            rec_check[m] = v
            rec_cmd[m] = k
            m += 1
        if v < following:
            following = v
    for a in range(m // 2):  # into increasing order (a loop: an array slice's copy costs ~1.5 s of compile)
        b = m - 1 - a
        rec_check[a], rec_check[b] = rec_check[b], rec_check[a]
        rec_cmd[a], rec_cmd[b] = rec_cmd[b], rec_cmd[a]
    f = NEVER
    i = 0
    last = -1
    for p in range(steps):  # the timeout: at each period start, the time since the last command took effect
        while i < m and (rec_check[i] + S - 1) // S <= p:
            last = rec_check[i]
            i += 1
        last_t = pt[last] if last >= 0 else 0.0
        if (pt[p * S] - last_t) > timeout_s + 1e-9:
            f = p
            break
    limit = NEVER if f == NEVER else min(f, steps) * S
    kept = 0
    worst = 0
    while kept < m and rec_check[kept] < limit:  # the records arrive in increasing order: a prefix
        worst = max(worst, rec_check[kept] // S - rec_cmd[kept])
        kept += 1
    for j in range(kept, rec_check.shape[0]):
        rec_check[j] = NEVER
        rec_cmd[j] = 0
    return f, kept, worst


@njit(cache=True, nogil=True)
def plan_cells(lo: int, hi: int, keys: np.ndarray, ints: np.ndarray, fps: np.ndarray, bos: np.ndarray,
               nbos: np.ndarray, guard: np.ndarray, timeout_s: float, t: np.ndarray, pt: np.ndarray, S: int,
               rate_hz: float, physics_hz: float, mode: np.ndarray, state: np.ndarray, up_lost: np.ndarray,
               down_lost: np.ndarray, failsafe: np.ndarray, rec_check: np.ndarray, rec_cmd: np.ndarray,
               count: np.ndarray, ages: np.ndarray) -> None:  # pragma: no cover
    """Plan cells lo..hi-1, without the GIL. Per cell i and direction d (0 down, 1 up): keys[d, i],
    ints[d, i] and fps[d, i] (:func:`bridge.link.fates.fate_params`), blackouts bos[d, i, :nbos[d, i]];
    guard[i] = (stale_s, stop_s). Writes rows i of mode, state, up_lost, down_lost [cells, steps],
    failsafe[i], count[i], ages[i] = (oldest command used, oldest state used; control steps), and rows i - lo
    of rec_check / rec_cmd [hi - lo, steps]."""
    steps = t.shape[0]
    # counts as int64 variables, not literals: a literal argument compiles its callee once more (~1 s each)
    zero, one = steps - steps, S // S
    lost = np.zeros(steps, np.bool_)
    jit = np.zeros(steps)
    held = np.zeros(steps, np.bool_)
    dup = np.zeros(steps, np.bool_)
    dup_jit = np.zeros(steps)
    ok = np.zeros(steps, np.bool_)
    seq = np.arange(steps)
    due = np.empty(steps)
    nxt = np.empty(steps, np.int64)
    arrive = np.empty(steps, np.int64)
    newest = np.empty(steps, np.int64)
    mode0 = np.empty(steps, np.int8)
    down_thr = t + ends.EPS_T  # the controller's deliver(t)
    up_thr = pt[:-1] + ends.EPS_T
    for k in range(steps):  # the loop's deliver(t) and the period's deliver(p.t)
        up_thr[k * S] = max(t[k], pt[k * S]) + ends.EPS_T
    for i in range(lo, hi):
        # down: a state every step; the guard controls on the newest delivered (ControllerEnd, LinkGuard.observe)
        draw_cell(keys[0, i], ints[0, i], fps[0, i], steps, lost, jit, held, dup, dup_jit)
        for k in range(steps):
            seq[k] = k
            d = lost[k] or _blacked_out(bos[0, i], nbos[0, i], t[k])
            down_lost[i, k] = d
            ok[k] = not d
        _arrivals(ok, seq, steps, t, fps[0, i], jit, held, dup, dup_jit, down_thr, rate_hz, one, due, nxt, arrive)
        newest[:] = -1
        for j in range(steps):
            a = arrive[j]
            if a < steps and j > newest[a]:
                newest[a] = j
        stale, stop = guard[i, 0], guard[i, 1]
        n_sent = zero
        for k in range(steps):
            if k and newest[k] < newest[k - 1]:
                newest[k] = newest[k - 1]
            m = NONE
            if newest[k] >= 0:
                age = t[k] - t[newest[k]]
                if age <= stop:
                    m = TRACK if age <= stale else HOLD
            mode0[k] = m
            seq[k] = n_sent - 1 + (m != NONE)  # each command numbered by the cell's count (its packet number)
            n_sent += m != NONE
        # up: a command on every step the guard acts
        draw_cell(keys[1, i], ints[1, i], fps[1, i], n_sent, lost, jit, held, dup, dup_jit)
        for k in range(steps):
            sent = mode0[k] != NONE
            u = sent and (_blacked_out(bos[1, i], nbos[1, i], t[k]) or lost[max(seq[k], 0)])
            up_lost[i, k] = u
            ok[k] = sent and not u
        _arrivals(ok, seq, n_sent, t, fps[1, i], jit, held, dup, dup_jit, up_thr, physics_hz, S, due, nxt, arrive)
        fs, kept, worst = commands_in_force(arrive, S, pt, timeout_s, rec_check[i - lo], rec_cmd[i - lo])
        failsafe[i] = fs
        count[i] = kept
        ages[i, 0] = worst
        # after the failsafe the vehicle reports it: states newer than its step carry "not offboard" (idle)
        oldest = 0
        for k in range(steps):
            m = mode0[k] if newest[k] <= fs else NONE
            mode[i, k] = m
            if m != NONE:
                state[i, k] = newest[k]
                oldest = max(oldest, k - newest[k])
            else:
                state[i, k] = -1
                up_lost[i, k] = False
        ages[i, 1] = oldest
