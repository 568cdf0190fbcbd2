"""The threads of one job: how many the compiled kernels (numba's parallel loops) run on.

One process, one setting: :func:`use_threads` at the start of a command (`--threads`, which the
workflow sets from each rule's `threads:`). The APGD kernels split their loops over contacts and
bodies across these threads and sum in as many fixed blocks, so a result depends on the thread
count only through the order of those sums (rounding, far below the solver's tolerance), and one
thread gives exactly the serial sums.

A job whose threads are as many as the CPUs it may run on (a whole machine, or a cluster job's
allocation) has them pinned one to a CPU (OpenMP's OMP_PROC_BIND=true), unless the user set
OpenMP's binding: unpinned, two threads on two cores lost up to half their speed to moves between
the cores (docs/performance.md, "Where the time goes").

The threads run on numba's OpenMP layer where it has one (:mod:`colsim.engine.compiled` chooses it,
not numba's TBB-first default); :func:`threading_layer` says which, once they have started.
"""
from __future__ import annotations

import logging
import os
import sys
from pathlib import Path

from .compiled import numba, prange   # noqa: F401 - prange for the kernels' modules

log = logging.getLogger(__name__)


def available_threads() -> int:
    """The most threads the kernels can use in this process (numba's NUMBA_NUM_THREADS, by default
    the machine's cores)."""
    return int(numba.config.NUMBA_NUM_THREADS)


def pins_threads(count: int, cpus: int, environ) -> bool:
    """Whether `count` threads on a process allowed `cpus` CPUs are pinned one to a CPU: only when
    they fill those CPUs (so no other job of ours shares them) and `environ` sets no OpenMP binding
    (OMP_PROC_BIND, OMP_PLACES) of its own."""
    return 1 < count == cpus and "OMP_PROC_BIND" not in environ and "OMP_PLACES" not in environ


def allowed_cpus() -> int:
    """The CPUs this process may run on (its affinity; the machine's count where that is unknown)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:   # pragma: no cover - macOS and Windows have no affinity call
        return os.cpu_count() or 1


def use_threads(count: int) -> int:
    """Run the kernels on `count` threads (>= 1; at most :func:`available_threads`, with a warning
    if more were asked), pinned one to a CPU where :func:`pins_threads` says so (it takes effect
    when numba's OpenMP threads start, at the process's first call). Returns the count in use."""
    if int(count) != count or count < 1:
        raise ValueError(f"threads must be a whole number >= 1, got {count}")
    count = int(count)
    most = available_threads()
    if count > most:
        log.warning("%d threads asked, %d available: using %d", count, most, most)
        count = most
    if pins_threads(count, allowed_cpus(), os.environ):
        os.environ["OMP_PROC_BIND"] = "true"
        log.info("%d threads, one to each CPU this job may use (OMP_PROC_BIND=true)", count)
    try:
        numba.set_num_threads(count)    # starts numba's threads, on the layer compiled.py chose
    except ValueError as error:         # numba: "No threading layer could be loaded" and a hint
        raise ValueError(layer_failure(str(error))) from None
    log.info("--threads %d on numba's %s threading layer", count, threading_layer())
    return count


def layer_failure(message: str) -> str:
    """One line saying why numba could not start its threads (its own `message` is several lines,
    and where TBB was asked for it says "pip install tbb" even where tbb is installed): for TBB, the
    library its loader failed to open, where the tbb package put it, and how to point the loader at
    it (or leave NUMBA_THREADING_LAYER unset: OpenMP)."""
    asked = os.environ.get("NUMBA_THREADING_LAYER", "")
    if "tbb" not in asked.lower() and "TBB" not in message:
        return f"numba could not start its threads: {' '.join(message.split())}"
    try:
        import numba.np.ufunc.tbbpool  # noqa: F401  (the layer's extension: its ImportError says why)
        why = "its TBB layer loads, yet numba refused it (TBB older than numba needs?)"
    except ImportError as error:
        why = str(error)
    found = sorted(Path(sys.prefix, "lib").glob("libtbb.so*")) + sorted(Path(sys.prefix, "lib").glob("libtbb*.dylib"))
    variable = "DYLD_LIBRARY_PATH" if sys.platform == "darwin" else "LD_LIBRARY_PATH"
    where = (f"the tbb package's library is in {found[0].parent}, where the loader does not look: export"
             f" {variable}={found[0].parent}" if found else "install tbb (pip install tbb) and point"
             f" {variable} at the folder of its libtbb")
    return (f"numba cannot load its TBB threading layer (NUMBA_THREADING_LAYER={asked or 'unset'}): {why}; {where},"
            " or unset NUMBA_THREADING_LAYER to run on OpenMP")


def threading_layer() -> str:
    """The threading layer numba's threads run on ('omp', 'workqueue' or 'tbb'), 'not started'
    before :func:`use_threads` (or a kernel) has started them."""
    try:
        return str(numba.threading_layer())
    except ValueError:   # no thread started yet
        return "not started"


def threads() -> int:
    """The thread count the kernels use now."""
    return int(numba.get_num_threads())
