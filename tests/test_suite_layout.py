"""Covers tests, tests.waiting, tests.scheduling and tests.timeline: the suite's own layout and its timing.

- every ``tests/test_*.py`` opens with a docstring whose first line names what it covers:
  ``Covers bridge.link.model: ...`` (modules or packages of the project, each of which exists);
- a test module that starts processes or opens sockets says so with ``pytestmark = pytest.mark.process``
  (``make test-fast`` runs the others: ``pytest -m "not process"``); one without the marker neither
  imports what does (:data:`PROCESS_IMPORTS`, the kits ``tests/sitlkit.py`` and ``tests/hostile.py``,
  a marked test module) nor runs a ``bsst`` command that starts processes (:data:`PROCESS_COMMANDS`);
- :func:`tests.waiting.wait_for` waits, and fails naming what it waited for;
- the tests that share a module-scoped fixture are one unit of work for pytest-xdist
  (:func:`tests.scheduling.scope_of`), so that one worker makes the fixture once; every other test is a
  unit of its own; the cheap fixtures left out of it are module-scoped fixtures that exist; the groups a
  controller parsed are read, not parsed again, by its workers (:func:`tests.scheduling.write_groups`), unless
  the module changed since;
- :func:`tests.timeline.report` sums each file's wall and CPU time from the workers' lines, and with one worker
  ranks the tests by the machine's CPU time during each.

Checked with ``ast`` on each file's source, and shown failing on broken samples.
"""

from __future__ import annotations

import ast
import json
import os
import re
import time
from pathlib import Path

import pytest

from tests import scheduling
from tests.quietgc import collector_off
from tests.scheduling import CHEAP, is_marked_process, scope_of, shared_groups, write_groups
from tests.timeline import report
from tests.waiting import wait_for

ROOT = Path(__file__).resolve().parents[1]
TESTS = sorted((ROOT / "tests").glob("test_*.py"))
COVERS = re.compile(r"Covers (?P<names>[\w.]+(?:(?:, | and )[\w.]+)*)(?::|\.(?:\s|$))")
# what a module imports when it starts processes or opens sockets (a prefix of the imported module's name)
PROCESS_IMPORTS = ("socket", "subprocess", "select", "selectors", "multiprocessing", "concurrent.futures", "dask",
                   "mavsdk", "pymavlink.mavutil", "tests.sitlkit", "tests.hostile", "bridge.session",
                   "bridge.mavlink.endpoint", "bridge.nodes.relay", "bridge.sweep.executors")
# bsst commands that start processes (children, pools), whether run as a subprocess or through bridge.cli.main
PROCESS_COMMANDS = {"sitl", "vehicle", "controller", "relay", "sweep", "margin"}


def module_exists(name: str) -> bool:
    path = ROOT / name.replace(".", "/")
    return path.with_suffix(".py").is_file() or (path / "__init__.py").is_file()


def covers_problem(path: str, source: str, tree: ast.Module | None = None) -> str | None:
    """What is wrong with a test module's first docstring line (None: it names what it covers); ``tree``: the
    source parsed, if it is already."""
    doc = ast.get_docstring(tree or ast.parse(source))
    if not doc:
        return f"{path}:1: no module docstring"
    first = doc.splitlines()[0]
    m = COVERS.match(first)
    if not m:
        return f"{path}:1: the docstring's first line does not start 'Covers <module>[, <module> and <module>]: '"
    missing = [n for n in re.split(r", | and ", m["names"]) if not module_exists(n)]
    if missing:
        return f"{path}:1: covers {', '.join(missing)}, which is no module of the project"
    return None


def process_uses(path: str, tree: ast.Module, marked_modules: set[str]) -> list[str]:
    """Each import or command of a test module that starts processes or opens sockets, as file:line."""
    out = []
    for node in ast.walk(tree):
        names: list[str] = []
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module:
            names = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
        for name in names:
            if any(name == p or name.startswith(p + ".") for p in PROCESS_IMPORTS) or name in marked_modules:
                out.append(f"{path}:{node.lineno}: imports {name}")
                break
        if isinstance(node, (ast.List, ast.Tuple)) and node.elts:
            head = node.elts[0]
            if isinstance(head, ast.Constant) and head.value in PROCESS_COMMANDS and len(node.elts) > 1:
                out.append(f"{path}:{node.lineno}: runs `bsst {head.value}`")
        if isinstance(node, ast.Call) and any(isinstance(a, ast.Constant) and a.value in PROCESS_COMMANDS
                                              for a in node.args[:1]) and _called(node) in ("bsst", "run_bsst"):
            out.append(f"{path}:{node.lineno}: runs `bsst {node.args[0].value}`")  # type: ignore[attr-defined]
    return out


def _called(call: ast.Call) -> str:
    f = call.func
    return f.id if isinstance(f, ast.Name) else f.attr if isinstance(f, ast.Attribute) else ""


def parse_tests() -> dict[str, tuple[str, ast.Module]]:
    """Each test module's path, source and tree, parsed with the garbage collector off: the trees kept while the
    rest are parsed made each collection walk them all (1.2 CPU-s, against 0.36 with it off)."""
    with collector_off():
        return {f"tests/{f.name}": (text, ast.parse(text)) for f in TESTS for text in [f.read_text()]}


def marker_problems(parsed: dict[str, tuple[str, ast.Module]] | None = None) -> list[str]:
    trees = {path: tree for path, (_, tree) in (parsed or parse_tests()).items()}
    marked = {f"tests.{Path(p).stem}" for p, t in trees.items() if is_marked_process(t)}
    out = []
    for path, tree in trees.items():
        if not is_marked_process(tree):
            uses = process_uses(path, tree, marked)
            if uses:
                out.append(f"{path}: starts processes or opens sockets without pytestmark = pytest.mark.process: "
                           + "; ".join(uses))
    return out


@pytest.fixture(scope="module")
def parsed_tests() -> dict[str, tuple[str, ast.Module]]:
    """Every test module parsed once for the two tests that read them all: a module-scoped fixture, so that both go
    to one worker (tests/scheduling.py), which parses them once, not once a test."""
    return parse_tests()


def test_every_test_module_names_what_it_covers(parsed_tests: dict[str, tuple[str, ast.Module]]) -> None:
    problems = [p for path, (text, tree) in parsed_tests.items() for p in [covers_problem(path, text, tree)] if p]
    assert not problems, "\n".join(problems)


def test_a_test_module_without_the_process_marker_starts_no_process_and_opens_no_socket(
        parsed_tests: dict[str, tuple[str, ast.Module]]) -> None:
    problems = marker_problems(parsed_tests)
    assert not problems, "\n".join(problems)


def test_the_process_marker_is_registered() -> None:
    text = (ROOT / "pyproject.toml").read_text()
    assert re.search(r'^markers = \[[^\]]*"process:', text, re.M), "pyproject.toml registers no 'process' marker"


@pytest.mark.parametrize("source, expected", [
    ('"""The relay."""\n', "does not start 'Covers"),
    ('"""Covers bridge.nodes.nowhere: x."""\n', "covers bridge.nodes.nowhere, which is no module"),
    ('"""Covers plant.model and plant.elsewhere."""\n', "covers plant.elsewhere"),
    ("x = 1\n", "no module docstring"),
])
def test_the_covers_check_fails_on_a_broken_docstring(source: str, expected: str) -> None:
    problem = covers_problem("tests/test_x.py", source)
    assert problem is not None and expected in problem and problem.startswith("tests/test_x.py:1:"), problem


@pytest.mark.parametrize("source", [
    '"""Covers bridge.core.clock: the clocks."""\n',
    '"""Covers plant.model, plant.rotors and controller: eq. (6).\n\nMore."""\n',
    '"""Covers bridge.sweep.\n\nMore."""\n',
])
def test_the_covers_check_passes_a_good_docstring(source: str) -> None:
    assert covers_problem("tests/test_x.py", source) is None


@pytest.mark.parametrize("source, expected", [
    ("import socket\n", "imports socket"),
    ("def f():\n    import subprocess  # late\n", "imports subprocess"),
    ("from tests.sitlkit import Proc\n", "imports tests.sitlkit"),
    ("from bridge.session import sitl\n", "imports bridge.session"),
    ("from tests.test_relay import udp\n", "imports tests.test_relay"),
    ("from bridge.cli import main\nmain(['sitl', 'm.toml'])\n", "runs `bsst sitl`"),
    ("Proc.bsst('vehicle', '--instance', '3')\n", "runs `bsst vehicle`"),
])
def test_the_marker_check_finds_a_process_or_a_socket(source: str, expected: str) -> None:
    uses = process_uses("tests/test_x.py", ast.parse(source), {"tests.test_relay"})
    assert any(expected in u and u.startswith("tests/test_x.py:") for u in uses), uses
    assert not process_uses("tests/test_x.py", ast.parse("from bridge.cli import main\nmain(['sim', 'm.toml'])\n"),
                            set())
    marked = ast.parse(source + "import pytest\npytestmark = pytest.mark.process\n")
    assert is_marked_process(marked) and not is_marked_process(ast.parse(source))


def test_wait_for_returns_once_the_predicate_holds_and_names_what_never_came() -> None:
    due = time.monotonic() + 0.05
    wait_for(lambda: time.monotonic() >= due, 5.0, "a time 50 ms away", poll_s=0.001)
    assert time.monotonic() >= due
    with pytest.raises(AssertionError, match=r"^the impossible: not within 0.05 s$"):
        wait_for(lambda: False, 0.05, "the impossible")


SHARING = '''
import pytest

@pytest.fixture(scope="module")
def flight(tmp_path_factory):
    return 1

@pytest.fixture(scope="module")
def sweep():
    return 2

@pytest.fixture
def trace(flight, tmp_path):
    return flight

@pytest.fixture(scope="module")
def cheap():
    return 3

def test_a(flight): pass
def test_b(trace, tmp_path): pass
def test_c(tmp_path): pass
def test_d(sweep): pass
def test_e(sweep, cheap): pass
def test_f(cheap): pass
'''


def test_the_tests_sharing_a_module_fixture_are_one_unit_of_work() -> None:
    groups = shared_groups(SHARING, "tests/test_x.py")
    assert groups == {"test_a": "flight", "test_b": "flight", "test_d": "cheap+sweep", "test_e": "cheap+sweep",
                      "test_f": "cheap+sweep"}, groups
    assert shared_groups(SHARING.replace("def test_e(sweep, cheap)", "def test_e(sweep)"), "tests/test_x.py") == {
        "test_a": "flight", "test_b": "flight", "test_d": "sweep", "test_e": "sweep", "test_f": "cheap"}
    CHEAP[("tests/test_x.py", "cheap")] = "for this test"
    try:
        assert "test_f" not in shared_groups(SHARING, "tests/test_x.py")
    finally:
        del CHEAP[("tests/test_x.py", "cheap")]
    # in the suite: a flight several tests read, and a test that shares nothing
    shared = scope_of("tests/test_mission_end.py::test_offline_sine_ends_landed_and_disarmed")
    assert shared == scope_of("tests/test_mission_end.py::test_lockstep_sine_lands_as_offline_to_the_bit") != \
        "tests/test_mission_end.py::test_offline_sine_ends_landed_and_disarmed"
    alone = "tests/test_link_trace.py::test_every_bad_row_is_named_by_file_and_line[x]"
    assert scope_of(alone) == alone


def test_a_worker_reads_the_controllers_groups_unless_the_module_changed_since(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The controller's table (write_groups) is what a worker's scope_of answers from: a group put in it is the one
    answered (no parse), and a module whose mtime or size differs from the table's is parsed again."""
    path, test = "tests/test_mission_end.py", "test_offline_sine_ends_landed_and_disarmed"
    parsed = scope_of(f"{path}::{test}")
    table = tmp_path / "groups.json"
    monkeypatch.setenv(scheduling.GROUPS_ENV, "")  # (put back as it was after: write_groups sets it)
    try:
        write_groups([str(ROOT / path) + "::" + test, str(ROOT / "tests" / "no_such_dir")], table)
        assert os.environ[scheduling.GROUPS_ENV] == str(table)
        written = json.loads(table.read_text())
        assert list(written) == [path] and f"{path}::<{written[path][2][test]}>" == parsed, written
        written[path][2][test] = "from-the-table"
        table.write_text(json.dumps(written))
        for cached in (scheduling._handed_on, scheduling._groups_in):
            cached.cache_clear()
        assert scope_of(f"{path}::{test}") == f"{path}::<from-the-table>"  # read, not parsed
        written[path][1] += 1  # the module's size when the table was written: not the file's now
        table.write_text(json.dumps(written))
        for cached in (scheduling._handed_on, scheduling._groups_in):
            cached.cache_clear()
        assert scope_of(f"{path}::{test}") == parsed  # parsed again
    finally:
        monkeypatch.undo()
        for cached in (scheduling._handed_on, scheduling._groups_in):
            cached.cache_clear()


def test_the_cheap_fixtures_left_unshared_are_module_fixtures_that_exist() -> None:
    for (path, name), why in CHEAP.items():
        source = (ROOT / path).read_text()
        assert re.search(rf'@pytest\.fixture\(scope="module"\)\ndef {name}\(', source), (path, name, why)


def test_the_timeline_sums_wall_and_cpu_by_file_and_ranks_by_the_machines_cpu_with_one_worker(tmp_path: Path) -> None:
    """Two tests on one worker: wall 2 s and 1 s, the worker's CPU 0.5 and 0.25 s, the machine's 3 and 0.5 s."""
    (tmp_path / "main.txt").write_text(
        "S 100.000 1.000 50.00 tests/test_a.py::test_one\n"
        "E 102.000 1.500 53.00 tests/test_a.py::test_one\n"
        "S 102.000 1.500 53.00 tests/test_b.py::test_two\n"
        "E 103.000 1.750 53.50 tests/test_b.py::test_two\n")
    lines = report(tmp_path).splitlines()
    assert "3.0 worker-seconds in all, 0.8 CPU-seconds" in lines[1], lines
    machine = lines[lines.index("machine CPU-seconds by file:") + 1:][:2]
    assert [ln.split() for ln in machine] == [["3.0", "tests/test_a.py"], ["0.5", "tests/test_b.py"]], lines
    costliest = lines[lines.index("costliest tests (CPU s, wall s):") + 1:]
    assert costliest[0].split() == ["3.0", "2.0", "tests/test_a.py::test_one"], lines
    (tmp_path / "gw1.txt").write_text("S 100.000 0.000 50.00 tests/test_c.py::test_three\n"
                                      "E 101.000 0.100 54.00 tests/test_c.py::test_three\n")
    two = report(tmp_path).splitlines()  # two workers: the machine's time is theirs together, not ranked
    assert "machine CPU-seconds by file:" not in two
    assert two[two.index("costliest tests (CPU s, wall s):") + 1].split() == ["0.5", "2.0", "tests/test_a.py::test_one"]


def test_no_hypothesis_example_has_a_deadline() -> None:
    """Speed is measured in benchmarks/, never asserted in a test: the suite's Hypothesis profile has no deadline
    (tests/conftest.py), and no test sets one of its own."""
    from hypothesis import settings

    assert settings.default.deadline is None
    set_here = [f.name for f in Path(__file__).parent.glob("test_*.py")
                if re.search(r"settings\([^)]*deadline\s*=\s*(?!None)", f.read_text())]
    assert set_here == []

