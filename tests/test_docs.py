"""Every Python example of the documentation runs: the ```python blocks of docs/**/*.md and README.md.

The blocks of one page run in order in one namespace (a page reads as one script), in a fresh working
directory. A block preceded by a line ``<!-- skip: why -->`` is only compiled, not run (for the few that need a
GPU or minutes of compilation on a CPU); the reason is required.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
FENCE = re.compile(r"^(?P<indent>[ \t]*)(?P<fence>```+|~~~+)\s*(?P<info>[^\n]*)$")
SKIP = re.compile(r"^\s*<!--\s*skip:\s*(?P<reason>\S.*?)\s*-->\s*$")
MAX_SKIPPED = 8  # the examples are meant to run: skipping is the exception


def code_blocks(path: Path) -> list[tuple[int, str, str | None]]:
    """``(first line, code, skip reason or None)`` of each ```python block of a markdown file."""
    lines = path.read_text().splitlines()
    blocks, i = [], 0
    while i < len(lines):
        match = FENCE.match(lines[i])
        if not match:
            i += 1
            continue
        indent, fence = match.group("indent"), match.group("fence")
        language = match.group("info").strip().split(" ")[0].strip("{}.").lower() if match.group("info") else ""
        start, body = i + 1, []
        i += 1
        while i < len(lines) and not lines[i].strip().startswith(fence):
            body.append(lines[i][len(indent):] if lines[i].startswith(indent) else lines[i].lstrip())
            i += 1
        i += 1
        if language not in ("python", "py"):
            continue
        previous = next((lines[k] for k in range(start - 2, -1, -1) if lines[k].strip()), "")
        skip = SKIP.match(previous)
        blocks.append((start + 1, "\n".join(body) + "\n", skip.group("reason") if skip else None))
    return blocks


PAGES_WITH_CODE = [p for p in PAGES if code_blocks(p)]


def test_pages_found():
    assert (ROOT / "docs" / "index.md").exists()
    assert any(p.name == "README.md" for p in PAGES_WITH_CODE), "README.md has no python example"
    assert len(PAGES_WITH_CODE) >= 10


def test_few_blocks_skipped():
    skipped = [(p.relative_to(ROOT), line, reason) for p in PAGES for line, _, reason in code_blocks(p) if reason]
    assert len(skipped) <= MAX_SKIPPED, f"too many skipped examples: {skipped}"


def misindented_blocks(path: Path) -> list[tuple[int, str]]:
    """Lines that start a block (after a blank line, outside fences) indented by other than a multiple of 4 spaces.
    The site's Markdown nests a paragraph, code block or figure in a list item only at 4 spaces (8 for code), so a
    block at 2 or 6 spaces falls out of its item and a command meant as code shows as plain text."""
    bad, fenced, after_blank = [], False, False
    for number, line in enumerate(path.read_text().splitlines(), 1):
        if line.lstrip().startswith(("```", "~~~")):
            fenced, after_blank = not fenced, False
            continue
        if fenced:
            continue
        if not line.strip():
            after_blank = True
            continue
        indent = len(line) - len(line.lstrip(" "))
        if after_blank and indent % 4:
            bad.append((number, line.strip()[:60]))
        after_blank = False
    return bad


def test_blocks_in_list_items_are_indented_by_four_spaces(tmp_path):
    bad = [f"{page.relative_to(ROOT)}:{number}: {text}" for page in PAGES for number, text in misindented_blocks(page)]
    assert bad == [], "indent these blocks by 4 spaces (code in a list item by 8)"
    broken = tmp_path / "page.md"
    broken.write_text("- an item:\n\n      jarena train ppo ARENA\n\n  More of the item.\n\n```\n  code\n```\n")
    assert [number for number, _ in misindented_blocks(broken)] == [3, 5]


def test_api_reference_lists_the_public_names():
    """Every name of ``jarena.__all__`` and ``jarena_agents.__all__`` has an entry (``::: name``) in the API
    reference, or, for a module, entries of its own names."""
    import jarena
    import jarena_agents

    text = "\n".join(p.read_text() for p in sorted((ROOT / "docs" / "reference").glob("*.md")))
    entries = set(re.findall(r"^::: (\S+)", text, re.MULTILINE))
    missing = []
    for package, names in (("jarena", jarena.__all__), ("jarena_agents", jarena_agents.__all__)):
        for name in names:
            dotted = f"{package}.{name}"
            if dotted in entries or any(e.startswith(dotted + ".") for e in entries):
                continue
            if package == "jarena_agents" and f"jarena.{name}" in entries:  # re-exported from jarena
                continue
            missing.append(dotted)
    assert not missing, f"public names without an API reference entry: {missing}"


@pytest.fixture
def registries():
    """The registries as they were: a page that registers an example builder or agent leaves no trace."""
    import jarena_agents  # noqa: F401  (the built-in builders and agents, registered before the snapshot)
    from jarena.building import builder
    from jarena.building.registry import AGENTS

    kept = {r: dict(r._entries) for r in (builder.BUILDERS, builder.TOOLS, builder.TASKS, AGENTS)}
    yield
    for registry, entries in kept.items():
        registry._entries.clear()
        registry._entries.update(entries)


@pytest.mark.parametrize("page", PAGES_WITH_CODE, ids=lambda p: str(p.relative_to(ROOT)))
def test_examples_run(page: Path, tmp_path, monkeypatch, registries):
    monkeypatch.chdir(tmp_path)
    namespace: dict = {"__name__": "__docs__"}
    for line, code, skip in code_blocks(page):
        compiled = compile(code, f"{page.relative_to(ROOT)}:{line}", "exec")  # skipped blocks must still parse
        if skip is None:
            exec(compiled, namespace)  # noqa: S102 - running the documented example is the test
