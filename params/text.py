"""Text from elsewhere, read: a message that quotes a user's code (its exception, a repr of what it returned) or a
failed cell's reason kept to the one line its record allows; a number a person typed; the word a slip misspelt.

In:  any text (an exception's message, a ``repr``), the most characters it may keep; a number's text as a person
     types it (a flag's value, a field of a trace or a waypoint file); a word and the words it may mean (a table's
     keys, a flag's choices)
Out: the text on one line: every run of whitespace (line breaks, tabs) one space; one over ``cap`` characters cut
     to ``cap``, ending ``...``; the number (:func:`number`, :func:`whole`), ValueError if it is none; the word it
     likely misspells (:func:`likely`, :func:`is_typo_of`), or None; what an unknown key's refusal adds
     (:func:`unknown_key_hint`: the key meant, where a PX4 parameter goes, else the keys allowed; :func:`meant_hint`,
     the first two alone: a vehicle parameter's name); a name a user gave, quoted and shortened (:func:`quoted`,
     :func:`shown_name`); where an integer over Python's limit of digits is (:func:`too_many_digits`)

(Apart from ``params/__init__.py``, which re-exports the misspelling's two and the digits' one, and was at its 500
lines.)
"""

from __future__ import annotations

import difflib
import re
import sys
from collections.abc import Iterable

from params.px4 import px4_hint

ONE_LINE_MAX = 300  # characters of a quoted message a line keeps (a sweep's error cell, a law's raise)


def one_line(text: str, cap: int = ONE_LINE_MAX) -> str:
    """``text`` on one line of at most ``cap`` characters: an ``events.log`` event, an error on stderr, a sweep's
    ``error`` cell are one line each, and a law's ``raise ValueError(f"singular:\\n{matrix}")`` or a numpy
    array's repr spans several."""
    flat = " ".join(text.split())
    return flat if len(flat) <= cap else flat[:cap - 3] + "..."


NAME_SHOWN_MAX = 60  # characters of a name a user gave (a parameter's) a message shows whole


def quoted(text: str) -> str:
    """``text`` a user gave, quoted in a message (its repr: one line, where it ends plain); one of over
    :data:`NAME_SHOWN_MAX` characters by its first ones, ``…`` and its length (a 3000-character name was echoed
    whole)."""
    if len(text) <= NAME_SHOWN_MAX:
        return repr(text)
    return f"{text[:NAME_SHOWN_MAX]!r}… ({len(text)} characters)"


def shown_name(name: object) -> str:
    """A name a user gave (a vehicle parameter's) before a refusal's ``: why``: as it is when plainly a name
    (printable, no ``: ``, ``=`` or quote, no space at its ends), else :func:`quoted` (``'A: B': no such
    parameter``: it was ``A: B: no such parameter``, and ``--param``'s Python path cut it to ``B: ...``)."""
    text = str(name)
    plain = (text.isprintable() and text == text.strip() and ": " not in text and not any(c in text for c in "='\"")
             and 0 < len(text) <= NAME_SHOWN_MAX)
    return text if plain else quoted(text)


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


TYPO_MIN_LENGTH = 4  # shorter keys of one table are one slip apart (u1 u2, c_p c_v, k1 k2): never taken for typos


def is_typo_of(text: str, name: str) -> bool:
    """Whether ``text`` is ``name`` (of at least :data:`TYPO_MIN_LENGTH` characters) with one typing slip: a
    character left out, added, changed, or two neighbours swapped (``duraton_s``, ``durattion_s``,
    ``duratoin_s``); two keys of one table are never that close (``velocity_noise_mps``,
    ``velocity_noise_z_mps`` are two apart)."""
    if len(name) < TYPO_MIN_LENGTH or text == name or abs(len(text) - len(name)) > 1:
        return False
    i = 0
    while i < min(len(text), len(name)) and text[i] == name[i]:
        i += 1
    a, b = text[i:], name[i:]  # from the first difference on
    return (a[1:] == b[1:] or a == b[1:] or a[1:] == b
            or (len(a) == len(b) >= 2 and a[0] == b[1] and a[1] == b[0] and a[2:] == b[2:]))


def likely(text: str, known: Iterable[str], cutoff: float = 0.6) -> str | None:
    """The word of ``known`` that ``text`` most likely misspells: one a single slip away (:func:`is_typo_of`: a
    swap of neighbours, which difflib ranks low), else difflib's closest from ``cutoff`` on; None if none is."""
    words = [str(k) for k in known]
    slips = [w for w in words if is_typo_of(text, w)]
    if slips:
        return slips[0]
    close = difflib.get_close_matches(text, words, n=1, cutoff=cutoff)
    return close[0] if close else None


ALLOWED_SHOWN_MAX = 12  # keys an unknown key's refusal lists whole; of a table of more, the closest few and "..."


def meant(text: str, known: Iterable[str]) -> str | None:
    """The word of ``known`` that ``text`` most likely means: itself in another case (``mpc_acc_hor`` for
    ``MPC_ACC_HOR``), else one it misspells (:func:`likely`), as written or in another case (``com_of_los_t`` for
    ``COM_OF_LOSS_T``); None if none is."""
    words = list(dict.fromkeys(str(k) for k in known))
    same = next((w for w in words if w.lower() == text.lower()), None)
    if same is not None:
        return same
    lowered = {w.lower(): w for w in words}
    like = likely(text, words) or likely(text.lower(), lowered)
    return lowered.get(like, like) if like else None


def meant_hint(text: str, known: Iterable[str]) -> str | None:
    """What an unknown name ``text``'s refusal adds when it says what was meant: ``; did you mean 'delay_ms'?``
    (:func:`meant`, ``known`` the names allowed), else where a PX4 parameter's name goes
    (:func:`params.px4.px4_hint`); None if neither (the caller lists what is allowed)."""
    like = meant(text, known)
    if like:
        return f"; did you mean {like!r}?"
    px4 = px4_hint(text)
    return f" ({px4})" if px4 else None


def unknown_key_hint(text: str, known: Iterable[str]) -> str:
    """What follows an unknown key ``text``'s refusal, ``known`` the keys its table takes (in the order it reads
    them): the key meant or where a PX4 parameter's name goes (:func:`meant_hint`), else ``; allowed: ...`` (every
    key, or of a table of more than :data:`ALLOWED_SHOWN_MAX` the closest few or the first, ``...`` and how many):
    the line says what it may be."""
    words = list(dict.fromkeys(str(k) for k in known))
    hint = meant_hint(text, words)
    if hint:
        return hint
    if not words:
        return ""
    if len(words) <= ALLOWED_SHOWN_MAX:
        return f"; allowed: {', '.join(words)}"
    close = difflib.get_close_matches(text, words, n=6, cutoff=0.4) or words[:6]  # (none close: the first ones)
    return f"; allowed: {', '.join(close)}, ... ({len(words)} keys)"


def too_many_digits(text: str, exc: ValueError) -> str:
    """What is wrong when a parser's ``int()`` refused an integer of ``text`` over Python's limit of digits
    (``sys.get_int_max_str_digits``; ``ValueError: Exceeds the limit ...``): where the longest run of digits
    is and how long it is, in words (any other ``exc``: its text, shortened)."""
    limit = sys.get_int_max_str_digits()
    runs = [m for m in re.finditer(r"[0-9][0-9_]*", text) if len(m.group()) > limit]
    if not runs or "limit" not in str(exc):
        return str(exc)[:200]
    m = max(runs, key=lambda r: len(r.group()))
    line = text.count("\n", 0, m.start()) + 1
    return f"line {line}: an integer of {len(m.group().replace('_', ''))} digits, over the {limit} Python reads"
