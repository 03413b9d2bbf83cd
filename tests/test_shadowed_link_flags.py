"""Covers bridge.cli.linkflags: a link flag for both directions given with both of its direction's own is refused.

``--delay 40 --up-delay 10 --down-delay 30`` flew 10 ms up and 30 ms down, and took ``--delay 40`` silently (until the
forty-fifth session): a direction's own flag wins over the flag for both, so with both directions' own given it sets
nothing. Now exit 2, one line naming it as typed and the two flags that override it (a typed
:class:`~params.ConfigError`: its ``source`` the flag), before anything flies; with one direction's own given it
still sets the other direction, and flies.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from bridge.cli import build_parser, link_table_from_args, main
from params import ConfigError
from tests.sitlkit import run_bsst

pytestmark = pytest.mark.process

ROOT = Path(__file__).resolve().parents[1]
TRACE = str(ROOT / "examples" / "link-trace.csv")
MISSION = ('name = "shadowed"\nduration_s = 2.0\nrate_hz = 250\n[trajectory]\nkind = "step"\n'
           'setpoints = [ { t = 0.0, x = 0.5, y = 0.0, z = 1.0, psi = 0.0 } ]\n')


def _mission(tmp_path: Path) -> Path:
    p = tmp_path / "m.toml"
    p.write_text(MISSION)
    return p


@pytest.mark.parametrize(("flags", "line"), [
    (("--delay", "40", "--up-delay", "10", "--down-delay", "30"),
     "--delay 40: sets nothing: --up-delay 10 and --down-delay 30 set the two directions, and a direction's own flag "
     "wins over --delay; drop --delay, or one of them"),
    (("--down-loss", "2", "--loss", "5", "--up-loss", "1"),
     "--loss 5: sets nothing: --up-loss 1 and --down-loss 2 set the two directions, and a direction's own flag wins "
     "over --loss; drop --loss, or one of them"),
    (("--blackout", "0.5:0.2", "--up-blackout", "1:0.1", "--blackout", "0.8:0.1", "--down-blackout", "1.5:0.1"),
     "--blackout 0.5:0.2 --blackout 0.8:0.1: sets nothing: --up-blackout 1:0.1 and --down-blackout 1.5:0.1 set the "
     "two directions, and a direction's own flag wins over --blackout; drop --blackout, or one of them"),
    (("--link-trace", TRACE, "--up-link-trace", "none", "--down-link-trace", "none"),
     f"--link-trace {TRACE}: sets nothing: --up-link-trace none and --down-link-trace none set the two directions, "
     "and a direction's own flag wins over --link-trace; drop --link-trace, or one of them"),
])
def test_a_flag_both_directions_own_override_is_refused_naming_them(capsys: Any, tmp_path: Path,
                                                                     flags: tuple[str, ...], line: str) -> None:
    out = tmp_path / "run"
    assert main(["sim", str(_mission(tmp_path)), *flags, "--no-plots", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err == f"bsst: {line}\n", err
    assert not out.exists()  # refused before anything flew


def test_the_refusal_is_typed_as_the_flags(tmp_path: Path) -> None:
    args = build_parser().parse_args(["sim", str(_mission(tmp_path)), "--jitter", "3", "--up-jitter", "1",
                                      "--down-jitter", "2"])
    with pytest.raises(ConfigError) as refused:
        link_table_from_args(args)
    assert refused.value.source == "--jitter 3" and refused.value.key is None, refused.value
    assert refused.value.what.startswith("sets nothing: --up-jitter 1 and --down-jitter 2 set the two directions")


def test_one_directions_own_leaves_the_flag_the_other_direction(capsys: Any, tmp_path: Path) -> None:
    """``--delay 40 --up-delay 10``: 10 ms up, 40 down, flown (no refusal)."""
    out = tmp_path / "run"
    assert main(["sim", str(_mission(tmp_path)), "--delay", "40", "--up-delay", "10", "--no-plots", "--out",
                 str(out)]) == 0, capsys.readouterr()
    link = json.loads((out / "summary.json").read_text())["link"]
    assert link["up"]["delay_ms"]["p50"] == pytest.approx(10.0), link["up"]
    assert link["down"]["delay_ms"]["p50"] == pytest.approx(40.0), link["down"]


def test_a_sweeps_fixed_flag_and_a_relays_are_refused_alike(tmp_path: Path) -> None:
    """Real ``bsst`` processes: ``bsst sweep`` (its fixed link flags) and ``bsst relay`` (whose stdout is reports)
    exit 2 with the line on stderr, nothing flown or relayed."""
    m = _mission(tmp_path)
    sweep = run_bsst("sweep", m, "--rate", "200,250", "--dup", "5", "--up-dup", "1", "--down-dup", "2", "--no-plots",
                     "--out", tmp_path / "sweep")
    assert sweep.returncode == 2, sweep
    assert sweep.stderr.strip().splitlines() == [
        "bsst: --dup 5: sets nothing: --up-dup 1 and --down-dup 2 set the two directions, and a direction's own flag "
        "wins over --dup; drop --dup, or one of them"], sweep.stderr
    assert not (tmp_path / "sweep").exists()
    relay = run_bsst("relay", "--listen", "127.0.0.1:0", "--to", "127.0.0.1:9", "--duration", "1", "--queue", "50",
                     "--up-queue", "20", "--down-queue", "30", "--bandwidth", "1000")
    assert relay.returncode == 2, relay
    assert relay.stderr.strip().splitlines()[-1].startswith("bsst: --queue 50: sets nothing: --up-queue 20 and "
                                                            "--down-queue 30 set the two directions"), relay.stderr
