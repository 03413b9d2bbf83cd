"""Covers bridge.cli, missions.mission and bridge.sweep.spec.

Bad input (issue 7): every flag of every ``bsst`` command, and every mission and sweep key,
given a bad value (wrong type, out of range, missing file, unreadable file, port in use)
exits 2 with one line on stderr naming it, and no traceback.

The flags are walked from the parser itself (a flag added later is walked too, and a flag
of a kind this file has no bad value for fails the walk); the keys from what the
validators ask for while a mission with every table is prepared. Most cases call
``bridge.cli.main`` in this process (an uncaught exception fails the test, the traceback
case); a few run ``python -m bridge`` as a real process.
"""

from __future__ import annotations

import argparse
import contextlib
import copy
import functools
import os
import signal
import socket
import subprocess
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from bridge import simulate
from bridge.autopilot.params import BY_NAME
from bridge.cli import build_parser, main
from bridge.cli.flags import UsageError
from bridge.core.flight import prepare
from bridge.mavlink.endpoint import LINK_PORT
from bridge.session import instance_slot
from missions import MISSION_DIR, mission_from_table
from missions.route import LIMIT_RANGES
from params import ConfigError, Table, dump_toml, is_typo_of, load_toml, show
from params.px4 import PX4_NAMES
from tests.sitlkit import ROOT, run_bsst

pytestmark = pytest.mark.process  # starts processes or opens sockets: not in make test-fast

TINY = 'name = "tiny"\nduration_s = 0.2\n[trajectory]\nkind = "sine"\n'
HUGE = 10**400  # an integer TOML and JSON read, past the float range: float() of it raises OverflowError
GUARD_S = 20  # s: a case that is not refused would fly or serve; it fails instead of hanging


@contextlib.contextmanager
def _guard() -> Iterator[None]:
    """Fail (instead of hanging) when a command meant to be refused starts serving; restore
    the signal handlers a command may have set."""
    def alarm(signum: int, frame: Any) -> None:
        raise TimeoutError(f"not refused within {GUARD_S} s")

    saved = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM, signal.SIGALRM)}
    signal.signal(signal.SIGALRM, alarm)
    signal.alarm(GUARD_S)
    try:
        yield
    finally:
        signal.alarm(0)
        for s, h in saved.items():
            signal.signal(s, h)


def _refused(capsys: Any, argv: list[Any], *names: str) -> str:
    """Run ``bsst argv`` in this process: exit 2, one line on stderr, naming one of ``names``."""
    with _guard():
        rc = main([str(a) for a in argv])
    _, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert rc == 2, f"bsst {' '.join(map(str, argv))}: exit {rc}, stderr {err!r}"
    assert len(lines) == 1 and lines[0].startswith("bsst"), err
    assert any(n in lines[0] for n in names), f"{lines[0]!r} names none of {names}"
    return lines[0]


# -- the files a walk needs ------------------------------------------------------------------------
class Files:
    def __init__(self, root: Path) -> None:
        self.root = root
        self.mission = root / "tiny.toml"
        self.mission.write_text(TINY)
        self.missing = root / "nowhere.toml"
        self.directory = root / "adir"
        self.directory.mkdir()
        self.binary = root / "binary.toml"
        self.binary.write_bytes(b"\xff\xfe\x00garbage")
        self.not_toml = root / "junk.toml"
        self.not_toml.write_text("<xml>not toml</xml>")
        self.regular = root / "afile"
        self.regular.write_text("x")
        self.socket_path = root / "a.sock"  # a path nobody can read, not even root: open() gives ENXIO
        self._sock = socket.socket(socket.AF_UNIX)
        self._sock.bind(str(self.socket_path))
        self.key_empty = root / "key.empty"
        self.key_empty.write_bytes(b"")
        self.key_empty.chmod(0o600)
        self.key_open = root / "key.open"
        self.key_open.write_bytes(bytes(32))
        self.key_open.chmod(0o644)
        self.out = root / "out"

    def close(self) -> None:
        self._sock.close()


@pytest.fixture
def files(tmp_path: Path) -> Iterator[Files]:
    f = Files(tmp_path)
    yield f
    f.close()


@pytest.fixture(scope="module")
def shared_files(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Files]:
    """One :class:`Files` for the walks whose tests only read them and write ``bad.toml`` (each overwrites
    it): the key walk's ~1 500 tests made ~1 500 directories of eight files each (~5 s of a worker's CPU
    to make and later delete, on this VM's disk); the flag walk's 329 tests, ~0.5 s."""
    f = Files(tmp_path_factory.mktemp("files"))
    yield f
    f.close()


BAD_FILES = ("missing", "directory", "binary", "not_toml", "socket_path")  # for a file to be read

# what each command needs besides the one bad value (so that only that value can be wrong)
BASE = {
    "sim": lambda f: [f.mission, "--out", f.out, "--no-plots"],
    "sitl": lambda f: [f.mission, "--out", f.out, "--no-plots", "--gcs", "none"],
    "vehicle": lambda f: [f.mission, "--listen", "127.0.0.1:0", "--gcs", "none"],
    "controller": lambda f: [f.mission, "--vehicle", "127.0.0.1:9", "--timeout", "0.2"],
    "sweep": lambda f: [f.mission, "--out", f.out, "--jobs", "1", "--no-plots"],
    "report": lambda f: [],
    "relay": lambda f: ["--listen", "127.0.0.1:0", "--to", "127.0.0.1:9", "--duration", "0.1"],
    "link": lambda f: [],
    "margin": lambda f: [f.mission, "--over", "delay_ms", "--until", "rms=0.1", "--out", f.out],
}
# bad values by the converter a flag's argparse type comes from
CONVERTER_BAD = {
    "number_in": ["x", "-1e300", "nan", "inf"],
    "pace_speed": ["x", "-1", "nan", "0.001"],  # 0.001: between 0 (as fast as it goes) and the slowest pace
    "link_number": ["x", "-1e300", "nan", "1e300"],
    "int_in": ["x", "-99999999999", "99999999999", "1.5"],
    "value_list": ["x", "-1e300", "1,1", ""],
    "name_list": ["x", "bsst,bsst"],
    "mission_number": ["x", "-1e300", "nan", "inf", "1001"],  # 1001: past --rate (1000 Hz) and --scatter (100 m)
    "mission_integer": ["x", "-1", "99999999999", "1.5"],
    "link_seed": ["x", "-1", "99999999999", "1.5"],
    "axis_values": ["x", "-1e300", "1,1", ""],
    "fleet_sizes": ["x", "0", "1.5", "1,1", "1e300"],
    "jobs_count": ["x", "0", "1025", "1.5"],
    "law_spec": ["x", "nofile.py:Law", "no_such_module:Law", "json:JSONDecoder", "bsst:"],
    "law_list": ["x", "bsst,bsst", "bsst,nofile.py:Law"],
    "blackout_window": ["x", "-1:1", "1:0"],
    "wind_flag": ["x", "-5", "5:x"],
    "_ids": ["x", "999:1", "200"],
    "_home": ["x", "91,0,0", "1,2"],
    "trace_file": ["no_such_trace.csv", "/"],
    "yes_no": ["maybe", "2"],
    "link_profile": ["no_such_profile", "no_such_profile.toml", "/"],
    "sensor_set_name": ["", "mo.cap", "bogus"],
    "noise_scale": ["x", "-1", "nan", "1e300"],
    "param_assignment": ["x", "NOPE=1", "COM_OF_LOSS_T=99", "COM_OBL_RC_ACT=2", "COM_OF_LOSS_T=nan",
                         "5:COM_OF_LOSS_T=99", "x:COM_OBL_ACT=1",
                         "EKF2_NOAID_TOUT=" + "1" * 50, "5:EKF2_NOAID_TOUT=" + "1" * 50],  # (a traceback once)
    "system_id": ["x", "0", "255", "1.5"],
    "fleet_size": ["x", "0", "65", "1.5"],
}
# bad values of the flags that take text (a callable of the files: values)
TEXT_BAD = {
    "--until": lambda f: ["rms=x", "rms=-1", "class=nope", "speed=3", "rms"],
    "--out": lambda f: [f.regular, ""],  # "" would be the current folder
    "--profile": lambda f: ["nosuch", f.missing.with_suffix(".profile.toml")],
    "--listen": lambda f: ["nowhere", "udpout:127.0.0.1:9", "127.0.0.1:70000"],
    "--gcs": lambda f: ["127.0.0.1:notaport", "udpin:x"],
    "--vehicle": lambda f: ["udpin:127.0.0.1:5", "nowhere"],
    "--to": lambda f: ["nowhere", "127.0.0.1:0"],
    "--client": lambda f: ["nowhere", "127.0.0.1:0", "udpin:127.0.0.1:5"],
    "--controller-from": lambda f: ["nowhere", "127.0.0.1:0", "udpin:127.0.0.1:5", "127.0.0.1:x"],
    "--mission": lambda f: [getattr(f, b) for b in BAD_FILES],
    "--stats": lambda f: [f.regular / "x.json", f.directory, "", f.regular],  # "": the current folder; one that exists
    "--dask": lambda f: ["notanaddress"],
    "--key": lambda f: [f.missing, f.key_empty, f.key_open, f.directory],
    "--at": lambda f: ["x", "5:bogus", "5:gps:sideways", "0.1:motor:9=0.5", "99:wind:3", "0.1:gust:0,3",
                       "0.1:gps:off", "0.1:motor:1=0.5", "0.1:link:bogus", "0.1:link:stale_ms=5"],  # flown: named too
    "--formation": lambda f: ["line", "ring:2", "line:0", "circle:x"],
    "--gate": lambda f: [f.missing, f.directory, f.regular],
    "--radio": lambda f: [f.missing, f.directory, f.regular, f.socket_path],
}
POSITIONAL_BAD = {  # command -> bad values of its positional argument
    "report": lambda f: [f.missing, f.regular, f.directory],
    "link": lambda f: ["bogus"],  # its actions (extract, fit, show): tests/test_link_trace.py
}


@functools.cache
def _commands() -> dict[str, argparse.ArgumentParser]:
    """Each command's parser, of one parser built once (read, never changed, by the tests)."""
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


def _flag_cases() -> list[tuple[str, str]]:
    out = []
    for cmd, p in _commands().items():
        for a in p._actions:
            if isinstance(a, argparse._HelpAction) or a.nargs == 0:
                continue
            out.append((cmd, a.option_strings[0] if a.option_strings else a.dest))
    return out


def _bad_values(cmd: str, action: argparse.Action, f: Files) -> list[Any]:
    if not action.option_strings:  # the positional: a mission file, or report's directory
        return POSITIONAL_BAD.get(cmd, lambda f: [getattr(f, b) for b in BAD_FILES])(f)
    flag = action.option_strings[0]
    if action.choices is not None and action.type is None:
        return ["bogus"]
    if action.type is None or getattr(action.type, "__qualname__", "").startswith("path_given"):
        assert flag in TEXT_BAD, f"bsst {cmd} {flag}: give tests/test_bad_input.py a bad value for it"
        return TEXT_BAD[flag](f)
    kind = action.type.__qualname__.split(".")[0]
    assert kind in CONVERTER_BAD, f"bsst {cmd} {flag} ({kind}): give tests/test_bad_input.py bad values for it"
    return CONVERTER_BAD[kind]


@pytest.mark.parametrize("cmd, flag", _flag_cases())
def test_every_flag_refuses_a_bad_value(shared_files, capsys, cmd, flag):
    p = _commands()[cmd]
    action = next(a for a in p._actions if (a.option_strings[:1] or [a.dest]) == [flag])
    base = BASE[cmd](shared_files)
    for bad in _bad_values(cmd, action, shared_files):
        if action.option_strings:
            argv = [cmd, *base, flag, bad]
            names = (flag, str(bad))
            if getattr(action.type, "__qualname__", "").startswith("law_"):  # named by its file, module or class
                names += tuple(p for p in str(bad).replace(",", ":").split(":") if len(p) > 2)
        else:  # the positional comes first; report's directory, or a mission file
            argv = [cmd, bad, *base[1:]]
            names = (str(bad), Path(str(bad)).name)
        _refused(capsys, argv, *names)
        assert not shared_files.out.exists() or not any(shared_files.out.iterdir()), f"{argv}: wrote into --out"


# -- mission and sweep keys ----------------------------------------------------------------------------
@functools.cache
def _robust() -> dict[str, Any]:
    return load_toml(MISSION_DIR / "robust.toml")


def _full_mission(controller: str) -> dict[str, Any]:
    """A mission with every table the validators read (the robust one, a link, a failsafe, gains)."""
    d = copy.deepcopy(_robust())
    d.update(controller=controller, duration_s=0.2, actuation="wrench", physics_hz=1000.0)
    d["start"] = {"position": [0.0, 0.0, 0.0], "psi": 0.0}
    d["link"] = {"delay_ms": 0.0, "stale_ms": 50.0, "up": {"loss_pct": 0.0}, "down": {"loss_pct": 0.0}}
    d["failsafe"] = {"timeout_s": 0.5}
    d["gains"] = {"smc_scale": 1.0}
    return d


def _keys_asked(data: dict[str, Any], source: str) -> dict[str, tuple[str, tuple, dict]]:
    """Every key the validators ask of ``data`` while a run is prepared from it: dotted name ->
    (getter, positional arguments, keyword arguments), recorded by wrapping Table's getters."""
    asked: dict[str, tuple[str, tuple, dict]] = {}
    saved = {}
    for getter in ("number", "integer", "string", "boolean", "vector", "table"):
        saved[getter] = original = getattr(Table, getter)

        def spy(self: Table, name: str, *a: Any, _g: str = getter, _o: Any = original, **kw: Any) -> Any:
            if self._source == source:
                asked.setdefault(self.key(name), (_g, a, kw))
            return _o(self, name, *a, **kw)

        setattr(Table, getter, spy)
    try:
        prepare(mission_from_table(data, source))
    finally:
        for getter, original in saved.items():
            setattr(Table, getter, original)
    return asked


def _bad_key_values(getter: str, args: tuple, kw: dict) -> list[Any]:
    lo, hi = kw.get("lo"), kw.get("hi")
    if getter == "number":
        out: list[Any] = ["x", float("nan"), HUGE]
        if lo is not None:
            out.append(lo if kw.get("lo_open") else lo - 1.0 - abs(lo))
        if hi is not None:
            out.append(hi if kw.get("hi_open") else hi + 1.0 + abs(hi))
        return out
    if getter == "integer":
        return [1.5, "x"] + ([lo - 1] if lo is not None else []) + ([hi + 1] if hi is not None else [])
    if getter == "string":
        return [5] + (["bogus"] if kw.get("choices") else [])
    if getter == "boolean":
        return ["yes", 1]
    if getter == "vector":
        n = args[0]
        return [[1.0] * (n + 1), ["x"] * n, [HUGE] * n] + ([[lo - 1.0 - abs(lo)] * n] if lo is not None else [])
    if getter == "table":
        return [5]
    raise AssertionError(getter)


def _set(data: dict[str, Any], dotted: str, value: Any) -> dict[str, Any]:
    """A deep copy of ``data`` with ``dotted`` (``a.b[0].c``) set to ``value``."""
    import copy

    out = copy.deepcopy(data)
    node: Any = out
    parts = dotted.split(".")
    for part in parts[:-1]:
        name, _, idx = part.partition("[")
        node = node.setdefault(name, {})
        if idx:
            node = node[int(idx.rstrip("]"))]
    node[parts[-1]] = value
    return out


def _key_cases() -> list[tuple[str, str, Any]]:
    """Each key any law's mission asks for, with each of its bad values, once: under the first law that asks it.
    A key every law asks is refused by the same validator whichever law the mission names (the same frames, the
    same line, checked for every case when this walk was cut from three laws to one: 1 824 cases to 608); a key
    only one law asks is walked under that law."""
    src = "<walk>"
    cases, seen = [], set()
    for ctl in ("bsst", "smc", "pid"):
        for key, (getter, a, kw) in _keys_asked(_full_mission(ctl), src).items():
            for bad in _bad_key_values(getter, a, kw):
                if (key, repr(bad)) not in seen:
                    seen.add((key, repr(bad)))
                    cases.append((ctl, key, bad))
    return cases


KEY_CASES = _key_cases()


def test_the_key_walk_covers_every_table():
    keys = {k for _, k, _ in KEY_CASES}
    for table in ("start", "trajectory", "gains", "effects", "link", "link.up", "failsafe"):
        assert any(k.startswith(table + ".") for k in keys), table
    assert len(keys) > 60


@pytest.mark.parametrize("ctl, key, bad", KEY_CASES, ids=[f"{c}-{k}={show(b)}" for c, k, b in KEY_CASES])
def test_every_mission_key_refuses_a_bad_value(shared_files, capsys, ctl, key, bad):
    mission = shared_files.root / "bad.toml"
    mission.write_text(dump_toml(_set(_full_mission(ctl), key, bad)))
    _refused(capsys, ["sim", mission, "--out", shared_files.out, "--no-plots"], key)


@pytest.mark.parametrize("cmd", ["sitl", "vehicle", "controller", "relay", "sweep"])
@pytest.mark.parametrize("key, bad", [("duration_s", "long"), ("link.up.delay_ms", -5.0), ("speed", 3),
                                      ("trajectory.omega", 1e9), ("failsafe.resume", "yes")])
def test_every_command_reads_missions_alike(shared_files, capsys, cmd, key, bad):
    mission = shared_files.root / "bad.toml"
    mission.write_text(dump_toml(_set(_full_mission("bsst"), key, bad)))
    argv = [cmd, *BASE[cmd](shared_files)]
    argv = argv + ["--mission", mission] if cmd == "relay" else [cmd, mission, *argv[2:]]
    _refused(capsys, argv, key)


SWEEP = 'mission = "{m}"\nmode = "offline"\nseeds = 1\n[grid]\ndelay_ms = [0.0]\n[classes]\nclean_rms_m = 0.001\n'


@pytest.mark.parametrize("key, bad", [("mission", 5), ("mission", "nowhere.toml"), ("mode", "fast"), ("jobs", -1),
                                      ("jobs", 0), ("jobs", 1025), ("classes.diverged_rms_m", 1e-4),
                                      ("seeds", 0), ("seeds", "x"), ("grid.delay_ms", "x"), ("grid.delay_ms", [-1.0]),
                                      ("grid.colour", [1]), ("classes.clean_rms_m", "x"), ("extra", 1),
                                      ("grid.noise", [-1.0]), ("grid.noise", "x"), ("grid.noise", [0.0, 1e300]),
                                      ("grid.estimator", ["kalman"]), ("grid.estimator", 5),
                                      ("grid.estimator", ["raw", "raw"]), ("grid.delay_ms", [HUGE])])
def test_every_sweep_key_refuses_a_bad_value(files, capsys, key, bad):
    data = load_toml_text(SWEEP.format(m=files.mission))
    sweep = files.root / "sweep.toml"
    sweep.write_text(dump_toml(_set(data, key, bad)))
    _refused(capsys, ["sweep", sweep, "--out", files.out, "--jobs", "1", "--no-plots"], key.split(".")[-1])


def test_a_grid_over_the_cap_counts_its_cells_as_they_are_made(files, capsys):
    """The refusal of a grid over ``--max-cells`` names factors that multiply to its count: a law without a
    super-twisting step (smc, pid) is one cell per point, so 3 laws x 2 discretizations x 2 delays is 8 cells, not
    12 (it said '3 controller x 2 delay_ms x 2 discretization x 1 seeds' for 8); a grid whose plain product is its
    count is said as before."""
    base = ["sweep", files.mission, "--delay", "0,5", "--max-cells", "1", "--out", files.out, "--no-plots"]
    line = _refused(capsys, [*base, "--controller", "bsst,smc,pid", "--discretization", "explicit,implicit"],
                    "grid: 8 cells")
    assert ("grid: 8 cells (4 law-schemes x 2 delay_ms x 1 seeds; the 4 law-schemes: bsst x 2 discretization + smc + "
            "pid, a law without a super-twisting step being one cell whatever the discretization), over the cap of 1"
            in line), line
    line = _refused(capsys, [*base, "--controller", "bsst,smc"], "grid: 4 cells")
    assert "grid: 4 cells (2 controller x 2 delay_ms x 1 seeds), over the cap of 1" in line, line
    assert not files.out.exists() or not any(files.out.iterdir())


@pytest.mark.parametrize("jobs", [0, 1, 1024, 1025])
def test_jobs_has_one_range_in_a_sweep_file_and_on_the_command_line(files, jobs):
    """``jobs = N`` in a sweep file and ``--jobs N`` (sweep, margin): each takes N, or each refuses it naming the one
    range (``jobs = 0`` was taken as all cores where ``--jobs 0`` was refused)."""
    from bridge.sweep.spec import load_sweep

    sweep = files.root / "sweep.toml"
    sweep.write_text(dump_toml(_set(load_toml_text(SWEEP.format(m=files.mission)), "jobs", jobs)))
    said = []
    for read in (lambda: load_sweep(sweep).jobs,
                 lambda: _commands()["sweep"].parse_args([str(sweep), "--jobs", str(jobs)]).jobs,
                 lambda: _commands()["margin"].parse_args([str(files.mission), "--over", "delay_ms", "--until", "rms=1",
                                                           "--jobs", str(jobs)]).jobs):
        try:
            said.append(read())
        except (ConfigError, UsageError) as exc:
            said.append(str(exc).replace("--jobs must", "must").split(": ")[-1])
    assert said == [jobs] * 3 if 1 <= jobs <= 1024 else said == [f"must be in [1, 1024], got {jobs}"] * 3, said
    if not 1 <= jobs <= 1024:  # a Python call's jobs= too (0 flew on every core, -1 was the pool's ValueError)
        from bridge.sweep import Grid
        from bridge.sweep import sweep as sweep_call
        from bridge.sweep.margin import margin, parse_until
        from missions import load_mission

        for call in (lambda: sweep_call(files.mission, Grid(delay_ms=(0.0,)), jobs=jobs),
                     lambda: margin(load_mission(files.mission), "delay_ms", parse_until("rms=1"), jobs=jobs)):
            with pytest.raises(ConfigError, match=rf"^jobs: must be a whole number in \[1, 1024\].*got {jobs}$"):
                call()


def load_toml_text(text: str) -> dict[str, Any]:
    import tomllib

    return tomllib.loads(text)


# -- an existing run directory, ports in use, unreadable files, real processes -----------------------
@pytest.mark.parametrize("cmd", ["sim", "sitl", "sweep"])
def test_a_non_empty_run_directory_is_refused_without_overwrite(files, capsys, cmd):
    files.out.mkdir()
    (files.out / "keep.txt").write_text("mine")
    _refused(capsys, [cmd, *BASE[cmd](files)], "--overwrite")
    assert [p.name for p in files.out.iterdir()] == ["keep.txt"]


def test_ports_in_use(files, capsys):
    taken = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    taken.bind(("127.0.0.1", 0))
    port = taken.getsockname()[1]
    try:
        _refused(capsys, ["relay", "--listen", f"127.0.0.1:{port}", "--to", "127.0.0.1:9", "--duration", "0.1"],
                 "--listen")
        _refused(capsys, ["vehicle", files.mission, "--listen", f"127.0.0.1:{port}", "--gcs", "none"], "--listen")
    finally:
        taken.close()
    with instance_slot() as n:  # bsst sitl: its vehicle cannot bind 14560 + N
        taken = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        taken.bind(("127.0.0.1", LINK_PORT + n))
        try:
            line = _refused(capsys, ["sitl", files.mission, "--instance", n, "--out", files.out, "--no-plots"],
                            "--instance", str(LINK_PORT + n))
        finally:
            taken.close()
    assert "in use" in line


def test_a_real_time_flight_is_not_sped_up(files, capsys):
    """``--speed`` paces lockstep; in real time the plant would outrun the controller's wall-clock
    schedule (it diverged at 2x): refused up front, nothing written."""
    line = _refused(capsys, ["sitl", files.mission, "--realtime", "--speed", "2", "--out", files.out, "--no-plots",
                             "--gcs", "none"], "--speed")
    assert "--realtime" in line and not files.out.exists()
    _refused(capsys, ["sitl", files.mission, "--realtime", "--speed", "0.5", "--out", files.out], "--speed")
    _refused(capsys, ["sitl", files.mission, "--realtime", "--speed", "0", "--out", files.out], "--speed")  # 0: unpaced


FLAG_FILES = [  # (flag, what follows it): a file a flag gives, bad on its own
    ("--link-trace", "line 1: unknown column 'name = \"tiny\"'; a trace has the columns t_s, delay_ms, direction"),
    ("--up-link-trace", "line 1: unknown column"),
    ("--down-link-trace", "line 1: unknown column"),
    ("--link-profile", ": link: a link profile needs a [link] table"),
]


@pytest.mark.parametrize("flag, said", FLAG_FILES)
def test_a_bad_file_a_flag_gives_is_named_as_the_flag_not_the_mission(files, capsys, flag, said):
    """``bsst sim m.toml --link-trace m.toml`` read ``bsst: m.toml: link.up.trace: .../m.toml line 2: ... (with these
    laid over the mission's [link]: ...)`` until the third wave's fortieth session: the mission blamed for the flag's
    file. Now the flag first, then the file and its line; ``--sensors`` alike."""
    line = _refused(capsys, ["sim", files.mission, flag, files.mission, "--out", files.out], flag)
    assert line.startswith(f"bsst: {flag} {files.mission.resolve()}") and said in line, line
    assert "laid over" not in line and "link.up" not in line, line


def test_a_sensor_set_a_flag_names_is_the_flags_from_the_command_line_and_python(files, capsys):
    line = _refused(capsys, ["sim", files.mission, "--sensors", "GNSS", "--out", files.out], "--sensors")
    assert line == "bsst: --sensors GNSS: profile 'paper' has no such sensor set; it has: ideal, mocap, gnss", line
    with pytest.raises(ConfigError, match=r"^--up-link-trace .*line 1: unknown column"):
        simulate(str(files.mission), link={"up": {"trace": str(files.mission)}})  # Python's: the field's flag


def test_a_table_a_caller_lays_over_the_mission_bad_alone_is_named_as_the_override(files):
    """``simulate("m.toml", wind={"speed": 5})`` read ``m.toml: wind.speed: ...`` of a file with no [wind], until the
    third wave's fortieth session; now as Overrides names a wrong type: ``overrides:``."""
    with pytest.raises(ConfigError) as exc:
        simulate(str(files.mission), wind={"speed": 5})
    assert str(exc.value) == "overrides: wind.speed: unknown key in [wind]; did you mean 'speed_mps'?"
    with pytest.raises(ConfigError) as exc:
        simulate(str(files.mission), failsafe={"mode": 1})
    assert str(exc.value) == ("overrides: failsafe.mode: unknown key in [failsafe]; allowed: timeout_s, descent_rate, "
                              "resume, action, hold_s")


def test_a_flags_value_is_named_as_given_not_as_the_files(files, capsys):
    """A link value from a flag that breaks a rule of the [link] table is named as the flag (``--burst 0.5``,
    ``--stop-after`` below the stale age: test_a_guard_flag_that_clashes_is_named_as_the_flag; ``--rate`` not
    dividing the physics rate: test_a_rate_the_physics_rate_is_no_multiple_of_is_named_as_the_flag); until the
    thirty-third session each read as the file's own key, which the file did not have (``--profile ''`` too).
    ``--blackout`` says its ranges; ``bsst report`` of a folder that is not there says so."""
    line = _refused(capsys, ["sim", files.mission, "--burst", "0.5", "--out", files.out], "--burst")
    assert line.endswith("must be 0 (Bernoulli loss) or >= 1 packet, got 0.5"), line
    line = _refused(capsys, ["sim", files.mission, "--stop-after", "40", "--out", files.out], "--stop-after 40")
    assert line == "bsst: --stop-after 40: must be >= stale_ms = 50, got 40 (--stale-after sets stale_ms)", line
    line = _refused(capsys, ["sim", files.mission, "--rate", "333", "--out", files.out], "--rate 333")
    assert line.startswith("bsst: --rate 333: the physics rate 1000 Hz must be a whole multiple of it"), line
    _refused(capsys, ["sim", files.mission, "--profile", "", "--out", files.out], "--profile ")  # not the file's
    line = _refused(capsys, ["sim", files.mission, "--blackout", "1000001:1"], "--blackout")
    assert "start in [0, 1e+06], duration in (0, 1e+06]" in line, line
    line = _refused(capsys, ["report", files.root / "gone"], "gone")
    assert "no such directory" in line and not files.out.exists(), line
    run = files.root / "run"  # a run's directory, not a sweep's (it said "cells.csv: no such file")
    run.mkdir()
    (run / "summary.json").write_text("{}")
    line = _refused(capsys, ["report", run], "summary.json")
    assert "a run's directory" in line, line


GUARD_CLASHES = [  # (the mission's [link], argv after the command's mission, the one line after "bsst: ")
    ("", ["sim", "--command-lag", "20"], '--command-lag 20: needs compensation = "predict" (--compensation sets '
                                         "compensation)"),
    ("", ["sitl", "--stop-after", "10", "--gcs", "none"], "--stop-after 10: must be >= stale_ms = 50, got 10 "
                                                          "(--stale-after sets stale_ms)"),
    ("", ["sim", "--stale-after", "300"], "--stale-after 300: must be <= stop_ms = 250, got 300 (--stop-after sets "
                                          "stop_ms)"),
    ("", ["sweep", "--delay", "0,5", "--command-lag", "20"], 'sweep: --command-lag 20: needs compensation = '
                                                             '"predict" (--compensation sets compensation)'),
    ("", ["margin", "--over", "delay_ms", "--until", "rms=0.1", "--stop-after", "10"],
     "--stop-after 10: must be >= stale_ms = 50, got 10 (--stale-after sets stale_ms)"),
    # the other key of the pair is the file's: still the flag's value is named
    ("stale_ms = 100\n", ["sim", "--stop-after", "60"], "--stop-after 60: must be >= stale_ms = 100, got 60 "
                                                        "(--stale-after sets stale_ms)"),
    ('compensation = "predict"\ncommand_lag_ms = 10\n', ["sim", "--compensation", "none"],
     "--compensation none: must be \"predict\" where command_lag_ms = 10 (the lag prediction covers), got 'none' "
     "(--command-lag sets command_lag_ms)"),
]


@pytest.mark.parametrize(("link", "argv", "said"), GUARD_CLASHES)
def test_a_guard_flag_that_clashes_is_named_as_the_flag(tmp_path, capsys, link, argv, said):
    """A guard flag whose value breaks the guard's rule with the flight's other guard keys (a command lag without
    prediction, a stop age below the stale age: bridge.link.model.guard_problem) is refused naming the flag and the
    value given (docs/links.md); until the ``fix-blackoutcrash`` branch the line named the mission file's key
    (``tiny.toml: link.command_lag_ms: ...``), which the file did not have, with the keys laid over it. Nothing
    is written; a flag that mends the clash flies."""
    mission = tmp_path / "m.toml"
    mission.write_text(TINY + (f"[link]\n{link}" if link else ""))
    out = tmp_path / "out"
    extra = {"sim": ["--no-plots"], "sitl": ["--no-plots"], "sweep": ["--jobs", "1", "--no-plots"]}.get(argv[0], [])
    line = _refused(capsys, [argv[0], mission, *argv[1:], *extra, "--out", out], said)
    assert line == f"bsst{' ' if argv[0] == 'sweep' else ': '}{said}", line
    assert not out.exists()


def test_a_mission_files_own_guard_clash_names_its_key(tmp_path, capsys):
    """The file's own clash is the file's to name (its key, and what was laid over it), whatever guard flag is
    given beside it; a flag that mends it flies."""
    mission = tmp_path / "m.toml"
    mission.write_text(TINY + "[link]\ncommand_lag_ms = 10\n")
    line = _refused(capsys, ["sim", mission, "--stop-after", "300", "--out", tmp_path / "out"], "link.command_lag_ms")
    assert f'{mission}: link.command_lag_ms: needs compensation = "predict" (with these laid over' in line, line
    with _guard():
        assert main(["sim", str(mission), "--compensation", "predict", "--out", str(tmp_path / "ok"),
                     "--no-plots"]) == 0


RATE_CLASHES = [  # (the mission's own top-level keys, argv after the command's mission, what the line says after it)
    ("", ["sim", "--rate", "333"], "the physics rate 1000 Hz must be a whole multiple of it (allowed: 1000 Hz divided "
                                   "by a whole number, 50-1000 Hz; the whole ones 50, 100, 125, 200, 250, 500, 1000)"),
    ("physics_hz = 1200\nrate_hz = 300\n", ["sitl", "--rate", "333", "--gcs", "none"],
     "the physics rate 1200 Hz (M's physics_hz) must be a whole multiple of it (allowed: 1200 Hz divided by a whole "
     "number, 50-1000 Hz; the whole ones 50, 60, 75, 80, 100, 120, 150, 200, 240, 300, 400, 600)"),
    ("", ["vehicle", "--rate", "333"], "the physics rate 1000 Hz must be"),
    ("physics_hz = 1200\nrate_hz = 300\n", ["sim", "--rate", "333"],
     "the physics rate 1200 Hz (M's physics_hz) must be"),
]


@pytest.mark.parametrize(("own", "argv", "said"), RATE_CLASHES)
def test_a_rate_the_physics_rate_is_no_multiple_of_is_named_as_the_flag(tmp_path, capsys, own, argv, said):
    """``--rate 333`` where the physics rate (1000 Hz, or the file's physics_hz) is no whole multiple of it is
    refused naming the flag, its value and the rates allowed (missions.mission.rate_problem, the loader's rule);
    until the third wave's thirty-seventh session the line named the mission file's key ``rate_hz``, which the user
    did not type, with the keys laid over it. Nothing is written; a rate that divides it flies, and the file's own
    rate_hz is still the file's to name."""
    mission = tmp_path / "m.toml"
    mission.write_text(own + TINY)
    out = tmp_path / "out"
    extra = ["--no-plots", "--out", out] if argv[0] in ("sim", "sitl") else []
    said = said.replace("(M's", f"({mission}'s")
    line = _refused(capsys, [argv[0], mission, *argv[1:], *extra], said)
    assert line.startswith(f"bsst: --rate 333: {said}"), line
    assert "rate_hz" not in line and "laid over" not in line, line
    assert not out.exists()
    if argv[0] == "sim":
        with _guard():
            assert main(["sim", str(mission), "--rate", "300" if "1200" in own else "250", "--no-plots", "--out",
                         str(out)]) == 0


def test_a_physics_rate_the_default_rate_does_not_fit_names_the_files_rate_hz(tmp_path, capsys):
    """A file with ``physics_hz = 1200`` and no ``rate_hz`` (so the default 250 Hz, which 1200 Hz is no whole
    multiple of) is refused naming the file's ``rate_hz``: that it was not given, the default it took, the physics
    rate it must divide and the rates allowed; ``bsst sim``, ``bsst sitl`` with or without ``--rate`` and the Python
    API alike. Until the third wave's thirty-ninth session ``bsst sitl --rate 333`` named the flag and offered
    ``--rate 300``, which the file's default still refused (``rate_hz: ..., got 250``, a key the file did not
    have). Nothing is written; the file flies once it gives a rate_hz that fits."""
    mission = tmp_path / "m.toml"
    mission.write_text("physics_hz = 1200\n" + TINY)
    out = tmp_path / "out"
    said = (f"bsst: {mission}: rate_hz: not given, so 250 Hz (the default), and the physics rate 1200 Hz (physics_hz) "
            "must be a whole multiple of it (allowed: 1200 Hz divided by a whole number, 50-1000 Hz; the whole ones "
            "50, 60, 75, 80, 100, 120, 150, 200, 240, 300, 400, 600); give rate_hz")
    for argv in (["sim"], ["sitl", "--gcs", "none"], ["sitl", "--gcs", "none", "--rate", "333"],
                 ["sitl", "--gcs", "none", "--rate", "300"], ["sim", "--rate", "300"]):
        line = _refused(capsys, [argv[0], mission, *argv[1:], "--no-plots", "--out", out], "rate_hz")
        assert line.startswith(said) and "--rate 333:" not in line, (argv, line)
        assert not out.exists()
    with pytest.raises(ConfigError) as e:
        simulate(mission, rate_hz=300.0)
    assert f"bsst: {e.value}".startswith(said), e.value
    mission.write_text("physics_hz = 1200\nrate_hz = 300\n" + TINY)
    with _guard():
        assert main(["sim", str(mission), "--no-plots", "--out", str(out)]) == 0
        (tmp_path / "own.toml").write_text("rate_hz = 333\n" + TINY)
        line = _refused(capsys, ["sim", tmp_path / "own.toml", "--out", tmp_path / "o2"], "rate_hz")
        assert line.startswith(f"bsst: {tmp_path / 'own.toml'}: rate_hz: the physics rate 1000 Hz must"), line


def test_a_scatter_for_a_fleet_is_named_as_the_flag(tmp_path, capsys):
    """``--scatter M`` for a fleet (``--vehicles N``, or the mission's own ``[[vehicles]]``) is refused naming the
    flag and what made the fleet (missions.scatter.fleet_scatter_problem, the mission's rule); until the third
    wave's thirty-seventh session the line named the file's ``start.scatter_m``, with what was laid over it.
    Nothing is written; the file's own scatter is still the file's to name."""
    mission, out = tmp_path / "m.toml", tmp_path / "out"
    mission.write_text(TINY)
    line = _refused(capsys, ["sim", mission, "--scatter", "5", "--vehicles", "3", "--no-plots", "--out", out],
                    "--scatter 5")
    assert line == ("bsst: --scatter 5: a fleet's starts are its formation's (--vehicles 3): scatter the starts of "
                    "a mission of one vehicle"), line
    fleet = tmp_path / "fleet.toml"
    fleet.write_text(TINY + "[[vehicles]]\nid = 1\n[[vehicles]]\nid = 2\nstart = [2.0, 0.0, 0.0, 0.0]\n")
    line = _refused(capsys, ["sitl", fleet, "--scatter", "0.5", "--gcs", "none", "--out", out], "--scatter 0.5")
    assert line.startswith(f"bsst: --scatter 0.5: a fleet's starts are its formation's ({fleet}'s [[vehicles]])")
    assert not out.exists()
    scattered = tmp_path / "scattered.toml"
    scattered.write_text(TINY + "[start]\nscatter_m = 1.0\n")
    line = _refused(capsys, ["sim", scattered, "--vehicles", "2", "--out", out], "start.scatter_m")
    assert line.startswith(f"bsst: {scattered}: start.scatter_m: a fleet's starts are its formation's"), line


IDLE_FLAGS = [  # (argv after the command's mission, what the one line names): a flag that would change nothing
    # --discretization where no law flown has a super-twisting step (docs/law.md; until the third wave's
    # thirty-seventh session it was taken, and summary.json said the scheme of a law that has none)
    (["sim", "--controller", "smc", "--discretization", "explicit"], "--discretization explicit: only bsst has"),
    (["sitl", "--controller", "pid", "--discretization", "implicit"], "--discretization implicit: only bsst has"),
    (["controller", "--controller", "smc", "--discretization", "explicit"], "--discretization explicit: only bsst"),
    (["sweep", "--controller", "smc,pid", "--discretization", "explicit,implicit"],
     "grid.discretization (--discretization): only bsst has a super-twisting step to discretize: pid and smc fly"),
    (["margin", "--over", "delay_ms", "--until", "rms=0.1", "--controller", "smc", "--discretization", "explicit"],
     "--discretization explicit: only bsst has"),
    # margin's --controller is a list of laws: a fixed --noise was refused as "overrides: controller: expected a
    # string" (until the same session), not for the noise it would not change
    (["margin", "--over", "delay_ms", "--until", "rms=0.1", "--controller", "bsst,smc", "--noise", "2"],
     "--noise 2: the estimator is 'truth'"),
    # --sensors where every vehicle flies the true state, its sensors not sampled (docs/sensors.md; until the third
    # wave's fortieth session bsst sim --sensors gnss flew byte for byte as without it): named with what to give
    (["sim", "--sensors", "gnss"], "--sensors gnss: the estimator is 'truth' (the true state: the sensors are not "
                                   "read), so the sensor set changes nothing; give --estimator raw or ekf"),
    (["sitl", "--vehicles", "2", "--sensors", "mocap"], "--sensors mocap: the estimator is 'truth'"),
    (["vehicle", "--sensors", "gnss"], "--sensors gnss: the estimator is 'truth'"),
    (["sweep", "--loss", "0,5", "--sensors", "gnss"], "bsst sweep: --sensors gnss: the estimator is 'truth'"),
    (["sweep", "--estimator", "truth", "--sensors", "gnss"], "bsst sweep: --sensors gnss: the estimator is 'truth'"),
    (["margin", "--over", "delay_ms", "--until", "rms=0.1", "--sensors", "gnss"],
     "--sensors gnss: the estimator is 'truth'"),
]


@pytest.mark.parametrize("argv, names", IDLE_FLAGS, ids=[" ".join(a[:1] + a[-2:]) for a, _ in IDLE_FLAGS])
def test_a_flag_that_would_change_nothing_is_refused(files, capsys, argv, names):
    """Exit 2, one line naming the flag and what it needs, before anything is written (no run directory)."""
    _refused(capsys, [argv[0], files.mission, *argv[1:], "--out", files.out], names)
    assert not files.out.exists()


def test_sensors_read_by_an_estimator_or_a_files_own_set_are_not_refused(files, tmp_path, capsys):
    """``--sensors`` is taken where a vehicle reads its sensors (``--estimator ekf``, a sweep's estimator axis with a
    kind that reads them) and a mission file's own ``[sensors]`` table under ``truth`` is not refused (older files
    have one): each is refused for what comes next instead (a later rule of the same command)."""
    _refused(capsys, ["sim", files.mission, "--sensors", "gnss", "--estimator", "ekf", "--burst", "3", "--out",
                      files.out], "--burst 3: changes nothing")
    _refused(capsys, ["sweep", files.mission, "--sensors", "gnss", "--estimator", "truth,ekf", "--loss", "0,5",
                      "--max-cells", "1", "--out", files.out], "over the cap of 1")
    own = tmp_path / "own.toml"
    own.write_text(Path(files.mission).read_text() + '\n[sensors]\nset = "gnss"\n')
    _refused(capsys, ["sim", own, "--burst", "3", "--out", files.out], "--burst 3: changes nothing")
    assert not files.out.exists()


def test_a_flag_that_would_change_nothing_in_a_long_mission_of_one_side_is_named_as_the_flag(tmp_path, capsys):
    """``bsst vehicle`` and ``bsst controller`` stream their rows to disk and fly a mission longer than a run keeps in
    memory (bridge.record.runlog.check_trace_steps): a flag that would change nothing in one is refused as that flag.
    Until the third wave's thirty-eighth session the check read the mission again with ``bsst sim``'s cap, and the
    line said it was too long, to be flown with bsst vehicle and bsst controller: the very commands refusing it."""
    mission = tmp_path / "long.toml"
    mission.write_text('name = "long"\nduration_s = 3000.0\n[trajectory]\nkind = "sine"\nclimb = 0.0\n')
    _refused(capsys, ["controller", mission, "--controller", "smc", "--discretization", "explicit"],
             "--discretization explicit: only bsst has")
    _refused(capsys, ["vehicle", mission, "--noise", "2"], "--noise 2: the estimator is 'truth'")


IDLE_LINK = [  # (argv, {m} the mission and {out} the run directory; what the one line names): a link flag that acts
    # only with another, given where nothing gives that (until the third wave's thirty-seventh session each was taken
    # and flew nothing different); a sweep's only where no cell has it, a margin's in the search's probes
    (["sim", "{m}", "--burst", "3"], "--burst 3: changes nothing: it sets the mean length of the loss bursts, and no "
                                     "packet is lost (loss_pct 0); give --loss PCT too, or drop --burst"),
    (["sim", "{m}", "--burst", "3", "--loss", "0"], "--burst 3: changes nothing"),
    (["sitl", "{m}", "--down-burst", "3", "--up-loss", "2"], "--down-burst 3: changes nothing: it sets the mean "
                                                             "length of the loss bursts, and no packet is lost"),
    (["sim", "{m}", "--queue", "200"], "--queue 200: changes nothing: it bounds the wait in the bandwidth cap's queue, "
                                       "and there is no bandwidth cap (rate_bps 0); give --bandwidth BYTES_PER_S too"),
    (["sim", "{m}", "--link-trace-loop"], "--link-trace-loop true: changes nothing: it loops the link trace, and no "
                                          "trace is replayed (trace none); give --link-trace FILE too"),
    (["sim", "{m}", "--vehicles", "2", "--up-queue", "50"], "--up-queue 50: changes nothing"),
    (["relay", "--listen", "127.0.0.1:0", "--to", "127.0.0.1:9", "--mission", "{m}", "--queue", "300", "--duration",
      "0.2"], "--queue 300: changes nothing"),
    (["sweep", "{m}", "--burst", "3"], "grid.burst_len (--burst): changes nothing in any cell: it sets the mean length "
                                       "of the loss bursts, and no packet is lost (loss_pct 0); sweep --loss too"),
    (["sweep", "{m}", "--burst", "0,3", "--loss", "0"], "grid.burst_len (--burst): changes nothing in any cell"),
    (["sweep", "{m}", "--delay", "0,5", "--up-burst", "3"], "bsst sweep: --up-burst 3: changes nothing in any cell"),
    (["sweep", "{m}", "--queue", "300"], "bsst sweep: --queue 300: changes nothing in any cell"),
    (["margin", "{m}", "--over", "delay_ms", "--until", "rms=0.1", "--burst", "3"], "--burst 3: changes nothing"),
    (["margin", "{m}", "--over", "burst_len", "--until", "rms=0.1"], "margin over burst_len: changes nothing: it sets"),
]


@pytest.mark.parametrize("argv, names", IDLE_LINK, ids=[" ".join(a[:1] + a[-2:]) for a, _ in IDLE_LINK])
def test_a_link_flag_that_would_change_nothing_is_refused(files, capsys, argv, names):
    """Exit 2, one line naming the flag and what it needs, before anything is written."""
    out = ["--out", files.out] if argv[0] != "relay" else []
    _refused(capsys, [a.replace("{m}", str(files.mission)) for a in argv] + out, names)
    assert not files.out.exists()


def test_a_link_key_that_needs_what_nobody_gives_is_refused(files, capsys):
    """A key of a mission's ``[link]``, a profile's or a handover's that acts only with another the table never
    gives (burst_len without loss_pct, queue_ms without rate_bps, trace_loop without trace; the same rule as the
    flags'), refused naming the file and the key; given as 0 (the loss switched off, the burst kept: a run's
    mission.toml after ``--loss 0``), or given by a flag or a swept axis, it is taken."""
    def mission(name: str, text: str) -> Path:
        p = files.root / name
        p.write_text(TINY + text)
        return p

    out = ["--out", files.out, "--no-plots"]
    burst = mission("burst.toml", "[link]\nburst_len = 3\n")
    line = _refused(capsys, ["sim", burst, *out], f"{burst}: link.burst_len")
    assert line.endswith("changes nothing: it sets the mean length of the loss bursts, and no loss_pct is given; give "
                         "loss_pct too, or remove burst_len"), line
    _refused(capsys, ["sitl", mission("q.toml", "[link.up]\nqueue_ms = 300\n"), *out], "q.toml: link.up.queue_ms")
    _refused(capsys, ["sim", mission("l.toml", "[link]\ntrace_loop = true\n"), *out], "l.toml: link.trace_loop")
    profile = files.root / "p.toml"
    profile.write_text('name = "p"\n[link]\ndelay_ms = 5\nburst_len = 2\n')
    _refused(capsys, ["sim", mission("pm.toml", '[link]\nprofile = "p.toml"\nloss_pct = 3\n'), *out],
             f"{profile}: link.burst_len: changes nothing")  # a profile describes one link: alone
    _refused(capsys, ["sim", mission("e.toml", '[[events]]\nt_s = 0.1\nkind = "link"\nburst_len = 3\n'), *out],
             "events (t_s = 0.1, kind = link): link.burst_len: changes nothing")
    _refused(capsys, ["sweep", burst, "--delay", "0,5", *out], f"{burst}: link.burst_len")
    assert not files.out.exists()
    for argv in (["sim", mission("b0.toml", "[link]\nburst_len = 3\nloss_pct = 0\n")], ["sim", burst, "--loss", "2"],
                 ["sim", burst, "--up-loss", "2"], ["sweep", burst, "--loss", "0,10"],
                 ["sim", files.mission, "--burst", "3", "--up-loss", "2"],
                 ["sweep", files.mission, "--loss", "0,10", "--burst", "3"]):
        with _guard():
            assert main([str(a) for a in [*argv, "--out", files.root / "ok", "--no-plots", "--overwrite"]]) == 0, argv
    capsys.readouterr()


@pytest.mark.parametrize("argv, names", [
    (["sim", ""], "the mission: an empty path"), (["sitl", ""], "the mission: an empty path"),
    (["vehicle", ""], "the mission: an empty path"), (["sweep", ""], "the mission: an empty path"),
    (["margin", "", "--over", "delay_ms"], "the mission: an empty path"), (["report", ""], "the sweep directory"),
    (["link", "fit", ""], "the trace: an empty path"), (["link", "extract", ""], "a source: an empty path"),
    (["vehicle", "--listen", ""], "--listen ''"), (["vehicle", "--gcs", ""], "--gcs ''"),
    (["controller", "missions/sine.toml", "--vehicle", ""], "--vehicle ''"),
    (["sim", "missions/sine.toml", "--vehicles", "2", "--formation", ""], "--formation"),
    (["sim", "missions/sine.toml", "--wind", "5:"], "--wind"),
    (["controller", "missions/sine.toml", "--radio-user", "2"], "--radio-user without --radio"),  # (it was taken)
    (["vehicle", "--trace-cap"], "--trace-cap: only with --await-mission"),  # (it would cap nothing)
    (["vehicle", "--param-at", "5:COM_OF_LOSS_T=1"], "--param-at: only with --await-mission"),  # (checks nothing)
    (["relay", "--listen", "127.0.0.1:0", "--to", "127.0.0.1:9", "--radio-user", "1", "--duration", "0.2"],
     "--radio-user without"),  # (a --duration: taken, as it once was, it relays briefly and exits 0, failing here)
    (["relay", "--listen", "0.0.0.0:31032", "--to", "localhost:31032", "--duration", "0.2"],  # (it relayed, exit 0)
     "--to localhost:31032 is the relay's own --listen 0.0.0.0:31032: it would forward into itself")])
def test_an_empty_path_address_or_value_is_refused_as_given(capsys, argv, names):
    """An empty positional path (an unset shell variable) is named as empty; it read as the current folder (".: is
    a directory"). An empty address is refused; it was taken for the default one, and the vehicle started. So are
    an empty ``--formation`` (it flew line:2) and ``--wind 5:``'s empty FROM (it flew from 0 deg)."""
    _refused(capsys, argv, names)


def test_a_link_refused_without_a_file_names_no_file(files, capsys):
    """A link refused where no file was given (``bsst relay`` without ``--mission``): every value is the command
    line's, and the message says so; until the third wave's thirty-third session it went on "(the file's [link]
    with these laid over it: ...)", of a file there was not."""
    trace = files.root / "short.csv"
    trace.write_text("t_s,delay_ms\n0,10\n0.01,10\n")  # 0.02 s, shorter than the relay's --duration 0.1
    line = _refused(capsys, ["relay", *BASE["relay"](files), "--link-trace", trace], "link.up.trace")
    assert line.startswith("bsst: command line: ") and "file's" not in line and "laid over" not in line, line


def test_a_refused_path_that_begins_with_bsst_follows_bsst_colon(files, capsys, monkeypatch):
    """``bsst sim bsstm.toml`` of a missing file printed ``bsstm.toml: no such file``, without ``bsst: ``, until the
    third wave's forty-fourth session: ``bsst``'s main told a refusal that opens with its own command (``bsst link
    extract: ...``) by its text's opening "bsst"; now by its typed source (params.ConfigError.source)."""
    monkeypatch.chdir(files.root)
    assert _refused(capsys, ["sim", "bsstm.toml"], "bsstm.toml") == "bsst: bsstm.toml: no such file"
    assert _refused(capsys, ["link", "extract", "bsstdir"], "bsstdir") == (  # (one that opens with its command: kept)
        "bsst link extract: bsstdir: no such file or directory; give a real-time run directory, or the vehicle's tlog "
        "and the controller's tlog")


@pytest.mark.skipif(os.geteuid() == 0, reason="root reads a file of mode 000 (the socket-path cases cover it)")
def test_a_file_without_read_permission(files, capsys):
    files.regular.write_text(TINY)
    files.regular.chmod(0)
    _refused(capsys, ["sim", files.regular, "--out", files.out], str(files.regular))


@pytest.mark.parametrize("argv, names", [
    (["sim", "missions/sine.toml", "--rate", "fast"], "--rate"),
    (["sitl", "missions/nowhere.toml"], "nowhere.toml"),
    (["vehicle", "--key", "/nonexistent/key"], "--key"),
    (["controller", "missions/sine.toml", "--key", "/nonexistent/key"], "--key"),
    (["relay", "--listen", "127.0.0.1:0", "--to", "nowhere"], "--to"),
    (["sweep", "missions/sine.toml", "--delay", "-5"], "--delay"),
    (["sweep", "missions/sine.toml", "--delay", "0,10", "--link-trace", "examples/link-trace.csv"],
     "bsst sweep: --delay with --link-trace: the trace gives the link's delay_ms"),  # not a cell's clash
    (["report", "/nonexistent/sweep"], "/nonexistent/sweep"),
])
def test_as_a_real_process_one_line_and_no_traceback(argv, names):
    r = run_bsst(*argv, cwd=ROOT, timeout=60)
    assert r.returncode == 2, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and names in r.stderr and "Traceback" not in r.stderr


# -- issue 11: files that cannot be read as they claim, missions that cannot be flown -------------------
def _bad_files_of_issue_11(root: Path) -> dict[str, Path]:
    def mission(name: str, text: str) -> Path:
        p = root / f"{name}.toml"
        p.write_text(text)
        return p

    def plan(name: str, old: str, new: str) -> Path:
        p = root / f"{name}.plan"
        p.write_text((ROOT / "examples" / "box.plan").read_text().replace(old, new))
        return p

    def profile(name: str, old: str, new: str) -> Path:
        p = root / f"{name}.toml"
        p.write_text((ROOT / "plant" / "profiles" / "paper.toml").read_text().replace(old, new))
        return p

    fifo = root / "fifo.toml"
    os.mkfifo(fifo)  # nobody writes it: opening it to read would wait for ever
    return {
        "escape": mission("escape", 'name = "../../escape"\n' + TINY.split("\n", 1)[1]),
        "newline": mission("newline", 'name = "two\\nlines"\n' + TINY.split("\n", 1)[1]),
        "fifo": fifo,
        "deep_array": mission("deep_array", TINY + "x = " + "[" * 5000 + "]" * 5000 + "\n"),
        "deep_keys": mission("deep_keys", "wind." + ".".join(["a"] * 3000) + " = 1\n" + TINY),
        "far": mission("far", 'name = "far"\nduration_s = 30.0\n[trajectory]\nkind = "step"\n'
                              "setpoints = [{ t = 0.0, x = 150.0, y = 0.0, z = 2.0 }]\n"),
        "day": mission("day", 'name = "day"\nduration_s = 86400.0\n[trajectory]\nkind = "sine"\nclimb = 0.0\n'),
        # over Python's 4300 digits (tomllib's, json's int()); past the float range; a key with a newline
        "digits": mission("digits", "seed = " + "1" * 5001 + "\n" + TINY),
        "huge": mission("huge", TINY.replace("duration_s = 0.2", f"duration_s = {HUGE}")),
        "sysid": mission("sysid", TINY + f"[params]\nMAV_SYS_ID = {HUGE}\n"),
        "gust": mission("gust", TINY + f"[wind]\ngusts = [[{HUGE}, 1, 1]]\n"),
        "blackout": mission("blackout", TINY + f"[link]\nblackouts = [[{HUGE}, 1]]\n"),
        "key_newline": mission("key_newline", TINY + '[params]\n"COM_OF_LOSS_T\\nX" = 1\n'),
        "path_newline": mission("path_newline", 'name = "p"\n[trajectory]\nkind = "plan"\nfile = "a\\nb.plan"\n'),
        "plan_digits": plan("plan_digits", '"cruiseSpeed": 15', '"cruiseSpeed": ' + "1" * 5001),
        "plan_inf": plan("plan_inf", '"hoverSpeed": 5', '"hoverSpeed": Infinity'),
        "profile": profile("profile", "omega_max = 1.5", "omega_max = 1e200"),
    }


ISSUE_11_CASES = [
    (["sim", "{escape}", "--no-plots"], ["name: must not contain /", "escape.toml"]),
    (["sitl", "{escape}", "--no-plots", "--gcs", "none"], ["name: must not contain /"]),
    (["sweep", "{escape}", "--jobs", "1", "--no-plots"], ["name: must not contain /"]),
    (["sim", "{newline}", "--no-plots"], ["name: must be printable"]),
    (["sim", "{fifo}"], ["fifo.toml: is a FIFO (named pipe), expected a TOML file"]),
    (["sweep", "{fifo}", "--jobs", "1"], ["fifo.toml: is a FIFO"]),
    (["relay", "--listen", "127.0.0.1:0", "--to", "127.0.0.1:9", "--mission", "{fifo}"], ["fifo.toml: is a FIFO"]),
    (["sim", "{deep_array}"], ["deep_array.toml: nested too deeply"]),
    (["sim", "{deep_keys}"], ["deep_keys.toml: wind: nested more than 32 levels deep"]),
    (["sim", "{far}", "--no-plots"], ["trajectory.setpoints[0]", "envelope of 100 m"]),
    (["sim", "{day}", "--no-plots"], ["day.toml: duration_s", "21600000 control steps", "over the 500000"]),
    (["sitl", "{day}", "--no-plots", "--gcs", "none"], ["duration_s", "over the 500000"]),
    (["sim", str(ROOT / "missions" / "sine.toml"), "--blackout", "40:1"],
     ["--blackout/--up-blackout (link.up.blackouts): the window [40, 41) s starts after the mission's end "
      "(duration_s = 30 s)"]),
    (["sim", "{digits}"], ["digits.toml: not valid TOML (line 1: an integer of 5001 digits, over the 4300 Python "
                           "reads)"]),
    (["sim", "{huge}"], ["huge.toml: duration_s: must be in (0, 86400], got an integer of 401 digits"]),
    (["sim", "{sysid}"], ["sysid.toml: params.MAV_SYS_ID: must be in [1, 254], got an integer of 401 digits"]),
    (["sim", "{gust}"], ["gust.toml: wind.gusts[0]: expected [t_s, duration_s, amplitude_mps] or [t_s, duration_s, "
                        "amplitude_mps, from_deg]"]),
    (["sim", "{blackout}"], ["blackout.toml: link.blackouts: element 0 must be a pair"]),
    (["sim", "{key_newline}"], ["key_newline.toml: 'params.COM_OF_LOSS_T\\nX': no such parameter"]),
    (["sim", "{path_newline}"], ["a\\nb.plan': no such file"]),
    (["sim", "{plan_digits}"], ["plan_digits.plan: not a QGroundControl plan (not valid JSON: line 10: an integer "
                                "of 5001 digits"]),
    (["sim", "{plan_inf}"], ["plan_inf.plan: mission.hoverSpeed: must be a finite number or null, got inf"]),
    (["sim", str(ROOT / "missions" / "sine.toml"), "--profile", "{profile}"],
     ["profile.toml: omega_max: must be in (0, 10000], got 1e+200"]),
]


@pytest.mark.parametrize("argv, words", ISSUE_11_CASES, ids=[" ".join(a[:2]) + f" {i}"
                                                            for i, (a, _) in enumerate(ISSUE_11_CASES)])
def test_issue_11_files_and_missions_exit_2_with_one_line(tmp_path: Path, argv: list[str], words: list[str]) -> None:
    """As a real process, in a fresh working directory: exit 2 within the deadline (a FIFO is never
    opened to wait on), one line naming the file and key, no traceback, and no directory made."""
    work = tmp_path / "work"
    work.mkdir()
    files = _bad_files_of_issue_11(tmp_path)
    cmd = [a.format(**files) for a in argv]
    r = run_bsst(*cmd, cwd=work, timeout=60)
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2, (cmd, r.returncode, r.stderr)
    assert len(lines) == 1 and lines[0].startswith("bsst: ") and "Traceback" not in r.stderr, r.stderr
    assert all(w in lines[0] for w in words), lines[0]
    assert not any(work.iterdir()), sorted(work.rglob("*"))  # no runs/ or sweeps/ directory, nothing inside
    assert not list(tmp_path.parent.glob("*escape*")) and not list(tmp_path.glob("*escape*/"))


def test_the_vehicle_at_rest_is_not_capped() -> None:
    """The 24 h at-rest mission of a bare ``bsst vehicle`` (rows streamed to disk) prepares as before:
    the trace cap is only where a run keeps its trace (bsst sim, sitl, sweep)."""
    from bridge.core.flight import at_rest  # local: only this test builds the at-rest mission
    from bridge.record.runlog import MAX_TRACE_STEPS  # local: as above

    flight = prepare(at_rest())
    assert flight.mission.steps == 86400 * 250 > MAX_TRACE_STEPS


# -- issue 22, defect 7: a trace file the csv module cannot read, through every path that reads a trace ----------
BAD_TRACES = {  # name: (the file's text, its line named, what the line says)
    "unclosed quote": ('t_s,delay_ms\n0,5\n0.1,"10\n0.2,5\n', "line 3", "unclosed quote"),
    "quoted newline": ('t_s,delay_ms\n0,5\n0.1,"10\n12",3\n0.3,5\n', "line 3", "unclosed quote"),
    "over the field limit": ("t_s,delay_ms\n0,5\n0.1," + "1" * 200_000 + "\n", "line 3", "characters long"),
    "quoted over the field limit": ('t_s,delay_ms\n0,5\n0.1,"' + "1" * 200_000 + '"\n', "line 3", "characters long"),
}


@pytest.mark.parametrize("kind", BAD_TRACES)
def test_issue_22_a_bad_trace_is_one_line_through_every_path(tmp_path: Path, kind: str) -> None:
    """``--link-trace``, ``[link] trace`` in a mission, a link profile's trace, ``bsst relay --link-trace``,
    ``bsst link fit`` and ``bsst link show``: each a real process, exit 2, one line naming the file and its line."""
    text, line, why = BAD_TRACES[kind]
    bad = tmp_path / "bad.csv"
    bad.write_text(text)
    mission = tmp_path / "m.toml"
    mission.write_text(TINY + '[link]\ntrace = "bad.csv"\ntrace_loop = true\n')
    profile = tmp_path / "p.toml"
    profile.write_text('name = "p"\n[link]\ntrace = "bad.csv"\ntrace_loop = true\n')
    paths = {
        "--link-trace": ["sim", str(MISSION_DIR / "sine.toml"), "--link-trace", str(bad), "--link-trace-loop"],
        "[link] trace": ["sim", str(mission)],
        "a profile's trace": ["sim", str(MISSION_DIR / "sine.toml"), "--link-profile", str(profile)],
        "relay --link-trace": ["relay", "--listen", "127.0.0.1:0", "--to", "127.0.0.1:9", "--link-trace", str(bad),
                               "--link-trace-loop", "--duration", "1"],
        "link fit": ["link", "fit", str(bad)],
        "link show": ["link", "show", str(bad), "--out", str(tmp_path / "bad.png")],
    }
    for name, argv in paths.items():
        r = run_bsst(*argv, cwd=tmp_path, timeout=60)
        lines = r.stderr.strip().splitlines()
        assert r.returncode == 2, (name, r.returncode, r.stderr[-2000:])
        assert len(lines) == 1 and "Traceback" not in r.stderr, (name, r.stderr[-2000:])
        assert f"{bad} {line}: " in lines[0] and why in lines[0], (name, lines[0])
        assert len(lines[0]) < 600, (name, len(lines[0]))  # the line says what is wrong, not the field
    assert not (tmp_path / "runs").exists() and not (tmp_path / "bad.png").exists()


# -- issue 23 (defect 7): misspellings get the likely word; each command has only the flags it uses ---------
def _bsst(*argv: Any, cwd: Path = ROOT) -> subprocess.CompletedProcess[str]:
    return run_bsst(*map(str, argv), cwd=cwd, timeout=120)


def _one_line(r: subprocess.CompletedProcess[str]) -> str:
    assert r.returncode == 2, f"exit {r.returncode}: {r.stderr}"
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    return lines[0]


def test_a_misspelled_required_key_is_an_unknown_key_with_the_likely_one(tmp_path: Path) -> None:
    mission = tmp_path / "typo.toml"
    mission.write_text(TINY.replace("duration_s", "duraton_s"))
    line = _one_line(_bsst("sim", mission, "--out", tmp_path / "out", "--no-plots"))
    assert line == f"bsst: {mission}: duraton_s: unknown key at the top level; did you mean 'duration_s'?"
    mission.write_text(TINY + "[link.up]\ndelya_ms = 10\n")
    line = _one_line(_bsst("sim", mission, "--out", tmp_path / "out", "--no-plots"))
    assert line == f"bsst: {mission}: link.up.delya_ms: unknown key in [link.up]; did you mean 'delay_ms'?"
    mission.write_text(TINY + "[seperation]\nminimum_m = 1\n")  # an optional table the mission does not hold
    line = _one_line(_bsst("sim", mission, "--out", tmp_path / "out", "--no-plots"))
    assert line == f"bsst: {mission}: seperation: unknown key at the top level; did you mean 'separation'?"


def _renamed(data: dict[str, Any], dotted: str, slip: Any) -> dict[str, Any] | None:
    """A deep copy of ``data`` with the key ``dotted`` (``a.b[0].c``) renamed to ``slip(name)`` (None: not there)."""
    import copy  # only this helper copies

    out = copy.deepcopy(data)
    node: Any = out
    *path, last = dotted.split(".")
    for part in path:
        name, _, idx = part.partition("[")
        if not isinstance(node, dict) or name not in node:
            return None
        node = node[name][int(idx.rstrip("]"))] if idx else node[name]
    if not isinstance(node, dict) or last not in node:
        return None
    node[slip(last)] = node.pop(last)
    return out


SLIPS = {"doubled first letter": lambda k: k[0] + k,
         "last letter dropped": lambda k: k[:-1] if len(k) > 3 else k + k[-1]}


@pytest.mark.parametrize("slip", SLIPS)
def test_every_mission_key_misspelled_is_named_with_the_likely_one(slip: str) -> None:
    """Every key of every table the validators read (required or not, tables too), misspelled: the error is the
    unknown key, in its table, with the key it most likely meant, whatever else its absence would break."""
    typo = SLIPS[slip]
    seen = 0
    for ctl in ("bsst", "smc", "pid"):
        data = _full_mission(ctl)
        for key in _keys_asked(data, "<walk>"):
            bad = _renamed(data, key, typo)
            if bad is None:  # a key the walk asked for and the mission leaves to its default
                continue
            seen += 1
            table, _, name = key.rpartition(".")
            with pytest.raises(ConfigError) as exc:
                prepare(mission_from_table(bad, "<walk>"))
            where = f"in [{table}]" if table else "at the top level"
            want = f"<walk>: {table + '.' if table else ''}{typo(name)}: unknown key {where}; did you mean {name!r}?"
            assert str(exc.value) == want
    assert seen > 60


UNKNOWN_KEYS = [  # (the file's text, the line's end after the file): what a key that is no slip of one is told
    ("foo = 1\n" + TINY, "foo: unknown key at the top level; allowed: name, trajectory, duration_s, profile, "
     "actuation, controller, ... (25 keys)"),
    (TINY + "[wind]\ndirection = 90\n", "wind.direction: unknown key in [wind]; allowed: speed_mps, from_deg, "
     "turbulence, turbulence_scaling, altitude_m, gusts"),
    (TINY + "[failsafe]\nmode = 1\n", "failsafe.mode: unknown key in [failsafe]; allowed: timeout_s, "
     "descent_rate, resume, action, hold_s"),
    (TINY + "[[vehicles]]\nid = 1\n[[vehicles]]\nid = 2\nsysid = 7\n", "vehicles[1].sysid: unknown key in "
     "[vehicles[1]]; allowed: id, trajectory, offset, start, profile, controller"),
    (TINY.replace('"sine"', '"waypoints"\npoints = [{t = 0, x = 0, y = 0, z = 0}, {t = 0.1, x = 0, y = 0, z = 1, '
                  'yaw = 1}]'), "trajectory.points[1].yaw: unknown key in [trajectory.points[1]]; allowed: t, x, y, z, "
     "psi"),
    (TINY + "mpc_acc_hor = 2.0\n", "trajectory.mpc_acc_hor: unknown key in [trajectory] (a PX4 limit of a plan's "
     'trajectory: put it in a [trajectory] of kind = "plan" as MPC_ACC_HOR)'),
    (TINY + "[failsafe]\ncom_of_loss_t = 2\n", "failsafe.com_of_loss_t: unknown key in [failsafe] (a PX4 "
     "parameter: put it in [params] as COM_OF_LOSS_T)"),
    (TINY + "[link]\nGF_ACTION = 2\n", "link.GF_ACTION: unknown key in [link] (a PX4 parameter: put it in [params] as "
     "GF_ACTION)"),
    (TINY.replace('"sine"', '"waypoints"\npoints = [{t = 0, x = 0, y = 0, z = 0}, {t_s = 0.1, x = 0, y = 0, z = 1}]'),
     "trajectory.points[1].t_s: unknown key in [trajectory.points[1]]; did you mean 't'?"),
]


@pytest.mark.parametrize("text, said", UNKNOWN_KEYS, ids=[s.split(":")[0] for _, s in UNKNOWN_KEYS])
def test_an_unknown_key_with_no_likely_one_is_told_what_its_table_takes(tmp_path, capsys, text, said):
    """The table's keys (all, or of a long table the closest or first few), where a PX4 parameter goes in
    any case, and a point's ``t_s`` before the ``t`` it leaves out (it said ``t: is required``): until the third
    wave's fortieth session such a line ended at ``unknown key in [wind]``."""
    mission = tmp_path / "m.toml"
    mission.write_text(text)
    line = _refused(capsys, ["sim", mission, "--out", tmp_path / "out", "--no-plots"], "unknown key")
    assert line == f"bsst: {mission}: {said}"


def test_a_key_of_a_plans_trajectory_in_the_wrong_case_is_the_likely_one(tmp_path, capsys):
    plan = ROOT / "examples" / "box.plan"
    mission = tmp_path / "m.toml"
    mission.write_text(f'name = "box"\n[trajectory]\nkind = "plan"\nfile = "{plan}"\nmpc_acc_hor = 2.0\n')
    line = _refused(capsys, ["sim", mission, "--out", tmp_path / "out", "--no-plots"], "unknown key")
    assert line == f"bsst: {mission}: trajectory.mpc_acc_hor: unknown key in [trajectory]; did you mean 'MPC_ACC_HOR'?"


def test_the_px4_names_an_unknown_key_is_told_of_are_the_vehicles_and_a_plans() -> None:
    """params.px4 holds the names apart (params imports nothing above it): they are the vehicle's parameters
    and a plan's limits, each where it goes."""
    assert set(PX4_NAMES) == set(BY_NAME) | set(LIMIT_RANGES)
    assert {n for n, where in PX4_NAMES.items() if "[params]" in where} == set(BY_NAME)
    assert {n for n, where in PX4_NAMES.items() if "[trajectory]" in where} == set(LIMIT_RANGES) - set(BY_NAME)


def test_every_mission_key_replaced_by_a_stranger_is_told_its_tables_keys() -> None:
    """Every key of every table the validators read, renamed to one like none of them: where the line is the
    unknown key's, it names the key it replaced among those its table takes (or says how many)."""
    seen = 0
    for ctl in ("bsst", "smc", "pid"):
        data = _full_mission(ctl)
        for key in _keys_asked(data, "<walk>"):
            bad = _renamed(data, key, lambda _: "qqqq")
            if bad is None:
                continue
            table, _, name = key.rpartition(".")
            with pytest.raises(ConfigError) as exc:
                prepare(mission_from_table(bad, "<walk>"))
            where = f"in [{table}]" if table else "at the top level"
            head = f"<walk>: {table + '.' if table else ''}qqqq: unknown key {where}; allowed: "
            if not str(exc.value).startswith(head):  # a required key's absence said first ("kind: is required")
                assert str(exc.value).endswith("is required"), str(exc.value)
                continue
            seen += 1
            allowed = str(exc.value).removeprefix(head)
            assert name in allowed.split(", ") or allowed.endswith(" keys)"), str(exc.value)
    assert seen > 60


@pytest.mark.parametrize("cmd", ["sim", "sitl"])
def test_a_duration_flag_says_the_mission_file_sets_it(files, capsys, cmd):
    """``bsst sim m.toml --duration 5`` offered ``--formation`` until the third wave's fortieth session."""
    line = _refused(capsys, [cmd, files.mission, "--duration", "5"], "--duration")
    assert line == (f"bsst {cmd}: unrecognized arguments: --duration 5; bsst {cmd} has no --duration flag: the "
                    "mission file's duration_s sets it"), line


def test_a_misspelled_flag_gets_the_likely_one() -> None:
    line = _one_line(_bsst("sim", "missions/sine.toml", "--dealy", "5"))
    assert line == "bsst sim: unrecognized arguments: --dealy 5; did you mean --delay?"
    line = _one_line(_bsst("link", "fit", "examples/link-trace.csv", "--outt", "x"))
    assert line == "bsst link fit: unrecognized arguments: --outt x; did you mean --out?"


@pytest.mark.parametrize("cmd", sorted(set(BASE) - {"link"}))  # link's actions: the test above
def test_every_flag_misspelled_names_itself(files: Files, capsys: Any, cmd: str) -> None:
    """Each flag of each command with two neighbouring letters swapped: refused, the command's own flag suggested."""
    flags = [f for a in _commands()[cmd]._actions for f in a.option_strings if len(f) >= 6]
    suggested = 0
    for flag in flags:
        slip = flag[:3] + flag[4] + flag[3] + flag[5:]
        if (slip == flag or any(slip == f or f.startswith(slip) for f in flags)  # the same, or still a flag's prefix
                or sum(is_typo_of(slip, f) for f in flags) > 1):  # as near another flag (--seped: --seed, --speed)
            continue
        with _guard():
            rc = main([cmd, *map(str, BASE[cmd](files)), slip, "1"])
        err = capsys.readouterr().err.strip().splitlines()
        assert rc == 2 and len(err) == 1, err
        if "unrecognized arguments" in err[0]:
            assert err[0].endswith(f"; did you mean {flag}?"), err[0]
            suggested += 1
    assert suggested >= 1


@functools.cache
def _whole_parser() -> argparse.ArgumentParser:
    return build_parser()


@pytest.mark.parametrize("cmd", sorted(set(BASE) - {"link", "report"}))  # (report takes no value of a flag)
def test_a_value_that_starts_with_a_minus_and_a_digit_is_the_flags_value(files: Files, cmd: str) -> None:
    """Every flag that takes one value takes ``-1``, ``-1:wind:3``, ``-33.9,151.2,20``, ``-.5:gps:off``, ``-inf`` or
    ``-nan:gps:off`` as it (argparse alone
    takes only a plain negative number so, and refused the rest as the flag's missing value: "expected one
    argument"): the flag's own check accepts or names it."""
    parser = _whole_parser()
    flags = [a.option_strings[0] for a in _commands()[cmd]._actions if a.option_strings and a.nargs is None]
    assert len(flags) >= 3
    for flag in flags:
        for value in ("-1", "-1:wind:3", "-33.9,151.2,20", "-.5:gps:off", "-inf", "-nan:gps:off"):
            try:
                parser.parse_args([cmd, *map(str, BASE[cmd](files)), flag, value])
            except (UsageError, ConfigError) as exc:  # (a flag type's refusal is a ConfigError, typed)
                assert "expected one argument" not in str(exc) and flag in str(exc), (flag, value, str(exc))
    with pytest.raises(UsageError, match="--at: expected one argument"):  # a flag is still a flag
        parser.parse_args(["sim", "missions/sine.toml", "--at", "--no-plots"])


def test_a_negative_event_time_and_a_southern_home_as_separate_words(files: Files, capsys: Any) -> None:
    """``--at -1:wind:3`` is refused as ``--at=-1:wind:3`` is, naming the flag and the time; ``--home`` south of
    the equator is taken."""
    for at in (["--at", "-1:wind:3"], ["--at=-1:wind:3"]):
        line = _refused(capsys, ["sim", *BASE["sim"](files), *at], "--at")
        assert line == "bsst: --at -1:wind:3: t_s: must be in [0, 0.2) s (before the mission's end), got -1", line
    line = _refused(capsys, ["sim", *BASE["sim"](files), "--at", "-.5:wind:3"], "--at")
    assert line == "bsst: --at -.5:wind:3: t_s: must be in [0, 0.2) s (before the mission's end), got -0.5", line
    line = _refused(capsys, ["sim", *BASE["sim"](files), "--at", "-inf:wind:3"], "--at")
    assert line == "bsst: --at -inf:wind:3: t_s: must be finite, got -inf", line
    home = _whole_parser().parse_args(["vehicle", "--home", "-33.86,151.21,20"]).home
    assert home == (-33.86, 151.21, 20.0)


def test_bsst_controller_has_no_run_directory_nor_plots(tmp_path: Path) -> None:
    """The controller alone writes its two files only into --out, and plots nothing: its help says so, and
    --no-plots is no flag of it."""
    p = _commands()["controller"]
    flags = {f: a for a in p._actions for f in a.option_strings}
    assert "--no-plots" not in flags
    assert "runs/" not in flags["--out"].help and "controller.tlog" in flags["--out"].help
    line = _one_line(_bsst("controller", "missions/sine.toml", "--no-plots"))
    assert line == "bsst controller: unrecognized arguments: --no-plots"
    r = _bsst("controller", ROOT / "missions" / "sine.toml", "--vehicle", "127.0.0.1:9", "--timeout", "0.2",
              cwd=tmp_path)
    assert r.returncode == 1, r.stderr
    assert list(tmp_path.iterdir()) == [], "bsst controller without --out wrote into the working directory"


CONTROLLER_ONLY = {"--compensation": "predict", "--command-lag": "5", "--stale-after": "50", "--stop-after": "100"}


def test_bsst_relay_takes_no_controller_flag() -> None:
    relay = {f for a in _commands()["relay"]._actions for f in a.option_strings}
    assert not relay & set(CONTROLLER_ONLY)
    assert set(CONTROLLER_ONLY) <= {f for a in _commands()["sitl"]._actions for f in a.option_strings}
    for flag, value in CONTROLLER_ONLY.items():
        line = _one_line(_bsst("relay", "--listen", "127.0.0.1:0", "--to", "127.0.0.1:9", flag, value))
        assert line.startswith(f"bsst relay: unrecognized arguments: {flag} {value}"), line


@pytest.mark.parametrize("cmd", ["sim", "sweep", "margin"])
def test_an_empty_out_is_refused_not_taken_for_the_current_folder(tmp_path: Path, cmd: str) -> None:
    """``--out "$DIR"`` with DIR unset: it flew into the current folder (and ``--overwrite`` would have replaced
    run files there); now one line, exit 2, nothing written."""
    (tmp_path / "m.toml").write_text(TINY)
    work = tmp_path / "work"
    work.mkdir()
    extra = {"sim": [], "sweep": ["--delay", "0,1"], "margin": ["--over", "delay_ms", "--until", "rms=1"]}[cmd]
    r = run_bsst(cmd, tmp_path / "m.toml", *extra, "--out", "", "--no-plots" if cmd == "sim" else "--jobs=1",
                 cwd=work, timeout=120)
    assert r.returncode == 2 and "--out: an empty path" in r.stderr and "Traceback" not in r.stderr, r.stderr
    assert list(work.iterdir()) == []


@pytest.mark.parametrize("argv, names", [
    (["sim", "missions/sine.toml", "--delay", "1_0"], "--delay must be a number in [0, 60000] ms, got '1_0'"),
    (["sim", "missions/sine.toml", "--seed", "1_0"], "--seed must be an integer, got '1_0'"),
    (["sim", "missions/sine.toml", "--wind", "1_0"], "--wind"),
    (["sim", "missions/sine.toml", "--blackout", "1_0:1"], "--blackout"),
    (["sim", "missions/sine.toml", "--at", "1_0:gps:off"], "--at 1_0:gps:off"),
    (["sim", "missions/sine.toml", "--param", "COM_OBL_ACT=1_0"], "COM_OBL_ACT: an INT32, expected an integer"),
    (["sweep", "missions/sine.toml", "--delay", "0,1_0"], "--delay takes numbers separated by commas, got '0,1_0'"),
    (["vehicle", "--home", "4_7,8,400"], "--home must be LAT,LON,ALT"),
    (["vehicle", "--controller-id", "2_00:19"], "--controller-id must be SYSID:COMPID"),
    (["margin", "missions/sine.toml", "--over", "delay_ms", "--until", "rms=0.1_0"], "--until rms=X"),
])
def test_a_number_with_digit_separators_is_refused(capsys, argv, names) -> None:
    """``1_0`` is 10 to Python's ``float()`` and ``int()``, and a slip to a person: refused, as any text that is
    not a number (it flew 10). (A TOML file's ``1_000`` is TOML's own number syntax, and stays.)"""
    _refused(capsys, [*argv, "--out", "/nonexistent-never-written"], names)


@pytest.mark.parametrize("argv, line", [
    (["sim", "{m}", "--vehicles", "0"], "bsst: --vehicles must be in [1, 64], got 0"),
    (["sim", "{m}", "--rate", "x"], "bsst: --rate must be a number in [50, 1000], got 'x'"),
    (["sim", "{m}", "--wind", "x"], "bsst: --wind: expected SPEED[:FROM_DEG] (m/s, compass degrees), got 'x'"),
    (["sim", "{m}", "--discretization", "foo"],
     "bsst: --discretization: invalid choice: 'foo' (choose from 'explicit', 'implicit')"),
    (["sitl", "{m}", "--out", ""], "bsst: --out: an empty path (give one, or leave the flag out)"),
    (["sweep", "{m}", "--vehicles", "x"], "bsst: --vehicles takes numbers separated by commas, got 'x'"),
    (["margin", "{m}", "--over", "delay_ms", "--jobs", "0"], "bsst: --jobs must be in [1, 1024], got 0"),
    (["vehicle", "--home", "1"], "bsst: --home must be LAT,LON,ALT in degrees and metres, got '1'"),
    (["controller", "{m}", "--sysid", "0"], "bsst: --sysid must be in [1, 254], got 0"),
    (["relay", "--stats", "", "--listen", "127.0.0.1:1", "--to", "127.0.0.1:2"],
     "bsst: --stats: an empty path (give one, or leave the flag out)"),
    (["link", "fit", ""], "bsst: the trace: an empty path (give one)"),
    (["link", "nope"], "bsst link: ACTION: invalid choice: 'nope' (choose from 'extract', 'fit', 'show')"),
    (["vehicle", "--realtime", "--lockstep"], "bsst: --lockstep: not allowed with --realtime: give one of them"),
    (["sweep", "{m}", "--offline", "--lockstep"], "bsst: --lockstep: not allowed with --offline: give one of them"),
    (["sim", "{m}", "--link-trace", ""], "bsst: --link-trace: an empty path (give one, or leave the flag out)"),
    (["relay", "--listen", "127.0.0.1:1", "--to", "127.0.0.1:2", "--up-link-trace", ""],
     "bsst: --up-link-trace: an empty path (give one, or leave the flag out)"),
])
def test_a_flags_bad_value_is_one_line_in_the_house_style(capsys, argv, line) -> None:
    """A value an argparse type refuses reads as bsst's own refusals do, ``bsst: --flag ...``, the flag named once,
    for every command; argparse's own words (an invalid choice, a missing value) follow the flag, or a positional's
    command. Until the third wave's fortieth session they read ``bsst sim: argument --vehicles: --vehicles must be
    ...``: the flag twice, behind the command's name; two flags of one group ``bsst: --lockstep: not allowed with
    argument --realtime``, and an empty trace ``bsst: --link-trace : is not a regular file`` (as --out's now)."""
    said = _refused(capsys, [a.format(m=MISSION_DIR / "sine.toml") for a in argv], "bsst")
    assert said == line and said.count(argv[-2]) <= 1, said


def test_a_trace_field_with_digit_separators_is_refused(tmp_path, capsys) -> None:
    trace = tmp_path / "t.csv"
    trace.write_text("t_s,delay_ms\n0,1_0\n0.1,10\n")
    _refused(capsys, ["sim", "missions/sine.toml", "--link-trace", trace, "--no-plots"],
             f"{trace} line 2: delay_ms is not a number: '1_0'")


@pytest.mark.parametrize("form", ["udpin:", "udp:"])
def test_a_fleet_given_a_bound_ground_station_address_is_refused_before_anything_starts(capsys, tmp_path, form) -> None:
    """Every vehicle of a SITL fleet sends to the one ``--gcs`` address, so a bound one (``udpin:``, ``udp:``)
    would be bound by each: until the third wave's fortieth session the first vehicle started, the run's files
    were written, and the second said ``cannot bind (Address already in use)``, its neighbour's port."""
    out = tmp_path / "fleet"
    line = _refused(capsys, ["sitl", "missions/sine.toml", "--vehicles", 2, "--gcs", f"{form}127.0.0.1:31999",
                             "--no-plots", "--out", out], "--gcs")
    assert "fleet" in line and "udpout" in line and not out.exists(), line


def test_every_flag_types_refusal_is_typed_the_flag_its_source(shared_files):
    """Every flag whose type checks its value (bridge.cli's types), given the walk's bad values: the refusal is a
    ConfigError whose ``source`` is the flag (with the value, for ``--param 'X=1': ...``) and ``what`` the bare reason,
    its message ``source what`` or ``source: what`` as it always read. Until the third wave's forty-fourth session each
    was a UsageError whose whole text was its ``what``, no source (``--rate 5``: source None)."""
    from bridge.cli import _parser  # (the parser bsst's main parses with, built once)

    typed = 0
    for cmd, flag in _flag_cases():
        action = next(a for a in _commands()[cmd]._actions if (a.option_strings[:1] or [a.dest]) == [flag])
        if not action.option_strings or not getattr(action.type, "__module__", "").startswith("bridge.cli"):
            continue
        for bad in _bad_values(cmd, action, shared_files):
            try:
                _parser().parse_args([str(a) for a in (cmd, *BASE[cmd](shared_files), flag, bad)])
            except ConfigError as e:
                assert e.source is not None and e.source.split(" ")[0] in action.option_strings, (cmd, flag, bad, e)
                assert str(e) in (f"{e.source} {e.what}", f"{e.source}: {e.what}") and e.key is None, (cmd, flag, e)
                typed += 1
            except UsageError as e:
                raise AssertionError(f"bsst {cmd} {flag} {bad!r}: refused untyped: {e}") from None
    assert typed > 100, typed
    # the flags checked once parsed (an address, a key file) alike: until the forty-fourth session each of these was
    # built by hand, source None (``--vehicle 127.0.0.1:x``: a bad_input report with source null, what null)
    from bridge.mavlink.endpoint import parse_address
    from bridge.mavlink.signing import key_from_file

    checks = [(flag, bad, functools.partial(parse_address, str(bad), "udpout", flag))
              for flag in ("--listen", "--gcs", "--vehicle", "--controller-from")
              for bad in TEXT_BAD[flag](shared_files)]
    checks += [("--key", bad, functools.partial(key_from_file, bad)) for bad in TEXT_BAD["--key"](shared_files)]
    refused = 0
    for flag, bad, check in checks:
        try:
            check()
        except ConfigError as e:
            assert e.source == f"{flag} {bad!r}" if flag != "--key" else e.source == f"{flag} {bad}", (flag, bad, e)
            assert str(e) == f"{e.source}: {e.what}" and e.key is None and e.what, (flag, bad, e)
            refused += 1
    assert refused >= 10, refused


def test_a_flags_range_refusal_says_the_flag_as_source_and_the_bare_reason(capsys):
    with pytest.raises(ConfigError) as refused:
        build_parser().parse_args(["sim", "missions/sine.toml", "--rate", "5"])
    e = refused.value
    assert (str(e), e.source, e.key, e.what) == ("--rate must be in [50, 1000], got 5", "--rate", None,
                                                 "must be in [50, 1000], got 5")
    assert main(["sim", "missions/sine.toml", "--rate", "5"]) == 2  # its line as it was
    assert capsys.readouterr().err == "bsst: --rate must be in [50, 1000], got 5\n"
