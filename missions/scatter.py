"""A scattered start: where each seed's flight begins, drawn around the mission's start.

In:  the mission's start (x, y, z m; psi rad), the scatter radius (m), the flight's seed
Out: the start that seed flies from: a point drawn uniformly in the horizontal disc of that radius around the
     start's position (z and psi as given: the vehicle still rests on its pad, on the ground plane z = 0 or
     where the mission puts it). Radius 0 draws nothing: the start as given, the same float. Why a scatter
     cannot be flown (:func:`fleet_scatter_problem`: a fleet's)

A deterministic mission flies one flight per seed, the same for every seed; a margin or a sweep over it is
then one draw of where its limit cycles settle (docs/law.md, "One initial condition"). ``[start] scatter_m``
gives each seed its own initial error, so that ``--seeds N`` flies N initial conditions (docs/campaigns.md).
"""

from __future__ import annotations

import math

import numpy as np

_DOMAIN = 0x5CA7  # keeps the start's draw apart from any other use of the same seed


def scattered_start(start: tuple[float, float, float, float], radius_m: float,
                    seed: int) -> tuple[float, float, float, float]:
    """``start`` (x, y, z m, psi rad) moved to a point drawn uniformly in the horizontal disc of ``radius_m`` (m)
    around its position, from ``seed``'s own stream; ``radius_m`` 0: ``start`` itself."""
    if radius_m <= 0.0:
        return start
    u, v = np.random.default_rng([seed, _DOMAIN]).random(2)
    r, a = radius_m * math.sqrt(float(u)), 2.0 * math.pi * float(v)  # uniform in area: P(|offset| <= r) = (r/R)^2
    return (start[0] + r * math.cos(a), start[1] + r * math.sin(a), start[2], start[3])


def fleet_scatter_problem(radius_m: float, fleet: str) -> str | None:
    """Why a scatter of ``radius_m`` (m) cannot be flown by a fleet (``fleet``: what gave it; "" none), or None: the
    one rule, for the mission (``start.scatter_m``) and ``--scatter`` (named as the flag:
    bridge.cli.options.checked_mission)."""
    if not radius_m or not fleet:
        return None
    return f"a fleet's starts are its formation's ({fleet}): scatter the starts of a mission of one vehicle"
