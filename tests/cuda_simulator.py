"""numba's CUDA simulator (NUMBA_ENABLE_CUDASIM=1, the tests' GPU), made faster and safe for its many
threads; nothing here runs on a GPU. conftest.py applies it to the tests' process, and
simulator_site/sitecustomize.py to the processes they start (the `colsim` command, the benchmarks).

The simulator runs each GPU thread of a block as a Python thread.

- Its block manager polls them in a loop that holds the GIL for a whole switch interval (5 ms by
  default) whenever a thread waits for it: most of the simulator's time. At 0.1 ms the kernels ran
  about 3x faster (the 30-iteration APGD test 59 -> 20 s on the project's 2-core Xeon).
- It makes a block's shared array when the first thread asks for it and hands it to the others,
  with nothing to stop two threads from asking at once. Both then make one, and a tree sum mixes
  the two (a CI run's dot product came out 1.2e49). A shorter switch interval makes that likelier;
  :func:`use` has them made as the simulator makes them, but under a lock.
- A device function sees the simulator's `cuda` (syncthreads, shared arrays) because each call
  swaps it into its module's globals and puts numba.cuda back on return. With many threads in one
  device function at once, the thread that swapped can put numba.cuda back while another is about
  to call cuda.syncthreads (a simulated APGD solve failed so: "module 'numba.cuda' has no attribute
  'syncthreads'"). :func:`use` has the swap counted under the lock: made by the first thread in,
  undone by the last one out.
"""
from __future__ import annotations

import contextlib
import sys
import threading
import traceback

import numpy as np
from numba.core import types
from numba.np import numpy_support

#: the switch interval while the simulator runs (seconds; Python's default is 0.005)
SWITCH_INTERVAL = 1e-4

_lock = threading.Lock()


def use() -> None:
    """Set the switch interval, and guard the making of shared arrays and the swap of a device
    function's cuda module (once a process is enough)."""
    from numba.cuda.simulator import kernelapi

    sys.setswitchinterval(SWITCH_INTERVAL)
    if getattr(kernelapi.FakeCUDAShared.array, "guarded", False):
        return
    plain = kernelapi.FakeCUDAShared.array

    def array(self, shape, dtype):
        """numba's FakeCUDAShared.array (one array per calling line a launch), made under a lock."""
        if shape == 0:   # dynamic shared memory: one buffer, nothing made
            return plain(self, shape, dtype)
        caller = tuple(traceback.extract_stack(sys._getframe())[-2][0:2])
        with _lock:
            made = self._allocations.get(caller)
            if made is None:
                made = self._allocations[caller] = plain_array(shape, dtype)
        return made

    array.guarded = True
    kernelapi.FakeCUDAShared.array = array
    from numba.cuda.simulator import kernel

    kernelapi.swapped_cuda_module = kernel.swapped_cuda_module = swapped_cuda_module


#: the modules' globals whose numba.cuda is swapped now, by id: [threads inside, the names swapped]
_swapped: dict = {}


@contextlib.contextmanager
def swapped_cuda_module(fn, fake_cuda_module):
    """numba's swapped_cuda_module (fn's module sees `fake_cuda_module` for numba.cuda while a thread
    runs it), counted: the first thread in swaps, the last one out puts numba.cuda back."""
    from numba import cuda

    names = fn.__globals__
    with _lock:
        entry = _swapped.get(id(names))
        if entry is None:
            real = {name: value for name, value in names.items() if value is cuda}
            names.update({name: fake_cuda_module for name in real})
            entry = _swapped[id(names)] = [0, real]
        entry[0] += 1
    try:
        yield
    finally:
        with _lock:
            entry[0] -= 1
            if entry[0] == 0:
                names.update(entry[1])
                del _swapped[id(names)]


def plain_array(shape, dtype):
    """An uninitialised array as the simulator makes one (numba types turned into numpy dtypes)."""
    if isinstance(dtype, types.Type):
        dtype = numpy_support.as_dtype(dtype)
    return np.empty(shape, dtype)
