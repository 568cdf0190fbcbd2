"""numba's CUDA simulator as colsim sets it up (tests/cuda_simulator.py): every thread of a
block gets the same shared array, and sees the simulator's cuda module in a device function,
however the threads interleave.

Without the lock, 32 threads asking at once (a 1 us switch interval) got two arrays in 24 of 200
trials on the project's 2-core Xeon; with it none can."""
import sys
import threading

import numpy as np
import pytest

kernelapi = pytest.importorskip("numba.cuda.simulator.kernelapi", reason="numba's simulator is not importable")
from numba import cuda  # noqa: E402

import cuda_simulator  # noqa: E402
from colsim.engine.cuda_apgd import _extrapolated  # noqa: E402
from colsim.engine.cuda_operator import THREADS, block_reduce  # noqa: E402


def test_threads_asking_at_once_share_one_shared_array():
    cuda_simulator.use()
    before = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)   # a switch between any two bytecodes, as often as can be
    try:
        for _ in range(50):
            shared = kernelapi.FakeCUDAShared(0)
            got = [None] * 32
            start = threading.Barrier(len(got))

            def ask(t):
                start.wait()
                got[t] = shared.array(128, np.float64)

            threads = [threading.Thread(target=ask, args=(t,)) for t in range(len(got))]
            for thread in threads:
                thread.start()
            for thread in threads:
                thread.join()
            assert len({id(array) for array in got}) == 1
            assert got[0].shape == (128,) and got[0].dtype == np.float64
    finally:
        sys.setswitchinterval(before)


def test_a_device_function_of_another_module_sees_the_simulator_in_every_thread():
    """128 threads call device functions of another module (colsim.engine.cuda_operator): first a
X
    cuda.syncthreads) twice, four rounds a launch, five launches, with a switch between any two
    bytecodes. Every call must
    see the simulator's cuda module, and the sums must come out right. numba's own swap lets the
    thread that swapped the module in for the plain one put numba.cuda back while others wait inside
    block_reduce: a simulated APGD solve failed so ("module 'numba.cuda' has no attribute
    'syncthreads'"), where the projection kernel calls wrench_on_device and then block_reduce.
    The race is rare: without the counted swap this test failed once in 19 runs here (2-core AMD
    EPYC), and the CUDA subset once; with it, neither has failed (13 runs of this test)."""
    cuda_simulator.use()
    before = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)
    try:
        values = np.arange(THREADS, dtype=np.float64)
        for _ in range(5):
            out = np.zeros(4)
            _four_sums[1, THREADS](np.repeat(values, 5), out)
            np.testing.assert_array_equal(out, values.sum() * np.arange(1, 5))
    finally:
        sys.setswitchinterval(before)


@cuda.jit
def _four_sums(values, out):
    """out[r] = (r + 1) sum(values[::5]), r = 0..3, by block_reduce in one block of THREADS threads, twice
    a round back to back (the second sum's cache is thread t's value again), each thread first reading
    its value values[5 t] through _extrapolated (beta 0) t % 5 + 1 times."""
    cache = cuda.shared.array(THREADS, dtype=np.float64)
    again = cuda.shared.array(THREADS, dtype=np.float64)
    t = cuda.threadIdx.x
    for r in range(4):
        value = 0.0
        for _ in range(t % 5 + 1):
            value = _extrapolated(values, values, 5 * t, 0.0)[0]
        cache[t] = value * (r + 1)
        again[t] = value * (r + 1)
        block_reduce(cache, t, False)
        block_reduce(again, t, False)
        if t == 0:
            out[r] = cache[0] if cache[0] == again[0] else -1.0
        cuda.syncthreads()
