"""Covers bridge.link.radio, bridge.swarm and bridge.cli: a fleet behind one shared radio (``--shared-link``).

Real flights, in process, short (2 s of the sine at 100 Hz): the vehicles' packets of a direction queue in one
FIFO behind one bandwidth budget, each packet's random fate drawn from its own vehicle's seed. The summary's
``radio`` block gives each vehicle's share of the rate (together never more than the rate), its queue waits
and drops; two runs give the same bytes; one vehicle on a shared radio flies, bit for bit, as on its own link.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from bridge.cli import main
from bridge.link.radio import ProcessRadio, Radio, finished_part, make_radio_file, occupancy_of_parts
from bridge.link.turns import TurnRadio
from bridge.swarm import simulate
from bridge.swarm import sitl as swarm_sitl
from missions import MISSION_DIR
from params import ConfigError
from tests.benchkit import benchmark_module

# 242-byte states at 100 Hz are 24 200 B/s down: one vehicle fits in 40 000 B/s, three do not
RADIO = {"rate_bps": 40000.0, "queue_ms": 20.0, "loss_pct": 5.0}


def short_sine(tmp_path: Path, seconds: float = 2.0) -> Path:
    text = (MISSION_DIR / "sine.toml").read_text().replace("duration_s = 30.0", f"duration_s = {seconds}")
    f = tmp_path / "short.toml"
    f.write_text(text)
    return f


def fly(tmp_path: Path, name: str, n: int, shared: bool) -> dict:
    run = simulate(short_sine(tmp_path), vehicles=n, out=tmp_path / name, plots=False, rate_hz=100.0,
                   link={**RADIO, "shared": shared})
    return run.summary


def test_three_vehicles_on_one_radio_share_its_rate_and_queue_never_more_than_it_reproducibly(
        tmp_path: Path) -> None:
    s = fly(tmp_path, "shared", 3, True)
    radio = s["radio"]
    assert radio["shared"] is True and "rotating" in radio["order"]
    for d in ("up", "down"):
        r = radio[d]
        shares = [v["share_bps"] for v in r["vehicles"]]
        assert [v["id"] for v in r["vehicles"]] == [1, 2, 3] and all(x > 0 for x in shares)
        assert sum(shares) <= r["rate_bps"] * (1 + 1e-12) and math.isclose(sum(shares), r["share_bps"])
        assert r["occupancy"] <= 1.0 and r["span_s"] >= 2.0
        for v, flown in zip(r["vehicles"], s["vehicles"]):  # the radio's drops are each vehicle's queue losses
            assert v["lost_queue"] == flown["link"][d]["lost_by"]["queue"]
            assert v["queue_wait_ms"]["max"] <= RADIO["queue_ms"] + 1e-9
    down = radio["down"]
    assert down["occupancy"] > 0.99 and down["lost_queue"] > 0  # three vehicles' states overflow it
    assert all(v["queue_wait_ms"]["p50"] > 0 for v in down["vehicles"])
    randoms = [v["link"]["down"]["lost_by"]["random"] for v in s["vehicles"]]
    assert len(set(randoms)) > 1, randoms  # each vehicle's fates are its own seed's
    alone = fly(tmp_path, "own", 3, False)  # on radios of their own, each vehicle fits: nothing queues out
    assert "radio" not in alone
    assert all(v["link"][d]["lost_by"]["queue"] == 0 for v in alone["vehicles"] for d in ("up", "down"))
    assert fly(tmp_path, "again", 3, True) == s  # contention is reproducible, byte for byte
    for i in (1, 2, 3):
        a, b = (tmp_path / r / f"vehicle-{i}" / "trace.csv" for r in ("shared", "again"))
        assert a.read_bytes() == b.read_bytes()


def test_one_vehicle_on_a_shared_radio_flies_bit_for_bit_as_on_its_own(tmp_path: Path) -> None:
    mission = str(short_sine(tmp_path))
    tight = ["--rate", "100", "--bandwidth", "15000", "--queue", "40", "--loss", "5", "--no-plots"]  # saturated
    for fleet in ([], ["--vehicles", "1"]):
        for name, flag in (("own", []), ("shared", ["--shared-link"])):
            main(["sim", mission, *fleet, *tight, *flag, "--out", str(tmp_path / f"{name}{len(fleet)}")])
    assert (tmp_path / "own0" / "trace.csv").read_bytes() == (tmp_path / "shared0" / "trace.csv").read_bytes()
    one, shared = (tmp_path / f"{n}2" / "vehicle-1" for n in ("own", "shared"))
    assert (one / "trace.csv").read_bytes() == (shared / "trace.csv").read_bytes()
    assert json.loads((one / "summary.json").read_text()) == json.loads((shared / "summary.json").read_text())
    radio = json.loads((tmp_path / "shared2" / "summary.json").read_text())["radio"]["down"]
    assert radio["lost_queue"] > 0 and radio["vehicles"][0]["share_bps"] <= 15000.0


def test_the_benchmarks_table_says_when_a_failsafe_came_not_its_traces_end(
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """README's table (``python benchmarks/swarm_radio.py``): four vehicles on one sik-57600 radio, vehicles 3 and 4
    in their failsafe at 0.52 s, which flies their descent on to the mission's end; the benchmark said "failsafe at
    30.00 s" (its trace's end: a tour ran the README's command). A divergence is still said at its trace's end.
    With ``--lockstep`` each row adds a column (bit for bit against offline, the wall time): the header has it too
    (its rows had one cell more than the header)."""
    bench = benchmark_module("swarm_radio")
    monkeypatch.chdir(bench.ROOT)  # (its mission's path is the checkout's, as figures() flies it)
    r = bench.row(4, True, 50.0, False)
    said = [bench.show(v) for v in r["vehicles"]]
    assert said[2:] == ["2.31 (failsafe at 0.52 s)"] * 2 and said[:2] == ["n/a (diverged at 1.02 s)",
                                                                          "n/a (diverged at 0.94 s)"], said
    for same in (None, True):  # offline's table, and --lockstep's (the same row, as said against offline)
        shown = {**r, "fits_hz": 3.7, "offered_down": 13.4, "same_as_offline": same, "wall_s": 1.0}
        bench.print_table({"profile": "sik-57600", "down_bps": 3600.0, "up_bps": 3600.0, "command_bytes": 55,
                           "rows": [shown], "loadavg": (0.0, 0.0, 0.0)})
        head, rule, line = capsys.readouterr().out.splitlines()[1:4]
        assert head.count("|") == rule.count("|") == line.count("|") == 8 + (same is not None), (head, line)


def test_the_radio_admits_in_order_and_drops_what_would_wait_too_long() -> None:
    r = Radio(1000.0, 0.05, users=2)  # 1000 B/s: a 20-byte packet holds it 20 ms
    assert r.admit(0.0, 20, 0) == pytest.approx(0.020)
    assert r.admit(0.0, 20, 1) == pytest.approx(0.040)  # behind user 0's packet
    assert r.admit(0.0, 20, 1) == pytest.approx(0.060)  # waits 40 ms: within the 50 ms queue
    assert r.admit(0.0, 20, 0) is None  # would wait 60 ms: dropped
    occ = r.occupancy([7, 8], 0.0)
    assert occ["span_s"] == pytest.approx(0.060) and occ["lost_queue"] == 1
    assert [v["bytes"] for v in occ["vehicles"]] == [20, 40] and occ["occupancy"] == pytest.approx(1.0)
    assert Radio(0.0, 1.0).admit(3.0, 100) == 3.0  # no cap: sent at once, counted


def test_radios_of_two_processes_on_one_file_queue_as_one_radio(tmp_path: Path) -> None:
    """Two users of one radio file (each its own descriptor and clock origin, as two relays' are) give each
    packet the fate one in-memory radio gives it, and their parts make its occupancy block."""
    f = tmp_path / "radio"
    make_radio_file(f, 2)
    one = Radio(1000.0, 0.05, users=2)
    a, b = (ProcessRadio(f, "down", 1000.0, 0.05, user=u, offset=off) for u, off in ((0, 100.0), (1, 103.5)))
    up = ProcessRadio(f, "up", 1000.0, 0.05, user=0, offset=100.0)  # the other direction: a queue of its own
    packets = [(0.0, 20, 0), (0.0, 20, 1), (0.003, 20, 1), (0.005, 20, 0), (0.2, 50, 0), (0.21, 10, 1)]
    for t, size, u in packets:  # (t: s since 100.0, the first user's origin)
        want = one.admit(t, size, u)
        got = a.admit(t, size, 0) if u == 0 else b.admit(t - 3.5, size, 1)
        got = got if got is None or u == 0 else got + 3.5
        assert (got is None and want is None) or got == pytest.approx(want, abs=1e-9), (t, size, u)
    assert up.admit(0.0, 20, 0) == pytest.approx(0.020)  # nothing queued ahead of it in its direction
    parts = [finished_part(a.part()), finished_part(b.part())]
    assert [p["lost_queue"] for p in parts] == one.dropped == [1, 0]
    merged, alone = occupancy_of_parts(parts, [7, 8], 1000.0, 0.05), one.occupancy([7, 8], 0.0)
    assert merged["span_s"] == pytest.approx(alone["span_s"]) and merged["occupancy"] <= 1.0
    for x, y in zip(merged["vehicles"], alone["vehicles"]):
        assert x["bytes"] == y["bytes"] and x["share_bps"] == pytest.approx(y["share_bps"])
        assert x["queue_wait_ms"] == pytest.approx(y["queue_wait_ms"])
    for r in (a, b, up):
        r.close()


@pytest.mark.parametrize("what, says", [
    ("missing", "cannot open"), ("short", "not a radio file (its magic or size is wrong)"),
    ("user", "no user 2 in it (users 0-1)")])
def test_a_bad_radio_file_is_named(tmp_path: Path, what: str, says: str) -> None:
    """(``bsst relay --radio`` says the same: tests/test_swarm_radio_sitl.py.)"""
    f = tmp_path / "radio"
    if what == "short":
        f.write_bytes(b"BSSR")
    elif what == "user":
        make_radio_file(f, 2)
    for radio in (ProcessRadio, TurnRadio):  # (the file is the same in real time and in lockstep)
        with pytest.raises(ConfigError, match=f"--radio {f}: .*{says}".replace("(", r"\(").replace(")", r"\)")):
            radio(f, "up", 1000.0, 0.05, user=2 if what == "user" else 0)


def test_shared_link_is_refused_where_it_means_nothing(tmp_path: Path) -> None:
    """A handover on one radio is not modelled, in any clock: refused before anything starts. A SITL fleet refused
    it only once its run directory was made, so ``--overwrite`` had already removed the run recorded there; and
    after its ports were checked, so a busy instance was said instead (free ports here: no socket is touched)."""
    kept = tmp_path / "kept"
    kept.mkdir()
    (kept / "summary.json").write_text('{"outcome": "completed"}')
    for fly_it, where in ((simulate, {}), (swarm_sitl, {"instance": None})):
        with pytest.raises(ConfigError, match=r"link handovers \(--at 1:link:wifi\) is not modelled"):
            fly_it(short_sine(tmp_path), vehicles=2, link={"shared": True}, at=("1:link:wifi",), out=kept,
                   overwrite=True, **where)
        assert [p.name for p in kept.iterdir()] == ["summary.json"], fly_it
    with pytest.raises(ConfigError, match="shared: a link handover takes a profile"):  # the flight's, not an event's
        simulate(short_sine(tmp_path), vehicles=2, at=({"t_s": 1.0, "kind": "link", "shared": True},))
    with pytest.raises(ConfigError, match="link.shared: expected true or false"):
        simulate(short_sine(tmp_path), vehicles=2, link={"shared": 1})
