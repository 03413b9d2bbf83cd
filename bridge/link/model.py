"""A mission's ``[link]`` table, read and checked: both directions of the link model and the controller's
guard (docs/design.md, "Link model"; docs/links.md).

In:  a ``[link]`` table (its keys, ``[link.up]`` / ``[link.down]``, a named ``profile`` laid under it, a
     ``trace`` file per direction), the mission's seed and duration (s)
Out: :class:`LinkSettings` (each direction's :class:`LinkConfig` and the guard's thresholds), or a
     ``ConfigError`` naming the table, the key and the allowed range; :func:`unmet_key`, a table's key that needs
     what nobody gives (a profile's is refused here); :func:`swept_links`, the values :func:`idle_problem` reads

The model itself (what happens to each packet, its statistics) is :mod:`bridge.link.impairment`; one
direction's settings and the range tables are :mod:`bridge.link.config`. Every public name of both is
re-exported here, so ``from bridge.link.model import ...`` is the one import for the link model.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from itertools import product
from typing import Any

from bridge.link.config import (
    BLACKOUT_DURATION_RANGE_S,
    BLACKOUT_START_RANGE_S,
    COMMAND_LAG_RANGE_MS,
    DIRECTION_KEYS,
    DIRECTIONS,
    GUARD_RANGES,
    HI_OPEN,
    JITTER_KINDS,
    LINK_KEYS,
    LO_OPEN,
    NEEDS,
    NUMBER_RANGES,
    SEED_RANGE,
    TRACE_EXCLUSIVE,
    LinkConfig,
    burst_problem,
    guard_problem,
    idle_problem,
    trace_clash,
)
from bridge.link.impairment import (
    FRAME_BYTES,
    Delivery,
    Fate,
    FateStream,
    LinkImpairment,
    LinkStats,
    fates,
    stream_key,
    uniform,
)
from bridge.link.profile import load_link_profile
from bridge.link.radio import Radio
from bridge.link.trace import (
    LENGTH_SLACK_S,
    MIN_TRACE_RECORDS,
    DirectionTrace,
    TraceFile,
    absolute_link_paths,
    read_trace,
    records_problem,
)
from controller.link_guard import COMPENSATIONS, GuardConfig
from params import ConfigError, Table, finite_float

__all__ = [  # re-exported: the link model's one import (absolute_link_paths: where a table's files are made absolute)
    "BLACKOUT_DURATION_RANGE_S", "BLACKOUT_START_RANGE_S", "COMMAND_LAG_RANGE_MS", "DIRECTION_KEYS", "DIRECTIONS",
    "FRAME_BYTES", "GUARD_RANGES", "HI_OPEN", "JITTER_KINDS", "LINK_KEYS", "LO_OPEN", "NEEDS", "NUMBER_RANGES",
    "SEED_RANGE", "TRACE_EXCLUSIVE", "Delivery", "Fate", "FateStream", "LinkConfig", "LinkImpairment", "LinkSettings",
    "LinkStats", "Radio", "absolute_link_paths", "burst_problem", "fates", "guard_problem", "idle_problem",
    "jitter_capped_text", "jitter_cell", "link_from_table", "merge_link_tables", "stream_key", "swept_links",
    "trace_clash", "uniform", "unmet_key",
]



def _defaults(seed: int) -> dict[str, Any]:
    """Every per-direction key at its default (the trace as its file name, "" for none)."""
    d = LinkConfig(seed=seed)
    return {name: getattr(d, name) for name in (*NUMBER_RANGES, "jitter", "seed", "blackouts")} | {
        "trace": "", "trace_loop": False}


def _direction(t: Table, base: Mapping[str, Any]) -> dict[str, Any]:
    """Read the per-direction keys of one table, defaults from ``base`` (the same keys)."""
    kw: dict[str, Any] = {}
    for name, (lo, hi) in NUMBER_RANGES.items():
        kw[name] = t.number(name, base[name], lo=lo, hi=hi, hi_open=name in HI_OPEN)
    kw["jitter"] = t.string("jitter", base["jitter"], choices=JITTER_KINDS)
    why = burst_problem(kw["loss_pct"], kw["burst_len"])
    if why:
        raise t.error("burst_len", why)
    kw["seed"] = t.integer("seed", base["seed"], lo=SEED_RANGE[0], hi=SEED_RANGE[1])
    kw["blackouts"] = _blackouts(t, base["blackouts"])
    kw["trace"] = t.string("trace", base["trace"])
    kw["trace_loop"] = t.boolean("trace_loop", base["trace_loop"])
    return kw


def _config(kw: Mapping[str, Any], direction: str, source: str, duration_s: float | None,
            files: dict[str, TraceFile], span: str) -> LinkConfig:
    """One direction's :class:`LinkConfig` from its keys: the trace file read (once per file) and checked
    against the other keys, its rows for this direction and, unless it loops, the mission's length."""
    kw = dict(kw)
    path, loop = kw.pop("trace"), kw.pop("trace_loop")
    if not path:
        return LinkConfig(**kw)
    key = f"link.{direction}.trace"
    clash = trace_clash(kw)
    if clash:
        raise ConfigError.at(source, f"link.{direction}", f"trace {path} cannot be combined with {clash} in the same "
                             "direction: the trace gives the delays and the losses (set those to 0 or remove them; "
                             "[link] sets both directions)")
    if path not in files:
        try:
            files[path] = read_trace(path)
        except ConfigError as exc:
            raise ConfigError.at(source, key, str(exc)) from None
    tf = files[path]
    why = records_problem(tf, direction)
    if why:
        raise ConfigError.at(source, key, f"{path} {why}")
    rec = tf.records(direction)
    assert rec is not None
    if rec.n < MIN_TRACE_RECORDS:  # no spacing, so no length: it would replay its one record for ever
        rows = "record" if tf.both is not None else f"{direction} record"
        raise ConfigError.at(source, key, f"{path} has 1 {rows}; a trace needs at least {MIN_TRACE_RECORDS} (it "
                             "lasts its last t_s plus its records' median spacing, and replays each record until the "
                             "next): for a constant link give delay_ms (or loss_pct = 100) instead")
    if duration_s is not None and not loop and rec.length_s < duration_s - LENGTH_SLACK_S:
        raise ConfigError.at(source, key, f"{path} lasts {rec.length_s:g} s ({rec.n} {direction} records), shorter "
                             f"than {span} ({duration_s:g} s); loop it with trace_loop = true (--link-trace-loop) or "
                             "give a longer trace")
    return LinkConfig(**kw, trace=DirectionTrace(path, rec, loop))


def _blackouts(t: Table, default: tuple[tuple[float, float], ...]) -> tuple[tuple[float, float], ...]:
    if not t.has("blackouts"):
        return default
    v = t.raw("blackouts")
    if not isinstance(v, (list, tuple)):
        raise t.error("blackouts", f"expected a list of [start_s, duration_s] pairs, got {v!r}"[:200])
    out = []
    for i, w in enumerate(v):
        ok = (isinstance(w, (list, tuple)) and len(w) == 2
              and all(finite_float(x) is not None for x in w))  # (an integer past the float range is not)
        if not ok:
            raise t.error("blackouts", f"element {i} must be a pair [start_s, duration_s] of numbers, got {w!r}"[:200])
        start, dur = float(w[0]), float(w[1])
        (s_lo, s_hi), (d_lo, d_hi) = BLACKOUT_START_RANGE_S, BLACKOUT_DURATION_RANGE_S
        if not s_lo <= start <= s_hi:
            raise t.error("blackouts", f"element {i}: start_s must be in [{s_lo:g}, {s_hi:g}], got {start:g}")
        if not d_lo < dur <= d_hi:
            raise t.error("blackouts", f"element {i}: duration_s must be in ({d_lo:g}, {d_hi:g}], got {dur:g}")
        out.append((start, dur))
    return tuple(sorted(out))


@dataclass(frozen=True)
class LinkSettings:
    """A mission's ``[link]`` table, validated: both directions and the controller's guard
    (``stale_ms``, ``stop_ms``, ``compensation``; its ``resume`` comes from ``[failsafe]``)."""

    up: LinkConfig = field(default_factory=LinkConfig)
    down: LinkConfig = field(default_factory=LinkConfig)
    guard: GuardConfig = field(default_factory=GuardConfig)
    handovers: tuple[tuple[float, LinkConfig, LinkConfig], ...] = ()  # (mission time s, up, down) from then on
    shared: bool = False  # a fleet's vehicles behind one radio ([link] shared, --shared-link; docs/swarm.md)

    @property
    def impaired(self) -> bool:
        return self.up.impaired or self.down.impaired or any(u.impaired or d.impaired for _, u, d in self.handovers)

    def jitter_capped(self) -> list[dict[str, Any]]:
        """Each jitter the delay capped (``summary.json["link"]["jitter_capped"]``; docs/links.md): its direction,
        from when (s of mission time: 0, or a handover's), what was asked (``jitter_ms``, ``jitter``,
        ``delay_ms``) and the half-width flown (``bound_ms``; 0: no jitter at all). Empty: flown as asked."""
        spans = ((0.0, self.up, self.down), *self.handovers)
        return [{"direction": d, "from_s": t, "jitter_ms": c.jitter_ms, "jitter": c.jitter, "delay_ms": c.delay_ms,
                 "bound_ms": c.jitter_bound_ms}
                for t, up, down in spans for d, c in (("up", up), ("down", down)) if c.jitter_capped]

    def make(self, radios: tuple[Radio, Radio] | None = None, user: int = 0) -> tuple[LinkImpairment, LinkImpairment]:
        """Fresh (up, down) models, each with its handovers; with ``radios``, on those (up, down) radios shared
        with other links, as their user ``user`` (a fleet on one radio: no handovers, ValueError)."""
        up, down = radios if radios is not None else (None, None)
        user = user if radios is not None else 0  # (a radio of its own has one user)
        return (LinkImpairment(self.up, "up", tuple((t, u) for t, u, _ in self.handovers), radio=up, user=user),
                LinkImpairment(self.down, "down", tuple((t, d) for t, _, d in self.handovers), radio=down, user=user))



def jitter_capped_text(cap: Mapping[str, Any]) -> str:
    """One of :meth:`LinkSettings.jitter_capped`'s entries for a person (``bsst sim``'s, ``sitl``'s and ``relay``'s
    printed summary): ``up  : jitter 10 ms uniform capped at the delay, 0 ms: flown without jitter``."""
    since = f" from t={cap['from_s']:g} s" if cap["from_s"] else ""
    flown = f"drawn within ± {cap['bound_ms']:g} ms" if cap["bound_ms"] else "flown without jitter"
    return (f"{cap['direction']:4}: jitter {cap['jitter_ms']:g} ms {cap['jitter']}{since} capped at the delay, "
            f"{cap['delay_ms']:g} ms: {flown}")


def jitter_cell(caps: Iterable[Mapping[str, Any]]) -> str:
    """The ``jitter_capped`` column (``bsst sweep``'s ``cells.csv``) of a run's ``summary["link"]["jitter_capped"]``
    (:meth:`LinkSettings.jitter_capped`): ``""`` when every jitter flew as asked, else each capped direction and the
    half-width of the jitter it flew, ms (``up:4 down:0``: up within ±4 ms, down none), from a handover at T s
    ``@T`` (``up@12:0``)."""
    out = []
    for c in caps:
        since = f"@{c['from_s']:g}" if c["from_s"] else ""
        out.append(f"{c['direction']}{since}:{c['bound_ms']:g}")
    return " ".join(out)


def link_from_table(data: Mapping[str, Any], source: str, seed: int = 0,
                    duration_s: float | None = None, span: str = "the mission") -> LinkSettings:
    """Validate a mission's ``[link]`` table.

    Keys of ``[link]`` itself: every per-direction key (a default for both directions), and
    the controller's: ``compensation = "none" | "predict"``, ``command_lag_ms`` (assumed
    up-link delay the prediction also covers), ``stale_ms``, ``stop_ms`` (thresholds on the
    age of the newest state), and ``profile`` (a named link profile the table is laid over).
    ``[link.up]`` and ``[link.down]`` override per direction. ``seed`` defaults to the mission's
    seed; the two directions always draw different streams. A ``trace`` file is read here; with
    ``duration_s`` (the mission's, s) one shorter than it is refused unless it loops (named as ``span``'s length:
    ``shorter than the mission (30 s)``; ``bsst relay`` without a mission, its run's). ``shared = true``: a fleet's
    vehicles behind one radio (:mod:`bridge.link.radio`; one vehicle: its own link, the same flight). Every refusal
    a :class:`ConfigError` with its typed fields (``source``, ``key``, ``what``) set.
    """
    t = Table(data, source, "link")
    profile = t.string("profile", "")
    if profile:
        return _with_profile(profile, data, source, seed, duration_s, span)
    shared = t.boolean("shared", False)
    both = _direction(t, _defaults(seed))
    g = GuardConfig()
    compensation = t.string("compensation", g.compensation, choices=COMPENSATIONS)
    r = GUARD_RANGES
    stale_ms = t.number("stale_ms", g.stale_s * 1000.0, lo=r["stale_ms"][0], lo_open=True, hi=r["stale_ms"][1])
    stop_ms = t.number("stop_ms", g.stop_s * 1000.0, lo=r["stop_ms"][0], lo_open=True, hi=r["stop_ms"][1])
    lag_ms = t.number("command_lag_ms", g.lag_s * 1000.0, lo=COMMAND_LAG_RANGE_MS[0], hi=COMMAND_LAG_RANGE_MS[1])
    clash = guard_problem({"compensation": compensation, "stale_ms": stale_ms, "stop_ms": stop_ms,
                           "command_lag_ms": lag_ms})
    if clash:
        raise t.error(clash[0], clash[1])
    dirs = {}
    files: dict[str, TraceFile] = {}
    for d in DIRECTIONS:
        sub = t.table(d)
        kw = _direction(sub, both)
        sub.done()
        dirs[d] = _config(kw, d, source, duration_s, files, span)
    t.done()
    guard = GuardConfig(stale_s=stale_ms / 1000.0, stop_s=stop_ms / 1000.0, compensation=compensation,
                        lag_s=lag_ms / 1000.0)
    return LinkSettings(dirs["up"], dirs["down"], guard, shared=shared)


def _with_profile(name: str, data: Mapping[str, Any], source: str, seed: int,
                  duration_s: float | None, span: str) -> LinkSettings:
    """``data`` laid over the ``[link]`` table of profile ``name``, validated (the profile alone first,
    so that a bad profile names its own file)."""
    try:
        prof = load_link_profile(name)
    except ConfigError as exc:
        raise ConfigError.at(source, "link.profile", str(exc)) from None
    if "shared" in prof.link:
        raise ConfigError.at(str(prof.path), "link.shared", "a profile describes one radio; whether a fleet shares "
                             "it is the mission's ([link] shared) or --shared-link's")
    link_from_table(prof.link, str(prof.path), seed)
    unmet = unmet_key(prof.link)  # a profile describes one link: a key of it that needs what it never gives
    if unmet:
        raise ConfigError.at(str(prof.path), f"link.{unmet[0]}", unmet[1])
    over = {k: v for k, v in data.items() if k != "profile"}
    return link_from_table(merge_link_tables(prof.link, over), source, seed, duration_s, span)


def merge_link_tables(base: Mapping[str, Any], over: Mapping[str, Any]) -> dict[str, Any]:
    """``[link]`` table ``base`` with ``over`` laid on top (sub-tables ``up``/``down`` merged key by key)."""
    out: dict[str, Any] = {k: (dict(v) if isinstance(v, Mapping) else v) for k, v in base.items()}
    for k, v in over.items():
        if k in DIRECTIONS and isinstance(v, Mapping) and isinstance(out.get(k), Mapping):
            out[k] = {**out[k], **v}
        else:
            out[k] = dict(v) if isinstance(v, Mapping) else v
    return out


def unmet_key(table: Mapping[str, Any], given: Iterable[str] = ()) -> tuple[str, str] | None:
    """The first key of :data:`NEEDS` a ``[link]`` table gives (``burst_len`` in ``[link]``, for both directions, or
    ``up.burst_len``) whose need no one gives for a direction it acts on: not the table (``[link]`` or that direction's
    table), not its profile, nor ``given`` (the needs the flags or a campaign's axes give), as (the key, why it changes
    nothing); None. A need given as 0 (``loss_pct = 0``) is given: the loss switched off, the burst kept, as a run's
    ``mission.toml`` holds it after ``--loss 0``. A profile that cannot be read is the loader's to name (None here)."""
    prof: Mapping[str, Any] = {}
    if isinstance(table.get("profile"), str) and table["profile"]:
        try:
            prof = load_link_profile(table["profile"]).link
        except ConfigError:
            return None
    given = set(given)

    def has(t: Mapping[str, Any], key: str, d: str) -> bool:
        own = t.get(d)
        return key in t or (isinstance(own, Mapping) and key in own)

    for key, (need, does, _) in NEEDS.items():
        places = [(key, DIRECTIONS)] if key in table else []
        places += [(f"{d}.{key}", (d,)) for d in DIRECTIONS if isinstance(table.get(d), Mapping) and key in table[d]]
        for where, dirs in places:
            if need not in given and not any(has(t, need, d) for t in (table, prof) for d in dirs):
                return where, f"changes nothing: {does}, and no {need} is given; give {need} too, or remove {key}"
    return None


def swept_links(links: Iterable[LinkSettings], axes: Mapping[str, Sequence[float]] | None = None
                ) -> list[tuple[dict[str, Any], dict[str, Any]]]:
    """Each (up, down) of ``links`` as the values a key's need reads (:data:`NEEDS`), once for every combination of
    ``axes``' values laid over both directions (a sweep's or a margin's link axes: each a value of a cell), for
    :func:`idle_problem`: a key is idle when no link nor cell uses it."""
    needs = sorted({need for need, *_ in NEEDS.values()})
    names = [a for a in (axes or {}) if a in needs]
    out = []
    for s in links:
        for combo in product(*((axes or {})[a] for a in names)):
            lay = dict(zip(names, combo, strict=True))
            up, down = ({**{n: getattr(c, n) for n in needs}, **lay} for c in (s.up, s.down))
            out.append((up, down))
    return out
