"""benchmarks/device_copies.py's redone step: it must be what its figures say, a step redone once whose
contacts are the train's two pairs and the cube's touching neighbours; its counts; and, counted by it,
every kernel launch of its stack's GPU steps through colsim.engine.cuda_launch.launch."""
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
from device_copies import redone_step  # noqa: E402

from colsim.engine.stepper import step  # noqa: E402
from colsim.solvers.apgd import ApgdSolver  # noqa: E402


def test_the_redone_step_is_redone_once_beside_the_cube():
    """A cube of 3^3 spheres has 54 neighbour pairs (3 axes x 9 lines x 2); with the train's
    C-A and the missed A-B, the redo has 56 contacts (the CPU's path: the scene, not the device)."""
    state, settings = redone_step(3)
    result = step(state, settings, ApgdSolver(tolerance=1e-8), 2)
    assert state.n == 3 + 27
    assert result.diagnostics.redone == 1 and result.diagnostics.missed_contacts == 1
    assert result.contacts.m == 2 + 54


def test_each_device_array_made_is_counted_with_its_bytes(monkeypatch):
    """counting_allocations: device_array, device_array_like and to_device each count one array with
    its bytes (by caller: here no colsim function, "elsewhere"); a copy into an array made before
    (to_device's `to`) makes none."""
    cuda = pytest.importorskip("numba.cuda")
    from device_copies import counting_allocations

    for name in ("device_array", "device_array_like", "to_device"):
        monkeypatch.setattr(cuda, name, getattr(cuda, name))   # put back after the test
    counts, sizes = counting_allocations()
    made = cuda.device_array(5)
    cuda.device_array_like(np.zeros((2, 3), dtype=np.int32))
    cuda.to_device(np.zeros(4))
    cuda.to_device(np.ones(5), to=made)
    assert counts == {"elsewhere": 3} and sizes == {"elsewhere": 5 * 8 + 6 * 4 + 4 * 8}


@pytest.mark.slow   # the CUDA simulator's longer runs, or studies end to end: `pytest -m slow`
def test_every_launch_of_a_collapse_step_goes_through_launch(monkeypatch):
    """A plain launch marshals each array anew (about 9 us an array on an H200, 29.5 us an empty
    launch against 10 through colsim.engine.cuda_launch.launch): the stack's GPU collapse steps,
    counted after two (the kernels then compiled: the second is the first to match a warm start),
    launch every kernel through launch(). On the simulator counting_launches counts them; on a GPU
    the launcher takes each launch but a kernel's with several overloads, or a kernel's one compiling
    launch (cuda_launch.plain_counts)."""
    pytest.importorskip("colsim.engine.cuda_operator", reason="numba.cuda is not importable")
    from numba.core import config as numba_config

    from colsim.engine import cuda_launch
    from colsim.engine.stepper import run
    from device_copies import counting_launches, stack

    from colsim.engine.backends import make_backend

    cuda = make_backend("cuda")
    results = run(*stack(), 4, ApgdSolver(backend=cuda), backend=cuda)
    next(results)
    next(results)
    if numba_config.ENABLE_CUDASIM:
        from numba.cuda.simulator import kernel

        monkeypatch.setattr(kernel.FakeCUDAKernel, "__call__", kernel.FakeCUDAKernel.__call__)   # put back after
    plain_before = dict(cuda_launch.plain_counts)
    launches = counting_launches()
    list(results)
    plain = {name: n - plain_before.get(name, 0) for name, n in cuda_launch.plain_counts.items()
             if n > plain_before.get(name, 0)}
    if launches is not None:   # the simulator: every launch the plain way, through launch()
        made = sum(counts["launches"] for counts in launches.values())
        assert made > 100   # two steps of detection, set-up and APGD's iterations
        assert sum(counts["through launch()"] for counts in launches.values()) == made
        assert sum(plain.values()) == made
    else:
        from colsim.engine import cuda_contacts, cuda_operator, cuda_state, cuda_warm_start
        from colsim.engine import cuda_apgd as apgd_cuda

        modules = (cuda_operator, cuda_contacts, cuda_state, cuda_warm_start, apgd_cuda)
        kernels = {name: getattr(m, name) for m in modules for name in plain if hasattr(m, name)}
        assert set(kernels) == set(plain), plain
        first_launched = set(plain) - set(plain_before)
        assert all(len(kernels[name].overloads) > 1 or (name in first_launched and plain[name] == 1)
                   for name in plain), plain
