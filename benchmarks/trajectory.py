"""How far APGD's trajectory drifts from Clarabel's over a collapse's first steps, by stopping rule.

    python benchmarks/trajectory.py COLUMN.nc --steps 100 --length-floors 0 0.1 1

The collapse is chaotic: over a whole run, any change in the 5th digit of one step's forces ends
in another deposit, so final heights and run-outs compare only as distributions over seeds
(`tolerance.py`). Over the first steps the trajectories still follow each other, and their
distance measures the solver's error directly. The column (from `colsim trim`) collapses with
mu = 0.577, mu_r = 0.12 at dt/sqrt(h0/g) = 4 / `--n-steps` for `--steps` steps with Clarabel
(tolerance 1e-8, the reference; and at `--clarabel-tolerance` to see how far Clarabel moves
itself) and with `auto` at APGD's tolerance 1e-5 and each length floor. Printed per run: the
largest and the root-mean-square distance of the sphere centres from the reference's, in mean
diameters, the kinetic energy's relative difference, and the CPU time and iterations per step.
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from colsim import io
from colsim.collapse import CollapseSettings, collapse
from colsim.solvers import make_solver


def run_one(column: Path, solver, n_steps: int, steps: int):
    state, source = io.read_state(column)
    settings = CollapseSettings(mu_r=0.12, n_steps=n_steps, checkpoint_every=10**9)
    start = time.process_time()
    run = collapse(state, float(source.attrs["h0"]), settings, solver,
                   warm_start=io.contact_forces_of(source), stop_after=steps)
    cpu = time.process_time() - start
    iterations = np.mean([d.solver_iterations for d in run.diagnostics])
    return state, run.diagnostics[-1], run.frames[-1][1], cpu, iterations


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("column", type=Path)
    parser.add_argument("--steps", type=int, default=100, help="steps compared (default: %(default)s)")
    parser.add_argument("--n-steps", type=int, default=1000,
                        help="steps to t/sqrt(h0/g) = 4, which sets dt (default: %(default)s)")
    parser.add_argument("--length-floors", type=float, nargs="+", default=[0.0, 0.1, 1.0])
    parser.add_argument("--clarabel-tolerance", type=float, default=1e-10)
    args = parser.parse_args(argv)
    runs = [("clarabel", make_solver("clarabel")),
            (f"clarabel {args.clarabel_tolerance:g}", make_solver("clarabel", tolerance=args.clarabel_tolerance))]
    runs += [(f"apgd 1e-05 floor {f:g}", make_solver("auto", scaled_time_step=4.0 / args.n_steps,
                                                      apgd={"length_floor": f}))
             for f in args.length_floors]
    results = {name: run_one(args.column, solver, args.n_steps, args.steps) for name, solver in runs}
    column, last_ref, ref, _, _ = results["clarabel"]
    d = 2 * column.radius.mean()
    energy_ref = last_ref.kinetic_energy + last_ref.rotational_energy
    print(f"{args.column}: {column.n} spheres, {args.steps} steps at dt/sqrt(h0/g) = {4.0 / args.n_steps:g}")
    print("| run | largest distance / d | rms distance / d | kinetic energy vs reference | CPU s | iterations a step |")
    print("|---|---|---|---|---|---|")
    for name, (_, last, end, cpu, iterations) in results.items():
        distance = np.linalg.norm(end.position - ref.position, axis=1) / d
        energy = last.kinetic_energy + last.rotational_energy
        print(f"| {name} | {distance.max():.2e} | {np.sqrt(np.mean(distance ** 2)):.2e} | "
              f"{energy / energy_ref - 1:+.2e} | {cpu:.1f} | {iterations:.0f} |", flush=True)


if __name__ == "__main__":
    main()
