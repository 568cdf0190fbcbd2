"""What every file records of how it was made (global attributes): `Conventions`, `title`,
`source`, `history`, the versions of colsim, Clarabel and numpy, the git commit of the source
(`colsim_commit`, " (modified)" when its tracked files differed), the run's configuration as JSON
in `config` and its `seed`."""
from __future__ import annotations

import functools
import importlib.metadata
import json
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from .. import __version__
from .cf import UNIT_SYSTEM
from .git import CODE_PATHS, git_state


def global_attributes(kind: str, title: str, config: dict, seed=None) -> dict:
    """CF global attributes with colsim's version, the configuration (JSON) and the seed."""
    attrs = {
        "Conventions": "CF-1.8",
        "title": title,
        "source": f"colsim {__version__}",
        "history": f"{datetime.now(timezone.utc).isoformat(timespec='seconds')} created by colsim {__version__}",
        "colsim_kind": kind,
        "config": json.dumps(config, sort_keys=True, default=_json_default),
        "unit_system": UNIT_SYSTEM,
        **versions(),
    }
    if seed is not None:
        attrs["seed"] = int(seed)
    return attrs


def versions() -> dict:
    """{colsim_version, colsim_commit, clarabel_version, numpy_version} of this process (installed
    distributions; the commit from :func:`source_commit`)."""
    found = {"colsim_version": __version__, "colsim_commit": source_commit(), "numpy_version": np.__version__}
    try:
        found["clarabel_version"] = importlib.metadata.version("clarabel")
    except importlib.metadata.PackageNotFoundError:
        found["clarabel_version"] = "not installed"
    return found


@functools.lru_cache(maxsize=1)
def source_commit() -> str:
    """The git commit of the checkout colsim's source lies in, with " (modified)" when its code
    (:data:`colsim.io.git.CODE_PATHS`: not a study's configuration) differs from it; "unknown (not a
    git checkout)" for an installed copy or without git. Asked once a process: a run's files all
    name the code it started with."""
    state = git_state(Path(__file__).parent, CODE_PATHS)
    if not state["commit"]:
        return "unknown (not a git checkout)"
    return state["commit"] + (" (modified)" if state["dirty"] else "")


def _json_default(value):
    if isinstance(value, (np.integer, np.floating)):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"cannot store {type(value).__name__} in the configuration")


def config_of(dataset) -> dict:
    """The configuration stored in a colsim dataset's attributes."""
    return json.loads(dataset.attrs.get("config", "{}"))
