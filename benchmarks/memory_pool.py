"""A pool of device memory for numba-cuda, to measure what a step's allocations cost on a GPU.

    NUMBA_CUDA_MEMORY_MANAGER=benchmarks.memory_pool python -m benchmarks gpu --spheres --columns COLUMN.nc ...

(from the repository's root, or with it on PYTHONPATH: numba-cuda imports the module the variable
names when it makes its context; any command, `colsim collapse` too). A collapse step on the GPU makes
about 60 device arrays (`benchmarks device_copies`: 59.5 a step of the stack's collapse), each a
cuMemAlloc (43-51 us on an H200) and later a cuMemFree, which numba-cuda queues and frees ten at a
time; a free waits for the device. This plugin (numba-cuda's External Memory Management interface,
chosen by the environment variable above) keeps freed blocks instead, by size class, and hands them
out again: after the first steps a step allocates nothing from the driver. Only the device memory is
pooled (host memory stays numba-cuda's). Blocks are returned when numba-cuda drops an array; every
kernel and copy runs on the one default stream, so a block reused by a later launch is not touched
before the earlier ones that used it are done. The same kernels on the same data: the same bits.

An experiment for the GPU sittings (docs/gpu-record.md), not a part of colsim.
"""
from __future__ import annotations

import weakref
from collections import defaultdict

#: the smallest block (bytes); larger requests are rounded up to one of 16 steps between powers of two
SMALLEST = 512
STEPS = 16


def size_class(size: int) -> int:
    """The block size (bytes) that serves a request of `size` bytes: at least SMALLEST, else `size`
    rounded up to a multiple of 1/STEPS of the next power of two, so at most 1/8 more than asked for
    (a step's arrays differ from the last step's by a few contacts, and share their blocks)."""
    if size <= SMALLEST:
        return SMALLEST
    step = max((1 << (size - 1).bit_length()) // STEPS, 1)
    return -(-size // step) * step


class FreeLists:
    """Blocks kept by size class: :meth:`take` gives a kept block of the request's class, or one made
    by `make(bytes)`; :meth:`give` keeps a block again. `made` lists every block made, (block, bytes)."""

    def __init__(self, make):
        self.make, self.free, self.made = make, defaultdict(list), []

    def take(self, size: int):
        """(block, its class's bytes) for a request of `size` bytes."""
        bytes_ = size_class(size)
        spare = self.free[bytes_]
        if spare:
            return spare.pop(), bytes_
        block = self.make(bytes_)
        self.made.append((block, bytes_))
        return block, bytes_

    def give(self, block, bytes_: int) -> None:
        self.free[bytes_].append(block)

    def clear(self) -> list:
        """Forget every block; returns those made, (block, bytes), to be freed."""
        made, self.made = self.made, []
        self.free.clear()
        return made


def _manager_class():
    """The EMM plugin class (numba-cuda is imported only when the plugin is asked for)."""
    from numba import cuda
    from numba.cuda.cudadrv import driver as cuda_driver

    class PooledMemoryManager(cuda.HostOnlyCUDAMemoryManager):
        """numba-cuda's device allocations from :class:`FreeLists` of cuMemAlloc'd blocks."""

        def initialize(self):
            super().initialize()
            self.pool = FreeLists(cuda_driver.driver.cuMemAlloc)

        def memalloc(self, size):
            block, bytes_ = self.pool.take(size)
            pool = self.pool
            return cuda_driver.AutoFreePointer(weakref.proxy(self.context), block, bytes_,
                                               finalizer=lambda: pool.give(block, bytes_))

        def reset(self):
            super().reset()
            for block, _ in self.pool.clear():
                cuda_driver.driver.cuMemFree(block)

        def get_memory_info(self):
            free, total = cuda_driver.driver.cuMemGetInfo()
            return cuda.MemoryInfo(free=free, total=total)

        def get_ipc_handle(self, memory):
            raise NotImplementedError("the pool's blocks are not shared between processes")

        @property
        def interface_version(self):
            return 1

    return PooledMemoryManager


def __getattr__(name):   # numba-cuda reads _numba_memory_manager when the variable names this module
    if name == "_numba_memory_manager":
        return _manager_class()
    raise AttributeError(name)
