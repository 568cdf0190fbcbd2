"""How far a collapse's deposit moves under rounding-sized changes: the scatter a device's answer is
judged against ("the same answer", docs/solvers.md).

    python -m benchmarks scatter .gpu/rest/r0_3_a2_seed1.nc --settings .gpu/rest/r0_3_a2_seed1.settings.yaml \
        --draws 1-10 --tolerances 9e-6 9.5e-6 1.05e-5 1.1e-5 --jobs 2 --record scatter.jsonl
    python -m benchmarks scatter COLUMN --settings S --device cuda --tolerances 9e-6 1.1e-5 ...

Each run is `colsim collapse` of the column with the run's settings (to rest), then `colsim
analyse`, in a child process: the settings' own run, one run at each APGD `--tolerances`, and one
for each of `--draws` with every starting position moved by `--epsilon` (1e-12) mean diameters times
a uniform draw in (-1, 1) (numpy's default_rng(draw)), a change of the size of rounding. The
collapse is chaotic, so these end on different deposits; their spread is what "the same answer"
means for two devices, whose arithmetic rounds differently. `--device` and `--threads` pass to
`colsim collapse`; `--gpu-storage float32` runs with APGD's float32 storage on the GPU, recorded as
the device "cuda-float32"; `--jobs` runs that many at once. Each finished run is appended to `--record` as
one JSON line, and runs already there are skipped, so a killed scatter resumes. The tables: each
run, then for each device the range, mean and standard deviation of h_inf/r0 and run-out (r_inf -
r0)/r0 (with `--compare H RUNOUT`, where a deposit measured elsewhere lies in them), and where the
records (`--also` adds another's) hold the CPU's runs and another device's, where each of the
other's deposits lies in the CPU's scatter and whether the other's mean is the CPU's (:func:`compared`).
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

import record
from colsim.solvers.defaults import DEFAULT_GPU_STORAGE, GPU_STORAGES

# HDF5, under netCDF4, is not safe to call from two threads at once: `--jobs 14` segfaulted in
# libhdf5 on the 16-core GPU host (2026-11-28). The runs themselves are child processes; only this
# process's reads and writes of the files are serialised.
NETCDF_LOCK = threading.Lock()


def draws_of(text: str) -> list[int]:
    """'1-10' or '3' or '1,4,7' -> the draws' seeds."""
    out = []
    for part in text.split(","):
        low, _, high = part.partition("-")
        out += list(range(int(low), int(high or low) + 1))
    return out


def perturbed(column: Path, draw: int, epsilon: float, folder: Path) -> Path:
    """A copy of `column` with every position moved by epsilon * (mean diameter) * uniform(-1, 1)."""
    import xarray as xr

    with NETCDF_LOCK:
        dataset = xr.load_dataset(column)
    diameter = 2.0 * float(dataset["radius"].mean())
    rng = np.random.default_rng(draw)
    dataset["position"] = dataset["position"] + epsilon * diameter * rng.uniform(-1.0, 1.0, dataset["position"].shape)
    dataset.attrs["scatter_perturbation"] = f"positions + {epsilon:g} d uniform(-1, 1), default_rng({draw})"
    path = folder / f"draw{draw}.nc"
    with NETCDF_LOCK:
        dataset.to_netcdf(path)
    return path


def recorded_device(device: str, storage: str = DEFAULT_GPU_STORAGE) -> str:
    """The device a run is recorded as: `device`, or for one with float32 storage on the GPU
    "cuda-float32"."""
    return device if storage == DEFAULT_GPU_STORAGE else f"{device}-{storage}"


def run_one(column: Path, settings: Path, run: dict, device: str, threads: int, epsilon: float,
            storage: str = DEFAULT_GPU_STORAGE) -> dict:
    """Collapse and analyse one run ({"kind": "settings" | "tolerance" | "draw", "value": ...});
    storage: APGD's on the GPU (`--gpu-storage`)."""
    with tempfile.TemporaryDirectory(prefix="scatter-") as scratch:
        folder = Path(scratch)
        start_from = perturbed(column, run["value"], epsilon, folder) if run["kind"] == "draw" else column
        flags = ["--solver-tolerance", f"{run['value']:g}"] if run["kind"] == "tolerance" else []
        command = [sys.executable, "-m", "colsim.cli", "collapse", "--settings", str(settings), "--input",
                   str(start_from), "--output", str(folder / "collapse.nc"), "--device", device,
                   "--threads", str(threads), "--gpu-storage", storage, "-q", *flags]
        started = time.perf_counter()
        done = subprocess.run(command, capture_output=True, text=True)
        wall = time.perf_counter() - started
        if done.returncode:
            raise RuntimeError(f"{run}: colsim collapse failed:\n{done.stderr[-2000:]}")
        subprocess.run([sys.executable, "-m", "colsim.cli", "analyse", "--input", str(folder / "collapse.nc"),
                        "--output", str(folder / "analysis.nc"), "-q"], check=True, capture_output=True)
        import xarray as xr

        with NETCDF_LOCK:
            with xr.open_dataset(folder / "collapse.nc") as trajectory:
                steps = int(trajectory.attrs["n_steps"])
            with xr.open_dataset(folder / "analysis.nc") as analysis:
                h, out = float(analysis["h_inf_over_r0"]), float(analysis["runout_over_r0"])
    return {"column": str(column), "device": recorded_device(device, storage), "kind": run["kind"],
            "value": run["value"], "h_inf_over_r0": h, "runout_over_r0": out, "steps": steps, "wall_s": wall}


def label(r: dict) -> str:
    if r["kind"] == "settings":
        return "the settings' own"
    return f"tolerance {r['value']:g}" if r["kind"] == "tolerance" else f"positions moved, draw {r['value']}"


def standard_deviation(values: np.ndarray) -> float:
    """The sample standard deviation (NaN for fewer than two values)."""
    return float(np.std(values, ddof=1)) if len(values) > 1 else float("nan")


def placed(value: float, values: np.ndarray) -> str:
    """Where value lies in a scatter: standard deviations from its mean, and inside or outside its range."""
    sd = standard_deviation(values)
    inside = "inside" if values.min() <= value <= values.max() else "outside"
    return f"{value:.3f}: {(value - values.mean()) / sd:+.1f} sd ({inside})"


def compared(cpu: np.ndarray, other: np.ndarray) -> dict:
    """Whether another device's deposits (one quantity, a run each) share the CPU's mean: the
    difference of the means and its 95 % interval (Welch's), Welch's t and its two-sided p, and the
    Mann-Whitney U test's two-sided p (which asks no normal law of a run-out's heavy tail). The
    interval is what the runs allow: 20-45 runs a side fix a run-out's mean to 1-2 % only."""
    from scipy import stats

    welch = stats.ttest_ind(other, cpu, equal_var=False)
    interval = welch.confidence_interval(0.95)
    return {"difference": float(other.mean() - cpu.mean()), "low": float(interval.low), "high": float(interval.high),
            "t": float(welch.statistic), "p_welch": float(welch.pvalue),
            "p_mann_whitney": float(stats.mannwhitneyu(other, cpu).pvalue)}


def report(records: list[dict], compare: list[float] | None) -> None:
    table = record.table(["device", "run", "h_inf/r0", "run-out/r0", "steps", "wall s"], title="runs")
    for r in records:
        table.row(r["device"], label(r), f"{r['h_inf_over_r0']:.3f}", f"{r['runout_over_r0']:.3f}", r["steps"],
                  f"{r['wall_s']:.0f}", data=r)
    print()
    columns = ["device", "runs", "h_inf/r0 range", "h_inf/r0 mean (sd)", "run-out/r0 range", "run-out/r0 mean (sd)"]
    if compare:
        columns += ["compared h_inf/r0: sd from mean", "compared run-out: sd from mean"]
    table = record.table(columns, title="scatter")
    for device in sorted({r["device"] for r in records}):
        runs = [r for r in records if r["device"] == device]
        row = [device, len(runs)]
        for name in ("h_inf_over_r0", "runout_over_r0"):
            values = np.array([r[name] for r in runs])
            row += [f"{values.min():.3f}-{values.max():.3f}", f"{values.mean():.3f} ({standard_deviation(values):.3f})"]
        if compare:
            row += [placed(value, np.array([r[name] for r in runs]))
                    for value, name in zip(compare, ("h_inf_over_r0", "runout_over_r0"))]
        table.row(*row)
    cpu = [r for r in records if r["device"] == "cpu"]
    others = [r for r in records if r["device"] != "cpu"]
    if cpu and others:
        print()
        table = record.table(["device", "run", "h_inf/r0 in the CPU's scatter", "run-out/r0 in the CPU's scatter"],
                             title="against the CPU's scatter")
        for r in others:
            table.row(r["device"], label(r), *(placed(r[name], np.array([c[name] for c in cpu]))
                                               for name in ("h_inf_over_r0", "runout_over_r0")))
        print()
        table = record.table(["device", "quantity", "runs (CPU; device)", "mean difference", "95 % interval",
                              "Welch's t (p)", "Mann-Whitney p"], title="the same mean as the CPU's?")
        for device in sorted({r["device"] for r in others}):
            for name in ("h_inf_over_r0", "runout_over_r0"):
                mine = np.array([r[name] for r in others if r["device"] == device])
                theirs = np.array([c[name] for c in cpu])
                if len(mine) < 2 or len(theirs) < 2:
                    continue
                c = compared(theirs, mine)
                table.row(device, name, f"{len(theirs)}; {len(mine)}", f"{c['difference']:+.3f}",
                          f"{c['low']:+.3f} to {c['high']:+.3f}", f"{c['t']:.2f} ({c['p_welch']:.3f})",
                          f"{c['p_mann_whitney']:.3f}", data={"device": device, "quantity": name, **c})


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("column", type=Path, help="a `colsim trim` column file")
    parser.add_argument("--settings", type=Path, required=True, help="the run's settings.yaml (the study's)")
    parser.add_argument("--tolerances", type=float, nargs="*", default=[], help="APGD tolerances, one run each")
    parser.add_argument("--draws", type=draws_of, default=[], help="perturbation seeds: '1-10', '3' or '1,4'")
    parser.add_argument("--epsilon", type=float, default=1e-12, help="the perturbation, mean diameters")
    parser.add_argument("--no-own", action="store_true", help="skip the run with the settings' own tolerance")
    parser.add_argument("--device", default="cpu", choices=("cpu", "cuda"))
    parser.add_argument("--gpu-storage", default=DEFAULT_GPU_STORAGE, choices=GPU_STORAGES,
                        help="APGD's storage on the GPU (--device cuda), recorded as cuda-float32")
    parser.add_argument("--threads", type=int, default=1, help="threads of each run")
    parser.add_argument("--jobs", type=int, default=1, help="runs at once")
    parser.add_argument("--record", type=Path, default=Path("scatter.jsonl"))
    parser.add_argument("--also", type=Path, nargs="*", default=[],
                        help="other records whose runs of this column join the tables (not run here: another "
                             "device's, say)")
    parser.add_argument("--compare", type=float, nargs=2, metavar=("H", "RUNOUT"),
                        help="another device's h_inf/r0 and run-out, placed in the scatter")
    args = parser.parse_args(argv)
    if args.gpu_storage != DEFAULT_GPU_STORAGE and args.device != "cuda":
        parser.error("--gpu-storage float32 is a GPU run's (--device cuda)")
    device = recorded_device(args.device, args.gpu_storage)
    records = [json.loads(line) for path in [args.record, *args.also] if path.exists()
               for line in path.read_text().splitlines()]
    records = [r for r in records if r["column"] == str(args.column)]
    done = {(r["device"], r["kind"], r["value"]) for r in records}
    plan = ([] if args.no_own else [{"kind": "settings", "value": None}])
    plan += [{"kind": "tolerance", "value": t} for t in args.tolerances]
    plan += [{"kind": "draw", "value": d} for d in args.draws]
    plan = [run for run in plan if (device, run["kind"], run["value"]) not in done]
    args.record.parent.mkdir(parents=True, exist_ok=True)

    def one(run):
        return run_one(args.column, args.settings, run, args.device, args.threads, args.epsilon,
                       args.gpu_storage)

    with ThreadPoolExecutor(max(1, args.jobs)) as pool:
        for result in pool.map(one, plan):
            records.append(result)
            with open(args.record, "a") as handle:
                handle.write(json.dumps(result) + "\n")
            print(f"{label(result)}: h_inf/r0 {result['h_inf_over_r0']:.3f}, run-out {result['runout_over_r0']:.3f}, "
                  f"{result['steps']} steps, {result['wall_s']:.0f} s", flush=True)
    report(records, args.compare)


if __name__ == "__main__":
    record.run("scatter", main)
