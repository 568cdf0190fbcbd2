"""`--device cuda` (issue 46.5): APGD's iterations of pack and collapse on one GPU, here on numba's
CUDA simulator (conftest sets NUMBA_ENABLE_CUDASIM=1). The rest of a step stays on the CPU, so the
GPU's collapse takes the CPU's steps with the same solver: the same iterations and, up to the
rounding of its sums, the same deposit."""
from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest
import xarray as xr

from colsim import io


def _gpu_outside_the_simulator() -> bool:
    """Whether numba.cuda sees a GPU once the simulator is off (a subprocess: numba reads it at import)."""
    probe = "from colsim.engine.backends import gpu_visible; print(gpu_visible())"
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                          env={**os.environ, "NUMBA_ENABLE_CUDASIM": "0"})
    return done.stdout.strip() == "True"


def colsim(*args, cwd, simulator: bool = True):
    env = {**os.environ, "NUMBA_ENABLE_CUDASIM": "1" if simulator else "0"}
    return subprocess.run([sys.executable, "-m", "colsim.cli", "-q", *args], cwd=cwd, capture_output=True,
                          text=True, timeout=900, env=env)


@pytest.fixture(scope="module")
def column(tmp_path_factory):
    """A 27-sphere column (r0 = 0.8, a = 1)."""
    folder = tmp_path_factory.mktemp("device")
    for args in (["pack", "--r0", "0.8", "--height", "0.8", "--seed", "1", "--output", "pack.nc"],
                 ["trim", "--input", "pack.nc", "--aspect-ratio", "1", "--output", "column.nc"]):
        assert colsim(*args, cwd=folder).returncode == 0
    return folder


@pytest.mark.slow
def test_a_collapse_on_the_gpu_takes_the_cpu_s_steps(column):
    """4 steps at dt/sqrt(h0/g) = 0.004 (the simulator runs about 0.5 s an iteration, each GPU thread
    a Python thread: 80 iterations here, 50 s; 20 steps would take over 3 minutes): the same
    iterations a step, and the end positions within 1e-9 of a diameter (measured: equal; both stop at
    the same check, and the GPU's sums differ from the CPU's by rounding only)."""
    runs = {}
    for device in ("cpu", "cuda"):
        done = colsim("collapse", "--input", "column.nc", "--steps", "4", "--duration", "0.016", "--device", device,
                      "--output", f"{device}.nc", cwd=column)
        assert done.returncode == 0, done.stderr[-2000:]
        runs[device] = io.open_dataset(column / f"{device}.nc", io.TRAJECTORY_KIND)
    cpu, gpu = runs["cpu"], runs["cuda"]
    np.testing.assert_array_equal(gpu.step_solver_iterations.values, cpu.step_solver_iterations.values)
    assert set(gpu.step_solver_backend.values) == {"apgd"}
    diameter = 2 * float(cpu.radius.mean())
    end = [run.position.isel(time=-1).values for run in (cpu, gpu)]
    assert np.abs(end[0] - end[1]).max() <= 1e-9 * diameter
    assert '"device": "cuda"' in gpu.attrs["config"] and '"kernel": "cuda"' in gpu.attrs["config"]


@pytest.mark.slow
def test_a_collapse_stored_in_float32_on_the_gpu_stops_where_float64_does(column):
    """--gpu-storage float32, 2 steps beside float64's (the first test's first two): every step by
    APGD, to its tolerance checked in float64, so the end positions agree within what the stopping rule
    admits (a step's velocities to its primal tolerance over its length, 1e-4 d of overlap under auto, a
    step: 2e-4 d over two); the file records the storage in the solver's settings."""
    runs = {}
    for storage in ("float64", "float32"):
        done = colsim("collapse", "--input", "column.nc", "--steps", "2", "--duration", "0.008", "--device", "cuda",
                      "--gpu-storage", storage, "--output", f"{storage}.nc", cwd=column)
        assert done.returncode == 0, done.stderr[-2000:]
        runs[storage] = io.open_dataset(column / f"{storage}.nc", io.TRAJECTORY_KIND)
    wide, narrow = runs["float64"], runs["float32"]
    assert set(narrow.step_solver_backend.values) == {"apgd"}
    diameter = 2 * float(wide.radius.mean())
    end = [run.position.isel(time=-1).values for run in (wide, narrow)]
    assert np.abs(end[0] - end[1]).max() <= 2e-4 * diameter
    assert '"storage": "float32"' in narrow.attrs["config"] and '"gpu_storage": "float32"' in narrow.attrs["config"]
    assert '"storage"' not in wide.attrs["config"].replace('"gpu_storage"', "")


def test_device_auto_runs_a_small_column_on_the_cpu_and_records_it(column):
    """--device auto (issue 46.5) on a 27-sphere column, far below GPU_FROM_SPHERES: APGD's compiled
    CPU kernels, and the file records the device that ran, cpu."""
    done = colsim("collapse", "--input", "column.nc", "--steps", "2", "--duration", "0.008", "--device", "auto",
                  "--output", "auto.nc", cwd=column)
    assert done.returncode == 0, done.stderr[-2000:]
    config = xr.load_dataset(column / "auto.nc").attrs["config"]
    assert '"device": "cpu"' in config and '"kernel": "numba"' in config


def test_a_gpu_storage_that_auto_leaves_on_the_cpu_is_dropped_on_record(column):
    """Issue 80.5: --device auto --gpu-storage float32 on a column the CPU runs: a warning, and the file
    records the float64 that the CPU stored, never float32."""
    done = colsim("collapse", "--input", "column.nc", "--steps", "2", "--duration", "0.008", "--device", "auto",
                  "--gpu-storage", "float32", "--output", "auto32.nc", cwd=column)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "--gpu-storage float32 does nothing here" in done.stderr
    config = xr.load_dataset(column / "auto32.nc").attrs["config"]
    assert '"gpu_storage": "float64"' in config and "float32" not in config


@pytest.mark.parametrize("extra, simulator, words", [
    (["--solver", "clarabel", "--device", "cuda"], True, ["--device cuda", "APGD's", "--solver clarabel"]),
    (["--device", "cuda"], False, ["needs a CUDA GPU", "NUMBA_ENABLE_CUDASIM"]),
    (["--device", "tpu"], True, ["--device", "invalid choice", "tpu"]),   # argparse's quotes vary by Python
    (["--solver", "clarabel", "--gpu-storage", "float32"], True, ["--gpu-storage float32", "APGD's", "--solver clarabel"]),
    (["--gpu-storage", "float16"], True, ["--gpu-storage", "invalid choice", "float16"]),
    # issue 80.5: the CPU stores float64; the file recorded float32
    (["--gpu-storage", "float32"], True, ["--gpu-storage float32 is a GPU's storage", "would do nothing"]),
])
def test_a_device_colsim_cannot_use_is_refused_in_one_line(column, extra, simulator, words):
    if not simulator and _gpu_outside_the_simulator():
        pytest.skip("this machine has a GPU: --device cuda runs")
    done = colsim("collapse", "--input", "column.nc", "--steps", "2", *extra, "--output", "x.nc", cwd=column,
                  simulator=simulator)
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr[-2000:]
    last = done.stderr.strip().splitlines()[-1]
    assert all(word in last for word in words), last
    assert not (column / "x.nc").exists()
