"""Typed, validated parameters read from TOML files.

Every parameter file of the project (vehicle profiles, missions, gains, sweeps) is read
through :func:`load_toml` and checked field by field with :class:`Table`, so that a bad
value always fails with one line naming the file, the key and what is allowed.
"""

from __future__ import annotations

import functools
import json
import math
import os
import stat
import tomllib
from collections.abc import Callable, Iterable, Iterator, Mapping
from contextlib import contextmanager
from contextvars import ContextVar
from pathlib import Path
from typing import Any, ParamSpec, TypeVar

from params.text import is_typo_of, likely, too_many_digits, unknown_key_hint  # noqa: F401  (params' own names)

_P = ParamSpec("_P")
_R = TypeVar("_R")


class ConfigError(ValueError):
    """A parameter file or value is wrong; the message names the file and the key.

    Its typed fields, set by the code that raises (None where it did not), are how a caller re-names or re-anchors a
    refusal: by reading them, never by matching the message's text (``str()`` is the message, unchanged). ``source``:
    what the message opens with, as given (a file's path, a flag, a command: ``bsst link extract``; None: it opens
    with the reason, ``unknown link profile 'x'``); ``key``: the dotted key in it (``link.up.trace``); ``what``: the
    bare reason after them."""

    def __init__(self, message: str = "", *, source: str | None = None, key: str | None = None,
                 what: str | None = None) -> None:
        super().__init__(message)
        self.source, self.key, self.what = source, key, what

    @classmethod
    def at(cls, source: str, key: str | None, what: str, *, sep: str = ": ") -> ConfigError:
        """``source: key: what`` (``source: what`` without a key), with its fields; each shown escaped in the message
        if it holds a newline or another unprintable character (every message is one line). ``sep``: what follows
        ``source`` (a flag's range, ``" "``: ``--rate must be in [50, 1000], got 5``)."""
        where = f"{_printable(key, KEY_SHOWN_MAX)}: " if key else ""
        return cls(f"{_printable(source)}{sep}{where}{what}", source=source, key=key, what=what)


MAX_TOML_BYTES = 4 << 20  # a mission, profile or sweep file is a few kB; anything this big is not one
MAX_DEPTH = 32  # tables and lists nested deeper are refused: ours nest 6 deep, and every walk stays far from
# Python's recursion limit (tomllib itself gives up at about 450 levels of arrays or inline tables)


# the files the command or API call under way has read as input (its real path -> the path as first given); None
# outside one: a read then is recorded nowhere (no later call is refused for it)
_INPUTS: ContextVar[dict[str, str] | None] = ContextVar("bsst_inputs_read", default=None)


@contextmanager
def input_scope() -> Iterator[dict[str, str]]:
    """One command's, or one API call's, record of the files it reads (:func:`inputs_read`): ``bsst``'s
    :func:`bridge.cli.main` opens one around its command, and each public call that may ``--overwrite`` a run
    directory (:func:`reads_inputs`) around itself. Opened inside another, it is that one (a command's API call
    keeps what the command read before it); the outermost ends with its call, and what it read is forgotten.
    Per thread and per asyncio task (a context variable)."""
    open_one = _INPUTS.get()
    if open_one is not None:
        yield open_one
        return
    fresh: dict[str, str] = {}
    token = _INPUTS.set(fresh)
    try:
        yield fresh
    finally:
        _INPUTS.reset(token)


def reads_inputs(func: Callable[_P, _R]) -> Callable[_P, _R]:
    """``func`` run inside an :func:`input_scope` (its own, or the one already open)."""
    @functools.wraps(func)
    def scoped(*args: _P.args, **kwargs: _P.kwargs) -> _R:
        with input_scope():
            return func(*args, **kwargs)
    return scoped


def note_input(path: str | Path) -> None:
    """Record ``path`` as a file the command or API call under way reads as input (:func:`inputs_read`). Every
    reader of a user's file calls it: :func:`read_regular_file` (missions, plans, profiles, link traces, sweeps,
    tlogs), a controller plug-in's loader and the signing key's. Outside an :func:`input_scope`, nothing."""
    inputs = _INPUTS.get()
    if inputs is not None:
        inputs.setdefault(os.path.realpath(path), str(path))


def inputs_read() -> dict[str, str]:
    """Every file the command or API call under way (:func:`input_scope`) has read as input so far: its real path
    (symbolic links resolved) -> the path it was first read by. ``--overwrite`` refuses to replace one
    (:func:`bridge.record.runlog.run_dir`). Outside a scope: none."""
    return dict(_INPUTS.get() or {})


def look_up(path: str | Path) -> tuple[os.stat_result | None, str | None]:
    """``path`` looked up, symbolic links followed: (its ``stat``, None); (None, None) if it is simply not there (or
    a folder on its way is a file); (None, why) if the system cannot look it up (a name too long, a folder this
    process may not search, a loop of links: the ``strerror``). The one way every reader and writer of a user's
    path asks whether it can reach it (:func:`unreachable`, ``bridge.record.runlog``'s output checks)."""
    try:
        return os.stat(path), None
    except (FileNotFoundError, NotADirectoryError):
        return None, None
    except OSError as exc:
        return None, exc.strerror or str(exc)
    except ValueError:  # a NUL byte in it: no path the system can take
        return None, "a NUL byte in the path"


def unreachable(path: str | Path) -> str | None:
    """Why the system cannot look ``path`` up (:func:`look_up`), or None: it exists, or is simply not there.
    pathlib's ``exists``, ``is_file`` and ``is_dir`` raise for the former: a check asks this first, to name the
    path (exit 2) instead of a traceback."""
    return look_up(path)[1]


def read_regular_file(path: str | Path, expected: str = "file", max_bytes: int | None = None) -> bytes:
    """The bytes of ``path``, which must be a regular file (never blocks: a FIFO, socket or device is
    refused before it is read, and opened without blocking should one be swapped in after the check).
    Every problem is a :class:`ConfigError` naming the path and saying that ``expected`` was wanted.
    The path is recorded as an input (:func:`note_input`)."""
    p = Path(path)
    note_input(p)
    src = str(p)  # (a path with a newline in it stays on the message's one line: ConfigError.at)
    try:
        kind = _file_kind(os.stat(p).st_mode)
    except FileNotFoundError:
        raise ConfigError.at(src, None, "no such file") from None
    except OSError as exc:
        raise ConfigError.at(src, None, f"cannot read ({exc.strerror})") from None
    if kind:
        raise ConfigError.at(src, None, f"is {kind}, expected {expected}")
    try:
        fd = os.open(p, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    except OSError as exc:
        raise ConfigError.at(src, None, f"cannot read ({exc.strerror})") from None
    try:
        st = os.fstat(fd)
        kind = _file_kind(st.st_mode)
        if kind:
            raise ConfigError.at(src, None, f"is {kind}, expected {expected}")
        if max_bytes is not None and st.st_size > max_bytes:
            raise ConfigError.at(src, None, f"{st.st_size} bytes, larger than {max_bytes} bytes: not {expected}")
        chunks = []
        while chunk := os.read(fd, 1 << 20):
            chunks.append(chunk)
        return b"".join(chunks)
    except OSError as exc:
        raise ConfigError.at(src, None, f"cannot read ({exc.strerror})") from None
    finally:
        os.close(fd)


def _file_kind(mode: int) -> str | None:
    """What a file that is not regular is, in words (None for a regular file)."""
    if stat.S_ISREG(mode):
        return None
    for test, words in ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
                        (stat.S_ISSOCK, "a socket"), (stat.S_ISCHR, "a character device"),
                        (stat.S_ISBLK, "a block device")):
        if test(mode):
            return words
    return "not a regular file"


def utf8_text(raw: bytes) -> str:
    """``raw`` decoded as UTF-8, a leading byte-order mark (U+FEFF, which Windows editors write) dropped: the
    one way every text file of ours is decoded (TOML files, plans, link traces). Raises UnicodeDecodeError."""
    return raw.decode("utf-8").removeprefix("\ufeff")


def path_problem(text: str, fix: str = "give one") -> str | None:
    """Why ``text`` is no path, or None: empty (an unset shell variable's ``"$DIR"``, a key left blank), which
    would be read as the current folder. The one check of every path given (a flag's, a mission file's key)."""
    return None if text else f"an empty path ({fix})"


def read_text_file(path: str | Path, expected: str, max_bytes: int = MAX_TOML_BYTES) -> str:
    """The UTF-8 text of a regular file of at most ``max_bytes`` (:func:`read_regular_file`, :func:`utf8_text`);
    every problem a :class:`ConfigError` naming the path and ``expected`` (a mission plan, a waypoint file)."""
    raw = read_regular_file(path, expected, max_bytes)
    try:
        return utf8_text(raw)
    except UnicodeDecodeError:
        raise ConfigError.at(str(Path(path)), None, f"not a text file (expected {expected})") from None


def load_toml(path: str | Path) -> dict[str, Any]:
    """Read a TOML file (UTF-8, with or without a byte-order mark: :func:`utf8_text`), turning every I/O or
    syntax problem into a :class:`ConfigError`: not a regular file, over :data:`MAX_TOML_BYTES`, not UTF-8,
    not TOML, nested over :data:`MAX_DEPTH`."""
    p = Path(path)
    return toml_from_bytes(read_regular_file(p, "a TOML file", MAX_TOML_BYTES), p)


def toml_from_bytes(raw: bytes, p: Path) -> dict[str, Any]:
    """The table in ``raw``, the bytes of the TOML file ``p`` (:func:`load_toml`'s errors, naming ``p``)."""
    src = str(p)
    try:
        data = tomllib.loads(utf8_text(raw))
    except UnicodeDecodeError:
        raise ConfigError.at(src, None, "not a text file (expected TOML)") from None
    except tomllib.TOMLDecodeError as exc:
        text = utf8_text(raw).lstrip()  # (a ground station's file is read by its name's suffix: say so)
        hint = ("; it reads as a QGroundControl plan: name it .plan" if text.startswith("{") and '"fileType"' in text
                else "; it reads as a QGC WPL waypoint file: name it .waypoints" if text.startswith("QGC WPL") else "")
        raise ConfigError.at(src, None, f"not valid TOML ({exc}){hint}") from None
    except ValueError as exc:  # an integer over Python's limit of digits (tomllib converts with int())
        raise ConfigError.at(src, None, f"not valid TOML ({too_many_digits(utf8_text(raw), exc)})") from None
    except RecursionError:
        raise ConfigError.at(src, None, f"nested too deeply (more than {MAX_DEPTH} levels of tables and lists)") \
            from None
    check_depth(data, str(p))
    return data


def finite_float(v: Any) -> float | None:
    """``v`` as a float if it is a number (an int or a float, not a bool) that is finite as a float; else None
    (an integer too large for a float, ~1e308, is not one: ``float()`` of it raises OverflowError)."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return None
    try:
        f = float(v)
    except OverflowError:
        return None
    return f if math.isfinite(f) else None


def check_depth(data: Any, source: str, limit: int = MAX_DEPTH) -> None:
    """Refuse tables and lists nested deeper than ``limit``, naming the top-level key that does, so
    that no recursive walk of ours (validation, ``repr``, ``dump_toml``, JSON) can exceed the stack.
    Iterative: it never recurses itself."""
    stack: list[tuple[Any, int, str]] = [(data, 0, "")]
    while stack:
        node, depth, top = stack.pop()
        if isinstance(node, Mapping):
            children: Iterable[tuple[str, Any]] = ((top or str(k), v) for k, v in node.items())
        elif isinstance(node, (list, tuple)):
            children = ((top, v) for v in node)
        else:
            continue
        if depth >= limit:
            where = f"{_printable(top[:40])}: " if top else ""
            raise ConfigError(f"{_printable(source)}: {where}nested more than {limit} levels deep", source=source,
                              key=top or None, what=f"nested more than {limit} levels deep")
        stack.extend((v, depth + 1, name) for name, v in children)


class Table:
    """One TOML table being validated: typed getters that name the file and the key.

    Call :meth:`done` at the end so that any key nobody asked for is rejected as unknown, with the
    likely key suggested, else the keys it takes (every key the table asked for is a known one). A misspelled
    required key (``duraton_s``; ``t_s`` for ``t``, ``t`` for ``t_s``) is reported as the unknown key it is, with
    ``did you mean 'duration_s'?``, not as the missing key it leaves behind.
    """

    def __init__(self, data: Mapping[str, Any], source: str, prefix: str = "") -> None:
        if not isinstance(data, Mapping):
            raise ConfigError(f"{source}: {prefix or 'top level'}: expected a table", source=source, key=prefix or None,
                              what="expected a table")
        self._data = data
        self._source = source
        self._prefix = prefix
        self._used: dict[str, None] = {}  # the keys asked for, in order: the ones it takes (an ordered set)

    def key(self, name: str) -> str:
        return f"{self._prefix}.{name}" if self._prefix else name

    def error(self, name: str, why: str) -> ConfigError:
        """The error of key ``name`` (it and the source shown escaped if either holds a newline or another
        unprintable character: every message is one line)."""
        return ConfigError.at(self._source, self.key(name), why)

    def has(self, name: str) -> bool:
        """Whether the table holds key ``name``; if not, a key it knows all the same (a misspelling suggests it)."""
        if name not in self._data:
            self._used[name] = None
        return name in self._data

    def _get(self, name: str, default: Any) -> Any:
        self._used[name] = None
        if name in self._data:
            return self._data[name]
        if default is _REQUIRED:
            # a key not asked for yet, one typing slip from this one, is this one misspelled: say that, not what its
            # absence leads to
            typo = [str(k) for k in self._data if k not in self._used and is_typo_of(str(k), name)]
            if typo:
                raise self.unknown(typo[0], [name])
            # the key without its unit (``t`` for ``t_s``): too short for a typing slip, but what was meant
            stem = name.rsplit("_", 1)[0] if "_" in name else None
            bare = [str(k) for k in self._data if k not in self._used and str(k) == stem]
            where = f"in [{self._prefix}]" if self._prefix else "at the top level"
            if bare:
                raise self.error(bare[0], f"unknown key {where}; did you mean {name!r} (the unit is in the name)?")
            # the key with a unit it does not take (``t_s`` for a point's ``t``)
            united = [str(k) for k in self._data if k not in self._used and str(k).rsplit("_", 1)[0] == name]
            if united:
                raise self.error(united[0], f"unknown key {where}; did you mean {name!r}?")
            raise self.error(name, "is required")
        return default

    def number(
        self,
        name: str,
        default: Any = ...,
        *,
        lo: float | None = None,
        hi: float | None = None,
        lo_open: bool = False,
        hi_open: bool = False,
    ) -> float:
        v = self._get(name, _REQUIRED if default is ... else default)
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise self.error(name, f"expected a number, got {show(v)}")
        try:
            v = float(v)
        except OverflowError:  # an integer past the float range (~1e308)
            allowed = "a finite number" if lo is None and hi is None else f"in {_range(lo, hi, lo_open, hi_open)}"
            raise self.error(name, f"must be {allowed}, got {show(v)}") from None
        if not math.isfinite(v):
            raise self.error(name, f"must be finite, got {v}")
        if (lo is not None and (v < lo or (lo_open and v == lo))) or (
            hi is not None and (v > hi or (hi_open and v == hi))
        ):
            raise self.error(name, f"must be in {_range(lo, hi, lo_open, hi_open)}, got {v:g}")
        return v

    def integer(self, name: str, default: Any = ..., *, lo: int | None = None, hi: int | None = None) -> int:
        v = self._get(name, _REQUIRED if default is ... else default)
        if isinstance(v, bool) or not isinstance(v, int):
            raise self.error(name, f"expected an integer, got {show(v)}")
        if (lo is not None and v < lo) or (hi is not None and v > hi):
            raise self.error(name, f"must be in {_range(lo, hi, False, False)}, got {show(v)}")
        return v

    def string(self, name: str, default: Any = ..., *, choices: Iterable[str] | None = None) -> str:
        v = self._get(name, _REQUIRED if default is ... else default)
        if not isinstance(v, str):
            raise self.error(name, f"expected a string, got {show(v)}")
        if choices is not None:
            allowed = tuple(choices)
            if v not in allowed:  # "" (the default's own choice, where allowed) shown as such, not as nothing
                shown = ", ".join(repr(a) if a == "" else a for a in allowed)
                raise self.error(name, f"must be one of {shown}; got {show(v)}")
        return v

    def boolean(self, name: str, default: Any = ...) -> bool:
        v = self._get(name, _REQUIRED if default is ... else default)
        if not isinstance(v, bool):
            raise self.error(name, f"expected true or false, got {show(v)}")
        return v

    def vector(
        self, name: str, length: int, default: Any = ..., *, lo: float | None = None, hi: float | None = None
    ) -> tuple[float, ...]:
        v = self._get(name, _REQUIRED if default is ... else default)
        if not isinstance(v, (list, tuple)) or len(v) != length:
            raise self.error(name, f"expected a list of {length} numbers, got {show(v)}")
        out = []
        for i, x in enumerate(v):
            f = finite_float(x)
            if f is None:
                raise self.error(name, f"element {i} must be a finite number, got {show(x)}")
            if (lo is not None and f < lo) or (hi is not None and f > hi):
                raise self.error(name, f"element {i} must be in {_range(lo, hi, False, False)}, got {f:g}")
            out.append(f)
        return tuple(out)

    def table(self, name: str, required: bool = False) -> Table:
        v = self._get(name, _REQUIRED if required else {})
        if not isinstance(v, Mapping):
            raise self.error(name, f"expected a table, got {show(v)}")
        return Table(v, self._source, self.key(name))

    def raw(self, name: str, default: Any = None) -> Any:
        return self._get(name, default)

    def unknown(self, name: str, known: Iterable[str]) -> ConfigError:
        """The error for key ``name``, which the table does not have: where it is, and the key of ``known``
        it most likely meant, else the keys of ``known`` (:func:`params.text.unknown_key_hint`)."""
        where = f"in [{self._prefix}]" if self._prefix else "at the top level"
        return self.error(name, f"unknown key {where}{unknown_key_hint(str(name), known)}")

    def done(self) -> None:
        unknown = sorted(set(self._data) - self._used.keys())
        if unknown:
            raise self.unknown(unknown[0], self._used)


class _Required:
    pass


_REQUIRED = _Required()


def _range(lo: float | None, hi: float | None, lo_open: bool, hi_open: bool) -> str:
    left = "(" if lo_open or lo is None else "["
    right = ")" if hi_open or hi is None else "]"
    return f"{left}{_bound(lo, '-inf')}, {_bound(hi, 'inf')}{right}"


def _bound(v: float | None, none: str) -> str:
    """A range end as written: integers in full (2147483647, not 2.14748e+09)."""
    if v is None:
        return none
    return str(v) if isinstance(v, int) else f"{v:g}"


def show(v: Any) -> str:
    """A value in a message: its repr (escaped: one line), shortened to 40 characters; an integer of over 40
    digits by its length (``an integer of 401 digits``)."""
    if isinstance(v, int) and not isinstance(v, bool) and abs(v) >= 10**40:
        return f"an integer of {len(str(abs(v)))} digits"
    text = repr(v)
    return text if len(text) <= 40 else text[:37] + "..."


def json_show(v: Any) -> str:
    """A value read from a JSON file (a QGroundControl plan) in a message: JSON's own words for its constants
    (``null``, ``true``, ``false``: it read ``None``), anything else as :func:`show` shows it."""
    if v is None or isinstance(v, bool):
        return json.dumps(v)
    return show(v)


def _printable(text: str, cap: int | None = None) -> str:
    """A key, a dotted path of keys or a file's path in a message: as it is if printable, else its repr, in full
    (``'A\\nB'``), so that a newline or another control character in it never breaks the message's line. With
    ``cap``, one of over ``cap`` characters by its start and end and its length (a key: a 100 000-character one was
    echoed whole; a file's path is shown whole, as the system names it)."""
    shown = text if text.isprintable() else repr(text)
    if cap is None or len(shown) <= cap:
        return shown
    return f"{shown[:cap // 2]}...{shown[-cap // 4:]} ({len(text)} characters)"


KEY_SHOWN_MAX = 300  # characters of a key a message shows whole


def dump_toml(data: Mapping[str, Any]) -> str:
    """Render nested dicts of numbers, strings, booleans and lists as TOML text.

    Enough for what this project writes back (missions as flown): scalar keys first, then
    sub-tables; lists of tables are written inline.
    """
    lines: list[str] = []
    _dump_table(data, [], lines)
    return "\n".join(lines).strip() + "\n"


def _dump_table(data: Mapping[str, Any], path: list[str], lines: list[str]) -> None:
    scalars = {k: v for k, v in data.items() if not isinstance(v, Mapping)}
    tables = {k: v for k, v in data.items() if isinstance(v, Mapping)}
    if path and (scalars or not tables):
        lines.append("")
        lines.append("[" + ".".join(_key(p) for p in path) + "]")
    for k, v in scalars.items():
        lines.append(f"{_key(k)} = {_value(v)}")
    for k, v in tables.items():
        _dump_table(v, [*path, k], lines)


def _key(k: str) -> str:
    return k if k.replace("_", "").replace("-", "").isalnum() else '"' + k.replace('"', '\\"') + '"'


def _value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return repr(v) if math.isfinite(v) else ("nan" if v != v else ("inf" if v > 0 else "-inf"))
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n") + '"'
    if isinstance(v, Mapping):
        return "{ " + ", ".join(f"{_key(k)} = {_value(x)}" for k, x in v.items()) + " }"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {type(v).__name__} as TOML")
