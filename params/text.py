"""Text from elsewhere made one line: the one way a message that quotes a user's code (its exception, a repr of
what it returned) or a failed cell's reason is kept to the one line its record allows.

In:  any text (an exception's message, a ``repr``), the most characters it may keep
Out: the text on one line: every run of whitespace (line breaks, tabs) one space; one over ``cap`` characters cut
     to ``cap``, ending ``...``

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
