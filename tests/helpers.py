"""Helpers shared by the tests: the session pile's settings (conftest, engine/test_pile), and for the
workflow tests (test_workflow, test_slurm) a copy of the workflow, a snakemake run in it, the jobs a
dry run plans and the names of the tiny study's files."""
from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np

from colsim import io
from colsim.cli import main
from colsim.engine.state import ContactLaw, ParticleState
from colsim.study.collect import SUMMARY_VARIABLES
from colsim.study.figure_names import FIGURES

__all__ = ["CF_UNITS", "COLLAPSE_LAW", "DT", "FIGURES", "G", "PACKING_R0", "ROOT", "SUMMARY_VARIABLES", "TINY",
           "assert_cf_units", "cf_check_failures", "copy_workflow", "main_in", "tiny_state_files", "max_speed", "planned_outputs", "snakemake"]

# the session pile (conftest.pile): gravity, time step, and the friction that locks it and collapses it
G = 9.81
DT = 0.02
COLLAPSE_LAW = ContactLaw.uniform(0.577, 0.12)

ROOT = Path(__file__).resolve().parents[1]
WORKFLOW_FILES = ("Snakefile", "config.yaml", "config", "workflow", "profiles")
#: where the tiny study (config/tiny.yaml, study: tiny) writes its summary, tables and figures
TINY = "results/tiny"


def max_speed(state: ParticleState) -> float:
    """Largest translational speed (length/time)."""
    return float(np.linalg.norm(state.velocity, axis=1).max(initial=0.0))


def copy_workflow(directory: Path) -> Path:
    """Copy the workflow's files (not results/) into `directory`; return it."""
    for name in WORKFLOW_FILES:
        source = ROOT / name
        if source.is_dir():
            shutil.copytree(source, directory / name)
        else:
            shutil.copy2(source, directory / name)
    return directory


def snakemake(directory: Path, *arguments, timeout=600) -> subprocess.CompletedProcess:
    """Run snakemake in `directory` with the interpreter's bin directory first on PATH (for `colsim`)."""
    env = dict(os.environ)
    env["PATH"] = os.pathsep.join([str(Path(sys.executable).parent), env.get("PATH", "")])
    env.setdefault("MPLBACKEND", "Agg")
    return subprocess.run([sys.executable, "-m", "snakemake", *arguments], cwd=directory, env=env,
                          capture_output=True, text=True, timeout=timeout)


def planned_outputs(result: subprocess.CompletedProcess) -> list[str]:
    """Output files of the jobs a dry run (snakemake -n) would run."""
    outputs = []
    for line in result.stdout.splitlines() + result.stderr.splitlines():
        line = line.strip()
        if line.startswith("output:"):
            outputs += [p.strip() for p in line[len("output:"):].split(",")]
    return outputs


RUN_PATH = re.compile(r"results/r0_(?P<r0>[^/]+)/seed_(?P<seed>\d+)/pack_(?P<packing>[0-9a-f]{10})"
                      r"/a_(?P<a>[^/]+)/mu_r_(?P<mu_r>[^/]+)/run_(?P<run>[0-9a-f]{10})/collapse\.nc")


SETTINGS_LINE = re.compile(r"printf '%s\\n' '(?P<text>\{.*\})' > (?P<path>\S+)\.tmp ")


def planned_settings(result: subprocess.CompletedProcess) -> dict[str, dict]:
    """{path: settings} of the settings.yaml files a dry run with -p would write (their text is
    in the settings rules' command lines)."""
    return {match.group("path"): json.loads(match.group("text"))
            for match in map(SETTINGS_LINE.search, result.stdout.splitlines()) if match}


def planned_collapses(result: subprocess.CompletedProcess) -> list[dict]:
    """The collapses of a dry run with -p: for each, the parts of its folder (r0, seed, packing, a,
    mu_r, run: strings), its `path`, its `command` line and the `settings` its settings.yaml will
    hold (None where that file exists already)."""
    settings = planned_settings(result)
    found = []
    for line in result.stdout.splitlines():
        if "colsim collapse" in line:
            match = RUN_PATH.search(line.split("--output", 1)[1])
            folder = match.group(0).rsplit("/", 1)[0]
            found.append({**match.groupdict(), "path": match.group(0), "command": line,
                          "settings": settings.get(f"{folder}/settings.yaml")})
    return found


def cf_check_failures(path, checker: str = "cf:1.8") -> list[str]:
    """What the IOOS compliance checker (an independent CF checker, offline) finds wrong with the
    netCDF file `path` at any priority (`--criteria strict`: errors, warnings and suggestions); a check
    that raised is a failure too."""
    from compliance_checker.base import BaseCheck
    from compliance_checker.suite import CheckSuite

    suite = CheckSuite()
    with warnings.catch_warnings():   # the checker's own deprecations (of its SOS checkers) are not ours
        warnings.simplefilter("ignore", DeprecationWarning)
        suite.load_all_available_checkers()
    dataset = suite.load_dataset(str(path))
    try:
        results, raised = suite.run_all(dataset, [checker], skip_checks=[])[checker]
    finally:
        dataset.close()
    failures = [f"{name} raised {error}" for name, error in raised.items()]
    for result in results:
        passed = result.value[0] == result.value[1] if isinstance(result.value, tuple) else bool(result.value)
        if passed or result.weight < BaseCheck.LOW:   # --criteria strict: low priority counts too
            continue
        failures.append(f"{result.name}: {'; '.join(result.msgs) or 'failed'}")
    return failures


#: the cylinder radius of the stage tests' packing (conftest.packing)
PACKING_R0 = 1.5

#: every unit colsim writes: UDUNITS strings (SI, with g = 9.81 m s-2) and "1"
CF_UNITS = set(io.SI_UNITS.values()) | {"1", "s"}


def assert_cf_units(dataset):
    """Every variable and coordinate of `dataset` has a long_name and units colsim writes (CF:
    UDUNITS strings; "1" for dimensionless numbers and text)."""
    for name, variable in dataset.variables.items():
        assert variable.attrs.get("long_name"), name
        assert variable.attrs.get("units") in CF_UNITS, (name, variable.attrs.get("units"))


def tiny_state_files(directory):
    """pack.nc (two stacked spheres of diameter 0.5, r0 = 1) and column.nc (the same, h0 = 1)."""
    state = ParticleState.at_rest([[0, 0, 0.25], [0, 0, 0.75]], [0.25, 0.25])
    io.write_state(directory / "pack.nc", state, {**io.global_attributes(io.STATE_KIND, "t", {}), "r0": 1.0})
    io.write_state(directory / "column.nc", state,
                   {**io.global_attributes(io.STATE_KIND, "t", {}), "r0": 1.0, "h0": 1.0, "aspect_ratio": 1.0,
                    "solid_fraction": 0.1})


def main_in(directory, args):
    cwd = os.getcwd()
    os.chdir(directory)
    try:
        return main(args)
    finally:
        os.chdir(cwd)
