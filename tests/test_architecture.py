"""The import order of docs/architecture.md, held against the code: each subpackage imports only
those below it, no module imports itself back through others, and reading a file or parsing the
command line loads no numerics."""
from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "src" / "colsim"

#: the subpackages from the bottom up: a module may import from its own subpackage and those below
LAYERS = {"engine": 0, "solvers": 1, "io": 1, "stages": 2, "study": 3, "cli": 4}
#: io reads and writes files: of the engine it may import these plain records only
IO_MAY_IMPORT = {"colsim.engine.state", "colsim.engine.records", "colsim.engine.warm_start",
                 "colsim.engine.contacts"}
#: what reading a file or parsing the command line must not load
HEAVY = ("numba", "clarabel", "colsim.engine.cones", "colsim.solvers.registry", "colsim.engine.stepper")


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _type_checking_block(node) -> bool:
    return isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test)


def imports_of(path: Path, top_level_only: bool = False) -> set[str]:
    """The colsim modules `path` imports (function-level ones too unless top_level_only; never
    those under `if TYPE_CHECKING:`), as absolute names."""
    me = module_name(path)
    package = me if path.name == "__init__.py" else me.rsplit(".", 1)[0]
    found = set()

    def visit(node, top):
        for child in ast.iter_child_nodes(node):
            if _type_checking_block(child):
                continue
            if isinstance(child, ast.ImportFrom):
                base = child.module or ""
                if child.level:
                    anchor = package.split(".")[: len(package.split(".")) - child.level + 1]
                    base = ".".join(anchor + ([base] if base else []))
                if base.startswith("colsim"):
                    for alias in child.names:   # 'from . import x' names a module
                        candidate = f"{base}.{alias.name}"
                        known = (PACKAGE.parent / candidate.replace(".", "/")).with_suffix(".py").exists() or \
                            (PACKAGE.parent / candidate.replace(".", "/")).is_dir()
                        found.add(candidate if known else base)
            elif isinstance(child, ast.Import):
                found.update(a.name for a in child.names if a.name.startswith("colsim"))
            nested = isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef))
            if not (top_level_only and nested):
                visit(child, top and not nested)

    visit(ast.parse(path.read_text()), True)
    return found - {me}


MODULES = sorted(PACKAGE.rglob("*.py"))


def layer(module: str) -> str | None:
    parts = module.split(".")
    return parts[1] if len(parts) > 2 or (len(parts) == 2 and parts[1] in LAYERS) else None


def test_every_module_lives_in_a_layer():
    loose = [module_name(p) for p in MODULES if p.parent != PACKAGE] + \
        [module_name(p) for p in MODULES if p.parent == PACKAGE and p.name != "__init__.py"]
    assert all(layer(m) in LAYERS for m in loose), [m for m in loose if layer(m) not in LAYERS]


@pytest.mark.parametrize("path", MODULES, ids=lambda p: module_name(p))
def test_a_module_imports_only_its_own_layer_and_those_below(path):
    me = module_name(path)
    mine = layer(me)
    for target in imports_of(path):
        theirs = layer(target)
        if theirs is None or mine is None:   # colsim itself (__version__)
            continue
        if mine == "io" and theirs == "engine":
            assert target in IO_MAY_IMPORT, f"{me} imports {target}: io may read only plain records of the engine"
            continue
        assert LAYERS[theirs] <= LAYERS[mine] and (theirs == mine or LAYERS[theirs] < LAYERS[mine]), \
            f"{me} ({mine}) imports {target} ({theirs}): against the order {LAYERS}"


def test_no_module_imports_itself_back_at_load_time():
    graph = {module_name(p): imports_of(p, top_level_only=True) for p in MODULES}
    done, stack = set(), []

    def visit(node):
        if node in stack:
            raise AssertionError("import cycle: " + " -> ".join(stack[stack.index(node):] + [node]))
        if node in done or node not in graph:
            return
        stack.append(node)
        for target in sorted(graph[node]):
            if not node.startswith(target + "."):   # a module's own package is loaded first anyway
                visit(target)
        stack.pop()
        done.add(node)

    for node in graph:
        visit(node)


def test_the_rule_catches_an_upward_import(tmp_path, monkeypatch):
    """The checker itself: an engine module that imports a stage is reported."""
    bad = PACKAGE / "engine" / "state.py"
    text = bad.read_text() + "\nfrom ..stages import pack\n"
    fake = tmp_path / "colsim" / "engine"
    fake.mkdir(parents=True)
    (fake / "state.py").write_text(text)
    monkeypatch.setattr(sys.modules[__name__], "PACKAGE", tmp_path / "colsim")
    with pytest.raises(AssertionError, match="against the order"):
        test_a_module_imports_only_its_own_layer_and_those_below(fake / "state.py")


@pytest.mark.parametrize("statement", [
    "import colsim.io, colsim.io.trajectory, colsim.io.steps, colsim.io.checkpoint, colsim.io.vtk",
    "import colsim.cli; colsim.cli.build_parser().parse_args(['collapse', '--input', 'c.nc', '--output', 'o.nc'])",
    "import colsim.solvers.defaults, colsim.stages.settings",
    # what the workflow's common.smk imports to plan a study (issue 47.6: a dry run loads no numba)
    "import colsim.study.figure_names, colsim.study.workflow.job_resources, colsim.study.workflow.report, "
    "colsim.study.workflow.checks, colsim.study.workflow.plan, colsim.stages.pour_geometry",
])
def test_files_and_the_command_line_load_no_numerics(statement):
    code = f"{statement}; import sys; print(sorted(m for m in sys.modules if m.startswith({HEAVY!r})))"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "[]", done.stdout


def test_a_dry_run_loads_no_numba(tmp_path):
    """Issue 47.6: `snakemake -n` of a study imports no numba, nor the engine's numerics (its
    planning needs only the configuration's checks and the files' names): measured 1.5-1.6 s against
    2.1-2.2 s when common.smk still imported the figures' module (the 2-core EPYC, the tiny study)."""
    from helpers import copy_workflow

    directory = copy_workflow(tmp_path)
    done = subprocess.run([sys.executable, "-X", "importtime", "-m", "snakemake", "-n", "all", "--configfile",
                           "config/tiny.yaml"], cwd=directory, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    loaded = {line.rsplit("|", 1)[-1].strip() for line in done.stderr.splitlines() if line.startswith("import time:")}
    assert not {name for name in loaded if name.split(".")[0] == "numba" or name in HEAVY}, sorted(loaded & set(HEAVY))


#: the packages whose modules must not import each other round in a circle, function-level imports included
INNER_PACKAGES = ("engine", "solvers")
#: the one module that may import a GPU module without being one: the back-ends' construction
CHOOSES_THE_DEVICE = "colsim.engine.backends"


def is_gpu_module(module: str) -> bool:
    return module.rsplit(".", 1)[-1].startswith("cuda_")


def inner_graph(package: str) -> dict[str, set[str]]:
    """The imports (function-level ones too) between the modules of colsim.`package`."""
    prefix = f"colsim.{package}."
    return {module_name(p): {t for t in imports_of(p) if t.startswith(prefix)}
            for p in MODULES if module_name(p).startswith(prefix)}


def cycle_in(graph: dict[str, set[str]]) -> list[str] | None:
    """One import circle of `graph` (its modules in order, the first again at the end), or None."""
    done, stack = set(), []

    def visit(node):
        if node in stack:
            return stack[stack.index(node):] + [node]
        if node in done:
            return None
        stack.append(node)
        for target in sorted(graph.get(node, ())):
            found = visit(target)
            if found:
                return found
        stack.pop()
        done.add(node)
        return None

    for node in sorted(graph):
        found = visit(node)
        if found:
            return found
    return None


@pytest.mark.parametrize("package", INNER_PACKAGES)
def test_no_import_circle_inside_the_engine_or_the_solvers(package):
    """Every module of engine/ and solvers/ sits above the modules it imports, function-level imports
    included: the package's import graph has no circle (so no arrow points back up)."""
    assert cycle_in(inner_graph(package)) is None, " -> ".join(cycle_in(inner_graph(package)))


def test_no_cpu_module_imports_a_gpu_module():
    """The GPU wing (cuda_* modules) imports the CPU's records and scalar functions, never the reverse:
    a CPU module reaches the GPU only through the back-end chosen once (colsim.engine.backends)."""
    wrong = [(module_name(p), target) for p in MODULES for target in imports_of(p)
             if not is_gpu_module(module_name(p)) and module_name(p) != CHOOSES_THE_DEVICE and is_gpu_module(target)]
    assert not wrong, wrong


def test_the_circle_check_finds_a_circle():
    assert cycle_in({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert cycle_in({"a": {"b"}, "b": set()}) is None


def test_no_module_reads_the_cuda_simulator_switch():
    """numba's simulator is the tests' GPU: the tests turn it on (tests/cuda_simulator.py), and no
    module of colsim reads NUMBA_ENABLE_CUDASIM to behave otherwise (numba reads it itself)."""
    readers = [str(path.relative_to(PACKAGE)) for path in MODULES
               if any(isinstance(node, ast.Constant) and node.value == "NUMBA_ENABLE_CUDASIM"
                      for node in ast.walk(ast.parse(path.read_text())))]
    assert readers == []
