"""A cold first step: a column without its packing's forces, solved by Clarabel and by auto's APGD.

    python -m benchmarks cold_step COLUMN.nc [COLUMN.nc ...] [--cap 20000]

For each column (a trimmed column, e.g. a study's results/r0_R/seed_1/pack_<key>/a_5/column.nc):
the first step of its collapse (mu = 0.577, mu_r = 0.12, dt/sqrt(h0/g) = 0.004), with no warm
start, as a user's column that comes without packing forces starts. Solved by Clarabel (auto's,
the default settings) and by APGD with auto's settings (tolerance, length floor, overlap
tolerance) from zero forces, capped at `--cap` iterations (auto's cap). Printed: CPU seconds of
each solve (wall, one thread: numba's threads spin, so CPU time would count both cores), APGD's iterations and whether it reached the cap, and the
agreement of the two: the increments' relative difference and the net contact force's (B' lam,
unique where the forces are not), and APGD's largest cone violation in mean diameters.
Issue 30, item 3: whether `auto` should give a cold step to APGD, with Clarabel as the fallback.
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import record
from apgd_iteration import first_step
from colsim.engine.cones import mean_diameter
from colsim.engine.program import cone_violation
from colsim.engine.threads import use_threads
from colsim.solvers import AutoSolver, SolverError, defaults


def timed(solve):
    """(solve()'s result or its SolverError, wall seconds)."""
    start = time.perf_counter()
    try:
        return solve(), time.perf_counter() - start
    except SolverError as error:
        return error, time.perf_counter() - start


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("columns", type=Path, nargs="+")
    parser.add_argument("--cap", type=int, default=defaults.AUTO_MAX_ITER)
    args = parser.parse_args(argv)
    use_threads(1)
    auto = AutoSolver(max_iter=args.cap)
    warm_up = first_step(args.columns[0])[0]
    timed(lambda: auto.apgd.solve(warm_up))   # compile (or load) the kernels once, outside the timings
    table = record.table(["column", "spheres", "contacts", "Clarabel s", "iterations", "APGD s",
                          "iterations", "at the cap", "du rel", "net force rel", "violation / d"])
    for column in args.columns:
        program, _, n = first_step(column)
        reference, clarabel_s = timed(lambda: auto.clarabel.solve(program))
        solution, apgd_s = timed(lambda: auto.apgd.solve(program))
        capped = isinstance(solution, SolverError)
        row = {"column": str(column), "spheres": n, "contacts": program.m, "clarabel_s": clarabel_s,
               "clarabel_iterations": reference.iterations, "apgd_s": apgd_s, "capped": capped}
        if capped:
            table.row(column.parent.name, n, program.m, f"{clarabel_s:.2f}", reference.iterations,
                      f"{apgd_s:.2f}", args.cap, "yes", "-", "-", "-", data=row)
            continue
        du = np.linalg.norm(solution.increments - reference.increments) / np.linalg.norm(reference.increments)
        net, net_ref = (program.jacobian.T @ s.forces.ravel() for s in (solution, reference))
        net_error = np.linalg.norm(net - net_ref) / np.linalg.norm(net_ref)
        violation = cone_violation(program, solution.increments, solution.forces)["primal"] / mean_diameter(program)
        row.update(apgd_iterations=solution.iterations, du_relative=du, net_force_relative=net_error,
                   violation_diameters=violation)
        table.row(column.parent.name, n, program.m, f"{clarabel_s:.2f}", reference.iterations, f"{apgd_s:.2f}",
                  solution.iterations, "no", f"{du:.1e}", f"{net_error:.1e}", f"{violation:.1e}", data=row)


if __name__ == "__main__":
    record.run("cold_step", main)
