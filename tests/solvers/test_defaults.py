"""Each solver default in one place (issue 33, item 2): colsim.solvers.defaults. The "Defaults" table
of docs/solvers.md lists every one of its constants with its value, and the configuration schema's
back-end names and default back-end are the module's (Snakemake's validate() reads the schema from
its file, so the schema repeats them and this test holds them equal)."""
from __future__ import annotations

import ast
from pathlib import Path

import yaml

from colsim.solvers import defaults

ROOT = Path(__file__).resolve().parents[2]


def module_defaults() -> dict:
    return {name: value for name, value in vars(defaults).items() if name.isupper()}


def documented_defaults() -> dict:
    """{name: value} of the rows of docs/solvers.md's "Defaults" table."""
    text = (ROOT / "docs" / "solvers.md").read_text()
    section = text.split("\n## Defaults\n", 1)[1].split("\n## ", 1)[0]
    rows = [line for line in section.splitlines() if line.startswith("| `")]
    found = {}
    for row in rows:
        name, value = [cell.strip() for cell in row.strip("|").split("|")[:2]]
        found[name.strip("`")] = ast.literal_eval(value.strip("`"))
    return found


def test_the_docs_table_lists_every_solver_default_with_its_value():
    documented, actual = documented_defaults(), module_defaults()
    assert set(documented) == set(actual)
    for name, value in actual.items():
        assert documented[name] == value and type(documented[name]) is type(value), name


def test_the_schema_offers_the_modules_solvers_and_default():
    schema = yaml.safe_load((ROOT / "workflow" / "schemas" / "config.schema.yaml").read_text())
    solver = schema["properties"]["solver"]
    assert tuple(solver["enum"]) == defaults.SOLVERS
    assert solver["default"] == defaults.DEFAULT_SOLVER
    storage = schema["properties"]["gpu_storage"]
    assert tuple(storage["enum"]) == defaults.GPU_STORAGES and storage["default"] == defaults.DEFAULT_GPU_STORAGE


def test_apgd_takes_its_lipschitz_decay_from_the_module():
    """The decay is a default of the solver's signature, read from the module (one place)."""
    from colsim.solvers.apgd import ApgdSolver

    assert ApgdSolver().lipschitz_decay == defaults.APGD_LIPSCHITZ_DECAY
    assert ApgdSolver().describe()["lipschitz_decay"] == defaults.APGD_LIPSCHITZ_DECAY   # recorded in a run's settings
