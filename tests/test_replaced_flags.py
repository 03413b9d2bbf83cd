"""Covers bridge.core.overrides and bridge.cli: a flag a mission's t = 0 event replaces is refused.

``--wind`` (a steady wind) and the link flags (``--delay``, ``--up-loss``, ``--link-trace``, ``--link-profile`` ...)
laid over a mission whose timeline sets the same thing at the flight's first control step (an ``[[events]]`` table
of kind ``wind`` or ``link`` at ``t_s = 0``, or an ``--at 0:...`` flag) flew the event's and said nothing (until the
forty-fifth session: ``bsst sim m.toml --wind 10`` printed ``air: wind 10 m/s`` and flew 3 from 90 degrees). Now
exit 2, one line naming the flag and the event (file and table); an event later than that leaves the flag flown
until it (docs/weather.md), and the controller's guard flags, which a handover keeps, are not refused.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from bridge.cli import main
from bridge.cli.linkflags import LINK_FLAGS
from bridge.core.flight import prepare
from bridge.core.overrides import LINK_KEY_STEMS
from params import ConfigError

ROOT = Path(__file__).resolve().parents[1]
HEAD = ('name = "replaced"\nduration_s = 2.0\nrate_hz = 250\n[trajectory]\nkind = "step"\n'
        'setpoints = [ { t = 0.0, x = 0.5, y = 0.0, z = 1.0, psi = 0.0 } ]\n')


def _mission(tmp_path: Path, t_s: float) -> Path:
    p = tmp_path / "m.toml"
    p.write_text(HEAD + f'[[events]]\nt_s = {t_s}\nkind = "wind"\nspeed_mps = 1.0\nfrom_deg = 90.0\n'
                        f'[[events]]\nt_s = {t_s}\nkind = "link"\ndelay_ms = 5\n')
    return p


def _refused(capsys: Any, tmp_path: Path, *argv: str) -> str:
    out = tmp_path / "run"
    rc = main(["sim", *argv, "--no-plots", "--out", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2, (rc, err)
    assert len(err) == 1 and err[0].startswith("bsst: "), err
    assert not out.exists()  # refused before anything flew
    return err[0]


@pytest.mark.parametrize(("flags", "named", "kind"), [
    (("--wind", "10"), "--wind 10:0: changes nothing", "wind"),
    (("--wind", "4:270"), "--wind 4:270: changes nothing", "wind"),
    (("--delay", "40"), "--delay 40: changes nothing", "link"),
    (("--up-loss", "5", "--down-delay", "30"), "--down-delay 30, --up-loss 5: change nothing", "link"),
    # as typed: until the forty-fifth session's review as the table holds them, "--up-delay 10, --down-delay 40" (a
    # flag never typed) and "--up-blackout 0.5:0.2, --down-blackout 1:0.1"
    (("--delay", "40", "--up-delay", "10"), "--delay 40, --up-delay 10: change nothing", "link"),
    (("--down-blackout", "1:0.1", "--blackout", "0.5:0.2"), "--blackout 0.5:0.2, --down-blackout 1:0.1: change",
     "link"),
    (("--link-profile", "wifi"), "--link-profile wifi: changes nothing", "link"),
    (("--blackout", "0.5:0.2"), "--blackout 0.5:0.2: changes nothing", "link"),
    (("--link-trace", str(ROOT / "examples" / "link-trace.csv")), "--link-trace ", "link"),
])
def test_a_flag_a_t0_event_replaces_is_refused_naming_both(capsys: Any, tmp_path: Path, flags: tuple[str, ...],
                                                           named: str, kind: str) -> None:
    m = _mission(tmp_path, 0.0)
    line = _refused(capsys, tmp_path, str(m), *flags)
    assert named in line, line
    assert f"{m}: events (t_s = 0, kind = {kind})" in line, line
    assert "first control step" in line, line


def test_an_at_flag_at_t0_is_named_as_the_event(capsys: Any, tmp_path: Path) -> None:
    m = tmp_path / "plain.toml"
    m.write_text(HEAD)
    line = _refused(capsys, tmp_path, str(m), "--delay", "3", "--at", "0:link:wifi")
    assert line.startswith("bsst: --delay 3: changes nothing: --at 0:link:wifi hands the link over"), line
    line = _refused(capsys, tmp_path, str(m), "--wind", "3", "--at", "0:wind:4")
    assert line.startswith("bsst: --wind 3:0: changes nothing: --at 0:wind:4 sets the steady wind"), line


def test_a_python_callers_wind_and_link_are_refused_too(tmp_path: Path) -> None:
    m = _mission(tmp_path, 0.0)
    with pytest.raises(ConfigError, match=r"--wind 10: changes nothing: .*kind = wind"):
        prepare(m, wind={"speed_mps": 10.0})
    with pytest.raises(ConfigError, match=r"--delay 40: changes nothing: .*kind = link"):
        prepare(m, link={"delay_ms": 40.0})
    prepare(m, wind={"turbulence": "light"}, link={"stop_ms": 400.0})  # kept by both events: flown


def test_a_later_event_leaves_the_flags_flown_until_it(capsys: Any, tmp_path: Path) -> None:
    """At t = 1 s of 2: the flags' 40 ms and 5 m/s fly the first second, the event's 5 ms and 1 m/s the second."""
    out = tmp_path / "run"
    rc = main(["sim", str(_mission(tmp_path, 1.0)), "--wind", "5", "--delay", "40", "--compensation", "predict",
               "--no-plots", "--out", str(out)])
    assert rc == 0, capsys.readouterr()
    s = json.loads((out / "summary.json").read_text())
    delays = s["link"]["up"]["delay_ms"]
    assert delays["p50"] == pytest.approx(5.0) or delays["p50"] == pytest.approx(40.0), delays
    assert delays["max"] == pytest.approx(40.0), delays
    assert 1.5 < s["wind"]["mean_speed_mps"] < 4.5, s["wind"]  # both winds flown, each about half the flight


def test_a_wind_flown_with_turbulence_is_its_pass_speed_and_kept(capsys: Any, tmp_path: Path) -> None:
    """With turbulence the steady wind's speed and direction also set the turbulence's pass speed and axes, which a
    wind event (the steady wind alone) leaves as they are: --wind acts, and is taken."""
    out = tmp_path / "run"
    assert main(["sim", str(_mission(tmp_path, 0.0)), "--wind", "10", "--turbulence", "moderate", "--no-plots",
                 "--out", str(out)]) == 0, capsys.readouterr()
    wind = json.loads((out / "summary.json").read_text())["wind"]
    assert wind["dryden"]["pass_speed_mps"] == 10.0 and wind["mean_speed_mps"] == pytest.approx(1.0), wind


def test_a_guard_flag_is_kept_by_a_t0_handover(capsys: Any, tmp_path: Path) -> None:
    out = tmp_path / "run"
    assert main(["sim", str(_mission(tmp_path, 0.0)), "--compensation", "predict", "--no-plots", "--out",
                 str(out)]) == 0, capsys.readouterr()


def test_the_key_stems_are_the_link_flags() -> None:
    assert {k: s for k, s in LINK_KEY_STEMS.items() if k in {key for _, key, *_ in LINK_FLAGS}} == \
        {key: stem for stem, key, *_ in LINK_FLAGS}
    assert {k: s for k, s in LINK_KEY_STEMS.items() if k not in {key for _, key, *_ in LINK_FLAGS}} == \
        {"blackouts": "blackout", "trace": "link-trace", "trace_loop": "link-trace-loop", "jitter": "jitter-dist",
         "seed": "link-seed"}
