"""The class of a cell: the thresholds (:class:`Classes`) and the rules (:func:`classify`).

In:  a ``cells.csv`` row (``outcome``, ``rms`` m, ``ripple_u2`` N) and the thresholds (``[classes]``:
     ``clean_rms_m`` m, ``diverged_rms_m`` m, ``ripple_u2`` N)
Out: its class name, one of :data:`CLASSES`; the rules as Markdown table rows

Classes, best to worst: ``clean``, ``degraded``, ``limit-cycling``, ``failsafe``,
``diverged``, ``crashed``, ``error`` (the rules are in :mod:`bridge.sweep.report`'s docstring and in
:func:`classify`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any

from params import ConfigError, Table

CLASSES = ("clean", "degraded", "limit-cycling", "failsafe", "diverged", "crashed", "error")  # best to worst
# the outcomes of a flight that ended on the ground or against another vehicle before its end: measured (a result, as
# a diverged one is), never ``error`` (which is a cell that could not be flown, its ``error`` column saying why)
CRASHED = ("crashed", "collision", "terminated")


@dataclass(frozen=True)
class Classes:
    """Thresholds that class a cell (the rules: :func:`classify`).

    ``clean_rms_m``: 3-D RMS error (m) up to which a cell is clean; ``diverged_rms_m``: RMS (m)
    above which it counts as diverged even if the plant's own check did not trip;
    ``ripple_u2``: high-frequency RMS of u2 (N, see :func:`ripple_rms`) above which the
    attitude loop is limit-cycling.
    """

    clean_rms_m: float = 1e-3
    diverged_rms_m: float = 1.0
    ripple_u2: float = 20.0

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (0.0 < v < math.inf):
                raise ConfigError(f"classes.{f.name}: must be a positive number, got {v!r}")
        why = _order_problem(self.clean_rms_m, self.diverged_rms_m)
        if why:
            raise ConfigError(f"classes.diverged_rms_m: {why}")

    @classmethod
    def of(cls, value: object) -> Classes:
        """A Python caller's ``classes=``: None (the defaults), a :class:`Classes`, or a mapping of its thresholds
        (``{"clean_rms_m": 0.01}``; an unknown key named). Anything else is a TypeError naming ``classes`` (a dict
        raised ``AttributeError: 'dict' object has no attribute 'diverged_rms_m'`` until the forty-third session)."""
        if value is None or isinstance(value, Classes):
            return value or cls()
        if not isinstance(value, Mapping):
            raise TypeError(f"classes: expected a Classes or a mapping of its thresholds, got {value!r}"[:200])
        names = [f.name for f in fields(cls)]
        unknown = [k for k in value if k not in names]
        if unknown:
            raise ConfigError(f"classes.{unknown[0]}: unknown threshold; allowed: {', '.join(names)}"[:200])
        return cls(**value)

    @classmethod
    def from_table(cls, t: Table) -> Classes:
        d = cls()
        values = {f.name: t.number(f.name, getattr(d, f.name), lo=0.0, lo_open=True, hi=1e9) for f in fields(cls)}
        # the key the file gave (clean_rms_m given alone can clash with diverged_rms_m's default), the file named
        key = "clean_rms_m" if t.has("clean_rms_m") and not t.has("diverged_rms_m") else "diverged_rms_m"
        why = _order_problem(values["clean_rms_m"], values["diverged_rms_m"], key,
                             not t.has("clean_rms_m" if key == "diverged_rms_m" else "diverged_rms_m"))
        if why:
            raise t.error(key, why)
        t.done()
        return cls(**values)


def _order_problem(clean: float, diverged: float, key: str = "diverged_rms_m", default: bool = False) -> str | None:
    """Why these thresholds cannot class a cell (a diverged RMS at or below the clean one), said of ``key``; None if
    they can. ``default``: the other threshold is its default, not given."""
    if diverged > clean:
        return None
    than, other, v, got = (("larger", "clean_rms_m", clean, diverged) if key == "diverged_rms_m"
                           else ("smaller", "diverged_rms_m", diverged, clean))
    return f"must be {than} than classes.{other} ({v:g} m{', its default' if default else ''}), got {got:g} m"


def classify(row: Mapping[str, Any], classes: Classes) -> str:
    """The class of one row (see the module docstring for the rules)."""
    outcome = row["outcome"]
    rms = row.get("rms")
    if outcome in CRASHED:  # what happened, whatever its RMS (its error is the fall's)
        return "crashed"
    if outcome not in ("completed", "failsafe", "diverged"):
        return "error"
    if outcome == "diverged" or (rms is not None and rms > classes.diverged_rms_m):
        return "diverged"
    if outcome == "failsafe":
        return "failsafe"
    ripple = row.get("ripple_u2")
    if ripple is not None and ripple > classes.ripple_u2:
        return "limit-cycling"
    if rms is None or rms > classes.clean_rms_m:
        return "degraded"
    return "clean"


def thresholds_text(c: Classes) -> list[str]:
    """The class rules with their thresholds, as Markdown table rows."""
    return [
        "| class | rule |",
        "|---|---|",
        "| clean | none of the below |",
        f"| degraded | 3-D RMS position error > {c.clean_rms_m:g} m |",
        f"| limit-cycling | ripple of u2 > {c.ripple_u2:g} N (RMS of u2 about its 0.2 s moving average, "
        "second half of the flight) |",
        "| failsafe | the vehicle's failsafe took over (outcome `failsafe`) |",
        f"| diverged | the plant's divergence check tripped, or 3-D RMS > {c.diverged_rms_m:g} m |",
        "| crashed | the flight ended on the ground or against another vehicle: outcome `crashed` (it hit the "
        "ground too hard), `collision` (a fleet's vehicles touched) or `terminated` (its motors cut) |",
        "| error | the cell could not be flown (see the `error` column) |",
    ]
