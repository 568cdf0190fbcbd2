"""The step's back-ends by device: the one place that chooses where a step runs.

:func:`make_backend` turns a stage's `device` setting ('cpu' or 'cuda'; 'auto' is resolved before,
by :func:`colsim.stages.devices.device_for`) into a :class:`colsim.engine.backend.Backend`. The
CUDA back-end (and numba.cuda with it) is imported here alone, and only when asked for.
"""
from __future__ import annotations

from .backend import Backend, CpuBackend

#: the devices a back-end is made for
DEVICES = ("cpu", "cuda")


def make_backend(device: str) -> Backend:
    """The back-end of `device`, 'cpu' or 'cuda' (one GPU, or numba's simulator where it is on).
    ValueError for another name, or 'cuda' where no GPU is visible and the simulator is off."""
    if device not in DEVICES:
        raise ValueError(f"unknown device {device!r}: choose one of {', '.join(DEVICES)}")
    if device == "cpu":
        return CpuBackend()
    from .cuda_operator import cuda   # numba.cuda behind the numpy 2.5 guard

    if not cuda.is_available():
        raise ValueError("device cuda needs a CUDA GPU (none is visible here) or numba's simulator "
                         "(NUMBA_ENABLE_CUDASIM=1)")
    from .cuda_backend import CudaBackend

    return CudaBackend()


def gpu_visible() -> bool:
    """Whether numba.cuda sees a CUDA GPU (False on numba's simulator, or where numba.cuda is missing)."""
    from numba.core import config

    try:
        from .cuda_operator import cuda
    except ImportError:
        return False
    return not config.ENABLE_CUDASIM and cuda.is_available()
