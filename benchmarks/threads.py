"""Threads inside one job: APGD's iteration and a whole collapse on 1, 2, ... threads.

    python benchmarks/threads.py COLUMN.nc [--threads 1 2] [--steps 200] [--iterations 200]

COLUMN.nc: a trimmed column (colsim trim; e.g. a study's results/r0_3/seed_1/pack_<key>/a_5/column.nc).
Two figures for each thread count:
- ms per APGD iteration (wall; the best of 3 runs of `--iterations` iterations) on the column's first
  collapse step (mu = 0.577, mu_r = 0.12, dt/sqrt(h0/g) = 0.004, warm-started from the packing's
  forces), with the speed-up over one thread;
- the first `--steps` steps of its collapse at the default step (`colsim collapse --steps S
  --duration 0.004 S --threads T`, a child process): wall and CPU seconds (user + system),
  iterations a step, and the share of the step spent in APGD's solve.
Time it on a quiet machine: every thread needs a core of its own.
"""
from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import xarray as xr

sys.path.insert(0, str(Path(__file__).resolve().parent))
import record   # noqa: E402
from apgd_iteration import first_step   # noqa: E402

from colsim.solvers.apgd import ApgdSolver   # noqa: E402
from colsim.engine.threads import use_threads   # noqa: E402


def per_iteration(program, guess, iterations: int) -> float:
    """ms of wall time per APGD iteration, the best of 3."""
    best = np.inf
    for _ in range(3):
        run = ApgdSolver().prepare(program, guess)
        run.iterate(10)
        start = time.perf_counter()
        run.iterate(iterations)
        best = min(best, (time.perf_counter() - start) / iterations)
    return 1e3 * best


def collapse(column: Path, steps: int, threads: int) -> dict:
    """Wall and CPU seconds, iterations a step and the solve's share of `steps` collapse steps."""
    with tempfile.TemporaryDirectory() as folder:
        output = Path(folder) / "collapse.nc"
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        start = time.perf_counter()
        subprocess.run([sys.executable, "-m", "colsim.cli", "collapse", "--input", str(column), "--steps",
                        str(steps), "--duration", f"{0.004 * steps:g}", "--threads", str(threads),
                        "--output", str(output)], check=True, capture_output=True)
        wall = time.perf_counter() - start
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        run = xr.load_dataset(output)
        return {"wall": wall, "cpu": (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime),
                "iterations": float(run["step_solver_iterations"].mean()),
                "solve_share": float(run["step_solve_time"].sum() / run["step_wall_time"].sum())}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("column", type=Path)
    parser.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--iterations", type=int, default=200)
    args = parser.parse_args(argv)
    program, guess, n = first_step(args.column)
    print(f"{args.column}: {n} spheres, {program.m} contacts at the first step; {os.cpu_count()} cores")
    table = record.table(["threads", "ms/iteration", "speed-up", "collapse wall s", "CPU s", "speed-up (wall)",
                          "iterations/step", "solve share"])
    base = None
    for count in args.threads:
        use_threads(count)
        ms = per_iteration(program, guess, args.iterations)
        run = collapse(args.column, args.steps, count)
        base = base or (ms, run["wall"])
        table.row(count, f"{ms:.2f}", f"{base[0] / ms:.2f}", f"{run['wall']:.1f}", f"{run['cpu']:.1f}",
                  f"{base[1] / run['wall']:.2f}", f"{run['iterations']:.0f}", f"{100 * run['solve_share']:.0f} %",
                  data={"threads": count, "ms_per_iteration": ms, **run})


if __name__ == "__main__":
    record.run("threads", main)
