"""colsim.io.git: a checkout's git state, on a throwaway repository. Issue 79.9: editing a study's
config.yaml, as the docs say to add a sweep, does not make colsim's files "(modified)" as an edit
of its code does."""
from __future__ import annotations

import shutil
import subprocess

import pytest

from colsim.io.git import CODE_PATHS, git_state

pytestmark = pytest.mark.skipif(shutil.which("git") is None, reason="git is not installed")


def _git(folder, *args):
    subprocess.run(["git", "-C", str(folder), "-c", "user.name=t", "-c", "user.email=t@t.invalid", *args],
                   check=True, capture_output=True)


@pytest.fixture
def checkout(tmp_path):
    """A repository laid out as colsim's: src/, workflow/, Snakefile, config.yaml, docs/."""
    for name in ("src/colsim/a.py", "workflow/rules/r.smk", "Snakefile", "config.yaml", "config/tiny.yaml",
                 "docs/x.md"):
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text("x\n")
    _git(tmp_path, "init", "-q")
    _git(tmp_path, "add", ".")
    _git(tmp_path, "commit", "-q", "-m", "first")
    return tmp_path


@pytest.mark.parametrize("edited, code_dirty", [("config.yaml", False), ("config/tiny.yaml", False),
                                               ("docs/x.md", False), ("src/colsim/a.py", True),
                                               ("workflow/rules/r.smk", True), ("Snakefile", True)])
def test_only_an_edit_of_the_code_makes_it_modified(checkout, edited, code_dirty):
    (checkout / edited).write_text("changed\n")
    asked_from = checkout / "src" / "colsim"   # as colsim asks: from its own package's folder
    assert git_state(asked_from, CODE_PATHS)["dirty"] is code_dirty
    assert git_state(asked_from)["dirty"] is True   # the whole checkout (the benchmarks' records) still tells
    assert len(git_state(asked_from)["commit"]) == 40


def test_a_clean_checkout_and_no_checkout(checkout, tmp_path_factory):
    assert git_state(checkout, CODE_PATHS)["dirty"] is False
    assert git_state(tmp_path_factory.mktemp("bare"), CODE_PATHS) == {"commit": None, "dirty": None, "branch": None}
