"""Covers controller.gains: the eq. (23) check and gains read from a mission's [gains] table.

Eq. (23): k2 > L and k1 > sqrt(4 L (k2 + L) / (k2 - L)), L bounding |d'| (erratum 7).
"""

from __future__ import annotations

import math
import tomllib

import pytest

from controller import Controller, Nominal
from controller.gains import PID_DEFAULTS, Gains, Twisting, check_twisting, gains_from_table
from controller.supertwisting import super_twisting_bound
from params import ConfigError
from plant import load_profile


def test_bound_values_of_law_md() -> None:
    """docs/law.md, "Gains": L = 1, k2 = 2 => k1 > 3.46; L = 2, k2 = 4 => k1 > 4.90."""
    assert super_twisting_bound(2.0, 1.0) == pytest.approx(math.sqrt(12.0))
    assert super_twisting_bound(2.0, 1.0) == pytest.approx(3.46, abs=5e-3)
    assert super_twisting_bound(4.0, 2.0) == pytest.approx(4.90, abs=5e-3)


def test_default_gains_pass() -> None:
    g = Gains()
    for st in (g.z_st, g.attitude_st, g.yaw_st):
        check_twisting(st)
        assert st.k2 > st.L and st.k1 > super_twisting_bound(st.k2, st.L)
    assert set(g.pid) == set(PID_DEFAULTS)


@pytest.mark.parametrize(
    "st, key, words",
    [
        (Twisting(5.0, 1.0, 1.0), "gains.z.k2", "k2 > L"),  # k2 = L
        (Twisting(5.0, 0.5, 1.0), "gains.z.k2", "k2 > L"),  # k2 < L
        (Twisting(3.4, 2.0, 1.0), "gains.z.k1", "3.464"),  # k1 just below sqrt(12)
        (Twisting(math.sqrt(12.0), 2.0, 1.0), "gains.z.k1", "sqrt"),  # k1 on the bound: strict
        (Twisting(5.0, 2.0, 0.0), "gains.z.L", "positive"),
    ],
)
def test_violations_name_the_key(st: Twisting, key: str, words: str) -> None:
    with pytest.raises(ConfigError) as exc:
        check_twisting(st, "gains.z")
    msg = str(exc.value)
    assert msg.startswith(key + ":") and words in msg


def test_construction_checks_every_loop() -> None:
    with pytest.raises(ConfigError, match=r"^gains\.attitude\.k1:"):
        Gains(attitude_st=Twisting(4.0, 4.0, 2.0))
    with pytest.raises(ConfigError, match=r"^gains\.yaw\.k2:"):
        Gains(yaw_st=Twisting(9.0, 1.0, 1.0))
    Gains(z_st=Twisting(3.5, 2.0, 1.0))  # the default set passes (docs/law.md, "Gains")


GOOD = """
smc_scale = 2.0
[z]
c = 2.5
alpha = 0.7
eps = 0.04
k1 = 4.5
k2 = 3.0
L = 1.5
[xy]
c_p = 1.2
c_v = 2.5
alpha = 0.75
eps_p = 0.03
eps_v = 0.01
[attitude]
k1 = 6.0
k2 = 5.0
L = 2.0
xi_max = 10.0
[yaw]
c = 4.0
[limits]
tilt_max = 0.5
[pid]
kp_pos = 3.0
"""


def test_gains_from_a_toml_table() -> None:
    g = gains_from_table(tomllib.loads(GOOD), "m.toml")
    assert (g.z.c, g.z.alpha, g.z.eps) == (2.5, 0.7, 0.04)
    assert (g.z_st.k1, g.z_st.k2, g.z_st.L) == (4.5, 3.0, 1.5)  # bound 4.243
    assert (g.position.c, g.position.alpha, g.position.eps) == (1.2, 0.75, 0.03)
    assert (g.velocity.c, g.velocity.alpha, g.velocity.eps) == (2.5, 0.75, 0.01)
    assert (g.attitude_st.k1, g.attitude_st.k2, g.attitude_st.xi_max) == (6.0, 5.0, 10.0)
    assert g.attitude == Gains().attitude  # not given: default
    assert g.yaw.c == 4.0 and g.yaw_st == Gains().yaw_st
    assert g.tilt_max == 0.5 and g.smc_scale == 2.0
    assert g.pid["kp_pos"] == 3.0 and g.pid["kd_pos"] == PID_DEFAULTS["kd_pos"]


def test_empty_table_is_the_defaults() -> None:
    assert gains_from_table({}, "m.toml") == Gains()


@pytest.mark.parametrize(
    "text, key",
    [
        ("[z]\nk1 = 2.0\n", "gains.z.k1"),  # eq. (23) bound 3.46
        ("[attitude]\nk2 = 2.0\n", "gains.attitude.k2"),  # k2 = L
        ("[yaw]\nalpha = 1.0\n", "gains.yaw.alpha"),  # alpha must be < 1
        ("[yaw]\nalpha = 0.5\n", "gains.yaw.alpha"),  # and > 1/2
        ("[xy]\nc_p = -1.0\n", "gains.xy.c_p"),
        ("[xy]\ngain = 1.0\n", "gains.xy.gain"),  # unknown
        ("kp = 1.0\n", "gains.kp"),  # unknown
        ('[z]\nc = "fast"\n', "gains.z.c"),  # wrong type
        ("z = 3\n", "gains.z"),  # a number where a table belongs
        ("[pid]\nkp_pos = -2.0\n", "gains.pid.kp_pos"),
        ("[limits]\ntilt_max = 2.0\n", "gains.limits.tilt_max"),
    ],
)
def test_bad_gains_name_file_and_key(text: str, key: str) -> None:
    with pytest.raises(ConfigError) as exc:
        gains_from_table(tomllib.loads(text), "missions/m.toml")
    msg = str(exc.value)
    assert msg.startswith(f"missions/m.toml: {key}:"), msg


def test_every_law_builds_with_default_gains() -> None:
    """Controller(name, nominal) with no gains: bsst, smc and pid all step."""
    nominal = Nominal.from_profile(load_profile("paper"))
    hover = ((0.0,) * 5, (0.0,) * 5, (1.0, 0, 0, 0, 0), (0.0,) * 5)
    X = (0.0,) * 4 + (1.0,) + (0.0,) * 7
    for name in ("bsst", "smc", "pid"):
        cmd = Controller(name, nominal).step(0.0, X, hover)
        assert cmd.demanded[0] == pytest.approx(nominal.mass * nominal.gravity, rel=1e-6)
        assert cmd.demanded[1:] == pytest.approx((0.0, 0.0, 0.0), abs=1e-9)
