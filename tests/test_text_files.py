"""Covers params: every text file a user gives is decoded one way, a UTF-8 byte-order mark accepted.

A link profile saved by a Windows editor (which starts a UTF-8 file with the bytes EF BB BF) was refused as
``not valid TOML (Invalid statement (at line 1, column 1))``, and so were missions, vehicle profiles, sweep files
and fleet missions, and a ``.plan`` as ``not valid JSON: Unexpected UTF-8 BOM``; link traces already took one.
``params.utf8_text`` is the one decoder now (``params.toml_from_bytes``, ``params.read_text_file``,
``bridge.link.trace``), and ``params`` the one module that reads TOML.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from bridge.link.profile import load_link_profile
from bridge.link.trace import read_trace
from bridge.sweep.spec import load_sweep
from missions import load_mission
from params import ConfigError, load_toml, utf8_text
from plant.profiles import load_profile

ROOT = Path(__file__).resolve().parents[1]
BOM = b"\xef\xbb\xbf"


def _with_bom(src: Path, dst: Path) -> Path:
    dst.write_bytes(BOM + src.read_bytes())
    return dst


def test_utf8_text_drops_one_leading_mark_only() -> None:
    assert utf8_text(BOM + b"a = 1\n") == "a = 1\n"
    assert utf8_text(b"a = 1\n") == "a = 1\n"
    assert utf8_text(BOM + BOM + b"x") == "\ufeffx"  # a second mark is text, and TOML refuses it
    with pytest.raises(UnicodeDecodeError):
        utf8_text(b"\xff")


@pytest.mark.parametrize("src, load", [
    ("bridge/link/profiles/wifi.toml", lambda p: load_link_profile(str(p)).name),
    ("plant/profiles/x500.toml", lambda p: load_profile(p).name),
    ("missions/sine.toml", lambda p: load_mission(p).name),
    ("examples/swarm-touch.toml", lambda p: len(load_mission(p).vehicles)),
    ("examples/box.plan", lambda p: load_mission(p).duration_s),
    ("examples/box.waypoints", lambda p: load_mission(p).duration_s),
    ("examples/link-trace.csv", lambda p: list(read_trace(p).records("up").t_s)),
], ids=lambda v: v if isinstance(v, str) else "")
def test_a_file_with_a_byte_order_mark_reads_as_the_file_without(tmp_path: Path, src: str, load) -> None:
    original = ROOT / src
    marked = _with_bom(original, tmp_path / original.name)
    assert load(marked) == load(original)


def test_a_sweep_file_with_a_byte_order_mark(tmp_path: Path) -> None:
    _with_bom(ROOT / "missions" / "step.toml", tmp_path / "m.toml")
    (tmp_path / "s.toml").write_bytes(BOM + b'mission = "m.toml"\n[grid]\ndelay_ms = [0, 10]\n')
    assert load_sweep(tmp_path / "s.toml").mission.name == "step"


def test_a_mark_inside_the_file_is_still_not_toml(tmp_path: Path) -> None:
    p = tmp_path / "m.toml"
    p.write_bytes(b'name = "m"\n' + BOM + b"duration_s = 1.0\n")
    with pytest.raises(ConfigError, match=r"m\.toml: not valid TOML \(.*line 2"):
        load_toml(p)


def test_only_params_reads_toml() -> None:
    """One way to read a TOML file: ``params.load_toml`` / ``toml_from_bytes``; no product module imports
    ``tomllib`` (or ``tomli``) but ``params`` (``bridge.cli.commands`` reads the project's own pyproject.toml for
    its version, not a user's file)."""
    readers = set()
    for pkg in ("bridge", "plant", "controller", "missions", "params"):
        for f in (ROOT / pkg).rglob("*.py"):
            for node in ast.walk(ast.parse(f.read_text(encoding="utf-8"))):
                names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                         else [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
                if any(n.split(".")[0] in ("tomllib", "tomli") for n in names):
                    readers.add(f.relative_to(ROOT).as_posix())
    assert readers == {"params/__init__.py", "bridge/cli/commands.py"}
