"""benchmarks/gpu_machine.sh, the prepared call for a machine with one NVIDIA GPU, run whole on numba's
CUDA simulator on a 29-sphere column (issue 83: each prepared call tested on a tiny column): its stage
"rest" (a column's collapse on the GPU, its analysis and its steps by phase) and its stage "pour" from
a packing an earlier call left (the trim, the collapse and the analysis), the logs and analyses it
returns in rest.tgz and pour.tgz, and the trimmed columns it returns for a later call on another
machine, which collapses one instead of pouring. The pour itself is tests/stages/test_pack.py's (a
pour to rest takes the simulator many minutes)."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tarfile
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

ROOT = Path(__file__).resolve().parents[2]

#: a collapse of two steps (the simulator runs about 15 s a step here), no rest test beyond them
COLLAPSE = {"duration": 0.008, "frame_every": 1, "friction_law": "associated", "friction_tolerance": None,
            "mu": 0.577, "mu_r": 0.12, "rest": {"max_duration": 0.008, "rest_energy": 0.01, "rest_tolerance": 0.1,
                                                 "rest_window": 0.004},
            "rolling_lever": "paper", "solver": "auto", "solver_overlap_tolerance": None, "steps": 2}
PACK = {"density": 1.0, "diameter_max": 0.5, "diameter_min": 0.25, "gravity": 9.81, "height": 0.8,
        "pack": {"dt": 0.02, "max_steps": 5000, "mu": 0.0, "rest_energy": 0.001}, "r0": 0.8, "root_seed": 2024,
        "seed": 1, "solver": "auto"}


def _colsim(*args, cwd) -> None:
    done = subprocess.run([sys.executable, "-m", "colsim.cli", "-q", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]


@pytest.fixture
def machine(tmp_path) -> Path:
    """A working copy as the GPU's machine gets it: the repository's folders, and a .gpu/ as
    benchmarks/gpu_prepare.sh lays it out, with a 29-sphere column (r0 = 0.8, a = 1) to collapse and,
    for the pour, the packing a call before left in results/gpu-pour; `python3` is this Python."""
    for name in ("src", "benchmarks", "tests"):
        (tmp_path / name).symlink_to(ROOT / name)
    rest, pour, poured = tmp_path / ".gpu" / "rest", tmp_path / ".gpu" / "pour", tmp_path / "results" / "gpu-pour" / "tiny"
    for folder in (rest, pour, poured, tmp_path / "bin"):
        folder.mkdir(parents=True)
    (tmp_path / "bin" / "python3").symlink_to(sys.executable)
    _colsim("pack", "--r0", "0.8", "--height", "0.8", "--seed", "1", "--output", str(poured / "packing.nc"), cwd=tmp_path)
    _colsim("trim", "--input", str(poured / "packing.nc"), "--aspect-ratio", "1", "--output", str(rest / "tiny.nc"),
            cwd=tmp_path)
    for path, settings in ((rest / "tiny.settings.yaml", COLLAPSE), (pour / "tiny.collapse.yaml", COLLAPSE),
                           (pour / "tiny.pack.yaml", PACK)):
        path.write_text(json.dumps(settings))
    return tmp_path


def _analysis(archive: Path, member: str) -> xr.Dataset:
    """The analysis file `member` of a returned archive."""
    path = archive.parent / Path(member).name
    with tarfile.open(archive) as tar:
        path.write_bytes(tar.extractfile(member).read())
    return xr.load_dataset(path)


@pytest.mark.slow
def test_the_gpu_call_collapses_analyses_and_returns_its_files_on_the_simulator(machine):
    """STAGES="rest pour": the column's collapse and the pour's trim and collapse each run to their end
    on the (simulated) GPU and are analysed; rest.tgz and pour.tgz hold each run's log and analysis
    (finite height and run-out, 29 spheres); the trimmed column comes back without its contact forces,
    and one at TRAVEL_ASPECTS' a = 0.5; and on a machine without the packing, a later call collapses
    the returned column instead of pouring. The script says what it did, never "failed"."""
    results = machine / "out"
    done = _call(machine, results, STAGES="rest pour", TRAVEL_ASPECTS="0.5")
    assert "tiny: poured in an earlier call" in done.stdout and "tiny: trim and collapse" in done.stdout
    assert "| tiny.nc | 29 | 2 |" in done.stdout   # the rest stage's steps by phase
    for archive, folder, log in (("rest.tgz", "rest-out", "tiny.log"), ("pour.tgz", "pour-out", "tiny.collapse.log")):
        with tarfile.open(results / archive) as tar:
            assert f"{folder}/{log}" in tar.getnames()
        _check_analysis(results / archive, f"{folder}/tiny.analysis.nc")
    travelling = {a: xr.load_dataset(results / f"tiny.a{a}.column.nc") for a in ("1", "0.5")}
    assert travelling["1"].sizes["particle"] == 29 and "contact_force" not in travelling["1"]
    assert 0 < travelling["0.5"].sizes["particle"] < 29

    # another machine: no packing there, the column the first call returned in .gpu/pour/
    shutil.rmtree(machine / "results")
    shutil.copy(results / "tiny.a1.column.nc", machine / ".gpu" / "pour")
    again = machine / "again"
    done = _call(machine, again, STAGES="pour")
    assert "tiny: the column of an earlier call (.gpu/pour/tiny.a1.column.nc)" in done.stdout
    assert "tiny: pour" not in done.stdout
    _check_analysis(again / "pour.tgz", "pour-out/tiny.analysis.nc")


def _call(machine: Path, results: Path, **settings) -> subprocess.CompletedProcess:
    """bash benchmarks/gpu_machine.sh on the simulator with `settings` (environment variables), its
    records into `results`; it exits 0 and says no step failed."""
    # no PYTHONPATH from the tests: the script sets up the simulator's processes itself, as a user's shell runs it
    env = {**{name: value for name, value in os.environ.items() if name != "PYTHONPATH"},
           "PATH": f"{machine / 'bin'}:{os.environ['PATH']}", "NUMBA_ENABLE_CUDASIM": "1", "POUR_NAMES": "tiny",
           "POUR_ASPECT": "1", "REST_LIMIT": "600", "POUR_LIMIT": "600", "COLSIM_BENCHMARK_RESULTS": str(results),
           **settings}
    done = subprocess.run(["bash", "benchmarks/gpu_machine.sh"], cwd=machine, env=env, capture_output=True, text=True,
                          timeout=1200)
    assert done.returncode == 0, (done.stdout + done.stderr)[-3000:]
    assert "failed" not in done.stdout, done.stdout[-3000:]
    return done


def _check_analysis(archive: Path, member: str) -> None:
    """The analysis `member` of a returned archive is the 29-sphere column's, with a finite deposit."""
    analysis = _analysis(archive, member)
    assert int(analysis.n_particles) == 29
    assert np.isfinite(float(analysis.h_inf_over_r0)) and np.isfinite(float(analysis.runout_over_r0))
