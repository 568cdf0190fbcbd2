"""Whole collapses of real columns: Clarabel at the paper's 100 steps against the small-step fast path.

    python benchmarks/collapse.py --r0 2 3 4                 # a = 5, seed 1, the three runs below
    python benchmarks/collapse.py --r0 2 --runs auto-1000    # one run
    python benchmarks/collapse.py --r0 6 --runs auto-1000 --threads 2   # issue 30's r0 = 6 target

Columns are made as a user makes them: `colsim pack` (in layers with --pack-layer-height 2.5;
cached under benchmarks/.cache/, with its wall and CPU time, peak memory and steps in a .json
beside it, printed with the runs) and `colsim trim`. --threads: of the packing and of each run. Each run is a separate process (so peak
memory is its own) that collapses the column to t/sqrt(h0/g) = 4 through :func:`colsim.stages.collapse.collapse`:

- clarabel-100: Clarabel, 100 steps (the paper's dt/sqrt(h0/g) = 0.04);
- auto-1000: `solver: auto`, 1,000 steps (0.004), warm-started from the packing's forces;
- clarabel-1000: Clarabel at 1,000 steps, timed over its first 20 steps and extrapolated (x 50).

Printed per run: CPU time of the collapse (user + system, imports excluded), wall time, peak resident memory, the
steps solved by each back-end, and iterations per step by phase: fast flow (kinetic energy above
half its peak), slowing (after the peak, 1-50 % of it) and rest (below 1 %). The table at the end
is markdown, for docs/performance.md. Time benchmarks on a quiet machine.
"""
from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

import record
from colsim.stages.settings import PackSettings

HERE = Path(__file__).resolve().parent
CACHE = record.cache_dir()
#: the colsim command of this interpreter (the colsim it imports, not whichever is installed as `colsim`)
COLSIM = [sys.executable, "-m", "colsim.cli"]
RUNS = {"clarabel-100": ("clarabel", 100, None), "auto-1000": ("auto", 1000, None),
        "clarabel-1000": ("clarabel", 1000, 20)}


def column_file(r0: float, aspect_ratio: float, seed: int, pack_solver: str, pack_dt: float,
                layer_height: str = "none", threads: int = 1) -> Path:
    """The trimmed column (made once with the colsim CLI and cached)."""
    CACHE.mkdir(parents=True, exist_ok=True)
    layer_height = str(layer_height).lower()
    layers = "" if layer_height == "none" else f"_layers{float(layer_height):g}"
    stem = f"r0_{r0:g}_seed_{seed}_{pack_solver}_dt{pack_dt:g}{layers}"
    packing = CACHE / f"packing_{stem}_h{aspect_ratio * r0:g}.nc"
    if not packing.exists():
        start, cpu = time.perf_counter(), _children_cpu()
        subprocess.run([*COLSIM, "pack", "--r0", f"{r0:g}", "--height", f"{aspect_ratio * r0:g}",
                        "--seed", str(seed), "--root-seed", "2024", "--dt", f"{pack_dt:g}",
                        "--solver", pack_solver, "--max-steps", "20000", "--layer-height", layer_height,
                        "--threads", str(threads), "--output", str(packing)],
                       check=True)
        built = {"wall_s": time.perf_counter() - start, "cpu_s": _children_cpu() - cpu,
                 "peak_mb": resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024,
                 "threads": threads}
        packing.with_suffix(".json").write_text(json.dumps(built))
    built = json.loads(packing.with_suffix(".json").read_text())
    import xarray as xr
    with xr.open_dataset(packing) as source:
        built.update(spheres=int(source.sizes["particle"]), steps=int(source.attrs["steps"]),
                     solid_fraction=float(source.attrs["solid_fraction"]))
    print("packing", packing.name, json.dumps(built), flush=True)
    record.note("packing", {"file": packing.name, **built})
    column = CACHE / f"column_{stem}_a{aspect_ratio:g}.nc"
    if not column.exists():
        subprocess.run([*COLSIM, "trim", "--input", str(packing), "--aspect-ratio", f"{aspect_ratio:g}",
                        "--output", str(column)], check=True)
    return column


def _children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def run_one(column: Path, name: str, threads: int = 1) -> dict:
    """One run in this process on `threads` threads; returns its record."""
    from colsim import io
    from colsim.stages.collapse import CollapseSettings, collapse
    from colsim.solvers import make_solver
    from colsim.engine.threads import use_threads

    use_threads(threads)

    solver_name, n_steps, timed_steps = RUNS[name]
    state, source = io.read_state(column)
    h0 = float(source.attrs["h0"])
    settings = CollapseSettings(mu_r=0.12, n_steps=n_steps, checkpoint_every=10**9)
    options = {"scaled_time_step": settings.duration / n_steps} if solver_name == "auto" else {}
    solver = make_solver(solver_name, **options)
    start, cpu = time.perf_counter(), time.process_time()
    run = collapse(state, h0, settings, solver, warm_start=io.contact_forces_of(source), stop_after=timed_steps)
    wall, cpu = time.perf_counter() - start, time.process_time() - cpu
    usage = resource.getrusage(resource.RUSAGE_SELF)
    d = run.diagnostics
    energy = np.array([x.kinetic_energy + x.rotational_energy for x in d])
    iterations = np.array([x.solver_iterations for x in d])
    backends = [x.solver_backend for x in d]
    return {"run": name, "spheres": state.n, "steps": len(d), "n_steps": n_steps, "threads": threads,
            "cpu_s": cpu, "wall_s": wall,
            "peak_mb": usage.ru_maxrss / 1024, "contacts": int(np.mean([x.n_contacts for x in d])),
            "backends": {b: backends.count(b) for b in sorted(set(backends))},
            "phases": phase_iterations(energy, iterations),
            "largest_overlap_over_dmin": float(max(x.largest_overlap for x in d) / (2 * state.radius.min()))}


def phase_iterations(energy: np.ndarray, iterations: np.ndarray) -> dict:
    """Mean iterations per step in the fast flow (energy above half its peak), slowing (after the
    peak, 1-50 % of it) and rest (below 1 % after the peak)."""
    peak = int(np.argmax(energy))
    share = energy / max(energy.max(), 1e-300)
    after = np.arange(len(energy)) > peak
    phases = {"fast": share > 0.5, "slowing": after & (share <= 0.5) & (share > 0.01),
              "rest": after & (share <= 0.01)}
    return {k: (float(iterations[v].mean()) if v.any() else None) for k, v in phases.items()}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--r0", type=float, nargs="+", default=[2.0, 3.0, 4.0])
    parser.add_argument("--aspect-ratio", type=float, default=5.0)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--runs", nargs="+", choices=list(RUNS), default=list(RUNS))
    parser.add_argument("--pack-solver", default="auto",
                        help="solver of `colsim pack` (default: %(default)s, as a user packs; clarabel: the reference)")
    parser.add_argument("--pack-dt", type=float, default=0.02)
    parser.add_argument("--pack-layer-height", default=str(PackSettings.layer_height).lower(),
                        help="colsim pack --layer-height (default: %(default)s, one pour; 2.5: layers)")
    parser.add_argument("--threads", type=int, default=1, help="threads of the packing and of each run")
    parser.add_argument("--clarabel-100-up-to", type=float, default=3.0, metavar="R0",
                        help="run clarabel-100 only up to this r0 (at r0 = 4 it takes 10-20 hours; "
                             "clarabel-1000's 20 timed steps stand for it there)")
    parser.add_argument("--one", nargs=2, metavar=("COLUMN", "RUN"), help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.one:
        print(json.dumps(run_one(Path(args.one[0]), args.one[1], args.threads)))
        return
    records = []
    for r0 in args.r0:
        column = column_file(r0, args.aspect_ratio, args.seed, args.pack_solver, args.pack_dt,
                             args.pack_layer_height, args.threads)
        for name in args.runs:
            if name == "clarabel-100" and r0 > args.clarabel_100_up_to:
                print(f"skipping clarabel-100 at r0 = {r0:g} (--clarabel-100-up-to {args.clarabel_100_up_to:g})")
                continue
            out = subprocess.run([sys.executable, __file__, "--one", str(column), name, "--threads", str(args.threads)],
                                 check=True, capture_output=True, text=True).stdout
            result = json.loads(out.strip().splitlines()[-1])
            result["r0"] = r0
            records.append(result)
            print(json.dumps(result), flush=True)
    print()
    table = record.table(["r0", "spheres", "run", "steps timed", "CPU s (whole collapse)", "wall s", "peak MB",
                          "iterations fast / slowing / rest", "back-ends"])
    for r in records:
        whole = r["cpu_s"] * r["n_steps"] / r["steps"]
        phases = " / ".join("-" if v is None else f"{v:.0f}" for v in r["phases"].values())
        table.row(f"{r['r0']:g}", r["spheres"], r["run"], r["steps"],
                  f"{whole:.0f}{' (extrapolated)' if r['steps'] < r['n_steps'] else ''}", f"{r['wall_s']:.0f}",
                  f"{r['peak_mb']:.0f}", phases, r["backends"], data=r)


if __name__ == "__main__":
    record.run("collapse", main)
