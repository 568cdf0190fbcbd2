"""Where APGD overtakes Clarabel: cost per step against the time step, for `solver: auto`'s rule.

    python benchmarks/crossover.py COLUMN.nc [--scaled-dt 0.04 0.02 0.01 0.005] [--steps 40]
    python benchmarks/crossover.py COLUMN.nc --whole     # whole collapses to t/sqrt(h0/g) = 4

For each dt / sqrt(h0/g), the column's collapse (mu = 0.577, mu_r = 0.12) runs its first `--steps`
steps twice from the same start: with Clarabel, and with APGD warm-started from the previous step
(the first step from the packing's forces; iteration cap 50,000 so that no step falls back). Printed:
CPU seconds per step (this process), mean and largest APGD iterations, and the ratio. AutoSolver's
`apgd_below` is the largest scaled step at which APGD is cheaper.

The first steps of a fine step cover only the start of the flow; `--whole` runs every collapse to
t/sqrt(h0/g) = 4 instead (APGD at every dt, Clarabel at the coarsest only: its iterations per step
hardly depend on dt, 20-35 here, so its cost per step there stands for all).
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import record
from colsim import io
from colsim.stages.collapse import CollapseSettings, collapse
from colsim.solvers import ApgdSolver, ClarabelSolver


def cost_per_step(column: Path, solver, scaled_dt: float, steps: int | None) -> tuple[float, list]:
    """(CPU s per step, per-step iterations) of the first `steps` steps (None: to t/sqrt(h0/g) = 4)."""
    state, source = io.read_state(column)
    h0 = float(source.attrs["h0"])
    steps = steps or int(round(4.0 / scaled_dt))
    settings = CollapseSettings(mu_r=0.12, duration=scaled_dt * steps, n_steps=steps, checkpoint_every=10**9)
    start = time.process_time()
    run = collapse(state, h0, settings, solver, warm_start=io.contact_forces_of(source))
    return (time.process_time() - start) / steps, [d.solver_iterations for d in run.diagnostics]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("column", type=Path)
    parser.add_argument("--scaled-dt", type=float, nargs="+", default=[0.04, 0.02, 0.01, 0.005])
    parser.add_argument("--steps", type=int, default=40)
    parser.add_argument("--tolerance", type=float, default=None, help="APGD tolerance (default: its own)")
    parser.add_argument("--whole", action="store_true", help="whole collapses (see the docstring)")
    args = parser.parse_args(argv)
    if args.whole:
        return whole_collapses(args)
    apgd = ApgdSolver(max_iter=50_000, **({} if args.tolerance is None else {"tolerance": args.tolerance}))
    print(f"{args.column.name}: first {args.steps} steps, APGD tolerance {apgd.tolerance:g}")
    table = record.table(["dt/sqrt(h0/g)", "Clarabel s/step", "iterations", "APGD s/step", "iterations mean (max)",
                          "APGD / Clarabel"], title=f"{args.column.name}: first {args.steps} steps")
    for scaled_dt in args.scaled_dt:
        reference, ref_iterations = cost_per_step(args.column, ClarabelSolver(), scaled_dt, args.steps)
        fast, iterations = cost_per_step(args.column, apgd, scaled_dt, args.steps)
        table.row(f"{scaled_dt:g}", f"{reference:.2f}", f"{np.mean(ref_iterations):.0f}", f"{fast:.2f}",
                  f"{np.mean(iterations):.0f} ({max(iterations)})", f"{fast / reference:.2f}",
                  data={"scaled_dt": scaled_dt, "clarabel_s": reference, "clarabel_iterations": ref_iterations,
                        "apgd_s": fast, "apgd_iterations": iterations})


def whole_collapses(args):
    apgd = ApgdSolver(max_iter=50_000, **({} if args.tolerance is None else {"tolerance": args.tolerance}))
    coarsest = max(args.scaled_dt)
    reference, ref_iterations = cost_per_step(args.column, ClarabelSolver(), coarsest, None)
    print(f"{args.column.name}: whole collapses to t/sqrt(h0/g) = 4, APGD tolerance {apgd.tolerance:g}; "
          f"Clarabel at {coarsest:g}: {reference:.2f} s/step, {np.mean(ref_iterations):.0f} iterations")
    record.note("clarabel", {"scaled_dt": coarsest, "s_per_step": reference, "iterations": ref_iterations})
    table = record.table(["dt/sqrt(h0/g)", "steps", "APGD s/step", "iterations mean (max)",
                          "APGD / Clarabel per step", "APGD whole CPU s"], title=f"{args.column.name}: whole collapses")
    for scaled_dt in sorted(args.scaled_dt, reverse=True):
        fast, iterations = cost_per_step(args.column, apgd, scaled_dt, None)
        table.row(f"{scaled_dt:g}", len(iterations), f"{fast:.2f}", f"{np.mean(iterations):.0f} ({max(iterations)})",
                  f"{fast / reference:.2f}", f"{fast * len(iterations):.0f}",
                  data={"scaled_dt": scaled_dt, "apgd_s": fast, "apgd_iterations": iterations})


if __name__ == "__main__":
    record.run("crossover", main)
