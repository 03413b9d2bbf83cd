"""An ARM's retransmissions: the vehicle acts on one arm once, however many of its copies come (docs/design.md).

In:  each COMMAND_LONG ARM_DISARM(1) taken from a sender (its system, component and address; its ``confirmation``:
     0 the first send, 1, 2, ... its retransmissions, MAVLink's command protocol), the wall time it came (s,
     ``time.monotonic``), and when the vehicle acted on one (its MAV_RESULT)
Out: whether a copy is still to be acted on, and for a retransmission of an arm already acted on the result to
     answer it with (the first's), nothing done

MAVLink's command protocol: a sender resends a command whose COMMAND_ACK did not come, with ``confirmation``
incremented; the recipient answers a retransmission of a command it already ran with that command's result and
does not run it twice (PX4's commander answers a duplicate so). Over a slow, lossy link an ARM's resends are on
their way while the first arms the vehicle; if the vehicle's failsafe then disarmed it (no target came: the
controller had no ACK yet), a late resend armed it again, and the flight the failsafe had ended went on
(``bsst sitl missions/sine.toml --realtime --delay 150 --loss 60 --seed 2``: armed, failsafe, disarmed, armed
again, crashed). One arm is the first copy with confirmation 0 and the resends that follow it from the same
sender within :data:`RETRY_GAP_S` of the previous copy; a confirmation 0 starts a new one (the guard's ``resume``
asks anew after each failsafe). A retransmission that came with no first before it (the first lost) is that arm.
"""

from __future__ import annotations

from dataclasses import dataclass

# s of wall time: a resend more than this after the arm's previous copy is no resend of it (the controller resends
# every 0.1 s for 3 s, MAVSDK every 0.5 s three times): a new controller's first ARM lost, its resend is acted on
RETRY_GAP_S = 2.0

Source = tuple[int, int, tuple[str, int]]  # sysid, compid, address


@dataclass
class Arm:
    """One arm asked for by one sender: its copies' latest arrival (s) and, once acted on, its result."""

    last_s: float
    result: int | None = None

    @property
    def acted(self) -> bool:
        return self.result is not None


class ArmRetries:
    """The arm each sender is asking for now."""

    def __init__(self) -> None:
        self._arms: dict[Source, Arm] = {}

    def copy(self, source: Source, confirmation: int, now: float) -> Arm:
        """A copy of an ARM came from ``source`` at ``now`` (s): the arm it belongs to (a new one for a first send,
        or a resend with no arm of this sender's recent enough)."""
        arm = self._arms.get(source)
        if confirmation == 0 or arm is None or now - arm.last_s > RETRY_GAP_S:
            arm = self._arms[source] = Arm(now)
        else:
            arm.last_s = now
        return arm

    def forget(self, source: Source) -> None:
        """``source`` disarmed the vehicle: its arm is over (a resend of its next ARM, whose first copy was lost, is
        that arm's, acted on; it was answered ACCEPTED as the old arm's resend, the vehicle left disarmed)."""
        self._arms.pop(source, None)

    @staticmethod
    def acted(arm: Arm, result: int) -> None:
        """The vehicle acted on ``arm`` (a copy of it): ``result`` answers its later copies."""
        if arm.result is None:
            arm.result = result
