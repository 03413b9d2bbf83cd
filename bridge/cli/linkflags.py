"""The link-impairment flags (``--delay MS`` ... for both directions, ``--up-delay``, ``--down-loss`` ... for one,
traces, profiles, the controller's guards), and the ``[link]`` override table read back from them.

In:  the parsed flags (link values in ms, %, packets, bytes/s; ``--blackout START:DURATION`` s; trace and profile
     files)
Out: :func:`link_table_from_args`'s ``[link]`` override table, which goes to :func:`bridge.core.flight.prepare` in
     an :class:`~bridge.core.overrides.Overrides` like every other override, with the flags that gave its traces as
     typed (:func:`link_flags_from_args`)
     (:func:`bridge.cli.options.overrides_from_args`); a combination no direction can fly is a ``UsageError``
     naming the flags (exit 2), a flag for both directions that both its direction's own override a typed
     :class:`~params.ConfigError` naming them (:func:`shadowed_flag_refusal`); :func:`idle_link_flag`, a flag that
     would change nothing, as its refusal's line;
     :func:`guard_flag_refusal`, a guard flag that clashes with the flight's other guard keys, as its line

The ranges are the mission loader's (:data:`bridge.link.model.NUMBER_RANGES`), one per key.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from bridge.cli.flags import (
    FlagRefusal,
    UsageError,
    blackout_window,
    existing_file,
    link_number,
    link_seed,
    yes_no,
)
from params import ConfigError

# -- link impairment flags (bridge.link.model): both directions, or one with --up-/--down- -----------


LINK_FLAGS = (  # flag stem, [link] key, metavar, help; the ranges are bridge.link.model.NUMBER_RANGES
    ("delay", "delay_ms", "MS", "one-way delay"),
    ("jitter", "jitter_ms", "MS", "delay jitter (uniform half-width or normal sigma)"),
    ("loss", "loss_pct", "PCT", "packet loss"),
    ("burst", "burst_len", "LEN", "mean loss burst length in packets (Gilbert-Elliott; 0 Bernoulli)"),
    ("dup", "dup_pct", "PCT", "duplicated packets"),
    ("reorder", "reorder_pct", "PCT", "packets held back past their successor"),
    ("bandwidth", "rate_bps", "BYTES_PER_S", "bandwidth cap in bytes/s (0: none)"),
    ("queue", "queue_ms", "MS", "with --bandwidth: longest wait in the queue before a packet is dropped"),
)
GUARD_FLAGS = (  # flag, [link] key, metavar, help: the controller's guard and prediction (not per direction)
    ("--command-lag", "command_lag_ms", "MS", "with --compensation predict: assumed command delay it also covers"),
    ("--stale-after", "stale_ms", "MS", "a state older than this is stale: the law holds its integrators"),
    ("--stop-after", "stop_ms", "MS", "a state older than this stops the targets (the vehicle's timeout takes over)"),
)


def add_link_options(p: argparse.ArgumentParser, skip: Sequence[str] = (), controller: bool = True) -> None:
    """The link-impairment flags (``--delay MS`` … for both directions, ``--up-delay``,
    ``--down-loss`` … for one) and (``controller``: for a command that flies the controller) the
    controller's compensation and guards; ``skip`` omits flag stems a command defines otherwise.
    :func:`link_table_from_args` reads them back."""
    g = p.add_argument_group("link impairment", "override the mission's [link] tables; every flag for both "
                             "directions also exists as --up-FLAG (controller -> vehicle) and --down-FLAG")
    for stem, key, meta, text in LINK_FLAGS:
        for pre in ("", "up-", "down-"):
            if stem in skip and not pre:
                continue
            flag = f"--{pre}{stem}"
            g.add_argument(flag, dest=f"link_{pre.replace('-', '_')}{key}", type=link_number(flag, key),
                           metavar=meta, help=argparse.SUPPRESS if pre else text)
    for pre in ("", "up-", "down-"):
        flag = f"--{pre}blackout"
        g.add_argument(flag, dest=f"link_{pre.replace('-', '_')}blackouts", action="append",
                       type=blackout_window(flag), metavar="START:DURATION",
                       help=argparse.SUPPRESS if pre else "no packets from START for DURATION s (repeatable)")
    add_trace_options(g)
    g.add_argument("--jitter-dist", dest="link_jitter", choices=("uniform", "normal"), help="jitter distribution")
    g.add_argument("--link-seed", dest="link_seed", type=link_seed("--link-seed"), metavar="N",
                   help="seed of the link's fates (default: the mission's seed)")
    if not controller:  # bsst relay: the link alone; what the controller does with its states is not its to set
        return
    g.add_argument("--compensation", dest="link_compensation", choices=("none", "predict"),
                   help="predict: control on the state carried forward over its age (nominal model)")
    for flag, key, meta, text in GUARD_FLAGS:
        g.add_argument(flag, dest=f"link_{key}", type=link_number(flag, key), metavar=meta, help=text)


TRACE_KEYS = ("trace", "trace_loop")  # per direction, read back like the numbers


def trace_file(flag: str) -> Callable[[str], str]:
    """An argparse type for a link trace: an existing file, made absolute (relative to the working
    directory, so that every process of a session finds it); ``none`` for no trace. The file's
    content is checked when the flight is built (bridge.link.trace), naming its bad lines."""
    def conv(text: str) -> str:
        if text.strip().lower() == "none":
            return ""
        return existing_file(flag, text)

    return conv


def link_profile(flag: str) -> Callable[[str], str]:
    """An argparse type for a link profile: a shipped name or a profile TOML (made absolute)."""
    def conv(text: str) -> str:
        from bridge.link.profile import profile_names  # lazy: building the parser loads no link code
        from bridge.link.trace import is_profile_path  # lazy: as above

        if not is_profile_path(text):
            if text not in profile_names():
                raise FlagRefusal(flag, f"unknown link profile {text!r}; shipped profiles: "
                                        f"{', '.join(profile_names())} (or a profile TOML path)", sep=": ")
            return text
        return existing_file(flag, text)

    return conv


def add_trace_options(g: Any) -> None:
    """``--link-trace FILE`` (``--up-link-trace``, ``--down-link-trace``), ``--link-trace-loop [true|false]``
    and ``--link-profile NAME``: a measured trace, looped or not, and a named link profile."""
    for pre in ("", "up-", "down-"):
        dest = f"link_{pre.replace('-', '_')}"
        g.add_argument(f"--{pre}link-trace", dest=f"{dest}trace", type=trace_file(f"--{pre}link-trace"),
                       metavar="FILE", help=argparse.SUPPRESS if pre else
                       "replay this measured link trace (CSV: t_s, delay_ms, optional direction; 'none': no trace)")
        g.add_argument(f"--{pre}link-trace-loop", dest=f"{dest}trace_loop", nargs="?", const=True,
                       type=yes_no(f"--{pre}link-trace-loop"), metavar="true|false",
                       help=argparse.SUPPRESS if pre else "loop a trace shorter than the mission (bare: true)")
    g.add_argument("--link-profile", dest="link_profile", type=link_profile("--link-profile"), metavar="NAME",
                   help="a named link profile the mission's [link] is laid over: wifi, lte, sik-57600, "
                        "satellite-geo, satellite-leo, or a profile TOML (bsst link fit writes one)")


def link_table_from_args(args: argparse.Namespace) -> dict[str, Any]:
    """The ``[link]`` overrides the flags of :func:`add_link_options` ask for ({} if none).

    Flags for both directions write both ``up`` and ``down``; ``--up-*`` / ``--down-*`` win. A flag for both given
    with both of its direction's own (``--delay 40 --up-delay 10 --down-delay 30``) sets nothing: refused
    (:func:`shadowed_flag_refusal`)."""
    refused = shadowed_flag_refusal(args)
    if refused is not None:
        raise refused
    out: dict[str, Any] = {}
    keys = [key for _, key, *_ in LINK_FLAGS] + ["blackouts", *TRACE_KEYS]
    for d in ("up", "down"):
        side: dict[str, Any] = {}
        for key in keys:
            for dest in (f"link_{key}", f"link_{d}_{key}"):
                v = getattr(args, dest, None)
                if v is not None:
                    side[key] = [list(w) for w in v] if key == "blackouts" else v
        for key in ("jitter", "seed"):
            v = getattr(args, f"link_{key}", None)
            if v is not None:
                side[key] = v
        if side:
            out[d] = side
        if "burst_len" in side:  # (without --loss: what needs no loss; the file's loss is checked with the file)
            from bridge.link.model import burst_problem  # lazy: start-up time

            why = burst_problem(side.get("loss_pct", 0.0), side["burst_len"])
            if why:
                raise UsageError("bsst", f"--burst / --{d}-burst: {why}")
        if side.get("trace"):
            from bridge.link.model import trace_clash  # lazy: start-up time

            clash = trace_clash(side)
            if clash:
                raise UsageError("bsst", f"--link-trace / --{d}-link-trace cannot be combined with {clash} (--delay, "
                                 f"--jitter, --loss, --burst) in the {d} direction: the trace gives the delays and "
                                 f"the losses")
    for key in ("compensation", "profile", "shared", *(k for _, k, *_ in GUARD_FLAGS)):
        v = getattr(args, f"link_{key}", None)
        if v is not None:
            out[key] = v
    return out


def _stems() -> list[tuple[str, str]]:
    """Each link flag for both directions with its table key (``("delay", "delay_ms")``, ``("blackout",
    "blackouts")``, ...): ``--STEM`` for both, ``--up-STEM`` and ``--down-STEM`` for one."""
    return [(stem, key) for stem, key, *_ in LINK_FLAGS] + [("blackout", "blackouts"), ("link-trace", "trace"),
                                                            ("link-trace-loop", "trace_loop")]


def _shown(flag: str, v: Any) -> str:
    """A link flag as typed: ``--delay 40``, ``--blackout 1:0.5`` once per window, ``--link-trace none``, ``--link-trace
    -loop true``."""
    if isinstance(v, bool):
        return f"{flag} {str(v).lower()}"
    if isinstance(v, list):
        return " ".join(f"{flag} {start:g}:{length:g}" for start, length in v)
    if isinstance(v, str):
        return f"{flag} {v or 'none'}"
    return f"{flag} {v:g}"


def shadowed_flag_refusal(args: argparse.Namespace) -> ConfigError | None:
    """The refusal (typed, :meth:`ConfigError.at`: its ``source`` the flag as typed) of a link flag for both directions
    (``--delay``, ``--loss``, ``--blackout``, ``--link-trace`` ...) given with both of its direction's own flags
    (``--up-delay`` and ``--down-delay``), which win over it in their direction, so it sets nothing in either: taken
    silently until the forty-fifth session (``--delay 40 --up-delay 10 --down-delay 30`` flew 10 and 30 ms). None."""
    for stem, key in _stems():
        both = getattr(args, f"link_{key}", None)
        own = [(f"--{d}-{stem}", v) for d in ("up", "down")
               if (v := getattr(args, f"link_{d}_{key}", None)) is not None]
        if both is not None and len(own) == 2:
            flag = _shown(f"--{stem}", both)
            return ConfigError.at(flag, None, f"sets nothing: {_shown(*own[0])} and {_shown(*own[1])} set the two "
                                  f"directions, and a direction's own flag wins over --{stem}; drop --{stem}, or one "
                                  "of them", sep=": ")
    return None


def link_flags_from_args(args: argparse.Namespace) -> dict[str, str]:
    """The flag that gave each per-direction entry and the profile of :func:`link_table_from_args`'s table, as typed,
    by its place there (``{"up.trace": "--link-trace", "down.trace": "--down-link-trace", "up.delay_ms": "--delay",
    "profile": "--link-profile"}``): the table writes ``--link-trace F`` as ``--up-link-trace F --down-link-trace
    F``, ``--delay 40 --up-delay 10`` as ``up.delay_ms = 10, down.delay_ms = 40``, and a refusal names the flags the
    user gave (:attr:`bridge.core.overrides.Overrides.link_flags`); {} if none."""
    out = {"profile": "--link-profile"} if getattr(args, "link_profile", None) is not None else {}
    for d in ("up", "down"):
        for stem, key in _stems():
            given = [f for dest, f in ((f"link_{d}_{key}", f"--{d}-{stem}"), (f"link_{key}", f"--{stem}"))
                     if getattr(args, dest, None) is not None]
            if given:  # (the direction's own flag wins, as in the table)
                out[f"{d}.{key}"] = given[0]
    return out


NEED_FLAGS = {"loss_pct": ("loss", "PCT"), "rate_bps": ("bandwidth", "BYTES_PER_S"), "trace": ("link-trace", "FILE")}


def idle_link_flag(args: argparse.Namespace, links: Sequence[Any], axes: Mapping[str, Sequence[float]] | None = None,
                   cells: bool = False) -> str | None:
    """The first link flag given (``--burst``, ``--up-queue``, ``--link-trace-loop`` ...: a key of
    :data:`bridge.link.model.NEEDS`) that changes nothing on every one of ``links`` (the flights' link settings, each
    vehicle's) in every combination of ``axes`` (a sweep's or a margin's link values, laid over both directions:
    :func:`bridge.link.model.swept_links`), as the line that refuses it (``cells``: a sweep's); None."""
    from bridge.link.model import DIRECTIONS, NEEDS, idle_problem, swept_links  # lazy: start-up time

    links = swept_links(links, axes)
    stems = {key: stem for stem, key, *_ in LINK_FLAGS} | {"trace_loop": "link-trace-loop"}
    for key, (need, *_) in NEEDS.items():
        for pre in ("", "up-", "down-"):
            v = getattr(args, f"link_{pre.replace('-', '_')}{key}", None)
            dirs = [DIRECTIONS.index(pre[:-1])] if pre else [0, 1]
            why = None if v is None else idle_problem(key, [pair[i] for pair in links for i in dirs])
            if why:
                flag = f"--{pre}{stems[key]}"
                shown = str(v).lower() if isinstance(v, bool) else f"{v:g}"
                stem, meta = NEED_FLAGS[need]
                return (f"{flag} {shown}: changes nothing{' in any cell' if cells else ''}: {why}; give "
                        f"--{pre}{stem} {meta} too, or drop {flag}")
    return None


def idle_flags_given(args: argparse.Namespace) -> bool:
    """Whether a link flag that acts only with another (:data:`bridge.link.model.NEEDS`) was given."""
    from bridge.link.model import NEEDS  # lazy: start-up time

    return any(getattr(args, f"link_{pre}{key}", None) is not None for key in NEEDS for pre in ("", "up_", "down_"))


def guard_flag_refusal(args: argparse.Namespace, own: Any, source: str) -> str | None:
    """The line refusing a guard flag (``--command-lag``, ``--stale-after``, ``--stop-after``, ``--compensation``)
    whose value breaks a rule of the guard's keys (:func:`bridge.link.model.guard_problem`: a command lag without
    prediction, a stop age below the stale age) with the rest of the flight's link (the mission's own ``[link]``,
    ``own``, as ``source`` has it: its files relative to its folder; its profile; the other link flags), named as the
    flag; None, and None for a clash of the file's own keys or a ``[link]`` that is no table (the loader names
    those)."""
    from bridge.link.model import (  # lazy: start-up time
        absolute_link_paths,
        guard_problem,
        link_from_table,
        merge_link_tables,
    )

    flags = {key: flag for flag, key, *_ in GUARD_FLAGS} | {"compensation": "--compensation"}
    given = {k: v for k in flags if (v := getattr(args, f"link_{k}", None)) is not None}
    if not given:
        return None
    own = absolute_link_paths(own, Path(source).parent) if isinstance(own, Mapping) else {}
    rest = {k: v for k, v in link_table_from_args(args).items() if k not in flags}  # (--link-profile: its keys)
    try:
        g = link_from_table(merge_link_tables(own, rest), source or "link").guard
    except ConfigError:
        return None  # a bad table or another flag: named where the flight is prepared
    values = {"compensation": g.compensation, "stale_ms": round(g.stale_s * 1e3, 9),
              "stop_ms": round(g.stop_s * 1e3, 9), "command_lag_ms": round(g.lag_s * 1e3, 9), **given}
    clash = guard_problem(values, given)
    if clash is None or clash[0] not in given:
        return None
    key, why, other = clash
    shown = given[key] if isinstance(given[key], str) else f"{given[key]:g}"
    return f"{flags[key]} {shown}: {why} ({flags[other]} sets {other})"


def radio_of(args: argparse.Namespace) -> tuple[str, int] | None:
    """``--radio FILE`` and ``--radio-user N`` (default 0) as the (file, user) a controller or relay queues on, None
    without ``--radio``; a ``--radio-user`` without it is refused (it was taken, and did nothing)."""
    if args.radio:
        return args.radio, args.radio_user or 0
    if args.radio_user is not None:
        raise UsageError("bsst", "--radio-user without --radio: it numbers this side among a fleet's one radio's "
                         "users (bsst sitl --vehicles N --shared-link gives both)")
    return None
