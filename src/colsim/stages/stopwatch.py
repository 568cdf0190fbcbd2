"""The time a packing or a collapse has taken over all its sittings: wall seconds and CPU seconds.

A run resumed from its checkpoint starts its stopwatch from the saved figures, so the totals in its
output cover every sitting (a Snakemake benchmark file holds the last sitting's only). CPU time is
the process's, all its threads together: above the wall time when a run used several threads.
"""
from __future__ import annotations

import time


class Stopwatch:
    """Wall and CPU seconds since a run started; `wall` and `cpu`: what earlier sittings took
    (cpu NaN when a sitting's is unknown: a checkpoint written before CPU time was saved)."""

    def __init__(self, wall: float = 0.0, cpu: float = 0.0):
        self._wall_start = time.perf_counter() - wall
        self._cpu_start = time.process_time() - cpu

    def wall(self) -> float:
        """Wall-clock seconds over all sittings."""
        return time.perf_counter() - self._wall_start

    def cpu(self) -> float:
        """CPU seconds of the process (all threads) over all sittings; NaN when one is unknown."""
        return time.process_time() - self._cpu_start
