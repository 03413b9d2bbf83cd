"""Covers bridge.record.runlog: an ``--out`` directory this process cannot write into, or cannot create, is bad
input named before any work (exit 2, one line), not a traceback after it.

A new user's run (the read-only cases of the bad-input walk): ``bsst sim --out DIR`` into an existing read-only
directory died with ``PermissionError`` writing ``mission.toml`` (exit 1, a traceback); ``bsst vehicle`` and
``bsst controller`` likewise opening their tlog; ``bsst margin --out RO/new`` flew its whole search and then
could not create its directory, losing every cell. ``/proc/self`` is a directory no process, root included, may
write into, so these cases run as any user; a directory of mode 0555 is the everyday case (not for root, who
writes into it).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import pytest

from bridge.record.runlog import run_dir, side_dir
from params import ConfigError
from tests.sitlkit import run_bsst

pytestmark = pytest.mark.process  # a command not refused would fly (sweep workers) or serve (a vehicle's sockets)

TINY = 'name = "tiny"\nduration_s = 0.2\n[trajectory]\nkind = "sine"\n'
READ_ONLY = Path("/proc/self")  # exists, is a directory, and refuses every new entry (os.access: not writable)
GUARD_S = 60  # s: a command that is not refused fails the test instead of serving for ever


@pytest.fixture
def mission(tmp_path: Path) -> Path:
    p = tmp_path / "tiny.toml"
    p.write_text(TINY)
    return p


def _refused(argv: list[Any], names: str) -> str:
    """``bsst argv`` as a real process (one that is not refused flies or serves: the timeout ends it)."""
    r = run_bsst(*[str(a) for a in argv], timeout=GUARD_S)
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2, f"exit {r.returncode}: {r.stderr!r}"
    assert len(lines) == 1 and names in lines[0], r.stderr  # one line: nothing was flown (no progress lines) first
    return lines[0]


@pytest.mark.skipif(not os.path.isdir(READ_ONLY) or os.access(READ_ONLY, os.W_OK), reason="needs Linux's /proc")
@pytest.mark.parametrize("command", ["sim", "sweep", "margin", "vehicle", "controller"])
@pytest.mark.parametrize("where", ["existing", "to create"])
def test_an_out_that_cannot_be_written_is_refused_first(command, where, mission):
    out = READ_ONLY if where == "existing" else READ_ONLY / "bsst-run"
    args = {"sim": [mission, "--no-plots"], "sweep": [mission, "--jobs", "1", "--no-plots"],
            "margin": [mission, "--over", "delay_ms", "--until", "rms=0.1"],
            "vehicle": [mission, "--listen", "127.0.0.1:0", "--gcs", "none"],
            "controller": [mission, "--vehicle", "127.0.0.1:9", "--timeout", "0.2"]}[command]
    line = _refused([command, *args, "--out", out, "--overwrite"], f"--out {out}")
    assert line.endswith("cannot write into it" if where == "existing" else "(cannot write into /proc/self)")


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into a directory of mode 0555")
def test_a_read_only_directory(mission, tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        _refused(["sim", mission, "--out", ro, "--no-plots"], f"--out {ro}: cannot write into it")
        _refused(["sim", mission, "--out", ro / "new", "--no-plots"], f"cannot write into {ro}")
    finally:
        ro.chmod(0o755)


def test_the_checks_name_the_path(tmp_path):
    """What each refusal says, from the functions every command's ``--out`` goes through."""
    a_file = tmp_path / "notes.txt"
    a_file.write_text("mine\n")
    for check in (lambda p: run_dir(p, "tiny", create=False), lambda p: side_dir(p, ("vehicle.tlog",))):
        with pytest.raises(ConfigError, match="exists and is not a directory"):
            check(a_file)
        with pytest.raises(ConfigError, match=r"cannot create \(.*notes.txt is not a directory\)"):
            check(a_file / "sub")
        assert check(tmp_path / "new" / "deeper") == tmp_path / "new" / "deeper"
    assert a_file.read_text() == "mine\n"


def test_an_output_file_names_what_is_wrong_with_its_folder(tmp_path):
    """``bsst link fit --out missing/f.toml`` said ``missing is not a directory`` of a folder that does not exist;
    it says so now. Output files (``check_writable``: ``bsst link fit|extract|show --out``, ``relay --stats``) and
    ``--out`` directories (``check_out_dir``) look their path up one way (``params.look_up``)."""
    a_file = tmp_path / "notes.txt"
    a_file.write_text("mine\n")
    missing = tmp_path / "missing"
    for out, says in ((missing / "f.toml", f"{missing} does not exist"),
                      (missing / "deeper" / "f.toml", f"{missing / 'deeper'} does not exist"),
                      (a_file / "f.toml", f"{a_file} is not a directory"),
                      (a_file / "sub" / "f.toml", f"{a_file} is not a directory"),
                      (tmp_path, "is a directory")):
        r = run_bsst("link", "fit", "examples/link-trace.csv", "--out", out, timeout=GUARD_S)
        assert r.returncode == 2 and r.stderr == f"bsst: --out {out}: {says}\n", r.stderr
    assert not missing.exists() and a_file.read_text() == "mine\n"
    r = run_bsst("link", "fit", "examples/link-trace.csv", "--out", tmp_path / "f.toml", timeout=GUARD_S)
    assert r.returncode == 0 and (tmp_path / "f.toml").is_file(), r.stderr
