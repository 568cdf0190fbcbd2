"""numba's CUDA simulator as colsim sets it up (colsim.engine.cuda_simulator): every thread of a
block gets the same shared array, however the threads interleave.

Without the lock, 32 threads asking at once (a 1 us switch interval) got two arrays in 24 of 200
trials on the project's 2-core Xeon; with it none can."""
import sys
import threading

import numpy as np
import pytest

kernelapi = pytest.importorskip("numba.cuda.simulator.kernelapi", reason="numba's simulator is not importable")
from colsim.engine import cuda_simulator  # noqa: E402


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
