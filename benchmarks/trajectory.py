"""How far APGD's trajectory drifts from Clarabel's over a collapse's first steps, by stopping rule.

    python benchmarks/trajectory.py COLUMN.nc --steps 100 --length-floors 0 0.1 1
    python benchmarks/trajectory.py COLUMN.nc --from-step 600 --steps 200 --overlap-tolerances 1e-5 1e-4

The collapse is chaotic: over a whole run, any change in the 5th digit of one step's forces ends
in another deposit, so final heights and run-outs compare only as distributions over seeds
(`tolerance.py`). Over the first steps the trajectories still follow each other, and their
distance measures the solver's error directly. The column (from `colsim trim`) collapses with
mu = 0.577, mu_r = 0.12 at dt/sqrt(h0/g) = 4 / `--n-steps` for `--steps` steps with Clarabel
(tolerance 1e-8, the reference; and at `--clarabel-tolerance` to see how far Clarabel moves
itself) and with `auto` at APGD's tolerance 1e-5 and each length floor (and, at the floor 0.1,
each `--overlap-tolerances`). Printed per run: the
largest and the root-mean-square distance of the sphere centres from the reference's, in mean
diameters, the kinetic energy's relative difference, and the CPU time and iterations per step.

With `--from-step K` every run starts at step K of one collapse by `auto` (its state and the
forces it hands on), so the comparison covers the slowing and resting steps instead of the first.
"""
from __future__ import annotations

import argparse
import copy
import pickle
import tempfile
import time
from pathlib import Path

import numpy as np

import record
from colsim import io
from colsim.stages.collapse import CollapseSettings, collapse
from colsim.solvers import make_solver
from colsim.engine.stepper import Carry, run


def start_at(column: Path, n_steps: int, first_step: int):
    """The column at step `first_step` of a collapse by auto: (state, h0, Carry), through a
    checkpoint written at that step (first_step 0: the column and its packing's forces)."""
    state, source = io.read_state(column)
    h0 = float(source.attrs["h0"])
    warm_start = io.contact_forces_of(source)
    if first_step == 0:
        return state, h0, Carry(warm_start)
    settings = CollapseSettings(mu_r=0.12, n_steps=n_steps, checkpoint_every=first_step)
    with tempfile.TemporaryDirectory() as directory:
        checkpoint = Path(directory) / "start.checkpoint"
        collapse(state, h0, settings, make_solver("auto", scaled_time_step=4.0 / n_steps),
                 warm_start=warm_start, checkpoint=checkpoint, stop_after=first_step)
        with open(checkpoint, "rb") as handle:
            saved = pickle.load(handle)
    return saved["state"], h0, saved["carry"]


def run_one(start, solver, n_steps: int, first_step: int, steps: int):
    """`steps` steps from `start` (state, h0, carry) with `solver`: the last diagnostics, the last
    state, CPU s and mean iterations a step."""
    state, h0, carry = start[0].copy(), start[1], copy.deepcopy(start[2])
    if not solver.uses_warm_start:   # as colsim.stages.collapse hands it on
        carry = Carry(None, carry.margin)
    step_settings = CollapseSettings(mu_r=0.12, n_steps=n_steps).step_settings(h0)
    cpu = time.process_time()
    results = list(run(state, step_settings, steps, solver, first_step, carry))
    cpu = time.process_time() - cpu
    iterations = np.mean([r.diagnostics.solver_iterations for r in results])
    return results[-1].diagnostics, results[-1].state, cpu, iterations


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("column", type=Path)
    parser.add_argument("--steps", type=int, default=100, help="steps compared (default: %(default)s)")
    parser.add_argument("--n-steps", type=int, default=1000,
                        help="steps to t/sqrt(h0/g) = 4, which sets dt (default: %(default)s)")
    parser.add_argument("--length-floors", type=float, nargs="+", default=[0.0, 0.1, 1.0])
    parser.add_argument("--overlap-tolerances", type=float, nargs="*", default=[],
                        help="also run auto (floor 0.1) with each of APGD's overlap tolerances, mean diameters")
    parser.add_argument("--clarabel-tolerance", type=float, default=1e-10)
    parser.add_argument("--from-step", type=int, default=0,
                        help="start every run at this step of a collapse by auto (default: %(default)s)")
    args = parser.parse_args(argv)
    runs = [("clarabel", make_solver("clarabel")),
            (f"clarabel {args.clarabel_tolerance:g}", make_solver("clarabel", tolerance=args.clarabel_tolerance))]
    runs += [(f"apgd 1e-05 floor {f:g}", make_solver("auto", scaled_time_step=4.0 / args.n_steps,
                                                      apgd={"length_floor": f, "overlap_tolerance": 0.0}))
             for f in args.length_floors]
    runs += [(f"apgd 1e-05 floor 0.1 overlap {o:g} d", make_solver(
        "auto", scaled_time_step=4.0 / args.n_steps, apgd={"length_floor": 0.1, "overlap_tolerance": o}))
        for o in args.overlap_tolerances]
    start = start_at(args.column, args.n_steps, args.from_step)
    results = {name: run_one(start, solver, args.n_steps, args.from_step, args.steps) for name, solver in runs}
    last_ref, ref, _, _ = results["clarabel"]
    d = 2 * start[0].radius.mean()
    energy_ref = last_ref.kinetic_energy + last_ref.rotational_energy
    print(f"{args.column}: {start[0].n} spheres, steps {args.from_step} to {args.from_step + args.steps} "
          f"at dt/sqrt(h0/g) = {4.0 / args.n_steps:g}")
    table = record.table(["run", "largest distance / d", "rms distance / d", "kinetic energy vs reference", "CPU s",
                          "iterations a step"])
    for name, (last, end, cpu, iterations) in results.items():
        distance = np.linalg.norm(end.position - ref.position, axis=1) / d
        energy = last.kinetic_energy + last.rotational_energy
        rms = float(np.sqrt(np.mean(distance ** 2)))
        table.row(name, f"{distance.max():.2e}", f"{rms:.2e}", f"{energy / energy_ref - 1:+.2e}", f"{cpu:.1f}",
                  f"{iterations:.0f}", data={"run": name, "largest_distance_d": float(distance.max()),
                                              "rms_distance_d": rms, "energy_vs_reference": energy / energy_ref - 1,
                                              "cpu_s": cpu, "iterations": float(iterations)})


if __name__ == "__main__":
    record.run("trajectory", main)
