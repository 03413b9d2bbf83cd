"""Why a flight was not flown as asked: the one list every command says it from (``bsst sim``, ``bsst sitl``, a
fleet's vehicle, ``bsst controller`` alone).

In:  a run's ``summary.json`` as a dict (one vehicle's), or the blocks of it a process alone knows (``bsst
     controller``: ``param_at``, ``end``, ``timing.stalls``): ``lockstep``, ``interventions``, ``param_at``, ``end``
     (:mod:`bridge.record.ending`), ``timing.stalls`` (t s, ms)
Out: :func:`ended_text`: why a flight ended before its mission did (its outcome, who ended it and how: ``failsafe:
     ended by vehicle: ...``), :func:`waited_text` the machine's stalls of its controller before the mission's first
     state, said with it (:func:`waiting_stalls_text`, the words); :func:`not_as_asked`: one line each, ``not flown
     as asked: ...`` (or ``not a lockstep run: ...``); any one of them makes the exit status 1

Split out of :mod:`bridge.cli.runreport` (which prints a run's summary) so that ``bsst controller``, below the CLI,
says it in the same words.
"""

from __future__ import annotations

from typing import Any


def ended_text(s: dict[str, Any]) -> str | None:
    """Why a run (one vehicle's: its ``outcome`` and ``ended_by``) ended before its mission did, as its summary says it
    (``diverged: ended by plant: diverged at t=3.632 s: position beyond 100 m``); None when it completed (exit 1
    otherwise: a failsafe, a divergence, a crash, a stop, ...)."""
    outcome = s.get("outcome")
    if outcome in (None, "completed"):
        return None
    eb = s.get("ended_by") or {}
    return f"{outcome}: ended by {eb['who']}: {eb['how']}" if eb else str(outcome)


def not_as_asked(s: dict[str, Any]) -> list[str]:
    """Why a run (one vehicle's) was not flown as the command asked, beyond its outcome and its policies, one text
    each (exit 1): it left lockstep, someone else changed it, a scheduled change went unconfirmed, the machine
    stalled it in real time, the vehicle never took the mission's end action."""
    from bridge.record.ending import not_taken_text  # lazy: numpy
    from bridge.record.interventions import intervention_text, unconfirmed_text  # lazy: numpy
    from bridge.record.policies import stalls_of  # lazy: numpy

    lock = s.get("lockstep") or {"held": True}
    said = ([f"not a lockstep run: the vehicle left lockstep at t={lock['left_at_s']:.3f} s ({lock['why']})"]
            if not lock.get("held", True) else [])
    said += [f"not flown as asked: {intervention_text(i)}" for i in s.get("interventions") or []]
    said += [f"not flown as asked: {unconfirmed_text(p)}" for p in s.get("param_at") or [] if not p.get("confirmed")]
    if not (s.get("end") or {}).get("taken", True):  # its end action lost: it came down by its failsafe
        said.append(f"not flown as asked: {not_taken_text(s['end'])}")
    stalls = stalls_of(s)
    return said + ([stalls_text(stalls)] if stalls is not None else [])


def waited_text(s: dict[str, Any]) -> str | None:
    """A run that ended before its mission did, its controller stalled by the machine before the mission's first
    state (``timing.stalls_waiting``, real time: not the mission's, but no target came meanwhile, which may have
    ended it): said with why it ended; None otherwise."""
    waited = (s.get("timing") or {}).get("stalls_waiting") or {}
    if s.get("outcome") in (None, "completed") or not waited.get("count"):
        return None
    return waiting_stalls_text(waited)


def stalls_text(stalls: dict[str, Any]) -> str:
    """The note of a real-time run the machine stalled (its events and printed summary)."""
    first = ", ".join(f"{s['side']} {s['ms']:g} ms at t={s['t']:.3f} s" for s in stalls["at"][:3])
    more = f" and {stalls['count'] - 3} more" if stalls["count"] > 3 else ""
    return (f"not flown as asked: the machine stalled the real-time loop {stalls['count']} time(s), worst "
            f"{stalls['worst_ms']:g} ms ({first}{more}): outages no link model asked for")


def waiting_stalls_text(stalls: dict[str, Any]) -> str:
    """The note of a flight that failed after the machine stalled its controller before the mission's first state
    (``timing.stalls_waiting``): no target came meanwhile, the vehicle's failsafe counting (docs/sitl.md)."""
    return (f"the machine stalled the controller {stalls['count']} time(s) before the mission's first state (after "
            f"the vehicle's arm), worst {stalls['worst_ms']:g} ms: no target meanwhile")
