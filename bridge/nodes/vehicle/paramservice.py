"""The vehicle's parameter service: PX4's parameters over MAVLink (docs/ground-station.md).

In:  PARAM_REQUEST_LIST, PARAM_REQUEST_READ (by index, or by name with index -1), PARAM_SET (name, value,
     MAV_PARAM_TYPE) from a sender with authority, with the link they came in on
Out: PARAM_VALUE (all, in one datagram, for a list; the new or unchanged value for a set); for a set refused
     or a name unknown, PARAM_ERROR (its MAV_PARAM_ERROR code) first and a STATUSTEXT saying why; a ``param``
     event of a set that changed a setting, with its sender (``by``) and the change (``param``: name, old and
     new value) as typed fields, said as a status line before the set's answer goes out (a set to the value in
     force is no change: answered, no event);
     refusals counted (``target``, ``reply_limited``, ``param_refused``, ``param_unknown``)

The parameters and their checks are :mod:`bridge.autopilot.params`; a set acts from the next control
period (:meth:`bridge.autopilot.simvehicle.SimVehicle.change_param`).

A refused set is answered as ArduPilot answers one (GCS_Param.cpp, ``handle_param_set``: PARAM_ERROR, then the
unchanged PARAM_VALUE), in one datagram with the STATUSTEXT: PARAM_ERROR first, so that MAVSDK (4.x,
``MavlinkParameterClient::process_param_error``) and QGroundControl end the set at once with its reason
(VALUE_OUT_OF_RANGE, READ_ONLY, DOES_NOT_EXIST, TYPE_MISMATCH, TYPE_UNSUPPORTED) where, on the unchanged value
alone, MAVSDK resent the set five times and gave up with TIMEOUT. PX4's src/modules/mavlink/mavlink_parameters.cpp
as read here (after 2020-11) checks no range and sends nothing for an unknown name or a wrong type (its console's
error only); PX4's main branch has added PARAM_ERROR since (in no release up to 1.17): by name (index -1), and
TYPE_UNSUPPORTED for a type other than INT32 and REAL32, as here.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

from bridge.autopilot.params import BY_NAME, PARAMS, ParamRefused, Refusal, VehicleParams, read_param
from bridge.autopilot.simvehicle import SimVehicle
from bridge.mavlink.endpoint import Endpoint
from bridge.mavlink.modes import PARAM_TYPES, param_from_wire, param_name, param_to_wire
from bridge.nodes.vehicle.authority import Authority
from bridge.nodes.vehicle.streams import StatusTexts

MESSAGES = frozenset({"PARAM_REQUEST_LIST", "PARAM_REQUEST_READ", "PARAM_SET"})
# MAV_PARAM_ERROR_TYPE_MISMATCH of MAVLink's common.xml, newer than the dialect of pymavlink 2.4.50 (which ends at
# READ_ONLY, 5); MAVSDK 4 reads it as TYPE_MISMATCH
MAV_PARAM_ERROR_TYPE_MISMATCH = 7
MAV_PARAM_ERROR_TYPE_UNSUPPORTED = 6  # (the same: common.xml's, after the dialect's READ_ONLY)
PARAM_ERRORS = {Refusal.VALUE: mavlink.MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE, Refusal.READ_ONLY:
                mavlink.MAV_PARAM_ERROR_READ_ONLY, Refusal.UNKNOWN: mavlink.MAV_PARAM_ERROR_DOES_NOT_EXIST,
                Refusal.TYPE: MAV_PARAM_ERROR_TYPE_MISMATCH,
                Refusal.TYPE_UNSUPPORTED: MAV_PARAM_ERROR_TYPE_UNSUPPORTED}  # PARAM_ERROR's code of each refusal


class ParamService:
    """Answers the parameter protocol for one vehicle (its :class:`SimVehicle` holds the values)."""

    def __init__(self, sim: SimVehicle, authority: Authority, texts: StatusTexts,
                 reject: Callable[[str], None], refused: Callable[[str], None], say: Callable[[], None]) -> None:
        self.sim = sim
        self.authority = authority
        self.sysid = authority.cfg.sysid
        self._texts = texts
        self._reject = reject
        self._refused = refused  # a set refused, and why (its report to the session)
        self._say = say  # the new events' status lines, now (Announcer.report_events): a change's before its echo

    def params(self) -> VehicleParams:
        return self.sim.params(self.sysid)

    def value(self, index: int, params: VehicleParams | None = None) -> Any:
        """PARAM_VALUE of the ``index`` th parameter."""
        spec = PARAMS[index]
        kind = PARAM_TYPES[spec.kind]
        value = read_param(params or self.params(), spec.name)
        return mavlink.MAVLink_param_value_message(spec.name.encode(), param_to_wire(value, kind), kind,
                                                   len(PARAMS), index)

    def value_of(self, name: str) -> Any:
        """PARAM_VALUE of the parameter ``name`` (PX4's name)."""
        return self.value(PARAMS.index(BY_NAME[name]))

    def handle(self, ep: Endpoint, m: Any, addr: tuple[str, int], link: str) -> bool:
        """PARAM_REQUEST_LIST (every PARAM_VALUE, in one datagram), PARAM_REQUEST_READ (by index, or
        by name with index -1), PARAM_SET (checked: made and answered with the new value, or refused,
        answered with the unchanged value and a STATUSTEXT saying why). Within the sender's reply
        budget. A refusal and an unknown name are answered with PARAM_ERROR first (the module's docstring).
        True when a parameter changed (its event is to be announced)."""
        if self.authority.for_others(m):
            self._reject("target")
            return False
        if not ep.reply_allowed(addr):
            self._reject("reply_limited")  # not acted on: its answer could not go
            return False
        kind = m._type
        if kind == "PARAM_REQUEST_LIST":
            params = self.params()
            ep.reply(tuple(self.value(i, params) for i in range(len(PARAMS))), addr)
            return False
        name = param_name(m)
        if kind == "PARAM_REQUEST_READ":
            index = m.param_index if m.param_index >= 0 else next(
                (i for i, p in enumerate(PARAMS) if p.name == name), -1)
            if not 0 <= index < len(PARAMS):
                by_name = m.param_index < 0  # (by a name it did not give: what it asked is the index it gave)
                what = (name or f"index {m.param_index} (no name)") if by_name else f"index {m.param_index}"
                self._unknown(ep, m, addr, what, name if by_name else "", m.param_index)
                return False
            ep.reply((self.value(index),), addr)
            return False
        return self._set(ep, m, addr, link, name)

    def _set(self, ep: Endpoint, m: Any, addr: tuple[str, int], link: str, name: str) -> bool:
        spec = BY_NAME.get(name)
        if spec is None:
            self._unknown(ep, m, addr, name, name, -1)
            return False
        index = PARAMS.index(spec)
        want = PARAM_TYPES[spec.kind]
        try:
            if m.param_type not in PARAM_TYPES.values():  # PX4 main: TYPE_UNSUPPORTED for any but INT32, REAL32
                raise ParamRefused(name, f"the set says {_type_named(m.param_type)}: the parameters here are INT32 "
                                   "or REAL32", Refusal.TYPE_UNSUPPORTED)
            if m.param_type != want:
                raise ParamRefused(name, f"is {spec.kind}, the set says {_type_named(m.param_type)}", Refusal.TYPE)
            changed = self.sim.change_param(name, param_from_wire(m.param_value, want), self.sysid)
            if changed is not None:  # its sender, typed: the session records who changed what, and when
                changed.by = self.authority.sender(m, addr, link)
                self._say()  # its line before its echo: the controller's word of the echo never comes first
        except ParamRefused as exc:
            self._reject("param_refused")
            self._refused(str(exc))
            error = _param_error(m, name, -1, PARAM_ERRORS[exc.why])  # as the set named it: by name (PX4 main)
            ep.reply((error, self.value(index), *self._texts(mavlink.MAV_SEVERITY_WARNING, str(exc))), addr)
            return False
        ep.reply((self.value(index),), addr)
        return True

    def _unknown(self, ep: Endpoint, m: Any, addr: tuple[str, int], what: str, name: str, index: int) -> None:
        """No such parameter: no PARAM_VALUE (the protocol's answer), PARAM_ERROR DOES_NOT_EXIST (the name or the
        index asked for) and a STATUSTEXT saying so."""
        self._reject("param_unknown")
        error = _param_error(m, name, index, mavlink.MAV_PARAM_ERROR_DOES_NOT_EXIST)
        ep.reply((error, *self._texts(mavlink.MAV_SEVERITY_WARNING, f"param {what}: no such parameter")), addr)


def _type_named(kind: int) -> str:
    """A PARAM_SET's ``param_type`` for its refusal: ``INT32 (type 6)``; a number MAV_PARAM_TYPE does not have, as
    such (``type 42, not a MAV_PARAM_TYPE``). Until the forty-fourth session's tour the number alone (``type 6``)."""
    entry = mavlink.enums["MAV_PARAM_TYPE"].get(kind)
    if entry is None or entry.name.endswith("_ENUM_END"):
        return f"type {kind}, not a MAV_PARAM_TYPE"
    return f"{entry.name.removeprefix('MAV_PARAM_TYPE_')} (type {kind})"


def _param_error(m: Any, name: str, index: int, code: int) -> Any:
    """PARAM_ERROR to the sender of ``m``: the parameter (``name``, ``index``; "" and -1 where not known) and
    ``code`` (MAV_PARAM_ERROR)."""
    return mavlink.MAVLink_param_error_message(m.get_srcSystem(), m.get_srcComponent(),
                                               name.encode(errors="replace")[:16], index, code)
