"""Vehicle profiles: the physical constants of one airframe, loaded from TOML and validated.

A profile is a frozen :class:`Profile`. Built-in profiles live in ``plant/profiles/*.toml``
(``paper``: Table 1 with ideal wrench actuation; ``x500``: PX4's x500 with real rotors).
A profile's ``[sensors]`` table holds named sensor sets (:mod:`plant.sensors`); a mission picks
one and overrides its keys with :func:`sensors_from_table`.

In:  a profile name or TOML (mass kg, inertias kg m^2, arm m, rotor inertia kg m^2, b N s^2, d N m s^2,
     omega_max rad/s, actuation, limits N, rotor drag s/m, an optional [battery])
Out: a frozen :class:`Profile`, its hover speed (rad/s) and limits u_max (N)
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from params import MAX_TOML_BYTES, ConfigError, Table, read_regular_file, toml_from_bytes
from plant.battery import BatteryConfig, battery_from_table
from plant.sensors import CLASS_KEYS, IDEAL, SensorConfig, sensor_config_from_table, sensor_sets_from_table

PROFILE_DIR = Path(__file__).with_name("profiles")
ACTUATIONS = ("wrench", "motors")
# One range per key (lo, hi, lo_open, unit), for every profile, built in or a user's file. The upper bounds are
# physical ones far past any multirotor (the paper's b = 5, d = 2 are already large), and keep the rotor
# envelope 4 b omega_max^2 finite: omega_max = 1e200 overflowed there.
PROFILE_RANGES: dict[str, tuple[float, float, bool, str]] = {
    "mass": (0.0, 1000.0, True, "kg"),
    "arm": (0.0, 10.0, True, "m"),
    "ixx": (0.0, 1000.0, True, "kg m^2"),
    "iyy": (0.0, 1000.0, True, "kg m^2"),
    "izz": (0.0, 1000.0, True, "kg m^2"),
    "rotor_inertia": (0.0, 1000.0, False, "kg m^2"),
    "thrust_coeff": (0.0, 100.0, True, "N s^2/rad^2"),
    "drag_coeff": (0.0, 100.0, True, "N m s^2/rad^2"),
    "gravity": (0.0, 100.0, True, "m/s^2"),
    "omega_max": (0.0, 10000.0, True, "rad/s"),  # 95 000 rpm: past the fastest small-propeller motors
    "drag": (0.0, 100.0, False, "N s/m, N m s/rad"),  # each of k1..k6
    "motor_time_constant": (0.0, 10.0, True, "s"),
    "rotor_drag": (0.0, 1.0, False, "s/m"),
}


@dataclass(frozen=True, slots=True)
class Profile:
    """Constants of one airframe (SI units, paper frame).

    ``u_max`` are the wrench limits (u1 in N, u2..u4 in N: the paper's torques are l*u).
    """

    name: str
    actuation: str
    mass: float
    arm: float
    ixx: float
    iyy: float
    izz: float
    rotor_inertia: float
    thrust_coeff: float
    drag_coeff: float
    gravity: float
    omega_max: float
    drag: tuple[float, float, float, float, float, float]
    motor_time_constant: float
    u_max: tuple[float, float, float, float]
    sensors: tuple[tuple[str, SensorConfig], ...] = (("ideal", IDEAL),)  # (name, set), as in the file
    rotor_drag: float = 0.0  # s/m: the rotors' induced drag per N of thrust and m/s of in-plane airspeed (in wind)
    battery: BatteryConfig | None = None  # the flight battery ([battery]; flown with [effects] battery = true)

    def sensor_set(self, name: str) -> SensorConfig:
        """The named sensor set; ConfigError naming the sets there are if there is none."""
        for n, cfg in self.sensors:
            if n == name:
                return cfg
        raise ConfigError(f"profile {self.name!r} has no sensor set {name!r}; it has: "
                          f"{', '.join(n for n, _ in self.sensors)}")

    @property
    def hover_omega(self) -> float:
        """Rotor speed at hover, rad/s (eq. 4 with u1 = m g)."""
        return math.sqrt(self.mass * self.gravity / (4.0 * self.thrust_coeff))

    def with_actuation(self, actuation: str) -> Profile:
        if actuation not in ACTUATIONS:
            raise ConfigError(f"actuation must be one of {', '.join(ACTUATIONS)}; got {actuation!r}")
        return replace(self, actuation=actuation)


def profile_names() -> list[str]:
    """Names of the built-in profiles."""
    return sorted(f.stem for f in PROFILE_DIR.glob("*.toml"))


def load_profile(name_or_path: str | Path) -> Profile:
    """Load a built-in profile by name (``paper``, ``x500``) or a profile TOML by path."""
    text = str(name_or_path)
    if text.endswith(".toml") or "/" in text:
        path = Path(text)
    else:
        path = PROFILE_DIR / f"{text}.toml"
        if not path.exists():
            raise ConfigError(f"unknown profile {text!r}; built-in profiles: {', '.join(profile_names())}")
    return _parsed(path)


_PARSED: dict[tuple[str, bytes], Profile] = {}  # (path, its bytes) -> its profile
_PARSED_MAX = 32


def _parsed(path: Path) -> Profile:
    """The profile in ``path``, parsed once for each content of the file: a sweep, a margin search or a test
    suite prepares hundreds of flights of one profile, and each parse (TOML and validation) costs ~1.5 ms
    where reading the file costs ~20 us. A :class:`Profile` is frozen, so one serves every flight."""
    raw = read_regular_file(path, "a TOML file", MAX_TOML_BYTES)
    key = (str(path), raw)
    prof = _PARSED.get(key)
    if prof is None:
        prof = profile_from_table(toml_from_bytes(raw, path), str(path))
        if len(_PARSED) >= _PARSED_MAX:
            _PARSED.clear()
        _PARSED[key] = prof
    return prof


def profile_from_table(data: dict, source: str) -> Profile:
    """Validate a profile table; errors name ``source`` and the key."""
    t = Table(data, source)
    name = t.string("name")
    actuation = t.string("actuation", choices=ACTUATIONS)

    def num(key: str, default: Any = ...) -> float:
        lo, hi, lo_open, _unit = PROFILE_RANGES[key]
        return t.number(key, default, lo=lo, hi=hi, lo_open=lo_open)

    mass, arm, ixx, iyy, izz = (num(k) for k in ("mass", "arm", "ixx", "iyy", "izz"))
    jr, b, d = num("rotor_inertia"), num("thrust_coeff"), num("drag_coeff")
    g = num("gravity", 9.81)
    omega_max = num("omega_max")
    drag = t.vector("drag", 6, (0.0,) * 6, lo=PROFILE_RANGES["drag"][0], hi=PROFILE_RANGES["drag"][1])
    tau = num("motor_time_constant", 0.02)
    rotor_drag = num("rotor_drag", 0.0)
    battery = battery_from_table(t.table("battery")) if t.has("battery") else None
    hover = math.sqrt(mass * g / (4.0 * b))
    if omega_max <= hover:
        raise t.error("omega_max", f"must be above the hover speed {hover:.4g} rad/s, got {omega_max:g}")
    envelope = (4 * b * omega_max**2, b * omega_max**2, b * omega_max**2, 2 * d * omega_max**2)
    lim = t.table("limits")
    u_max = (
        lim.number("u1", envelope[0], lo=mass * g, lo_open=True),
        lim.number("u2", envelope[1], lo=0.0, lo_open=True),
        lim.number("u3", envelope[2], lo=0.0, lo_open=True),
        lim.number("u4", envelope[3], lo=0.0, lo_open=True),
    )
    lim.done()
    sensors = sensor_sets_from_table(t.raw("sensors", {}), source) if t.has("sensors") else (("ideal", IDEAL),)
    t.done()
    if actuation == "motors" and u_max[0] > envelope[0] * (1 + 1e-9):
        raise lim.error("u1", f"exceeds what the rotors give (4 b w_max^2 = {envelope[0]:.4g} N)")
    return Profile(name, actuation, mass, arm, ixx, iyy, izz, jr, b, d, g, omega_max, drag, tau, u_max, sensors,
                   rotor_drag, battery)


NOISE_SCALE_RANGE = (0.0, 100.0)  # the mission's [sensors] noise_scale: multiplies every sigma of the set


def sensors_from_table(profile: Profile, table: Mapping[str, Any], source: str) -> SensorConfig:
    """A mission's ``[sensors]`` table over its profile's sets: ``set`` picks one (default
    ``ideal``), any key of a set overrides it, ``noise_scale`` multiplies every σ.

    A ``position_class`` override drops the keys of the set's own class, so the other class's keys
    must then be given. Errors name ``source``, the ``sensors.`` key and its range.
    """
    t = Table(table, source, "sensors")
    names = [n for n, _ in profile.sensors]
    name = t.string("set", "ideal", choices=names)
    scale = t.number("noise_scale", 1.0, lo=NOISE_SCALE_RANGE[0], hi=NOISE_SCALE_RANGE[1])
    base = profile.sensor_set(name).as_table()
    overrides = {k: v for k, v in table.items() if k not in ("set", "noise_scale")}
    cls = overrides.get("position_class", base["position_class"])
    if cls != base["position_class"]:
        for k in CLASS_KEYS.get(str(base["position_class"]), ()):
            base.pop(k, None)
    merged = {**base, **overrides}
    cfg = sensor_config_from_table(Table(merged, source, "sensors"), name)
    return cfg.scaled(scale) if scale != 1.0 else cfg
