"""benchmarks/device_copies.py's redone step: it must be what its figures say, a step redone once whose
contacts are the train's two pairs and the cube's touching neighbours."""
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
