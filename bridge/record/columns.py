"""The columns of every per-step record of a run: one table, imported by the writers and the readers.

In:  nothing but, for the helpers, an eq. (7) state (:func:`state_columns`) or a file's header
     (:func:`column_index`)
Out: column-name tuples; :class:`TraceRow`, :class:`VehicleRow`, :class:`ControllerRow`: one row of each file
     with its columns as named fields; a state in the trace's column order; the positions of named columns

- :data:`TRACE_COLUMNS`: ``trace.csv``, one row per control step (offline and SITL alike);
- :data:`VEHICLE_COLUMNS`: ``vehicle.bin``, the vehicle's half of a SITL trace (:mod:`bridge.record.halves`);
- :data:`CONTROLLER_COLUMNS`: ``controller.bin``, the controller's half.

Units: time s, position m, velocity m/s, angles rad, rates rad/s, ``u1..u4`` N (paper frame;
the torques are l·u2..u4 in N m), ``c1..c4`` normalised actuator command, ``*_wall`` monotonic wall clock s.
The state columns are the true state; the ``*_est`` columns (last, so the older columns keep their
places) the vehicle's on-board estimate of it, what the controller was sent (equal to the truth
under the ``truth`` estimator), and ``nees`` its NEES against its own covariance (every 10th step,
nan between; 0 under truth: no error). ``cmd_arrived`` (vehicle) and ``odo_arrived`` (controller) count the
targets of new steps (states) taken from the link since the side's previous record, the row's own included: one
superseded before it was used (two arrived in one period) is counted there, so the link's loss can be read from
the halves alone (:mod:`bridge.record.linkextract`).
"""

from __future__ import annotations

from collections import namedtuple
from collections.abc import Sequence

STATE_COLUMNS = ("x", "y", "z", "vx", "vy", "vz", "phi", "theta", "psi", "dphi", "dtheta", "dpsi")
REF_COLUMNS = ("x_ref", "y_ref", "z_ref", "psi_ref")
INPUT_COLUMNS = ("u1", "u2", "u3", "u4")
WIRE_COLUMNS = ("c1", "c2", "c3", "c4")
REALISED_COLUMNS = ("u1_act", "u2_act", "u3_act", "u4_act")
DESIRED_COLUMNS = ("phi_d", "theta_d")
ESTIMATE_COLUMNS = tuple(f"{c}_est" for c in STATE_COLUMNS)
TRACE_COLUMNS = (
    ("t",) + STATE_COLUMNS + REF_COLUMNS + INPUT_COLUMNS + WIRE_COLUMNS + REALISED_COLUMNS
    + ("state_age_s",) + DESIRED_COLUMNS + ESTIMATE_COLUMNS + ("nees",)
)
VEHICLE_COLUMNS = (
    ("k", "t") + STATE_COLUMNS + ("mode", "cmd_k") + WIRE_COLUMNS + INPUT_COLUMNS + REALISED_COLUMNS
    + ("state_age_s", "rtt_s", "odo_sent_wall", "cmd_recv_wall") + ESTIMATE_COLUMNS + ("nees", "cmd_arrived")
)
CONTROLLER_COLUMNS = (
    ("k", "t") + REF_COLUMNS + INPUT_COLUMNS + WIRE_COLUMNS + DESIRED_COLUMNS
    + ("odo_recv_wall", "cmd_sent_wall", "state_to_cmd_s", "period_error_s", "state_age_s", "odo_arrived")
)

# one row of each file with its columns as named fields (a tuple of floats: written, stacked into arrays and
# extended into array('d') as one), made from the column tuples above so that the two never differ
TraceRow = namedtuple("TraceRow", TRACE_COLUMNS)
TraceRow.__doc__ = "One ``trace.csv`` row (:data:`TRACE_COLUMNS`, in order; units in the module docstring)."
VehicleRow = namedtuple("VehicleRow", VEHICLE_COLUMNS)
VehicleRow.__doc__ = ("One ``vehicle.bin`` record (:data:`VEHICLE_COLUMNS`), filled by the file's header "
                      "(:class:`bridge.record.halves.HalfReader`).")
ControllerRow = namedtuple("ControllerRow", CONTROLLER_COLUMNS)
ControllerRow.__doc__ = "One ``controller.bin`` record (:data:`CONTROLLER_COLUMNS`), filled by the file's header."

_new_row = tuple.__new__  # TraceRow from one tuple at once: a third of the time of its 45-argument constructor


def state_columns(X: Sequence[float]) -> tuple[float, ...]:
    """Eq. (7) state -> the trace's state columns (x y z vx vy vz phi theta psi rates)."""
    return (X[0], X[2], X[4], X[1], X[3], X[5], X[6], X[8], X[10], X[7], X[9], X[11])


def trace_row(t: float, state: Sequence[float], ref: Sequence[Sequence[float]], demanded: Sequence[float],
              wire: Sequence[float], realised: Sequence[float], state_age_s: float,
              desired: Sequence[float], estimate: Sequence[float], nees: float) -> TraceRow:
    """One ``trace.csv`` row (:data:`TRACE_COLUMNS`), for the offline loop and the SITL joiner alike.

    ``state``: the trace's 12 state columns (:func:`state_columns`); ``ref``: the reference
    sample (x, y, z, psi; the values are taken); ``demanded``: u1..u4 N as the law asked;
    ``wire``: c1..c4 as sent; ``realised``: u1..u4 N as the plant realised; ``state_age_s``:
    age of the state the command came from (nan: none); ``desired``: (phi_d, theta_d) rad;
    ``estimate``: the vehicle's estimate in the state columns' order (:func:`state_columns`);
    ``nees``: its normalised estimation error squared (0 under ``truth``: no error).
    """
    return _new_row(TraceRow, (t, *state, ref[0][0], ref[1][0], ref[2][0], ref[3][0], *demanded, *wire, *realised,
                               state_age_s, *desired, *estimate, nees))


def column_index(columns: Sequence[str], names: Sequence[str], where: str) -> dict[str, int]:
    """Position of each of ``names`` in ``columns`` (a file's header); ValueError naming
    ``where`` and the first missing column."""
    pos = {c: i for i, c in enumerate(columns)}
    missing = [n for n in names if n not in pos]
    if missing:
        raise ValueError(f"{where}: no column {missing[0]!r} in its header")
    return {n: pos[n] for n in names}
