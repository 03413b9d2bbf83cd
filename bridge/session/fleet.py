"""Several SITL sessions at once: one vehicle process and one controller process per vehicle (``bsst sitl --vehicles``).

In:  each vehicle's prepared :class:`~bridge.core.flight.Flight` with its id (1..N; system id B + id), directory, the
     fleet's options: clock (lockstep or real time), first instance B (0-9, or None: free ports), the one
     ground-station address every vehicle sends to (``HOST:PORT``, or None), ``speed`` (x real time), a signing
     key file
Out: each vehicle's :class:`~bridge.record.runlog.Run` (its own ``trace.csv``, tlogs, ``summary.json`` in its
     directory), in the order given

Each vehicle is one :class:`~bridge.session.session.Session` (the single vehicle's, unchanged), run in a thread of
this process: vehicle i is PX4's instance B + i - 1 (its controller link on 127.0.0.1:14560 + B + i - 1), with PX4's
system id for it, B + i (free ports: i), and every vehicle's ground-station traffic goes to the one address, so a
ground station there sees N systems. In lockstep the vehicles step on one shared clock (given the vehicles' disc
radii, m): each vehicle's gate file (``vehicle-<id>/gate.json``: every vehicle's id, disc radius and gate port)
makes its vehicle wait, after each step, for every other vehicle to fly it, and end its flight ``collision`` at the
step it touches another (:mod:`bridge.nodes.vehicle.gate`); each controller then waits up to
:data:`~bridge.session.children.READY_TIMEOUT_S` for the mission's second state, since the first step waits for the
slowest vehicle to start, and up to :data:`~bridge.nodes.vehicle.gate.STATE_WAIT_S` for each state after, since
its vehicle waits at its gate up to :data:`~bridge.nodes.vehicle.gate.SILENT_S` for a silent one. A vehicle whose
process ends (killed, crashed, stopped by its session) is said gone to the others' gates at once, from its gate port
(:func:`~bridge.nodes.vehicle.gate.say_lost`), and they fly on; one frozen (its controller hears nothing from it)
is killed by its session at once and said gone so (:mod:`bridge.session.alone`). A vehicle a ground station
takes over (HOLD, TAKEOFF, ...) leaves the shared clock and flies on under it, on the wall clock, recorded, while a
vehicle not taken over still flies and until its record holds as many steps as theirs (a single vehicle's session
stops it at once); the fleet judges that record afterwards (:mod:`bridge.record.wallclock`). In real time each pair
keeps its own wall clock, a vehicle taken over flies on under its ground station the same way (its session's
``sitl.flew_on``), and the shared world is judged afterwards on their traces (:mod:`bridge.swarm`). Ctrl-C or SIGTERM
stops every pair (each session's own stop: SIGTERM, then SIGKILL at its deadline) and each still writes its summary.
"""

from __future__ import annotations

import contextlib
import functools
import os
import socket
import tempfile
import threading
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from bridge.autopilot.estimator import compile_estimator
from bridge.core.flight import Flight
from bridge.link.radio import make_radio_file, occupancy_of_parts
from bridge.link.turns import TURNS
from bridge.mavlink.endpoint import LINK_PORT, parse_address
from bridge.mavlink.signing import key_from_file
from bridge.nodes.forkserver import warm
from bridge.record.runlog import Run, blackout_windows, finish_run
from bridge.session import check_options
from bridge.session.children import READY_TIMEOUT_S, catch_stop_signals, check_port_free, free_udp_port, hold_instances
from bridge.session.session import Session
from params import ConfigError

if TYPE_CHECKING:
    from bridge.nodes.vehicle.gate import GateConfig

MAX_INSTANCE = 9  # instances 0-9, as bridge.session.children.instance_slot holds them
ARRIVAL = ("first come, first served on the wall clock: each vehicle's relay puts its packets in the one queue as "
           "they arrive")


def check_fleet(count: int, *, realtime: bool, instance: int | None, gcs: str | None, speed: float | None,
                key: str | Path | None) -> str | None:
    """Check a fleet's options as :func:`bridge.session.sitl` checks one session's (ConfigError naming the flag,
    before anything starts): the key file, the clock and pace, instances B..B + N - 1 within 0-9; the one
    ground-station address every vehicle sends to (``gcs``, else 127.0.0.1:14550 + B; None: none)."""
    if key is not None:
        key_from_file(key)
    gcs_text = check_options(realtime=realtime, instance=instance, gcs=gcs, speed=speed)
    if count > 1 and gcs_text is not None and parse_address(gcs_text, "udpout", "--gcs").mode == "udpin":
        # each vehicle would bind that one port: the second met its neighbour there, after the first had started
        raise ConfigError(f"--gcs {gcs_text}: a fleet's vehicles all send to the one --gcs address, so it cannot be "
                          f"bound (udpin: or udp:) by each of {count} vehicles; give HOST:PORT (udpout, where the "
                          "ground station listens)")
    if instance is None:
        return gcs_text
    last = instance + count - 1
    if last > MAX_INSTANCE:
        room = MAX_INSTANCE + 1 - instance
        raise ConfigError(f"--vehicles {count} from --instance {instance}: vehicle i is instance {instance} + i - 1, "
                          f"up to instance {last}; instances are 0-{MAX_INSTANCE}: fly at most "
                          f"{room} vehicle{'s' if room != 1 else ''} from this instance")
    return gcs_text


@contextlib.contextmanager
def fleet_instances(count: int, instance: int | None) -> Iterator[None]:
    """Hold a fleet's instances B..B + N - 1 for the block (the fleet's life: :func:`hold_instances`), and refuse,
    before anything is written, one another session holds or whose controller port (14560 + B + i - 1) is taken."""
    numbers = range(instance, instance + count) if instance is not None else range(0)
    with hold_instances(numbers, lambda n: f"--instance {instance} (vehicle {n - numbers.start + 1})"):
        for n in numbers:
            check_port_free(LINK_PORT + n, f"--instance {instance} (vehicle {n - numbers.start + 1})")
        yield


def fly_sessions(flights: Sequence[Flight], ids: Sequence[int], dirs: Sequence[Path], *, realtime: bool,
                 instance: int | None, gcs: str | None, speed: float | None, key: Path | None, plots: bool,
                 keep: bool, radii: Sequence[float] | None = None, shared_radio: bool = False,
                 announce: bool = False) -> list[Run]:
    """Fly every vehicle's session at once (the module's docstring); each vehicle's :class:`Run`, in order.
    ``radii`` (m, each vehicle's disc), in lockstep: on one shared clock. ``shared_radio``: the fleet's one radio
    (a file in the temporary directory, :func:`bridge.link.radio.make_radio_file`, removed after), vehicle j (from
    0) its user j: in real time through its relay; in lockstep its vehicle (by its gate file) and its controller
    (``--radio``) take turns on it (:mod:`bridge.link.turns`). ``announce``: each session says on stderr, once its
    vehicle is up, where a ground station connects. A session that fails to start (bad input, a child dead at
    start) stops the others; its error is raised."""
    with _radio_file(len(flights)) if shared_radio else contextlib.nullcontext() as radio:
        return _fly(flights, ids, dirs, realtime=realtime, instance=instance, gcs=gcs, speed=speed, key=key,
                    plots=plots, keep=keep, radii=radii, radio=radio, announce=announce)


@contextlib.contextmanager
def _radio_file(users: int) -> Iterator[Path]:
    """A fresh radio file for ``users`` vehicles in the temporary directory, removed after."""
    fd, name = tempfile.mkstemp(prefix="bsst-radio-")
    os.close(fd)
    try:
        make_radio_file(name, users)
        yield Path(name)
    finally:
        os.unlink(name)


def radio_block(ids: Sequence[int], flights: Sequence[Flight], runs: Sequence[Run], realtime: bool) -> dict[str, Any]:
    """A SITL fleet's ``summary.json["radio"]``: each direction's occupancy of the one radio, from every
    vehicle's part of it (in its ``summary.json["link"]["radio"]``: its relay's in real time; in lockstep its
    vehicle's, up, and its controller's, down), as offline's (:func:`bridge.link.radio.occupancy_of_parts`; in
    lockstep over the steps flown, as offline). In lockstep a state that entered out of turn (a controller that
    waited :data:`~bridge.nodes.offboard.radioturn.TURN_WAIT_S` for another) is listed: that flight is not the
    offline one."""
    link = flights[0].link
    parts = [(r.summary.get("link") or {}).get("radio") or {} for r in runs]
    until = None if realtime else max(len(r.trace["t"]) for r in runs) / flights[0].mission.rate_hz
    out = {"shared": True, "order": ARRIVAL if realtime else TURNS,
           **{d: occupancy_of_parts([p.get(d) for p in parts], ids, cfg.rate_bps, cfg.queue_ms / 1000.0, until)
              for d, cfg in (("up", link.up), ("down", link.down))}}
    if not realtime:
        out["late_turns"] = {str(i): (p.get("down") or {}).get("late_turns", []) for i, p in zip(ids, parts)}
    return out


def _fly(flights: Sequence[Flight], ids: Sequence[int], dirs: Sequence[Path], *, realtime: bool,
         instance: int | None, gcs: str | None, speed: float | None, key: Path | None, plots: bool,
         keep: bool, radii: Sequence[float] | None, radio: Path | None, announce: bool) -> list[Run]:
    """:func:`fly_sessions`, ``radio`` the fleet's one radio file (None: each link its own)."""
    forked = warm()  # the fork server's imports (bridge.nodes.forkserver) overlap what follows
    if not forked:  # (forked: the server loads them before it forks a child that flies them)
        for f in flights:
            compile_estimator(f.estimator)  # a first EKF on this machine compiles here, once, before any child starts
    gates: list[Path | None] = [None] * len(flights)
    cfgs: list[GateConfig] = []
    if radii is not None and not realtime and len(flights) > 1:
        from bridge.nodes.vehicle.gate import GateConfig  # lazy: a lockstep fleet's (the vehicle's code, ~0.03 CPU-s)

        ports = tuple(free_udp_port() for _ in flights)
        for j, d in enumerate(dirs):
            gates[j] = d / "gate.json"
            cfgs.append(GateConfig(j, tuple(ids), tuple(radii), ports, str(radio) if radio is not None else None))
            cfgs[j].dump(gates[j])
    sessions = [Session(f, d, realtime=realtime, instance=None if instance is None else instance + i - 1,
                        gcs=gcs, speed=speed, progress=None, live=False, key=key, sysid=(instance or 0) + i, gate=g,
                        start_timeout=READY_TIMEOUT_S if g is not None else None,
                        radio=(radio, j) if radio is not None else None, announce=announce,
                        label=f"vehicle {i}" if len(flights) > 1 else None)
                for j, (f, i, d, g) in enumerate(zip(flights, ids, dirs, gates))]
    runs: list[Run | None] = [None] * len(sessions)
    errors: list[BaseException] = []
    if len(sessions) > 1:  # a vehicle taken over by a ground station flies on while the others fly
        for j, s in enumerate(sessions):
            s.flies_on = functools.partial(_flies_on, sessions, runs, j)
    held: list[socket.socket] = []  # the gate ports of vehicles gone, held until the fleet is over
    for s, cfg in zip(sessions, cfgs):  # its process ended: the others fly on without waiting for it
        s.vehicle_ended = functools.partial(_lost, cfg, held)

    def fly(j: int) -> None:
        try:
            runs[j] = sessions[j].run(plots=False, keep=keep)  # the figures after: matplotlib is not thread-safe
        except BaseException as exc:  # noqa: BLE001  (raised in the caller's thread, after every session stopped)
            errors.append(exc)
            for s in sessions:
                s.interrupted = True

    threads = [threading.Thread(target=fly, args=(j,), name=f"vehicle-{ids[j]}", daemon=True)
               for j in range(len(sessions))]
    restore = catch_stop_signals(sessions)
    try:
        for t in threads:
            t.start()
        for t in threads:
            while t.is_alive():
                t.join(0.2)
    finally:
        restore()
        for sock in held:
            sock.close()
    if errors:
        raise errors[0]
    done: list[Run] = [r for r in runs if r is not None]
    if keep and plots:
        for f, r in zip(flights, done):
            if r.path is not None and r.summary.get("outcome") != "aborted":
                m = f.mission
                title = f"{m.name} ({m.controller}, {f.profile.name}, SITL {r.summary['clock']})"
                finish_run(r.path, r.trace, r.summary, title, True, blackout_windows(m))
    return done


def _lost(cfg: GateConfig, held: list[socket.socket], frozen: bool) -> None:
    """Vehicle ``cfg.index``'s process has ended (``frozen``: its session killed it so): the other gates are told
    (:func:`say_lost`); its port held."""
    from bridge.nodes.vehicle.gate import say_lost  # lazy: as GateConfig in _fly

    sock = say_lost(cfg, frozen)
    if sock is not None:
        held.append(sock)


def _recorded(s: Session) -> int:
    """The steps a session's record holds so far (its trace's rows and its end action's)."""
    joiner = getattr(s, "joiner", None)
    return 0 if joiner is None else len(joiner.rows) + len(joiner.after_at)


def _flies_on(sessions: Sequence[Session], runs: Sequence[Run | None], j: int) -> bool:
    """Whether vehicle j (index), taken over by a ground station, flies on under it: while a vehicle not taken over
    still flies, and until its record holds as many steps as the longest of theirs (the judge matches rows by
    step: bridge.record.wallclock). Else its session stops it, as a single vehicle's does."""
    others = [i for i in range(len(sessions)) if i != j and not sessions[i].flying_on]
    if sessions[j].diverged:  # (its plant halted: nothing more to record)
        return False
    if any(runs[i] is None for i in others):
        return True
    return _recorded(sessions[j]) < max((_recorded(sessions[i]) for i in others), default=0)
