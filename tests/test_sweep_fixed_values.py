"""Covers bridge.sweep.grid: a link axis a sweep does not sweep is written as the flight flies it, its link profile's
value where the mission's own tables give none.

A new user's ``bsst sweep missions/sine.toml --loss 0,10 --link-profile lte`` wrote ``delay_ms`` 0, ``jitter_ms`` 0
and ``burst_len`` 0 in every row of ``cells.csv`` and as the fixed values of ``report.md``, of flights at LTE's 35 ms,
sigma 6 ms, bursts of 5.
"""

from __future__ import annotations

from dataclasses import replace

from bridge.sweep.grid import Grid, cells, mission_value
from missions import Mission, Sine

SHORT = Mission(Sine(), duration_s=2.0, name="short")


def test_an_unswept_link_axis_is_the_profiles_value_as_flown() -> None:
    lte = replace(SHORT, link={"profile": "lte"})
    rows = cells(lte, Grid(loss_pct=(0.0, 10.0)))
    assert [(c.delay_ms, c.jitter_ms, c.burst_len, c.loss_pct) for c in rows] == [
        (35.0, 6.0, 5.0, 0.0), (35.0, 6.0, 5.0, 10.0)]
    assert rows[0].link == ("loss_pct",)  # only the swept axis is laid over the flight: the profile flies as it is


def test_the_missions_own_keys_are_laid_over_its_profiles_as_the_flight_lays_them() -> None:
    m = replace(SHORT, link={"profile": "lte", "delay_ms": 20.0, "up": {"jitter_ms": 2.0}})
    assert [mission_value(m, a) for a in ("delay_ms", "jitter_ms", "loss_pct")] == [20.0, 2.0, 0.5]
    # bsst margin's "the mission already sets it" reads the mission's own tables only: a profile's delay is searched
    assert mission_value(replace(SHORT, link={"profile": "lte"}), "delay_ms", with_profile=False) == 0.0
