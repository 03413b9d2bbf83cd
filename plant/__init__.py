"""The simulated quadrotor: pure physics, no I/O and nothing of MAVLink.

- :mod:`plant.model`      the 12-state rigid-body model of the paper, eq. (6) corrected
- :mod:`plant.rotors`     the rotor equations (4)-(5) and the first-order motor lag
- :mod:`plant.integrate`  the fixed-step RK4 integrator
- :mod:`plant.effects`    drag, external disturbance, parameter mismatch
- :mod:`plant.profiles`   vehicle profiles (``profiles/*.toml``), validated on load
- :mod:`plant.quadrotor`  :class:`Quadrotor`, the stateful plant that ties them together

In:  a profile, effects, a seed, the physics rate (Hz)
Out: the simulated vehicle's state (eq. 7: m, m/s, rad, rad/s), see :mod:`plant.quadrotor`
"""

from plant.effects import Disturbance, Effects
from plant.profiles import Profile, load_profile, profile_names
from plant.quadrotor import Quadrotor

__all__ = ["Disturbance", "Effects", "Profile", "Quadrotor", "load_profile", "profile_names"]
