"""Missions: the paper's scenarios as TOML files and the trajectory references they define.

Scripting::

    from missions import Mission, Sine, Step, Setpoint
    m = Mission(Sine(), duration_s=30.0, name="sine")
"""

from pathlib import Path

from missions.mission import CONTROLLERS, Mission, load_mission, mission_from_table
from missions.references import Reference, Setpoint, Sine, Step, Waypoints

MISSION_DIR = Path(__file__).parent

__all__ = [
    "CONTROLLERS",
    "MISSION_DIR",
    "Mission",
    "Reference",
    "Setpoint",
    "Sine",
    "Step",
    "Waypoints",
    "load_mission",
    "mission_from_table",
]
