"""Everything that connects a law to a plant; the only package that touches the network.

In:  a mission (a TOML file or a :class:`missions.Mission`) and its overrides (a frozen
     :class:`bridge.Overrides`, or its fields as keywords: profile, law, rate Hz, seed, a ``[link]``
     table, ...); for the nodes, UDP addresses and a signing key file
Out: a :class:`~bridge.record.runlog.Run` (trace arrays in SI units, ``summary.json`` as a dict, the
     run directory), MAVLink 2 over UDP between the nodes, sweep directories, ``bsst``'s exit status

Public names: :func:`bridge.simulate`, :func:`bridge.sitl` (a fleet too), :class:`bridge.Overrides` and
:class:`bridge.Run` (imported on first use), :func:`bridge.session.sitl`, :class:`bridge.sweep.Grid`,
:func:`bridge.sweep.sweep`.

The layers (docs/design.md, "Parts and layers"), listed lowest first. An arrow means "may import",
and a layer imports nothing above it (tests/test_layers.py checks it):
``cli -> sweep -> {session, loop} -> nodes -> {mavlink, record} -> core``.

- :mod:`bridge.core`: simulation time only, no sockets, no files

  - :mod:`bridge.core.flight`      a mission validated into the parts that fly it (the one path)
  - :mod:`bridge.autopilot.simvehicle`  plant + arming + timeout + failsafe, shared by every clock
  - :mod:`bridge.autopilot.failsafe`    level-and-descend failsafe
  - :mod:`bridge.link.model`        link impairment: one seeded model of a bad link, used by every clock
  - :mod:`bridge.link.ends`    the two ends of an impaired link in simulation time (offline, lockstep)
  - :mod:`bridge.core.wire`        frames NWU <-> NED / FRD, actuator normalisation, step stamps
  - :mod:`bridge.core.clock`       the real-time clocks: the vehicle's pace, the controller's fixed rate

- :mod:`bridge.mavlink`: bytes and sockets, no plant, no law

  - :mod:`bridge.mavlink.endpoint`   MAVLink 2 over UDP: an endpoint owning its socket, hot-path codec, tlogs
  - :mod:`bridge.mavlink.receive`    the one receive path of both endpoints: what is refused, how it is counted
  - :mod:`bridge.mavlink.signing`    MAVLink 2 message signing
  - :mod:`bridge.mavlink.telemetry`  what the vehicle tells a ground station, from the paper state

- :mod:`bridge.record`: the files of a run, no sockets

  - :mod:`bridge.record.columns`  every record's columns (trace.csv, vehicle.bin, controller.bin)
  - :mod:`bridge.record.runlog`   the run directory: trace, events, summary; :class:`~bridge.record.runlog.Run`
  - :mod:`bridge.record.joiner`   vehicle.bin + controller.bin -> trace.csv rows (SITL)
  - :mod:`bridge.record.metrics`  RMS, settling, finite-time bound, total variation, the summary
  - :mod:`bridge.record.events`   a run's events, typed, with their sender as a field
  - :mod:`bridge.record.summary`  a SITL session's summary.json, pure functions of what the session saw
  - :mod:`bridge.record.plots`    the paper-style figures

- :mod:`bridge.nodes`: one process each

  - :mod:`bridge.nodes.process`   report lines, stop signals and parent death for the child processes
  - :mod:`bridge.nodes.report`    the children's reports to the session: one JSON object a line, read in one place
  - :mod:`bridge.nodes.vehicle`   the simulated vehicle as a MAVLink endpoint (``bsst vehicle``)
  - :mod:`bridge.nodes.offboard`  the offboard controller as a MAVLink endpoint (``bsst controller``)
  - :mod:`bridge.nodes.relay`     a real-time UDP relay applying the link model on the wall clock (``bsst relay``)

- :mod:`bridge.loop`: the in-process closed loop (``bsst sim``), :func:`~bridge.loop.simulate`
- :mod:`bridge.swarm`: several vehicles in one world offline, :func:`bridge.simulate` (``vehicles=``)
- :mod:`bridge.session`: the SITL session launcher (``bsst sitl``), :func:`~bridge.session.sitl`

  - :mod:`bridge.session.session`   the session: start, supervise and stop the children, summarise
  - :mod:`bridge.session.children`  the child processes and the instance lock

- :mod:`bridge.sweep`: latency and dropout campaigns (``bsst sweep``)

  - :mod:`bridge.sweep.grid`       axes, their ranges, grid and cells
  - :mod:`bridge.sweep.spec`       a campaign as one value, and the sweep TOML file
  - :mod:`bridge.sweep.cells`      ``cells.csv``: columns, rows, the file
  - :mod:`bridge.sweep.classes`    the class of a cell: thresholds and rules
  - :mod:`bridge.sweep.executors`  process pool, Dask, progress bar
  - :mod:`bridge.sweep.campaign`   a campaign from start to end
  - :mod:`bridge.sweep.report`     a sweep's report: tables, heat maps (``bsst report``)

- :mod:`bridge.cli`: ``bsst`` (the parser, the flags, one module per command family); nothing imports it
"""

from typing import Any

__all__ = ["Overrides", "Run", "simulate", "sitl"]


def __getattr__(name: str) -> Any:
    # imported on first use, so that ``bsst --help`` or a refused flag does not load the law
    if name == "simulate":  # one vehicle: bridge.loop.simulate, as it always flew; several: bridge.swarm
        from bridge.swarm import simulate  # lazy: start-up time

        return simulate
    if name == "sitl":  # one vehicle: bridge.session.sitl; several: bridge.swarm (a process pair per vehicle)
        from bridge.swarm import sitl  # lazy: start-up time

        return sitl
    if name == "Overrides":
        from bridge.core.overrides import Overrides  # lazy: start-up time

        return Overrides
    if name == "Run":
        from bridge.record.runlog import Run  # lazy: start-up time

        return Run
    raise AttributeError(f"module 'bridge' has no attribute {name!r}")
