"""The children's command lines of one SITL session: the vehicle's, the relay's, the controller's.

In:  the session's options (:class:`Commands`: the run directory, clock, GCS address, system id, speed x real time,
     --await-mission, a fleet's gate file and radio, the controller's start timeout in s, the scheduled parameter
     changes, the signing key file) and the ports :meth:`bridge.session.session.Session._start` chose (UDP, 127.0.0.1)
Out: each child's ``bsst`` arguments (a list of str, after ``python -m bridge``), the key's flags included

Split out of :class:`~bridge.session.session.Session` (which starts, supervises and stops the children): what each
child is told is here, in one place, as plain data; no process is started and no port is chosen here.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bridge.autopilot.params import param_at_args
from bridge.session.children import READY_TIMEOUT_S


@dataclass(frozen=True)
class Commands:
    """What a session's children are told (the session's options, read once its ports are chosen)."""

    path: Path  # the run directory: both children's --out, and mission.toml (as flown) in it
    realtime: bool
    gcs: str | None
    sysid: int
    speed: float | None  # x real time (None: the clock's default)
    await_mission: bool
    gate: Path | None  # a lockstep fleet's shared clock: the vehicle's gate file
    start_timeout: float | None  # s: the controller's --start-timeout (None: its default)
    radio: tuple[Path, int] | None  # a fleet's one radio: its file, this vehicle's user
    param_changes: Any  # the flight's scheduled parameter changes (bridge.autopilot.params.param_at_args)
    key: Path | None  # the signing key file (its path only) both children get as --key

    @property
    def mission(self) -> str:
        return str(self.path / "mission.toml")

    def _key(self) -> list[str]:
        return ["--key", str(self.key)] if self.key is not None else []

    def radio_args(self) -> list[str]:
        """The flags for the fleet's one radio (none: the link's own radio)."""
        return ["--radio", str(self.radio[0]), "--radio-user", str(self.radio[1])] if self.radio else []

    def vehicle(self, listen: str, back: int) -> list[str]:
        """``bsst vehicle``: listening on ``listen``, hearing the controller's ids from 127.0.0.1:``back`` only."""
        argv = ["vehicle", self.mission, "--listen", listen, "--gcs", self.gcs or "none",
                "--sysid", str(self.sysid), "--realtime" if self.realtime else "--lockstep",
                "--controller-from", f"127.0.0.1:{back}", "--out", str(self.path), "--overwrite"]
        if self.speed is not None:
            argv += ["--speed", repr(self.speed)]
        elif not self.realtime:  # as fast as it goes, said: the vehicle's own default paces a ground station's mission
            argv += ["--speed", "0"]
        if self.await_mission:  # its start refuses what the controller would: past the trace kept, over before a change
            argv += ["--await-mission", "--trace-cap", *param_at_args(self.param_changes)]
        if self.gate is not None:  # a fleet: its processes outnumber the cores, so none polls before it sleeps
            argv += ["--gate", str(self.gate), "--spin", "0"]
        return argv + self._key()

    def relay(self, to: str, port: str, back: int, source: int) -> list[str]:
        """``bsst relay``: the link model on the wall clock, from 127.0.0.1:``to`` to the vehicle's ``port``, sending
        back from ``back`` to the controller's ``source`` port."""
        # no --overwrite: relay.json is a run file, so the run directory is new (or a fresh temporary one) or
        # was cleared (runlog.run_dir, clear_run); one there now is not this run's: refused, not replaced
        return ["relay", "--listen", f"127.0.0.1:{to}", "--to", f"127.0.0.1:{port}",
                "--back-port", str(back), "--client", f"127.0.0.1:{source}",
                "--mission", self.mission, "--mission-clock",
                "--stats", str(self.path / "relay.json"), *self.radio_args()]

    def controller(self, to: str, source: int) -> list[str]:
        """``bsst controller``: sending to 127.0.0.1:``to`` (the vehicle's, or the relay's) from ``source``."""
        # its wait for the vehicle's heartbeat now includes the vehicle's start-up: the session's budget for it
        argv = ["controller", self.mission, "--vehicle", f"127.0.0.1:{to}", "--target-sysid", str(self.sysid),
                "--source-port", str(source), "--timeout", f"{READY_TIMEOUT_S:g}", "--out", str(self.path),
                "--overwrite"]
        if self.realtime:
            argv.append("--realtime")
        if self.start_timeout is not None:
            argv += ["--start-timeout", repr(self.start_timeout), "--spin", "0"]
        if self.gate is not None:  # its vehicle may wait at its gate for a silent one (bridge.nodes.vehicle.gate)
            from bridge.nodes.vehicle.gate import STATE_WAIT_S  # lazy: a fleet's (the vehicle's code, ~0.03 CPU-s)

            argv += ["--state-timeout", repr(STATE_WAIT_S)]
        if not self.realtime:  # a lockstep fleet's one radio: the controllers' states queue on it (the vehicles':
            argv += self.radio_args()  # their commands, by their gate file)
        if self.await_mission:
            argv.append("--await-mission")
        argv += param_at_args(self.param_changes)
        return argv + self._key()
