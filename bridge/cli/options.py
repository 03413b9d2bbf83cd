"""The options the flying commands share (the flight's overrides, the failsafe, parameters, sensors,
ports, signing key) and the one way from their flags to an :class:`~bridge.core.overrides.Overrides`.

In:  an ``argparse`` parser to add options to; the parsed ``argparse.Namespace`` (``--rate`` Hz,
     ``--seed``, ``--param NAME=VALUE`` in the parameter's unit, ``--param-at T:NAME=VALUE`` T in s,
     ``--noise`` a scale, the link flags of :mod:`bridge.cli.flags`)
Out: the options on the parser; :func:`overrides_from_args`, the frozen
     :class:`~bridge.core.overrides.Overrides` those flags ask for (a flag a command does not have: the
     mission's own), which :func:`bridge.core.flight.prepare` lays over the mission; :func:`checked_mission`, the
     mission a flying command flies, read once, a flag that would change nothing in it (or that its own keys make
     wrong) refused as a ``ConfigError`` naming it;
     :func:`refuse_vehicle_flags`, ``bsst vehicle``'s flags that need another
"""

from __future__ import annotations

import argparse
from collections.abc import Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from bridge.cli.flags import (
    FlagRefusal,
    axis_values,
    int_in,
    law_spec,
    mission_integer,
    mission_number,
    name_list,
    noise_scale,
    pace_speed,
    param_assignment,
    path_given,
    sensor_set_name,
)
from bridge.cli.linkflags import (
    guard_flag_refusal,
    idle_flags_given,
    idle_link_flag,
    link_flags_from_args,
    link_table_from_args,
)
from params import ConfigError, load_toml
from params.text import number

if TYPE_CHECKING:  # annotations only: building the parser loads no flight code
    from bridge.core.overrides import Overrides
    from missions import Mission
    from missions.steps import StepCap


def add_failsafe_options(p: argparse.ArgumentParser) -> None:
    """``--failsafe-action A``: over the mission's ``[failsafe] action``; :func:`failsafe_table_from_args`
    reads it back."""
    # the choices are bridge.autopilot.failsafe.FAILSAFE_ACTIONS (tests/test_failsafe_actions.py keeps them equal),
    # written out so that building the parser loads no flight code
    p.add_argument("--failsafe-action", choices=("descend", "land", "hold", "disarm", "return"),
                   help="what the vehicle does when its targets stop: descend (default: level, sink, disarm on the "
                        "ground), land (here), hold (here for [failsafe] hold_s, 5 s, then land), disarm "
                        "(motors off at once) or return (Return mode: home at RTL_RETURN_ALT, then land)")


def add_param_options(p: argparse.ArgumentParser, start: bool = True, schedule: bool = True,
                      schedule_help: str = "set a vehicle parameter at mission time T s (e.g. 10:COM_OBL_ACT=1), the "
                                           "same step in every clock; repeatable") -> None:
    """``--param NAME=VALUE`` (``start``: the vehicle's parameters at start, over the mission's ``[params]``)
    and ``--param-at T:NAME=VALUE`` (``schedule``: a change at mission time T s, what it does ``schedule_help``),
    each repeatable; :func:`param_overrides_from_args` reads them back."""
    if start:
        p.add_argument("--param", type=param_assignment("--param"), action="append", metavar="NAME=VALUE",
                       help="a vehicle parameter at start, PX4's name (e.g. COM_OF_LOSS_T=1.0); repeatable")
    if schedule:
        p.add_argument("--param-at", type=param_assignment("--param-at", timed=True), action="append",
                       metavar="T:NAME=VALUE", help=schedule_help)


def param_overrides_from_args(args: argparse.Namespace) -> dict[str, Any]:
    """The :class:`~bridge.core.overrides.Overrides` fields the flags of :func:`add_param_options` ask for
    (``params``, ``param_at``; {} if none)."""
    out: dict[str, Any] = {}
    given = getattr(args, "param", None)
    if given:
        out["params"] = dict(given)
    changes = getattr(args, "param_at", None)
    if changes:
        out["param_at"] = tuple(changes)
    return out


def failsafe_table_from_args(args: argparse.Namespace) -> dict[str, Any]:
    """The ``[failsafe]`` overrides the flags of :func:`add_failsafe_options` ask for ({} if none)."""
    action = getattr(args, "failsafe_action", None)
    return {"action": action} if action is not None else {}


def add_sensor_options(p: argparse.ArgumentParser) -> None:
    """``--sensors NAME``, ``--estimator KIND``, ``--noise X``: over the mission's ``[sensors] set``,
    ``[estimator] kind`` and ``[sensors] noise_scale``; :func:`sensor_overrides_from_args` reads them back."""
    p.add_argument("--sensors", type=sensor_set_name("--sensors"), metavar="NAME",
                   help="the vehicle's sensor set from its profile's [sensors]: ideal, mocap or gnss")
    # the choices are bridge.autopilot.estimator.ESTIMATOR_KINDS (tests/test_estimation_flight.py keeps them equal),
    # written out so that building the parser loads no flight code
    p.add_argument("--estimator", choices=("truth", "raw", "ekf"),
                   help="what the vehicle sends the controller: truth (default: the true state), raw (the "
                        "measurements as they come) or ekf (its Kalman filter's estimate)")
    p.add_argument("--noise", type=noise_scale("--noise"), metavar="X",
                   help="multiply every noise sigma of the sensor set by X")


def add_sensor_axes(p: argparse.ArgumentParser) -> None:
    """``bsst sweep``'s ``--sensors NAME`` (fixed for every cell) and its two vehicle axes, ``--estimator
    truth,ekf,raw`` and ``--noise 0,0.5,1,2`` (lists; one value flies every cell with it, as ``bsst sim``'s flag)."""
    p.add_argument("--sensors", type=sensor_set_name("--sensors"), metavar="NAME",
                   help="the vehicle's sensor set from its profile's [sensors], for every cell: ideal, mocap or gnss")
    # the kinds are bridge.autopilot.estimator.ESTIMATOR_KINDS, written out as in add_sensor_options
    p.add_argument("--estimator", type=name_list("--estimator", ("truth", "ekf", "raw")), metavar="KIND,...",
                   help="estimator kinds to compare: truth (the true state), ekf (the vehicle's Kalman filter), "
                        "raw (the measurements as they come)")
    p.add_argument("--noise", type=axis_values("--noise", "noise"), metavar="X,...",
                   help="noise scales: every sigma of the sensor set times X (0-100)")


def sensor_overrides_from_args(args: argparse.Namespace) -> dict[str, Any]:
    """The :class:`~bridge.core.overrides.Overrides` fields ``sensors``, ``estimator`` and ``noise`` from
    :func:`add_sensor_options`' flags."""
    name = getattr(args, "sensors", None)
    return {"sensors": {"set": name} if name is not None else None,
            "estimator": getattr(args, "estimator", None), "noise": getattr(args, "noise", None)}


def checked_mission(args: argparse.Namespace, mission: Mission | str | Path | None, cap: StepCap | None = None,
                    laws: Sequence[str] | None = None, axes: Mapping[str, Sequence[float]] | None = None
                    ) -> Mission | None:
    """The mission a flying command flies, read once (``mission``: a path, loaded with ``cap``; a
    :class:`missions.Mission` it loaded already; None: a bare ``bsst vehicle``, ``--await-mission``, flown at rest
    here), with the flags that would change nothing in it refused, each by the rule a sweep refuses its axis with:
    ``--noise X`` where every vehicle flies the true state (``truth``: it has no sensors, so none are streamed
    either, HIGHRES_IMU and GPS_RAW_INT included) or a sensor set with no noise
    (:func:`bridge.core.flight.noise_problem`); ``--sensors NAME`` where every vehicle flies the true state
    (:func:`bridge.core.flight.unread_problem`); a link flag that acts only with another (``--burst`` without loss,
    ``--queue`` without a bandwidth cap, ``--link-trace-loop`` without a trace) where nothing gives that
    (:func:`bridge.cli.linkflags.idle_link_flag`). Before the file is validated, the flags its own keys make wrong,
    named as the flags: a guard flag that clashes with its other guard keys (``--command-lag`` without prediction:
    :func:`bridge.cli.linkflags.guard_flag_refusal`), ``--rate`` and ``--scatter`` where it cannot take them.
    ``laws``: the laws ``bsst margin`` searches (its ``--controller``; none given: the mission's), flown in place of
    the mission's, each with ``--discretization``; ``axes``: the link values it searches, laid over both
    directions. A key of the mission's ``[link]`` that would change nothing and a ``--discretization`` for a law
    without a super-twisting step are :func:`bridge.core.flight.prepare`'s to refuse, the command's and the Python
    API's alike (:func:`bridge.core.flight.idle_link_key`, :func:`bridge.core.flight.discretization_refusal`)."""
    from bridge.core.flight import at_rest, discretization_refusal  # lazy: start-up time
    from missions import Mission, load_mission  # lazy: start-up time

    table, source = _own(mission)
    own = table.get("link", {}) if table is not None else {}
    clash = (guard_flag_refusal(args, own, source) or _rate_flag_refusal(args, table or {}, source)
             or _scatter_flag_refusal(args, table or {}, source))  # (before the loader or prepare names the key)
    if clash:
        raise ConfigError(clash)
    flown = mission if isinstance(mission, Mission) or mission is None else load_mission(mission, cap, table)
    m = flown if flown is not None else at_rest()
    if laws is not None:  # bsst margin: its --controller is the list of laws it searches, not one to lay over
        idle = discretization_refusal(getattr(args, "discretization", None), laws or (m.controller,))
        if idle:
            raise ConfigError(idle)
        args = argparse.Namespace(**{**vars(args), "controller": None, "discretization": None})
    if getattr(args, "noise", None) is not None or getattr(args, "sensors", None) is not None or idle_flags_given(args):
        _refuse_idle_flags(args, m, axes)
    return flown


def _refuse_idle_flags(args: argparse.Namespace, m: Mission, axes: Mapping[str, Sequence[float]] | None) -> None:
    """Refuse (ConfigError) ``--noise X``, ``--sensors NAME`` or a link flag that would change nothing in the flights
    of ``m`` with ``args`` laid over it (:func:`checked_mission`). Apart, so that a command given none (every
    session's children) imports none of the fleet's code."""
    from bridge.core.flight import noise_problem, prepare, unread_problem  # lazy: start-up time
    from bridge.swarm import fleet_flights, fleet_mission  # lazy: start-up time

    noise = getattr(args, "noise", None)
    over = replace(overrides_from_args(args), noise=1.0)  # the set's own sigmas: a scale of 0 changes a noisy set
    fleet = fleet_mission(m, getattr(args, "vehicles", None), getattr(args, "formation", None))
    flights = (fleet_flights(fleet, over, laid_named=True) if fleet is not None  # (bad input)
               else [prepare(m, over, axes=axes or (), laid_named=True)])
    whys = [noise_problem((f.estimator,), f.sensors) for f in flights]
    if noise is not None and all(whys):
        raise ConfigError(f"--noise {noise:g}: {whys[0]}")
    unread = unread_problem([f.estimator for f in flights], "the sensor set")  # (a file's own [sensors]: its own)
    if getattr(args, "sensors", None) is not None and unread:
        raise ConfigError(f"--sensors {args.sensors}: {unread}")
    idle = idle_link_flag(args, [f.link for f in flights], axes)
    if idle:
        raise ConfigError(idle)


def _rate_flag_refusal(args: argparse.Namespace, own: Mapping[str, Any], source: str) -> str | None:
    """The line refusing ``--rate HZ`` that the mission's physics rate (``own``: its top-level table, from
    ``source``) is no whole multiple of (:func:`missions.mission.rate_problem`, the loader's rule), named as the
    flag; None, and None for a physics rate or a file's own rate_hz (given or the default) the loader will refuse
    (and name: the file must fit on its own, whatever --rate lays over it)."""
    from missions import Mission  # lazy: start-up time
    from missions.mission import rate_problem  # lazy: start-up time

    rate = getattr(args, "rate", None)
    if rate is None:
        return None
    physics = own.get("physics_hz", Mission.physics_hz)  # (the loader's default, a plan's and a bare vehicle's)
    if isinstance(physics, bool) or not isinstance(physics, (int, float)) or not physics > 0:
        return None
    own_rate = own.get("rate_hz", Mission.rate_hz)  # the file's own (or the default) first: no use naming a flag
    if not isinstance(own_rate, (int, float)) or not own_rate > 0 or rate_problem(own_rate, physics):  # it won't fix
        return None
    set_by = f" ({source}'s physics_hz)" if source and physics != Mission.physics_hz else ""  # (not the default)
    why = rate_problem(rate, physics, set_by)
    return None if why is None else f"--rate {rate:g}: {why}"


def _scatter_flag_refusal(args: argparse.Namespace, own: Mapping[str, Any], source: str) -> str | None:
    """The line refusing ``--scatter M`` for a fleet (``--vehicles N``, or the mission's own ``[[vehicles]]``, in
    ``own`` from ``source``: :func:`missions.scatter.fleet_scatter_problem`, the mission's rule), named as the flag;
    None."""
    from missions.scatter import fleet_scatter_problem  # lazy: start-up time

    scatter, n = getattr(args, "scatter", None), getattr(args, "vehicles", None)
    if scatter is None:
        return None
    fleet = f"--vehicles {n}" if isinstance(n, int) else f"{source}'s [[vehicles]]" if own.get("vehicles") else ""
    why = fleet_scatter_problem(scatter, fleet)
    return None if why is None else f"--scatter {scatter:g}: {why}"


def _own(mission: Mission | str | Path | None) -> tuple[dict[str, Any] | None, str]:
    """A mission's own top-level table as its file holds it (``link``, ``physics_hz``, ``rate_hz`` and ``vehicles`` of a
    :class:`missions.Mission`) and its source, read once, without validating it: ({}, "") for none (a bare
    vehicle) and a plan file, (None, "") for a file its loader will refuse (and name)."""
    from missions import Mission  # lazy: start-up time
    from missions.mission import is_plan_file, mission_path  # lazy: start-up time

    if isinstance(mission, Mission):
        return ({"link": mission.link, "physics_hz": mission.physics_hz, "rate_hz": mission.rate_hz,
                 "vehicles": mission.vehicles}, mission.source)
    if mission is None or is_plan_file(mission):
        return {}, ""
    path = mission_path(mission)  # (a shipped mission by name too)
    try:
        return load_toml(path), str(path)
    except ConfigError:
        return None, ""


def add_flight_options(p: argparse.ArgumentParser, vehicle: bool = True, optional_mission: bool = False) -> None:
    """Options every flying command shares: overrides of the mission's own values (``vehicle``: with the
    vehicle's failsafe action, its weather, its start parameters, and a run directory with plots, for the commands that
    fly the vehicle and record the whole run, ``sim`` and ``sitl``; ``bsst controller`` writes its own two
    files only when given ``--out``, and plots nothing). ``optional_mission``: ``bsst sitl``, whose
    ``--await-mission`` takes none."""
    if optional_mission:
        p.add_argument("mission", nargs="?", type=path_given("the mission"),
                       help="mission: a TOML file (see missions/) or a ground station's .plan or .waypoints; "
                            "none with --await-mission")
    else:
        p.add_argument("mission", type=path_given("the mission"),
                       help="mission: a TOML file (see missions/) or a ground station's .plan or .waypoints")
    if vehicle:
        p.add_argument("--out", type=path_given("--out"),
                       metavar="DIR", help="run directory (default runs/<UTC time>-<mission>)")
        p.add_argument("--overwrite", action="store_true", help="allow writing into a non-empty --out")
    else:
        p.add_argument("--out", type=path_given("--out"),
                       metavar="DIR", help="write controller.tlog and controller.bin into DIR "
                                           "(default: nothing written)")
        p.add_argument("--overwrite", action="store_true", help="allow replacing those files")
    p.add_argument("--rate", type=mission_number("--rate", "rate_hz"), metavar="HZ",
                   help="control rate, 50-1000 Hz (default: the mission's, 250)")
    p.add_argument("--profile", metavar="NAME", help="vehicle profile: paper, x500 or a profile TOML path")
    p.add_argument("--controller", type=law_spec("--controller"), metavar="LAW",
                   help="control law: bsst, smc, pid, or your own (path/to/file.py:Class or package.module:Class)")
    p.add_argument("--seed", type=mission_integer("--seed", "seed"), metavar="N", help="seed of random effects")
    add_scatter_option(p)
    add_discretization_option(p)
    if vehicle:
        p.add_argument("--no-plots", action="store_true", help="skip the PNG figures")
        add_failsafe_options(p)
        add_weather_options(p)
    add_param_options(p, start=vehicle)  # the controller sets no start values: it schedules changes only


def wind_flag(text: str) -> tuple[float, float]:
    """``--wind SPEED[:FROM_DEG]``: (m/s, compass degrees it blows from), each in ``[wind]``'s range (the one table:
    plant.events.EVENT_RANGES, with its unit)."""
    from plant.events import EVENT_RANGES  # lazy: only where --wind is given

    speed, sep, frm = text.partition(":")
    try:
        values = (number(speed), number(frm) if sep else 0.0)  # "5:" is a FROM left out, refused
    except ValueError:
        raise FlagRefusal("--wind", f"expected SPEED[:FROM_DEG] (m/s, compass degrees), got {text!r}",
                          sep=": ") from None
    (slo, shi, su), (flo, fhi, fu) = EVENT_RANGES["speed_mps"], EVENT_RANGES["from_deg"]
    if not (slo <= values[0] <= shi and flo <= values[1] <= fhi):
        raise FlagRefusal("--wind", f"SPEED must be in [{slo:g}, {shi:g}] {su} and FROM_DEG in [{flo:g}, "
                                    f"{fhi:g}] {fu}, got {text!r}", sep=": ")
    return values


def add_weather_options(p: argparse.ArgumentParser) -> None:
    """``--wind``, ``--turbulence`` (over the mission's ``[wind]``) and ``--at T:KIND[:ARGS]`` (after its
    ``[[events]]``; checked when the flight is built: plant/events.py). docs/weather.md."""
    p.add_argument("--wind", type=wind_flag, metavar="SPEED[:FROM_DEG]",
                   help="steady wind, m/s, blowing from compass FROM_DEG (default 0: from the north)")
    # the levels are plant.wind.TURBULENCE, written out so that building the parser loads no flight code
    p.add_argument("--turbulence", choices=("none", "light", "moderate", "severe"),
                   help="Dryden turbulence of MIL-HDBK-1797 at low altitude")
    p.add_argument("--turbulence-scaling", choices=("exact", "none"),  # plant.wind.SCALING
                   help="exact (default): the flight's turbulence record shifted to a zero mean and scaled to "
                        "the level's sigma, as TurbSim's ScaleIEC; none: the filters free-running (a short "
                        "flight's sample strays from both)")
    p.add_argument("--at", action="append", metavar="T:KIND[:ARGS]",
                   help="an event at mission time T s: motor:N=EFF, gps:off|on|jump=DX,DY,DZ, baro:drift=M_PER_S, "
                        "mag:off|on, gyro:bias=X,Y,Z, battery:empty|ok, wind:SPEED[:FROM], "
                        "gust:DURATION,AMPLITUDE[,FROM], link:PROFILE[,KEY=VALUE,...] (a handover); repeatable")



def add_scatter_option(p: argparse.ArgumentParser) -> None:
    """``--scatter M``: the Overrides field ``scatter_m`` ([start] scatter_m; missions/scatter.py)."""
    p.add_argument("--scatter", type=mission_number("--scatter", "start_scatter_m"), metavar="M",
                   help="start each seed's flight at a point drawn in a horizontal disc of M metres around the "
                        "mission's start (0-100 m; default: the mission's [start] scatter_m, else 0)")


def add_discretization_option(p: argparse.ArgumentParser) -> None:
    """``--discretization explicit|implicit``: the Overrides field of the same name (docs/law.md)."""
    from missions import DISCRETIZATIONS  # lazy: start-up time

    p.add_argument("--discretization", choices=DISCRETIZATIONS,
                   help="how bsst steps its super-twisting step: implicit (backward Euler, chattering-free; "
                        "docs/law.md) or explicit (the paper as printed, bit for bit) (default: the mission's "
                        "discretization key, else implicit)")


def overrides_from_args(args: argparse.Namespace) -> Overrides:
    """The :class:`~bridge.core.overrides.Overrides` a flying command's flags ask for (a flag the command does
    not have keeps the mission's own): the one way from ``bsst``'s flags to :func:`~bridge.core.flight.prepare`."""
    from bridge.core.overrides import Overrides  # lazy: building the parser loads no flight code

    return Overrides(profile=getattr(args, "profile", None), controller=getattr(args, "controller", None),
                     discretization=getattr(args, "discretization", None), rate_hz=getattr(args, "rate", None),
                     seed=getattr(args, "seed", None), scatter_m=getattr(args, "scatter", None),
                     link=link_table_from_args(args) or None, link_flags=link_flags_from_args(args) or None,
                     failsafe=failsafe_table_from_args(args) or None, **sensor_overrides_from_args(args),
                     **param_overrides_from_args(args),
                     wind=getattr(args, "wind", None), turbulence=getattr(args, "turbulence", None),
                     turbulence_scaling=getattr(args, "turbulence_scaling", None),
                     at=tuple(getattr(args, "at", None) or ()))


def add_key_option(p: argparse.ArgumentParser) -> None:
    """``--key FILE``: MAVLink 2 signing (bridge.mavlink.signing); the key is read from the file, never given on
    the command line, so it never shows in ``ps``."""
    p.add_argument("--key", metavar="FILE", help="sign every frame and accept only frames signed with this key: "
                                                 "a 32-byte file or a passphrase (hashed with SHA-256, as "
                                                 "MAVProxy does); not readable by others")



def add_port_options(p: argparse.ArgumentParser, vehicle: bool) -> None:
    """The ports, the clock, the pace and the signing key of ``bsst vehicle`` (``vehicle``) and ``bsst sitl``."""
    if vehicle:
        p.add_argument("--listen", metavar="HOST:PORT",
                       help="controller link, bound (default 127.0.0.1:14560 + instance)")
    p.add_argument("--gcs", metavar="HOST:PORT", help="ground station link: telemetry goes there "
                                                       "(default 127.0.0.1:14550 + instance; 'none': no GCS link)")
    p.add_argument("--instance", type=int_in("--instance", 0, 9), default=0, metavar="N",
                   help="PX4-style instance 0-9: ports 14560 + N and 14550 + N, sysid N + 1")
    clock = p.add_mutually_exclusive_group()
    if vehicle:
        clock.add_argument("--lockstep", dest="realtime", action="store_false", help="lockstep clock (default)")
    clock.add_argument("--realtime", action="store_true", help="run on the wall clock (default lockstep)")
    p.set_defaults(realtime=False)
    p.add_argument("--speed", type=pace_speed("--speed"), metavar="X",
                   help="lockstep: at most X times real time, 0 as fast as it goes (default: as fast as it goes; 1 "
                        "with --await-mission, as PX4's and ArduPilot's SITL); also the pace after the controller "
                        "is lost (X, else 1)")
    add_key_option(p)



def refuse_vehicle_flags(args: argparse.Namespace) -> None:
    """``bsst vehicle``'s flags that need another it was not given (a ``ConfigError`` naming both)."""
    from bridge.core.clock import realtime_speed_problem  # lazy: start-up time

    if args.realtime and (why := realtime_speed_problem(args.speed)):  # as bsst sitl refuses it
        raise ConfigError(why)
    # (each typed, source the flag, as every flag's refusal: a session's child reports it with its fields)
    if args.gate and args.realtime:
        raise ConfigError.at("--gate", None, "with --realtime: a fleet's shared step clock is lockstep's (real time "
                             "keeps the wall clock)", sep=" ")
    if args.trace_cap and not args.await_mission:
        raise ConfigError.at("--trace-cap", None, "only with --await-mission (it caps the mission a ground station "
                             "starts)")
    if args.param_at and not args.await_mission:  # (a change at a mission time is the controller's to send)
        raise ConfigError.at("--param-at", None, "only with --await-mission (the vehicle refuses at its start a ground "
                             "station's mission over before T; give the change to the controller, which sends it)")
