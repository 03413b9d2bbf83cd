"""Covers bridge.cli.campaigns: ``bsst margin``'s console lines put the unit's words after a number, never after
``interrupted`` or ``none``.

A new user's Ctrl-C of ``bsst margin ... --over noise --sensors mocap --estimator raw`` read ``margin bsst: noise:
interrupted x the sigmas of mocap, estimator raw (bracket so far [1.5, 2]: ...)``.
"""

from __future__ import annotations

from typing import Any

from bridge.cli.campaigns import margin_lines

WHAT = " x the sigmas of mocap, estimator raw"  # what bsst margin --over noise passes


def _entry(**fields: Any) -> dict[str, Any]:
    """One law's entry of margin.json (docs/campaigns.md, "margin.json"), with ``fields`` changed."""
    e = {"controller": "bsst", "margin": None, "bracket": [None, None], "held_to_range": False, "monotone": None,
         "failed_below": [], "holds_below": None, "checked_below": None, "seeds_alike": None, "error": None,
         "interrupted_in": None, "cells": []}
    e.update(fields)
    return e


def test_interrupted():
    (line,) = margin_lines(_entry(bracket=[1.5, 2.0], interrupted_in="bisection"), "noise", WHAT, "rms=0.1")
    assert line == (f"margin bsst: noise: interrupted (bracket so far [1.5, 2]{WHAT}: holds at 1.5, fails at 2; "
                    "until rms=0.1)")


def test_no_value_holds():
    (line,) = margin_lines(_entry(bracket=[None, 0.0]), "noise", WHAT, "rms=0.1")
    assert line.startswith(f"margin bsst: noise: none (fails at every value flown, down to 0{WHAT}, "), line


def test_the_law_failed():
    err = {"noise": 2.0, "seed": 0, "outcome": "law_failed", "phase": "bisection", "error": "raised"}
    (line,) = margin_lines(_entry(bracket=[1.0, None], error=err), "noise", WHAT, "rms=0.1")
    said = f"margin bsst: noise: none (the law failed, not the criterion: law_failed at 2{WHAT}; "
    assert line.startswith(said), line


def test_a_margin_keeps_its_words_after_the_number():
    e = _entry(margin=1.75, bracket=[1.75, 2.0], monotone=True, holds_below=1.75, checked_below=[0.0, 1.75])
    assert margin_lines(e, "noise", WHAT, "rms=0.1")[0].startswith(f"margin bsst: noise 1.75{WHAT} (bracket [1.75, 2]")
