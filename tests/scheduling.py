"""How ``make test`` shares the suite between pytest-xdist's workers (``--dist loadscope``, pyproject.toml;
installed by tests/conftest.py's ``pytest_xdist_make_scheduler``).

In:  a test id as pytest-xdist's controller sees it (``tests/test_x.py::test_name[params]``), and the source of
     that test module
Out: :func:`is_marked_process` (a module whose tests all start processes or open sockets); :func:`scope_of`,
     the unit of work the test belongs to: the test alone, or, for a test that uses a
     module-scoped fixture of its module (a flight, a sweep, a SITL session made once for several tests), the
     group of all the module's tests that do, so that one worker makes the fixture once;
     :class:`SharedFixtureScheduling`, pytest-xdist's ``loadscope`` scheduler with those units

Why: ``--dist load`` hands tests out round-robin, then in chunks, whatever their module, so a module's tests may
go to both workers and each then sets up its module-scoped fixture (a 40-test sample module: both did); ``--dist
loadfile`` (or pytest-xdist's own ``loadscope``) keeps each whole file on one worker, which leaves a worker idle
while the other finishes a long file. Here only the tests that share a fixture are kept together: the groups go
first (the largest first, those flying the batch engine after the others: tests/conftest.py orders them), then
every other test one at a time to the worker that is free. (pytest-xdist's ``loadgroup`` would do this from
``xdist_group`` marks, but under pytest 9 it renames ``item._nodeid``, which pytest 9 no longer reads: its groups
are silently ignored.)

The controller does not collect tests, so the fixtures are read from each module's source with ``ast``: a
function decorated ``@pytest.fixture(scope="module")``, and any fixture of the module that takes one as an
argument, is shared; a test function that takes a shared fixture as an argument joins its module's group.
Every worker needs the groups too (it orders its collection by them: tests/conftest.py), and parsing the suite's
modules took each ~0.35 CPU-s: the controller parses them once, before it starts the workers, and hands its table
on (:func:`write_groups`, a JSON file :data:`GROUPS_ENV` names); a module changed since (its mtime or size) is
parsed again where it is read.
"""

from __future__ import annotations

import ast
import functools
import json
import os
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from xdist.scheduler import LoadScopeScheduling

from tests.quietgc import collector_off

ROOT = Path(__file__).resolve().parents[1]
GROUPS_ENV = "BSST_TEST_GROUPS"  # the controller's table of each module's groups (write_groups), for its workers


def is_marked_process(tree: ast.Module) -> bool:
    """Whether the module sets ``pytestmark`` to ``pytest.mark.process`` (alone or in a list)."""
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "pytestmark" for t in node.targets):
            return any(isinstance(n, ast.Attribute) and n.attr == "process" for n in ast.walk(node.value))
    return False


def _fixture_scope(dec: ast.expr) -> str | None:
    """``"function"`` for a ``@pytest.fixture`` decorator without a scope, its scope if given, None if the
    decorator is not pytest.fixture."""
    call = dec if isinstance(dec, ast.Call) else None
    target = call.func if call else dec
    if not (isinstance(target, ast.Attribute) and target.attr == "fixture"):
        return None
    for kw in call.keywords if call else ():
        if kw.arg == "scope" and isinstance(kw.value, ast.Constant):
            return str(kw.value.value)
    return "function"


# module-scoped fixtures too cheap to hold their tests together (a worker may well make them twice)
CHEAP = {("tests/test_sweep.py", "mission_file"): "writes a 10-line mission file",
         ("tests/test_laws.py", "nominal"): "a dataclass from the paper's profile",
         ("tests/test_bad_input.py", "shared_files"): "writes eight small files"}


def shared_groups(source: str, path: str = "") -> dict[str, str]:
    """Test function name -> its group (the names of the module-scoped fixtures it shares, joined), for
    the tests of a module that use one (directly or through another fixture of the module): tests whose
    fixtures overlap are in one group. :data:`CHEAP` fixtures of ``path`` share nothing."""
    funcs = [n for n in ast.parse(source).body if isinstance(n, ast.FunctionDef | ast.AsyncFunctionDef)]
    args = {f.name: {a.arg for a in f.args.args + f.args.kwonlyargs} for f in funcs}
    fixtures = {f.name: s for f in funcs for s in map(_fixture_scope, f.decorator_list) if s is not None}
    uses = {name: {name} if fixtures.get(name) in ("module", "package", "session") and (path, name) not in CHEAP
            else set() for name in args}
    grew = True
    while grew:  # what a fixture takes, a test taking it uses too
        grew = False
        for name in args:
            more = set().union(*(uses[a] for a in args[name] if a in fixtures)) - uses[name]
            uses[name] |= more
            grew |= bool(more)
    group = {name: name for name in fixtures}  # union-find over the shared fixtures
    def root(x: str) -> str:
        while group[x] != x:
            x = group[x]
        return x
    tests = {f.name: uses[f.name] for f in funcs if f.name.startswith("test") and f.name not in fixtures}
    for used in tests.values():
        first, *rest = sorted(used) or [None]
        for other in rest:
            group[root(other)] = root(first)
    members: dict[str, set[str]] = {}
    for name in fixtures:
        members.setdefault(root(name), set()).add(name)
    return {t: "+".join(sorted(members[root(min(used))] & set().union(*tests.values())))
            for t, used in tests.items() if used}


def _stamp(path: str) -> list[int]:
    """What tells the module ``path`` changed: its mtime (ns) and size (bytes)."""
    st = (ROOT / path).stat()
    return [st.st_mtime_ns, st.st_size]


@functools.cache
def _handed_on() -> dict[str, list]:
    """The controller's table (:func:`write_groups`), where :data:`GROUPS_ENV` names one; else, or unreadable, none."""
    where = os.environ.get(GROUPS_ENV)
    if not where:
        return {}
    try:
        return json.loads(Path(where).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}


def write_groups(args: Iterable[str], where: Path) -> None:
    """Parse the suite's test modules (``tests/test_*.py``) that ``args`` name (pytest's arguments: files, folders,
    test ids; a folder names those inside it) and write each one's groups, with its :func:`_stamp`, as JSON to
    ``where``; name it in :data:`GROUPS_ENV` for the processes started after (pytest-xdist's workers)."""
    given = [Path(arg.split("::", 1)[0]).resolve() for arg in args]
    paths = [f.relative_to(ROOT).as_posix() for f in sorted((ROOT / "tests").glob("test_*.py"))
             if any(f == g or f.is_relative_to(g) for g in given)]
    table = {path: [*_stamp(path), _groups_in(path)] for path in paths}
    where.write_text(json.dumps(table), encoding="utf-8")
    os.environ[GROUPS_ENV] = str(where)


@functools.cache
def _groups_in(path: str) -> dict[str, str]:
    known = _handed_on().get(path)
    try:
        if known is not None and known[:2] == _stamp(path):
            return known[2]
    except OSError:
        return {}
    try:
        with collector_off():  # the controller parses every test module (tests/quietgc.py)
            return shared_groups((ROOT / path).read_text(encoding="utf-8"), path)
    except (OSError, SyntaxError, UnicodeDecodeError):
        return {}  # not a file we can read: every test of it on its own (as --dist load)


def scope_of(nodeid: str) -> str:
    """The unit of work of a test id: its group if it shares a module-scoped fixture, else the test itself."""
    path, _, rest = nodeid.partition("::")
    group = _groups_in(path).get(rest.split("[", 1)[0])
    return f"{path}::<{group}>" if group else nodeid


class SharedFixtureScheduling(LoadScopeScheduling):
    """pytest-xdist's ``loadscope`` with :func:`scope_of`'s units (module docstring), handed out in the
    collection's order, which tests/conftest.py's ``pytest_collection_modifyitems`` makes (the groups first, the
    largest first): not re-sorted by size here (``--loadscope-reorder`` off), so that the groups flying the batch
    engine can come after the others."""

    def __init__(self, config: Any, log: Any = None) -> None:
        super().__init__(config, log)
        config.option.loadscopereorder = False  # (read once, by schedule(); this scheduler's run only)

    def _split_scope(self, nodeid: str) -> str:
        return scope_of(nodeid)
