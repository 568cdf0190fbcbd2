"""Which residual holds APGD's steps: iterations until each stopping level, on a collapse's own steps.

    python benchmarks/stopping.py COLUMN.nc --steps 2 50 300 900
    python benchmarks/stopping.py benchmarks/.cache/column_r0_4_seed_1_auto_dt0.02_a5.nc --steps 30 60

The column (from `colsim trim`) collapses with mu = 0.577, mu_r = 0.12 at dt/sqrt(h0/g) =
4 / `--n-steps` with `solver: auto` up to the last step named. At each named step the step's cone
program is also solved by APGD (tolerance 1e-5, length floor 0.1 d, no overlap tolerance) from the
same warm start, checking every 10 iterations, and the table gives the iterations until
complementarity first reaches 1e-5, and until, with it, the largest cone violation of the
end-of-step gaps is at most 1e-3, 1e-4, 1e-5 and 1e-6 mean diameters d (1e-6 d: where the
relative tolerance alone stops at the floor 0.1 d). The collapse itself goes on with `auto`'s own
settings.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import record
from colsim import io
from colsim.solvers.apgd import ApgdSolver
from colsim.stages.collapse import CollapseSettings, collapse
from colsim.engine.cones import mean_diameter
from colsim.engine.solver_contract import Solver
from colsim.solvers import make_solver

LEVELS = (1e-3, 1e-4, 1e-5, 1e-6)   # largest violation, mean diameters
TOLERANCE = 1e-5


def iterations_to_levels(program, warm_start, max_iter: int = 20_000) -> dict:
    """Iterations (multiples of 10) until complementarity <= 1e-5 ('complementarity') and until,
    with it, the largest violation <= each level of LEVELS (mean diameters)."""
    solver = ApgdSolver(tolerance=TOLERANCE, length_floor=0.1)
    run = solver.prepare(program, warm_start)
    d = mean_diameter(program)
    scale, floor, _ = solver.stopping_scales(program)
    first, k = {}, 0
    while k < max_iter and len(first) < len(LEVELS) + 1:
        run.iterate(10)
        k += 10
        res = run.residuals(program.mu, program.mu_r, scale, floor)
        if res["complementarity"] <= TOLERANCE:
            first.setdefault("complementarity", k)
            for level in LEVELS:
                if res["primal"] * scale <= level * d:
                    first.setdefault(level, k)
    return first


class Probe(Solver):
    """`inner` for every step; at the steps named, the stopping levels of the step's program first."""

    uses_warm_start = True

    def __init__(self, inner: Solver, steps: set[int]):
        self.inner, self.steps, self.rows = inner, steps, []
        self.name = inner.name

    def solve(self, program, warm_start=None, step=None):
        if step in self.steps and warm_start is not None:
            self.rows.append((step, program.m, iterations_to_levels(program, warm_start)))
            print(self.format(self.rows[-1]), file=sys.stderr, flush=True)   # progress
        return self.inner.solve(program, warm_start=warm_start, step=step)

    @staticmethod
    def cells(row) -> list:
        step, m, first = row
        return [step, f"{m:,}", *(str(first.get(key, "-")) for key in ("complementarity", *LEVELS))]

    @staticmethod
    def format(row) -> str:
        return "| " + " | ".join(map(str, Probe.cells(row))) + " |"


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("column", type=Path)
    parser.add_argument("--steps", type=int, nargs="+", required=True, help="the steps probed")
    parser.add_argument("--n-steps", type=int, default=1000,
                        help="steps to t/sqrt(h0/g) = 4, which sets dt (default: %(default)s)")
    args = parser.parse_args(argv)
    state, source = io.read_state(args.column)
    settings = CollapseSettings(mu_r=0.12, n_steps=args.n_steps, checkpoint_every=10**9)
    probe = Probe(make_solver("auto", scaled_time_step=settings.duration / args.n_steps), set(args.steps))
    print(f"{args.column}: {state.n} spheres, dt/sqrt(h0/g) = {settings.duration / args.n_steps:g}")
    collapse(state, float(source.attrs["h0"]), settings, probe, warm_start=io.contact_forces_of(source),
             stop_after=max(args.steps))
    table = record.table(["step", "contacts", "complementarity 1e-5", "violation 1e-3 d", "1e-4 d", "1e-5 d",
                          "1e-6 d"])
    for row in probe.rows:
        table.row(*Probe.cells(row), data={"step": row[0], "contacts": row[1],
                                           "iterations": {str(k): v for k, v in row[2].items()}})


if __name__ == "__main__":
    record.run("stopping", main)
