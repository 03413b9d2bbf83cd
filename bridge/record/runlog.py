"""A run on disk (docs/design.md, "Files of a run"): directory, trace, events, summary (the tlogs are
:mod:`bridge.mavlink.endpoint`'s).

In:  trace rows (floats, :data:`~bridge.record.columns.TRACE_COLUMNS`), events (t s, kind, text), a
     summary dict, an ``--out`` path (or none: ``runs/<UTC time>-<mission>``)
Out: the run directory with ``trace.csv`` (repr floats), ``events.log`` (``t=<s> <kind>: <text>`` and, when
     the event names them, `` [by SENDER]`` and `` [SOURCE]``),
     ``summary.json`` (written atomically) and ``plots/``; a trace read back as numpy arrays; a
     :class:`Run`

Everything is written crash-safe: trace rows and events are appended as whole lines with
one ``os.write`` each batch (a SIGKILL leaves the file whole up to its last complete
row), and ``summary.json`` is written to a temporary name and renamed.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import time
from collections.abc import Iterable, Sequence
from dataclasses import replace
from pathlib import Path
from stat import S_ISDIR
from typing import Any

from bridge.autopilot.vehicleevents import Sender
from bridge.link.model import link_from_table
from bridge.record.columns import TRACE_COLUMNS
from missions import Mission
from missions.mission import name_problem
from missions.steps import StepCap
from params import ConfigError, dump_toml, inputs_read, look_up

MAX_TRACE_STEPS = 500_000  # control steps a run that keeps its trace for its summary may fly (see check_trace_steps)
TRACE_CAP = StepCap(MAX_TRACE_STEPS, "a run keeps in memory for its summary",
                    "fly longer with bsst vehicle and bsst controller, which stream their rows to disk")


def trace_cap(rate_hz: float | None = None) -> StepCap:
    """The cap of :func:`check_trace_steps` for a command that flies at ``rate_hz`` (an override; None: the
    mission's rate), to load a mission with (:func:`missions.load_mission`): a plan too long for it is refused
    before its trajectory is timed."""
    return replace(TRACE_CAP, rate_hz=rate_hz)


def check_trace_steps(mission: Mission) -> None:
    """Refuse a mission too long to keep its trace in memory, before anything starts.

    ``bsst sim``, ``bsst sitl`` and every sweep cell keep one row per control step (37 floats)
    to compute the summary, the sweep's columns and the plots at the end: about 0.6 KB a step
    offline and 1.6 KB in a session (measured), so :data:`MAX_TRACE_STEPS` steps (2000 s at
    250 Hz) stay under 1 GB. A longer flight is flown by ``bsst vehicle`` and ``bsst controller``,
    which write their rows to disk and hold none (the vehicle at rest flies 24 h).
    """
    why = TRACE_CAP.problem(mission.duration_s, mission.rate_hz)
    if why:
        raise ConfigError(f"{mission.source}: {why}")


def run_dir(
    out: str | Path | None, mission_name: str, overwrite: bool = False, root: str | Path = "runs", create: bool = True
) -> Path:
    """Create the run directory: ``out`` exactly, or ``runs/<UTC time>-<mission>``.

    Refuses a non-empty directory unless ``overwrite``, and one it cannot write into or create
    (:func:`check_out_dir`). With ``create=False`` it only checks
    (so a command can name every bad input before it starts anything). ``out`` is the user's own
    choice and taken as given; a mission name must be one safe path component
    (:func:`missions.mission.name_problem`), so the directory it names stays inside ``root``.
    """
    if out is None:
        why = name_problem(mission_name)
        if why:  # a Mission refuses such a name already; this is the one place it becomes a path
            raise ConfigError(f"mission name: {why}")
        stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime())
        path = Path(root) / f"{stamp}-{mission_name}"
        n = 1
        while path.exists():
            n += 1
            path = Path(root) / f"{stamp}-{mission_name}-{n}"
    elif isinstance(out, str | os.PathLike):
        path = Path(out)
    else:  # a Python caller's out=5: named, not os.fspath's bare TypeError
        raise TypeError(f"out: expected a directory's path, got {out!r}"[:200])
    check_out_dir(path)
    if path.is_dir() and any(path.iterdir()):
        if not overwrite:
            raise ConfigError(f"--out {path}: directory is not empty (use --overwrite to replace its run)")
        check_overwrite(path)
    if not create:
        return path
    if path.is_dir():
        clear_run(path)
    try:
        path.mkdir(parents=True, exist_ok=True)  # plots/ is made by the figures, when there are figures
    except OSError as exc:
        raise ConfigError(f"--out {path}: cannot create ({exc.strerror})") from None
    return path


# Every file (and the one directory) a run of ours writes into its directory, as glob patterns: the one
# table overwriting reads, so that an overwritten directory holds exactly one run and nothing of a user's is
# touched. The run itself (sim, sitl), its children, bsst link extract/show, a sweep, a margin, and the
# temporary names of write_text_atomic; a lockstep fleet's vehicle's gate file (bridge.session.fleet).
RUN_FILES = ("summary.json", "mission.toml", "trace.csv", "events.log", "vehicle.bin", "controller.bin",
             "vehicle.tlog", "controller.tlog", "vehicle.log", "controller.log", "relay.log", "relay.json",
             "link-trace.csv", "link-trace.png", "cells.csv", "sweep.json", "report.md", "map_*.png",
             "margin.json", "gate.json", ".*.tmp*")
PLOTS_DIR, PLOT_FILES = "plots", ("*.png", ".*.tmp*")  # plots/ and the figures in it
VEHICLE_DIRS = "vehicle-[0-9]*"  # a fleet's vehicles' own runs (bridge.swarm): each a run directory of its own


def _ours(p: Path, patterns: Sequence[str]) -> bool:
    return any(p.match(pat) for pat in patterns)


def run_entries(path: Path) -> list[Path]:
    """What ``--overwrite`` replaces in run directory ``path``, whatever each is: the entries named as a run's
    files (:data:`RUN_FILES`), the figures in ``plots/`` and, in a fleet's ``vehicle-<id>/``, theirs. A run's
    files are removed (:func:`clear_run`) and written anew under these names."""
    out = [p for p in sorted(path.iterdir()) if _ours(p, RUN_FILES)]
    plots = path / PLOTS_DIR
    if plots.is_dir() and not plots.is_symlink():
        out += [p for p in sorted(plots.iterdir()) if _ours(p, PLOT_FILES)]
    for d in sorted(path.glob(VEHICLE_DIRS)):
        if d.is_dir() and not d.is_symlink():
            out += run_entries(d)
    return out


def check_overwrite(path: Path) -> None:
    """Refuse an ``--overwrite`` of run directory ``path`` that would lose what is not a run's, before anything
    is removed: a file this command, or this API call, reads as input (:func:`params.inputs_read`, one command's
    or call's: :func:`params.input_scope`; its mission, link trace, profile, plan, controller plug-in, key ...)
    among those it replaces (:func:`run_entries`), or an entry of a
    run's name that is no run's file (a directory; a symbolic link, which a run would write through)."""
    inputs = inputs_read()
    entries = run_entries(path)
    for p in entries:
        given = inputs.get(os.path.realpath(p))
        if given is not None:
            raise ConfigError(f"{given}: an input of this command, which --overwrite would overwrite (--out {path}: "
                              f"{p.relative_to(path)}); move it out of {path}, or write the run elsewhere")
    check_replaceable(path, entries)


def check_replaceable(path: Path, entries: Iterable[Path], said: str | None = None, fix: str | None = None) -> None:
    """Refuse, before anything is written, an entry of ``path`` that a run would replace but that is no file a run
    wrote: a directory, a symbolic link (a run would write through it), anything not a regular file. ``said``
    names ``path`` in the message (default ``--out PATH``), ``fix`` what the user can do (default: move it away, or
    write the run elsewhere)."""
    for p in entries:
        kind = ("a symbolic link" if p.is_symlink() else "a directory" if p.is_dir()
                else None if p.is_file() else "not a regular file")
        if kind:
            raise ConfigError(f"{said or f'--out {path}'}: cannot replace {p.relative_to(path)}: it is {kind}, not a "
                              f"file a run wrote ({fix or 'move it away, or write the run elsewhere'})")


def foreign_files(path: Path) -> list[str]:
    """The names in run directory ``path`` no run of ours writes (:data:`RUN_FILES`), sorted; a user's
    files in ``plots/`` as ``plots/NAME``."""
    out = [p.name for p in path.iterdir() if not _ours(p, RUN_FILES) and p.name != PLOTS_DIR]
    plots = path / PLOTS_DIR
    if plots.is_dir() and not plots.is_symlink():
        out += [f"{PLOTS_DIR}/{p.name}" for p in plots.iterdir() if not _ours(p, PLOT_FILES)]
    elif plots.exists() or plots.is_symlink():
        out.append(PLOTS_DIR)
    return sorted(out)


def clear_run(path: Path) -> list[str]:
    """Remove the run in ``path`` (``--overwrite``): every file of :data:`RUN_FILES`, the figures in ``plots/``
    and ``plots/`` itself once empty; the summary first (until the new one is written whole there is none,
    never one of another run beside this run's files). Nothing else is touched: returns what was kept
    (:func:`foreign_files`), which the new run's ``events.log`` names. ConfigError if a file cannot go
    (:func:`check_overwrite` has refused, before, what is not a run's file)."""
    def remove(p: Path) -> None:
        try:
            p.unlink()
        except FileNotFoundError:
            pass
        except OSError as exc:
            raise ConfigError(f"--out {path}: cannot replace {p.name} ({exc.strerror})") from None

    remove(path / "summary.json")
    for p in sorted(path.iterdir()):
        if p.is_file() and not p.is_symlink() and _ours(p, RUN_FILES):
            remove(p)
    plots = path / PLOTS_DIR
    if plots.is_dir() and not plots.is_symlink():
        for p in plots.iterdir():
            if p.is_file() and _ours(p, PLOT_FILES):
                remove(p)
        if not any(plots.iterdir()):
            plots.rmdir()
    for p in sorted(path.glob(VEHICLE_DIRS)):  # a fleet's vehicles: their runs go too, a user's files stay
        if p.is_dir() and not p.is_symlink():
            clear_run(p)
            if not any(p.iterdir()):
                p.rmdir()
    return foreign_files(path)


class LineWriter:
    """Append whole lines to a file, in batches of ``batch`` lines, one write each."""

    def __init__(self, path: str | Path, header: str | None = None, batch: int = 50) -> None:
        self.path = Path(path)
        self._fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_APPEND, 0o644)
        self._pending: list[str] = []
        self._batch = batch
        if header is not None:
            os.write(self._fd, (header + "\n").encode())

    def write(self, line: str) -> None:
        self._pending.append(line)
        if len(self._pending) >= self._batch:
            self.flush()

    def flush(self) -> None:
        if self._pending and self._fd >= 0:
            os.write(self._fd, ("\n".join(self._pending) + "\n").encode())
            self._pending.clear()

    def close(self) -> None:
        if self._fd >= 0:
            self.flush()
            os.close(self._fd)
            self._fd = -1


class TraceWriter(LineWriter):
    """``trace.csv``: one row per control step, columns :data:`TRACE_COLUMNS` (repr floats)."""

    def __init__(self, path: str | Path, columns: Sequence[str] = TRACE_COLUMNS, batch: int = 50) -> None:
        super().__init__(path, ",".join(columns), batch)

    def row(self, values: Iterable[float]) -> None:
        self.write(",".join(map(repr, values)))


class EventLog(LineWriter):
    """``events.log``: one line per event, ``t=<s> <kind>: <text>[ [by SENDER]][ [SOURCE]]`` (``t=n/a``: no time
    known), flushed at once: for people (the sender is the event's field, :attr:`bridge.record.events.RunEvent.by`).

    Lines are appended as they are recorded, which in a session is as its children report (a controller's judgement
    stamped at its cause, the closing notes at the trace's last row, after the end action's lines; a stopped run's
    at its stop): a run stopped mid-way keeps them so. :meth:`close` rewrites the file in time order (atomically:
    the appended file, or the sorted one), as :func:`bridge.record.events.in_time_order` orders ``summary.json``'s
    events: stably, a line with no time after the one before it. Lines on a clock ahead of the mission's
    (:meth:`clock_moved`) are ordered on the mission's and keep their written times."""

    def __init__(self, path: str | Path) -> None:
        super().__init__(path, None, batch=1)
        self._order: list[tuple[float, str]] = []  # (the time ordered at, s on the mission's clock; the line)

    def event(self, t: float, kind: str, text: str, by: Sender | None = None, source: str | None = None) -> None:
        shown = text + (by.suffix if by is not None else "") + (f" [{source}]" if source is not None else "")
        if math.isfinite(t):  # (rounded to 1 us first, as summary.json's times: the same ms shown, the same ties)
            at = round(t, 6)
            line = f"t={at:.3f} {kind}: {shown}"
        else:  # (ordered after the line before it)
            at = self._order[-1][0] if self._order else -math.inf
            line = f"t=n/a {kind}: {shown}"
        self._order.append((at, line))
        self.write(line)

    def clock_moved(self, ahead_s: float) -> None:
        """The lines written so far are on a clock ``ahead_s`` s ahead of the mission's (the vehicle's, before the
        mission's time 0 was known: :mod:`bridge.record.missionclock`): ordered at their time less it."""
        self._order = [(round(at - ahead_s, 6), line) for at, line in self._order]

    def close(self) -> None:
        """Close the file, then put its lines in time order (unchanged if they are; left as appended if it cannot
        be rewritten: whole, in the order recorded)."""
        if self._fd < 0:
            return
        super().close()
        ordered = sorted(self._order, key=lambda x: x[0])  # (stable: a tie keeps the order recorded)
        if ordered != self._order:
            try:
                write_text_atomic(self.path, "".join(line + "\n" for _, line in ordered))
            except OSError:
                pass  # (the file as appended stays, whole)


class RunRecord:
    """The one writer of a run's record, for the offline loop and the SITL session alike:
    ``mission.toml`` as flown (atomically, before anything flies), ``trace.csv`` rows
    (:func:`bridge.record.columns.trace_row`) and ``events.log`` as the flight goes, and at
    the end ``summary.json`` (atomically) and the figures (:func:`finish_run`)."""

    def __init__(self, path: Path, mission: Mission) -> None:
        self.path = path
        self.mission = mission
        write_text_atomic(path / "mission.toml", dump_toml(mission.to_dict()))
        self.trace = TraceWriter(path / "trace.csv")
        self.events = EventLog(path / "events.log")
        kept = foreign_files(path)
        if kept:  # an overwritten directory: what was not ours stayed, and is named
            self.events.event(0.0, "note", f"kept in the run directory, not written by a run: {', '.join(kept)}")

    def close(self) -> None:
        """Flush and close the trace and the event log (what was written stays whole)."""
        try:
            self.trace.close()
        finally:
            self.events.close()

    def finish(self, trace: dict[str, Any], summary: dict[str, Any], title: str, plots: bool = True) -> None:
        finish_run(self.path, trace, summary, title, plots, blackout_windows(self.mission) if plots else ())


def write_json_atomic(path: str | Path, obj: Any) -> None:
    """Write JSON to ``path`` via a temporary file and rename: complete or absent."""
    write_text_atomic(path, json.dumps(obj, indent=2, allow_nan=False, default=_jsonable) + "\n")


def write_text_atomic(path: str | Path, text: str) -> None:
    """Write ``text`` to ``path`` via a temporary file (flushed to disk) and rename: whatever
    kills the process, ``path`` is the old file, the new one complete, or absent. A write or rename that fails
    removes the temporary file (it was left beside the run's files, ``.events.log.tmp<pid>``)."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    try:
        with open(tmp, "w", encoding="utf-8") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:  # (an interrupt too: only a kill leaves it)
        with contextlib.suppress(OSError):
            tmp.unlink(missing_ok=True)
        raise


def _jsonable(v: Any) -> Any:
    if hasattr(v, "item"):
        return v.item()
    raise TypeError(f"not JSON serialisable: {type(v).__name__}")


def read_trace(path: str | Path) -> dict[str, Any]:
    """Read a ``trace.csv`` back into numpy arrays by column, ignoring a torn last line."""
    with open(path, encoding="utf-8") as f:
        header = f.readline().strip().split(",")
        rows = []
        for line in f:
            if not line.endswith("\n"):
                break
            parts = line.rstrip("\n").split(",")
            if len(parts) != len(header):
                break
            rows.append([float(p) for p in parts])
    return trace_arrays(rows, header)


class Run:
    """The result of one flight, offline or networked: trace arrays, summary, directory; a session's ``after``: the
    true positions (m, x y z) of its end action's control periods after the mission's (a fleet judges them)."""

    def __init__(self, trace: dict[str, Any], summary: dict[str, Any], path: Path | None,
                 after: Sequence[tuple[float, float, float]] = ()) -> None:
        self.trace = trace
        self.summary = summary
        self.path = path
        self.after = after

    @property
    def outcome(self) -> str:
        return self.summary["outcome"]

    @property
    def rms(self) -> float | None:
        """3-D position RMS error (m) over t >= summary['rms_from_s']; None when it measured nothing (no row
        flown from then on, or not a finite number: a law that failed before, a flight that diverged)."""
        return self.summary["rms_3d"]

    def __repr__(self) -> str:
        return f"Run(outcome={self.outcome!r}, rms_3d={self.rms!r}, path={str(self.path) if self.path else None!r})"


def trace_arrays(rows: Sequence[Any], columns: Sequence[str] = TRACE_COLUMNS) -> dict[str, Any]:
    """Rows of the trace (a list of rows, or one flat ``array('d')`` of them end to end) -> numpy
    arrays by column name."""
    import numpy as np  # lazy: the nodes write lines and never need numpy

    arr = np.array(rows, dtype=float).reshape(-1, len(columns))
    return {name: arr[:, i] for i, name in enumerate(columns)}


def finish_run(path: Path, trace: dict[str, Any], summary: dict[str, Any], title: str, plots: bool = True,
               blackouts: Sequence[tuple[float, float]] = ()) -> None:
    """Write ``summary.json`` atomically, then the plots (a run without plots still has its numbers), with the
    link ``blackouts`` ((start s, duration s) windows) and the summary's failsafes marked."""
    write_json_atomic(path / "summary.json", summary)
    if plots and len(trace["t"]) > 1:
        from bridge.record.plots import make_plots, run_spans  # lazy: loads matplotlib

        spans = run_spans(summary.get("events", ()), blackouts, float(trace["t"][-1]))
        make_plots(trace, path / "plots", title, spans)


def blackout_windows(mission: Mission) -> list[tuple[float, float]]:
    """The link blackouts ``mission`` (as flown: its ``[link]`` with the overrides) scheduled, both directions:
    (start s, duration s) windows of mission time. Its ``[link]`` was validated before the flight; a trace or
    profile file it names that has changed since cannot be read again: then no windows (the figures go without)."""
    try:
        link = link_from_table(mission.link, mission.source, seed=mission.seed, duration_s=mission.duration_s)
    except (ConfigError, OSError):
        return []
    return [*link.up.blackouts, *link.down.blackouts]


def _nearest_existing(path: Path, flag: str) -> tuple[Path, os.stat_result]:
    """``path`` or its nearest ancestor that exists, and its ``stat`` (:func:`params.look_up`); a
    :class:`ConfigError` naming ``flag`` if one on the way cannot be looked up."""
    for p in (path, *path.parents):
        st, why = look_up(p)
        if why:
            raise ConfigError(f"{flag} {path}: cannot reach it ({why})")
        if st is not None:
            return p, st
    raise ConfigError(f"{flag} {path}: no folder of it exists (not even {path.anchor or '.'})")


def check_out_dir(path: Path) -> None:
    """Refuse ``--out`` ``path`` unless it is a directory this process may write into, or one it may create (its
    nearest existing ancestor such a directory), before any work: a run flown, or a search made, and then not
    written would be lost (``bsst margin --out RO/new`` flew its whole search first). :class:`ConfigError`."""
    p, st = _nearest_existing(path, "--out")
    if not S_ISDIR(st.st_mode):
        raise ConfigError(f"--out {path}: exists and is not a directory" if p == path
                          else f"--out {path}: cannot create ({p} is not a directory)")
    if not os.access(p, os.W_OK | os.X_OK):
        raise ConfigError(f"--out {path}: cannot write into it" if p == path
                          else f"--out {path}: cannot create (cannot write into {p})")


def check_writable(path: str | Path, flag: str) -> Path:
    """``path`` as a file that can be written: not a directory, in an existing directory this
    process may write into. Raises :class:`ConfigError` naming ``flag`` otherwise (a folder that does not exist,
    or is a file), so that a bad output path is bad input (exit 2) before any work, not a failure after it."""
    p = Path(path)
    found, st = _nearest_existing(p, flag)
    parent = p.parent
    if found == p:
        if S_ISDIR(st.st_mode):
            raise ConfigError(f"{flag} {p}: is a directory")
    elif not S_ISDIR(st.st_mode):
        raise ConfigError(f"{flag} {p}: {found} is not a directory")
    elif found != parent:
        raise ConfigError(f"{flag} {p}: {parent} does not exist")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise ConfigError(f"{flag} {p}: cannot write into {parent}")
    return p


def side_dir(out: str | Path, files: Sequence[str], overwrite: bool = False) -> Path:
    """The directory one side of a networked run (vehicle or controller) writes ``files``
    into: created if needed; refuses to replace those files unless ``overwrite``."""
    path = Path(out)
    check_out_dir(path)
    taken = [f for f in files if (path / f).exists()]
    if taken and not overwrite:
        raise ConfigError(f"--out {path}: already holds {', '.join(taken)} (use --overwrite to replace)")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ConfigError(f"--out {path}: cannot create ({exc.strerror})") from None
    return path
