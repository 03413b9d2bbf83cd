"""Missions: the paper's scenarios as TOML files and the trajectory references they define.

In:  a mission TOML file (``missions/*.toml`` or a path), a ground station's plan (``.plan``, ``.waypoints``),
     or a mission's fields in Python;
Out: a validated :class:`Mission` and its :class:`Reference` (x, y, z m and psi rad against t s,
     with four derivatives). Pure: no sockets, no processes; the file is read by :mod:`params`

- :mod:`missions.mission`     the mission file: load, validate, the :class:`Mission`
- :mod:`missions.trajectories` its ``[trajectory]`` table, and a plan, as a reference
- :mod:`missions.references`  the trajectories: set-points, steps, sine, waypoints
- :mod:`missions.planfiles`   ground stations' plans: QGroundControl ``.plan`` and ``QGC WPL 110`` text
- :mod:`missions.geodetic`    PX4's projection of latitude, longitude, altitude to the local frames
- :mod:`missions.route`       a plan's knots, stops, yaw and times from PX4's speed limits
- :mod:`missions.minsnap`     minimum-snap trajectories through knots (``kind = "smooth"``)

Scripting::

    from missions import Mission, Sine, Step, Setpoint
    m = Mission(Sine(), duration_s=30.0, name="sine")
"""

from missions.mission import (
    CONTROLLERS,
    DEFAULT_DISCRETIZATION,
    DISCRETIZATIONS,
    MISSION_RANGES,
    Mission,
    load_mission,
    mission_from_table,
    mission_path,
)
from missions.mission import SHIPPED_DIR as MISSION_DIR
from missions.references import Reference, Setpoint, Sine, Step, Waypoints

__all__ = [
    "CONTROLLERS",
    "DEFAULT_DISCRETIZATION",
    "DISCRETIZATIONS",
    "MISSION_RANGES",
    "MISSION_DIR",
    "Mission",
    "Reference",
    "Setpoint",
    "Sine",
    "Step",
    "Waypoints",
    "load_mission",
    "mission_from_table",
    "mission_path",
]
