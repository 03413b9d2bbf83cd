"""Covers bridge.sweep.margin, bridge.sweep.campaign and bridge.sweep.classes: a Python caller's arguments to
``margin()`` and ``sweep()`` are checked as ``bsst margin``'s and ``bsst sweep``'s flags are, before any cell flies: a
ConfigError or TypeError naming the argument, never a search of nothing or a bare error.

A new user's script read ``margin(m, "delay_ms", Until(rms=0.1), seeds=0)`` as a margin of 60000 ms, the whole
range, with no cell flown; ``controllers="smc"`` flew a law named 's'; ``until="rms=0.1"`` (the flag's text) raised
``AttributeError: 'str' object has no attribute 'failed'`` once a round had flown, ``Until(cls="foo")`` a bare
``tuple.index(x): x not in tuple``, ``Until(rms=-1)`` searched a criterion nothing can meet, and a mission given as
its path (as ``sweep()`` takes it) ``'str' object has no attribute 'controller'``.
"""

from __future__ import annotations

from typing import Any

import pytest

from bridge.sweep import Classes, Grid, sweep
from bridge.sweep.margin import Until, margin
from missions import Mission, Sine

# imports the sweep's executors (process pools), though no test here starts one: every call is refused first
pytestmark = pytest.mark.process

SHORT = Mission(Sine(), duration_s=2.0, name="short")


@pytest.mark.parametrize("kwargs, error, names", [
    ({"seeds": 0}, ValueError, "seeds: must be a whole number in [1, 1000], got 0"),
    ({"seeds": "2"}, ValueError, "seeds: must be a whole number in [1, 1000], got '2'"),
    ({"seeds": True}, ValueError, "seeds: must be a whole number"),
    ({"controllers": "smc"}, TypeError, "controllers: expected a list of law names"),
    ({"controllers": []}, TypeError, "controllers: expected a list of law names"),
    ({"controllers": ["bsst", 3]}, TypeError, "controllers: expected a list of law names"),
    ({"resolution": "1"}, TypeError, "resolution: expected a number, got '1'"),
    ({"below": "1"}, TypeError, "below: expected a number, got '1'"),
])
def test_a_bad_argument_is_named_before_any_flight(kwargs: dict[str, Any], error: type, names: str) -> None:
    with pytest.raises(error) as caught:
        margin(SHORT, "delay_ms", Until(rms=0.1), **kwargs)
    assert names in str(caught.value)


@pytest.mark.parametrize("make, names", [
    (lambda: Until(cls="foo"), "until.cls: must be one of degraded, limit-cycling, failsafe, diverged, crashed, "
                               "error, got 'foo'"),
    (lambda: Until(cls="clean"), "until.cls: must be one of degraded"),
    (lambda: Until(rms=-1.0), "until.rms: must be a positive number of metres, got -1.0"),
    (lambda: Until(rms=float("nan")), "until.rms: must be a positive number of metres, got nan"),
    (lambda: Until(rms="0.1"), "until.rms: must be a positive number of metres, got '0.1'"),
    (lambda: Until(), "until: give one of rms=METRES or cls=NAME"),
    (lambda: Until(rms=0.1, cls="diverged"), "until: give one of rms=METRES or cls=NAME"),
])
def test_a_criterion_made_in_python_is_checked_as_the_flag_is(make: Any, names: str) -> None:
    with pytest.raises(ValueError) as caught:
        make()
    assert names in str(caught.value)


def test_the_criterion_may_be_the_flags_text_and_a_bad_one_is_named_as_the_flag() -> None:
    with pytest.raises(ValueError, match=r"^--until rms=X: X must be a positive number of metres, got 'x'$"):
        margin(SHORT, "delay_ms", "rms=x")
    with pytest.raises(TypeError, match=r"^until: expected an Until or 'rms=METRES' / 'class=NAME', got 0.1$"):
        margin(SHORT, "delay_ms", 0.1)  # type: ignore[arg-type]


def test_the_mission_may_be_its_path_and_anything_else_is_named() -> None:
    # the path is loaded: the shipped sine's estimator (truth) is what refuses a noise margin, before any flight
    with pytest.raises(ValueError, match=r"^margin over noise: the estimator is 'truth'"):
        margin("missions/sine.toml", "noise", "rms=0.1")
    with pytest.raises(TypeError, match=r"^mission: expected a Mission or a path to its file, got None$"):
        margin(None, "delay_ms", "rms=0.1")  # type: ignore[arg-type]


@pytest.mark.parametrize("kwargs, error, names", [
    ({"classes": "strict"}, TypeError, "classes: expected a Classes or a mapping of its thresholds, got 'strict'"),
    ({"classes": {"clean": 0.01}}, ValueError, "classes.clean: unknown threshold; allowed: clean_rms_m, "
                                               "diverged_rms_m, ripple_u2"),
    ({"classes": {"clean_rms_m": -1}}, ValueError, "classes.clean_rms_m: must be a positive number, got -1"),
    ({"resume": "no"}, ValueError, "resume: expected True or False, got 'no'"),  # truthy: it resumed
    ({"overwrite": 1}, ValueError, "overwrite: expected True or False, got 1"),
    ({"report": "no"}, ValueError, "report: expected True or False, got 'no'"),
    ({"client": 5}, TypeError, "client: expected a distributed.Client, got 5"),
])
def test_a_sweeps_bad_argument_is_named_before_any_flight(kwargs: dict[str, Any], error: type, names: str) -> None:
    """``classes={"clean_rms_m": 0.01}`` raised ``AttributeError: 'dict' object has no attribute 'diverged_rms_m'``,
    ``client=5`` ``'int' object has no attribute 'nthreads'``, and ``resume="no"`` resumed, until the third wave's
    forty-third session."""
    with pytest.raises(error) as caught:
        sweep(SHORT, Grid(delay_ms=(0.0,)), **kwargs)
    assert str(caught.value) == names
    if "classes" in kwargs:  # margin() takes its classes alike
        with pytest.raises(error) as caught:
            margin(SHORT, "delay_ms", Until(rms=0.1), classes=kwargs["classes"])
        assert str(caught.value) == names


def test_classes_of_takes_a_mapping_of_thresholds() -> None:
    assert Classes.of({"clean_rms_m": 0.01}) == Classes(clean_rms_m=0.01)
    assert Classes.of(None) == Classes() and Classes.of(Classes(ripple_u2=5.0)) == Classes(ripple_u2=5.0)
