"""What a caller lays over a mission: one frozen :class:`Overrides`, checked for its types, laid over a mission.

In:  ``bsst``'s flags or Python's keywords (:meth:`Overrides.of`): profile, controller, discretization, ``rate_hz``
     Hz, seed, ``scatter_m`` m, actuation, tables laid over ``[link]``, ``[failsafe]``, ``[sensors]``, an estimator
     kind, a noise scale, ``[params]`` entries by PX4 name, parameter changes at mission times s, ``[wind]``
     (m/s, compass degrees), events (tables or ``T:KIND[:ARGS]``)
Out: an :class:`Overrides` (a type that is wrong raises ``ConfigError`` naming the field, or the flag for
     ``--param`` and ``--at``); :meth:`Overrides.laid_over` the mission with them laid over it, validated again by
     the mission; :func:`merged_failsafe_params`, :func:`merged_tables`, how two tables are laid one over the other;
     :func:`laid_file_problem`, :func:`laid_trace_misfit`, a refused trace or profile the ``link`` override laid,
     named as the flag that laid it (``link_flags``: the flags as typed); :func:`replaced_laid_problem`, a steady
     wind or link laid over a mission whose event at 0 s replaces it, as the line refusing the flag

Every other value is checked by the part that owns it when :func:`bridge.core.flight.prepare` builds the flight.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields
from numbers import Integral, Real
from pathlib import Path
from typing import Any

from bridge.autopilot.params import BY_NAME, ParamChange, VehicleParams, apply_params, params_as_failsafe, typed_value
from bridge.link.model import DIRECTIONS, absolute_link_paths, merge_link_tables
from bridge.link.profile import load_link_profile
from bridge.link.trace import read_trace
from missions import Mission
from missions.mission import law_spec_from
from params import ConfigError
from params.text import shown_name
from plant.events import AT_KEY, TimedEvent, at_first_step, event_given, event_table_from_flag, table_where
from plant.wind import SCALING, TURBULENCE


def _not_alone(name: str, value: object, one: tuple[type, ...], what: str) -> None:
    """Refuse one entry given where a tuple of them goes: it would be read item by item (``'2'`` of ``'2:gps:off'``,
    a table's keys, a ParamChange's fields), and refused naming a part the caller never wrote."""
    if isinstance(value, one):
        raise ConfigError(f"{name}: expected a tuple of {what}, got {value!r} alone (a tuple of one: {name}=(...,))"
                          [:300])


def check_switches(**switches: object) -> None:
    """Refuse a Python caller's switch (``realtime``, ``overwrite``, ``plots``, ...) that is not True or False: a
    string is truthy, so ``realtime="no"`` flew in real time (a user's tour)."""
    for name, value in switches.items():
        if not isinstance(value, bool):
            raise ConfigError(f"{name}: expected True or False, got {value!r}"[:300])


@dataclass(frozen=True)
class Overrides:
    """What a caller lays over a mission: ``bsst``'s flags, or Python's keywords. None (and an empty
    table) keeps the mission's own. Each field is checked for its type here, ``params`` for its
    parameters' types, ranges and clashes (ConfigError naming ``--param``); every other value by the
    part that owns it when :func:`prepare` builds the flight (the mission's ranges, the link model's)."""

    profile: str | None = None  # vehicle profile: paper, x500, or a profile TOML path
    controller: str | None = None  # law: bsst, smc, pid, file.py:Class or module:Class (from the working dir)
    discretization: str | None = None  # how bsst steps its super-twisting step: explicit or implicit (docs/law.md)
    rate_hz: float | None = None  # control rate, Hz
    seed: int | None = None  # seed of the random effects (and of the link's fates, unless [link] seed)
    scatter_m: float | None = None  # [start] scatter_m, m: each seed starts in a disc this wide (missions.scatter)
    actuation: str | None = None  # the profile's actuation: wrench or motors
    link: Mapping[str, Any] | None = None  # over [link] (merge_link_tables): delay_ms ms, loss_pct %, blackouts s, ...
    link_flags: Mapping[str, str] | None = None  # bsst's: the flag that laid each entry of link, by its place there
    #   ("up.trace": "--link-trace"), kept as typed so that a refusal names it; None: each named by its own flag
    failsafe: Mapping[str, Any] | None = None  # over [failsafe], key by key: timeout_s s, descent_rate m/s, action
    sensors: Mapping[str, Any] | None = None  # over [sensors], key by key: {"set": "mocap"}
    estimator: str | None = None  # [estimator] kind: truth, raw or ekf
    noise: float | None = None  # [sensors] noise_scale: every sigma of the set times it (no unit)
    params: Mapping[str, float] | None = None  # over [params], PX4 names: COM_OF_LOSS_T s, COM_OBL_ACT (an integer)
    param_at: tuple[ParamChange, ...] = ()  # parameter changes at mission times (s), at the start of their step
    wind: Mapping[str, Any] | float | tuple[float, float] | None = None  # over [wind]: a table, SPEED m/s, or
    #   (SPEED m/s, FROM_DEG compass direction it blows from)
    turbulence: str | None = None  # [wind] turbulence: none, light, moderate or severe
    turbulence_scaling: str | None = None  # [wind] turbulence_scaling: exact (the flight's record at σ) or none
    at: tuple[Mapping[str, Any] | str, ...] = ()  # events after the mission's [[events]]: tables or "T:KIND[:ARGS]"
    #   (kept as tables, a flag's with its text under plant.events.AT_KEY, a table with its place there: "at[0]")

    def __post_init__(self) -> None:
        _check_type("turbulence", self.turbulence, str, "a string")
        _check_type("scatter_m", self.scatter_m, (int, float), "a number (m)")
        _check_type("turbulence_scaling", self.turbulence_scaling, str, "a string")
        for name, value, allowed in (("turbulence", self.turbulence, TURBULENCE),
                                     ("turbulence_scaling", self.turbulence_scaling, SCALING)):
            if value is not None and value not in allowed:  # (named as given, not as the mission's [wind] key)
                raise ConfigError(f"overrides: {name}: must be one of {', '.join(allowed)}; got {value!r}"[:200])
        w = self.wind
        if isinstance(w, (int, float)) and not isinstance(w, bool):
            object.__setattr__(self, "wind", {"speed_mps": float(w)})
        elif isinstance(w, tuple) and len(w) == 2 and all(isinstance(v, (int, float)) for v in w):
            object.__setattr__(self, "wind", {"speed_mps": float(w[0]), "from_deg": float(w[1])})
        else:
            _check_type("wind", w, Mapping, "a table, a speed (m/s) or (speed m/s, from deg)")
            if w is not None:
                object.__setattr__(self, "wind", dict(w))
        _not_alone("at", self.at, (str, Mapping), "event tables or 'T:KIND[:ARGS]' strings")
        events, named = [], []
        for i, e in enumerate(tuple(self.at)):
            if isinstance(e, str):
                named.append(f"--at {e}")
                try:  # the flag kept in its table (AT_KEY): a run's mission.toml flown again names it
                    e = {**event_table_from_flag(e), AT_KEY: e}
                except ValueError as exc:
                    raise ConfigError(f"--at {e}: {exc}"[:300]) from None
            elif isinstance(e, Mapping):
                named.append(f"at[{i}]")
                e = {**e, AT_KEY: e.get(AT_KEY, f"at[{i}]")}  # its place kept too: named so in a run's children
            else:
                raise ConfigError(f"at: expected event tables or 'T:KIND[:ARGS]' strings, got {e!r}"[:200])
            events.append(e)
        object.__setattr__(self, "at", tuple(events))
        object.__setattr__(self, "_at_named", tuple(named))  # (not a field) each event as its caller gave it
        for f in ("profile", "controller", "discretization", "actuation", "estimator"):
            _check_type(f, getattr(self, f), str, "a string")
        for f in ("rate_hz", "noise"):
            _check_type(f, getattr(self, f), Real, "a number")
        _check_type("seed", self.seed, Integral, "an integer")
        for f in ("link", "link_flags", "failsafe", "sensors", "params"):
            v = getattr(self, f)
            _check_type(f, v, Mapping, f"a table (a mapping: {{'set': {v!r}}}, as --sensors {v})"
                        if f == "sensors" and isinstance(v, str) else "a table (a mapping)")
            if v is not None:  # a copy: a caller's later change to its dict changes nothing here
                object.__setattr__(self, f, dict(v))
        if self.params:  # each as its parameter's type (an INT32 an int), checked, named as the flag
            apply_params(VehicleParams(), self.params.items(), "",
                         lambda name, value: f"--param {shown_name(name)}={value}")
            object.__setattr__(self, "params", {n: typed_value(BY_NAME[n], v) for n, v in self.params.items()})
        _not_alone("param_at", self.param_at, (str, ParamChange), "ParamChange(t_s, name, value) entries")
        changes = tuple(self.param_at)
        for c in changes:
            if not isinstance(c, ParamChange):
                raise ConfigError(f"param_at: expected ParamChange(t_s, name, value) entries, got {c!r}"[:200])
        object.__setattr__(self, "param_at", changes)

    @classmethod
    def of(cls, given: Overrides | Mapping[str, Any] | None = None, /, **keywords: Any) -> Overrides:
        """``given`` (an :class:`Overrides`, a mapping of its fields, or None) with ``keywords`` (its
        fields by name) laid over it: how :func:`prepare`, :func:`bridge.loop.simulate` and
        :func:`bridge.session.sitl` take ``overrides=`` and keywords alike. A name that is no field is
        a TypeError, as an unknown keyword argument is."""
        base = given.given() if isinstance(given, Overrides) else dict(given or {})
        unknown = sorted(set(base) - OVERRIDE_FIELDS) + sorted(set(keywords) - OVERRIDE_FIELDS)
        if unknown:
            raise TypeError(f"unknown override {', '.join(map(repr, unknown))}; the overrides are "
                            f"{', '.join(f.name for f in fields(cls))}")
        if isinstance(given, Overrides) and not keywords:
            return given
        return cls(**{**base, **keywords})

    def given(self) -> dict[str, Any]:
        """The fields that lay something over the mission (not None, not empty), by name."""
        return {f.name: v for f in fields(self)
                if (v := getattr(self, f.name)) is not None and not (isinstance(v, (dict, tuple)) and not v)}

    def laid_over(self, m: Mission) -> Mission:
        """The mission with these overrides laid over it (validated again by the mission)."""
        # trace and profile files: a mission's from its folder, an override's from the working directory
        own_link = absolute_link_paths(m.link, Path(m.source).parent)
        link = merge_link_tables(own_link, absolute_link_paths(self.link, Path("."))) if self.link else own_link
        failsafe, params = merged_failsafe_params(m, self.failsafe, self.params)
        sensors = merged_tables(m.sensors, self.sensors, {} if self.noise is None else {"noise_scale": self.noise})
        estimator = merged_tables(m.estimator, {} if self.estimator is None else {"kind": self.estimator})
        # a law file given on the command line or from Python: from the working directory
        law = law_spec_from(self.controller, Path(".")) if self.controller is not None else None
        wind = merged_tables(m.wind, self.wind, {} if self.turbulence is None else {"turbulence": self.turbulence},
                             {} if self.turbulence_scaling is None else {"turbulence_scaling": self.turbulence_scaling})
        for e, named in zip(self.at, self._at_named, strict=True):  # each checked alone first: errors name its flag
            event_given(e, named, "", m.duration_s)
        events = (*m.events, *self.at) if self.at else None
        try:
            return m.with_overrides(profile=self.profile, controller=law, discretization=self.discretization,
                                    rate_hz=self.rate_hz, seed=self.seed, start_scatter_m=self.scatter_m,
                                    actuation=self.actuation, link=link, failsafe=failsafe, sensors=sensors,
                                    estimator=estimator, params=params, wind=wind, events=events)
        except ConfigError as exc:  # the file alone was valid: what was laid over it made this, so say what that was
            laid = {k: v for k, v in self.given().items() if k != "link_flags"}  # (how it was named: not laid)
            raise ConfigError(f"{exc} (with these laid over the mission: {table_settings(laid)})") from None


def table_settings(table: Mapping[str, Any], prefix: str = "") -> str:
    """Settings as ``KEY = VALUE`` text for a message, nested tables flattened under their key
    (``link.up.burst_len = 0.5``; ``prefix``: the table's own key), each cut at 120 characters."""
    def one(k: str, v: Any) -> str:
        key = f"{prefix}.{k}" if prefix else k
        return table_settings(v, key) if isinstance(v, Mapping) else f"{key} = {v!r}"[:120]

    return ", ".join(one(k, v) for k, v in table.items())


OVERRIDE_FIELDS = frozenset(f.name for f in fields(Overrides))
OWN_FLAGS = {"trace": "link-trace", "profile": "link-profile"}  # a link override's entry -> its flag's stem


def laid_flag(place: str, flags: Mapping[str, str] | None) -> str:
    """The flag that laid ``place`` (``up.trace``, ``trace``, ``profile``) of a ``link`` override: the one typed
    (``bsst``'s :attr:`Overrides.link_flags`), else the place's own (a Python caller's ``link={"up": {"trace": F}}``
    is ``--up-link-trace``'s, ``{"trace": F}`` ``--link-trace``'s)."""
    if flags and place in flags:
        return flags[place]
    d, _, key = place.rpartition(".")
    return f"--{d}-{OWN_FLAGS[key]}" if d else f"--{OWN_FLAGS[key]}"


def laid_file_problem(link: Mapping[str, Any], flags: Mapping[str, str] | None = None) -> str | None:
    """The line refusing a trace or profile file that ``link`` (the flags', or a caller's ``link=``) lays over a
    mission's ``[link]`` and that is bad on its own, named as the flag(s) that gave it (:func:`laid_flag`:
    ``--link-trace``, ``--up-link-trace / --down-link-trace`` for one file given to both, ``--link-profile``), not as
    the mission's key; None. Read again only once the table was refused (a trace may be millions of records)."""
    link = absolute_link_paths(link, Path("."))
    places = {"profile": link.get("profile"), "trace": link.get("trace")}
    places |= {f"{d}.trace": t.get("trace") for d in DIRECTIONS if isinstance(t := link.get(d), Mapping)}
    files: dict[tuple[str, bool], list[str]] = {}  # each file once (a profile's apart), with the flags that gave it
    for place, path in places.items():
        if isinstance(path, str) and path:
            files.setdefault((path, place == "profile"), []).append(laid_flag(place, flags))
    for (path, profile), named in files.items():
        try:
            load_link_profile(path) if profile else read_trace(path)
        except ConfigError as exc:  # (a file's refusal opens with its path, its source; a profile's unknown name not)
            flag = " / ".join(dict.fromkeys(named))
            return f"{flag} {exc}" if exc.source is not None else f"{flag}: {exc}"
    return None


def laid_trace_misfit(exc: ConfigError, source: str, link: Mapping[str, Any], over: Overrides) -> str | None:
    """``exc`` (``source``'s refusal of ``link.D.trace``, ``link`` the ``[link]`` flown: no rows of D, one, or shorter
    than the mission) named as the flag that laid that trace over the mission (:func:`laid_flag`), not as the
    mission's key it does not hold; None if ``over`` did not lay it (``--link-trace t.csv`` read ``sine.toml:
    link.up.trace: ...``)."""
    laid = over.link or {}
    d = next((d for d in DIRECTIONS if exc.source == source and exc.key == f"link.{d}.trace"), None)
    if d is None or exc.what is None:
        return None
    side = laid.get(d)
    if isinstance(side, Mapping) and side.get("trace"):  # laid for D: it wins over the mission's
        place = f"{d}.trace"
    elif laid.get("trace") and not (link.get(d) or {}).get("trace") and not link.get("profile"):  # for both: D's own
        place = "trace"  # (the mission's [link.D], a profile's) would win over it
    else:
        return None
    return f"{laid_flag(place, over.link_flags)} {exc.what}"


# a link override's per-direction key -> its flag's stem (bridge.cli.linkflags: LINK_FLAGS and the trace, seed and
# jitter-distribution flags; tests/test_replaced_flags.py keeps them equal)
LINK_KEY_STEMS = {"delay_ms": "delay", "jitter_ms": "jitter", "loss_pct": "loss", "burst_len": "burst",
                  "dup_pct": "dup", "reorder_pct": "reorder", "rate_bps": "bandwidth", "queue_ms": "queue",
                  "blackouts": "blackout", "trace": "link-trace", "trace_loop": "link-trace-loop",
                  "jitter": "jitter-dist", "seed": "link-seed"}


def _replaced_link_flags(link: Mapping[str, Any], flags: Mapping[str, str] | None) -> list[str]:
    """The flags that laid ``link``'s settings of the two directions (a handover replaces those whole), as typed where
    :attr:`Overrides.link_flags` has them (``--delay 40 --up-delay 10`` as typed, not as the table holds them:
    ``--up-delay 10, --down-delay 40`` until the forty-fifth session's review), else by the key's own flag (both
    directions alike: ``--delay``; one: ``--up-delay``; ``--jitter-dist`` and ``--link-seed`` have no direction); a
    ``--link-profile`` only if it gives no guard key (those stay the flight's). The controller's guard keys are not
    the link's: not named."""
    def shown(flag: str, v: Any) -> str:  # the flag with its value (a trace's file, a window's START:DURATION)
        if isinstance(v, bool) or not isinstance(v, (int, float, str, list, tuple)):
            return flag
        if isinstance(v, (list, tuple)):
            return " ".join(f"{flag} {w[0]:g}:{w[1]:g}" if isinstance(w, (list, tuple)) and len(w) == 2 else flag
                            for w in v) or flag
        return f"{flag} {v:g}" if not isinstance(v, str) else f"{flag} {v}" if v else f"{flag} none"

    out: list[str] = []
    for key, stem in LINK_KEY_STEMS.items():
        sides = {d: t[key] for d in DIRECTIONS if isinstance(t := link.get(d), Mapping) and key in t}
        typed = {d: flags[f"{d}.{key}"] for d in sides if flags and f"{d}.{key}" in flags}
        if sides and len(typed) == len(sides):  # bsst's: each flag as typed, once (--delay 40 --up-delay 10)
            laid = {typed[d]: v for d, v in sides.items()}  # (a flag of both ways: one value, named once)
            out += [shown(f, laid[f]) for f in sorted(laid, key=lambda f: f.startswith(("--up-", "--down-")))]
        elif key in link or (len(sides) == 2 and sides["up"] == sides["down"]) or (sides and key in ("jitter", "seed")):
            v = link[key] if key in link else next(iter(sides.values()))
            out.append(shown(laid_flag("trace", flags) if key == "trace" else f"--{stem}", v))
        else:
            out += [shown(laid_flag(f"{d}.trace", flags) if key == "trace" else f"--{d}-{stem}", v)
                    for d, v in sides.items()]
    profile = link.get("profile")
    if isinstance(profile, str) and profile:
        try:
            guards = {"compensation", "command_lag_ms", "stale_ms", "stop_ms"} & set(load_link_profile(profile).link)
        except ConfigError:
            guards = set()  # (a bad profile: refused as such where the link is read)
        if not guards:
            out.append(shown(laid_flag("profile", flags), profile))
    return list(dict.fromkeys(out))


def replaced_laid_problem(over: Overrides, source: str, timeline: Sequence[TimedEvent], rate_hz: float,
                          turbulent: bool = False) -> str | None:
    """The line refusing a steady wind (``--wind``, Python's ``wind=`` speed or direction) or a link setting of the
    two directions (``--delay``, ``--loss``, ``--blackout``, ``--link-trace``, ``--link-profile`` ..., Python's
    ``link=``) laid over a mission whose timeline (``source``'s ``[[events]]`` and the ``--at`` flags) sets that
    thing itself at the flight's first control step (an event of kind ``wind``, or a ``link`` handover, acting at
    step 0: ``t_s = 0``): the event replaces it before anything flies, so it would change nothing, silently. An
    event later than that leaves it flown until then (docs/weather.md). A steady wind is not refused where the flight
    flies turbulence (``turbulent``): its speed and direction set the turbulence's pass speed and axes, which the
    event (the steady wind alone) leaves as they are. None."""
    wind = at_first_step(timeline, rate_hz, "wind")
    if wind is not None and not turbulent and over.wind and {"speed_mps", "from_deg"} & set(over.wind):
        w = over.wind
        laid = f"{w.get('speed_mps', 0.0):g}" + (f":{w['from_deg']:g}" if "from_deg" in w else "")
        return (f"--wind {laid}: changes nothing: {table_where(source, wind)} sets the steady wind ({wind.text()}) "
                "at the flight's first control step, and no turbulence is flown (whose pass speed and axes it would "
                "set), so the flight never flies the flag's; drop --wind, or give the wind in that event (an event at "
                "a later time leaves --wind blowing until it)")
    link = at_first_step(timeline, rate_hz, "link")
    named = _replaced_link_flags(over.link, over.link_flags) if link is not None and over.link else []
    if named:
        flags = ", ".join(named)
        one = len(named) == 1
        return (f"{flags}: change{'s' if one else ''} nothing: {table_where(source, link)} hands the link over "
                f"({link.text()}) at the flight's first control step, and a handover replaces both directions' link "
                f"whole, so the flight never flies {'that flag' if one else 'those flags'}; drop "
                f"{'it' if one else 'them'}, or give the link in that event (an event at a later time leaves the "
                "flags' link flown until it)")
    return None


def _check_type(name: str, value: Any, kind: type | tuple[type, ...], what: str) -> None:
    """ConfigError unless ``value`` is None or a ``kind`` (never a bool)."""
    if value is not None and (isinstance(value, bool) or not isinstance(value, kind)):
        raise ConfigError(f"overrides: {name}: expected {what}, got {value!r}"[:200])


def merged_failsafe_params(m: Mission, failsafe: Mapping[str, Any] | None,
                           params: Mapping[str, float] | None) -> tuple[Mapping[str, Any] | None,
                                                                        Mapping[str, Any] | None]:
    """The mission's ``[failsafe]`` and ``[params]`` tables with the overrides laid over them, so that
    an override wins over whichever of the file's two tables holds the same setting (and the result
    holds each setting in one of them only): None for a table nothing was laid over."""
    if not failsafe and not params:
        return None, None
    over_fs = dict(failsafe or {})
    over_params = dict(params or {})
    by_params = params_as_failsafe(over_params)  # failsafe key -> the parameter override setting it
    for key, name in by_params.items():
        if key in over_fs:
            raise ConfigError(f"--param {name} and the failsafe override of {key} (--failsafe-action) set the same "
                              "thing: give one")
    fs = {k: v for k, v in m.failsafe.items() if k not in by_params}
    fs.update(over_fs)
    taken = set(over_fs) | set(by_params)  # the settings an override sets: the file's entries for them go
    ps = {n: v for n, v in m.params.items() if params_as_failsafe({n: v}).keys().isdisjoint(taken)}
    ps.update(over_params)
    return fs, ps


def merged_tables(own: Mapping[str, Any], *over: Mapping[str, Any] | None) -> Mapping[str, Any] | None:
    """``own`` with each of ``over`` laid over it key by key; None (keep the mission's) when nothing is laid."""
    given = [o for o in over if o]
    if not given:
        return None
    out = dict(own)
    for o in given:
        out.update(o)
    return out
