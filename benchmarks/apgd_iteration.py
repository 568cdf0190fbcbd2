"""The cost of one APGD iteration on the host against the number of contacts (the fused numba kernels).

    python benchmarks/apgd_iteration.py COLUMN.nc [COLUMN.nc ...]   # columns from colsim trim
    python benchmarks/apgd_iteration.py                             # the columns benchmarks/collapse.py cached

The program is the first step of each column's collapse (mu = 0.577, mu_r = 0.12, dt/sqrt(h0/g) =
0.004), warm-started from the packing's forces. The iteration runs 10 iterations to compile and warm
up, then the best of 3 timings of `--iterations` iterations (CPU time of this process) is printed in
ms per iteration, with the time of one residual check (done every 10 iterations) beside it.
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import record
from colsim import io
from colsim.solvers.apgd import ApgdSolver
from colsim.stages.collapse import CollapseSettings
from colsim.engine.contacts import detect
from colsim.engine.program import assemble
from colsim.engine.backend import predicted_displacement
from colsim.engine.stepper import base_margin

CACHE = record.cache_dir()


def first_step(column: Path):
    """(program, warm start (m, 5)) of the first collapse step of a column file."""
    state, source = io.read_state(column)
    h0 = float(source.attrs["h0"])
    collapse = CollapseSettings(mu_r=0.12, n_steps=1000)
    settings = collapse.step_settings(h0)
    found = detect(state, settings.walls, settings.law, predicted_displacement(state, settings),
                   base_margin(state, settings), settings.detection_slack)
    forces = io.contact_forces_of(source)
    guess = None if forces is None else forces.match(found)
    return assemble(state, found, settings.dt, settings.gravity), guess, state.n


def per_iteration(program, guess, iterations: int) -> tuple[float, float]:
    """(ms per iteration, ms per residual check), best of 3, CPU time."""
    solver = ApgdSolver()
    best = np.inf
    for _ in range(3):
        run = solver.prepare(program, guess)
        run.iterate(10)
        start = time.process_time()
        run.iterate(iterations)
        best = min(best, (time.process_time() - start) / iterations)
    start = time.process_time()
    for _ in range(10):
        run.gradient_at_x()
    check = (time.process_time() - start) / 10
    return 1e3 * best, 1e3 * check


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("columns", nargs="*", type=Path)
    parser.add_argument("--iterations", type=int, default=200)
    args = parser.parse_args(argv)
    columns = args.columns or sorted(CACHE.glob("column_*.nc"))
    table = record.table(["spheres", "contacts", "numba ms/iteration", "gradient check ms"])
    for column in columns:
        program, guess, n = first_step(column)
        fast, check = per_iteration(program, guess, args.iterations)
        table.row(n, program.m, f"{fast:.2f}", f"{check:.2f}",
                  data={"column": str(column), "spheres": n, "contacts": program.m, "numba_ms": fast,
                        "gradient_check_ms": check})


if __name__ == "__main__":
    record.run("apgd_iteration", main)
