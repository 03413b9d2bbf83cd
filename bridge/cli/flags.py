"""The command line's flag types: each checks its range and names the flag in its error (the link-impairment
flags themselves, with the ``[link]`` overrides read back from them, are :mod:`bridge.cli.linkflags`).

In:  command-line text (link values in ms, %, packets, bytes/s; ``--blackout START:DURATION`` s;
     ``--rate`` Hz; ``--speed`` x real time; ``--home`` degrees, degrees, m AMSL; ``--param NAME=VALUE``
     in the parameter's unit, an INT32's value an integer)
Out: parsed values, each checked against its range (a bad one is a :class:`~params.ConfigError` whose ``source``
     is the flag and ``what`` the reason, :class:`FlagRefusal`: exit 2); the exit statuses

The ranges are the mission loader's (:data:`bridge.link.model.NUMBER_RANGES`), one per key.
"""

from __future__ import annotations

import argparse
import re
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, NoReturn

from params import ConfigError, likely, path_problem, unreachable
from params.text import number, whole

EXIT_OK, EXIT_FAILED, EXIT_BAD_INPUT = 0, 1, 2


class UsageError(Exception):
    """Bad command-line input (exit 2), one line that opens with its command: ``command`` (``bsst``, ``bsst relay``)
    and ``what`` is wrong, typed (``str()``: ``command: what``), so that a reader (:func:`bridge.cli.main`'s report to
    a session) never cuts the command off the text."""

    def __init__(self, command: str, what: str) -> None:
        super().__init__(f"{command}: {what}")
        self.command, self.what = command, what

    def __reduce__(self) -> tuple[type[UsageError], tuple[str, str]]:
        return type(self), (self.command, self.what)  # (pickled whole: a process pool's)


class FlagRefusal(argparse.ArgumentTypeError):
    """A flag type's refusal, typed (:meth:`params.ConfigError.at`): ``source`` the flag (with the value it names, if
    its message opens with both: ``--param 'X=1'``), ``what`` the bare reason; its message as it always read, ``flag
    what`` (``--rate must be in [50, 1000], got 5``) or, ``sep=": "``, ``flag: what``. The parser raises
    :attr:`refused` (:meth:`_Parser.parse_known_args`)."""

    def __init__(self, flag: str, what: str, sep: str = " ") -> None:
        self.refused = ConfigError.at(flag, None, what, sep=sep)
        super().__init__(str(self.refused))


def as_config_error(exc: UsageError | ConfigError) -> ConfigError:
    """A refusal as the typed :class:`~params.ConfigError` it is said from (:func:`bridge.cli.main`: ``bsst: `` before
    it, unless its ``source`` is its command): a usage error's command its ``source`` (``bsst relay``; ``bsst`` alone
    is the ``bsst: `` every line opens with: no source), its ``what`` the rest."""
    if isinstance(exc, ConfigError):
        return exc
    if exc.command == "bsst":
        return ConfigError(exc.what, what=exc.what)
    return ConfigError(str(exc), source=exc.command, what=exc.what)


def opens_with_command(exc: ConfigError) -> bool:
    """Whether a refusal opens with the command it refuses for (its typed ``source``, ``bsst link extract``: a part's
    own, raised for that command), not with a file or flag (``bsstm.toml: no such file`` was once printed bare)."""
    words = (exc.source or "").split(" ")
    return len(words) > 1 and words[0] == "bsst"


def refusal_line(exc: ConfigError) -> str:
    """The one line ``bsst`` says a refusal in (exit 2): ``bsst: `` and it, or it alone when it opens with its
    command (:func:`opens_with_command`)."""
    return str(exc) if opens_with_command(exc) else f"bsst: {exc}"


FLAG_CUTOFF = 0.75  # difflib's ratio from which a known flag is suggested (--dealy: --delay 0.86; --compensation
# to bsst relay: --mission 0.70, not one to suggest)
UNRECOGNIZED_IN = "_bsst_unrecognized_in"  # on the namespace: the (sub-)parser that met an unknown flag first
# a command whose stdout is its reports (``bsst vehicle``, ``controller``, ``relay``: bridge.nodes.report, a session's
# children), as its parser declares it (``add_parser(..., reports=True)``): on its namespace, and on a refusal raised
# while its parser parsed; its refusal is then one of its reports too (bridge.cli.main: :func:`reports`)
REPORTS = "_bsst_reports"


def reports(*of: object) -> bool:
    """Whether a command's namespace, or a refusal raised while its parser parsed, says its stdout is reports."""
    return any(getattr(x, REPORTS, False) for x in of)


# a word that starts with a minus and a number (a digit, a point and a digit, inf or nan) is a value, never a flag (no
# flag of bsst's is one): argparse takes only a plain negative number so, and read ``--at -1:wind:3``, ``--at
# -.5:gps:off``, ``--home -33.9,151.2,20`` or ``--blackout -1:2`` as a flag with its value missing ("expected one
# argument") where the flag's own check names what is wrong, or takes it
VALUE_NOT_FLAG = re.compile(r"^-(\.?\d|(inf|nan)([:,=]|$))", re.IGNORECASE)


CLASH = "not allowed with argument "  # argparse's words for two flags of a mutually exclusive group


class _Parser(argparse.ArgumentParser):
    def __init__(self, *args: Any, reports: bool = False, **kwargs: Any) -> None:
        kwargs.setdefault("exit_on_error", False)  # a bad value raises here, to be said in the house's words (refusal)
        super().__init__(*args, **kwargs)
        self.reports = reports  # its command's stdout is reports (REPORTS)
        if reports:
            self.set_defaults(**{REPORTS: True})
        # argparse's own test of "a negative number, so a value" (an attribute of every parser and sub-parser since
        # Python 3.2; tests/test_cli.py pins what it does here)
        self._negative_number_matcher = VALUE_NOT_FLAG

    def error(self, message: str) -> NoReturn:  # one line, no usage dump
        raise UsageError(self.prog, message)

    def parse_known_args(self, args: Sequence[str] | None = None,  # type: ignore[override]
                         namespace: argparse.Namespace | None = None) -> tuple[argparse.Namespace, list[str]]:
        """As argparse's; a sub-command's parser that is left with an unknown flag records itself on the
        namespace (the innermost first), so that the error names that command and suggests its flags."""
        try:
            ns, extras = super().parse_known_args(args, namespace)
        except argparse.ArgumentError as exc:
            if isinstance(exc.__context__, FlagRefusal):  # a flag type's (the one place flags are checked): typed
                raise self.marked(exc.__context__.refused) from None
            raise self.marked(UsageError(*self.refusal(exc))) from None
        except (UsageError, ConfigError) as exc:  # (its error(), or a sub-command's parser's)
            self.marked(exc)
            raise
        if any(a.startswith("-") for a in extras) and not hasattr(ns, UNRECOGNIZED_IN):
            setattr(ns, UNRECOGNIZED_IN, self)
        return ns, extras

    def parse_args(self, args: Sequence[str] | None = None,  # type: ignore[override]
                   namespace: argparse.Namespace | None = None) -> argparse.Namespace:
        """As argparse's, and an unknown flag's error adds the command's likely flag: ``did you mean --delay?``."""
        ns, extras = self.parse_known_args(args, namespace)
        where = vars(ns).pop(UNRECOGNIZED_IN, self)
        if extras:
            raise where.marked(UsageError(where.prog, f"unrecognized arguments: {' '.join(extras)}"
                                                      f"{where.flag_hint(extras)}"))
        return ns

    def marked(self, exc: Exception) -> Exception:
        """``exc`` raised while this parser parsed: marked :data:`REPORTS` if its command's stdout is reports."""
        if self.reports:
            setattr(exc, REPORTS, True)
        return exc

    def refusal(self, exc: argparse.ArgumentError) -> tuple[str, str]:
        """A bad value's line as bsst's own refusals read, as a UsageError's two parts (the command it opens with, the
        rest): a flag type's words alone (they name the flag: ``bsst: --vehicles must be in [1, 64], got 0``),
        argparse's own after the flag (``bsst: --at: expected one argument``), or a positional's after its command
        (``bsst link: ACTION: invalid choice: ...``). Argparse said ``bsst sim: argument --vehicles: --vehicles must
        be ...`` (until the third wave's fortieth session). Two flags of a mutually exclusive group: ``bsst:
        --lockstep: not allowed with --realtime: give one of them``."""
        if isinstance(exc.__context__, argparse.ArgumentTypeError):  # (raised by a type of flags.py, which names it)
            return "bsst", exc.message
        name, message = exc.argument_name, exc.message
        if name is None:
            return self.prog, message
        if message.startswith(CLASH):  # two flags of one group (--realtime --lockstep): named as flags are
            message = f"not allowed with {message.removeprefix(CLASH)}: give one of them"
        return "bsst" if name.startswith("-") else self.prog, f"{name}: {message}"

    def flag_hint(self, extras: Sequence[str]) -> str:
        """``; did you mean --delay?`` for the first unknown flag of ``extras`` close to one of this parser's
        flags ('' if none is)."""
        flags = [f for action in self._actions for f in action.option_strings]
        for text in extras:
            if text.startswith("-"):
                name = text.partition("=")[0]
                if name in KEY_NOT_FLAG:  # a mission's key taken for a flag: no flag is like it (--formation was)
                    return f"; {self.prog} has no {name} flag: the mission file's {KEY_NOT_FLAG[name]} sets it"
                like = likely(name, flags, cutoff=FLAG_CUTOFF)
                return f"; did you mean {like}?" if like else ""
        return ""


KEY_NOT_FLAG = {"--duration": "duration_s", "--duration-s": "duration_s"}  # flags a mission's key is asked as


def path_given(name: str) -> Callable[[str], str]:
    """An argparse type: a path that is not empty (an unset shell variable's ``--out "$DIR"`` would be the current
    folder, with ``--overwrite`` the user's own files), named in the error."""
    def conv(text: str) -> str:
        why = path_problem(text, "give one" if not name.startswith("-") else "give one, or leave the flag out")
        if why:
            raise FlagRefusal(name, why, sep=": ")
        return text

    return conv


def int_in(name: str, lo: int, hi: int) -> Callable[[str], int]:
    def conv(text: str) -> int:
        try:
            v = whole(text)
        except ValueError:
            raise FlagRefusal(name, f"must be an integer, got {text!r}") from None
        if not lo <= v <= hi:
            raise FlagRefusal(name, f"must be in [{lo}, {hi}], got {v}")
        return v

    return conv


def number_in(name: str, lo: float, hi: float, *, lo_open: bool = False,
              hi_open: bool = False, unit: str = "") -> Callable[[str], float]:
    """An argparse type: a finite number in [lo, hi] (either end open with ``lo_open`` / ``hi_open``), named in
    the error with its range and ``unit`` (``--delay 20ms``: a number in [0, 10000] ms, the unit not written)."""
    span = f"{'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}" + (f" {unit}" if unit else "")

    def conv(text: str) -> float:
        try:
            v = number(text)
        except ValueError:
            raise FlagRefusal(name, f"must be a number in {span}, got {text!r}") from None
        if not (lo < v if lo_open else lo <= v) or not (v < hi if hi_open else v <= hi):  # also refuses nan
            raise FlagRefusal(name, f"must be in {span}, got {text}")
        return v

    return conv


def pace_speed(flag: str) -> Callable[[str], float]:
    """An argparse type for a lockstep pace, x real time: 0 (as fast as it goes) or within
    :data:`bridge.core.clock.SPEED_RANGE` (:func:`~bridge.core.clock.speed_problem`)."""
    def conv(text: str) -> float:
        from bridge.core.clock import speed_problem  # lazy: building the parser loads no clock code

        try:
            v = number(text)
        except ValueError:
            raise FlagRefusal(flag, f"must be a number, got {text!r}") from None
        why = speed_problem(v)
        if why:
            raise FlagRefusal(flag, why)
        return v

    return conv


def value_list(name: str, lo: float, hi: float) -> Callable[[str], tuple[float, ...]]:
    """``--delay 0,5,10``: comma-separated numbers in [lo, hi], no repeats."""
    def conv(text: str) -> tuple[float, ...]:
        parts = [x.strip() for x in text.split(",")]
        try:
            vals = tuple(number(x) for x in parts)
        except ValueError:
            raise FlagRefusal(name, f"takes numbers separated by commas, got {text!r}") from None
        bad = [v for v in vals if not lo <= v <= hi]  # also catches nan
        if bad or not vals:
            raise FlagRefusal(name, f"values must be in [{lo:g}, {hi:g}], got {text}")
        if len(set(vals)) != len(vals):
            raise FlagRefusal(name, f"repeated value in {text}", sep=": ")
        return vals

    return conv


def name_list(name: str, choices: Sequence[str]) -> Callable[[str], tuple[str, ...]]:
    def conv(text: str) -> tuple[str, ...]:
        vals = tuple(x.strip() for x in text.split(","))
        bad = [v for v in vals if v not in choices]
        if bad or len(set(vals)) != len(vals):
            raise FlagRefusal(name, f"takes distinct names among {','.join(choices)}, got {text!r}")
        return vals

    return conv


def link_seed(flag: str) -> Callable[[str], int]:
    """An argparse type for the link's seed, in :data:`bridge.link.model.SEED_RANGE`."""
    def conv(text: str) -> int:
        from bridge.link.model import SEED_RANGE  # lazy: start-up time

        return int_in(flag, *SEED_RANGE)(text)

    return conv


def blackout_window(name: str) -> Callable[[str], tuple[float, float]]:
    """``START:DURATION`` in seconds of mission time."""
    def conv(text: str) -> tuple[float, float]:
        from bridge.link.model import BLACKOUT_DURATION_RANGE_S, BLACKOUT_START_RANGE_S  # lazy: start-up time

        (s_lo, s_hi), (d_lo, d_hi) = BLACKOUT_START_RANGE_S, BLACKOUT_DURATION_RANGE_S
        a, sep, b = text.partition(":")
        try:
            start, dur = number(a), number(b)
        except ValueError:
            start = dur = float("nan")
        if not sep or not (s_lo <= start <= s_hi and d_lo < dur <= d_hi):
            raise FlagRefusal(name, f"must be START:DURATION in seconds (start in [{s_lo:g}, "
                                    f"{s_hi:g}], duration in ({d_lo:g}, {d_hi:g}]), got {text!r}")
        return start, dur

    return conv


def law_spec(flag: str) -> Callable[[str], str]:
    """An argparse type for a law: a built-in name, ``file.py:Class`` or ``module:Class``
    (checked for its form here; the file, module and class when the flight is built)."""
    def conv(text: str) -> str:
        from missions.mission import law_spec_problem  # lazy: building the parser loads no mission code

        why = law_spec_problem(text)
        if why:
            raise FlagRefusal(flag, why)
        return text

    return conv


def law_list(flag: str) -> Callable[[str], tuple[str, ...]]:
    """``--controller bsst,pid,examples/my_law.py:MyLaw``: distinct laws, comma-separated."""
    def conv(text: str) -> tuple[str, ...]:
        vals = tuple(x.strip() for x in text.split(","))
        if len(set(vals)) != len(vals):
            raise FlagRefusal(flag, f"repeated law in {text!r}", sep=": ")
        return tuple(law_spec(flag)(v) for v in vals)

    return conv


def mission_number(flag: str, key: str) -> Callable[[str], float]:
    """An argparse type for a mission's top-level number (``rate_hz``): in the range the mission
    file allows (:data:`missions.MISSION_RANGES`, looked up when the flag is given)."""
    def conv(text: str) -> float:
        from missions import MISSION_RANGES  # lazy: building the parser loads no mission code

        return number_in(flag, *MISSION_RANGES[key])(text)

    return conv


def mission_integer(flag: str, key: str) -> Callable[[str], int]:
    """As :func:`mission_number`, for an integer (``seed``)."""
    def conv(text: str) -> int:
        from missions import MISSION_RANGES  # lazy: building the parser loads no mission code

        lo, hi = MISSION_RANGES[key]
        return int_in(flag, int(lo), int(hi))(text)

    return conv


def axis_values(flag: str, axis: str) -> Callable[[str], tuple[float, ...]]:
    """An argparse type for a swept axis (``--delay 0,5,10``): each value in the axis's one
    range (:data:`bridge.sweep.grid.RANGES`, the mission loader's), looked up when given."""
    def conv(text: str) -> tuple[float, ...]:
        from bridge.sweep.grid import RANGES  # lazy: only a sweep loads the sweep

        return value_list(flag, *RANGES[axis])(text)

    return conv


LINK_UNITS = {"_ms": "ms", "_pct": "%", "_bps": "bytes/s", "burst_len": "packets"}  # a [link] key's, by its end


def link_number(flag: str, key: str | None = None) -> Callable[[str], float]:
    """An argparse type for a ``[link]`` number: in the range the mission file allows for
    ``key`` (bridge.link.model, looked up when a flag is given, so that building the parser does
    not load the link model; ``None``: the command lag)."""
    def conv(text: str) -> float:
        from bridge.link.model import GUARD_RANGES, HI_OPEN, LO_OPEN, NUMBER_RANGES  # lazy: start-up time

        k = key or "command_lag_ms"
        unit = next((u for end, u in LINK_UNITS.items() if k.endswith(end)), "")
        return number_in(flag, *{**NUMBER_RANGES, **GUARD_RANGES}[k], lo_open=k in LO_OPEN, hi_open=k in HI_OPEN,
                         unit=unit)(text)

    return conv


def param_assignment(flag: str, timed: bool = False) -> Callable[[str], Any]:
    """An argparse type for ``NAME=VALUE`` (``--param``) or ``T:NAME=VALUE`` (``--param-at``): a
    parameter the vehicle has, a value in its one range (bridge.autopilot.params, looked up when given)."""
    def conv(text: str) -> Any:
        from bridge.autopilot.params import BY_NAME, parse_assignment, parse_change, value_problem  # lazy: start-up
        from params import ConfigError  # lazy: start-up time
        from params.text import quoted  # lazy: start-up time

        try:
            got = parse_change(text) if timed else parse_assignment(text)
        except ConfigError as exc:
            raise FlagRefusal(f"{flag} {quoted(text)}", str(exc), sep=": ") from None
        name, value = (got.name, got.value) if timed else got
        why = value_problem(BY_NAME[name], value)
        if why:
            raise FlagRefusal(f"{flag} {quoted(text)}", why, sep=": ")
        return got

    return conv


def system_id(flag: str) -> Callable[[str], int]:
    """An argparse type for the vehicle's system id: MAV_SYS_ID's range (bridge.autopilot.params.SYSID_RANGE)."""
    def conv(text: str) -> int:
        from bridge.autopilot.params import SYSID_RANGE  # lazy: start-up time

        return int_in(flag, *SYSID_RANGE)(text)

    return conv


def sensor_set_name(flag: str) -> Callable[[str], str]:
    """An argparse type for a sensor set's name (``--sensors mocap``): checked for its form here (a
    TOML bare key: letters, digits, ``_``, ``-``); whether the profile has it, when the flight is built."""
    def conv(text: str) -> str:
        if not text or not all(c.isascii() and (c.isalnum() or c in "_-") for c in text):
            raise FlagRefusal(flag, f"takes the name of a sensor set of the profile "
                                    f"(ideal, mocap, gnss), got {text!r}")
        return text

    return conv


def noise_scale(flag: str) -> Callable[[str], float]:
    """An argparse type for the noise scale: in the mission's ``[sensors] noise_scale`` range
    (:data:`plant.profiles.NOISE_SCALE_RANGE`, looked up when the flag is given)."""
    def conv(text: str) -> float:
        from plant.profiles import NOISE_SCALE_RANGE  # lazy: building the parser loads no plant code

        return number_in(flag, *NOISE_SCALE_RANGE)(text)

    return conv



def existing_file(flag: str, text: str) -> str:
    """``text`` as an absolute path to a regular file (relative: to the working directory); an empty one refused as
    :func:`path_given` refuses it (it read ``--link-trace : is not a regular file``)."""
    p = Path(path_given(flag)(text)).expanduser()
    why = unreachable(p)
    if why:
        raise FlagRefusal(f"{flag} {text}", f"cannot read ({why})", sep=": ")
    if not p.is_file():
        raise FlagRefusal(f"{flag} {text}", "is not a regular file" if p.exists() else "no such file", sep=": ")
    return str(p.absolute())


def yes_no(flag: str) -> Callable[[str], bool]:
    """``true|false`` (also yes/no, on/off, 1/0) for a flag that may be given bare (meaning true)."""
    words = {"true": True, "yes": True, "on": True, "1": True, "false": False, "no": False, "off": False, "0": False}

    def conv(text: str) -> bool:
        v = words.get(text.strip().lower())
        if v is None:
            raise FlagRefusal(flag, f"takes true or false (or yes/no, on/off, 1/0), got {text!r}")
        return v

    return conv


def _ids(text: str) -> tuple[int, int]:
    a, sep, b = text.partition(":")
    try:
        ids = (whole(a), whole(b))
    except ValueError:
        ids = (-1, -1)
    if not sep or not (1 <= ids[0] <= 255 and 0 <= ids[1] <= 255):
        raise FlagRefusal("--controller-id", f"must be SYSID:COMPID (1-255:0-255), got {text!r}")
    return ids


def _home(text: str) -> tuple[float, float, float]:
    try:
        lat, lon, alt = (number(x) for x in text.split(","))
    except ValueError:
        raise FlagRefusal("--home", f"must be LAT,LON,ALT in degrees and metres, got {text!r}") from None
    if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0 and -1000.0 <= alt <= 10000.0):
        raise FlagRefusal("--home", f"out of range (lat [-90, 90], lon [-180, 180], alt [-1000, 10000]), "
                                    f"got {text!r}")
    return lat, lon, alt

