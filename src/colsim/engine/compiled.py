"""numba (a dependency) for the kernels' modules: the module itself and prange, its parallel range.

The threading layer is chosen here, on import, before numba can start its threads: OpenMP where
numba has it, else its own workqueue, and Intel TBB last (LAYER_PRIORITY). numba's own order puts TBB
first, so merely installing a package that brings libtbb switched colsim's threads to TBB, where two
threads took turns and a collapse ran many times slower than on one thread (docs/performance.md,
"Where the time goes"). A user who sets NUMBA_THREADING_LAYER or
NUMBA_THREADING_LAYER_PRIORITY keeps that choice. Which layer a job ran on is logged at its start and
kept in its file (colsim.engine.threads.threading_layer)."""
from __future__ import annotations

import os

import numba

prange = numba.prange

#: numba's threading layers in colsim's order of preference
LAYER_PRIORITY = ("omp", "workqueue", "tbb")
#: the environment variables with which a user chooses the layer instead
USER_LAYER_SETTINGS = ("NUMBA_THREADING_LAYER", "NUMBA_THREADING_LAYER_PRIORITY")

if not any(name in os.environ for name in USER_LAYER_SETTINGS):
    numba.config.THREADING_LAYER_PRIORITY = list(LAYER_PRIORITY)
