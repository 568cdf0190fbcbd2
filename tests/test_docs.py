"""The documentation (issue 32, item 1): README.md stays short and keeps the two set-up commands, and
every relative link in README.md and docs/**/*.md points at a file or folder that exists. Fast: no
simulation, no Snakemake."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
PAGES = [README, *sorted((ROOT / "docs").rglob("*.md"))]
README_MAX_LINES = 250
SET_UP_COMMANDS = (
    "pip install -r environment.txt -c constraints.txt && snakemake -j2 all",
    "pip install -r environment.txt -c constraints.txt && pytest",
)

FENCE = re.compile(r"^(```|~~~).*?^\1[^\n]*$", re.M | re.S)
CODE_SPAN = re.compile(r"(`+)(?:(?!\1).)+?\1", re.S)
LINK = re.compile(r"!?\[(?:[^\[\]]|\[[^\]]*\])*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
REFERENCE = re.compile(r"^\s*\[[^\]]+\]:\s*<?(\S+?)>?(?:\s+.*)?$", re.M)


def links(text: str) -> list[str]:
    """The targets of the Markdown links and images in `text`, outside code blocks and code spans."""
    text = CODE_SPAN.sub("", FENCE.sub("", text))
    return LINK.findall(text) + REFERENCE.findall(text)


def is_relative(target: str) -> bool:
    return not (target.startswith("#") or re.match(r"^[a-zA-Z][a-zA-Z0-9+.-]*:", target) or target.startswith("//"))


def test_the_pages_are_found():
    assert README.is_file()
    assert (ROOT / "docs" / "README.md") in PAGES, "docs/README.md, the index of the pages, is missing"


@pytest.mark.parametrize("page", PAGES, ids=lambda page: str(page.relative_to(ROOT)))
def test_every_relative_link_resolves(page):
    broken = []
    for target in links(page.read_text(encoding="utf-8")):
        if not is_relative(target):
            continue
        path = target.split("#", 1)[0].split("?", 1)[0]
        resolved = (ROOT if path.startswith("/") else page.parent) / path.lstrip("/")
        if not resolved.exists():
            broken.append(target)
    assert not broken, f"{page.relative_to(ROOT)}: links to nothing: {broken}"


def test_readme_is_short():
    lines = README.read_text(encoding="utf-8").splitlines()
    assert len(lines) <= README_MAX_LINES, f"README.md has {len(lines)} lines, more than {README_MAX_LINES}"


@pytest.mark.parametrize("command", SET_UP_COMMANDS)
def test_readme_gives_the_set_up_commands_verbatim(command):
    assert command in README.read_text(encoding="utf-8")


def test_the_link_finder_sees_links_and_skips_code():
    text = ("[a](docs/a.md) ![b](figures/b.png \"title\") [c](https://x.org) [d](#anchor)\n"
            "`[e](not/a/link.md)`\n```\n[f](inside/a/fence.md)\n```\n[g]: docs/g.md\n")
    assert links(text) == ["docs/a.md", "figures/b.png", "https://x.org", "#anchor", "docs/g.md"]
    assert [t for t in links(text) if is_relative(t)] == ["docs/a.md", "figures/b.png", "docs/g.md"]
