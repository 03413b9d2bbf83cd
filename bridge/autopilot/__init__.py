"""The on-board autopilot of the simulated vehicle, for every clock: no sockets, no files.

In:  actuator targets (paper frame), arm/mode requests, sensor readings, PX4 parameter sets;
Out: the flown state, the estimate the vehicle reports, failsafe decisions and events

- :mod:`bridge.autopilot.simvehicle`  plant + arming + offboard timeout + failsafe, for every clock
- :mod:`bridge.autopilot.failsafe`    the failsafe's actions, the on-board targets and gains
- :mod:`bridge.autopilot.onboard`     the on-board position controller that flies them
- :mod:`bridge.autopilot.params`      PX4 parameters: names, one range table, changes
- :mod:`bridge.autopilot.returnland`  Return's height near home (PX4's cone), the auto landing's speed by height
- :mod:`bridge.autopilot.estimator`   truth or EKF estimate of the state
- :mod:`bridge.autopilot.ekfkernels`  the EKF's compiled kernels: propagation, updates, the estimate
- :mod:`bridge.autopilot.ekfstate`    the EKF's state layout, its buffer of past states, P carried in time
- :mod:`bridge.autopilot.closedloop`  the estimator's offline harness (plant, sensors, estimator, law)
- :mod:`bridge.autopilot.cholesky`    a small weighted-square helper of the EKF
- :mod:`bridge.autopilot.kernelcache` the project's one ``njit``: a cache stale when any source it compiles in changed
"""
