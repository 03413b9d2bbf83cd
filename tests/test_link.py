"""Covers bridge.link.model.

The link-impairment model (bridge.link.model): statistics, reproducibility, invariants, configuration."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bridge.cli import main
from bridge.link import impairment
from bridge.link.config import NORMAL_BOUND_SIGMAS
from bridge.link.model import (
    FRAME_BYTES,
    LinkConfig,
    LinkImpairment,
    fates,
    link_from_table,
    merge_link_tables,
)
from params import ConfigError

N = 10_000
PERIOD = 0.004  # s, 250 Hz


def stream(cfg: LinkConfig, n: int = N, period: float = PERIOD, size: int = 93, direction: str = "up"):
    """Send n packets every ``period`` s, drain, return (model, deliveries)."""
    link = LinkImpairment(cfg, direction)
    out = []
    for i in range(n):
        link.send(i * period, size, i)
        out += link.deliver(i * period)
    out += link.drain()
    return link, out


def bursts(lost: list[bool]) -> list[int]:
    """Lengths of the runs of consecutive losses."""
    runs, n = [], 0
    for x in lost:
        if x:
            n += 1
        elif n:
            runs.append(n)
            n = 0
    if n:
        runs.append(n)
    return runs


# -- statistics over 10 000 packets (fixed seeds: the model is deterministic per seed) --------
@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("loss", [1.0, 5.0, 20.0, 50.0])
def test_bernoulli_loss_rate_within_one_point(loss: float, seed: int) -> None:
    link, _ = stream(LinkConfig(loss_pct=loss, seed=seed))
    s = link.stats
    assert s.sent == N and s.lost + s.delivered == N
    assert abs(100.0 * s.lost / N - loss) <= 1.0


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize(("loss", "burst"), [(10.0, 3.0), (20.0, 5.0), (30.0, 8.0)])
def test_gilbert_elliott_mean_burst_within_ten_percent(loss: float, burst: float, seed: int) -> None:
    lost = [f.lost for f in fates(LinkConfig(loss_pct=loss, burst_len=burst, seed=seed), "down", N)]
    runs = bursts(lost)
    assert abs(sum(runs) / len(runs) - burst) <= 0.1 * burst
    assert abs(100.0 * sum(lost) / N - loss) <= 0.3 * loss  # bursty: the fraction varies more than Bernoulli's


def test_bernoulli_bursts_are_short_and_gilbert_bursts_long() -> None:
    """Same loss rate, different burstiness: Bernoulli's mean run is 1/(1-p)."""
    b = bursts([f.lost for f in fates(LinkConfig(loss_pct=20.0), "up", N)])
    g = bursts([f.lost for f in fates(LinkConfig(loss_pct=20.0, burst_len=6.0), "up", N)])
    assert abs(sum(b) / len(b) - 1.25) < 0.1
    assert sum(g) / len(g) > 5.0


@pytest.mark.parametrize(("delay", "jitter", "kind"),
                         [(20.0, 5.0, "uniform"), (20.0, 5.0, "normal"), (2.0, 5.0, "uniform"),
                          (2.0, 5.0, "normal"), (10.0, 0.0, "uniform")])
def test_delay_plus_jitter_mean_and_never_negative(delay: float, jitter: float, kind: str) -> None:
    link, out = stream(LinkConfig(delay_ms=delay, jitter_ms=jitter, jitter=kind, seed=3))
    d = [(x.due_t - x.sent_t) * 1000.0 for x in out]
    assert len(d) == N
    assert min(d) >= 0.0
    assert abs(sum(d) / N - delay) <= 0.2
    if jitter:
        assert max(d) - min(d) > min(delay, jitter)  # it does jitter
    p = link.stats.summary()["delay_ms"]
    assert p["p50"] <= p["p95"] <= p["p99"] <= p["max"]


@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("pct", [2.0, 10.0, 20.0])
def test_reorder_and_duplication_rates_within_one_point(pct: float, seed: int) -> None:
    link, out = stream(LinkConfig(reorder_pct=pct, seed=seed))
    assert abs(100.0 * link.stats.reordered / N - pct) <= 1.0
    assert link.stats.delivered == N and link.stats.duplicated == 0
    link, out = stream(LinkConfig(dup_pct=pct, seed=seed))
    assert abs(100.0 * link.stats.duplicated / N - pct) <= 1.0
    assert len(out) == N + link.stats.duplicated and link.stats.delivered == N


def test_held_packet_arrives_right_after_its_successor() -> None:
    """Reordering holds a packet back until the next packet that is not held goes through."""
    _, out = stream(LinkConfig(reorder_pct=20.0, seed=5), n=2000)
    order = [d.seq for d in out]
    assert sorted(order) == list(range(2000))
    highest, releaser = -1, {}
    for s in order:
        if s > highest:
            highest = s
        else:
            releaser[s] = highest
    assert 300 < len(releaser) < 500
    for s, r in releaser.items():
        assert r > s and all(x in releaser for x in range(s + 1, r))  # r is its first successor not held


def test_a_held_packets_copy_is_held_with_it() -> None:
    """Duplication copies the packet as the hold-back left it: with every packet duplicated, as many are reordered
    as without, both copies of a held packet come after a later packet, and every copy is counted. Until the
    fix-linkdup branch the copy went through on time and undid the hold-back (reordered 0: ``--dup 100 --reorder
    99.9`` flew as a perfect link), and the held original, never released, was counted nowhere."""
    cfg = LinkConfig(delay_ms=4.0, jitter_ms=1.0, reorder_pct=20.0, seed=5)
    plain, _ = stream(cfg, n=2000)
    link, out = stream(replace(cfg, dup_pct=100.0), n=2000)
    assert 300 < plain.stats.reordered == link.stats.reordered
    assert link.stats.delivered == link.stats.duplicated == 2000 and len(out) == 4000
    held = [f.held for f in fates(replace(cfg, dup_pct=100.0), "up", 2000)]
    highest = -1
    for d in out:
        assert not held[d.seq] or highest > d.seq, d  # each copy of a held packet: after a later packet
        highest = max(highest, d.seq)
    # nearly every packet held: its copies wait with it for the rare one that is not (no successor: in flight)
    link = LinkImpairment(LinkConfig(dup_pct=100.0, reorder_pct=99.9), "down")
    for i in range(750):
        link.send(i * PERIOD, 93, i)
        link.deliver(i * PERIOD)
    s = link.stats
    assert s.delivered + s.in_flight == 750 and s.in_flight > 0 and s.duplicated == s.delivered > 0


def test_blackout_loses_exactly_the_window() -> None:
    link, out = stream(LinkConfig(blackouts=((1.0, 0.3), (5.0, 2.0))), n=2500)
    got = {d.seq for d in out}
    for i in range(2500):
        t = i * PERIOD
        inside = 1.0 <= t < 1.3 or 5.0 <= t < 7.0
        assert (i not in got) == inside
    assert link.stats.lost_by["blackout"] == 75 + 500


def test_bandwidth_cap_spaces_frames_and_tail_drops() -> None:
    size = FRAME_BYTES["ODOMETRY"]
    rate = 0.8 * size / PERIOD  # 80 % of what 250 Hz needs
    link, out = stream(LinkConfig(rate_bps=rate, queue_ms=200.0), n=5000, size=size)
    gaps = [b.due_t - a.due_t for a, b in zip(out, out[1:])]
    assert min(gaps) >= size / rate - 1e-9
    assert link.stats.lost_by["queue"] > 0
    assert max(d.due_t - d.sent_t for d in out) <= 0.2 + size / rate + 1e-9
    delivered_rate = link.stats.delivered * size / (out[-1].due_t - out[0].sent_t)
    assert delivered_rate <= rate * 1.001


# -- reproducibility: the fate of packet n is a function of (seed, direction, n) -------------------
def full_cfg(seed: int) -> LinkConfig:
    return LinkConfig(delay_ms=5.0, jitter_ms=3.0, jitter="normal", loss_pct=10.0, burst_len=3.0,
                      dup_pct=5.0, reorder_pct=5.0, seed=seed)


def test_same_seed_same_fates_whatever_the_clock() -> None:
    cfg = full_cfg(7)
    a = LinkImpairment(cfg, "down")
    b = LinkImpairment(cfg, "down")
    for i in range(3000):
        a.send(i * 0.004, 242, i)
        b.send(100.0 + i * 0.0173 + (i % 7) * 1e-3, 242, i)  # another clock, uneven spacing
    assert a.fates.n == b.fates.n
    assert fates(cfg, "down", 3000) == fates(cfg, "down", 3000)
    sa, sb = a.stats.summary(), b.stats.summary()
    assert sa["lost"] == sb["lost"] and sa["sent"] == sb["sent"]
    ja = [(d.seq, round(d.due_t - d.sent_t, 12)) for d in a.drain() if not d.copy]
    jb = [(d.seq, round(d.due_t - d.sent_t, 12)) for d in b.drain() if not d.copy]
    assert {s for s, _ in ja} == {s for s, _ in jb}


def test_seeds_and_directions_draw_different_streams() -> None:
    cfg = full_cfg(1)
    assert fates(cfg, "up", 500) != fates(full_cfg(2), "up", 500)
    assert fates(cfg, "up", 500) != fates(cfg, "down", 500)


# -- invariants (hypothesis) ---------------------------------------------------------------------
configs = st.builds(
    LinkConfig,
    delay_ms=st.floats(0.0, 200.0),
    jitter_ms=st.floats(0.0, 100.0),
    jitter=st.sampled_from(["uniform", "normal"]),
    loss_pct=st.floats(0.0, 60.0),
    burst_len=st.sampled_from([0.0, 2.0, 5.0]),
    dup_pct=st.floats(0.0, 50.0),
    reorder_pct=st.floats(0.0, 50.0),
    rate_bps=st.sampled_from([0.0, 20_000.0, 60_000.0]),
    blackouts=st.lists(st.tuples(st.floats(0.0, 2.0), st.floats(0.01, 0.5)), max_size=2).map(tuple),
    seed=st.integers(0, 2**31 - 1),
)


@settings(max_examples=60, deadline=None)
@given(cfg=configs, n=st.integers(1, 600), period=st.floats(0.0005, 0.02))
def test_model_invariants(cfg: LinkConfig, n: int, period: float) -> None:
    link = LinkImpairment(cfg, "up")
    out = []
    for i in range(n):
        link.send(i * period, 93, i)
        got = link.deliver(i * period)
        assert all(d.due_t <= i * period for d in got)
        out += got
    out += link.drain()
    s = link.stats
    # conservation
    assert s.sent == n
    assert s.delivered + s.lost == n and s.in_flight == 0
    assert len(out) == s.delivered + s.duplicated
    originals = [d.seq for d in out if not d.copy]
    assert len(originals) == len(set(originals)) == s.delivered
    # delivery order is time order, delays never negative and bounded
    assert all(a.due_t <= b.due_t for a, b in zip(out, out[1:]))
    lim = cfg.delay_ms / 1000.0
    for d in out:
        delay = d.due_t - d.sent_t
        assert delay >= 0.0
        if not cfg.rate_bps and not cfg.reorder_pct:
            assert delay <= 2.0 * lim + 1e-9
    # nothing sent in a blackout comes out
    for d in out:
        assert not any(a <= d.sent_t < a + w for a, w in cfg.blackouts)
    # loss is only what the fates, blackouts and the queue say
    f = fates(cfg, "up", n)
    assert s.lost_by["random"] <= sum(x.lost for x in f)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), loss=st.floats(0.0, 99.0), burst=st.floats(1.0, 50.0))
def test_gilbert_elliott_chain_is_valid_or_refused(seed: int, loss: float, burst: float) -> None:
    L = loss / 100.0
    if L > 0 and burst < L / (1 - L):
        with pytest.raises(ConfigError, match="burst_len"):
            LinkConfig(loss_pct=loss, burst_len=burst, seed=seed)
        return
    f = fates(LinkConfig(loss_pct=loss, burst_len=burst, seed=seed), "up", 200)
    assert all(x.jitter_s == 0.0 and not x.held and x.dup_jitter_s is None for x in f)


# -- MAVLink frame sizes ---------------------------------------------------------------------
def test_frame_sizes_are_pymavlink_encodings() -> None:
    from pymavlink.dialects.v20 import common as m

    mav = m.MAVLink(None, srcSystem=1, srcComponent=1)
    nan = float("nan")
    odo = m.MAVLink_odometry_message(12_345_678, m.MAV_FRAME_LOCAL_NED, m.MAV_FRAME_BODY_FRD, 1.1, 2.2, -3.3,
                                     [0.9, 0.1, 0.2, 0.3], 0.4, 0.5, 0.6, 0.01, 0.02, 0.03,
                                     [nan] + [0.0] * 20, [nan] + [0.0] * 20, 0, 0, 0)
    hil = m.MAVLink_hil_actuator_controls_message(12_345_678, [0.5] * 4 + [0.0] * 12,
                                                  m.MAV_MODE_FLAG_SAFETY_ARMED, 1)
    sact = m.MAVLink_set_actuator_control_target_message(12_345_678, 0, 1, 1, [0.1, -0.2, 0.3, 0.5, 0, 0, 0, 0])
    arm = m.MAVLink_command_long_message(1, 1, m.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
    assert len(odo.pack(mav)) == FRAME_BYTES["ODOMETRY"]
    assert len(hil.pack(mav)) == FRAME_BYTES["HIL_ACTUATOR_CONTROLS"]
    assert len(sact.pack(mav)) == FRAME_BYTES["SET_ACTUATOR_CONTROL_TARGET"]
    assert len(arm.pack(mav)) == FRAME_BYTES["COMMAND_LONG"]


# -- the [link] table -------------------------------------------------------------------------
def test_link_table_both_directions_and_overrides() -> None:
    s = link_from_table({"delay_ms": 10, "loss_pct": 5, "up": {"delay_ms": 3}, "down": {"blackouts": [[1, 2]]},
                         "compensation": "predict", "stale_ms": 40, "stop_ms": 300}, "m.toml", seed=9)
    assert (s.up.delay_ms, s.down.delay_ms, s.up.loss_pct, s.down.loss_pct) == (3.0, 10.0, 5.0, 5.0)
    assert s.down.blackouts == ((1.0, 2.0),) and s.up.blackouts == ()
    assert s.up.seed == s.down.seed == 9
    assert s.guard.compensation == "predict" and s.guard.stale_s == 0.04 and s.guard.stop_s == 0.3
    assert not link_from_table({}, "m.toml").impaired


@pytest.mark.parametrize(("table", "message"), [
    ({"loss_pct": 120}, r"m\.toml: link\.loss_pct: must be in \[0, 100\], got 120"),
    ({"up": {"delay_ms": -1}}, r"m\.toml: link\.up\.delay_ms: must be in \[0, 60000\], got -1"),
    ({"down": {"jitter": "pareto"}}, r"m\.toml: link\.down\.jitter: must be one of uniform, normal"),
    ({"up": {"burst_len": 0.5}}, r"m\.toml: link\.up\.burst_len: must be 0 .* or >= 1"),
    ({"loss_pct": 90, "burst_len": 2}, r"m\.toml: link\.burst_len: with loss_pct = 90 the mean burst must be >= 9"),
    ({"blackouts": [[1.0]]}, r"m\.toml: link\.blackouts: element 0 must be a pair"),
    ({"down": {"blackouts": [[1.0, 0.0]]}}, r"m\.toml: link\.down\.blackouts: element 0: duration_s must be in"),
    ({"up": {"seed": 1.5}}, r"m\.toml: link\.up\.seed: expected an integer"),
    ({"up": {"delay": 10}}, r"m\.toml: link\.up\.delay: unknown key"),
    ({"sideways": {}}, r"m\.toml: link\.sideways: unknown key"),
    ({"compensation": "smith"}, r"m\.toml: link\.compensation: must be one of none, predict"),
    ({"stale_ms": 100, "stop_ms": 50}, r"m\.toml: link\.stop_ms: must be >= stale_ms = 100"),
    ({"command_lag_ms": 10}, r"m\.toml: link\.command_lag_ms: needs compensation = \"predict\""),
])
def test_link_table_errors_name_file_and_key(table: dict, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        link_from_table(table, "m.toml")


def test_merge_link_tables() -> None:
    base = {"delay_ms": 5, "up": {"loss_pct": 1, "delay_ms": 2}}
    over = {"up": {"delay_ms": 20}, "down": {"loss_pct": 3}, "compensation": "predict"}
    assert merge_link_tables(base, over) == {"delay_ms": 5, "up": {"loss_pct": 1, "delay_ms": 20},
                                            "down": {"loss_pct": 3}, "compensation": "predict"}
    assert base == {"delay_ms": 5, "up": {"loss_pct": 1, "delay_ms": 2}}


def test_mission_file_link_error_exits_2_with_one_line(tmp_path, capsys, missions_dir) -> None:
    text = (missions_dir / "sine.toml").read_text() + "\n[link.up]\nloss_pct = 101\n"
    bad = tmp_path / "bad.toml"
    bad.write_text(text)
    assert main(["sim", str(bad), "--out", str(tmp_path / "run"), "--no-plots"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "bad.toml: link.up.loss_pct: must be in [0, 100], got 101" in err[0]


@pytest.mark.parametrize(("flags", "message"), [
    (["--loss", "120"], "--loss must be in [0, 100] %, got 120"),
    (["--delay", "20ms"], "--delay must be a number in [0, 60000] ms, got '20ms'"),
    (["--up-delay", "x"], "--up-delay must be a number"),
    (["--blackout", "3"], "--blackout must be START:DURATION"),
    (["--down-blackout", "3:-1"], "--down-blackout must be START:DURATION"),
    (["--loss", "90", "--burst", "2"], "mean burst must be >= 9"),
    (["--compensation", "smith"], "--compensation: invalid choice"),
])
def test_bad_link_flags_exit_2_with_one_line(flags: list[str], message: str, capsys, missions_dir) -> None:
    assert main(["sim", str(missions_dir / "sine.toml"), "--no-plots", *flags]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]


def test_flags_become_the_link_table(tmp_path, missions_dir) -> None:
    import argparse

    from bridge.cli import build_parser, link_table_from_args

    args = build_parser().parse_args(["sim", "m.toml", "--delay", "10", "--up-delay", "3", "--down-loss", "5",
                                      "--blackout", "15:0.3", "--jitter", "2", "--jitter-dist", "normal",
                                      "--compensation", "predict", "--link-seed", "4"])
    table = link_table_from_args(args)
    assert table == {
        "up": {"delay_ms": 3.0, "jitter_ms": 2.0, "blackouts": [[15.0, 0.3]], "jitter": "normal", "seed": 4},
        "down": {"delay_ms": 10.0, "jitter_ms": 2.0, "loss_pct": 5.0, "blackouts": [[15.0, 0.3]],
                 "jitter": "normal", "seed": 4},
        "compensation": "predict",
    }
    assert link_table_from_args(build_parser().parse_args(["sim", "m.toml"])) == {}
    assert link_table_from_args(argparse.Namespace()) == {}
    s = link_from_table(table, "flags")
    assert s.up.delay_ms == 3.0 and s.down.loss_pct == 5.0 and s.guard.compensation == "predict"
    assert math.isclose(s.down.blackouts[0][1], 0.3)


@pytest.mark.parametrize("cfg, text, bound", [
    (LinkConfig(delay_ms=20.0, jitter_ms=5.0), "delay 20 ms ± 5 ms uniform", 5.0),
    (LinkConfig(delay_ms=20.0, jitter_ms=2.0, jitter="normal"), "delay 20 ms ± 2 ms normal", 10.0),
    (LinkConfig(delay_ms=0.0, jitter_ms=10.0), "delay 0 ms, no jitter (jitter 10 ms uniform capped at the delay)", 0.0),
    (LinkConfig(delay_ms=5.0, jitter_ms=10.0), "delay 5 ms ± 5 ms uniform (jitter 10 ms capped at the delay)", 5.0),
    (LinkConfig(delay_ms=5.0, jitter_ms=2.0, jitter="normal"),
     "delay 5 ms ± 2 ms normal truncated at ± 5 ms (the delay)", 5.0),
])
def test_the_described_jitter_is_the_jitter_flown(cfg: LinkConfig, text: str, bound: float) -> None:
    """``--jitter 10 --delay 0`` flies no jitter (it is capped at the delay: no delay is negative), yet the relay's
    and the session's ready line said ``delay 0 ms ± 10 ms uniform``: the line says what is flown now, and the
    bound is the one the model draws within (the largest jitter of 10 000 packets)."""
    assert cfg.describe() == text
    assert cfg.jitter_bound_ms == bound
    assert NORMAL_BOUND_SIGMAS == impairment._NORMAL_BOUND_SIGMAS  # the model's truncation, said as it flies
    assert cfg.jitter_capped == (cfg.delay_ms < (cfg.jitter_ms if cfg.jitter == "uniform" else 5.0 * cfg.jitter_ms))
    _, out = stream(cfg)
    worst = max(abs((d.due_t - d.sent_t) * 1e3 - cfg.delay_ms) for d in out)
    assert worst <= bound + 1e-9 and (bound == 0.0 or worst > 0.8 * bound)


def test_a_capped_jitter_is_in_the_summary_and_the_printed_one(tmp_path, capsys) -> None:
    """``bsst sim --jitter 10 --delay 0``: summary.json's ``link.jitter_capped`` names each direction's cap (a
    handover's too, from its time), and the printed summary says the flight flew without jitter."""
    from bridge import simulate

    mission = tmp_path / "m.toml"
    mission.write_text('name = "m"\nduration_s = 1.0\n[trajectory]\nkind = "sine"\n'
                       '[[events]]\nt_s = 0.5\nkind = "link"\ndelay_ms = 4.0\njitter_ms = 6.0\n')
    run = simulate(mission, plots=False, link={"delay_ms": 0.0, "jitter_ms": 10.0})
    caps = run.summary["link"]["jitter_capped"]
    assert caps == [
        {"direction": "up", "from_s": 0.0, "jitter_ms": 10.0, "jitter": "uniform", "delay_ms": 0.0, "bound_ms": 0.0},
        {"direction": "down", "from_s": 0.0, "jitter_ms": 10.0, "jitter": "uniform", "delay_ms": 0.0, "bound_ms": 0.0},
        {"direction": "up", "from_s": 0.5, "jitter_ms": 6.0, "jitter": "uniform", "delay_ms": 4.0, "bound_ms": 4.0},
        {"direction": "down", "from_s": 0.5, "jitter_ms": 6.0, "jitter": "uniform", "delay_ms": 4.0, "bound_ms": 4.0}]
    plain = tmp_path / "plain.toml"
    plain.write_text('name = "m"\nduration_s = 1.0\n[trajectory]\nkind = "sine"\n')
    uncapped = simulate(plain, plots=False, link={"delay_ms": 20.0, "jitter_ms": 5.0})
    assert "jitter_capped" not in uncapped.summary["link"]
    argv = ["sim", str(mission), "--delay", "0", "--jitter", "10", "--no-plots", "--out", str(tmp_path / "r")]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "link up  : jitter 10 ms uniform capped at the delay, 0 ms: flown without jitter\n" in out
    assert "link down: jitter 6 ms uniform from t=0.5 s capped at the delay, 4 ms: drawn within ± 4 ms\n" in out


def test_a_link_that_delivered_nothing_yet_is_shown(tmp_path, capsys) -> None:
    """Every state still in flight at the end (a delay past the flight): the summary's link lines show it (they were
    left out, as if the link were perfect, since nothing was lost, duplicated or reordered and no delay measured)."""
    mission = tmp_path / "m.toml"
    mission.write_text('name = "m"\nduration_s = 1.0\n[trajectory]\nkind = "sine"\n')
    assert main(["sim", str(mission), "--down-delay", "40000", "--no-plots", "--out", str(tmp_path / "r")]) == 1
    out = capsys.readouterr().out
    assert "\nlink down: sent 250 delivered 0 lost 0 in flight 250 dup 0 reordered 0 delay p50 n/a ms" in out, out
