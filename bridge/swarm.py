"""Several vehicles in one world, offline: N plants and N laws stepped in one loop (``bsst sim``).

In:  a mission (a :class:`~missions.Mission` or a TOML path) with ``[[vehicles]]``, or any mission with
     ``vehicles=N`` and ``formation="line:SPACING"`` (m; :mod:`missions.fleet`), and its overrides (as
     :func:`bridge.loop.simulate` takes them)
Out: a :class:`FleetRun`: each vehicle's :class:`~bridge.record.runlog.Run` (system ids 1..N) and the
     fleet's ``summary.json`` as a dict: ``duration_s`` (the time flown: to its last vehicle's end, as one
     vehicle's), ``vehicles`` (id, outcome, RMS m, ...), ``separation`` (the
     closest approach of every pair, m, and when, s), ``policies``, the worst ``outcome``; with a directory,
     ``vehicle-<id>/`` (each vehicle's own run: ``trace.csv``, ``summary.json``, ``plots/``), ``mission.toml``
     (the fleet as flown), ``summary.json`` and ``plots/`` (every vehicle); on one shared radio
     (``[link] shared``, ``--shared-link``) ``radio``: each vehicle's share of it (bytes/s), its queue waits (ms)

A mission without vehicles is flown by :func:`bridge.loop.simulate` as it always was, byte for byte.
A fleet's vehicles fly one control step each, in turn (:data:`TURNS`), then the shared world is judged on their true
positions after that step (:class:`~bridge.record.separation.Watch`): clearance (centres' distance less both disc radii,
:class:`missions.fleet.Separation`) below ``min_m`` breaks the ``separation`` policy (exit 1); at zero
or less the two touch and both end ``collision``. Each vehicle is its own flight
(:func:`missions.fleet.vehicle_mission`: its own seed, so its own link's fates, effects and sensors), on
the same clock: a vehicle flies exactly as it would alone, until something touches it (or, on one shared
radio, :mod:`bridge.link.radio`, its packets wait behind the others'). The end landing after the mission is
stepped and judged as the mission's steps are; a vehicle that has ended stays where it ended, an obstacle. A
failsafe's landing still going at the mission's end is flown alone, as by itself, judged but told nothing (as a
lockstep fleet judges it on its record): a contact there is found, not prevented (both ``collision`` in the fleet's
summary, their flights as flown), and ``separation.alone`` says who flew so, from when to when.
"""

from __future__ import annotations

import shutil
import tempfile
from collections.abc import Generator, Sequence
from inspect import GEN_CLOSED, getgeneratorstate
from pathlib import Path
from typing import Any

from bridge.core.flight import Flight, Progress, discretization_refusal, prepare
from bridge.core.overrides import Overrides, check_switches
from bridge.link.model import merge_link_tables
from bridge.link.radio import Radio
from bridge.link.turns import TURNS, turn_order
from bridge.loop import Alone, Step, flying, recorded_run
from bridge.loop import simulate as simulate_one
from bridge.record.outlock import check_out_free, out_held
from bridge.record.policies import run_ok
from bridge.record.runlog import (
    MAX_TRACE_STEPS,
    Run,
    check_trace_steps,
    run_dir,
    trace_cap,
    write_json_atomic,
    write_text_atomic,
)
from bridge.record.separation import CONTINUED, WALL_CLOCK, Untold, Watch, judge_traces
from bridge.record.wallclock import REALTIME, clocked_records, judged_on_wall_clock, taken_over_records
from controller.law import DISCRETIZED
from missions import Mission, load_mission
from missions.fleet import (
    DEFAULT_MIN_SEPARATION_M,
    Separation,
    VehicleSpec,
    clearance,
    formation,
    link_seeds_moved,
)
from missions.fleet import vehicle_mission as mission_of
from params import ConfigError, dump_toml, reads_inputs

# each vehicle's, each way, in the fleet's summary: enough that sent = delivered + lost + in flight (a duplicate and a
# reordered packet are delivered ones, counted again)
LINK_FIGURES = ("sent", "delivered", "lost", "lost_by", "in_flight", "duplicated", "reordered", "delay_ms")
# the outcomes from best to worst: the fleet's outcome is its worst vehicle's (an unknown one is worst)
SEVERITY = ("completed", "failsafe", "law_failed", "denied", "diverged", "crashed", "terminated", "collision",
            "aborted")


class FleetRun:
    """The result of a fleet's flight: ``runs`` (each vehicle's :class:`Run`, by id), ``summary``, ``path``."""

    def __init__(self, runs: list[Run], summary: dict[str, Any], path: Path | None) -> None:
        self.runs = runs
        self.summary = summary
        self.path = path

    @property
    def outcome(self) -> str:
        return self.summary["outcome"]

    @property
    def rms(self) -> float | None:
        """The largest of the vehicles' 3-D RMS errors (m)."""
        return self.summary["rms_3d"]

    def __repr__(self) -> str:
        return (f"FleetRun(vehicles={len(self.runs)}, outcome={self.outcome!r}, rms_3d={self.rms!r}, "
                f"path={str(self.path) if self.path else None!r})")


@reads_inputs
def simulate(mission: Mission | str | Path, *, vehicles: int | Sequence[Any] | None = None,
             formation: str | None = None, out: str | Path | None = None, write: bool = False,
             overwrite: bool = False, plots: bool = True, progress: Progress | None = None,
             overrides: Overrides | None = None, **keywords: Any) -> Run | FleetRun:
    """Fly a mission offline: one vehicle as :func:`bridge.loop.simulate` flies it (its :class:`Run`), or a
    fleet (a :class:`FleetRun`): the mission's ``[[vehicles]]``, or ``vehicles`` = N with ``formation``
    (``line:SPACING``, ``grid:SPACING`` or ``circle:RADIUS``, m; default ``line:2``), or ``vehicles`` = a
    sequence of :class:`~missions.fleet.VehicleSpec`. ``progress`` follows vehicle 1. Everything else as
    :func:`bridge.loop.simulate`."""
    check_switches(write=write, overwrite=overwrite, plots=plots)
    rate = Overrides.of(overrides, **keywords).rate_hz  # the cap's rate: a plan too long is refused before it is timed
    m = mission if isinstance(mission, Mission) else load_mission(mission, trace_cap(rate))  # loaded once
    fleet = fleet_mission(m, vehicles, formation)
    if fleet is None:
        return simulate_one(m, out=out, write=write, overwrite=overwrite, plots=plots, progress=progress,
                            overrides=overrides, **keywords)
    over = Overrides.of(overrides, **keywords)
    flights = fleet_flights(fleet, over)
    check_fleet_steps(fleet, flights)  # before the run directory is made: a refused mission writes nothing
    check_fleet_starts(fleet, flights, vehicles, formation)
    radios = shared_radios(fleet, flights, over)
    with out_held(out):  # (another run writing this --out: refused before its files are touched)
        path = run_dir(out, fleet.name, overwrite) if (out is not None or write) else None
        return fly_fleet(over.laid_over(fleet), flights, path, plots=plots, progress=progress, radios=radios)


def check_fleet_steps(m: Mission, flights: list[Flight]) -> None:
    """Refuse a fleet whose traces together would not fit in memory: every vehicle keeps a row a control step
    for its summary, and together they may keep what one run may (:func:`bridge.record.runlog.check_trace_steps`)."""
    for f in flights:
        check_trace_steps(f.mission)
    total = sum(f.mission.steps for f in flights)
    if total > MAX_TRACE_STEPS:
        raise ConfigError(f"{m.source}: duration_s: {len(flights)} vehicles of {flights[0].mission.steps} control "
                          f"steps are {total} steps, over the {MAX_TRACE_STEPS} a run keeps in memory for its "
                          "summary: fly fewer vehicles or a shorter mission")


def check_fleet_starts(m: Mission, flights: list[Flight], vehicles: object, layout: str | None) -> None:
    """Refuse a fleet whose vehicles start touching (a clearance of zero or less between two rotor discs at the
    start: a contact before anything flies), naming where the starts came from: ``--formation`` (``layout``, with
    ``vehicles`` = N; N alone lays out ``line:2``), the given :class:`VehicleSpec` s, or the mission's
    ``vehicles`` (their starts and offsets)."""
    watch = _watch(m, flights)
    starts = [f.mission.start[:3] for f in flights]
    pairs = [(clearance(starts[a], starts[b], watch.radii[a], watch.radii[b]), a, b)
             for a in range(len(starts)) for b in range(a + 1, len(starts))]
    touching = [p for p in pairs if p[0][1] <= 0.0]
    if not touching:
        return
    (d, c), a, b = min(touching, key=lambda p: p[0][1])
    where = (f"{m.source}: vehicles" if vehicles is None else
             f"--formation {layout or 'line:2'}" if isinstance(vehicles, int) else "vehicles")
    raise ConfigError(f"{where}: vehicles {watch.ids[a]} and {watch.ids[b]} start touching: their rotor discs are "
                      f"{c:.3f} m apart (centres {d:.3f} m; a clearance of zero or less is a contact): spread them")


def fleet_mission(m: Mission, vehicles: int | Sequence[Any] | None, layout: str | None) -> Mission | None:
    """``m`` with its fleet (its own ``[[vehicles]]``, or the one given), or None for a mission of one vehicle."""
    if vehicles is None:
        if layout is not None:
            raise ConfigError(f"--formation {layout}: lays out several vehicles: give --vehicles N")
        return m if m.vehicles else None
    if m.vehicles:
        raise ConfigError(f"{m.source}: vehicles: the mission has its own [[vehicles]]; --vehicles would replace "
                          "them: give one or the other")
    if isinstance(vehicles, int) and not isinstance(vehicles, bool):
        specs = formation(vehicles, "line:2" if layout is None else layout)  # "" refused, not the default
    else:
        specs = tuple(vehicles) if isinstance(vehicles, Sequence) and not isinstance(vehicles, str) else ()
        if not specs or not all(isinstance(v, VehicleSpec) for v in specs) or \
                sorted(v.id for v in specs) != list(range(1, len(specs) + 1)):
            raise ConfigError(f"vehicles: expected a number of vehicles or VehicleSpec values with ids 1..N, "
                              f"got {vehicles!r}"[:300])
        if layout is not None:
            raise ConfigError(f"--formation {layout}: the vehicles given place themselves: give one or the other")
        specs = tuple(sorted(specs, key=lambda v: v.id))
    return m.with_overrides(vehicles=specs)


def fleet_flights(m: Mission, over: Overrides, laid_named: bool = False) -> list[Flight]:
    """Each vehicle's :class:`Flight`, by id: its own mission with the overrides laid over it (a ``seed``
    override, and the seeds a ``[link]`` override names, moved by the vehicle's id less one, as its own; a
    ``discretization`` override on the vehicles that fly ``bsst``, refused where none does); ``laid_named``:
    as :func:`bridge.core.flight.prepare`'s."""
    laws = [over.controller or v.controller or m.controller for v in m.vehicles]  # (each as mission_of gives it)
    idle = discretization_refusal(over.discretization, laws)
    if idle:
        raise ConfigError(idle)
    flights = []
    for v, law in zip(m.vehicles, laws, strict=True):
        given = over.given()
        if law not in DISCRETIZED:  # (a law without a super-twisting step: the scheme is the others')
            given.pop("discretization", None)
        if "seed" in given:
            given["seed"] = (given["seed"] + v.id - 1) % 2**31
        if "link" in given:
            given["link"] = link_seeds_moved(given["link"], v.id - 1)
        try:
            flights.append(prepare(mission_of(m, v), Overrides.of(given), laid_named=laid_named))
        except ConfigError as exc:
            moved = f", moved by ({', '.join(f'{c:g}' for c in v.offset)}) m" if any(v.offset) else ""
            raise ConfigError(f"{exc} (vehicle {v.id}{moved})"[:400]) from None
    return flights



def shared_radios(m: Mission, flights: list[Flight], over: Overrides | None = None) -> tuple[Radio, Radio] | None:
    """The fleet's one radio, (up, down) (:mod:`bridge.link.radio`: every vehicle's traffic of a direction in one
    queue behind one bandwidth budget, each vehicle a user, by id), when its ``[link]`` says ``shared``; else
    None (each vehicle its own link). A handover (an event of kind ``link``) on a shared radio is refused, named
    where each was given: the flags (``over``: ``--shared-link``, ``--at``) or the mission's keys."""
    if not flights[0].link.shared:
        return None
    if any(f.link.handovers for f in flights):
        given = [n for e, n in zip(over.at, over._at_named, strict=True) if e.get("kind") == "link"] if over else []
        where = "--shared-link" if over and "shared" in (over.link or {}) else f"{m.source}: link.shared"
        which = given[0] if given else "events of kind link"
        raise ConfigError(f"{where}: a fleet on one radio with link handovers ({which}) is not modelled yet: give "
                          "one or the other")
    up, down, n = flights[0].link.up, flights[0].link.down, len(flights)
    return Radio(up.rate_bps, up.queue_ms / 1000.0, n), Radio(down.rate_bps, down.queue_ms / 1000.0, n)


def fly_fleet(m: Mission, flights: list[Flight], path: Path | None, *, plots: bool = True,
              progress: Progress | None = None, radios: tuple[Radio, Radio] | None = None) -> FleetRun:
    """Fly a fleet's prepared flights in one world (the module's docstring), on one shared radio if ``radios``
    (:func:`shared_radios`); write its directory into ``path``."""
    watch = _watch(m, flights)
    dirs = _vehicle_dirs(m, path)
    steps = [flying(f, d, plots=plots, progress=progress if i == 0 else None, radios=radios, user=i)
             for i, (f, d) in enumerate(zip(flights, dirs))]
    runs, untold, stopped = _fly_together(steps, [f.mission.start[:3] for f in flights], flights[0].mission.rate_hz,
                                          watch)
    runs = [r if r.outcome == "collision" else _touched(r, untold.found.get(j)) for j, r in enumerate(runs)]
    summary = fleet_summary(m, flights, runs, watch)
    if untold.first:  # a failsafe's landing after the mission, flown alone: judged, said
        summary["separation"]["alone"] = untold.summary()
    if radios is not None:
        ids = [v.id for v in m.vehicles]
        until = max(len(r.trace["t"]) for r in runs) / flights[0].mission.rate_hz  # the steps flown, s
        summary["radio"] = {"shared": True, "order": TURNS,
                            **{d: r.occupancy(ids, until) for d, r in zip(("up", "down"), radios)}}
    _finish(m, path, runs, watch, summary, plots)
    if stopped:
        raise KeyboardInterrupt  # (held as the last flights were judged: the fleet's record is whole, as it ended)
    return FleetRun(runs, summary, path)


def _watch(m: Mission, flights: list[Flight]) -> Watch:
    """The fleet's separation policy (its ``[separation]``, else the default) over its vehicles' discs."""
    sep = m.separation or Separation(DEFAULT_MIN_SEPARATION_M)
    return Watch([v.id for v in m.vehicles], [sep.disc_radius(f.profile.arm) for f in flights], sep.min_m)


def _vehicle_dirs(m: Mission, path: Path | None) -> list[Path | None]:
    """Write the fleet as flown (``mission.toml``) and make each vehicle's ``vehicle-<id>/`` (None: no files)."""
    if path is None:
        return [None] * len(m.vehicles)
    write_text_atomic(path / "mission.toml", dump_toml(m.to_dict()))
    dirs = [path / f"vehicle-{v.id}" for v in m.vehicles]
    for d in dirs:
        d.mkdir(exist_ok=True)  # (an overwritten one may keep a user's files)
    return list(dirs)


def _finish(m: Mission, path: Path | None, runs: list[Run], watch: Watch, summary: dict[str, Any],
            plots: bool) -> None:
    """Write the fleet's ``summary.json`` and its figures (every vehicle) into ``path``."""
    if path is None:
        return
    write_json_atomic(path / "summary.json", summary)
    if plots:
        from bridge.record.fleetplots import fleet_plots  # lazy: loads matplotlib

        fleet_plots([r.trace for r in runs], watch.ids, watch.radii, watch.min_m, path / "plots", m.name)


def _fly_together(steps: list[Generator[Step, str | None, Run]], starts: list[Sequence[float]],
                  rate: float, watch: Watch) -> tuple[list[Run], Untold, bool]:
    """Step every vehicle's flight once a control step until all have ended; judge the world after each step (a
    vehicle flying alone, :class:`~bridge.loop.Alone`, judged but told nothing: :class:`Untold`). A stop ends every
    flight (each recorded); True if no flight took it (it came as the last were judged:
    :func:`bridge.loop.recorded_run`)."""
    n = len(steps)
    runs: list[Run | None] = [None] * n
    positions: list[Sequence[float]] = list(starts)
    told: list[str | None] = [None] * n  # a contact to tell each vehicle at its next step
    untold = Untold(watch.ids, rate)
    for a, b, why in watch.check(0.0, positions):
        told[a] = told[b] = why
    live = list(range(n))
    k = 0
    pending = False  # a stop that no flight took
    try:
        while live:
            for i in turn_order(live, k):  # who goes first this step (TURNS): on one radio, the first in its queue
                try:
                    X = steps[i].send(told[i]) if k else next(steps[i])
                    if isinstance(X, Alone):
                        untold.flew(i, k)
                        X = X.state
                    positions[i] = (X[0], X[2], X[4])
                except StopIteration as done:
                    runs[i] = done.value
                    live.remove(i)
                    if done.value.outcome == "aborted":  # Ctrl-C in one vehicle's step: every vehicle stops
                        raise KeyboardInterrupt from None
                except KeyboardInterrupt as stop:
                    if getgeneratorstate(steps[i]) == GEN_CLOSED:  # raised by the flight: recorded (a stop held as
                        live.remove(i)  # it was judged: its run kept) or not started yet (none)
                        runs[i] = recorded_run(stop)
                    raise
            k += 1
            for a, b, why in untold.told(k, watch.check(k / rate, positions)):
                for i in (a, b):
                    if i in live:
                        told[i] = why
    except KeyboardInterrupt:
        for i in list(live):
            try:
                steps[i].throw(KeyboardInterrupt)
            except StopIteration as done:
                runs[i] = done.value
            except KeyboardInterrupt as again:  # another stop as it was judged (its run kept), or not started yet
                runs[i] = recorded_run(again)  # (interrupted within the first step: nothing recorded)
        if any(r is None for r in runs):
            raise
        # taken by a flight (aborted) it is the fleet's end; else it came as the last flights were judged (each
        # recorded whole, as it ended): raised once the fleet's record is written, as one flight's is
        pending = not any(r.outcome == "aborted" for r in runs)  # type: ignore[union-attr]
    except BaseException:
        for s in steps:
            s.close()  # each closes its record
        raise
    return runs, untold, pending  # type: ignore[return-value]


def fleet_summary(m: Mission, flights: list[Flight], runs: list[Run], watch: Watch,
                  clock: str = "offline", instance: int = 0) -> dict[str, Any]:
    """The fleet's ``summary.json``: the worst outcome decides; vehicle i's system id ``instance`` + i (PX4's);
    ``duration_s`` the longest any vehicle flew (each one's time flown: bridge.record.metrics), not the mission's
    (``mission_duration_s``, as one vehicle's summary has it)."""
    rank = {o: i for i, o in enumerate(SEVERITY)}
    vehicles = []
    policies = [watch.verdict()]
    for v, f, r in zip(m.vehicles, flights, runs):
        s = r.summary
        vehicles.append({"id": v.id, "sysid": instance + v.id, "dir": f"vehicle-{v.id}", "outcome": s["outcome"],
                         "ok": run_ok(s), "rms_3d": s.get("rms_3d"), "profile": f.profile.name,
                         "controller": f.mission.controller, "seed": f.mission.seed, "offset": list(v.offset),
                         "trajectory": "own" if v.trajectory is not None else "the mission's",
                         "start": list(f.mission.start), "ended_by": s.get("ended_by"),
                         **({"contact": s["contact"]} if "contact" in s else {}),
                         "link": {**{d: {k: (s.get("link") or {}).get(d, {}).get(k) for k in LINK_FIGURES}
                                     for d in ("up", "down")},
                                  **{k: v for k, v in (s.get("link") or {}).items() if k == "jitter_capped"}}})
        policies += [{**p, "name": f"{p['name']} (vehicle {v.id})"} for p in s.get("policies") or ()
                     if not p.get("ok")]
    worst = max((x["outcome"] for x in vehicles), key=lambda o: rank.get(o, len(SEVERITY)))
    rms = [x["rms_3d"] for x in vehicles if x["rms_3d"] is not None]
    flown = [r.summary.get("duration_s") for r in runs]
    return {"mission": m.name, "clock": clock, "rate_hz": m.rate_hz,
            "duration_s": max((d for d in flown if d is not None), default=0.0),
            "mission_duration_s": float(m.duration_s),  # as asked (a fleet whose every vehicle ended early flew less)
            "controller": m.controller, "profile": m.profile, "outcome": worst, "rms_3d": max(rms) if rms else None,
            "vehicles": vehicles, "separation": watch.summary(), "policies": policies}


# -- the same fleet as SITL sessions (bsst sitl --vehicles) ---------------------------------------------------
@reads_inputs
def sitl(mission: Mission | str | Path | None, *, vehicles: int | Sequence[Any] | None = None,
         formation: str | None = None, out: str | Path | None = None, write: bool = False, overwrite: bool = False,
         plots: bool = True, realtime: bool = False, instance: int | None = 0, gcs: str | None = None,
         speed: float | None = None, key: str | Path | None = None, live: bool = False,
         progress: Progress | None = None, overrides: Overrides | None = None, await_mission: bool = False,
         **keywords: Any) -> Run | FleetRun:
    """Fly a mission as SITL: one vehicle as :func:`bridge.session.sitl` flies it (every keyword as there), or a
    fleet (``vehicles``, ``formation`` or the mission's ``[[vehicles]]``, as :func:`simulate` takes them) as one
    vehicle process and one controller process per vehicle (:mod:`bridge.session.fleet`): vehicle i is instance
    ``instance`` + i - 1, system id ``instance`` + i (PX4's), every vehicle's ground-station traffic goes to ``gcs``
    (default 127.0.0.1:14550 + ``instance``; ``live``: each vehicle's line saying so); ``progress`` is one vehicle's.
    In lockstep the vehicles step on one shared clock; a contact ends both flights at its step (``collision``), as
    offline; the world is judged on the vehicles' traces (and where each stayed) at matching steps
    (:func:`~bridge.record.separation.judge_traces`), and on the rows a vehicle flew on the wall clock after it left
    the shared clock (a ground station's mode, its controller lost), said in the summary
    (:mod:`bridge.record.wallclock`). In real time a contact makes both ``collision`` too, found
    afterwards (the flights went on: :data:`~bridge.record.separation.CONTINUED`); a vehicle a ground station takes
    over flies on under it, recorded, judged on its record, said (``separation.taken_over``)."""
    from bridge.core.clock import lockstep_pace  # lazy: start-up time
    from bridge.session import sitl as sitl_one  # lazy: start-up time
    from bridge.session.fleet import check_fleet, fleet_instances, fly_sessions, radio_block  # lazy: start-up

    given = Overrides.of(overrides, **keywords)
    given_link = given.link or {}
    m = mission if isinstance(mission, Mission) or mission is None else None
    if await_mission or mission is None:  # a ground station's mission (bsst sitl --await-mission): one vehicle
        if vehicles is not None or formation is not None:
            flag = f"--vehicles {vehicles}" if vehicles is not None else f"--formation {formation}"
            raise ConfigError(f"{flag} with --await-mission: a ground station's mission flies one vehicle"[:300])
        fleet = None
    else:
        if m is None:  # loaded once: the session flies this one
            m = load_mission(mission, trace_cap(given.rate_hz))
        fleet = fleet_mission(m, vehicles, formation)
        given_link = merge_link_tables(m.link, given_link)
    shared = given_link.get("shared") is True and fleet is not None  # one vehicle: its own radio, the same link
    if fleet is None:
        return sitl_one(m if m is not None else mission, out=out, write=write, overwrite=overwrite, plots=plots,
                        realtime=realtime, instance=instance, gcs=gcs, speed=speed, key=key, live=live,
                        progress=progress, overrides=overrides, **({"await_mission": True} if await_mission else {}),
                        **keywords)
    over = Overrides.of(overrides, **keywords)
    flights = fleet_flights(fleet, over)
    check_fleet_steps(fleet, flights)
    check_fleet_starts(fleet, flights, vehicles, formation)
    if any("MAV_SYS_ID" in f.mission.params for f in flights):  # (its vehicle process refused it, files written)
        where = "--param MAV_SYS_ID" if "MAV_SYS_ID" in (given.params or {}) else f"{fleet.source}: params.MAV_SYS_ID"
        raise ConfigError(f"{where}: a fleet's vehicles take PX4's system ids from their instances (vehicle i of "
                          "--instance B is system B + i): give --instance, not MAV_SYS_ID")
    if shared:  # a handover on one radio is refused, as offline (before a port is checked or a directory touched)
        shared_radios(fleet, flights, over)
    gcs_text = check_fleet(len(flights), realtime=realtime, instance=instance, gcs=gcs, speed=speed, key=key)
    speed = lockstep_pace(speed, realtime=realtime, await_mission=False)
    keep = out is not None or write
    if keep:  # a refused run directory is named before a busy port (both before anything starts)
        run_dir(out, fleet.name, overwrite, create=False)
        check_out_free(out)  # another run writing it now
    with fleet_instances(len(flights), instance), out_held(out):  # both for the fleet's life
        path = run_dir(out, fleet.name, overwrite) if keep else Path(tempfile.mkdtemp(prefix="bsst-sitl-fleet-"))
        try:
            fm = over.laid_over(fleet)
            dirs = [d for d in _vehicle_dirs(fm, path) if d is not None]
            ids = [v.id for v in fm.vehicles]
            watch = _watch(fm, flights)
            clocked = not realtime  # lockstep: one shared step clock (bridge.nodes.vehicle.gate)
            runs = fly_sessions(flights, ids, dirs, realtime=realtime, instance=instance, gcs=gcs_text, speed=speed,
                                key=Path(key) if key is not None else None, plots=plots, keep=keep,
                                radii=watch.radii if clocked else None, shared_radio=shared, announce=live)
            rec = clocked_records(runs, ids, fm.rate_hz) if clocked else taken_over_records(runs, ids, fm.rate_hz)
            contacts = judge_traces(watch, [r.trace for r in runs], fm.rate_hz, rec.finals,
                                    [f.mission.start for f in flights] if clocked else None, rec.afters, rec.walls,
                                    own_clocks=not clocked)
            runs = [_touched(r, contacts.get(j)) for j, r in enumerate(runs)]
            summary = fleet_summary(fm, flights, runs, watch, "realtime" if realtime else "lockstep", instance or 0)
            if rec.flown:  # a vehicle flew on: lockstep, on the wall clock; real time, under a ground station
                judged_on_wall_clock(summary, rec, *(() if clocked else ("taken_over", REALTIME)))
            if shared:
                summary["radio"] = radio_block(ids, flights, runs, realtime)
            summary["sitl"] = {"instances": None if instance is None else list(range(instance, instance + len(ids))),
                               "gcs": gcs_text, "sysids": [(instance or 0) + i for i in ids], "shared_clock": clocked,
                               "signed": key is not None}
            if clocked:
                summary["sitl"]["gate"] = {str(i): (r.summary.get("sitl") or {}).get("gate") for i, r in zip(ids, runs)}
            if contacts and not clocked:
                summary["sitl"]["note"] = CONTINUED
            elif any(c.get("continued") for c in contacts.values()):
                summary["sitl"]["note"] = WALL_CLOCK
            _finish(fm, path if keep else None, runs, watch, summary, plots)
            return FleetRun(runs, summary, path if keep else None)
        finally:
            if not keep:
                shutil.rmtree(path, ignore_errors=True)


def _touched(run: Run, contact: dict[str, Any] | None) -> Run:
    """``run`` with the outcome ``collision`` and its ``contact`` when another vehicle touched it (its own
    ``summary.json`` in ``vehicle-<id>/`` stays as its session wrote it: the flight as flown, on past the contact)."""
    if contact is None:
        return run
    return Run(run.trace, {**run.summary, "outcome": "collision", "contact": contact}, run.path, run.after)
