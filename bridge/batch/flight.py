"""The whole flight of every cell of a batch in one compiled call: wire, prediction, law, actuation, plant
substeps, failsafe landing and figures, cell by cell over numba's threads.

In:  a batch's prepared flights (one mission, one control rate; :func:`bridge.batch.scope.flights_problem`
     says which), its link plan (:class:`bridge.link.plan.LinkPlan`) and clocks, the references (x, y, z,
     psi: m, rad, value and 4 derivatives) per control step
Out: per cell the running figures (:class:`bridge.batch.metrics.Metrics`: squared 3-D error m^2, the last
     step outside each settling band, the total variation and the history of u2 N), the steps flown and
     whether it diverged or crashed (touched the ground hard while armed)

:func:`fly_cells` flies control steps k0..k1 of a block of cells, each cell its own steps in order, without
the GIL: one compiled call per block of cells instead of a few dozen Python calls per control step, the
cell's state stays in the core's cache, and threads fly other blocks meanwhile (one per core:
bridge.batch.engine). The per-step helpers, here and in .plant, .control and .wire, are inlined
(``inline="always"``): called, each took the shared constants (a few hundred floats) by value, and the
step cost 1.44 us a cell instead of 1.0-1.1. In the step loop no array is read as a field of ``Cells`` or
through a view, nor handed to an inlined helper with branches (but a windy cell's gusts and turbulence, to
``_air``; events, on their steps): each costs two atomic reference counts a time, which numba's pruning
leaves, and they were a third of the step's time. A cell's
flight depends on nothing of another cell's, so the rows are the same whatever the number of threads.
Per cell and step it runs what the engine ran over the cell axis before, in the same order and with the
same functions (bridge.batch.kernels, .wire, .plant, .control, .predict): the state over the float32 wire
into the ring of states the guard may use; on the steps the guard acts, that state (carried to t + lag
where the cell predicts), the law, the actuation, the integrators, the command over the wire into the
ring of commands; the figures; then each physics step: the command that takes effect there, the
``descend`` landing after a failsafe, the motor lag, the disturbance and the RK4 step.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import numpy as np

from bridge.autopilot.failsafe import DEFAULT_GAINS
from bridge.autopilot.kernelcache import njit
from bridge.batch import kernels as K
from bridge.batch.control import BatchActuation, allocate_cell
from bridge.batch.plant import (
    BatchPlant,
    battery_cell,
    disturbance_cell,
    diverged_cell,
    events_cell,
    held_cell,
    realised_cell,
    rk4_cell,
    targets_cell,
    wind_cell,
)
from bridge.batch.predict import BatchPredictor, carry, record
from bridge.batch.weather import faulty, weather_arrays
from bridge.batch.wire import command_over_wire, state_over_wire
from bridge.core.flight import Flight
from bridge.link import plan_cell  # its constants compiled in as plan_cell.X: the cache's closure (kernelcache)
from bridge.link.plan import Clocks, LinkPlan
from bridge.record import metrics as record_metrics
from controller.bsst import law_constants, law_tables
from controller.pid import pid_constants

_BSST, _SMC, _PID, _BSST_IMPLICIT = 0, 1, 2, 3  # the cells' laws (bsst: its super-twisting step explicit or implicit)


def law_code(controller: str, discretization: str) -> int:
    """The kernel's code of a cell's law and discretization (only ``bsst`` has a step it changes)."""
    if controller == "bsst":
        return _BSST_IMPLICIT if discretization == "implicit" else _BSST
    return {"smc": _SMC, "pid": _PID}[controller]


class Constants(NamedTuple):
    """What every cell of a batch shares (plain numbers and tuples, typed once for the compiled kernel)."""

    substeps: int  # physics steps per control step
    rate_hz: float
    dt: float  # control period, s
    h: float  # physics step, s
    ground: bool
    motors: bool  # the plant's profile flies rotor speeds
    lagged: bool  # ... with motor lag
    disturbed: bool
    lag_k: float  # the motor lag's factor per physics step
    wrench_wire: bool  # the command crosses the wire as a wrench (else as four motor commands)
    body: tuple  # plant.model.rk4_constants of the plant
    u_max: tuple  # the plant's limits (N)
    b: float  # the plant's thrust and drag coefficients, top rotor speed (rad/s)
    d: float
    omega_max: float
    freq_hz: float  # the disturbance
    dist_const: tuple
    dist_amp: tuple
    law: Any  # controller.bsst.LawConstants (explicit super-twisting step)
    law_implicit: Any  # the same with the implicit step's period
    tables: tuple  # controller.bsst.law_tables
    k1: tuple  # the super-twisting integrators' gains and bounds per channel (z, phi, theta, yaw)
    k2: tuple
    xi_max: tuple
    pid: Any  # controller.pid.PidConstants
    i_max: float
    nom_motors: bool  # the nominal model's actuation (the laws' and the landing's allocation)
    nom_u_max: tuple
    nom_b: float
    nom_d: float
    nom_omega_max: float
    nom_w2_max: float
    land: tuple  # bridge.autopilot.onboard.level_wrench's constants after X
    dt_max: float  # the predictor's: largest step (s), nominal mass and gravity, coefficients
    pm: float
    pg: float
    coef: tuple
    start: tuple  # the start state (eq. 7)
    band: tuple  # the settling bands x, y, z (m)
    body_air: tuple  # the same of a cell in a [wind] (the profile's drag on, on the airspeed)
    rotor_drag: float  # the plant's rotor drag in wind (s/m)
    speeds: bool  # a command holds rotor speeds (motor lag, or faults), not their wrench
    faulty: bool  # a cell's rotor may fail (motor events): the wrench from the speeds and each rotor's effectiveness
    battery: bool  # the x500's battery ([effects] battery): its sag caps the rotors' speed
    pack: tuple  # plant.battery.pack_constants; the rotors' drag-torque factor (N m s^2); the full pack's V
    torque_factor: float
    full_v: float


class Cells(NamedTuple):
    """Every cell's arrays: [n, ...] cell first where the engine made them, the plan's and the
    predictor's in their own layout ([n, steps], [depth, n])."""

    X: np.ndarray  # [n, 12] the plant's state
    ring_X: np.ndarray  # [n, R, 12] the states over the wire, by step
    ring_held: np.ndarray  # [n, H, 5] what each command holds, by step
    holding: np.ndarray  # [n, 5] what the vehicle holds now (u1..u4 N and omega_d; with motor lag target speeds)
    omega: np.ndarray  # [n, 4] the rotor speeds under motor lag (rad/s)
    phases: np.ndarray  # [n, 6] the disturbance's
    law: np.ndarray  # [n] int8: law_code
    xi: np.ndarray  # [n, 4] the super-twisting integrators
    integral: np.ndarray  # [n, 3] the PID's
    omega_d: np.ndarray  # [n] the law's last allocated omega_d (rad/s)
    predicts: np.ndarray  # [n] bool
    lag: np.ndarray  # [n] the command lag (s)
    ref_idx: np.ndarray  # [n] which of refs the cell's law reads (0: at t; others at t + its lag)
    refs: np.ndarray  # [tables, steps, 4, 5]
    from_t: np.ndarray  # the predictor's (bridge.batch.predict.carry)
    cache_t: np.ndarray
    cache_X: np.ndarray
    cmd_t: np.ndarray
    cmd_u: np.ndarray
    total: np.ndarray
    mode: np.ndarray  # the plan's [n, steps] int8
    state_step: np.ndarray  # [n, steps] int32
    apply_check: np.ndarray  # [n, slots] int64
    apply_cmd: np.ndarray  # [n, slots] int32
    failsafe_step: np.ndarray  # [n] int64
    ptr: np.ndarray  # [n] the next command to take effect (index into apply_check)
    in_failsafe: np.ndarray  # [n] bool
    armed: np.ndarray  # [n] bool
    sq_sum: np.ndarray  # the figures (bridge.batch.metrics.Metrics)
    sq_max: np.ndarray
    last_out: np.ndarray
    tv: np.ndarray
    u2: np.ndarray  # [n, steps]
    u2_now: np.ndarray  # [n]
    seg_of: np.ndarray  # [steps] the set-point change each step follows (-1: none)
    late: np.ndarray  # [steps] bool: the step counts in the RMS
    t_step: np.ndarray  # [steps] s
    t_plant: np.ndarray  # [physics steps + 1] the plant's clock (s)
    alive: np.ndarray  # [n] bool
    flown: np.ndarray  # [n] steps flown
    diverged: np.ndarray  # [n] bool
    impact: np.ndarray  # [n] int8: 0 no hard touchdown; this period one armed 1, disarmed 3; 2 noted (plant_verdict)
    crashed: np.ndarray  # [n] bool: touched down hard while armed
    # the cells' air and events (bridge.batch.weather.Weather)
    windy: np.ndarray  # [n] bool: the cell flies in air (bridge.batch.plant.wind_cell)
    wind: np.ndarray  # [n, 3] the steady wind (m/s NWU)
    gusts: np.ndarray  # [n, G, 4] the gusts (t_s s, duration_s s, amplitude m/s, from_deg in rad)
    n_gusts: np.ndarray  # [n]
    turb_idx: np.ndarray  # [n] the cell's row of turb (-1: none)
    turb: np.ndarray  # [rows, physics steps, 3] the turbulence's samples (m/s NWU)
    event_step: np.ndarray  # [n, E + 1] the control step of each event
    events: np.ndarray  # [n, E + 1, 4] what each does
    next_event: np.ndarray  # [n]
    effectiveness: np.ndarray  # [n, 4] the rotors'
    pack: np.ndarray  # [n, 3] the battery's charge used (mAh), drawn (A s), and the speed cap (of omega_max)


@njit(cache=True, nogil=True)
def fly_cells(lo: int, hi: int, k0: int, k1: int, c: Constants, a: Cells) -> None:  # pragma: no cover
    """Control steps k0..k1-1 of the cells lo..hi-1 still flying; without the GIL, so that threads fly
    other cells meanwhile."""
    for j in range(lo, hi):
        if a.alive[j]:
            _fly_cell(j, k0, k1, c, a)


@njit(cache=True)
def _fly_cell(j: int, k0: int, k1: int, c: Constants, a: Cells) -> None:  # pragma: no cover
    """Cell j's steps k0..k1-1: its state read into locals, flown, written back. Every array the loop touches
    is taken out of ``a`` once, here, and indexed in place, element by element: a field of ``a`` read in the
    loop, a view (``ring_X[j, s]``) or an array handed to an inlined helper each cost two atomic reference
    counts a time, and they were a third of the step's time (perf: NRT_incref and NRT_decref)."""
    x, hold, om, xi, integ, od, ptr, fs, armed, u2, impact, steady, pk, eff = _cell_state(j, a)
    ph = (a.phases[j, 0], a.phases[j, 1], a.phases[j, 2], a.phases[j, 3], a.phases[j, 4], a.phases[j, 5])
    lc, windy, ti, predicts, lag, table, fs_step = a.law[j], a.windy[j], a.turb_idx[j], a.predicts[j], a.lag[j], \
        a.ref_idx[j], a.failsafe_step[j]
    ring_X, ring_held, mode, state_step, refs, late, seg_of, t_plant = a.ring_X, a.ring_held, a.mode, a.state_step, \
        a.refs, a.late, a.seg_of, a.t_plant
    apply_check, apply_cmd, u2_a, last_out, t_step = a.apply_check, a.apply_cmd, a.u2, a.last_out, a.t_step
    from_t, cache_t, cache_X, cmd_t, cmd_u, total = a.from_t, a.cache_t, a.cache_X, a.cmd_t, a.cmd_u, a.total
    next_event, event_step, events, turb, gusts, n_gusts = a.next_event, a.event_step, a.events, a.turb, a.gusts, \
        a.n_gusts
    body = c.body_air if windy else c.body
    sq_sum, sq_max, tv = a.sq_sum[j], a.sq_max[j], a.tv[j]
    n_ring, n_held, S = ring_X.shape[1], ring_held.shape[1], c.substeps
    for k in range(k0, k1):
        t = k / c.rate_hz
        w = state_over_wire(x)  # what the laws read: ODOMETRY float32, as offline
        slot = k % n_ring
        for i in range(12):
            ring_X[j, slot, i] = w[i]
        m = mode[j, k]
        if m != plan_cell.NONE:
            s = state_step[j, k] % n_ring
            xg = (ring_X[j, s, 0], ring_X[j, s, 1], ring_X[j, s, 2], ring_X[j, s, 3], ring_X[j, s, 4],
                  ring_X[j, s, 5], ring_X[j, s, 6], ring_X[j, s, 7], ring_X[j, s, 8], ring_X[j, s, 9],
                  ring_X[j, s, 10], ring_X[j, s, 11])
            if predicts:
                xg = carry(j, t_step[state_step[j, k]], xg, t + lag, from_t, cache_t, cache_X, cmd_t, cmd_u,
                           total, c.dt_max, c.pm, c.pg, c.coef)
            ref = (_row(refs, table, k, 0), _row(refs, table, k, 1), _row(refs, table, k, 2), _row(refs, table, k, 3))
            u, real, cmd, od, xi, integ = _law_step(xg, ref, lc, xi, integ, od, m == plan_cell.HOLD, c)
            if predicts:
                record(j, t, lag, real, od, cmd_t, cmd_u, total)
            u2 = u[1]
            cw = command_over_wire(cmd, c.wrench_wire)  # under a battery: the command itself (targets_cell)
            held = (cw[0], cw[1], cw[2], cw[3], 0.0) if c.battery else held_cell(cw, c.motors, c.speeds, c.u_max,
                                                                                  c.b, c.d, c.omega_max)
            hslot = k % n_held
            for i in range(5):
                ring_held[j, hslot, i] = held[i]
        # the figures of the trace row of step k (bridge.batch.metrics.Metrics), summed in locals
        ex, ey, ez = x[0] - refs[0, k, 0, 0], x[2] - refs[0, k, 1, 0], x[4] - refs[0, k, 2, 0]
        e2 = ex * ex + ey * ey + ez * ez
        if late[k]:
            sq_sum += e2
            if e2 > sq_max or e2 != e2:  # np.maximum's: a nan stays
                sq_max = e2
        seg = seg_of[k]
        if seg >= 0:  # the last step outside the settling band so far, per axis
            if abs(ex) > c.band[0]:
                last_out[seg, 0, j] = k
            if abs(ey) > c.band[1]:
                last_out[seg, 1, j] = k
            if abs(ez) > c.band[2]:
                last_out[seg, 2, j] = k
        if k:
            tv += abs(u2 - u2_a[j, k - 1])
        u2_a[j, k] = u2
        fs = fs or fs_step == k
        if event_step[j, next_event[j]] <= k:  # the timeline's events of this step, before its physics
            steady, eff = events_cell(j, k, steady, eff, next_event, event_step, events)
        for i in range(S):  # the physics steps, each after the command that takes effect there
            check = k * S + i
            if apply_check[j, ptr] == check:
                q = apply_cmd[j, ptr] % n_held
                hold = (ring_held[j, q, 0], ring_held[j, q, 1], ring_held[j, q, 2], ring_held[j, q, 3],
                        ring_held[j, q, 4])
                if c.battery:  # Quadrotor.command under the battery's speed cap now
                    hold = targets_cell(hold, pk[2], c.omega_max)
                ptr += 1
            air = _air(steady, turb, ti, check, gusts[j], n_gusts[j], t_plant[check], c.rotor_drag) if windy else \
                (0.0, 0.0, 0.0, 0.0)
            x, hold, om, after, hard, pk = _physics_step(x, hold, om, fs and armed, armed, ph, t_plant[check], air,
                                                         windy, body, eff, pk, c)
            if hard and impact == 0:  # the first hard touchdown (Quadrotor.impact): armed as it touched down, or not
                impact = 1 if armed else 3
            armed = after  # (the landing disarms on the ground the step after its touchdown)
        if diverged_cell(x):  # SimVehicle.plant_verdict: diverged, else a hard touchdown armed ends the flight
            a.diverged[j], a.alive[j], a.flown[j] = True, False, k + 1
            x = c.start  # a resting state: no nan downstream
            break
        if impact == 1 or impact == 3:  # noted: armed at it, crashed (ImpactWatch); disarmed, the flight goes on
            crashed, impact = impact == 1, 2
            if crashed:
                a.crashed[j], a.alive[j], a.flown[j] = True, False, k + 1
                break
    a.sq_sum[j], a.sq_max[j], a.tv[j] = sq_sum, sq_max, tv
    _put_cell_state(j, a, x, hold, om, xi, integ, od, ptr, fs, armed, u2, impact, steady, pk, eff)


@njit(cache=True, inline="always")
def _cell_state(j: int, a: Cells) -> tuple:  # pragma: no cover
    """Cell j's flight state as locals: (x, hold, om, xi, integ, od, ptr, fs, armed, u2, impact, steady, pk, eff)
    (the fields of :class:`Cells` of the same names)."""
    X, h, o, xi, ig, w, p, e = a.X, a.holding, a.omega, a.xi, a.integral, a.wind, a.pack, a.effectiveness
    x = (X[j, 0], X[j, 1], X[j, 2], X[j, 3], X[j, 4], X[j, 5], X[j, 6], X[j, 7], X[j, 8], X[j, 9], X[j, 10],
         X[j, 11])
    return (x, (h[j, 0], h[j, 1], h[j, 2], h[j, 3], h[j, 4]), (o[j, 0], o[j, 1], o[j, 2], o[j, 3]),
            (xi[j, 0], xi[j, 1], xi[j, 2], xi[j, 3]), (ig[j, 0], ig[j, 1], ig[j, 2]), a.omega_d[j], a.ptr[j],
            a.in_failsafe[j], a.armed[j], a.u2_now[j], a.impact[j], (w[j, 0], w[j, 1], w[j, 2]),
            (p[j, 0], p[j, 1], p[j, 2]), (e[j, 0], e[j, 1], e[j, 2], e[j, 3]))


@njit(cache=True, inline="always")
def _put_cell_state(j: int, a: Cells, x: tuple, hold: tuple, om: tuple, xi: tuple, integ: tuple, od: float,
                    ptr: int, fs: bool, armed: bool, u2: float, impact: int, steady: tuple, pk: tuple,
                    eff: tuple) -> None:  # pragma: no cover
    """Write cell j's flight state back into ``a`` (:func:`_cell_state`'s fields)."""
    for i in range(12):
        a.X[j, i] = x[i]
    for i in range(5):
        a.holding[j, i] = hold[i]
    for i in range(4):
        a.omega[j, i] = om[i]
        a.xi[j, i] = xi[i]
        a.effectiveness[j, i] = eff[i]
    for i in range(3):
        a.integral[j, i] = integ[i]
        a.wind[j, i] = steady[i]
        a.pack[j, i] = pk[i]
    a.omega_d[j], a.ptr[j], a.in_failsafe[j], a.armed[j], a.u2_now[j], a.impact[j] = od, ptr, fs, armed, u2, impact


@njit(cache=True, inline="always")
def _air(steady: tuple, turb: np.ndarray, ti: int, check: int, gusts: np.ndarray, n_gusts: int, t: float,
         rotor_drag: float) -> tuple:  # pragma: no cover
    """The air of a windy cell's physics step ``check`` at t (s): (wind m/s NWU, the rotor drag s/m). Wind.now:
    the steady wind plus the turbulence's sample (row ti of turb; -1: none), then the gusts."""
    st = steady
    if ti >= 0:
        st = (steady[0] + turb[ti, check, 0], steady[1] + turb[ti, check, 1], steady[2] + turb[ti, check, 2])
    w = wind_cell(st, gusts, n_gusts, t)
    return (w[0], w[1], w[2], rotor_drag)


@njit(cache=True, inline="always")
def _row(refs: np.ndarray, table: int, k: int, r: int) -> tuple:  # pragma: no cover
    """Row r (x, y, z, psi) of the reference sample of step k in table ``table`` of refs [tables, steps, 4, 5]:
    value and 4 derivatives, read element by element (no view)."""
    return (refs[table, k, r, 0], refs[table, k, r, 1], refs[table, k, r, 2], refs[table, k, r, 3],
            refs[table, k, r, 4])


@njit(cache=True, inline="always")
def _law_step(xg: tuple, sample: tuple, law: int, xi: tuple, integ: tuple, od: float, idle: bool,
              c: Constants) -> tuple:  # pragma: no cover
    """One cell's law step on the state xg: (demanded u, realisable, normalised command, omega_d, the
    super-twisting integrators xi after the step, the PID's integrals after it); ``idle`` cells (the guard
    holds) do not integrate."""
    if law == _PID:
        r = K.pid_law(xg, sample, integ, c.pid)
        u = (r[0], r[1], r[2], r[3])
        s = (r[4], r[5], r[6], 0.0)  # the position errors
    else:
        q = K.backstepping(xg, sample, od, xi, law == _SMC, c.law_implicit if law == _BSST_IMPLICIT else c.law,
                           c.tables)
        u = (q[0], q[1], q[2], q[3])
        s = (q[4], q[5], q[6], q[7])  # the sliding variables
    real, cmd, sat, od = allocate_cell(u, c.nom_motors, c.nom_u_max, c.nom_b, c.nom_d, c.nom_omega_max,
                                       c.nom_w2_max)
    if law == _BSST:
        xi = (K.advance_xi(xi[0], s[0], c.k2[0], c.dt, c.xi_max[0], idle or sat[0]),
              K.advance_xi(xi[1], s[1], c.k2[1], c.dt, c.xi_max[1], idle or sat[1]),
              K.advance_xi(xi[2], s[2], c.k2[2], c.dt, c.xi_max[2], idle or sat[2]),
              K.advance_xi(xi[3], s[3], c.k2[3], c.dt, c.xi_max[3], idle or sat[3]))
    elif law == _BSST_IMPLICIT:
        xi = (K.advance_xi_implicit(xi[0], s[0], c.k1[0], c.k2[0], c.dt, c.xi_max[0], idle or sat[0]),
              K.advance_xi_implicit(xi[1], s[1], c.k1[1], c.k2[1], c.dt, c.xi_max[1], idle or sat[1]),
              K.advance_xi_implicit(xi[2], s[2], c.k1[2], c.k2[2], c.dt, c.xi_max[2], idle or sat[2]),
              K.advance_xi_implicit(xi[3], s[3], c.k1[3], c.k2[3], c.dt, c.xi_max[3], idle or sat[3]))
    elif law == _PID and not (idle or sat[0]):
        integ = K.pid_integrals(integ, (s[0], s[1], s[2]), c.dt, c.i_max)
    return u, real, cmd, od, xi, integ


@njit(cache=True, inline="always")
def _physics_step(x: tuple, hold: tuple, om: tuple, landing: bool, armed: bool, ph: tuple, t: float, air: tuple,
                  windy: bool, body: tuple, eff: tuple, pk: tuple, c: Constants) -> tuple:  # pragma: no cover
    """One physics step of one cell from state x at t (s), holding ``hold`` (u1..u4 N and omega_d, or target
    speeds under motor lag or faults), rotor speeds om under lag: the ``descend`` landing where ``landing`` (in
    failsafe and armed; on the ground it disarms and commands zero), the motor lag, the rotors'
    effectiveness ``eff`` (0..1, where the batch is ``faulty``), the battery's draw and cap (``pk``: used mAh,
    charge A s, speed cap; plant.battery), the disturbance
    (phases ph), RK4 (``body``: plant.model.rk4_constants) in the air ``air`` (wind m/s, rotor drag s/m) where
    the cell is ``windy``, and the ground.
    (x, hold, om, armed, whether it touched the ground hard, pk) after it."""
    if landing:
        if x[4] <= 0.0 and x[5] <= 0.0 and c.ground:
            armed = False
            cmd = (0.0, 0.0, 0.0, 0.0)
        else:
            w = K.level_wrench(x, c.land[0], c.land[1], c.land[2], c.land[3], c.land[4], c.land[5], c.land[6],
                               c.land[7], c.land[8], c.land[9])
            cmd = allocate_cell(w, c.nom_motors, c.nom_u_max, c.nom_b, c.nom_d, c.nom_omega_max, c.nom_w2_max)[1]
        hold = targets_cell(cmd, pk[2], c.omega_max) if c.battery else held_cell(cmd, c.motors, c.speeds, c.u_max,
                                                                                c.b, c.d, c.omega_max)
    if c.battery:  # Quadrotor._draw_battery: the draw at the speeds now, the targets under its cap
        hold, pk = battery_cell(hold, om, pk, c.lagged, c.pack, c.torque_factor, c.h, c.full_v, c.omega_max)
    if c.lagged:
        om = (om[0] + (hold[0] - om[0]) * c.lag_k, om[1] + (hold[1] - om[1]) * c.lag_k,
              om[2] + (hold[2] - om[2]) * c.lag_k, om[3] + (hold[3] - om[3]) * c.lag_k)
        u = realised_cell(om, eff, c.faulty, c.b, c.d)
    elif c.speeds:  # the rotors at the held speeds (a cell whose rotors may fail)
        om = (hold[0], hold[1], hold[2], hold[3])
        u = realised_cell(om, eff, c.faulty, c.b, c.d)
    else:
        u = hold
    if c.disturbed:
        ext = (disturbance_cell(c.freq_hz, c.dist_const, c.dist_amp, ph, t),
               disturbance_cell(c.freq_hz, c.dist_const, c.dist_amp, ph, t + 0.5 * c.h),
               disturbance_cell(c.freq_hz, c.dist_const, c.dist_amp, ph, t + c.h))
    else:
        z = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        ext = (z, z, z)
    y, hard = rk4_cell(x, u, ext, c.disturbed, body, c.h, c.ground, air, windy)
    return y, hold, om, armed, hard, pk


def batch_arrays(flights: Sequence[Flight], plan: LinkPlan, clocks: Clocks, refs: np.ndarray,
                 lagged_refs: Callable[[float], np.ndarray]) -> tuple[Constants, Cells]:
    """The constants and the arrays of a batch of flights (one mission and rate) flown along ``plan``:
    the state at the mission's start, the laws' integrators at zero, the commands the vehicle holds at
    rest. ``refs`` [steps, 4, 5]: the reference at each step; ``lagged_refs(lag)``: the same at t + lag (s)."""
    f0 = flights[0]
    m, nominal, gains = f0.mission, f0.nominal, f0.gains
    n, steps, rate = len(flights), clocks.steps, clocks.rate_hz
    # each flight's own start: the mission's, or with [start] scatter_m the one its seed draws (missions.scatter)
    states = np.array([(x, 0.0, y, 0.0, z, 0.0, 0.0, 0.0, 0.0, 0.0, psi, 0.0)
                       for x, y, z, psi in (f.mission.flight_start for f in flights)], float).T
    start = tuple(float(v) for v in states[:, 0])  # the first flight's: where a diverged cell is put (no nan)
    plant = BatchPlant(f0.profile, f0.effects, [f.mission.seed for f in flights], physics_hz=m.physics_hz,
                       state=states, faulty=faulty(flights))
    act = BatchActuation(nominal, n)
    dist = plant.effects.disturbance
    st = (gains.z_st, gains.attitude_st, gains.attitude_st, gains.yaw_st)  # z, phi (u2), theta (u3), yaw
    guards = [f.guard for f in flights]
    predicts = np.array([g.compensation == "predict" for g in guards])
    lag = np.array([g.lag_s for g in guards])
    tables, ref_idx = [refs], np.zeros(n, np.int64)
    for v in sorted({float(v) for v in lag[predicts]} - {0.0}):
        ref_idx[predicts & (lag == v)] = len(tables)
        tables.append(lagged_refs(v))
    depth = plan.state_age_max + int(math.ceil(float(lag.max()) * rate)) + 4 if predicts.any() else 1
    pred = BatchPredictor(nominal, 1.0 / rate, lag, depth)
    og = DEFAULT_GAINS
    p = f0.profile
    c = Constants(
        clocks.substeps, float(rate), 1.0 / rate, plant.dt, plant.ground, plant.motors, plant.lagged,
        plant.disturbed, plant._lag_k, nominal.actuation == "wrench", plant.body.constants, plant._u_max,
        p.thrust_coeff, p.drag_coeff, p.omega_max, float(dist.freq_hz), tuple(dist.force_const + dist.torque_const),
        tuple(dist.force_amp + dist.torque_amp), law_constants(nominal, gains),
        law_constants(nominal, gains, 1.0 / rate), law_tables(gains), tuple(float(s.k1) for s in st),
        tuple(float(s.k2) for s in st), tuple(float(s.xi_max) for s in st), pid_constants(nominal, gains),
        float(gains.pid["i_max"]), act.motors, act.u_max, act.b, act.d, act.omega_max, act.w2_max,
        (-f0.failsafe.descent_rate, nominal.mass, nominal.gravity, nominal.ixx / nominal.arm,
         nominal.iyy / nominal.arm, nominal.izz / nominal.arm, og.k_vel_level, og.k_att_level, og.d_att_level,
         og.d_yaw),
        pred.dt_max, pred.m, pred.g, tuple(float(v) for v in pred._coefficients), start,
        tuple(record_metrics.BANDS[axis] for axis in "xyz"), plant.body_air.constants, float(p.rotor_drag),
        plant.speeds,
        plant.faulty, *plant.pack)
    holding = np.zeros((n, 5))
    holding[:, :plant.holding.shape[0]] = plant.holding.T
    changes = list(m.trajectory.change_times())
    t_step = clocks.step_t
    a = Cells(
        np.ascontiguousarray(plant.X.T), np.zeros((n, plan.state_age_max + 1, 12)),
        np.zeros((n, plan.cmd_age_max + 1, 5)), holding, np.ascontiguousarray(plant.omega.T),
        np.ascontiguousarray(plant._phases.T) if plant.disturbed else np.zeros((n, 6)),
        np.array([law_code(f.mission.controller, f.mission.discretization) for f in flights], np.int8),
        np.zeros((n, 4)), np.zeros((n, 3)),
        np.zeros(n), predicts, lag, ref_idx, np.ascontiguousarray(np.stack(tables)), pred.from_t, pred.cache_t,
        pred.cache_X, pred.cmd_t, pred.cmd_u, pred.total, plan.mode, plan.state_step, plan.apply_check,
        plan.apply_cmd, plan.failsafe_step, np.zeros(n, np.int64), np.zeros(n, bool), np.ones(n, bool),
        np.zeros(n), np.zeros(n), np.full((max(1, len(changes)), 3, n), -1, np.int64), np.zeros(n),
        np.zeros((n, steps)), np.zeros(n),
        (np.searchsorted(np.array(changes), t_step, side="right") - 1).astype(np.int64),
        t_step >= min(record_metrics.RMS_FROM_S, 0.5 * m.duration_s), t_step, clocks.plant_t, np.ones(n, bool),
        np.full(n, steps, np.int64), np.zeros(n, bool), np.zeros(n, np.int8), np.zeros(n, bool),
        *weather_arrays(flights, clocks), np.tile([0.0, 0.0, 1.0], (n, 1)))
    return c, a

