"""PX4's parameter names that a mission takes, and the table each goes in: what an unknown key's refusal says when the
key is one of them, in any case, in a table that does not take it (``[trajectory] mpc_acc_hor`` on a sine).

In:  nothing (the names: :data:`bridge.autopilot.params.PARAMS`, the vehicle's, and
     :data:`missions.route.LIMIT_RANGES`, a plan's limits; tests/test_bad_input.py holds the two equal to these)
Out: :data:`PX4_NAMES`, name -> where it goes, in a message's words (``{name}``: the name); :func:`px4_hint`,
     the hint for a key

(Here, and not read from those two, as the imports point down only: ``params`` reads neither ``bridge`` nor
``missions``.)
"""

from __future__ import annotations

_IN_PARAMS = (  # the vehicle's parameters (bridge.autopilot.params.PARAMS): a mission's [params] table
    "COM_OF_LOSS_T", "COM_OBL_ACT", "COM_OBL_RC_ACT", "COM_FAIL_ACT_T", "MPC_LAND_SPEED", "MPC_Z_V_AUTO_DN",
    "MPC_LAND_ALT1", "MPC_LAND_ALT2", "MIS_TAKEOFF_ALT", "MAV_SYS_ID", "RTL_RETURN_ALT", "RTL_DESCEND_ALT",
    "RTL_CONE_ANG", "RTL_MIN_DIST", "NAV_ACC_RAD", "SYS_FAILURE_EN", "COM_DISARM_PRFLT", "GF_MAX_HOR_DIST",
    "GF_MAX_VER_DIST", "GF_ACTION", "BAT_LOW_THR", "BAT_CRIT_THR", "BAT_EMERGEN_THR", "COM_LOW_BAT_ACT",
    "EKF2_NOAID_TOUT", "COM_DISARM_LAND",
)
_PLAN_LIMITS = (  # a plan's speed and acceleration limits (missions.route.LIMIT_RANGES): its [trajectory] table
    "MPC_XY_CRUISE", "MPC_ACC_HOR", "MPC_Z_V_AUTO_UP", "MPC_Z_V_AUTO_DN", "MPC_ACC_UP_MAX", "MPC_ACC_DOWN_MAX",
    "MPC_YAWRAUTO_MAX",
)
PX4_NAMES: dict[str, str] = {  # MPC_Z_V_AUTO_DN is both: the vehicle's landing, and a plan's descent
    **{n: 'a PX4 limit of a plan\'s trajectory: put it in a [trajectory] of kind = "plan" as {name}'
       for n in _PLAN_LIMITS},
    **{n: "a PX4 parameter: put it in [params] as {name}" for n in _IN_PARAMS},
}


def px4_hint(key: str) -> str | None:
    """Where ``key``, a PX4 parameter's name in any case, goes (``a PX4 parameter: put it in [params] as
    COM_OF_LOSS_T``); None for any other key."""
    where = PX4_NAMES.get(key.upper())
    return None if where is None else where.format(name=key.upper())
