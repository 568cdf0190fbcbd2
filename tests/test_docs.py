"""The documentation (issue 32, item 1): README.md stays short and keeps the two set-up commands,
every relative link in README.md and docs/**/*.md points at a file or folder that exists, and the
site (mkdocs.yml) builds with `mkdocs build --strict`: every page in the nav, every link and anchor
resolving inside docs/. Fast: no simulation, no Snakemake (a build takes seconds)."""
from __future__ import annotations

import importlib.util
import re
import shutil
import subprocess
import sys
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


needs_mkdocs = pytest.mark.skipif(
    importlib.util.find_spec("mkdocs") is None or importlib.util.find_spec("pymdownx") is None,
    reason="the site's tools are not installed: pip install -r docs/requirements.txt -c constraints.txt")


def _mkdocs_build(root: Path, site: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--config-file", str(root / "mkdocs.yml"),
                           "--site-dir", str(site)], capture_output=True, text=True, timeout=300)


@needs_mkdocs
def test_the_site_builds_strictly(tmp_path):
    """Bound: mkdocs exits 0 in strict mode, where mkdocs.yml makes a page left out of the nav, a
    link to nothing (or out of docs/) and an anchor that no heading has each a warning, so a
    failure; and every page of docs/ becomes a page of the site."""
    done = _mkdocs_build(ROOT, tmp_path / "site")
    assert done.returncode == 0, done.stderr[-3000:]
    for page in PAGES[1:]:
        relative = page.relative_to(ROOT / "docs").with_suffix("")
        built = tmp_path / "site" / (relative.parent if relative.name == "README" else relative) / "index.html"
        assert built.is_file(), built
    # headings get GitHub's anchors, which the pages link to: "Why r0 = 3" keeps its double hyphen
    assert 'id="why-r0--3"' in (tmp_path / "site" / "getting-started" / "index.html").read_text(encoding="utf-8")


@needs_mkdocs
@pytest.mark.parametrize("link, warning", [
    ("[x](method.md#no-such-heading)", "does not contain an anchor '#no-such-heading'"),
    ("[x](../config.yaml)", "'../config.yaml', but the target is not found"),
    ("[x](no-such-page.md)", "'no-such-page.md', but the target is not found"),
])
def test_the_strict_build_fails_on_a_broken_link(tmp_path, link, warning):
    """The site test is not blind: a copy of the docs with one broken link (an anchor no heading of
    the page has, GitHub's anchors being the site's; a file outside docs/; a missing page) fails."""
    shutil.copytree(ROOT / "docs", tmp_path / "docs")
    shutil.copy(ROOT / "mkdocs.yml", tmp_path / "mkdocs.yml")
    with open(tmp_path / "docs" / "cli.md", "a", encoding="utf-8") as page:
        page.write(f"\nSee {link}.\n")
    done = _mkdocs_build(tmp_path, tmp_path / "site")
    assert done.returncode != 0 and warning in done.stderr, done.stderr[-3000:]



def test_every_configuration_file_is_listed_with_its_commands():
    """Issue 48.4: docs/study-config.md lists every file in config/, in the workflow's files and in
    the table of runs and reports."""
    text = (ROOT / "docs" / "study-config.md").read_text()
    for path in sorted((ROOT / "config").glob("*.yaml")):
        name = f"config/{path.name}"
        assert f"\n{name} " in text, f"{name} missing from the workflow's files"
        assert f"| `{name}` | `snakemake -j2 all --configfile {name}` |" in text, f"{name} missing from the table"


@pytest.mark.parametrize("page", sorted(p.name for p in (ROOT / "docs" / "validation").glob("*.md") if p.name != "README.md"))
def test_every_validation_page_names_its_lever_commit_and_config(page):
    """Issue 48.4: a measurement says what made it: the rolling lever, the commit and the
    configuration (a file, or 'none' for one made by hand)."""
    text = (ROOT / "docs" / "validation" / page).read_text()
    assert "lever" in text.lower(), "no rolling lever named"
    assert re.search(r"commit[^.]*\b[0-9a-f]{7,40}\b", text, flags=re.I), "no commit named"
    assert re.search(r"config", text, flags=re.I), "no configuration named"


DATE = re.compile(r"\b20\d\d-\d\d-\d\d\b")


def test_the_code_carries_no_dates():
    """Issue 47.5: a date belongs beside its measurement in docs/ (with its commit and machine), not in
    a docstring or comment of the package or the workflow, where it goes stale unseen."""
    files = [*(ROOT / "src" / "colsim").rglob("*.py"), *(ROOT / "workflow").rglob("*.smk"),
             *(ROOT / "workflow").rglob("*.yaml"), ROOT / "Snakefile", ROOT / "config.yaml"]
    dated = [f"{path.relative_to(ROOT)}:{n}" for path in files
             for n, line in enumerate(path.read_text().splitlines(), 1) if DATE.search(line)]
    assert not dated, dated
