"""What a long command shows while it runs: a bar on a terminal and a log line now and then."""
from __future__ import annotations

import logging
import time

log = logging.getLogger("colsim")


def progress_bar(total: int, description: str, interval_s: float = 60.0, clock=time.monotonic):
    """A tqdm bar on a terminal (off otherwise, and under -q) and a log line every 10 % of the steps, or sooner
    once interval_s seconds have passed since the last line (a long step or run to rest would
    otherwise leave the log silent for many minutes)."""
    from tqdm import tqdm

    quiet = not log.isEnabledFor(logging.INFO)    # colsim -q: no bar either
    bar = tqdm(total=total, desc=description, disable=True if quiet else None, unit="step")
    every = max(1, total // 10)
    started = clock()
    counter = {"n": 0, "last": started}

    def update(diagnostics, *_):
        counter["n"] += 1
        bar.update(1)
        bar.set_postfix(contacts=diagnostics.n_contacts, iters=diagnostics.solver_iterations)
        now = clock()
        if counter["n"] % every == 0 or now - counter["last"] >= interval_s:
            counter["last"] = now
            log.info("%s step %d of at most %d (%.0f s): %d contacts, kinetic energy %.3g, "
                     "overlap %.2g, solve %.2f s, %d iterations", description, diagnostics.step,
                     total, now - started, diagnostics.n_contacts,
                     diagnostics.kinetic_energy + diagnostics.rotational_energy,
                     diagnostics.largest_overlap, diagnostics.solve_time, diagnostics.solver_iterations)
    update.close = bar.close
    return update
