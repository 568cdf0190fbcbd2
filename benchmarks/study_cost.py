"""What a study's packings and collapses cost, by column size: CPU, wall, memory, threads, iterations a step.

    python -m benchmarks study_cost                      # the runs under results/
    python -m benchmarks study_cost RESULTS --aspect-ratio 5 2

Issue 30's table, read from the runs a study made rather than from new runs: each job's Snakemake
benchmark file (results/benchmarks/<the job's folder>/pack.tsv or collapse.tsv: wall `s`,
`cpu_time` in s, `max_rss` in MB) and the run's own file (packing.nc: spheres, steps, and
`wall_time` and `cpu_time` over all segments, and APGD iterations a step where the file keeps its
steps (packings since 2026-11-26); collapse.nc: spheres, steps, APGD iterations a step, threads from
its config). A job resumed from its checkpoint has benchmark figures for its last
segment only: its row says `resumed`, and its CPU over all segments is the file's where the file
has one (runs since CPU time was saved), else unknown.

Printed: one row a packing and one a collapse at each `--aspect-ratio`, then one row a column size
(means over seeds) with the growth of the mean collapse CPU with the spheres, N^k between
successive sizes. CPU above wall means the job ran on several threads. A results folder holding
cylinders and channels (whose box length L0 takes r0's place) keeps them apart: each row names its
column, "cylinder" or "channel W = ..." (the channel's width).
"""
from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path

import numpy as np

import record


def benchmark_of(results: Path, run_file: Path, name: str) -> dict | None:
    """The Snakemake benchmark figures (wall s, CPU s, peak RSS MB) of the job that wrote
    `run_file`, or None when the job left none (run outside Snakemake)."""
    tsv = results / "benchmarks" / run_file.parent.relative_to(results) / name
    if not tsv.exists():
        return None
    with tsv.open() as handle:
        rows = list(csv.DictReader(handle, delimiter="\t"))
    last = rows[-1]
    return {"wall": float(last["s"]), "cpu": float(last["cpu_time"]), "rss": float(last["max_rss"])}


def column_of(attrs) -> str:
    """The kind of column a file holds: "cylinder", or a channel with its width ("channel W = 2")."""
    from colsim.stages.pour_geometry import geometry_of

    if geometry_of(attrs) == "channel":
        return f"channel W = {float(attrs['channel_width']):g}"
    return "cylinder"


def packing_rows(results: Path) -> list[dict]:
    import xarray as xr

    rows = []
    for path in sorted(results.glob("r0_*/seed_*/pack_*/packing.nc")):
        with xr.open_dataset(path) as ds:
            attrs = ds.attrs
            row = {"column": column_of(attrs), "r0": float(attrs["r0"]), "seed": int(attrs["seed"]),
                   "spheres": ds.sizes["particle"],
                   "steps": int(attrs["steps"]), "wall_all": float(attrs["wall_time"]),
                   "cpu_file": float(attrs.get("cpu_time", np.nan)),
                   "threads": json.loads(attrs["config"]).get("threads", 1), "file": str(path),
                   "iterations": (float(ds["step_solver_iterations"].mean()) if "step_solver_iterations" in ds
                                  else None)}
        rows.append(with_benchmark(row, benchmark_of(results, path, "pack.tsv")))
    return rows


def collapse_rows(results: Path, aspect_ratios) -> list[dict]:
    import xarray as xr

    rows = []
    for path in sorted(results.glob("r0_*/seed_*/pack_*/a_*/mu_r_*/run_*/collapse.nc")):
        with xr.open_dataset(path) as ds:
            attrs = ds.attrs
            a = float(attrs["aspect_ratio"])
            if not any(np.isclose(a, wanted) for wanted in aspect_ratios):
                continue
            iterations = ds["step_solver_iterations"].values
            row = {"column": column_of(attrs), "r0": float(attrs["r0"]), "seed": int(attrs["seed"]), "a": a,
                   "mu_r": float(attrs["mu_r"]),
                   "spheres": int(attrs["n_particles"]), "steps": len(iterations),
                   "iterations": float(np.mean(iterations)), "wall_all": float(attrs["wall_time"]),
                   "cpu_file": float(attrs.get("cpu_time", np.nan)),
                   "threads": json.loads(attrs["config"]).get("threads", 1),
                   "resumed_from": int(attrs.get("resumed_from_step", 0)), "file": str(path)}
        rows.append(with_benchmark(row, benchmark_of(results, path, "collapse.tsv")))
    return rows


def with_benchmark(row: dict, bench: dict | None) -> dict:
    """row with its job's CPU, wall and memory; resumed when the job's wall is well under the file's
    wall over all segments (a checkpoint carried the rest); cpu_all: the CPU over all segments (the
    file's, else the job's when it was not resumed, else None)."""
    row.update({"cpu": None, "wall": None, "rss": None} if bench is None else bench)
    row["resumed"] = bool(row.get("resumed_from")) or (bench is not None and bench["wall"] < 0.9 * row["wall_all"])
    if np.isfinite(row.get("cpu_file", np.nan)):
        row["cpu_all"] = row["cpu_file"]
    else:
        row["cpu_all"] = None if row["resumed"] else row["cpu"]
    return row


def growth(sizes: list[tuple[float, float]]) -> list[float | None]:
    """k of cost ~ N^k between each size and the one before ((N, cost) pairs, sorted by N)."""
    out = [None]
    for (n0, c0), (n1, c1) in zip(sizes, sizes[1:]):
        out.append(float(np.log(c1 / c0) / np.log(n1 / n0)) if n1 > n0 and c0 > 0 and c1 > 0 else None)
    return out


def number(value, fmt="{:,.0f}") -> str:
    return "" if value is None else fmt.format(value)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("results", type=Path, nargs="?", default=Path("results"),
                        help="the study's results folder (default: %(default)s)")
    parser.add_argument("--aspect-ratio", type=float, nargs="+", default=[5.0],
                        help="the collapses listed (default: %(default)s)")
    args = parser.parse_args(argv)
    if not args.results.is_dir():
        raise SystemExit(f"{args.results} is not a folder of results")
    packings, collapses = packing_rows(args.results), collapse_rows(args.results, args.aspect_ratio)
    if not packings and not collapses:
        raise SystemExit(f"no packing.nc or collapse.nc under {args.results}")

    print(f"{args.results}: {len(packings)} packings, {len(collapses)} collapses at a = "
          f"{', '.join(f'{a:g}' for a in args.aspect_ratio)}")
    table = record.table(["job", "column", "r0", "seed", "a", "spheres", "steps", "threads", "CPU s, all segments",
                          "wall s, all segments", "last segment: CPU s", "wall s", "peak MB", "iterations a step"])
    for row in packings:
        table.row("pack" + (" (resumed)" if row["resumed"] else ""), row["column"], f"{row['r0']:g}", row["seed"], "",
                  f"{row['spheres']:,}", row["steps"], row["threads"], number(row["cpu_all"]),
                  number(row["wall_all"]), number(row["cpu"]), number(row["wall"]), number(row["rss"]),
                  number(row["iterations"]), data=row)
    for row in collapses:
        table.row("collapse" + (" (resumed)" if row["resumed"] else ""), row["column"], f"{row['r0']:g}", row["seed"],
                  f"{row['a']:g}", f"{row['spheres']:,}", row["steps"], row["threads"], number(row["cpu_all"]),
                  number(row["wall_all"]), number(row["cpu"]), number(row["wall"]), number(row["rss"]),
                  f"{row['iterations']:.0f}", data=row)

    print()
    sizes = record.table(["column", "r0", "a", "spheres (mean)", "packing CPU s (mean)", "collapse CPU s (mean)",
                          "collapse CPU growth N^k", "iterations a step (mean)", "peak MB (largest)"])
    for column in sorted({row["column"] for row in collapses}):
        for a in args.aspect_ratio:
            size_rows(sizes, [row for row in collapses if row["column"] == column],
                      [row for row in packings if row["column"] == column], column, a)


def size_rows(sizes, collapses: list[dict], packings: list[dict], column: str, a: float) -> None:
    """One row of `sizes` a column size at aspect ratio a: the means over seeds of one column's runs."""
    by_size = []
    for r0 in sorted({row["r0"] for row in collapses if np.isclose(row["a"], a)}):
        runs = [row for row in collapses if row["r0"] == r0 and np.isclose(row["a"], a)]
        packs = [row for row in packings if row["r0"] == r0 and row["cpu_all"] is not None]
        timed = [row["cpu_all"] for row in runs if row["cpu_all"] is not None]
        by_size.append((r0, runs, packs, timed))
    ks = growth([(np.mean([r["spheres"] for r in runs]), np.mean(timed) if timed else np.nan)
                 for _, runs, _, timed in by_size])
    for (r0, runs, packs, timed), k in zip(by_size, ks):
        pack_cpu = np.mean([p["cpu_all"] for p in packs]) if packs else None
        rss = max((r["rss"] for r in runs + packs if r["rss"] is not None), default=None)
        sizes.row(column, f"{r0:g}", f"{a:g}", f"{np.mean([r['spheres'] for r in runs]):,.0f}", number(pack_cpu),
                  number(np.mean(timed) if timed else None), number(k, "{:.2f}"),
                  f"{np.mean([r['iterations'] for r in runs]):.0f}", number(rss),
                  data={"column": column, "r0": r0, "a": a, "packing_cpu": pack_cpu, "collapse_cpu": timed,
                        "growth": k})


if __name__ == "__main__":
    record.run("study_cost", main)
