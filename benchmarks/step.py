"""One engine step on settled packings: where the time goes, and which Clarabel settings are fastest.

    python benchmarks/step.py                  # 1k and 4k spheres, qdldl vs faer with 1 and 2 threads
    python benchmarks/step.py --large          # and 16k (minutes per step)
    python benchmarks/step.py --sizes 1000 --configs faer:2 --repeat 3

The step is the first step of a collapse: a settled packing (benchmarks/packings.py, built and
cached on first use), cylinder removed, mu = 0.577, mu_r = 0.12, dt = 0.02, Clarabel's displacement
form at tolerance 1e-8. Each (size, configuration) runs in its own process, so that its peak
resident memory (ru_maxrss) is its own; "base MB" is that process's resident memory before the
step (packing loaded, modules imported), "peak MB" after it. Times are wall-clock seconds except
"step cpu s", the process's CPU time (user + system, all threads) for the step, which shows how much
of a wall time was the machine's other load; "outside"
is everything in the step but the solver (detection, assembly, update, overlap check), as a
percentage of the step. "du rel" is the largest difference of the increments from the first
configuration's, relative to the largest increment: equal accuracy means that all stay at the level
of the solver tolerance.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import record

HERE = Path(__file__).resolve().parent
DEFAULT_CONFIGS = ["qdldl:1", "faer:1", "faer:2"]


def one(n: int, method: str, threads: int, out: str, seed: int = 0, equilibrate: bool = False) -> dict:
    """Run one step in this process and return its measurements (also writes u to out.npy)."""
    sys.path.insert(0, str(HERE))
    from packings import settled_packing

    from colsim.solvers import ClarabelSolver
    from colsim.engine.state import ContactLaw, StepSettings, Walls
    from colsim.engine.stepper import step

    state = settled_packing(n, seed)
    settings = StepSettings(dt=0.02, walls=Walls(floor=True, cylinder_radius=None),
                            law=ContactLaw.uniform(0.577, 0.12))
    options = {"equilibrate": True} if equilibrate else {}
    solver = ClarabelSolver(direct_solve_method=method, threads=threads, **options)
    before = resource.getrusage(resource.RUSAGE_SELF)
    start = time.perf_counter()
    result = step(state, settings, solver, step_number=1)
    total = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_SELF)
    base, peak = before.ru_maxrss / 1024, after.ru_maxrss / 1024
    cpu = after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime
    d = result.diagnostics
    np.save(out, result.solution.increments)
    return {
        "spheres": state.n, "contacts": d.n_contacts, "active": d.n_active,
        "method": method + (" eq" if equilibrate else ""), "threads": threads, "cpu": cpu, "detection": d.detection_time,
        "assembly": d.assembly_time, "setup": d.setup_time, "solve": d.solve_time,
        "iterations": d.solver_iterations, "status": d.solver_status, "step": total,
        "outside": total - d.setup_time - d.solve_time, "redone": d.redone,
        "retries": len(result.solution.info.get("retries", [])),
        "base_mb": base, "peak_mb": peak,
    }


def measure(n: int, config: str, repeat: int, seed: int) -> tuple[dict, np.ndarray]:
    """Run (size, config) `repeat` times in fresh processes; keep the fastest step."""
    method, threads, *flags = config.split(":")
    best, u = None, None
    for _ in range(repeat):
        with tempfile.TemporaryDirectory() as tmp:
            out = os.path.join(tmp, "u.npy")
            proc = subprocess.run(
                [sys.executable, __file__, "--one", str(n), method, threads, out, "--seed", str(seed)]
                + (["--equilibrate"] if "eq" in flags else []),
                capture_output=True, text=True, check=False)
            if proc.returncode != 0:
                raise RuntimeError(f"{n} {config} failed:\n{proc.stderr[-3000:]}")
            row = json.loads(proc.stdout.strip().splitlines()[-1])
            if best is None or row["step"] < best["step"]:
                best, u = row, np.load(out)
    return best, u


def print_table(rows: list[dict]) -> None:
    """The Markdown table of the rows (printed, and kept in the benchmark's record)."""
    table = record.table(["spheres", "contacts", "solver", "detect s", "assemble s", "setup s", "solve s", "iters",
                          "step s", "step cpu s", "outside %", "base MB", "peak MB", "du rel"])
    for r in rows:
        table.row(r["spheres"], r["contacts"], f"{r['method']} x{r['threads']}", f"{r['detection']:.3f}",
                  f"{r['assembly']:.3f}", f"{r['setup']:.2f}", f"{r['solve']:.2f}", r["iterations"],
                  f"{r['step']:.2f}", f"{r['cpu']:.2f}", f"{100 * r['outside'] / r['step']:.1f}",
                  f"{r['base_mb']:.0f}", f"{r['peak_mb']:.0f}", f"{r['du']:.1e}", data=r)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[1000, 4000])
    parser.add_argument("--large", action="store_true", help="add 16,000 spheres (minutes per step)")
    parser.add_argument("--configs", nargs="+", default=DEFAULT_CONFIGS,
                        help="method:threads[:eq], e.g. qdldl:1 faer:2 qdldl:1:eq (eq: equilibration on)")
    parser.add_argument("--repeat", type=int, default=None,
                        help="runs per configuration, fastest kept (default 3 below 2,000 spheres, else 1)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--equilibrate", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--one", nargs=4, metavar=("N", "METHOD", "THREADS", "OUT"), help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.one:
        n, method, threads, out = args.one
        print(json.dumps(one(int(n), method, int(threads), out, args.seed, args.equilibrate)))
        return
    sizes = args.sizes + ([16000] if args.large else [])
    sys.path.insert(0, str(HERE))
    from packings import settled_packing

    rows = []
    for n in sizes:
        settled_packing(n, args.seed)  # build and cache once, outside the timed processes
        reference = None
        for config in args.configs:
            repeat = args.repeat or (3 if n < 2000 else 1)
            row, u = measure(n, config, repeat, args.seed)
            if reference is None:
                reference = u
            row["du"] = float(np.abs(u - reference).max() / np.abs(reference).max())
            rows.append(row)
            print(f"{n} {config}: step {row['step']:.2f} s, solve {row['solve']:.2f} s, "
                  f"{row['iterations']} iterations, {row['status']}", file=sys.stderr, flush=True)
    print_table(rows)


if __name__ == "__main__":
    record.run("step", main)
