"""From a mission to the parts that fly it: every table validated by the part that owns it.

In:  a mission (a :class:`~missions.Mission` or a TOML path) and its
     :class:`~bridge.core.overrides.Overrides` (one frozen value: profile, controller, ``rate_hz`` Hz, seed,
     actuation, tables laid over ``[link]``, ``[failsafe]``, ``[sensors]``, an estimator kind, a noise scale,
     ``[params]`` entries by PX4 name, parameter changes at mission times s), or the same as keywords
Out: a frozen :class:`Flight`, which builds the plant, the :class:`~bridge.autopilot.simvehicle.SimVehicle`,
     the law and the guard's configuration, and lists the blackouts (mission time s); a bad value
     raises ``ConfigError`` naming file and key (or the flag, for an override)

:func:`prepare` lays the overrides over the mission and validates its profile, ``[effects]``,
``[gains]``, ``[failsafe]``, ``[link]``, ``[sensors]``, ``[estimator]`` and ``[params]`` tables, so that a
bad value fails before anything starts, with the file and key named. ``Overrides.of``
(bridge/core/overrides.py) is the one way from keywords (``simulate(mission, rate_hz=500)``) to an ``Overrides``.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from bridge.autopilot.batterywatch import BatteryWatch
from bridge.autopilot.compiling import cold
from bridge.autopilot.estimator import ESTIMATOR_KINDS, load_ekf_kernels, make_estimator
from bridge.autopilot.failsafe import FailsafeConfig, failsafe_from_table
from bridge.autopilot.landdisarm import LandDisarm
from bridge.autopilot.params import (
    ParamChange,
    VehicleParams,
    check_param_changes,
    params_as_failsafe,
    params_from_table,
)
from bridge.autopilot.simvehicle import HOLD, OFFBOARD, SimVehicle
from bridge.core.overrides import (
    Overrides,
    laid_file_problem,
    laid_trace_misfit,
    replaced_laid_problem,
    table_settings,
)
from bridge.core.scalar import checked_choice, compile_for, compiled_needed, compiled_wanted, wire_for
from bridge.core.weather import handovers_of, weather_of
from bridge.link.model import (
    DIRECTIONS,
    NEEDS,
    LinkSettings,
    absolute_link_paths,
    idle_problem,
    link_from_table,
    unmet_key,
)
from bridge.link.profile import load_link_profile
from controller import Controller, Gains, Nominal, gains_from_table
from controller.law import LawError, LawFactory, discretization_problem, resolve_law
from controller.link_guard import GuardConfig
from missions import Mission, Setpoint, Sine, Step, load_mission
from missions.airframe import fitted_to_airframe
from params import ConfigError, Table
from plant import Effects, Profile, Quadrotor, load_profile
from plant.alignment import aligned_start
from plant.effects import effects_from_table
from plant.events import TimedEvent
from plant.profiles import sensors_from_table
from plant.sensors import IDEAL, SIGMA_KEYS, SensorConfig, SensorSuite
from plant.wind import WindConfig, wind_from_table

Progress = Callable[[float, float, float], None]  # a flight's progress: (t s, duration s, current 3-D error m)


@dataclass(frozen=True)
class Flight:
    """A validated mission and everything built from it."""

    mission: Mission
    profile: Profile
    effects: Effects
    gains: Gains
    failsafe: FailsafeConfig
    link: LinkSettings = field(default_factory=LinkSettings)
    law: LawFactory | None = None  # the mission's controller, resolved (None: resolved on use)
    sensors: SensorConfig = IDEAL  # the vehicle's sensor set (profile's set, mission's overrides, noise scale)
    estimator: str = "truth"  # the vehicle's estimator kind (bridge.autopilot.estimator.ESTIMATOR_KINDS)
    params: VehicleParams = VehicleParams()  # the vehicle's parameters at start (failsafe: the same as .failsafe)
    param_changes: tuple[ParamChange, ...] = ()  # scheduled PARAM_SETs (--param-at), by mission time
    wind: WindConfig | None = None  # the air it flies through ([wind]); None: still air, the paper's model
    timeline: tuple[TimedEvent, ...] = ()  # faults and weather changes ([[events]], --at), by mission time

    @property
    def nominal(self) -> Nominal:
        """The controller's model: the profile's nominal numbers, never the effects."""
        return Nominal.from_profile(self.profile)

    @property
    def substeps(self) -> int:
        return int(round(self.mission.physics_hz / self.mission.rate_hz))

    def make_plant(self) -> Quadrotor:
        m = self.mission
        x, y, z, psi = m.flight_start  # the mission's start, or its seed's draw around it ([start] scatter_m)
        state = (x, 0.0, y, 0.0, z, 0.0, 0.0, 0.0, 0.0, 0.0, psi, 0.0)
        plant = Quadrotor(self.profile, self.effects, seed=m.seed, physics_hz=m.physics_hz, state=state,
                          wind=self.wind)
        if self.compiled:
            compile_for(plant=plant)
        return plant

    def make_vehicle(self, armed: bool = False) -> SimVehicle:
        plant = self.make_plant()
        p, m = self.params, self.mission
        # disarmed, it boots in HOLD, as PX4 does: a ground station's arm holds it on the ground until a takeoff;
        # the controller's arm takes offboard control
        settings = {"armed": armed, "mode": OFFBOARD if armed else HOLD, "takeoff_alt_m": p.takeoff_alt_m,
                    "timeline": self.timeline, "gust_notes": self.wind.gust_notes() if self.wind else (),
                    "failure_injection": p.failure_injection, "rtl": p.rtl,
                    "preflight_disarm_s": p.preflight_disarm_s, "max_hor_m": p.max_hor_m, "max_ver_m": p.max_ver_m,
                    "rally": m.rally, "fence": m.geofence, "fence_action": p.fence_action,
                    "noaid_timeout_us": p.noaid_timeout_us,
                    "reference_z": lambda t: m.trajectory.sample(t)[2][0],
                    "battery_watch": BatteryWatch(p.battery_low, p.battery_critical, p.battery_emergency,
                                                  p.low_battery_action),
                    "land_disarm": LandDisarm(p.land_disarm_s)}
        if self.estimator == "truth":  # no sensors to sample: the plant's state is published as it is
            return SimVehicle(plant, self.substeps, self.failsafe, **settings)
        suite = SensorSuite(self.sensors, m.seed, m.physics_hz, self.profile.gravity)
        start = plant.state
        if self.estimator == "ekf":  # an EKF has averaged its readings on the pad before its clock starts
            start = aligned_start(self.sensors, self.profile.gravity, plant.state, m.seed)
        est = make_estimator(self.estimator, self.sensors, start, self.profile.gravity, lambda: plant.state)
        return SimVehicle(plant, self.substeps, self.failsafe, sensors=suite, estimator=est, **settings)

    def make_controller(self) -> Controller:
        ctl = self._controller()
        if self.compiled:
            compile_for(ctl=ctl)
        return ctl

    def _controller(self) -> Controller:
        """The flight's law, built (a user's law checked), not yet given its compiled kernels."""
        m = self.mission
        return Controller(self.law or m.controller, self.nominal, self.gains, m.rate_hz, m.discretization)

    @property
    def compiled(self) -> bool:
        """Whether this flight's controller and plant fly compiled kernels (bridge.core.scalar)."""
        return compiled_wanted(self.mission.duration_s * self.mission.rate_hz)

    def kernels_flown(self) -> str:
        """The compiled kernels this flight flies in any process, for its children's fork server to load before it
        forks them (bridge.core.scalar.FLIES_ENV): ``ekf`` for its EKF, ``scalar`` for its law and plant
        (bridge.core.scalar.compiled_needed), comma-separated; "" for neither."""
        kinds = (("ekf", self.estimator == "ekf"),
                 ("scalar", compiled_needed(self.mission.duration_s * self.mission.rate_hz)))
        return ",".join(kind for kind, flown in kinds if flown)

    def wire(self) -> tuple[Callable[..., tuple[float, ...]], Callable[..., tuple[float, ...]]]:
        """The state's wire conversion as this flight calls it, out (a state's ODOMETRY fields) and in (the state
        of ODOMETRY's fields): compiled when its kernels are (bridge.core.scalar.wire_for; the same bits)."""
        return wire_for(self.compiled)

    @property
    def guard(self) -> GuardConfig:
        """The controller's link guard: ``[link]`` thresholds and compensation, ``[failsafe] resume``."""
        return replace(self.link.guard, resume=self.failsafe.resume)

    def blackout_notes(self) -> list[tuple[float, str]]:
        """Events to log at the start of each scheduled link blackout: (mission time s, text), in time order."""
        windows: dict[tuple[float, float], list[str]] = {}
        for d, cfg in (("up", self.link.up), ("down", self.link.down)):
            for w in cfg.blackouts:
                windows.setdefault(w, []).append(d)
        return [(s, f"{'+'.join(ds)} link blackout from {s:.3f} s for {dur:.3f} s")
                for (s, dur), ds in sorted(windows.items())]


def _blackouts_given(m: Mission, over: Overrides, d: str) -> str:
    """Where direction ``d``'s blackouts were given, as a refusal names them: the flags (``--blackout``), the
    mission's direction table or its ``[link]``, else its link profile's file (``--link-profile``, ``link.profile``)."""
    def key_in(link: Mapping[str, Any]) -> str | None:
        own = link.get(d)
        return (f"link.{d}.blackouts" if isinstance(own, Mapping) and "blackouts" in own
                else "link.blackouts" if "blackouts" in link else None)

    given = (over.link or {}).get(d)
    if isinstance(given, Mapping) and "blackouts" in given:  # an override: the flags' table
        return f"{m.source}: --blackout/--{d}-blackout ({key_in(m.link) or f'link.{d}.blackouts'})"
    if (mine := key_in(m.link)) is not None or not m.link.get("profile"):
        return f"{m.source}: {mine or 'link.blackouts'}"
    prof = load_link_profile(m.link["profile"])  # (loaded already: the settings came from it)
    return f"{prof.path}: {key_in(prof.link) or 'link.blackouts'} (the flight's link profile)"


# where else a fleet flies, said where a [[vehicles]] mission is refused (a sweep's axis lays its own fleets)
FLEETS_ELSEWHERE = ("a sweep lays fleets out itself (--vehicles N,... on a mission without [[vehicles]]); bsst "
                    "margin, vehicle and controller fly one vehicle")


@dataclass(frozen=True)
class Span:
    """What a flight's ``duration_s`` is the length of, in its refusals' words (:func:`prepare`'s ``span``): a
    mission's, or ``bsst relay``'s run without one (bridge.cli.linktools)."""

    whole: str = "the mission"  # a link trace "shorter than the mission (30 s)"
    end: str = "the mission's end"  # a blackout "after the mission's end (duration_s = 30 s)"
    given: str = "duration_s ="  # how that length was given, before it


def prepare(mission: Mission | str | Path, overrides: Overrides | None = None, *, axes: Iterable[str] = (),
            laid_named: bool = False, span: Span = Span(), **keywords: Any) -> Flight:
    """Validate a mission (object or file) with its :class:`Overrides` into a :class:`Flight`.

    The overrides are ``overrides``, or the same fields as keywords (:meth:`Overrides.of`: ``rate_hz=500``).
    ``link`` is laid over the mission's ``[link]`` table (see :func:`bridge.link.model.merge_link_tables`);
    ``failsafe`` over its ``[failsafe]`` table, key by key (``{"action": "hold"}``); ``sensors`` over
    its ``[sensors]`` table, key by key (``{"set": "mocap"}``); ``estimator`` replaces ``[estimator] kind``;
    ``noise`` replaces ``[sensors] noise_scale`` (every σ of the set times it); ``params`` over its
    ``[params]`` table (``{"COM_OF_LOSS_T": 1.0}``; a parameter standing for a ``[failsafe]`` key wins
    over it, and a ``failsafe`` override over a ``[params]`` entry of the file). ``param_at``: parameter
    changes at mission times (:class:`bridge.autopilot.params.ParamChange`), checked here. What would change
    nothing is refused, last: a key of the mission's own ``[link]`` whose need nobody gives (:func:`idle_link_key`;
    ``axes``: the keys a campaign's cells lay over this flight, a sweep's swept axes, a margin's searched one),
    then one ``link`` lays over it (unless ``laid_named``: the caller names what it lays over itself, a command
    its flags, bridge.cli.linkflags.idle_link_flag, a campaign its cells' axes, bridge.sweep.spec), a
    ``discretization`` override for a law without a super-twisting step (:func:`discretization_refusal`), a
    turbulence scaling with no turbulence (:func:`scaling_refusal`). ``span``: what the mission's length is called.
    """
    over = Overrides.of(overrides, **keywords)
    axes = tuple(axes)  # (read by each refusal below)
    m = mission if isinstance(mission, Mission) else load_mission(mission)
    own = m  # (as given: its own law, and its own [link] keys to tell from what is laid over them)
    m = over.laid_over(m)
    src = m.source
    if m.vehicles:  # each vehicle's flight is prepared from its own mission (missions.fleet.vehicle_mission)
        raise ConfigError(f"{src}: vehicles: a mission of several vehicles is flown by bsst sim and bsst sitl "
                          "(bridge.simulate, bridge.swarm.sitl): " + FLEETS_ELSEWHERE)
    _laid_tables_alone(m, over)
    prof = _profile_of(m, over)
    effects = effects_from_table(Table(m.effects, src, "effects"))
    gains = gains_from_table(m.gains, src) if m.gains else Gains()
    m = fitted_to_airframe(m, prof.mass, prof.gravity, prof.u_max[0], gains.tilt_max)  # a plan's: slowed or refused
    for key, name in params_as_failsafe(m.params).items():  # two keys of one file for one setting
        if key in m.failsafe:
            raise ConfigError(f"{src}: params.{name} and failsafe.{key} set the same thing: give one of them")
    vehicle_params = params_from_table(m.params, src, VehicleParams(failsafe_from_table(m.failsafe, src)))
    failsafe = vehicle_params.failsafe
    changes = check_param_changes(over.param_at, m.duration_s)
    link_settings = _link_of(m, over, span)
    sensor_config, estimator_kind = _sensing_of(m, over, prof)
    _check_blackouts(m, over, link_settings, span)
    # an event's refusal is named where it was given (plant.events.table_where): a flag's by its TimedEvent.at
    # (--at 10:gps:off), else the mission's table, with a table laid from Python's place in at= (at[0])
    wind, timeline = weather_of(m, prof, sensor_config, estimator_kind, effects.battery)
    link_settings = replace(link_settings, handovers=handovers_of(timeline, m))
    try:
        law = resolve_law(m.controller)
        flight = Flight(m, prof, effects, gains, failsafe, link_settings, law, sensor_config, estimator_kind,
                        vehicle_params, changes, wind, timeline)
        checked_choice()  # BSST_KERNELS: bad input before anything flies
        flight._controller()  # a user's law is built once here, so that one that does not fit is bad input (not
        # compiled: a process that only prepares, a relay or a planner, never loads numba for it)
    except LawError as exc:  # named where the law was given: the override (--controller), else the mission's key
        given = over.controller is not None and m.controller != own.controller
        raise LawError(exc.spec, exc.what, f"--controller {over.controller}" if given else f"{src}: {exc.where}") \
            from None
    except ConfigError as exc:
        raise ConfigError(f"{src}: {exc}") from None
    # last: a flight that cannot be flown is named for that first
    idle = (idle_link_key(own, over.link, axes)
            or (None if laid_named else idle_laid_key(src, over.link, flight.link, axes))
            or discretization_refusal(over.discretization, (m.controller,))
            or scaling_refusal(m, over, flight.wind, axes)
            or replaced_laid_problem(over, src, timeline, m.rate_hz,  # a t = 0 wind or link event over a flag's
                                     flight.wind is not None and flight.wind.turbulence != "none"))
    if idle:
        raise ConfigError(idle)
    return flight


def _laid_tables_alone(m: Mission, over: Overrides) -> None:
    """A ``wind`` or ``failsafe`` table a caller lays over the mission, checked alone first: a key or value bad on
    its own is named as the override it came in (``overrides: wind.speed: unknown key in [wind]; did you mean
    'speed_mps'?``, as :class:`Overrides` names a wrong type), not as the file's, which may have no such table (the
    flags that fill them, ``--wind``, ``--failsafe-action``, are checked as they are parsed)."""
    if over.wind:
        wind_from_table(Table(over.wind, "overrides", "wind"), m.duration_s)
    if over.failsafe:
        failsafe_from_table(over.failsafe, "overrides")


def _profile_of(m: Mission, over: Overrides) -> Profile:
    """The mission's vehicle profile (:func:`plant.profiles.load_profile`), its actuation if the mission gives one; a
    profile refused is named where it was given: the ``--profile`` override, else the mission's key."""
    try:
        prof = load_profile(m.profile)
    except ConfigError as exc:  # an override's named as the flag (the mission may have no profile key)
        raise ConfigError(f"{f'--profile {over.profile}' if over.profile is not None else f'{m.source}: profile'}: "
                          f"{exc}") from None
    return prof.with_actuation(m.actuation) if m.actuation else prof


def _link_of(m: Mission, over: Overrides, span: Span) -> LinkSettings:
    """The mission's link settings (:func:`bridge.link.model.link_from_table`, the overrides laid over already); a
    table refused with overrides over a file's says what was laid over it."""
    src = m.source
    try:
        return link_from_table(m.link, src, seed=m.seed, duration_s=m.duration_s, span=span.whole)
    except ConfigError as exc:
        if not over.link or not Path(src).is_file():  # no file (bsst relay or vehicle without one, --await-mission,
            raise  # a Mission made in Python): no file's [link] to tell the overrides from
        flagged = laid_file_problem(over.link, over.link_flags) or laid_trace_misfit(exc, src, m.link, over)  # a
        # trace or profile the flags gave, bad alone or not fitting this flight: the flag's
        if flagged:
            raise ConfigError(flagged) from None
        if exc.source != src:  # another file's key (the profile's own link.delay): what was laid over the mission's
            raise  # [link] is not in it
        # the file's [link] with the overrides over it: say them, or a user who gave --stop-after 40 reads that the
        # file has a stop_ms it does not have
        laid = table_settings(over.link, "link")
        raise ConfigError(f"{exc} (with these laid over the mission's [link]: {laid})") from None


def _sensing_of(m: Mission, over: Overrides, prof: Profile) -> tuple[SensorConfig, str]:
    """The flight's sensors (its profile's set the mission or ``--sensors`` names: :func:`sensors_from_table`) and
    its estimator's kind (``[estimator] kind``: :data:`ESTIMATOR_KINDS`)."""
    src = m.source
    given_set = (over.sensors or {}).get("set")
    if given_set is not None and given_set not in [n for n, _ in prof.sensors]:  # an override: named as the flag
        raise ConfigError(f"--sensors {given_set}: profile {prof.name!r} has no such sensor set; it has: "
                          f"{', '.join(n for n, _ in prof.sensors)}")
    sensor_config = sensors_from_table(prof, m.sensors, src)
    est_table = Table(m.estimator, src, "estimator")
    estimator_kind = est_table.string("kind", "truth", choices=ESTIMATOR_KINDS)
    est_table.done()
    return sensor_config, estimator_kind


def _check_blackouts(m: Mission, over: Overrides, link_settings: LinkSettings, span: Span) -> None:
    """Refuse a link blackout that starts after the mission's end: one that would never happen is a mistake in the
    file, not a plan (named where it was given: :func:`_blackouts_given`)."""
    for d in ("up", "down"):
        for start, dur in getattr(link_settings, d).blackouts:
            if start >= m.duration_s:
                raise ConfigError(f"{_blackouts_given(m, over, d)}: the window [{start:g}, {start + dur:g}) s starts "
                                  f"after {span.end} ({span.given} {m.duration_s:g} s), so it would never happen")


def idle_link_key(m: Mission, link: Mapping[str, Any] | None, axes: Iterable[str] = ()) -> str | None:
    """The line refusing a key of ``m``'s own ``[link]`` (:data:`bridge.link.model.NEEDS`: ``burst_len`` without
    ``loss_pct``, ``queue_ms`` without ``rate_bps``, ``trace_loop`` without ``trace``) whose need nobody gives: not the
    table, its profile (or the one ``link`` names), ``link`` (what is laid over it: any key of it or of its
    directions, a flag's or a caller's) nor ``axes`` (:func:`bridge.link.model.unmet_key`), naming the file and the
    key; None."""
    own = absolute_link_paths(m.link, Path(m.source).parent)
    over = absolute_link_paths(link, Path(".")) if link else {}
    table = {**own, "profile": over["profile"]} if "profile" in over else own
    given = {k for t in (over, *(over.get(d) for d in DIRECTIONS)) if isinstance(t, Mapping) for k in t} | set(axes)
    unmet = unmet_key(table, given)
    return None if unmet is None else f"{m.source}: link.{unmet[0]}: {unmet[1]}"


def idle_laid_key(source: str, link: Mapping[str, Any] | None, flown: LinkSettings, axes: Iterable[str] = ()
                  ) -> str | None:
    """The line refusing a key of :data:`bridge.link.model.NEEDS` that ``link`` (what a Python caller lays over
    ``source``'s ``[link]``) gives and that changes nothing on every direction it is given for, as the ``flown``
    links have it (the rule a command's flag is refused by: bridge.cli.linkflags.idle_link_flag; ``burst_len``
    for both directions acts where one loses packets), unless ``axes`` (a campaign's) give its need; None."""
    laid, given = link or {}, set(axes)
    for key, (need, *_) in NEEDS.items():
        dirs = [d for d in DIRECTIONS if key in laid or key in (laid.get(d) or {})]
        why = None if not dirs or need in given else idle_problem(key, [getattr(flown, d) for d in dirs])
        if why:
            where = key if key in laid else f"{dirs[0]}.{key}"
            return (f"{source}: link.{where}: changes nothing: {why}; give {need} too, or remove {key} (with these "
                    f"laid over the mission's [link]: {table_settings(laid, 'link')})")
    return None


def scaling_refusal(m: Mission, over: Overrides, wind: WindConfig | None, axes: Iterable[str] = ()) -> str | None:
    """The line refusing a turbulence scaling with no turbulence to scale (it would change nothing, yet its
    ``[wind]`` table switched the air model on): ``--turbulence-scaling`` (Python's ``turbulence_scaling=``) where
    the flight flies none, named as the flag as ``--discretization`` is; a ``[wind] turbulence_scaling`` key of
    ``m`` (the mission with the overrides laid over it) where no ``turbulence`` is given at all (not the table,
    nor laid over it, nor ``axes``: a sweep's turbulence axis, whose cells each lay theirs), as a ``[link]`` key
    whose need nobody gives; ``turbulence = "none"`` beside it is taken, what a run's mission.toml holds after
    ``--turbulence none``. None."""
    does = "it sets how the turbulence is scaled"
    if over.turbulence_scaling is not None and (wind is None or wind.turbulence == "none"):
        return (f"--turbulence-scaling {over.turbulence_scaling}: changes nothing: {does}, and the flight flies no "
                "turbulence (turbulence none); give --turbulence LEVEL too, or drop --turbulence-scaling")
    if "turbulence_scaling" not in m.wind or "turbulence" in m.wind or "turbulence" in axes:
        return None
    laid = (f" (with these laid over the mission: {table_settings(over.wind, 'wind')})"
            if "turbulence_scaling" in (over.wind or {}) else "")
    return (f"{m.source}: wind.turbulence_scaling: changes nothing: {does}, and no turbulence is given; give "
            f"turbulence too, or remove turbulence_scaling{laid}")


def discretization_refusal(scheme: str | None, laws: Iterable[str]) -> str | None:
    """The line refusing a discretization ``scheme`` laid over a flight (``--discretization``, or Python's
    ``discretization=``) where no law of ``laws`` (a flight's, a fleet's vehicles', a margin's) is ``bsst``: it would
    change nothing (:func:`controller.law.discretization_problem`); None, and None for no scheme."""
    why = None if scheme is None else discretization_problem(laws)
    return None if why is None else f"--discretization {scheme}: {why}; drop the flag, or fly --controller bsst"


def noiseless(sensors: SensorConfig) -> bool:
    """Whether a sensor set has no noise at all (every sigma 0 or unused): scaling it changes nothing."""
    return not any(getattr(sensors, k) for k in SIGMA_KEYS)


def unread_problem(estimators: Sequence[str], what: str, choose: str = "--estimator raw or ekf") -> str | None:
    """Why ``what`` of the sensors (their noise, the set flown) would change nothing in flights with these estimator
    kinds (None if it would): every one is ``truth`` (the true state: the sensors are not read); ``choose``: how the
    caller picks another (the flag; a Python caller's keyword)."""
    if set(estimators) <= {"truth"}:
        return (f"the estimator is 'truth' (the true state: the sensors are not read), so {what} changes nothing; "
                f"give {choose} (or [estimator] kind)")
    return None


def laid_sensing_refusal(over: Overrides, flight: Flight) -> str | None:
    """The line refusing a Python caller's ``noise=`` or ``sensors=`` that the flight does not read (its estimator
    ``truth``), as ``--noise`` / ``--sensors`` are refused (bridge.cli.options): ``simulate(m, noise=5.0)`` flew the
    true state, byte for byte as without it, until the third wave's forty-third session; None."""
    if over.noise is not None:
        given, what = f"noise = {over.noise:g}", "noise"
    elif over.sensors and "set" in over.sensors:
        given, what = f"sensors = {dict(over.sensors)!r}", "the sensor set"
    else:
        return None
    why = unread_problem((flight.estimator,), what, choose="estimator='raw' or 'ekf'")
    return f"{given}: {why}" if why else None


def noise_problem(estimators: Sequence[str], sensors: SensorConfig) -> str | None:
    """Why a noise scale would change nothing in flights with these estimator kinds and this sensor set
    (None if it does): every one is ``truth`` (:func:`unread_problem`), or the set has no noise to scale."""
    unread = unread_problem(estimators, "noise")
    if unread:
        return unread
    if noiseless(sensors):
        return (f"the sensor set {sensors.name!r} has no noise (every sigma is 0), so its scale changes nothing; "
                "choose one with --sensors mocap or gnss (or [sensors] set)")
    return None


def at_rest(duration_s: float = 86400.0) -> Mission:
    """What a bare ``bsst vehicle`` (or ``bsst relay`` without ``--mission``) flies: the paper
    profile at rest at the origin for ``duration_s`` (a day at most); its tables are the command line's."""
    return Mission(Step((Setpoint(0.0, 0.0, 0.0, 0.0, 0.0),)), duration_s=min(duration_s, 86400.0), name="vehicle",
                   source="command line")


def compiled_kernels_cached(ekf: bool = True) -> bool:
    """Whether :func:`load_compiled_kernels` would load the kernels from numba's cache on disk, not compile them
    (~4 s, the EKF's ~7 s more): what ``auto`` asks before it loads them on behalf of children that would fly
    plain otherwise (bridge.core.kernelpreload, bridge.core.kernelwarm). Imports numba (~0.6 s) to look."""
    import bridge.autopilot.ekfkernels  # noqa: F401  (imported: its dispatchers are looked at)
    import bridge.core.scalarkernels  # noqa: F401  (as above)

    packages = ["bridge.core.scalarkernels", *(["bridge.autopilot.ekfkernels"] if ekf else [])]
    return not any(cold(p) for p in packages)


def load_compiled_kernels(ekf: bool = True) -> None:
    """Load the scalar engine's compiled kernels (a built-in law's step, the plant's RK4 step) into this process,
    and with ``ekf`` the EKF's, from numba's cache on disk (numba's import and the load: ~1 s of CPU; a cold cache
    compiles them). The fork server does it when every flight asks for them (``BSST_KERNELS=compiled``), so that
    each child it forks starts with them loaded instead of paying the load itself (bridge.cli.forkserver)."""
    flight = prepare(Mission(Sine(), duration_s=1.0, name="kernels"))
    compile_for(ctl=flight.make_controller(), plant=flight.make_plant())
    wire_for(True)
    if ekf:
        load_ekf_kernels()
