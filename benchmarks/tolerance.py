"""Which APGD tolerance is tight enough: final height and run-out against Clarabel at the same dt.

    python benchmarks/tolerance.py results/r0_2/seed_*/a_{2,5}/column.nc --record tolerance.jsonl
    python benchmarks/tolerance.py ... --tolerances 1e-3 1e-4 1e-5 --clarabel a_2/seed_1 ...
    python benchmarks/tolerance.py ... --tolerances 1e-5 --length-floors 0 0.1
    python benchmarks/tolerance.py ... --tolerances 1e-5 --length-floors 0.1 --overlap-tolerances 0 1e-4

Every column (from `colsim trim`) collapses with mu = 0.577, mu_r = 0.12, to t/sqrt(h0/g) = 4 in
`--steps` steps (1,000 by default: dt/sqrt(h0/g) = 0.004) with `solver: auto` at each APGD
tolerance, length floor (the residuals' length is at least this many mean diameters) and overlap
tolerance (the largest cone violation, mean diameters, that counts as feasible;
:class:`colsim.solvers.apgd.ApgdSolver`), and with Clarabel where `--clarabel` names the column (a substring of its path;
Clarabel at 1,000 steps costs about 30 CPU minutes at a = 2, r0 = 2). The deposit is measured as
the workflow's analysis does (main mass, contact tolerance 1 % of the smallest diameter).

Each run is appended to `--record` as one JSON line as soon as it ends, and runs already there
are skipped, so a killed study resumes. The tables at the end: every run, then per aspect ratio
and run the mean and standard deviation over seeds. (Run by run, any two settings differ about as
much as two seeds do: the collapse is chaotic, so a change in the 5th digit of one step's forces
ends in another deposit. Compare distributions, and Clarabel against itself at another tolerance.)
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

import record
from scatter import standard_deviation
from colsim import io
from colsim.stages.analyse import measure_deposit
from colsim.stages.collapse import CollapseSettings, collapse
from colsim.solvers import make_solver


def run_one(column: Path, solver_name: str, tolerance: float | None, steps: int,
            length_floor: float = 0.0, overlap_tolerance: float = 0.0) -> dict:
    state, source = io.read_state(column)
    h0, r0 = float(source.attrs["h0"]), float(source.attrs["r0"])
    settings = CollapseSettings(mu_r=0.12, n_steps=steps, checkpoint_every=10**9)
    if solver_name == "auto":
        options = {"scaled_time_step": settings.duration / steps,
                   "apgd": {"tolerance": tolerance, "length_floor": length_floor, "overlap_tolerance": overlap_tolerance}}
    else:
        options = {} if tolerance is None else {"tolerance": tolerance}
    start = time.process_time()
    run = collapse(state, h0, settings, make_solver(solver_name, **options),
                   warm_start=io.contact_forces_of(source))
    cpu = time.process_time() - start
    deposit = measure_deposit(run.frames[-1][1])
    d = run.diagnostics
    backends = [x.solver_backend for x in d]
    return {"column": str(column), "aspect_ratio": float(source.attrs["aspect_ratio"]),
            "seed": int(source.attrs.get("seed", -1)), "spheres": state.n, "steps": steps,
            "solver": solver_name, "tolerance": tolerance,
            "length_floor": length_floor if solver_name == "auto" else None,
            "overlap_tolerance": overlap_tolerance if solver_name == "auto" else None,
            "h_inf_over_r0": deposit.h_inf / r0, "runout_over_r0": (deposit.r_inf - r0) / r0,
            "cpu_s": cpu, "mean_iterations": float(np.mean([x.solver_iterations for x in d])),
            "fallbacks": backends.count("clarabel-fallback"),
            "largest_overlap_over_dmin": float(max(x.largest_overlap for x in d) / (2 * state.radius.min()))}


def label(record: dict) -> str:
    """'clarabel' (its default tolerance), 'clarabel 1e-10', 'apgd 0.001' or, with a length
    floor, 'apgd 1e-05 floor 0.1' (and ' overlap 0.0001 d' with an overlap tolerance)."""
    name = "clarabel" if record["solver"] == "clarabel" else "apgd"
    name = name if record["tolerance"] is None else f"{name} {record['tolerance']:g}"
    floor = record.get("length_floor") or 0.0
    name = f"{name} floor {floor:g}" if floor else name
    overlap = record.get("overlap_tolerance") or 0.0
    return f"{name} overlap {overlap:g} d" if overlap else name


def report(records: list[dict]) -> None:
    table = record.table(["a", "seed", "run", "h_inf/r0", "run-out/r0", "CPU s", "iterations/step", "fallbacks",
                          "overlap/d_min"], title="runs")
    for r in sorted(records, key=lambda r: (r["aspect_ratio"], r["seed"], label(r))):
        table.row(f"{r['aspect_ratio']:g}", r["seed"], label(r), f"{r['h_inf_over_r0']:.3f}",
                  f"{r['runout_over_r0']:.3f}", f"{r['cpu_s']:.0f}", f"{r['mean_iterations']:.0f}",
                  r["fallbacks"], f"{r['largest_overlap_over_dmin']:.4f}", data=r)
    print()
    table = record.table(["a", "run", "seeds", "h_inf/r0 mean (sd)", "run-out/r0 mean (sd)", "CPU s mean",
                          "iterations/step"], title="over seeds")
    for a in sorted({r["aspect_ratio"] for r in records}):
        for name in sorted({label(r) for r in records if r["aspect_ratio"] == a}):
            runs = [r for r in records if r["aspect_ratio"] == a and label(r) == name]
            h, out = ([r[q] for r in runs] for q in ("h_inf_over_r0", "runout_over_r0"))
            table.row(f"{a:g}", name, len(runs), f"{np.mean(h):.3f} ({standard_deviation(h):.3f})",
                      f"{np.mean(out):.3f} ({standard_deviation(out):.3f})",
                      f"{np.mean([r['cpu_s'] for r in runs]):.0f}",
                      f"{np.mean([r['mean_iterations'] for r in runs]):.0f}")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("columns", nargs="+", type=Path)
    parser.add_argument("--tolerances", type=float, nargs="+", default=[1e-3, 1e-4, 1e-5])
    parser.add_argument("--length-floors", type=float, nargs="+", default=[0.0],
                        help="APGD's length floors, mean diameters (default: 0, the step's free flight alone)")
    parser.add_argument("--overlap-tolerances", type=float, nargs="+", default=[0.0],
                        help="APGD's overlap tolerances, mean diameters (default: 0, the relative tolerance alone)")
    parser.add_argument("--clarabel", nargs="*", default=[], help="columns (substrings) also run with Clarabel")
    parser.add_argument("--clarabel-tolerances", type=float, nargs="*", default=[],
                        help="Clarabel also at these tolerances (its own sensitivity; default 1e-8 only)")
    parser.add_argument("--steps", type=int, default=1000)
    parser.add_argument("--record", type=Path, default=Path("tolerance.jsonl"))
    args = parser.parse_args(argv)
    records = [json.loads(line) for line in args.record.read_text().splitlines()] if args.record.exists() else []
    records = [r for r in records if r["steps"] == args.steps]
    done = {(r["column"], r["solver"], r["tolerance"], r.get("length_floor") or 0.0,
             r.get("overlap_tolerance") or 0.0) for r in records}
    plan = [(c, "auto", t, f, o) for o in args.overlap_tolerances for f in args.length_floors
            for t in sorted(args.tolerances, reverse=True) for c in args.columns]
    plan += [(c, "clarabel", t, 0.0, 0.0) for t in [None, *args.clarabel_tolerances] for c in args.columns
             if any(k in str(c) for k in args.clarabel)]
    for column, solver, tolerance, floor, overlap in plan:
        if (str(column), solver, tolerance, floor, overlap) in done:
            continue
        record = run_one(column, solver, tolerance, args.steps, floor, overlap)
        records.append(record)
        with open(args.record, "a") as handle:  # every steps setting in one record file
            handle.write(json.dumps(record) + "\n")
        print(json.dumps(record), flush=True)
    report(records)


if __name__ == "__main__":
    record.run("tolerance", main)
