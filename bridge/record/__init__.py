"""The files of a run: columns, writers, the SITL joiner, metrics and figures. No sockets.

- :mod:`bridge.record.columns`  every record's columns (trace.csv, vehicle.bin, controller.bin)
- :mod:`bridge.record.runlog`   run directory, line writers, atomic writes, :class:`~bridge.record.runlog.Run`
- :mod:`bridge.record.joiner`   vehicle.bin + controller.bin -> trace.csv rows, by column name
- :mod:`bridge.record.metrics`  RMS, settling, finite-time bound, total variation, the summary
- :mod:`bridge.record.events`   a run's events, typed, with their sender as a field
- :mod:`bridge.record.missionclock`  a session's events on the mission's clock, the vehicle's met at its time 0
- :mod:`bridge.record.summary`  a SITL session's summary.json as pure functions of what the session saw
- :mod:`bridge.record.policies` the safety policies checked over every run
- :mod:`bridge.record.plots`    the paper-style figures
- :mod:`bridge.record.linkextract`  a link's trace from a run directory or two tlogs
- :mod:`bridge.record.tlogmatch`    tlog frames, and one link's packets matched between its two ends
- :mod:`bridge.record.linkplots`    a link trace's figure
"""
