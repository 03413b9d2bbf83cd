"""The one interface every control law implements, the laws by name, and a user's own law.

A law is a class built as ``Law(nominal, gains, rate_hz)`` and stepped once per control
period by :class:`controller.Controller`:

1. ``update(t, state, ref, omega_d)`` -> the inputs ``(u1, u2, u3, u4)``: collective thrust
   u1 in N and the torque inputs u2, u3, u4 in N (the model has (l/I)·u, eq. 6, so the
   torques are l·u in N m), in the paper frame. ``t`` is mission time (s); ``state`` the
   12 states of eq. (7) in their order
   (x, ẋ, y, ẏ, z, ż in m and m/s; φ, φ̇, θ, θ̇, ψ, ψ̇ in rad and rad/s); ``ref`` the
   reference sample: for x, y, z (m) and ψ (rad) each a tuple of the value and its first
   four time derivatives; ``omega_d`` the signed rotor speed sum of eq. (5) (rad/s) for the
   gyroscopic term.
2. ``advance(saturated, hold)``: step the law's integrators over one period; ``saturated``
   says per input whether the actuation clipped it (anti-windup), ``hold`` freezes them
   (a stale state: see :mod:`controller.link_guard`).
3. ``reset()``: forget the integrators (a re-arm).

and it exposes ``desired`` = (φ_d, θ_d) in rad, the attitude its outer loop asked for, which
goes to the trace. ``bsst``, ``smc`` and ``pid`` are the built-in laws; any other class that
fits is flown with ``--controller path/to/file.py:ClassName`` or
``--controller package.module:ClassName`` (``examples/my_law.py`` is a template).

In:  a law spec (built-in name, ``file.py:Class``, ``module:Class``) or factory; the nominal model, gains,
     control rate (Hz)
Out: a built law that fits :class:`Law` (units in the list above), or a one-line ConfigError; a user's law is
     flown inside :class:`CheckedLaw`, which turns its failures in flight (a raise, ``SystemExit`` too; inputs
     that are not four finite numbers; a ``desired`` gone bad) into :class:`LawFailed`; which laws a discretization
     steps (:data:`DISCRETIZED`: ``bsst`` alone) and :func:`discretization_problem`

A user's law that cannot be loaded (its import or its constructor raises, ``SystemExit`` included) is bad input:
nothing is flown (exit 2). One that fails in flight ends the flight ``law_failed`` (docs/usage.md, "Plug in your own
law"). What the law's code says (its exception's message, a repr of what it returned) is quoted on one line
(:func:`params.text.one_line`): the error and the ``events.log`` event stay one line each.
"""

from __future__ import annotations

import hashlib
import importlib
import importlib.util
import inspect
import math
import os
import stat
import sys
import traceback
from collections.abc import Callable, Iterable, Iterator, Mapping
from collections.abc import Set as AbstractSet
from contextlib import contextmanager
from functools import partial
from numbers import Real
from pathlib import Path
from types import ModuleType, TracebackType
from typing import NoReturn, Protocol, runtime_checkable

from controller.bsst import BacksteppingSuperTwisting
from controller.gains import Gains
from controller.nominal import Nominal
from controller.pid import CascadedPid
from missions import CONTROLLERS, DEFAULT_DISCRETIZATION
from missions.references import Sample
from params import ConfigError, read_regular_file
from params.text import one_line

Quad = tuple[float, float, float, float]


@runtime_checkable
class Law(Protocol):
    """What a control law takes and gives (see the module docstring for units and frames)."""

    desired: tuple[float, float]  # (phi_d, theta_d) rad: the attitude the outer loop asks for

    def update(self, t: float, state: tuple[float, ...], ref: Sample, omega_d: float) -> Quad:
        """The inputs (u1, u2, u3, u4), all in N, for ``state`` at mission time ``t`` (s)."""
        ...

    def advance(self, saturated: tuple[bool, bool, bool, bool], hold: bool = False) -> None:
        """Step the integrators over one control period."""
        ...

    def reset(self) -> None:
        """Forget the integrators."""
        ...


LawFactory = Callable[[Nominal, Gains, float], Law]  # (nominal, gains, rate_hz) -> a law

BUILTIN: dict[str, LawFactory] = {
    "bsst": BacksteppingSuperTwisting,
    "smc": partial(BacksteppingSuperTwisting, reaching="sign"),
    "pid": CascadedPid,
}
assert tuple(BUILTIN) == CONTROLLERS  # the names a mission may give are the laws built in here
_METHODS = ("update", "advance", "reset")


def is_number(v: object) -> bool:
    """Whether ``v`` is a finite real number as the contract means it: an int or a float (numpy's too), never a
    bool (numpy's ``bool_`` neither), a complex, a string or None."""
    if type(v) is float:  # the common case, first: a law's every step
        return math.isfinite(v)
    if not isinstance(v, Real) or isinstance(v, bool):
        return False
    try:
        return math.isfinite(v)
    except (TypeError, ValueError, OverflowError):  # a Real of the user's own whose float() fails
        return False


def law_problem(law: object) -> str | None:
    """Why ``law`` (a built law) does not fit :class:`Law`, or None if it does."""
    for name in _METHODS:
        if not callable(getattr(law, name, None)):
            return f"has no method {name}()"
    desired = getattr(law, "desired", None)
    if not (isinstance(desired, tuple) and len(desired) == 2 and all(is_number(v) for v in desired)):
        return f"its 'desired' must be a tuple (phi_d, theta_d) of two finite numbers, got {_shown(desired)}"
    return None


class LawError(ConfigError):
    """A law that cannot be flown (bad input, one line): ``where`` it was named (``controller 'SPEC'``, then where
    the spec came from: :func:`bridge.core.flight.prepare` names the mission's key or the ``--controller`` flag)
    and ``what`` is wrong with it."""

    def __init__(self, spec: str, what: str, where: str | None = None) -> None:
        self.where = where or f"controller {spec!r}"
        self.spec = spec
        super().__init__(f"{self.where}: {what}", what=what)


def is_builtin(spec: str) -> bool:
    return spec in BUILTIN


DISCRETIZED = ("bsst",)  # the laws with a super-twisting step for a discretization to step (docs/law.md)


def discretization_problem(laws: Iterable[str]) -> str | None:
    """Why a discretization changes nothing in a flight (or a campaign's cells) of these law specs: none of them
    is ``bsst``, the one law with a super-twisting step (``smc``'s sign, ``pid`` and a user's law have none).
    None when one of them is."""
    names = sorted(set(laws))
    if any(law in DISCRETIZED for law in names):
        return None
    flown = f"{names[0]} flies" if len(names) == 1 else f"{', '.join(names[:-1])} and {names[-1]} fly"
    return f"only bsst has a super-twisting step to discretize: {flown} the same under both (docs/law.md)"


def resolve_law(spec: str) -> LawFactory:
    """The factory of the law named ``spec``: a built-in name, ``path/to/file.py:ClassName`` or
    ``package.module:ClassName``. :class:`ConfigError` naming what is wrong (the file, the
    module, the class) otherwise; the class's fit is checked by :func:`make_law`."""
    if spec in BUILTIN:
        return BUILTIN[spec]
    where, sep, cls_name = spec.rpartition(":")
    if not sep or not where or not cls_name.isidentifier():
        raise LawError(spec, f"must be one of {', '.join(BUILTIN)}, "
                          "or path/to/file.py:ClassName, or package.module:ClassName")
    if where.endswith(".py") or "/" in where or "\\" in where:
        module = _load_file(Path(where), spec)
    elif os.path.isfile(where):  # probe.txt:Probe, a file here that an import would not take for a module
        raise LawError(spec, f"{where} is not a .py file (a law is path/to/file.py:ClassName "
                          "or package.module:ClassName)")
    else:
        try:
            with RefusedExit(), imports_from():
                module = importlib.import_module(where)
        except ModuleNotFoundError as exc:
            raise LawError(spec, f"no module named {exc.name!r}") from None
        except (Exception, SystemExit, ExitCalled) as exc:  # the user's module raised (or exited) importing: one line
            raise LawError(spec, f"importing {where} {did(exc)}") from None
    cls = getattr(module, cls_name, None)
    if cls is None:
        raise LawError(spec, f"{where} has no class {cls_name!r}")
    if not inspect.isclass(cls):
        raise LawError(spec, f"{cls_name} is not a class")
    missing = [m for m in _METHODS if not callable(getattr(cls, m, None))]
    if missing:
        raise LawError(spec, f"{cls_name} does not fit the Law interface "
                          f"(controller/law.py): no method {missing[0]}()")
    return cls


@contextmanager
def imports_from(folder: str | None = None) -> Iterator[None]:
    """Imports inside look in ``folder`` first (default: the working directory, as documented for ``module:Class``,
    docs/usage.md: ``python -m bridge`` has it first on ``sys.path``, the ``bsst`` console script its own folder, a
    script using the API its script's folder; a law file's own folder while it loads, as Python runs a script).
    Only for the import: the process's ``sys.path`` is left as it was."""
    here = os.getcwd() if folder is None else folder
    sys.path.insert(0, here)
    try:
        yield
    finally:
        if here in sys.path:  # (the import may have taken it out itself)
            sys.path.remove(here)  # its first entry: ours, unless the import put the very same folder before it


def _load_file(path: Path, spec: str) -> ModuleType:
    """The module of the law file ``path``, executed once for each content the file has had in this process: a
    sweep's hundreds of flights of one law load it once, and an edited file is flown at its next flight (keyed
    on the path and the bytes, as ``plant.profiles`` keys a profile; an edit that keeps the file's time and
    size is seen too). The bytes hashed are the bytes run."""
    try:
        mode = path.stat().st_mode
    except FileNotFoundError:
        raise LawError(spec, f"no file {path}") from None
    except OSError as exc:
        raise LawError(spec, f"cannot read {path} ({exc.strerror})") from None
    if stat.S_ISDIR(mode):
        raise LawError(spec, f"{path} is a directory, not a Python file")
    if not stat.S_ISREG(mode):  # (a FIFO would block the import for ever)
        raise LawError(spec, f"{path} is not a regular file, not a Python file")
    if path.suffix != ".py":
        raise LawError(spec, f"{path} is not a .py file")
    try:
        source = read_regular_file(path, "a Python file")  # (records it as an input: never replaced by --overwrite)
    except ConfigError as exc:  # swapped for a FIFO, unreadable: said as read_regular_file says it
        raise LawError(spec, str(exc)) from None
    digest = hashlib.sha256(str(path.resolve()).encode() + b"\0" + source).hexdigest()
    name = f"bsst_user_law_{digest[:20]}"
    if name in sys.modules:
        return sys.modules[name]
    mod_spec = importlib.util.spec_from_file_location(name, path)
    if mod_spec is None:
        raise LawError(spec, f"{path} is not a Python file")
    module = importlib.util.module_from_spec(mod_spec)
    sys.modules[name] = module  # (a dataclass, a pickle look their module up while it runs)
    folder, before = path.resolve().parent, set(sys.modules)
    try:
        with RefusedExit(), imports_from(str(folder)):  # (a module beside it: imported as a script's)
            exec(compile(source, str(path), "exec", dont_inherit=True), module.__dict__)
    except (Exception, SystemExit, ExitCalled) as exc:  # a syntax error, a raise or an exit in the file: one line
        del sys.modules[name]
        raise LawError(spec, f"loading {path} {did(exc)}") from None
    finally:
        _forget_beside(set(sys.modules) - before - {name}, folder)
    return module


def _forget_beside(imported: set[str], folder: Path) -> None:
    """The modules a law file imported from its own folder (``imported``: the names new in ``sys.modules``) are its
    own: forgotten once it has loaded (it keeps them), so that another law file's module of the same name beside
    it, or this one's edited, is imported afresh (one folder's ``helpers`` was another's)."""
    for mod_name in imported:
        where = getattr(sys.modules.get(mod_name), "__file__", None)
        if where and Path(where).resolve().is_relative_to(folder):
            del sys.modules[mod_name]


def make_law(spec: str | LawFactory, nominal: Nominal, gains: Gains, rate_hz: float,
             discretization: str = DEFAULT_DISCRETIZATION) -> Law:
    """Build the law ``spec`` (a name of :func:`resolve_law`, or a factory) and check that it fits.
    ``discretization`` (controller.bsst.DISCRETIZATIONS) reaches the super-twisting law ``bsst``; the
    others (``smc``'s sign, ``pid``, a user's law) have no super-twisting step to discretize."""
    factory = resolve_law(spec) if isinstance(spec, str) else spec
    label = spec if isinstance(spec, str) else _label(spec)
    try:
        if factory is BacksteppingSuperTwisting:
            law = BacksteppingSuperTwisting(nominal, gains, rate_hz, discretization=discretization)
        else:
            with RefusedExit():
                law = factory(nominal, gains, rate_hz)
    except (Exception, SystemExit, ExitCalled) as exc:  # the user's constructor (an exit too): one line naming it
        raise LawError(label, f"building it as ({label.rpartition(':')[2]})(nominal, gains, "
                          f"rate_hz) {did(exc)}") from None
    why = law_problem(law)
    if why:
        raise LawError(label, f"does not fit the Law interface (controller/law.py): {why}")
    return law if factory in BUILTIN.values() else CheckedLaw(law, label)


class ExitCalled(BaseException):
    """A user's law called ``os._exit(code)`` while bsst ran its code (:class:`RefusedExit`): raised instead, so
    that the process stays and the law's failure is recorded as a raise is. A BaseException, as SystemExit is:
    the law's own ``except Exception`` does not swallow it."""

    def __init__(self, code: object) -> None:
        super().__init__(f"os._exit({code!r})")
        self.code = code


_REAL_EXIT = os._exit
_refusing = False  # a user's law code runs now, under RefusedExit, in this process


def _refused_exit(code: int) -> NoReturn:
    """``os._exit`` while a user's law code runs: :class:`ExitCalled`; else (a process the law forked, a name the
    law bound under the guard and called outside it) the process ends as asked."""
    if not _refusing:
        _REAL_EXIT(code)
    raise ExitCalled(code)


def _forked() -> None:
    global _refusing
    _refusing = False  # a child the law forked is not the flight's process


os.register_at_fork(after_in_child=_forked)


class RefusedExit:
    """``with RefusedExit():`` runs a user's law code (loading, building, each call) with ``os._exit`` raising
    :class:`ExitCalled`: a law that ended the process would leave no record and exit 0 (bsst is one thread; what
    the law binds under this guard, ``from os import _exit`` at import, is refused too). A signal, ``os.abort()``
    or a crash in a C extension still ends the process: ``bsst sim`` flies a user's law in a watched child
    process for those (bridge.nodes.watched)."""

    def __enter__(self) -> None:
        global _refusing
        self._saved = (os._exit, _refusing)
        os._exit, _refusing = _refused_exit, True

    def __exit__(self, kind: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        global _refusing
        os._exit, _refusing = self._saved


def did(exc: BaseException) -> str:
    """What a user's code did, for the one line: ``called os._exit(0)`` or ``raised Kind: message (in file.py:N)``,
    the line the innermost frame outside Python's own installation was at (:func:`where_raised`)."""
    if isinstance(exc, ExitCalled):
        return f"called os._exit({exc.code!r})"
    said = one_line(str(exc))  # (a message of several lines, a matrix printed in it: one line all the same)
    at = where_raised(exc)
    return (f"raised {type(exc).__name__}: {said}" if said else f"raised {type(exc).__name__}") + \
        (f" (in {at})" if at else "")


def where_raised(exc: BaseException) -> str | None:
    """``file.py:N`` of the innermost frame of ``exc``'s traceback that is not Python's own or an installed
    package's (under ``sys.prefix`` or ``sys.base_prefix``): the user's line that raised, or that called numpy
    when numpy raised; None when there is none (a SyntaxError at load names its own line)."""
    if isinstance(exc, SyntaxError):
        return None
    frames = traceback.extract_tb(exc.__traceback__)
    ours = tuple(os.path.join(p, "") for p in (sys.prefix, sys.base_prefix))  # (with the separator: not .venv2/)
    mine = [f for f in frames if not f.filename.startswith(ours)]
    return f"{os.path.basename(mine[-1].filename)}:{mine[-1].lineno}" if mine else None


class LawFailed(Exception):
    """A user's law failed in flight: ``label`` (its spec) and ``what`` it did (one line)."""

    def __init__(self, label: str, what: str) -> None:
        super().__init__(f"controller {label!r}: {what}")
        self.label = label
        self.what = what


def _inputs(u: object) -> tuple[Quad | None, str]:
    """``u`` as four finite floats, or None and why not: not a sequence of four (a string, None, another length),
    or a value that is no finite real number (inf, nan, a bool, a complex, a string: :func:`is_number`)."""
    if isinstance(u, (str, bytes)) or u is None:
        return None, "not a sequence of four numbers"
    if isinstance(u, (Mapping, AbstractSet)):  # its keys, or its items in no set order: never flown as u1..u4
        kind = "a mapping" if isinstance(u, Mapping) else "unordered"
        return None, f"a {type(u).__name__}: {kind}, not a sequence of four numbers"
    try:
        given = tuple(u)  # type: ignore[call-overload]
    except Exception:  # not iterable, or its own iteration raised
        return None, "not a sequence of four numbers"
    if len(given) != 4:
        return None, f"{len(given)} values, not 4"
    for i, v in enumerate(given):
        if not is_number(v):
            what = (f"is {v!r}, not a finite number" if isinstance(v, Real) and not isinstance(v, bool)
                    else f"is a {type(v).__name__}, not a number")
            return None, f"u{i + 1} {what}"
    return tuple(map(float, given)), ""  # type: ignore[return-value]


class CheckedLaw:
    """A user's law as the loop flies it: each call's failure (a raise, ``SystemExit`` included, but not
    Ctrl-C) and each ``update`` that is not four finite numbers, or that leaves ``desired`` bad, is a
    :class:`LawFailed` naming what it did. The built-in laws are flown bare (their arithmetic is the reference)."""

    def __init__(self, law: Law, label: str) -> None:
        self.law = law
        self.label = label

    @property
    def desired(self) -> tuple[float, float]:
        return self.law.desired

    def __getattr__(self, name: str) -> object:  # the law's own attributes (its integrators, ...) read through
        if name == "law":  # not set yet (a copy being built): no recursion
            raise AttributeError(name)
        return getattr(self.law, name)

    def _call(self, method: str, *args: object) -> object:
        global _refusing
        saved = os._exit, _refusing  # RefusedExit, written out: every step's two calls
        os._exit, _refusing = _refused_exit, True
        try:
            return getattr(self.law, method)(*args)
        except (Exception, SystemExit, ExitCalled) as exc:
            raise LawFailed(self.label, f"{method}() {did(exc)}") from None
        finally:
            os._exit, _refusing = saved

    def update(self, t: float, state: tuple[float, ...], ref: Sample, omega_d: float) -> Quad:
        u = self._call("update", t, state, ref, omega_d)
        values, why = _inputs(u)
        if values is None:
            raise LawFailed(self.label, "update() must return four finite numbers (u1, u2, u3, u4) in N, "
                                        f"got {_shown(u)} ({why})")
        why = law_problem(self.law)
        if why:
            raise LawFailed(self.label, f"after update(): {why}")
        return values

    def advance(self, saturated: tuple[bool, bool, bool, bool], hold: bool = False) -> None:
        self._call("advance", saturated, hold)

    def reset(self) -> None:
        self._call("reset")


def _shown(value: object) -> str:
    """What a law gave, in its message: its repr on one line of at most 80 characters (a numpy column spans
    several)."""
    return one_line(repr(value), 80)


def _label(factory: LawFactory) -> str:
    """``file.py:Class`` of a law class (what a user would have written), else its repr."""
    try:
        return f"{inspect.getfile(factory)}:{factory.__qualname__}"  # type: ignore[arg-type, union-attr]
    except (TypeError, AttributeError, OSError):
        return repr(factory)
