"""numba where it is installed (a dependency; the kernels fall back to plain Python loops without it):
HAVE_NUMBA, the module itself or None, and prange (numba's parallel range, or range).

The threading layer is chosen here, on import, before numba can start its threads: OpenMP where
numba has it, else its own workqueue, and Intel TBB last (LAYER_PRIORITY). numba's own order puts TBB
first, so merely installing a package that brings libtbb switched colsim's threads to TBB, where two
threads took turns and a collapse ran many times slower than on one thread (issue 50;
docs/performance.md, "Threads"). A user who sets NUMBA_THREADING_LAYER or
NUMBA_THREADING_LAYER_PRIORITY keeps that choice. Which layer a job ran on is logged at its start and
kept in its file (colsim.engine.threads.threading_layer)."""
from __future__ import annotations

import os

try:
    import numba
except ImportError:  # pragma: no cover - numba is a dependency
    numba = None

HAVE_NUMBA = numba is not None
prange = numba.prange if HAVE_NUMBA else range

#: numba's threading layers in colsim's order of preference
LAYER_PRIORITY = ("omp", "workqueue", "tbb")
#: the environment variables with which a user chooses the layer instead
USER_LAYER_SETTINGS = ("NUMBA_THREADING_LAYER", "NUMBA_THREADING_LAYER_PRIORITY")

if HAVE_NUMBA and not any(name in os.environ for name in USER_LAYER_SETTINGS):
    numba.config.THREADING_LAYER_PRIORITY = list(LAYER_PRIORITY)
