"""Covers bridge.record.linkextract, bridge.record.tlogmatch and bridge.cli.linktools: which end is which.

``bsst link extract`` as a real subprocess on tlogs of real pymavlink frames written to disk: two tlogs given
the wrong way round are refused (each end is known by what its MAVLink sources sent); tlogs cut short at
different points (a truncated copy, a logger stopped early) still give each source to the end that sent it,
so no delay comes out negative, and what they give is a trace ``bsst link fit`` takes; a frame stamped received
a little before it was sent (the stamps' resolution) is written with delay 0 and said so; a bad argument is
named as given, not as the ``--out`` it would have made; an ``--out`` that is the command's own input is refused;
a session's per-step delays come from its run's tlogs.
"""

from __future__ import annotations

import math
import subprocess
from pathlib import Path

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from bridge.link.trace import read_trace
from bridge.record.linkblock import Cut, cut_counts
from bridge.record.linkextract import step_delays, step_records
from bridge.record.tlogmatch import DirectionRecords, merge_directions
from tests.sitlkit import ENV, ROOT, run_bsst
from tests.test_link_trace import _frame, _tlog

pytestmark = pytest.mark.process  # starts processes: not in make test-fast

DOWN_S, UP_S, PERIOD_S = 0.003, 0.005, 0.004


def bsst(*args: str | Path) -> subprocess.CompletedProcess[str]:
    return run_bsst(*map(str, args), cwd=ROOT, env=ENV, timeout=120)


def refused(p: subprocess.CompletedProcess[str]) -> str:
    """The one line of a refusal: exit 2, no traceback."""
    assert p.returncode == 2 and len(p.stderr.splitlines()) == 1 and "Traceback" not in p.stderr, (p.returncode,
                                                                                                    p.stderr)
    return p.stderr.strip()


def our_link(steps: int, early_at: int | None = None, early_s: float = 0.0, still: bool = False,
             held: tuple[int, ...] = ()) -> tuple[bytes, bytes]:
    """A vehicle's (8:1: an autopilot's HEARTBEAT, ODOMETRY down) and a controller's (200:191: its HEARTBEAT,
    SET_ACTUATOR_CONTROL_TARGET up) tlogs of a lossless link, as bsst sitl --realtime writes them: 3 ms down,
    5 ms up. ``early_at``: that step's target is stamped received ``early_s`` before it was sent. ``still``: the
    controller's sequence number stands at 0 (a script that never advances it). ``held``: those steps' targets
    are received a period and a half late, after the next step's (reordered)."""
    veh = mavlink.MAVLink(None, srcSystem=8, srcComponent=1)
    ctl = mavlink.MAVLink(None, srcSystem=200, srcComponent=191)
    vlog: list[tuple[float, bytes]] = []
    clog: list[tuple[float, bytes]] = []
    for k in range(steps):
        t = 1000.0 + k * PERIOD_S
        if k % 25 == 0:
            for m, log, other, delay, hb in ((veh, vlog, clog, DOWN_S, (2, 12)), (ctl, clog, vlog, UP_S, (18, 8))):
                f = _frame(m, m.heartbeat_encode(*hb, 0, 0, 3))
                log.append((t, f))
                other.append((t + delay, f))
        state = _frame(veh, veh.odometry_encode(k * 4000, 1, 1, 0, 0, 0, [1, 0, 0, 0], 0, 0, 0, 0, 0, 0,
                                                [math.nan] * 21, [math.nan] * 21))
        vlog.append((t + 0.0001, state))
        clog.append((t + 0.0001 + DOWN_S, state))
        ctl.seq = 0 if still else ctl.seq
        target = _frame(ctl, ctl.set_actuator_control_target_encode(k * 4000, 0, 8, 1, [0.1] * 8))
        sent = t + 0.0001 + DOWN_S + 0.0002
        clog.append((sent, target))
        vlog.append((sent - early_s if k == early_at else sent + UP_S + 1.5 * PERIOD_S * (k in held), target))
    return _tlog(vlog), _tlog(clog)


def test_two_tlogs_given_the_wrong_way_round_are_refused_and_the_right_way_extracted(tmp_path: Path) -> None:
    v, c = our_link(500)
    (tmp_path / "vehicle.tlog").write_bytes(v)
    (tmp_path / "controller.tlog").write_bytes(c)
    out = tmp_path / "t.csv"
    err = refused(bsst("link", "extract", tmp_path / "controller.tlog", tmp_path / "vehicle.tlog", "--out", out))
    assert err == (f"bsst link extract: the tlogs are given the wrong way round (both ends say so): "
                   f"{tmp_path / 'vehicle.tlog'} looks like the vehicle's end (8:1 sent an autopilot's HEARTBEAT or "
                   f"ODOMETRY) and {tmp_path / 'controller.tlog'} looks like the controller's end (200:191 sent "
                   f"actuator targets); give the vehicle's tlog first: bsst link extract {tmp_path / 'vehicle.tlog'} "
                   f"{tmp_path / 'controller.tlog'}"), err
    assert not out.exists()
    p = bsst("link", "extract", tmp_path / "vehicle.tlog", tmp_path / "controller.tlog", "--out", out)
    assert p.returncode == 0, p.stderr
    tf = read_trace(out)
    assert tf.up is not None and tf.down is not None
    assert np.allclose(tf.up.delay_s, UP_S, atol=2e-6) and np.allclose(tf.down.delay_s, DOWN_S, atol=2e-6)
    assert tf.up.lost == tf.down.lost == 0


def test_a_sender_whose_sequence_stands_still_is_refused(tmp_path: Path) -> None:
    """The losses are read from the sequence numbers: a controller whose frames all carry seq 0 read as 255 lost
    between any two delivered (484 865 sent of the 2 000 it logged, 99.6 % loss, a fit of it 99.6 %)."""
    v, c = our_link(300, still=True)
    (tmp_path / "vehicle.tlog").write_bytes(v)
    (tmp_path / "controller.tlog").write_bytes(c)
    err = refused(bsst("link", "extract", tmp_path / "vehicle.tlog", tmp_path / "controller.tlog", "--out",
                       tmp_path / "t.csv"))
    assert "source 200:191's frames do not count up" in err and "cannot be counted" in err, err
    assert not (tmp_path / "t.csv").exists()


@pytest.mark.parametrize("v_part,c_part", [(1.0, 0.4), (0.3, 1.0), (0.9, 0.55)])
def test_tlogs_cut_short_give_each_source_to_its_sender_and_a_trace_fit_takes(tmp_path: Path, v_part: float,
                                                                            c_part: float) -> None:
    """A controller's tlog cut at 40 % of its bytes held fewer of the controller's frames than the vehicle's: the
    source went to the vehicle, every up delay came out negative and bsst link fit refused the trace. Cut (mid
    frame) anywhere, the frames past either cut are left out, and said so."""
    v, c = our_link(1500)
    (tmp_path / "v.tlog").write_bytes(v[:int(len(v) * v_part) - 7])
    (tmp_path / "c.tlog").write_bytes(c[:int(len(c) * c_part) - 7])
    out = tmp_path / "t.csv"
    p = bsst("link", "extract", tmp_path / "v.tlog", tmp_path / "c.tlog", "--out", out)
    assert p.returncode == 0, p.stderr
    assert "left out: only the time both tlogs cover counts" in p.stdout
    tf = read_trace(out)
    assert tf.up is not None and tf.down is not None and tf.up.n > 100 and tf.down.n > 100
    assert np.allclose(tf.up.delay_s, UP_S, atol=2e-6) and np.allclose(tf.down.delay_s, DOWN_S, atol=2e-6)
    fit = bsst("link", "fit", out)
    assert fit.returncode == 0, fit.stderr


def test_a_frame_stamped_received_just_before_it_was_sent_is_written_with_delay_zero(tmp_path: Path) -> None:
    """Within the stamps' resolution (2 ms) on one clock, a frame received 0.4 ms "before" it left is delay 0 in the
    trace, with a note saying how many and by how much (bsst link fit and --link-trace refuse a negative delay);
    3 ms before is refused as before: the clocks differ."""
    v, c = our_link(300, early_at=100, early_s=0.0004)
    (tmp_path / "v.tlog").write_bytes(v)
    (tmp_path / "c.tlog").write_bytes(c)
    out = tmp_path / "t.csv"
    p = bsst("link", "extract", tmp_path / "v.tlog", tmp_path / "c.tlog", "--out", out)
    assert p.returncode == 0, p.stderr
    note = ("1 frame arrived before they were sent by the stamps (by up to 0.400 ms; within the stamps' resolution "
            "(2 ms)): their delays are written as 0")
    assert f"note: {note}" in p.stdout and f"# {note}" in out.read_text()
    tf = read_trace(out)
    assert tf.up is not None and min(tf.up.delay_s) == 0.0 and sorted(tf.up.delay_s)[1] == pytest.approx(UP_S)
    assert bsst("link", "fit", out).returncode == 0
    v, c = our_link(300, early_at=100, early_s=0.003)
    (tmp_path / "v.tlog").write_bytes(v)
    (tmp_path / "c.tlog").write_bytes(c)
    err = refused(bsst("link", "extract", tmp_path / "v.tlog", tmp_path / "c.tlog", "--out", tmp_path / "u.csv"))
    assert "1 frames arrived before they were sent by the stamps (by up to 0.003 s)" in err, err


def test_a_bad_run_directory_is_named_as_given_not_as_the_out_it_would_make(tmp_path: Path) -> None:
    (tmp_path / "summary.json").write_text("{}\n")
    (tmp_path / "vehicle.tlog").write_bytes(our_link(10)[0])
    give = "give a real-time run directory, or the vehicle's tlog and the controller's tlog"
    for arg, why in ((tmp_path / "nosuchdir", "no such file or directory"),
                     (tmp_path / "summary.json", "a file, not a run directory"),
                     (tmp_path / "vehicle.tlog", "one tlog (the other end's is missing)")):
        err = refused(bsst("link", "extract", arg))
        assert err == f"bsst link extract: {arg}: {why}; {give}", err
        assert "--out" not in err and not (tmp_path / "link-trace.csv").exists()


def test_a_fleets_run_directory_names_its_vehicles_directories_to_extract_from(tmp_path: Path) -> None:
    """A real-time fleet's run directory holds each vehicle's link in its ``vehicle-<id>/`` (docs/swarm.md): the
    command names them, and the one it names extracts (it said only "neither vehicle.tlog and controller.tlog nor
    vehicle.bin and controller.bin: no record of a link to extract", a tour's ``bsst link extract`` of
    ``bsst sitl --vehicles 2 --shared-link --realtime``'s directory)."""
    (tmp_path / "summary.json").write_text('{"clock": "realtime"}\n')
    for i in (2, 10, 1):
        (tmp_path / f"vehicle-{i}").mkdir()
        for side, log in zip(("vehicle", "controller"), our_link(100), strict=True):
            (tmp_path / f"vehicle-{i}" / f"{side}.tlog").write_bytes(log)
    err = refused(bsst("link", "extract", tmp_path))
    assert err == (f"bsst: {tmp_path}: a fleet's run directory: each vehicle's link is in its own (vehicle-1, "
                   f"vehicle-2, vehicle-10); extract each, as bsst link extract {tmp_path / 'vehicle-1'}"), err
    assert bsst("link", "extract", tmp_path / "vehicle-1").returncode == 0
    assert (tmp_path / "vehicle-1" / "link-trace.csv").is_file() and not (tmp_path / "link-trace.csv").exists()


def test_an_out_that_is_the_commands_own_input_is_refused_even_with_overwrite(tmp_path: Path) -> None:
    """``--overwrite`` lets extract, fit and show replace an old output, never the file they read."""
    v, c = our_link(300)
    (tmp_path / "vehicle.tlog").write_bytes(v)
    (tmp_path / "controller.tlog").write_bytes(c)
    (tmp_path / "summary.json").write_text('{"clock": "realtime"}\n')
    for args, out in ((("link", "extract", tmp_path), tmp_path / "vehicle.tlog"),
                      (("link", "extract", tmp_path / "vehicle.tlog", tmp_path / "controller.tlog"),
                       tmp_path / "controller.tlog")):
        err = refused(bsst(*args, "--out", out, "--overwrite"))
        assert err == (f"bsst: --out {out}: is {out}, an input of this command, which writing would destroy; write the "
                       "output elsewhere"), err
    assert (tmp_path / "vehicle.tlog").read_bytes() == v and (tmp_path / "controller.tlog").read_bytes() == c
    assert bsst("link", "extract", tmp_path).returncode == 0  # RUN/link-trace.csv
    trace = tmp_path / "link-trace.csv"
    text = trace.read_text()
    (tmp_path / "t.png").symlink_to(trace)  # the figure's name, the trace's file
    for verb, out in (("fit", trace), ("show", tmp_path / "t.png")):
        err = refused(bsst("link", verb, trace, "--out", out, "--overwrite"))
        assert err == f"bsst: --out {out}: is {trace}, an input of this command, which writing would destroy; write " \
                      "the output elsewhere", err
    assert trace.read_text() == text


def test_a_sessions_step_delays_are_its_per_step_messages_from_its_tlogs(tmp_path: Path) -> None:
    """What a real-time session through a relay reports as ``delay_ms`` (:func:`step_delays`): one delay per target
    up and per ODOMETRY down delivered (the HEARTBEATs beside them left out); no tlogs, no figures (None)."""
    assert step_delays(tmp_path) is None
    v, c = our_link(100)
    (tmp_path / "vehicle.tlog").write_bytes(v)
    assert step_delays(tmp_path) is None
    (tmp_path / "controller.tlog").write_bytes(c)
    got = step_delays(tmp_path)
    assert got is not None and len(got[0]) == len(got[1]) == 100
    assert np.allclose(got[0], UP_S * 1e3, atol=2e-3) and np.allclose(got[1], DOWN_S * 1e3, atol=2e-3)


def test_a_killed_sides_link_counts_its_reordered_messages_from_the_tlogs_order(tmp_path: Path) -> None:
    """A session whose side was killed counts its link from both tlogs (:func:`step_records`, ``cut_counts``):
    ``reordered`` is each per-step message received after one sent later, in the order the receiver's tlog holds
    them (the link model's count): two targets held past their successors are 2 up, 0 down, and the ``counted``
    note says what it counted. Until the third wave's forty-third session it was null, said nowhere."""
    v, c = our_link(100, held=(10, 40))
    (tmp_path / "vehicle.tlog").write_bytes(v)
    (tmp_path / "controller.tlog").write_bytes(c)
    both = step_records(tmp_path)
    assert both is not None and (both[0].reordered, both[1].reordered) == (2, 0)
    assert both[0].sent == both[1].sent == 100 and both[0].lost == 0
    cut = Cut("vehicle", "killed by SIGKILL", both)
    up, down = cut_counts("up", cut), cut_counts("down", cut)
    assert (up["reordered"], up["duplicated"], down["reordered"]) == (2, 0, 0), (up, down)
    assert "reordered: received after one sent later, in the order the receiver's tlog read them" in up["counted"]
    assert "link model" not in up["counted"]  # real time: nothing acted after the sockets
    # in lockstep the vehicle's link model acted on the up link after its socket: these are the sockets' counts
    said = cut_counts("up", Cut("vehicle", "killed by SIGKILL", both, modelled=True))["counted"]
    assert said.endswith("counted at the sockets: the link model the vehicle applied after its socket (lockstep) "
                         "went with its stats, so what that model lost, duplicated or held back is not in these "
                         "counts"), said
    assert "link model" not in cut_counts("down", Cut("vehicle", "killed by SIGKILL", both, modelled=True))["counted"]


def test_reordered_over_sources_is_their_sum_or_unknown_if_one_is() -> None:
    """Merged over a direction's sources, ``reordered`` is the sum of each source's count; one source not counted
    (None) makes it unknown, not the others' sum passed off as the whole (a review's finding)."""
    counted = [DirectionRecords(reordered=2), DirectionRecords(reordered=3)]
    assert merge_directions(counted).reordered == 5
    assert merge_directions([*counted, DirectionRecords(reordered=None)]).reordered is None
    assert merge_directions([]).reordered is None
