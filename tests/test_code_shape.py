"""Covers bridge, controller, plant and missions: their shape (sizes, docstrings, ports, type hints).

Walks every module of those packages with ``ast`` (as python-control's ``kwargs_test.py`` and
``docstrings_test.py`` walk theirs) and checks the rules of the house:

- no module over :data:`MAX_MODULE_LINES` lines, no function over :data:`MAX_FUNCTION_LINES`;
- every module opens with a docstring, and a module that defines anything (a function or a class)
  has a ports block in it: a line starting ``In:`` and, on it or after it, ``Out:`` (what comes in,
  what goes out, units); a package index that only re-exports needs the docstring only;
- every public function and method (no leading underscore, in a public class or at module level)
  has type hints on all its arguments and its return.

Every failure names ``file:line``. There is no allow-list: the limits hold for every module.

And, in those packages and ``params``: no ``except ... as exc`` reads its exception's own text to re-anchor or reword
it (``str(exc).startswith(f"{src}: ")``, ``str(exc).replace("the mission (", ...)``, ``"x" in str(exc)``): a
refusal's parts are its typed fields (``params.ConfigError``'s ``source``, ``key``, ``what``; ``ParamRefused.what``),
set by the code that raises. Only a third party's words are read, each named in :data:`OTHERS_WORDS`.
"""

from __future__ import annotations

import ast
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.quietgc import collector_off

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("bridge", "controller", "plant", "missions")
MAX_MODULE_LINES = 500
MAX_FUNCTION_LINES = 100
NO_DOCSTRING: set[str] = set()  # modules allowed no docstring (none now)


def modules(root: Path = ROOT) -> Iterator[tuple[str, str, ast.Module]]:
    """(path relative to the root, source, tree) of every module of :data:`PACKAGES`."""
    for pkg in PACKAGES:
        for f in sorted((root / pkg).rglob("*.py")):
            src = f.read_text()
            yield f.relative_to(root).as_posix(), src, ast.parse(src)


def functions(tree: ast.AST) -> Iterator[tuple[ast.FunctionDef | ast.AsyncFunctionDef, bool, bool]]:
    """(function, public?, method?) for every function of a tree, nested ones included (never public)."""

    def walk(node: ast.AST, public: bool, in_class: bool) -> Iterator:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                yield child, public and not child.name.startswith("_"), in_class
                yield from walk(child, False, False)
            elif isinstance(child, ast.ClassDef):
                yield from walk(child, public and not child.name.startswith("_"), True)
            else:
                yield from walk(child, public, in_class)

    yield from walk(tree, True, False)


def size_problems(path: str, src: str, tree: ast.Module) -> dict[str, str]:
    """{path, or path::function: the problem, naming file:line} for each limit passed."""
    out = {}
    n = len(src.splitlines())
    if n > MAX_MODULE_LINES:
        out[path] = f"{path}:1: {n} lines, over {MAX_MODULE_LINES}"
    for fn, _, _ in functions(tree):
        length = fn.end_lineno - fn.lineno + 1
        if length > MAX_FUNCTION_LINES:
            out[f"{path}::{fn.name}"] = f"{path}:{fn.lineno}: {fn.name} is {length} lines, over {MAX_FUNCTION_LINES}"
    return out


TEXT_READS = {"startswith", "endswith", "removeprefix", "removesuffix", "replace", "partition", "rpartition", "find",
              "index"}  # what re-anchors or rewords a text (not split(): a third party's whitespace made one line)
OTHERS_WORDS = {("bridge/link/trace.py", "end of data"): "csv's unclosed quote"}  # (module, words read): whose


def _text_of(node: ast.AST, name: str) -> bool:
    """Whether ``node`` is the text of the exception bound to ``name``: ``str(name)``, ``name.args[...]``."""
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "str":
        return len(node.args) == 1 and isinstance(node.args[0], ast.Name) and node.args[0].id == name
    if isinstance(node, ast.Subscript):
        node = node.value
    return isinstance(node, ast.Attribute) and node.attr == "args" and isinstance(node.value, ast.Name) \
        and node.value.id == name


def text_read_problems(path: str, tree: ast.Module) -> list[str]:
    """A line per place where an ``except ... as exc`` reads ``exc``'s text (:data:`TEXT_READS`, or ``in``),
    but for a third party's words (:data:`OTHERS_WORDS`)."""
    out = []
    for handler in ast.walk(tree):
        if not isinstance(handler, ast.ExceptHandler) or handler.name is None:
            continue
        for node in ast.walk(handler):
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr in TEXT_READS \
                    and _text_of(node.func.value, handler.name):
                words = node.args[0] if node.args else None
            elif isinstance(node, ast.Compare) and isinstance(node.ops[0], (ast.In, ast.NotIn)) \
                    and _text_of(node.comparators[0], handler.name):
                words = node.left
            else:
                continue
            said = words.value if isinstance(words, ast.Constant) else None
            if (path, said) not in OTHERS_WORDS:
                out.append(f"{path}:{node.lineno}: reads the text of {handler.name}: read its typed fields instead "
                           "(params.ConfigError's source, key, what)")
    return out


SAID = {"text", "reason", "how", "why"}  # what a report, an event or a child says for people (bridge.nodes.report)


def _says(node: ast.AST) -> bool:
    """Whether ``node`` holds words said for people: an attribute of :data:`SAID` (``e.text``, ``done.reason``), or a
    child's last stderr line (``child.last_error()``)."""
    return any(isinstance(n, ast.Attribute) and n.attr in SAID
               or isinstance(n, ast.Call) and isinstance(n.func, ast.Attribute) and n.func.attr == "last_error"
               for n in ast.walk(node))


def words_read_problems(path: str, tree: ast.Module) -> list[str]:
    """A line per place where a function reads words said for people (:func:`_says`, directly or through a name it
    assigned them to) with :data:`TEXT_READS` or ``in``: across a process or an event's boundary, read the typed
    fields (a ``bad_input`` report's, an event's ``result``) instead."""
    out = []
    for fn in ast.walk(tree):
        if not isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
            continue
        held = {t.id for n in ast.walk(fn) if isinstance(n, ast.Assign) and _says(n.value)
                for t in n.targets if isinstance(t, ast.Name)}

        def read(node: ast.AST) -> bool:
            return node.id in held if isinstance(node, ast.Name) else _says(node)  # noqa: B023  (called at once)

        for node in ast.walk(fn):
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr in TEXT_READS \
                    and read(node.func.value) or isinstance(node, ast.Compare) \
                    and isinstance(node.ops[0], (ast.In, ast.NotIn)) and read(node.comparators[0]):
                out.append(f"{path}:{node.lineno}: reads words said for people: read the typed fields instead")
    return out


def has_ports(doc: str) -> bool:
    """Whether a docstring has a ports block: a line starting ``In:`` and ``Out:`` on it or after it."""
    lines = [line.strip() for line in doc.splitlines()]
    for i, line in enumerate(lines):
        if line.startswith("In:"):
            return any("Out:" in later for later in lines[i:])
    return False


def defines_anything(tree: ast.Module) -> bool:
    return any(isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)) for n in tree.body)


def docstring_problem(path: str, tree: ast.Module) -> str | None:
    """What is missing from a module's docstring (None: nothing)."""
    if path in NO_DOCSTRING:
        return None
    doc = ast.get_docstring(tree)
    if not doc:
        return f"{path}:1: no module docstring"
    if defines_anything(tree) and not has_ports(doc):
        return f"{path}:1: the docstring has no ports block (a line 'In: ...', then 'Out: ...', with units)"
    return None


def hint_problems(path: str, tree: ast.Module) -> list[str]:
    """A line per public function or method without a type hint on an argument or its return."""
    out = []
    for fn, public, method in functions(tree):
        if not public:
            continue
        a = fn.args
        args = a.posonlyargs + a.args + a.kwonlyargs + [x for x in (a.vararg, a.kwarg) if x is not None]
        if method and args and args[0].arg in ("self", "cls") and not _is_static(fn):
            args = args[1:]
        missing = [x.arg for x in args if x.annotation is None] + (["return"] if fn.returns is None else [])
        if missing:
            out.append(f"{path}:{fn.lineno}: {fn.name} has no type hint for {', '.join(missing)}")
    return out


def _is_static(fn: ast.FunctionDef | ast.AsyncFunctionDef) -> bool:
    return any(isinstance(d, ast.Name) and d.id == "staticmethod" for d in fn.decorator_list)


Parsed = tuple[tuple[str, str, ast.Module], ...]


@pytest.fixture(scope="module")
def parsed() -> Parsed:
    """Every module of the packages, parsed once, when a test first asks (not while the suite is collected:
    each worker collects every test file, and parsing ~150 modules cost each ~0.9 s before any test ran); a
    module-scoped fixture, so that its three tests go to one worker (tests/scheduling.py), which parses once. The
    garbage collector is off meanwhile: the trees kept made each collection walk them all (1.2 CPU-s, 0.31 off)."""
    with collector_off():
        return tuple(modules())


def test_no_module_or_function_is_over_its_limit(parsed: Parsed) -> None:
    problems = [p for path, src, tree in parsed for p in size_problems(path, src, tree).values()]
    assert not problems, "\n".join(problems)


def test_every_module_opens_with_a_docstring_with_its_ports(parsed: Parsed) -> None:
    problems = [p for path, _, tree in parsed for p in [docstring_problem(path, tree)] if p]
    assert not problems, "\n".join(problems)


def test_public_functions_have_type_hints(parsed: Parsed) -> None:
    problems = [p for path, _, tree in parsed for p in hint_problems(path, tree)]
    assert not problems, "\n".join(problems)


def test_no_refusal_is_reworded_by_matching_its_own_text() -> None:
    """Until the third wave's forty-fourth session, eight places re-anchored or reworded a refusal by its words
    (``bridge/core/flight.py``'s ``str(exc).startswith(f"{src}: ")`` among them), and one named the flag the user did
    not type: ``--up-link-trace F --down-link-trace F`` was refused as ``--link-trace F``."""
    found = [p for pkg in ("bridge", "missions", "params") for f in sorted((ROOT / pkg).rglob("*.py"))
             for p in text_read_problems(f.relative_to(ROOT).as_posix(), ast.parse(f.read_text()))]
    assert not found, "\n".join(found)
    bad = ast.parse('try:\n    f()\nexcept ValueError as exc:\n    if str(exc).startswith("m.toml: "):\n        raise\n'
                    'except KeyError as e:\n    g("limit" in str(e), e.args[0].replace("a", "b"))\n')
    assert [p.split(": ")[0] for p in text_read_problems("x/m.py", bad)] == ["x/m.py:4", "x/m.py:7", "x/m.py:7"]


def test_no_report_or_event_is_read_by_its_words() -> None:
    """Until the third wave's forty-fourth session the session cut ``bsst: `` off a child's last stderr line to say why
    it refused (a law's own goodbye at its exit was said instead), and bridge.record.ending cut the end action's answer
    out of the controller's ``end`` event's text after its last ``): ``; both now read typed fields (the ``bad_input``
    report, the event's ``result``). No module of ``bridge/`` reads such words again."""
    found = [p for f in sorted((ROOT / "bridge").rglob("*.py"))
             for p in words_read_problems(f.relative_to(ROOT).as_posix(), ast.parse(f.read_text()))]
    assert not found, "\n".join(found)
    bad = ast.parse("def f(child, events):\n    err = child.last_error()\n    said = err.removeprefix('bsst: ')\n"
                    "    why = next(e.text for e in events).rpartition('): ')[2]\n"
                    "    return 'gave up' in child.done.reason, said\n")
    assert [p.split(": ")[0] for p in words_read_problems("x/m.py", bad)] == ["x/m.py:3", "x/m.py:4", "x/m.py:5"]


@pytest.mark.parametrize("source, rule", [
    ('"""Doc.\n\nIn: a\nOut: b\n"""\n' + "x = 1\n" * 500, "lines, over"),
    ('"""Doc.\n\nIn: a\nOut: b\n"""\ndef f() -> None:\n' + "    pass\n" * 100, "f is 101 lines"),
    ('"""Doc without ports."""\ndef f() -> None:\n    pass\n', "no ports block"),
    ("def f() -> None:\n    pass\n", "no module docstring"),
    ('"""Doc.\n\nIn: a; Out: b\n"""\ndef f(a) -> None:\n    pass\n', "no type hint for a"),
    ('"""Doc.\n\nIn: a; Out: b\n"""\nclass C:\n    def m(self, a: int):\n        pass\n', "no type hint for return"),
])
def test_the_checks_fail_on_a_broken_rule(source: str, rule: str) -> None:
    tree = ast.parse(source)
    found = [*size_problems("x/m.py", source, tree).values(), docstring_problem("x/m.py", tree),
             *hint_problems("x/m.py", tree)]
    assert any(p and rule in p and p.startswith("x/m.py:") for p in found), found


def test_the_checks_pass_a_module_that_keeps_the_rules() -> None:
    source = ('"""Doc.\n\nIn:  a (m)\nOut: b (s)\n"""\n\nclass _Private:\n    def m(self, a):\n        pass\n\n\n'
              "def f(a: int, *rest: float, **kw: str) -> None:\n    def inner(b):\n        pass\n")
    tree = ast.parse(source)
    assert not size_problems("x/m.py", source, tree)
    assert docstring_problem("x/m.py", tree) is None and not hint_problems("x/m.py", tree)
