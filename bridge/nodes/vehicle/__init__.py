"""The simulated vehicle as a MAVLink 2 endpoint: ``bsst vehicle`` (docs/design.md, "The MAVLink contract").

In:  actuator targets on the controller link, stamped with the ``time_usec`` of the state they answer:
     HIL_ACTUATOR_CONTROLS (``motors``: c1..c4 = omega / omega_max, each in [0, 1]) or
     SET_ACTUATOR_CONTROL_TARGET group 0 (``wrench``: roll, pitch, yaw in [-1, 1], thrust in [0, 1]),
     or the no-target acknowledgement; COMMAND_LONG / COMMAND_INT (among them DO_SET_MODE, NAV_TAKEOFF
     m AMSL, NAV_LAND), SET_MODE, PARAM_REQUEST_LIST / PARAM_REQUEST_READ / PARAM_SET, TIMESYNC, PING,
     HEARTBEAT on either link
Out: ODOMETRY (NED position m, FRD body velocity m/s, quaternion FRD to NED, FRD rates rad/s;
     ``time_usec`` = simulation time, us), once per control step; HEARTBEAT at 1 Hz (PX4's
     ``custom_mode``), STATUSTEXT on each event, the GCS streams (25 Hz / 10 Hz, ``time_boot_ms`` =
     simulation time; with sensors HIGHRES_IMU and GPS_RAW_INT), PARAM_VALUE, the mission protocol's answers,
     MISSION_CURRENT (1 Hz) and MISSION_ITEM_REACHED; ``vehicle.tlog``,
     ``vehicle.bin`` rows; its reports on stdout (JSON lines)

Its clocks and its end of the link model: docs/design.md, "Clocks" and "Link model". Its
parameters, flight modes (OFFBOARD, HOLD, LAND, TAKEOFF, RTL, in PX4's encoding: :mod:`bridge.mavlink.modes`)
and what a ground station can do with them: docs/ground-station.md. Who may
do what on which link: docs/design.md, "Authority" (:mod:`.authority`); every
command's numbers are checked before use (:mod:`bridge.mavlink.receive`), and every command
that changes the flight is an event naming its sender (its ``by``, a :class:`~bridge.autopilot.vehicleevents.Sender`).

It wraps :class:`bridge.autopilot.simvehicle.SimVehicle` (plant, arming, command timeout, failsafe:
the same object the offline loop flies) with two UDP links:

- the **controller link** (``--listen``, default ``udpin:127.0.0.1:14560``): ODOMETRY out
  at every control step, actuator targets in (HIL_ACTUATOR_CONTROLS for a ``motors``
  profile, SET_ACTUATOR_CONTROL_TARGET group 0 for a ``wrench`` profile), accepted only
  from the configured controller (sysid/compid) and only while armed in offboard control
  (in a lockstep flight the up-link model delivers them, and refuses them then);
- the **GCS link** (``--gcs``, default ``udpout:127.0.0.1:14550``): HEARTBEAT, ATTITUDE,
  LOCAL_POSITION_NED, GLOBAL_POSITION_INT, SYS_STATUS, ACTUATOR_OUTPUT_STATUS, ... on the
  wall clock, and STATUSTEXT on events; commands are answered on the socket they came in on.

Clocks:

- **lockstep** (default): the state of step k (time_usec = round(k / rate_hz * 1e6)) is sent
  and the vehicle advances one control period only when it holds the controller's answer
  stamped with that time_usec: an actuator target, or the **no-target acknowledgement**
  (HIL_ACTUATOR_CONTROLS with SAFETY_ARMED clear in ``mode``, for either actuation: the
  controller has no valid target this step, the step clock ticks on and the vehicle's
  timeout runs). The mission's ``[link]`` model acts here, in simulation time, on what
  crossed the socket (:class:`bridge.link.ends.VehicleEnd`, the offline loop's end): the
  target of step k enters the ``up`` model at t_k and acts at the physics step it is
  delivered in; so does an ARM_DISARM(arm) from the controller while its flight is on
  (a re-arm after a failsafe). The step clock keeps ticking while the vehicle, landed by
  its failsafe, is disarmed, for as long as the controller answers. ``speed`` caps the pace
  at that many times real time. Heartbeats and telemetry keep flowing on the wall clock
  meanwhile. A controller silent for ``lost_after_s`` of wall time is lost: the vehicle
  leaves lockstep, runs on at real-time pace (``speed`` if given) and its timeout and
  failsafe take over; it returns to lockstep when armed again.
- **realtime**: physics steps against the wall clock at the physics rate; a target is
  applied at the physics step it arrives in and held; ODOMETRY goes out at the control rate.

With ``out``, it writes ``vehicle.tlog`` (both directions) and ``vehicle.bin`` (its half of
the trace: one row per control step flown, columns :data:`VEHICLE_COLUMNS`).
Its reports (:mod:`bridge.nodes.report`: ready, event, refused, stats) go to ``status``, one JSON
line each under ``bsst vehicle``; the session launcher reads them.

Its parts, as PX4 splits an autopilot:

- :mod:`.clock`         the step clock: one state machine (idle, lockstep, answered, free-running,
                        halted), its transitions in one table
- :mod:`.authority`     who may command what on which link; who caused an event (its ``by``)
- :mod:`.commander`     arming, flight modes, commands
- :mod:`.clocking`      which clock the flight runs on as its modes and its end change; what ends a flight
- :mod:`.requests`      requests for messages and their rates (SET/GET_MESSAGE_INTERVAL, REQUEST_MESSAGE, ...)
- :mod:`.paramservice`  PX4's parameters over MAVLink
- :mod:`.mission`       PX4's mission protocol (upload, download, clear, set current) and the mission held
- :mod:`.targets`       the controller's answers: actuator targets, the no-target acknowledgement
- :mod:`.receiver`      the receive path: each message, its sender's authority checked, to its part
- :mod:`.streams`       the telemetry streams (message id -> builder and rate), HEARTBEAT, ODOMETRY
- :mod:`.streaming`     the vehicle's view for its messages, each link's streams sent when due, its load
- :mod:`.rows`          ``vehicle.bin``
- :mod:`.config`        :class:`VehicleConfig`
- :mod:`.node`          :class:`Vehicle`, which wires the parts to the links
- :mod:`.run`           :func:`run_vehicle`: ``bsst vehicle``
"""

from bridge.nodes.vehicle.clock import TRANSITIONS, Clock, ClockState, IllegalTransition, Trigger
from bridge.nodes.vehicle.commander import OFFBOARD_STREAM_S
from bridge.nodes.vehicle.config import CLOCKS, VehicleConfig
from bridge.nodes.vehicle.node import Vehicle
from bridge.nodes.vehicle.rows import MODE_CODES
from bridge.nodes.vehicle.run import run_vehicle
from bridge.nodes.vehicle.streams import DEFAULT_STREAMS, STREAMS, StreamTable, odometry_covariance

__all__ = [
    "CLOCKS",
    "DEFAULT_STREAMS",
    "MODE_CODES",
    "OFFBOARD_STREAM_S",
    "STREAMS",
    "TRANSITIONS",
    "Clock",
    "ClockState",
    "IllegalTransition",
    "StreamTable",
    "Trigger",
    "Vehicle",
    "VehicleConfig",
    "odometry_covariance",
    "run_vehicle",
]
