"""The threads of one job: how many the compiled kernels (numba's parallel loops) run on.

One process, one setting: :func:`use_threads` at the start of a command (`--threads`, which the
workflow sets from each rule's `threads:`). The APGD kernels split their loops over contacts and
bodies across these threads and sum in as many fixed blocks, so a result depends on the thread
count only through the order of those sums (rounding, far below the solver's tolerance), and one
thread gives exactly the serial sums.
"""
from __future__ import annotations

import logging

from .compiled import HAVE_NUMBA, numba, prange   # noqa: F401 - prange for the kernels' modules

log = logging.getLogger(__name__)


def available_threads() -> int:
    """The most threads the kernels can use in this process (numba's NUMBA_NUM_THREADS, by default
    the machine's cores; 1 without numba)."""
    return int(numba.config.NUMBA_NUM_THREADS) if HAVE_NUMBA else 1


def use_threads(count: int) -> int:
    """Run the kernels on `count` threads (>= 1; at most :func:`available_threads`, with a warning
    if more were asked). Returns the count in use."""
    if int(count) != count or count < 1:
        raise ValueError(f"threads must be a whole number >= 1, got {count}")
    count = int(count)
    most = available_threads()
    if count > most:
        log.warning("%d threads asked, %d available: using %d", count, most, most)
        count = most
    if HAVE_NUMBA:
        numba.set_num_threads(count)
    return count


def threads() -> int:
    """The thread count the kernels use now."""
    return int(numba.get_num_threads()) if HAVE_NUMBA else 1
