"""One event of a flight's timeline acted on: the plant's rotors, air and battery, the vehicle's sensors
(docs/weather.md).

In:  a timeline event (:class:`plant.events.TimedEvent`: motor, wind, gust, link, gps, mag, baro, gyro, battery;
     its fields in SI: effectiveness 0..1, m/s, deg, s, m, m/s of drift, rad/s of bias), the plant (its time s),
     the vehicle's sensor suite (None under truth)
Out: the plant's and the sensors' state changed now, and the kind of event that says so (:func:`act_on`); whether
     an event would change nothing (:func:`changes_nothing`)
"""

from __future__ import annotations

from plant import Quadrotor
from plant.events import TimedEvent, device_set
from plant.sensors import SensorSuite
from plant.wind import Gust


def changes_nothing(e: TimedEvent, p: Quadrotor, sensors: SensorSuite | None) -> bool:
    """Whether acting on ``e`` now would leave the vehicle as it is: a GPS or compass switched to the state it is
    in, a rotor set to the effectiveness it has (:func:`plant.events.device_set`). A ground station's such
    injection (FAILURE_TYPE_OK of a working unit) is then no change to the flight, as a PARAM_SET to the value in
    force is none."""
    sets = device_set(e)
    if sets is None:
        return False
    device, state = sets
    if device[0] == "motor":
        return p.effectiveness[device[1] - 1] == state
    if device[0] == "battery":
        return p.battery is not None and p.battery.reads_empty == (state == "empty")
    if sensors is None or device[0] not in ("gps", "mag"):
        return False
    on = sensors.faults.gps_on if device[0] == "gps" else sensors.faults.mag_on
    return on == (state == "on")


def act_on(e: TimedEvent, p: Quadrotor, sensors: SensorSuite | None) -> str:
    """Act on ``e`` now (checked against the flight when it was built: :func:`bridge.core.flight.prepare`); the kind
    of event that says it: ``fault``, ``wind`` for the weather's, ``link`` for a handover (which the link models
    make themselves at this step: LinkSettings.handovers). ValueError for an event the vehicle cannot act on (a
    sensor's under truth, wind without a plant's wind model)."""
    k = e.kind
    if k == "motor":
        p.set_effectiveness(e.get("motor"), e.get("effectiveness"))
    elif k in ("wind", "gust"):
        if p.wind is None:
            raise ValueError("a wind or gust event needs the plant built with a wind (prepare gives one)")
        if k == "wind":
            p.wind.set_steady(e.get("speed_mps"), e.get("from_deg"))
        else:
            p.wind.add_gust(Gust(p.t, e.get("duration_s"), e.get("amplitude_mps"), e.get("from_deg")))
        return "wind"
    elif k == "link":
        return "link"
    elif k == "battery":
        if p.battery is None:
            raise ValueError("a battery event needs the plant built with its battery ([effects] battery)")
        p.battery.reads_empty = e.get("state") == "empty"
    else:
        if sensors is None:
            raise ValueError(f"a {k} event needs the vehicle's sensors (an estimator other than truth)")
        f = sensors.faults
        if k == "gps":
            if e.get("jump") is not None:
                f.jump(e.get("jump"))
            else:
                f.gps_on = e.get("state") == "on"
        elif k == "mag":
            f.mag_on = e.get("state") == "on"
        elif k == "baro":
            f.set_drift(e.get("drift_mps"), p.t)
        else:
            bias = sensors.gyro_bias
            for i, b in enumerate(e.get("bias")):
                bias[i] += b
    return "fault"
