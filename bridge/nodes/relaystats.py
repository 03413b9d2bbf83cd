"""A relay's counters copied at one moment, and their snapshots written to disk away from its serving loop.

In:  a copy of :class:`bridge.nodes.relay.Relay`'s counters: each direction's
     :class:`~bridge.link.impairment.LinkStats`, the delays it really added (us, ``array``), its fixed figures
     (counts, client, refusals, radio), its CPU time (s)
Out: :meth:`RelayCounters.summary`, ``relay.json``'s content (``measured_ms`` percentiles in ms, ``cpu_us_per_packet``
     us, ``final``); :class:`SnapshotWriter`, which writes the newest copy handed to it atomically from a thread of
     its own (the relay's module docstring, "Records that survive a kill")
"""

from __future__ import annotations

import threading
from array import array
from pathlib import Path
from typing import Any

from bridge.link.impairment import LinkStats
from bridge.link.radio import finished_part


class RelayCounters:
    """A copy of a relay's counters at one moment, turned into its summary away from the serving loop."""

    def __init__(self, stats: dict[str, LinkStats], added: dict[str, array], fixed: dict[str, Any],
                 cpu_user_s: float, cpu_sys_s: float) -> None:
        self.stats, self.added, self.fixed = stats, added, fixed
        self.cpu_user_s, self.cpu_sys_s = cpu_user_s, cpu_sys_s

    def summary(self, final: bool) -> dict[str, Any]:
        from bridge.record.metrics import percentiles  # loads numpy: not needed while relaying

        out: dict[str, Any] = {}
        for d, st in self.stats.items():
            s = st.summary()
            s["measured_ms"] = percentiles(self.added[d], 1000.0, empty=None)
            out[d] = s
        out.update(self.fixed)
        if "radio" in out:
            out["radio"] = {d: finished_part(p) for d, p in out["radio"].items()}
        cpu = self.cpu_user_s + self.cpu_sys_s
        forwarded = self.fixed["forwarded"]
        out["cpu_s"] = cpu
        out["cpu_user_s"] = self.cpu_user_s
        out["cpu_sys_s"] = self.cpu_sys_s
        out["cpu_us_per_packet"] = 1e6 * cpu / forwarded if forwarded else None
        out["final"] = final
        return out


class SnapshotWriter:
    """Writes the newest :class:`RelayCounters` handed to it to ``path`` atomically, from its own thread (the
    summary's percentiles and the file's write stay out of the serving loop)."""

    def __init__(self, path: Path) -> None:
        from bridge.record.runlog import write_json_atomic  # lazy: start-up time, and only a relay with --stats writes

        self._write = write_json_atomic
        self.path = path
        self._cond = threading.Condition()
        self._pending: RelayCounters | None = None
        self._closing = False
        self._thread = threading.Thread(target=self._run, name="bsst-relay-stats", daemon=True)
        self._thread.start()

    def put(self, counters: RelayCounters) -> None:
        with self._cond:
            self._pending = counters
            self._cond.notify()

    def close(self) -> None:
        """Write what is pending, then stop the thread (the final record is the owner's, after this)."""
        with self._cond:
            self._closing = True
            self._cond.notify()
        self._thread.join()

    def _run(self) -> None:
        while True:
            with self._cond:
                while self._pending is None and not self._closing:
                    self._cond.wait()
                counters, self._pending = self._pending, None
                closing = self._closing
            if counters is not None:
                try:
                    self._write(self.path, counters.summary(final=False))
                except OSError:
                    pass  # the owner's final write says so, by name
            if closing and self._pending is None:
                return
