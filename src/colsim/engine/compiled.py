"""numba where it is installed (a dependency; the kernels fall back to plain Python loops without it):
HAVE_NUMBA, the module itself or None, and prange (numba's parallel range, or range)."""
from __future__ import annotations

try:
    import numba
except ImportError:  # pragma: no cover - numba is a dependency
    numba = None

HAVE_NUMBA = numba is not None
prange = numba.prange if HAVE_NUMBA else range
