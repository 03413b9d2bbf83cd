"""Covers bridge.nodes.vehicle.takeoff: NAV_TAKEOFF's altitude as PX4 takes it (pure)."""

from __future__ import annotations

import math

import pytest

from bridge.nodes.vehicle.takeoff import TakeoffAltitude, takeoff_altitude

HOME = 488.0  # m AMSL


@pytest.mark.parametrize("amsl, want", [
    (math.nan, TakeoffAltitude(2.5)),  # not given: MIS_TAKEOFF_ALT
    (HOME + 10.0, TakeoffAltitude(10.0)),
    (HOME + 50.0, TakeoffAltitude(50.0)),  # the highest, taken
    (HOME + 2.45, TakeoffAltitude(2.5)),  # within 10 cm of the least: raised, nothing said (as PX4)
    (HOME + 1.0, TakeoffAltitude(2.5, warning="Using minimum takeoff altitude: 490.50 m")),
    (HOME - 5.0, TakeoffAltitude(2.5, warning="Using minimum takeoff altitude: 490.50 m")),  # below home too
])
def test_an_altitude_is_taken_above_home_and_raised_to_the_least_saying_so(amsl, want):
    assert takeoff_altitude(amsl, 2.5, 50.0, HOME) == want


@pytest.mark.parametrize("amsl", [HOME + 50.5, math.inf, -math.inf])
def test_an_altitude_above_the_highest_or_not_finite_is_refused_naming_it(amsl):
    got = takeoff_altitude(amsl, 2.5, 50.0, HOME)
    assert got.alt_m is None and got.warning is None
    assert got.why is not None and got.why.startswith(f"NAV_TAKEOFF: altitude {amsl:g} m AMSL")
    assert got.why.endswith("must be at most 50 m above (home 488 m)")
