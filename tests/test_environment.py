"""The install (issue 79, item 1): the Pythons pyproject.toml names are those its requires-python
admits, the runtime lock holds no documentation tool, and every pin of the lock that depends on the
Python says so with a marker. `.ci/install-check` resolves the README's command on each of them; this
file holds the statements that check rests on, without the network."""
from __future__ import annotations

import re
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOCS_TOOLS = {"mkdocs", "pymdown-extensions"}


def _project() -> dict:
    return tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]


def named_pythons() -> list[tuple[int, int]]:
    prefix = "Programming Language :: Python :: "
    return sorted(tuple(int(part) for part in c[len(prefix):].split(".")) for c in _project()["classifiers"]
                  if c.startswith(prefix) and c[len(prefix):].count(".") == 1)


def requirement_names(path: Path) -> set[str]:
    names = set()
    for line in path.read_text(encoding="utf-8").splitlines():
        line = line.split(" #", 1)[0].strip()
        if line and not line.startswith(("#", "-")):
            names.add(re.split(r"[<>=!~;\[ ]", line, maxsplit=1)[0].lower())
    return names


def test_requires_python_starts_at_the_oldest_named_python():
    lowest = named_pythons()[0]
    assert _project()["requires-python"] == f">={lowest[0]}.{lowest[1]}"
    assert named_pythons() == [(3, minor) for minor in range(lowest[1], named_pythons()[-1][1] + 1)], \
        "the named Pythons leave a gap"


def test_the_runtime_requirements_hold_no_documentation_tool():
    assert not DOCS_TOOLS & requirement_names(ROOT / "environment.txt")
    assert DOCS_TOOLS <= requirement_names(ROOT / "docs" / "requirements.txt")


def test_a_package_pinned_twice_is_pinned_by_the_python():
    """Two pins of one package in the lock must split the Pythons by markers, or pip finds no version."""
    pins: dict[str, list[str]] = {}
    for line in (ROOT / "constraints.txt").read_text(encoding="utf-8").splitlines():
        line = line.split(" #", 1)[0].strip()
        if line and not line.startswith("#"):
            pins.setdefault(line.split("==", 1)[0].lower(), []).append(line)
    for name, lines in pins.items():
        if len(lines) > 1:
            assert all("; python_full_version" in line for line in lines), lines


def test_a_virtual_environment_in_the_checkout_is_ignored():
    """Issue 79.9: the README's `python3 -m venv .venv` leaves nothing for git to list."""
    import shutil
    import subprocess
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        import pytest
        pytest.skip("not a git checkout")
    done = subprocess.run(["git", "-C", str(ROOT), "check-ignore", "-q", ".venv/bin/python"])
    assert done.returncode == 0, ".venv/ is not in .gitignore"
