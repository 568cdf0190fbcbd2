"""The time a packing or a collapse has taken over all its segments: wall seconds and CPU seconds.

A segment is the stretch of a run that one process makes, from its start or a resume to the run's
end or the process's. A run resumed from its checkpoint starts its stopwatch from the saved figures,
so the totals in its output cover every segment (a Snakemake benchmark file holds the last segment's only). CPU time is
the process's, all its threads together: above the wall time when a run used several threads.
"""
from __future__ import annotations

import time

#: a run also writes its checkpoint once this much wall time (s) has passed since its last one (or
#: since its segment began), whatever its checkpoint_every: a segment cut off then loses at most this
#: much work: a large pour's settling steps can take a minute each, so its checkpoint_every steps
#: can be many minutes.
CHECKPOINT_INTERVAL_S = 600.0


class Stopwatch:
    """Wall and CPU seconds since a run started; `wall` and `cpu`: what earlier segments took
    (cpu NaN when a segment's is unknown: a checkpoint written before CPU time was saved)."""

    def __init__(self, wall: float = 0.0, cpu: float = 0.0):
        self._wall_start = time.perf_counter() - wall
        self._cpu_start = time.process_time() - cpu
        self._saved = time.perf_counter()

    def wall(self) -> float:
        """Wall-clock seconds over all segments."""
        return time.perf_counter() - self._wall_start

    def cpu(self) -> float:
        """CPU seconds of the process (all threads) over all segments; NaN when one is unknown."""
        return time.process_time() - self._cpu_start

    def checkpoint_due(self, step_due: bool) -> bool:
        """Whether to write a checkpoint now: at a step where one is due (step_due), or once
        :data:`CHECKPOINT_INTERVAL_S` of wall time have passed since the last (counted from now when True)."""
        due = step_due or time.perf_counter() - self._saved >= CHECKPOINT_INTERVAL_S
        if due:
            self._saved = time.perf_counter()
        return due
