"""Kernel launches whose array arguments are marshalled once.

numba-cuda's dispatcher marshals every argument anew at each launch: it types it, wraps it and
flattens a device array into its words (pointer, sizes, shape, strides), at a cost that grows with
the arrays a launch takes (benchmarks/gpu.py, `launch_costs`; docs/performance.md). An APGD iteration
is six launches with 44 arrays, so a small column's iteration was mostly this marshalling.

:func:`launch` is ``kernel[griddim, blockdim](*args)`` with each device array's words made at its
first launch and kept (weakly: they go with the array), and the scalars marshalled at each launch
by the kernel's own code, to the types it was compiled for. It takes the dispatcher's one compiled
overload, its function and numba-cuda's own marshalling (``_prepare_args``), then calls the launch
numba-cuda calls (``cuda.core.launch``): the same kernel on the same words, so the same bits. Where
any of that is not at hand (numba's simulator, a kernel not yet compiled or compiled for several
signatures, a host array, a debug or extended kernel, another numba-cuda) it launches the plain way.

:class:`Prepared` is one launch made again and again with the same arguments (APGD's trial step),
through :func:`launch` (docs/performance.md: what it saves, and what was tried and dropped).
"""
from __future__ import annotations

import collections
import contextlib
import weakref

#: False: every launch the plain way (:func:`plain_launches`)
enabled = True

#: launches made the plain way, by kernel name, since the process started: a kernel's first (it
#: compiles), and every one of a kernel with several overloads or an argument the launcher cannot
#: take (on numba's simulator, all of them); the card's tests read it
plain_counts: collections.Counter = collections.Counter()

#: dispatcher -> its _Launcher, or False where the plain way is the only way
_launchers: dict = {}


class _Launcher:
    """One compiled kernel's launches: numba-cuda's launch with its device arrays' words kept."""

    def __init__(self, kernel):
        from cuda.core import LaunchConfig
        from cuda.core import launch as core_launch
        from numba.cuda import types
        from numba.cuda._compat import CUDA_CORE_GE_1_0
        from numba.cuda.cudadrv import driver
        from numba.cuda.cudadrv.devicearray import DeviceNDArray
        from numba.cuda.typing.typeof import Purpose, typeof

        if kernel.debug or getattr(kernel, "extensions", None):
            raise TypeError("a debug or extended kernel")
        self._kernel = kernel
        self._function = kernel._codelibrary.get_cufunc().kernel
        self._types = tuple(kernel.argument_types)
        self._arrays = tuple(isinstance(t, types.Array) for t in self._types)
        self._integers = tuple(isinstance(t, types.Integer) for t in self._types)
        # a boolean or a tuple goes as given (cuda.core would pass an int for a bool at another width, and
        # ctypes takes no float for a tuple's integer): its value must type as the kernel's, else the plain way
        self._exact = tuple(isinstance(t, (types.Boolean, types.BaseTuple)) for t in self._types)
        self._stream = driver._to_core_stream(0)
        self._core_launch = core_launch
        self._device_array = DeviceNDArray
        self._typeof = lambda value: typeof(value, Purpose.argument)
        cooperative = {"is_cooperative" if CUDA_CORE_GE_1_0 else "cooperative_launch": kernel.cooperative}
        self._config = lambda griddim, blockdim: LaunchConfig(grid=(griddim, 1, 1), block=(blockdim, 1, 1),
                                                              shmem_size=0, **cooperative)
        self._configs: dict = {}
        self._words = weakref.WeakKeyDictionary()

    def __call__(self, griddim: int, blockdim: int, args) -> bool:
        """Launch on the default stream; False (nothing launched) where an argument is not what the
        kernel was compiled for, or not a device array where it takes an array."""
        words = self.words(args)
        if words is None:
            return False
        config = self._configs.get((griddim, blockdim))
        if config is None:
            config = self._configs[griddim, blockdim] = self._config(griddim, blockdim)
        self._core_launch(self._stream, config, self._function, *words)
        return True

    def words(self, args) -> list | None:
        """The kernel's parameters for `args`, as numba-cuda marshals them (an array's words kept from
        its first launch); None where an argument is not what the kernel was compiled for."""
        if len(args) != len(self._types):
            return None
        words = []
        for value, kind, is_array, is_integer, exact in zip(args, self._types, self._arrays, self._integers,
                                                            self._exact):
            if is_array:
                kept = self._words.get(value) if isinstance(value, self._device_array) else None
                if kept is None:
                    if not isinstance(value, self._device_array) or self._typeof(value) != kind:
                        return None
                    kept = []
                    self._kernel._prepare_args(kind, value, 0, [], kept)
                    self._words[value] = kept
                words.extend(kept)
            else:
                if is_integer:   # ctypes' integers take no float, not even 3.0
                    if value != int(value):
                        return None
                    value = int(value)
                elif exact and self._typeof(value) != kind:
                    return None
                self._kernel._prepare_args(kind, value, 0, [], words)
        return words


def _launcher(kernel):
    """The kernel's _Launcher, or None: not compiled yet, several overloads, or no such internals."""
    found = _launchers.get(kernel)
    if found is not None:
        return found or None
    overloads = getattr(kernel, "overloads", None)
    if overloads is None or getattr(kernel, "_launch_config_sensitive", False):
        _launchers[kernel] = False
        return None
    if len(overloads) != 1:
        return None
    try:
        found = _Launcher(next(iter(overloads.values())))
    except (AttributeError, ImportError, TypeError):
        found = False
    _launchers[kernel] = found
    return found or None


def launch(kernel, griddim: int, blockdim: int, *args) -> None:
    """kernel[griddim, blockdim](*args) on the default stream, device arrays' words kept (see the
    module's docstring); griddim and blockdim: one-dimensional."""
    launcher = _launcher(kernel) if enabled else None
    if launcher is None or not launcher(griddim, blockdim, args):
        plain_counts[getattr(getattr(kernel, "py_func", kernel), "__name__", "?")] += 1
        kernel[griddim, blockdim](*args)


@contextlib.contextmanager
def plain_launches():
    """Every launch inside the block the plain way, ``kernel[griddim, blockdim](*args)`` (to compare)."""
    global enabled
    before, enabled = enabled, False
    try:
        yield
    finally:
        enabled = before


class Prepared:
    """``kernel[griddim, blockdim](*args)`` as a call without arguments, for a launch made again and
    again with the same arguments (APGD's trial step), through :func:`launch`."""

    def __init__(self, kernel, griddim: int, blockdim: int, *args):
        self.kernel, self.griddim, self.blockdim, self.args = kernel, griddim, blockdim, args

    def __call__(self) -> None:
        launch(self.kernel, self.griddim, self.blockdim, *self.args)
