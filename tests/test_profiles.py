"""Covers plant.profiles: vehicle profiles load into frozen dataclasses and are validated.

Every bad value raises params.ConfigError naming the file and the key (and the range).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import pytest

from params import ConfigError
from plant import Profile, load_profile, profile_names
from plant.profiles import PROFILE_DIR

X500_TEXT = (PROFILE_DIR / "x500.toml").read_text()


def test_builtin_profiles_load() -> None:
    assert {"paper", "x500"} <= set(profile_names())
    for name in profile_names():
        p = load_profile(name)
        assert isinstance(p, Profile) and p.name == name
        assert p.omega_max > p.hover_omega
        assert p.u_max[0] > p.mass * p.gravity


def test_paper_is_table_1() -> None:
    p = load_profile("paper")
    assert p.actuation == "wrench"
    assert (p.mass, p.arm, p.ixx, p.iyy, p.izz) == (1.1, 0.21, 1.22, 1.22, 2.2)
    assert (p.rotor_inertia, p.thrust_coeff, p.drag_coeff) == (0.2, 5.0, 2.0)
    assert p.drag == (0.1, 0.1, 0.1, 0.12, 0.12, 0.12)
    assert p.u_max == pytest.approx((4 * 1.1 * 9.81, 60.0, 60.0, 60.0))


def test_x500_is_px4s_numbers_with_the_rotor_envelope() -> None:
    p = load_profile("x500")
    assert p.actuation == "motors"
    assert (p.mass, p.arm, p.omega_max, p.rotor_inertia) == (2.0, 0.25, 1000.0, 1e-5)
    assert p.ixx == pytest.approx(0.0217, abs=1e-4) and p.izz == pytest.approx(0.040, abs=1e-4)
    assert p.thrust_coeff == 8.54858e-06
    assert p.drag_coeff == pytest.approx(0.016 * 8.54858e-06 / 0.25, rel=1e-12)
    b, d, w = p.thrust_coeff, p.drag_coeff, p.omega_max
    assert p.u_max == pytest.approx((4 * b * w * w, b * w * w, b * w * w, 2 * d * w * w))


def test_profile_is_frozen() -> None:
    p = load_profile("paper")
    with pytest.raises(dataclasses.FrozenInstanceError):
        p.mass = 2.0  # type: ignore[misc]
    assert p.with_actuation("motors").actuation == "motors" and p.actuation == "wrench"
    with pytest.raises(ConfigError, match="actuation"):
        p.with_actuation("jets")


def test_load_by_path(tmp_path: Path) -> None:
    f = tmp_path / "mine.toml"
    f.write_text(X500_TEXT.replace('name = "x500"', 'name = "mine"'))
    assert load_profile(f).name == "mine"
    assert load_profile(str(f)) == load_profile(f)


def test_a_file_edited_between_two_loads_gives_its_new_profile_at_once(tmp_path: Path) -> None:
    """Parsed profiles are kept by their file's bytes: an edit of the same size, in the same clock tick, is
    seen; the same bytes give the same (frozen) object, and a bad edit is refused as from a fresh load."""
    f = tmp_path / "mine.toml"
    f.write_text(X500_TEXT.replace('mass = 2.0', 'mass = 2.1'))
    first = load_profile(f)
    f.write_text(X500_TEXT.replace('mass = 2.0', 'mass = 2.2'))
    second = load_profile(f)
    assert (first.mass, second.mass) == (2.1, 2.2)
    assert load_profile(f) is second
    f.write_text(X500_TEXT.replace('mass = 2.0', 'mass = -2.0'))
    with pytest.raises(ConfigError, match="mass"):
        load_profile(f)


def _edit(text: str, key: str, value: str | None) -> str:
    """Replace (or with None, delete) the line ``key = ...`` of a profile."""
    out = []
    for line in text.splitlines():
        if line.split("=")[0].strip() == key:
            if value is not None:
                out.append(f"{key} = {value}")
        else:
            out.append(line)
    return "\n".join(out) + "\n"


@pytest.mark.parametrize(
    "key, value, words",
    [
        ("mass", "-2.0", "(0, 1000]"),
        ("mass", "0", "(0, 1000]"),
        ("ixx", "0.0", "(0, 1000]"),
        ("izz", "-0.04", "(0, 1000]"),
        ("arm", "-0.25", "(0, 10]"),
        ("rotor_inertia", "-1e-5", "[0, 1000]"),
        ("thrust_coeff", "0.0", "(0, 100]"),
        ("thrust_coeff", "1e300", "(0, 100]"),  # (each upper bound keeps 4 b omega_max^2 finite)
        ("drag_coeff", "1e300", "(0, 100]"),
        ("omega_max", "500.0", "hover speed"),  # hover is ~757 rad/s
        ("omega_max", "-1.0", "(0, 10000]"),
        ("omega_max", "1e200", "(0, 10000], got 1e+200"),  # was OverflowError at omega_max**2
        ("mass", "1" + "0" * 400, "(0, 1000], got an integer of 401 digits"),  # was OverflowError at float()
        ("drag", "[0.1, 0.1, 0.1, 1e300, 0.0, 0.0]", "element 3 must be in [0, 100]"),
        ("actuation", '"jets"', "wrench, motors"),
        ("mass", '"heavy"', "expected a number"),
        ("mass", "true", "expected a number"),
        ("drag", "[0.1, 0.1]", "list of 6 numbers"),
        ("drag", "[0.1, 0.1, 0.1, -1.0, 0.0, 0.0]", "element 3"),
        ("motor_time_constant", "0", "(0, 10]"),
        ("gravity", "nan", "finite"),
        ("mass", None, "is required"),
        ("name", "3", "expected a string"),
    ],
)
def test_bad_values_name_file_and_key(tmp_path: Path, key: str, value: str | None, words: str) -> None:
    f = tmp_path / "bad.toml"
    f.write_text(_edit(X500_TEXT, key, value))
    with pytest.raises(ConfigError) as exc:
        load_profile(f)
    msg = str(exc.value)
    assert msg.startswith(f"{f}: {key}:"), msg
    assert words in msg, msg


def test_omega_max_message_gives_the_hover_speed(tmp_path: Path) -> None:
    f = tmp_path / "slow.toml"
    f.write_text(_edit(X500_TEXT, "omega_max", "700.0"))
    hover = math.sqrt(2.0 * 9.81 / (4 * 8.54858e-06))
    with pytest.raises(ConfigError, match=f"{hover:.4g}"):
        load_profile(f)


def test_unknown_key(tmp_path: Path) -> None:
    f = tmp_path / "bad.toml"
    f.write_text(X500_TEXT + "propellers = 4\n")
    with pytest.raises(ConfigError, match=r": propellers: unknown key"):
        load_profile(f)


@pytest.mark.parametrize(
    "limits, key, words",
    [
        ("[limits]\nu1 = 100.0\n", "limits.u1", "exceeds what the rotors give"),
        ("[limits]\nu1 = 10.0\n", "limits.u1", "must be in"),  # below m g = 19.6 N
        ("[limits]\nu2 = -1.0\n", "limits.u2", "must be in"),
        ("[limits]\nu5 = 1.0\n", "limits.u5", "unknown key"),
        ("limits = 3\n", "limits", "expected a table"),
    ],
)
def test_bad_limits(tmp_path: Path, limits: str, key: str, words: str) -> None:
    f = tmp_path / "bad.toml"
    f.write_text(X500_TEXT + limits)
    with pytest.raises(ConfigError) as exc:
        load_profile(f)
    assert str(exc.value).startswith(f"{f}: {key}:") and words in str(exc.value), str(exc.value)


def test_missing_file_non_toml_and_unknown_name(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"nope\.toml: no such file"):
        load_profile(tmp_path / "nope.toml")
    junk = tmp_path / "junk.toml"
    junk.write_text("mass = = 2\n")
    with pytest.raises(ConfigError, match=r"junk\.toml: not valid TOML"):
        load_profile(junk)
    binary = tmp_path / "bin.toml"
    binary.write_bytes(b"\xff\xfe\x00mass")
    with pytest.raises(ConfigError, match=r"bin\.toml: not a text file"):
        load_profile(binary)
    with pytest.raises(ConfigError, match=r"unknown profile 'f450'.*paper.*x500"):
        load_profile("f450")
    with pytest.raises(ConfigError, match="is a directory"):
        load_profile(str(tmp_path) + "/")
