"""Covers bridge.cli: a path the system cannot look up (a name longer than the filesystem takes, a folder this
process may not search) is bad input named in one line (exit 2), as a missing file is, not a traceback.

A new user's run found ``bsst sim noexec/m.toml`` (``noexec`` a folder of mode 0700, another user's) dying with
``PermissionError`` in ``Path.exists()`` before the mission was read: pathlib's ``exists``, ``is_file`` and
``is_dir`` answer False only for a missing entry, and raise for EACCES or ENAMETOOLONG. Root searches every
folder, so the name too long (ENAMETOOLONG, for every user) is the case that runs everywhere.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from bridge.cli import main

SINE = "missions/sine.toml"
LONG = "a" * 300  # one path component: Linux's filesystems take 255 bytes


def _cases(bad: str) -> list[tuple[list[str], str]]:
    """(argv, what the line must name) for each command's reading or writing of ``bad``."""
    return [
        (["sim", f"{bad}.toml"], f"{bad}.toml: cannot read"),
        (["sim", SINE, "--link-trace", f"{bad}.csv"], f"--link-trace {bad}.csv: cannot read"),
        (["sim", SINE, "--link-profile", f"{bad}.toml"], f"--link-profile {bad}.toml: cannot read"),
        (["report", bad], f"{bad}: cannot read"),
        (["link", "extract", bad], f"{bad}: cannot read"),
        (["link", "show", "examples/link-trace.csv", "--out", f"{bad}.png"], f"--out {bad}.png: cannot reach it"),
    ]


def _refused(capsys: pytest.CaptureFixture[str], argv: list[str], names: str) -> None:
    rc = main(argv)
    _, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert rc == 2, f"bsst {' '.join(argv)}: exit {rc}, {err!r}"
    assert len(lines) == 1 and names in lines[0], err


@pytest.mark.parametrize("argv, names", _cases(LONG), ids=lambda v: v[0] if isinstance(v, list) else "")
def test_a_name_too_long(argv, names, capsys, monkeypatch):
    monkeypatch.chdir(Path(__file__).resolve().parents[1])  # the project's root: SINE and the example trace
    _refused(capsys, argv, names)


@pytest.mark.skipif(os.geteuid() == 0, reason="root searches a folder of mode 0700")
def test_a_folder_that_may_not_be_searched(capsys, monkeypatch, tmp_path):
    root = Path(__file__).resolve().parents[1]
    closed = tmp_path / "closed"
    closed.mkdir()
    closed.chmod(0)
    monkeypatch.chdir(tmp_path)
    try:
        for argv, names in _cases("closed/x"):
            argv = [str(root / a) if a in (SINE, "examples/link-trace.csv") else a for a in argv]
            _refused(capsys, argv, names)
    finally:
        closed.chmod(0o755)
