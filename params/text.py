"""Text from elsewhere made one line: the one way a message that quotes a user's code (its exception, a repr of
what it returned) or a failed cell's reason is kept to the one line its record allows.

In:  any text (an exception's message, a ``repr``), the most characters it may keep; a number's text as a person
     types it (a flag's value, a field of a trace or a waypoint file)
Out: the text on one line: every run of whitespace (line breaks, tabs) one space; one over ``cap`` characters cut
     to ``cap``, ending ``...``; the number (:func:`number`, :func:`whole`), ValueError if it is none

(A module of its own: ``params/__init__.py`` is at its 500 lines.)
"""

from __future__ import annotations

ONE_LINE_MAX = 300  # characters of a quoted message a line keeps (a sweep's error cell, a law's raise)


def one_line(text: str, cap: int = ONE_LINE_MAX) -> str:
    """``text`` on one line of at most ``cap`` characters: an ``events.log`` event, an error on stderr, a sweep's
    ``error`` cell are one line each, and a law's ``raise ValueError(f"singular:\\n{matrix}")`` or a numpy
    array's repr spans several."""
    flat = " ".join(text.split())
    return flat if len(flat) <= cap else flat[:cap - 3] + "..."


def number(text: str) -> float:
    """A number's text as a person types it: what ``float()`` takes (``1``, ``-1.5e3``, ``nan``, ``inf``, spaces
    around) but its digit separators, ``1_000``, which Python reads as 1000 and a person's ``1_0`` is a slip (the
    one way a flag's, a trace's or a waypoint file's number is read); ValueError otherwise."""
    if "_" in text:
        raise ValueError(f"could not convert string to float: {text!r}")
    return float(text)


def whole(text: str) -> int:
    """An integer's text as :func:`number` reads a number's: ``int()`` without its digit separators."""
    if "_" in text:
        raise ValueError(f"invalid literal for int() with base 10: {text!r}")
    return int(text)
