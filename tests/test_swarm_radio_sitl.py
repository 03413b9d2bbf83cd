"""Covers bridge.link.radio, bridge.link.turns, bridge.nodes.relay, bridge.session.fleet and bridge.swarm: a SITL
fleet behind one shared radio (``bsst sitl --vehicles N --shared-link [--realtime]``).

Real processes: per vehicle a ``bsst vehicle``, a ``bsst controller`` and the ``bsst relay`` that applies its link
on the wall clock, over UDP on 127.0.0.1 (free ports, ``instance=None``). On one radio every relay puts its
vehicle's packets of a direction in the one queue (a radio file they all map), so two vehicles whose states
each fit the radio's rate overflow it together; on radios of their own neither queues out. The fleet's
``radio`` block is made of each relay's part, which is that vehicle's own queue losses. In lockstep the vehicles
(commands) and the controllers (states) take turns on the radio's file in the offline loop's order: the flights
and the radio block are the offline fleet's, bit for bit, also when vehicles leave.
"""

from __future__ import annotations

import json
import math
import tempfile
from pathlib import Path

import numpy as np
import pytest

from bridge.cli.flags import refusal_line
from bridge.cli.runreport import report_fleet
from bridge.link.radio import make_radio_file
from bridge.link.turns import TURNS
from bridge.nodes.report import BadInput, parse_line
from bridge.session.children import PORT_LOCKS
from bridge.swarm import simulate, sitl
from missions import MISSION_DIR
from tests.sitlkit import ENV, ROOT, run_bsst, stall_blackouts

pytestmark = pytest.mark.process  # starts processes

# 242-byte states at 100 Hz are 24 200 B/s down, 76 % of 32 000 B/s: one vehicle fits (its 100 ms queue rides
# out a burst of 13 states), two offer 1.5 times the rate
RADIO = {"rate_bps": 32000.0, "queue_ms": 100.0, "loss_pct": 5.0}


def fly(tmp_path: Path, name: str, shared: bool, radio: dict | None = None, seconds: float = 3.0) -> dict:
    """Two vehicles of the sine cut to ``seconds`` in real time, each behind its relay, on one radio or on their
    own: the fleet's summary. Its end holds: the end landing (down from 0.3 m, then COM_DISARM_LAND) added ~2.4 s of
    both pairs and relays on the wall clock that no assertion reads (tests/test_mission_end.py flies the end
    landing)."""
    text = (MISSION_DIR / "sine.toml").read_text().replace("duration_s = 30.0", f"duration_s = {seconds}")
    (tmp_path / "short.toml").write_text(text + '\n[end]\naction = "hold"\n')
    run = sitl(tmp_path / "short.toml", vehicles=2, realtime=True, instance=None, out=tmp_path / name,
               plots=False, rate_hz=100.0, link={**(RADIO if radio is None else radio), "shared": shared})
    assert json.loads((tmp_path / name / "summary.json").read_text()) == run.summary  # what was written
    return run.summary


def test_two_vehicles_on_one_radio_in_real_time_share_its_rate_and_overflow_it_where_each_alone_fits(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    private = tmp_path / "tmp"
    private.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(private))  # where the fleet keeps its radio file
    s = fly(tmp_path, "shared", True)
    radio = s["radio"]
    assert radio["shared"] is True and radio["order"].startswith("first come, first served on the wall clock")
    for d in ("up", "down"):
        r = radio[d]
        shares = [v["share_bps"] for v in r["vehicles"]]
        assert [v["id"] for v in r["vehicles"]] == [1, 2] and all(x > 0 for x in shares)
        assert r["rate_bps"] == RADIO["rate_bps"] and r["queue_ms"] == RADIO["queue_ms"] and r["span_s"] > 2.0
        assert sum(shares) <= r["rate_bps"] * (1 + 1e-9) and math.isclose(sum(shares), r["share_bps"])
        for v, flown in zip(r["vehicles"], s["vehicles"]):  # each relay's part: its vehicle's own queue losses
            assert v["lost_queue"] == flown["link"][d]["lost_by"]["queue"]
            assert v["queue_wait_ms"]["max"] <= RADIO["queue_ms"] + 1e-6
    down = radio["down"]
    # the two vehicles' states overflow it; but while the machine stalls a vehicle or a relay (which is the radio:
    # timing.stalls, docs/sitl.md) nothing is offered or handed on, and that time may stand idle
    stalls = [a for i in (1, 2) for a in
              json.loads((tmp_path / "shared" / f"vehicle-{i}" / "summary.json").read_text())["timing"]["stalls"]["at"]]
    idle_s = sum(d for _, d in stall_blackouts({"at": stalls}, math.inf))  # their union
    # and while only one vehicle sends (one alone fits the radio): before the later first packet and after the earlier
    # last one, as when a vehicle's flight ends first (a crash: it stops)
    ends = [json.loads((tmp_path / "shared" / f"vehicle-{i}" / "relay.json").read_text())["radio"]["down"]
            for i in (1, 2)]
    idle_s += abs(ends[0]["first_s"] - ends[1]["first_s"]) + abs(ends[0]["last_end_s"] - ends[1]["last_end_s"])
    assert down["occupancy"] > 0.9 - idle_s / down["span_s"] and down["lost_queue"] > 0, (down, idle_s)
    # each vehicle's states waited behind the other's while both sent; not at the median, for a vehicle that flies
    # on alone for more than half its flight (the other crashed: one alone fits the radio), but above it
    assert all(v["queue_wait_ms"]["p95"] > 0 for v in down["vehicles"]), down["vehicles"]
    assert s["sitl"]["shared_clock"] is False and s["clock"] == "realtime"
    # the radio file is gone with the fleet (the port lock file stays, as the instances' lock files do)
    assert {f.name for f in private.iterdir()} <= {PORT_LOCKS}
    alone = fly(tmp_path, "own", False)  # on radios of their own, each vehicle's states fit: none queues out
    assert "radio" not in alone
    assert all(v["link"][d]["lost_by"]["queue"] == 0 for v in alone["vehicles"] for d in ("up", "down")), alone


def test_one_radio_without_a_rate_counts_every_vehicles_bytes_in_real_time(tmp_path: Path) -> None:
    """A perfect link shared: the relays are the radio all the same (as offline, the bytes only)."""
    s = fly(tmp_path, "perfect", True, radio={}, seconds=1.0)
    for d in ("up", "down"):
        r = s["radio"][d]
        assert r["rate_bps"] is None and r["occupancy"] is None and r["lost_queue"] == 0
        assert [v["id"] for v in r["vehicles"]] == [1, 2] and all(v["bytes"] > 0 for v in r["vehicles"]), r
    for i in (1, 2):
        assert (tmp_path / "perfect" / f"vehicle-{i}" / "relay.json").is_file()


@pytest.mark.parametrize("what, says", [("missing", "cannot open"), ("user", "no user 2 in it (users 0-1)"),
                                        ("handover", "the link has handovers (events of kind link)")])
def test_a_relay_given_a_bad_radio_file_names_it_in_one_line_and_exits_2(tmp_path: Path, what: str,
                                                                           says: str) -> None:
    f, mission = tmp_path / "radio", tmp_path / "handover.toml"
    if what != "missing":
        make_radio_file(f, 2)
    mission.write_text((MISSION_DIR / "step.toml").read_text() + '\n[[events]]\nt_s = 1.0\nkind = "link"\n'
                       'profile = "wifi"\n')
    extra = ["--radio-user", "0", "--mission", str(mission)] if what == "handover" else ["--radio-user", "2"]
    p = run_bsst("relay", "--listen", "127.0.0.1:0", "--to", "127.0.0.1:9", "--radio", str(f), "--bandwidth", "1000",
                 *extra, cwd=ROOT, env=ENV, timeout=60)
    assert p.stderr.startswith(f"bsst: --radio {f}: ") and says in p.stderr and p.stderr.count("\n") == 1, p.stderr
    # its stdout is reports (a session's child's, run by hand too): the refusal is its one line there, typed
    reports = [parse_line(ln) for ln in p.stdout.splitlines()]
    assert p.returncode == 2 and len(reports) == 1 and isinstance(reports[0], BadInput), p.stdout
    assert refusal_line(reports[0].error()) == p.stderr.strip()
    assert reports[0].source == f"--radio {f}" and reports[0].key is None and says in reports[0].what  # typed: its flag


# -- in lockstep: the offline fleet's radio, bit for bit (bridge.link.turns) ------------------------------------
def _offline_and_lockstep(tmp_path: Path, n: int, seconds: float, rate: float, link: dict, **kw: object) -> tuple:
    text = (MISSION_DIR / "sine.toml").read_text().replace("duration_s = 30.0", f"duration_s = {seconds}")
    (tmp_path / "short.toml").write_text(text)
    args = {"vehicles": n, "plots": False, "rate_hz": rate, "link": {**link, "shared": True}, **kw}
    off = simulate(tmp_path / "short.toml", **args)
    run = sitl(tmp_path / "short.toml", instance=None, out=tmp_path / "lockstep", **args)
    return off, run


def _same_flights(off: object, run: object) -> None:
    for a, b in zip(off.runs, run.runs):  # type: ignore[attr-defined]
        assert a.outcome == b.outcome and len(a.trace["t"]) == len(b.trace["t"])
        for c in ("x", "y", "z", "phi", "u1_act", "u2_act", "state_age_s"):
            assert np.array_equal(a.trace[c], b.trace[c], equal_nan=True), c
    for d in ("up", "down"):
        assert run.summary["radio"][d] == off.summary["radio"][d]  # type: ignore[attr-defined]
    assert run.summary["radio"]["order"] == off.summary["radio"]["order"] == TURNS  # type: ignore[attr-defined]
    assert run.summary["radio"]["late_turns"] == {str(i): [] for i in range(1, len(off.runs) + 1)}  # type: ignore


def test_a_lockstep_fleet_on_one_radio_flies_the_offline_fleets_packets_bit_for_bit(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Three vehicles whose states overflow the radio together (each alone fits): every vehicle's trace, and each
    direction's radio block (bytes, queue drops and waits per vehicle), are the offline fleet's."""
    private = tmp_path / "tmp"
    private.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(private))  # where the fleet keeps its radio file
    off, run = _offline_and_lockstep(tmp_path, 3, 2.0, 100.0, RADIO)
    _same_flights(off, run)
    down = run.summary["radio"]["down"]
    assert down["occupancy"] > 0.99 and all(v["lost_queue"] > 0 for v in down["vehicles"])
    assert run.summary["clock"] == "lockstep" and run.summary["sitl"]["shared_clock"] is True
    assert {f.name for f in private.iterdir()} <= {PORT_LOCKS}  # the radio file is gone with the fleet


def test_a_state_that_entered_the_radio_out_of_turn_is_said_and_exits_1(tmp_path: Path, capsys) -> None:
    """(A controller that waited TURN_WAIT_S for another's turn: the summary's radio.late_turns, which
    bsst sitl reads.) The fleet above as recorded, with vehicle 2's state of step 7 entered out of turn."""
    off, run = _offline_and_lockstep(tmp_path, 2, 0.5, 100.0, RADIO)
    assert report_fleet(run, "sitl") == 0
    run.summary["radio"]["late_turns"]["2"] = [7]
    assert report_fleet(run, "sitl") == 1
    assert "bsst sitl: vehicle 2: its states of steps 7 entered the radio out of turn: not the offline fleet's " \
        "flight" in capsys.readouterr().err


def test_a_lockstep_radio_without_a_rate_counts_the_bytes_as_offline_without_turns(tmp_path: Path) -> None:
    """Without a rate no packet waits, so the order changes nothing and no turns are taken: the same flights and
    byte counts as offline, and no controller ever waited for a turn (tests/test_radio_turns.py: none is taken)."""
    off, run = _offline_and_lockstep(tmp_path, 2, 1.0, 100.0, {})
    _same_flights(off, run)
    assert run.summary["radio"]["down"]["rate_bps"] is None and run.summary["radio"]["down"]["share_bps"] > 0
    for i in (1, 2):
        own = json.loads((tmp_path / "lockstep" / f"vehicle-{i}" / "summary.json").read_text())
        assert own["link"]["radio"]["down"]["turn_waits"] == 0


def test_vehicles_that_leave_a_lockstep_radio_leave_its_turns_as_offline(tmp_path: Path) -> None:
    """On one sik-57600 radio at 50 Hz two of four vehicles diverge within a second and leave; the two others fly
    on in failsafe, their turns over the two left: the same flights and radio as offline."""
    off, run = _offline_and_lockstep(tmp_path, 4, 3.0, 50.0, {"profile": "sik-57600"}, formation="line:2")
    assert [r.outcome for r in off.runs] == ["diverged", "diverged", "failsafe", "failsafe"]
    _same_flights(off, run)


def test_a_controller_given_a_bad_radio_names_it_in_one_line_and_exits_2(tmp_path: Path) -> None:
    f = tmp_path / "radio"
    make_radio_file(f, 2)
    for extra, says in ((["--radio", str(tmp_path / "none")], "cannot open"),
                        (["--radio", str(f), "--radio-user", "2"], "no user 2 in it (users 0-1)"),
                        (["--radio", str(f), "--realtime"], "--radio with --realtime")):
        p = run_bsst("controller", str(MISSION_DIR / "sine.toml"), "--vehicle", "127.0.0.1:9", "--timeout", "1",
                     *extra, cwd=ROOT, env=ENV, timeout=60)
        assert p.returncode == 2 and p.stderr.count("\n") == 1 and says in p.stderr, p.stderr
