"""The files a sweep's cells read besides ``mission.toml``: plug-in law files, link traces, link profile files
(and the traces a profile names), hashed into ``sweep.json`` so that ``--resume`` refuses to add rows flown
with another version of one of them to rows flown with the recorded one.

In:  a sweep's identity (its ``mission`` and ``grid`` tables, :meth:`bridge.sweep.spec.Sweep.identity`)
Out: ``{path: SHA-256}`` of every such file (the path as the cells name it), and the check of a resume
"""

from __future__ import annotations

import hashlib
import importlib.util
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

from params import ConfigError


def input_hashes(ident: Mapping[str, Any]) -> dict[str, str]:
    """The SHA-256 of each file the cells read that ``mission.toml``'s own hash does not cover, by path."""
    return {p: file_sha256(Path(p)) for p in sorted(set(_input_files(ident)))}


def check_inputs(recorded: Mapping[str, Any], sweep_json: Path) -> None:
    """Refuse (ConfigError, one line naming the file) a resume whose input file is missing or differs from the one
    ``sweep.json`` recorded: the kept rows flew that version."""
    for p, digest in sorted(recorded.items()):
        try:
            now = file_sha256(Path(p))
        except OSError as exc:
            raise ConfigError(f"--resume: {p}: cannot be read ({exc.strerror or exc}); the sweep's cells read it "
                              f"({sweep_json} records its hash): restore it, or fly the sweep into another "
                              "--out") from None
        if now != digest:
            raise ConfigError(f"--resume: {p}: edited after the sweep ({sweep_json} records another version of it, "
                              "which the kept rows flew); restore the file, or fly the sweep into another --out")


def file_sha256(path: Path) -> str:
    h = hashlib.sha256()
    with path.open("rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _input_files(ident: Mapping[str, Any]) -> Iterator[str]:
    """The paths named in the mission and grid tables that the cells read: law files and modules, traces, profile
    files (and the traces in a profile file)."""
    for key, v in _strings(ident.get("mission", {}), ident.get("grid", {})):
        if key == "controller":
            yield from _law_file(v)
        elif key in ("trace", "profile") and _is_path(v) and Path(v).is_file():
            yield v
            if key == "profile":
                yield from _profile_traces(v)


def _strings(*tables: Any, key: str = "") -> Iterator[tuple[str, str]]:
    """Every string in nested tables and lists, with the key it sits under (a list's items: the list's key)."""
    for t in tables:
        if isinstance(t, Mapping):
            for k, v in t.items():
                yield from _strings(v, key=str(k))
        elif isinstance(t, (list, tuple)):
            yield from _strings(*t, key=key)
        elif isinstance(t, str):
            yield key, t


def _is_path(v: str) -> bool:
    return "/" in v or "\\" in v or v.endswith((".toml", ".csv", ".json", ".py"))


def _law_file(spec: str) -> Iterator[str]:
    """A plug-in law's file (``path/law.py:Class``), or its module's (``package.module:Class``); nothing for a
    built-in law (its code is bsst's) or a module that cannot be found (the cell says so)."""
    where, sep, _ = spec.rpartition(":")
    if not sep or not where:
        return
    if where.endswith(".py") or "/" in where or "\\" in where:
        if Path(where).is_file():
            yield where
        return
    from controller.law import imports_from  # lazy: only for a sweep over a module's law

    try:
        with imports_from():  # found where the cell's resolve_law finds it
            found = importlib.util.find_spec(where)
    except (ImportError, ValueError, AttributeError):  # the cell's own resolve_law says what is wrong
        return
    origin = getattr(found, "origin", None)
    if origin and Path(origin).is_file():
        yield origin


def _profile_traces(path: str) -> Iterator[str]:
    """The trace files a link profile file names (made absolute against its folder by its reader)."""
    from bridge.link.profile import load_link_profile  # lazy: only for a sweep over a profile file

    try:
        link = load_link_profile(path).link
    except ConfigError:
        return
    for key, v in _strings(link):
        if key == "trace" and Path(v).is_file():
            yield v
