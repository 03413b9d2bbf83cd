"""The controller under a bad link: what to do with a state of a given age. Pure logic, no sockets.

:class:`LinkGuard` wraps a :class:`~controller.Controller`. The endpoint that receives the
vehicle's messages calls :meth:`LinkGuard.observe` for every state that arrives (older ones
than the newest are ignored) and :meth:`LinkGuard.step` once per control step; the
returned :class:`Decision` says whether to send a command, which one, and whether to ask
the vehicle to arm again. By the age a = t - t_state of the newest state:

- a <= ``stale_s``: **track** — control normally (on the prediction if
  ``compensation = "predict"``);
- ``stale_s`` < a <= ``stop_s``: **hold** — keep commanding, with the super-twisting
  integrators frozen (``Controller.step(..., hold=True)``) so they do not wind up on
  errors the controller cannot see;
- a > ``stop_s`` (or no state yet): **stop** — send nothing, so that the vehicle holds its
  last command and, after its own timeout, its failsafe takes over.

When the vehicle reports that it left offboard control (failsafe, landed) the guard stops
commanding; with ``resume`` it instead asks the vehicle to arm again as soon as the state is
fresh, resets the integrators and resumes the mission where the reference is by then.

With ``compensation = "predict"`` the newest state is carried to the current time through
the nominal model (:class:`controller.predict.Predictor`) with the commands sent since.
With an assumed command latency ``lag_s`` > 0 as well, each command is taken to act
``lag_s`` after it is sent, and the law aims the new command at the time it will act: it
controls the state predicted at t + lag_s towards the reference at t + lag_s (a Smith
predictor over the whole loop; the offboard process can set ``lag_s`` from its TIMESYNC
estimate of the up-link delay).

In:  the age (s) of the newest state the controller holds, the guard's thresholds ``stale_s``, ``stop_s`` (s)
Out: what to do with it: track, hold the integrators, stop commanding, re-arm
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

from controller import Command, Controller
from controller.predict import Predictor
from missions.references import Sample

COMPENSATIONS = ("none", "predict")
TRACK, HOLD, STOP, REARM, IDLE = "track", "hold", "stop", "rearm", "idle"


@dataclass(frozen=True)
class GuardConfig:
    """Thresholds (s) on the age of the newest state, and what to do about delay and failsafe."""

    stale_s: float = 0.05  # older: freeze the super-twisting integrators
    stop_s: float = 0.25  # older: stop commanding (the vehicle's failsafe takes over)
    compensation: str = "none"  # "predict": control on the state carried forward to now
    lag_s: float = 0.0  # assumed command latency (s): predict to, and aim at, t + lag_s
    resume: bool = False  # re-arm and resume when the link returns after a failsafe

    def __post_init__(self) -> None:
        if self.compensation not in COMPENSATIONS:
            raise ValueError(f"compensation must be one of {', '.join(COMPENSATIONS)}, got {self.compensation!r}")
        if not 0.0 < self.stale_s <= self.stop_s:
            raise ValueError(f"need 0 < stale_s <= stop_s, got {self.stale_s:g}, {self.stop_s:g}")
        if self.lag_s < 0.0 or (self.lag_s > 0.0 and self.compensation != "predict"):
            raise ValueError(f"lag_s must be >= 0 and needs compensation 'predict', got {self.lag_s:g}")


class Decision(NamedTuple):
    """One step's verdict. ``command`` None: send nothing this step. (A named tuple: one a control step, made in a
    third of a frozen dataclass's time.)"""

    mode: str  # track | hold | stop | rearm | idle
    command: Command | None
    arm: bool  # ask the vehicle to arm and take offboard control again
    state_age_s: float  # age of the newest state (nan before the first one)
    state_t: float  # its time stamp (nan before the first one)


class LinkGuard:
    """A controller that knows the age of its newest state (see the module docstring)."""

    def __init__(self, controller: Controller, cfg: GuardConfig | None = None) -> None:
        self.ctl = controller
        self.cfg = cfg = cfg or GuardConfig()
        self.predictor = (Predictor(controller.nominal, 1.0 / controller.rate_hz, cfg.lag_s)
                          if cfg.compensation == "predict" else None)
        self.state_t = -math.inf
        self.state: tuple[float, ...] | None = None
        self.offboard = True  # as last reported by the vehicle
        self.mode = STOP
        self.events: list[tuple[float, str, str]] = []
        self._rearming = False
        self._lost_since: float | None = None

    def observe(self, t_state: float, X: tuple[float, ...], offboard: bool | None = None) -> bool:
        """A state measured at ``t_state`` (s) arrived. False (and ignored) if not newer than
        the newest; ``offboard``: the vehicle's report that it is armed under offboard control."""
        if t_state <= self.state_t:
            return False
        self.state_t = t_state
        self.state = tuple(X)
        if offboard is not None:
            self.offboard = offboard
        return True

    def _event(self, t: float, kind: str, text: str) -> None:
        self.events.append((t, kind, text))

    def step(self, t: float, reference: Callable[[float], Sample]) -> Decision:
        """The decision for control step time t (s); ``reference(t)`` samples the mission's reference."""
        cfg = self.cfg
        if self.state is None:
            return Decision(STOP, None, False, math.nan, math.nan)
        age = t - self.state_t
        if age > cfg.stop_s:
            mode = STOP
        elif not self.offboard:
            mode = REARM if cfg.resume and age <= cfg.stale_s else IDLE
        else:
            mode = TRACK if age <= cfg.stale_s else HOLD
        self._transition(t, mode, age)
        if mode in (STOP, IDLE):
            return Decision(mode, None, False, age, self.state_t)
        X = self.state
        aim = t
        if self.predictor is not None:
            aim = t + cfg.lag_s
            X = self.predictor.predict(self.state_t, X, aim)
        cmd = self.ctl.step(aim, X, reference(aim), hold=(mode == HOLD))
        if self.predictor is not None:
            self.predictor.sent(t, cmd.realisable, self.ctl.actuation.omega_d)
        return Decision(mode, cmd, mode == REARM, age, self.state_t)

    def _transition(self, t: float, mode: str, age: float) -> None:
        prev = self.mode
        if mode == prev:
            return
        self.mode = mode
        if mode == HOLD:
            self._lost_since = self._lost_since if self._lost_since is not None else t
            self._event(t, "link_stale", f"newest state {age * 1000:.0f} ms old: integrators frozen")
        elif mode == STOP and prev != STOP:
            self._lost_since = self._lost_since if self._lost_since is not None else t
            self._event(t, "link_lost", f"no state for {age * 1000:.0f} ms: commands stopped")
        elif mode == IDLE:
            self._event(t, "vehicle_left_offboard", "vehicle not under offboard control: commands stopped")
        elif mode == REARM:
            self.ctl.reset()
            if self.predictor is not None:
                self.predictor.reset()
            self._rearming = True
            self._event(t, "rearm", "link back, vehicle in failsafe: asking it to arm, integrators reset")
        elif mode == TRACK:
            if self._rearming:
                self._rearming = False
                self._event(t, "resumed", "vehicle back under offboard control: mission resumed")
            elif self._lost_since is not None:
                self._event(t, "link_restored", f"fresh state again after {t - self._lost_since:.3f} s")
            self._lost_since = None
