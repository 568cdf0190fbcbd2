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
Then what the machine's cores give on their own (`--probe-windows`, 0 to skip): two numba kernels
run for 1 s windows alternately on 1 thread and on each other count, and the speed-up over one
thread (min / median / max over the windows) of one that computes (independent multiply-adds on
4,096 numbers in cache) and one that streams memory (c = 1.5 a + b on 4 million numbers, 96 MB).
APGD's iteration reads and writes some 450 bytes a contact, a working set of 13 MB at 28,000
contacts, so it scales as the memory does: on the project's virtual 2-core machine the streaming
kernel's 2-thread speed-up moved between 1.1 and 2.3 from one second to the next while the
computing one stayed at 1.9-2.0.
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


def _probe_kernels():
    """(compute, stream): numba kernels on the threads in use (benchmark code, not colsim's)."""
    from colsim.engine.compiled import numba, prange

    @numba.njit(parallel=True, fastmath=True)
    def compute(a, b, out, repeats):
        for i in prange(a.size):
            x, y, s0, s1, s2, s3 = a[i], b[i], 0.0, 0.0, 0.0, 0.0
            for _ in range(repeats):
                s0 = 0.999 * s0 + x
                s1 = 0.998 * s1 + y
                s2 = 0.997 * s2 + x * y
                s3 = 0.996 * s3 + x - y
            out[i] = s0 + s1 + s2 + s3

    @numba.njit(parallel=True)
    def stream(a, b, c):
        for i in prange(a.size):
            c[i] = 1.5 * a[i] + b[i]

    return compute, stream


def probe(counts: list[int], windows: int) -> dict[int, dict[str, np.ndarray]]:
    """{thread count: {"compute", "stream": speed-ups over 1 thread, one a window pair}}: each
    kernel run for 1 s on 1 thread, then 1 s on the count, `windows` times."""
    compute, stream = _probe_kernels()
    rng = np.random.default_rng(0)
    small = [rng.random(4096), rng.random(4096), np.empty(4096)]
    large = [rng.random(4_000_000), rng.random(4_000_000), np.empty(4_000_000)]
    kernels = {"compute": lambda: compute(*small, 2000), "stream": lambda: stream(*large)}

    def calls_in_a_second(kernel) -> int:
        kernel()
        start, calls = time.perf_counter(), 0
        while time.perf_counter() - start < 1.0:
            kernel()
            calls += 1
        return calls

    speedups = {}
    for count in counts:
        ratios = {name: [] for name in kernels}
        for _ in range(windows):
            for name, kernel in kernels.items():
                use_threads(1)
                one = calls_in_a_second(kernel)
                use_threads(count)
                ratios[name].append(calls_in_a_second(kernel) / one)
        speedups[count] = {name: np.array(values) for name, values in ratios.items()}
    use_threads(1)
    return speedups


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("column", type=Path)
    parser.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--iterations", type=int, default=200)
    parser.add_argument("--probe-windows", type=int, default=10)
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
    counts = [count for count in args.threads if count > 1]
    if args.probe_windows > 0 and counts:
        table = record.table(["threads", "compute: speed-up min / median / max",
                              "stream memory: speed-up min / median / max", "windows"])
        for count, found in probe(counts, args.probe_windows).items():
            cells = {name: " / ".join(f"{f(v):.2f}" for f in (np.min, np.median, np.max))
                     for name, v in found.items()}
            table.row(count, cells["compute"], cells["stream"], args.probe_windows,
                      data={"threads": count, **{name: v.tolist() for name, v in found.items()}})


if __name__ == "__main__":
    record.run("threads", main)
