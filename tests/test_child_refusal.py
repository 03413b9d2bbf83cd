"""Covers bridge.session.session, bridge.nodes.report, bridge.nodes.watched and bridge.cli: a refusal that crosses a
process boundary travels typed, never as text to be cut.

- A session's child (``bsst vehicle``, ``controller``, ``relay``) refused at its start writes its refusal as a
  ``bad_input`` report on stdout (its text and its ConfigError's ``source``, ``key``, ``what``) beside its line on
  stderr, which stays the person's; the session raises it again from those fields. Until the third wave's
  forty-fourth session the session cut ``bsst: `` off the child's last stderr line: a law of the user's own that says
  goodbye on stderr at its exit was said as the refusal (``bsst: mylaw: unloaded``), and a Python caller got a
  ConfigError with none of its typed fields.
- Each kind of refusal a child can say (a ConfigError; a usage error of its command, ``bsst relay: ...``; one of
  ``bsst`` alone, ``bsst: --radio-user ...``; argparse's) said again from its report is the child's line, to the
  byte.
- ``bsst sim``'s watched child (a law of the user's own flies in it) sends its refusal back typed too: a usage error's
  was said after a second ``bsst: ``.

Real processes (``python -m bridge``), a UDP port held by the test.
"""

from __future__ import annotations

import contextlib
import socket
from collections.abc import Iterator
from pathlib import Path

import pytest

from bridge.cli.flags import refusal_line
from bridge.link.radio import make_radio_file
from bridge.nodes.report import BadInput, parse_line
from bridge.session import instance_slot, sitl
from params import ConfigError
from tests.sitlkit import ENV, ROOT, run_bsst

pytestmark = pytest.mark.process  # starts processes or opens sockets: not in make test-fast

GOODBYE_LAW = '''
import atexit
import sys

atexit.register(lambda: print("mylaw: unloaded", file=sys.stderr))  # a law's own last word, at its process's exit


class Law:
    def __init__(self, nominal, gains, rate_hz):
        self.m, self.g = nominal.mass, nominal.gravity
        self.desired = (0.0, 0.0)

    def update(self, t, state, ref, omega_d):
        return (self.m * self.g, 0.0, 0.0, 0.0)

    def advance(self, saturated, hold=False):
        pass

    def reset(self):
        pass
'''


@contextlib.contextmanager
def _taken_port() -> Iterator[int]:
    """A UDP port of 127.0.0.1 this test holds bound while the block runs."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        yield s.getsockname()[1]


def test_a_childs_refusal_is_said_from_its_report_not_from_its_last_stderr_line(tmp_path: Path) -> None:
    """``bsst sitl --gcs udpin:127.0.0.1:P`` with P taken: the vehicle child refuses at its start (it binds P), and a
    law of the user's own (loaded by the vehicle too, as it checks the mission) then says ``mylaw: unloaded`` on
    the child's stderr at its exit. The session says the vehicle's refusal, exit 2; the old one said the law's line:
    ``bsst: mylaw: unloaded``. The child's own line in vehicle.log is unchanged."""
    law = tmp_path / "goodbye_law.py"
    law.write_text(GOODBYE_LAW)
    out = tmp_path / "run"
    with _taken_port() as port, instance_slot() as n:
        r = run_bsst("sitl", "missions/sine.toml", "--controller", f"{law}:Law", "--instance", str(n), "--gcs",
                     f"udpin:127.0.0.1:{port}", "--out", str(out), "--no-plots", cwd=ROOT, env=ENV, timeout=120)
    refusal = f"bsst: --gcs udpin:127.0.0.1:{port}: cannot bind (Address already in use)"
    assert r.returncode == 2 and r.stderr.splitlines()[0] == refusal, r.stderr
    assert "Traceback" not in r.stderr, r.stderr
    assert (out / "vehicle.log").read_text().splitlines() == [refusal, "mylaw: unloaded"]  # the person's, as it was


def test_a_childs_refusal_keeps_its_typed_fields_through_the_session(tmp_path: Path) -> None:
    """``sitl(..., gcs="udpin:127.0.0.1:P")`` from Python, P taken: the ConfigError the caller gets is the vehicle
    child's, its ``source``, ``key`` and ``what`` too (the old session's had the text only, no source)."""
    with _taken_port() as port, instance_slot() as n:
        with pytest.raises(ConfigError) as refused:
            sitl(ROOT / "missions" / "sine.toml", out=tmp_path / "run", instance=n, gcs=f"udpin:127.0.0.1:{port}",
                 plots=False)
    e = refused.value
    assert str(e) == f"--gcs udpin:127.0.0.1:{port}: cannot bind (Address already in use)"
    assert (e.source, e.key, e.what) == (f"--gcs udpin:127.0.0.1:{port}", None, "cannot bind (Address already in use)")


RELAY_REFUSALS = {  # case: (bsst relay's arguments after --listen, with {p} the port taken; its line's start)
    "config_error": (["127.0.0.1:{p}", "--to", "127.0.0.1:9"], "bsst: --listen 127.0.0.1:{p}: cannot bind"),
    "a_flag": (["127.0.0.1:0", "--to", "127.0.0.1:0"], "bsst: --to '127.0.0.1:0': port must be in"),
    "bsst_alone": (["127.0.0.1:0", "--to", "127.0.0.1:9", "--radio-user", "1"], "bsst: --radio-user without --radio"),
    "argparse": (["127.0.0.1:0", "--to", "127.0.0.1:9", "--bogus"], "bsst relay: unrecognized arguments: --bogus"),
}


@pytest.mark.parametrize("case", RELAY_REFUSALS)
def test_a_childs_bad_input_report_says_its_line_again_to_the_byte(case: str) -> None:
    """``bsst relay`` refused (a session's child, as it starts it): exit 2, its one line on stderr, and one
    ``bad_input`` report on stdout whose refusal, said as ``bsst`` says one, is that line (the old relay wrote no
    report: the session had only the line's text)."""
    args, opens = RELAY_REFUSALS[case]
    with _taken_port() as port:
        r = run_bsst("relay", "--listen", *(a.format(p=port) for a in args), "--duration", "0.1", cwd=ROOT, env=ENV,
                     timeout=60)
    line = r.stderr.strip()
    assert r.returncode == 2 and "\n" not in line and line.startswith(opens.format(p=port)), r.stderr
    refusals = [x for x in map(parse_line, r.stdout.splitlines()) if isinstance(x, BadInput)]
    assert len(refusals) == 1, r.stdout
    assert refusal_line(refusals[0].error()) == line


def test_a_watched_sims_usage_error_comes_back_typed_said_once(tmp_path: Path) -> None:
    """``bsst sim --controller mylaw.py:Law --link-trace F --delay 5``: the flight (and the flags' check) runs in a
    watched child, whose refusal came back to the command's process as text, said after a second ``bsst: ``."""
    law = tmp_path / "goodbye_law.py"
    law.write_text(GOODBYE_LAW)
    trace = tmp_path / "trace.csv"
    trace.write_text("t_s,delay_ms,lost\n0,10,0\n100,10,0\n")
    r = run_bsst("sim", "missions/sine.toml", "--controller", f"{law}:Law", "--link-trace", str(trace), "--delay", "5",
                 "--out", str(tmp_path / "run"), "--no-plots", cwd=ROOT, env=ENV, timeout=120)
    assert r.returncode == 2, r.stderr
    assert r.stderr.splitlines()[0] == ("bsst: --link-trace / --up-link-trace cannot be combined with delay_ms = 5 "
                                        "(--delay, --jitter, --loss, --burst) in the up direction: the trace gives "
                                        "the delays and the losses"), r.stderr


def _typed_child_refusals(tmp: Path, port: int) -> list[tuple[list[str], str, str]]:
    """(a session's child's arguments, the ``source`` and ``what`` of its refusal): a flag's, typed."""
    radio = tmp / "radio"
    make_radio_file(radio, 2)
    relay = ["relay", "--listen", f"127.0.0.1:{port}", "--duration", "0.1"]
    return [([*relay, "--to", "127.0.0.1:0"], "--to '127.0.0.1:0'", "port must be in [1, 65535]"),
            ([*relay, "--to", "nowhere"], "--to 'nowhere'", "expected [udpin:|udpout:]HOST:PORT"),
            ([*relay, "--to", "127.0.0.1:9", "--client", "udpin:127.0.0.1:5"], "--client 'udpin:127.0.0.1:5'",
             "the relay sends to it (udpout), not udpin"),
            ([*relay, "--to", f"127.0.0.1:{port}"], f"--to 127.0.0.1:{port}",
             f"is the relay's own --listen 127.0.0.1:{port}: it would forward into itself"),
            (["controller", "missions/sine.toml", "--vehicle", "127.0.0.1:9", "--timeout", "1", "--radio", str(radio),
              "--realtime"], "--radio", "with --realtime: a fleet's one radio in real time is its relays' (bsst relay "
                                        "--radio); the controller's is lockstep's"),
            (["vehicle", "--gate", str(tmp / "gate"), "--realtime"], "--gate",
             "with --realtime: a fleet's shared step clock is lockstep's (real time keeps the wall clock)")]


def test_a_childs_flag_refusal_reports_the_flag_as_its_source(tmp_path: Path) -> None:
    """A session's child refused for a flag (``bsst relay --to``/``--client``, its ``--to`` its own ``--listen``;
    ``bsst controller --radio F --realtime``; ``bsst vehicle --gate --realtime``): exit 2, one line ``bsst: `` and
    the refusal, and its ``bad_input`` report typed as every flag's refusal: ``source`` the flag (and the value, as
    given), ``what`` the bare reason. Until the forty-fifth session the relay turned its address's typed ConfigError
    into a plain ValueError, said as ``bsst relay: --to ...``, its report's source ``bsst relay`` and its ``what``
    the whole message; ``--radio with --realtime`` and ``--gate with --realtime`` had no source, no ``what``."""
    with _taken_port() as port:  # (refused before the relay binds it)
        for args, source, what in _typed_child_refusals(tmp_path, port):
            r = run_bsst(*args, cwd=ROOT, env=ENV, timeout=60)
            line = f"bsst: {source}{' ' if what.startswith(('with ', 'is ')) else ': '}{what}"
            assert r.returncode == 2 and r.stderr == line + "\n", (args, r.stderr)
            [refused] = [x for x in map(parse_line, r.stdout.splitlines()) if isinstance(x, BadInput)]
            assert (refused.source, refused.key, refused.what) == (source, None, what), (args, refused)
            assert refusal_line(refused.error()) == line


def test_the_link_tools_out_refusals_are_typed(tmp_path: Path, capsys) -> None:
    """``bsst link show --out`` not a PNG, ``bsst link fit --out`` a file that exists or the trace it reads: exit 2,
    one line, and the ConfigError typed as every flag's refusal (``source`` ``--out PATH``, ``what`` the reason).
    Until the forty-fifth session they had no source (the PNG one said as ``bsst link show: --out ...``)."""
    from bridge.cli import _parser, main

    trace, taken, txt = tmp_path / "t.csv", tmp_path / "p.toml", tmp_path / "f.txt"
    trace.write_text("t_s,delay_ms\n0,10\n1,10\n")
    taken.write_text("mine\n")
    read = f"is {trace}, an input of this command, which writing would destroy; write the output elsewhere"
    for argv, source, what in ((["link", "show", trace, "--out", txt], f"--out {txt}",
                                "the figure is a PNG (name it *.png)"),
                               (["link", "fit", trace, "--out", taken], f"--out {taken}",
                                "exists; --overwrite to replace it"),
                               (["link", "fit", trace, "--out", trace, "--overwrite"], f"--out {trace}", read)):
        argv = [str(a) for a in argv]
        assert main(argv) == 2, argv
        assert capsys.readouterr().err == f"bsst: {source}: {what}\n", argv
        args = _parser().parse_args(argv)
        with pytest.raises(ConfigError) as refused:
            args.func(args)
        assert (refused.value.source, refused.value.key, refused.value.what) == (source, None, what), argv
    assert taken.read_text() == "mine\n" and not txt.exists()
