"""Covers bridge, controller, plant, missions and params.

The layout is the architecture: every import points down the layers, and none goes round.

Reads every module of the project with ``ast`` (function-local imports included) and checks:

- an import goes to a lower layer, or within its own package; never up, never to a sibling
  package of the same layer, and nothing but ``bridge/__main__.py`` imports the CLI;
- there is no circle between modules;
- a function-local import says why in a comment on its line (they stay only where they
  buy start-up time, or for an optional dependency);
- only ``bridge.mavlink``, ``bridge.nodes`` and ``bridge.session`` touch the network or
  start processes, and ``plant``, ``controller``, ``missions`` are pure (no sockets, no
  files, no processes);
- every module of ``bridge/`` opens with a docstring.

The checker is a pure function of ``{module name: source}``, so the tests below also show
that it fails on an upward import, a sibling import and a circle.
"""

from __future__ import annotations

import ast
import functools
from collections.abc import Mapping
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("params", "plant", "controller", "missions", "bridge")
# low to high: a module may import any lower layer, and its own package
LAYERS: tuple[tuple[str, ...], ...] = (
    ("params",),
    ("plant", "missions"),
    ("controller",),
    ("bridge.autopilot",),  # the simulated vehicle's on-board parts: estimator, failsafe, PX4 parameters
    ("bridge.link",),  # the link model; its ends carry a simulated vehicle
    ("bridge.core",),  # the one path from a mission to a flight (link + autopilot), the wire, the clocks
    ("bridge.mavlink", "bridge.record"),
    ("bridge.nodes",),
    ("bridge.loop", "bridge.batch", "bridge.session"),
    ("bridge.swarm",),  # several vehicles in one world: the offline loop's flights stepped together
    ("bridge.sweep",),
    ("bridge.cli",),
    ("bridge.__main__",),  # python -m bridge: the CLI
    ("bridge",),  # the package's own __init__: the public API (bridge.simulate, bridge.Run), imported lazily
)
NETWORK_MODULES = {"socket", "select", "selectors", "subprocess", "multiprocessing", "ssl"}
NETWORK_LAYERS = ("bridge.mavlink", "bridge.nodes", "bridge.session", "bridge.sweep")  # sweep: process pools
PURE = ("plant", "controller", "missions")
FILE_CALLS = {"open", "read_text", "write_text", "read_bytes", "write_bytes", "mkdir", "unlink"}


def group_of(module: str) -> str | None:
    """The layer group a project module belongs to (the longest matching prefix)."""
    best = None
    for layer in LAYERS:
        for g in layer:
            if (module == g or module.startswith(g + ".")) and (best is None or len(g) > len(best)):
                best = g
    return best


def rank_of(group: str) -> int:
    return next(i for i, layer in enumerate(LAYERS) if group in layer)


def project_sources(root: Path = ROOT) -> dict[str, str]:
    """``{module name: source}`` of every module of the project's packages."""
    out = {}
    for pkg in PACKAGES:
        for f in sorted((root / pkg).rglob("*.py")):
            parts = f.relative_to(root).with_suffix("").parts
            name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
            out[name] = f.read_text()
    return out


@functools.lru_cache(maxsize=4096)  # every test re-checks the whole project with one module changed
def _import_nodes(source: str) -> tuple[tuple[int, str, int, tuple[str, ...], int, bool, str], ...]:
    """(is-from, module, level, names, line, function-local?, source line) of each import statement."""
    tree = ast.parse(source)
    lines = source.splitlines()
    local: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            for sub in ast.walk(node):
                if isinstance(sub, (ast.Import, ast.ImportFrom)):
                    local.add(id(sub))
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.append((0, "", 0, tuple(a.name for a in node.names), node.lineno, id(node) in local,
                        lines[node.lineno - 1]))
        elif isinstance(node, ast.ImportFrom):
            out.append((1, node.module or "", node.level, tuple(a.name for a in node.names), node.lineno,
                        id(node) in local, lines[node.lineno - 1]))
    return tuple(out)


def imports_of(name: str, source: str, modules: set[str] | frozenset[str]) -> list[tuple[str, int, bool, str]]:
    """(imported module, line, function-local?, source line) for each import of ``source``.

    ``from a.b import c`` imports the module ``a.b.c`` when there is one, else ``a.b``.
    """
    out = []
    package = name if name in modules and _is_package(name, modules) else name.rpartition(".")[0]
    for is_from, base, level, names, lineno, local, text in _import_nodes(source):
        if not is_from:
            targets = list(names)
        else:
            if level:
                up = package.split(".")[: len(package.split(".")) - level + 1]
                base = ".".join(up + ([base] if base else []))
            targets = [f"{base}.{a}" if f"{base}.{a}" in modules else base for a in names]
        for t in dict.fromkeys(targets):
            out.append((t, lineno, local, text))
    return out


def _is_package(name: str, modules: set[str]) -> bool:
    return any(m.startswith(name + ".") for m in modules)


def layer_problems(sources: Mapping[str, str]) -> list[str]:
    """Every broken rule of the module docstring, one line each (empty: the layout holds)."""
    modules = frozenset(sources)
    problems = []
    graph: dict[str, set[str]] = {m: set() for m in modules}
    for name, src in sources.items():
        g = group_of(name)
        for target, line, local, text in imports_of(name, src, modules):
            top = target.split(".")[0]
            if local and "#" not in text:
                problems.append(f"{name}:{line}: function-local import of {target} without a comment saying why")
            if name.split(".")[0] in PURE and top in NETWORK_MODULES | {"threading", "tempfile", "shutil"}:
                problems.append(f"{name}:{line}: pure package imports {target}")
            if top in NETWORK_MODULES and g is not None and g.startswith("bridge") and g not in NETWORK_LAYERS:
                problems.append(f"{name}:{line}: {g} may not touch the network or processes ({target})")
            if top not in PACKAGES:
                continue
            tg = group_of(target)
            if g is None or tg is None:
                continue
            if target in modules:
                graph[name].add(target)
            if tg == "bridge.cli" and g not in ("bridge.cli", "bridge.__main__"):
                problems.append(f"{name}:{line}: imports the CLI ({target}); nothing imports the CLI")
            elif tg == g:
                continue
            elif rank_of(tg) > rank_of(g):
                problems.append(f"{name}:{line}: upward import {g} -> {tg} ({target})")
            elif rank_of(tg) == rank_of(g):
                problems.append(f"{name}:{line}: sibling import {g} -> {tg} ({target})")
    problems += [f"import circle: {' -> '.join(c)}" for c in circles(graph)]
    return problems


def circles(graph: Mapping[str, set[str]]) -> list[list[str]]:
    """One circle (as a path that ends where it starts) per strongly connected group of modules."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1 or v in graph.get(v, ()):
                found.append(_path_in(sorted(comp), graph))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def _path_in(comp: list[str], graph: Mapping[str, set[str]]) -> list[str]:
    """A closed path through a strongly connected group, from its first module."""
    members = set(comp)
    start = comp[0]
    path = [start]
    seen = {start}
    v = start
    while True:
        nxt = sorted(w for w in graph[v] if w in members)
        back = [w for w in nxt if w == start]
        if back and len(path) > 1 or (back and v == start and start in graph[start]):
            return path + [start]
        fresh = [w for w in nxt if w not in seen]
        v = fresh[0] if fresh else nxt[0]
        if v in seen:
            return path + [v]
        path.append(v)
        seen.add(v)


@pytest.fixture(scope="module")
def sources() -> dict[str, str]:
    """:func:`project_sources`, read once for the module's tests that check the whole project: a module-scoped
    fixture, so that they go to one worker (tests/scheduling.py), whose ``_import_nodes`` cache then parses each
    module once (spread over six workers, each parsed the whole project again: ~1 CPU-s a worker). Copied where a
    test changes it."""
    return project_sources()


def test_the_project_keeps_its_layers(sources: dict[str, str]) -> None:
    problems = layer_problems(sources)
    assert not problems, "\n".join(problems)


def test_every_bridge_subpackage_is_a_layer() -> None:
    for d in sorted(p for p in (ROOT / "bridge").iterdir() if p.is_dir() and not p.name.startswith("__")):
        assert group_of(f"bridge.{d.name}") == f"bridge.{d.name}", f"bridge/{d.name}/ is in no layer of LAYERS"


def test_every_bridge_module_opens_with_a_docstring(sources: dict[str, str]) -> None:
    for name, src in sources.items():
        if name.startswith("bridge") and name != "bridge.__main__":
            assert ast.get_docstring(ast.parse(src)), f"{name} has no module docstring"


def test_pure_packages_touch_no_files(sources: dict[str, str]) -> None:
    for name, src in sources.items():
        if name.split(".")[0] not in PURE:
            continue
        for node in ast.walk(ast.parse(src)):
            if isinstance(node, ast.Call):
                f = node.func
                called = f.id if isinstance(f, ast.Name) else f.attr if isinstance(f, ast.Attribute) else ""
                assert called not in FILE_CALLS, f"{name}:{node.lineno}: pure package calls {called}()"


@pytest.mark.parametrize("name, source, expected", [
    ("bridge.core.bad", "from bridge.nodes.vehicle import Vehicle\n", "upward import bridge.core -> bridge.nodes"),
    ("bridge.record.bad", "import bridge.mavlink.endpoint\n", "sibling import bridge.record -> bridge.mavlink"),
    ("bridge.nodes.bad", "def f():\n    from bridge.cli import main  # lazy\n", "imports the CLI"),
    ("bridge.loop", "from bridge.sweep import Grid\n", "upward import bridge.loop -> bridge.sweep"),
    ("controller.bad", "from bridge.link.model import LinkConfig\n", "upward import controller -> bridge.link"),
    ("bridge.core.bad", "import socket\n", "may not touch the network"),
    ("plant.bad", "import subprocess\n", "pure package imports subprocess"),
    ("bridge.core.bad", "def f():\n    from bridge.link import model\n", "without a comment"),
])
def test_the_checker_fails_on_a_broken_rule(sources: dict[str, str], name: str, source: str, expected: str) -> None:
    sources = dict(sources)
    assert not any(expected in p for p in layer_problems(sources))
    sources[name] = source
    problems = layer_problems(sources)
    assert any(expected in p for p in problems), problems


def test_the_checker_fails_on_a_circle(sources: dict[str, str]) -> None:
    sources = dict(sources)
    sources["bridge.core.ping"] = "from bridge.core.pong import x\n"
    sources["bridge.core.pong"] = "def f():\n    from bridge.core.ping import y  # lazy\n"
    problems = layer_problems(sources)
    assert any(p.startswith("import circle:") and "bridge.core.ping" in p and "bridge.core.pong" in p
               for p in problems), problems
