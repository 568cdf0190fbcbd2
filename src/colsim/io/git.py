"""Which code wrote a file: the git state of a checkout (its commit, whether its tracked files
differ from it, its branch), asked of git itself; None where git or the checkout is missing."""
from __future__ import annotations

import subprocess
from pathlib import Path


#: the files of colsim's checkout that make its results: the package, the workflow's rules and
#: schema, the Snakefile (git pathspecs from the checkout's top). A study's config.yaml and config/,
#: the docs and the tests are edited as colsim is used, and make no file "(modified)".
CODE_PATHS = (":(top)src", ":(top)workflow", ":(top)Snakefile")


def git_state(folder: Path, paths: tuple[str, ...] = ()) -> dict:
    """{commit, dirty, branch} of the git checkout `folder` lies in (each None when git cannot
    tell: not a checkout, no git). dirty: whether its tracked files differ from the commit, those
    under the git pathspecs `paths` only where given."""
    def git(*args) -> str | None:
        try:
            done = subprocess.run(["git", "-C", str(folder), *args], capture_output=True, text=True,
                                  timeout=20)
        except (OSError, subprocess.TimeoutExpired):
            return None
        return done.stdout.strip() if done.returncode == 0 else None

    commit = git("rev-parse", "HEAD")
    status = git("status", "--porcelain", "--untracked-files=no", *(("--", *paths) if paths else ()))
    return {"commit": commit, "dirty": None if status is None else bool(status),
            "branch": git("rev-parse", "--abbrev-ref", "HEAD")}
