"""Covers bridge, bridge.cli, bridge.session and bridge.sweep: their front page, README.md, and docs/*.md.

The pages themselves, not the code (nothing here starts a process). Checks that the README is at
most 12 KB; that every relative link (``[text](target)``, ``![alt](target)``) outside code names a file
of the repository and, with ``#anchor``, a heading of that page (GitHub's heading ids); that no link,
and no ``../`` path in the text, points outside the repository (or at nothing); that the README has
one example per ``bsst`` command and a two-command quick start; and that its Python example parses,
imports names that exist, and flies only under ``if __name__ == "__main__":`` (a sweep's workers
import the script again: unguarded, each worker re-ran the script and every cell came back
"worker process died").
"""

from __future__ import annotations

import argparse
import ast
import importlib
import re
from pathlib import Path
from urllib.parse import unquote, urlsplit

import pytest

from bridge.cli import build_parser

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
PAGES = [README, *sorted((ROOT / "docs").glob("*.md"))]
FRONT_PAGE_MAX_BYTES = 12_000  # "at most 12 KB", read as the stricter of 12 000 and 12 288

FENCE = re.compile(r"^(```|~~~).*?^\1[^\n]*$", re.S | re.M)
CODE_SPAN = re.compile(r"(`+)(?!`).*?(?<!`)\1(?!`)", re.S)
LINK = re.compile(r"!?\[(?:[^\]\[]|\[[^\]]*\])*\]\(\s*(?:<([^>\n]+)>|([^)\s]+))(?:\s+\"[^\"]*\")?\s*\)")
HEADING = re.compile(r"^(#{1,6})[ \t]+(.+?)[ \t]*#*[ \t]*$", re.M)
UP_PATH = re.compile(r"(?<![\w.])((?:\.\./)+(?:[\w.\-/]*[\w/])?)")  # a sentence's full stop is not the path's


def page_id(page: Path) -> str:
    return str(page.relative_to(ROOT))


def prose(text: str) -> str:
    """The text outside fenced code blocks and code spans: what Markdown renders as links."""
    return CODE_SPAN.sub("", FENCE.sub("", text))


def link_targets(text: str) -> list[str]:
    """The target of every inline link and image in Markdown text, code left out."""
    return [bracketed or bare for bracketed, bare in LINK.findall(prose(text))]


def slug(heading: str) -> str:
    """GitHub's id for a heading: its rendered text, lower case, punctuation dropped, spaces to hyphens."""
    text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", heading)  # a link in a heading renders as its text
    text = text.replace("`", "").strip().lower()
    return re.sub(r"[^\w\- ]", "", text).replace(" ", "-")


def anchors(page: Path) -> set[str]:
    """Every heading id of a page (a repeated heading gets -1, -2, ... as on GitHub)."""
    seen: dict[str, int] = {}
    out = set()
    for _, title in HEADING.findall(FENCE.sub("", page.read_text(encoding="utf-8"))):
        s = slug(title)
        n = seen.get(s, 0)
        seen[s] = n + 1
        out.add(s if n == 0 else f"{s}-{n}")
    return out


def inside_repository(path: Path) -> bool:
    return path.resolve().is_relative_to(ROOT)


def test_the_readme_is_a_front_page_of_at_most_12_kb() -> None:
    size = len(README.read_bytes())
    assert size <= FRONT_PAGE_MAX_BYTES, f"README.md is {size} bytes; its depth belongs in docs/ (docs/usage.md)"


@pytest.mark.parametrize("page", PAGES, ids=page_id)
def test_every_relative_link_lands_on_a_file_and_heading_of_the_repository(page: Path) -> None:
    broken = []
    for target in link_targets(page.read_text(encoding="utf-8")):
        parts = urlsplit(target)
        if parts.scheme in ("http", "https", "mailto"):
            continue  # the web: not checked offline
        if parts.scheme or parts.netloc or target.startswith("/"):
            broken.append(f"{target}: not a path inside the repository")
            continue
        dest = (page.parent / unquote(parts.path)).resolve() if parts.path else page
        if not inside_repository(dest):
            broken.append(f"{target}: points outside the repository")
        elif not dest.exists():
            broken.append(f"{target}: no such file")
        elif parts.fragment and dest.suffix == ".md" and unquote(parts.fragment) not in anchors(dest):
            broken.append(f"{target}: {page_id(dest)} has no heading with that id")
    assert not broken, f"{page_id(page)}: " + "; ".join(broken)


@pytest.mark.parametrize("page", PAGES, ids=page_id)
def test_no_path_in_the_text_climbs_out_of_the_repository(page: Path) -> None:
    """Code and prose alike: a ``../`` path that leaves the repository, or names nothing in it, means nothing
    to a reader of a clone (the project's notes outside it are not shipped)."""
    text = page.read_text(encoding="utf-8")
    out = [p for p in UP_PATH.findall(text)
           if not inside_repository(page.parent / p) or not (page.parent / p).exists()]
    assert not out, f"{page_id(page)} names paths that are not in the repository: {out}"


def test_the_checks_see_links_headings_and_escapes() -> None:
    """The helpers above on known text, so that a checker that sees nothing cannot pass the tests above."""
    assert slug("Signing: `--key FILE`") == "signing---key-file"
    assert slug("On the wall clock: `bsst relay`") == "on-the-wall-clock-bsst-relay"
    assert slug("The `[link]` table") == "the-link-table"
    sample = "see [a](docs/a.md#x) and ![b](b.png)\n```sh\n[c](c.md)\n```\n`[d](d.md)` [e](<e f.md>)"
    assert link_targets(sample) == ["docs/a.md#x", "b.png", "e f.md"]
    assert UP_PATH.findall("read ../outside/LAW.md, ../../x and ../README.md.") == [
        "../outside/LAW.md", "../../x", "../README.md"]
    assert not inside_repository(ROOT / "docs" / "../../outside")
    assert "the-link-table" in anchors(ROOT / "docs" / "links.md")


def subcommands() -> set[str]:
    actions = [a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction)]
    assert len(actions) == 1
    return set(actions[0].choices)


def readme_blocks(lang: str) -> list[str]:
    return re.findall(rf"^```{lang}\n(.*?)^```$", README.read_text(encoding="utf-8"), re.S | re.M)


def test_the_readme_has_one_example_per_command() -> None:
    examples = [ln.split()[1] for block in readme_blocks("sh") for ln in block.splitlines()
                if ln.startswith("bsst ")]
    missing = subcommands() - set(examples)
    assert not missing, f"README.md has no example of bsst {', '.join(sorted(missing))}"
    repeated = {c for c in examples if examples.count(c) > 1}
    assert not repeated, f"README.md has more than one example of bsst {', '.join(sorted(repeated))} (more: usage.md)"


def test_the_quick_start_is_two_commands() -> None:
    quick = re.search(r"^## Quick start\n(.*?)^## ", README.read_text(encoding="utf-8"), re.S | re.M)
    assert quick, "README.md has no Quick start"
    block = re.search(r"^```sh\n(.*?)^```$", quick.group(1), re.S | re.M)
    assert block, "README.md's Quick start has no commands"
    assert [ln.split("#")[0].strip() for ln in block.group(1).splitlines()] == ["make demo", "make test"]


def is_main_guard(node: ast.stmt) -> bool:
    return (isinstance(node, ast.If) and isinstance(node.test, ast.Compare) and isinstance(node.test.left, ast.Name)
            and node.test.left.id == "__name__" and isinstance(node.test.ops[0], ast.Eq)
            and [c.value for c in node.test.comparators if isinstance(c, ast.Constant)] == ["__main__"])


def test_the_python_example_parses_imports_what_exists_and_flies_under_a_main_guard() -> None:
    """The README's Python example (run in full by hand: it flies a SITL session and a sweep)."""
    (source,) = readme_blocks("python")
    tree = ast.parse(source)
    imports = [n for n in tree.body if isinstance(n, ast.ImportFrom)]
    assert imports
    for node in imports:
        module = importlib.import_module(node.module or "")
        for alias in node.names:
            assert hasattr(module, alias.name), f"README.md imports {alias.name} from {node.module}: not there"
    rest = [n for n in tree.body if not isinstance(n, (ast.Import, ast.ImportFrom))]
    assert rest and all(is_main_guard(n) for n in rest), "README.md's Python example flies outside its main guard"
    assert is_main_guard(ast.parse('if __name__ == "__main__":\n    pass').body[0])
    assert not is_main_guard(ast.parse('if __name__ == "x":\n    pass').body[0])
