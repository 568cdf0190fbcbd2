# The large-column limits at mu_r = 0.12, 0.15 and 0.2 from the seed design of config/limits.yaml
# (docs/validation/calibration.md, "Seeds where they pay"). From the repository root:
#   python docs/data/limits_design.py
# It reads the design's runs, one row each, from docs/data/limits-design-runs.csv (5 seeds at r0 = 2,
# 2 at r0 = 3 and 4; runs of other seeds are left out), fits each limit by the calibration's method
# (colsim.study.calibration.limit_intervals: X = X_inf + k d/r0 over every run, the seeds resampled
# within each r0, p drawn from 0.5-1.5, Student's t) and prints, for every mu_r whose every a has runs
# at two r0 or more, the limits with their 95 % half-widths; then the design's CPU and how far the
# half-widths are from 3 %: the seeds' part (the same bootstrap with p kept at 1) shrinks as one over
# the square root of the design's repetitions, the exponent's part does not.
#   python docs/data/limits_design.py --from-analyses results/r0_*/seed_*/pack_*/a_*/mu_r_*/run_*/analysis_*.nc
# writes that CSV from the study's analysis files first, with each run's collapse and pour CPU time
# (the cpu_time of the collapse.nc beside the analysis and of its packing.nc).
from pathlib import Path

import numpy as np

from colsim.study.calibration import calibrate, limit_intervals, mu_r_interval
from runs_csv import calibration_runs, main, read_rows, run_costs, write_rows

HERE = Path(__file__).parent
RUNS = HERE / "limits-design-runs.csv"
DESIGN = {2: 5, 3: 2, 4: 2}      #: seeds a size (colsim.study.seed_design.best_seeds)
MU_RS = (0.12, 0.15, 0.2)
TARGET = 0.03                    #: the half-width the issue asks of every limit
REPLICATES = 1000
MEASURES = ("height", "runout")
FIT = ("mu_r", "aspect_ratio", "r0", "seed", "d_over_r0", "height", "runout")
COLUMNS = FIT + ("collapse_cpu_time", "pour_cpu_time", "commit")


def _in_design(r0: float, seed: float) -> bool:
    return seed <= DESIGN.get(int(r0), 0)


def write_runs(paths) -> None:
    """The design's runs among the analysis files `paths` into RUNS, sorted by mu_r, r0, seed and a."""
    import xarray as xr

    from colsim.study.calibration import runs_from_analyses

    kept = [(path, analysis) for path, analysis in ((path, xr.load_dataset(path)) for path in paths)
            if _in_design(float(analysis.attrs["r0"]), int(analysis.attrs["seed"]))
            and any(np.isclose(float(analysis.attrs["mu_r"]), MU_RS))]
    runs = runs_from_analyses([analysis for _, analysis in kept])
    rows = [(*values, *run_costs(path)) for values, (path, _) in
            zip(zip(*(getattr(runs, name) for name in FIT)), kept)]
    rows.sort(key=lambda row: (row[0], row[2], row[3], row[1]))
    write_rows(RUNS, "The seed design of config/limits.yaml, one row a run: its analysis file's h_inf/r0 (height),\n"
               "(r_inf - r0)/r0 (runout) and mean diameter over r0, the CPU seconds of its collapse and of its\n"
               "packing's pour, and the commit of its collapse; written by limits_design.py. Machine: the 2-core AMD EPYC.",
               COLUMNS, rows)


def complete(rows, mu_r: float) -> bool:
    """Whether every a at mu_r has runs at two r0 or more (so that it has a limit)."""
    mine = [row for row in rows if np.isclose(float(row["mu_r"]), mu_r)]
    ratios = {row["aspect_ratio"] for row in mine}
    return bool(mine) and all(len({row["r0"] for row in mine if row["aspect_ratio"] == a}) >= 2 for a in ratios)


def half_widths(limits, low, high) -> np.ndarray:
    """The relative 95 % half-width of each limit: its interval's longer side over the limit."""
    return np.maximum(high - limits, limits - low) / np.abs(limits)


def runs_made(rows, mu_r: float, r0: float) -> int:
    return sum(np.isclose(float(row["mu_r"]), mu_r) and float(row["r0"]) == r0 for row in rows)


def progress(rows) -> list:
    """Per mu_r: its runs against the design's 6 a times its seeds, per r0."""
    lines = []
    for mu_r in MU_RS:
        counts = [f"r0 = {r0}: {runs_made(rows, mu_r, r0)} of {6 * seeds}" for r0, seeds in DESIGN.items()]
        lines.append(f"- mu_r = {mu_r:g}: {', '.join(counts)} runs")
    return lines


def cost(rows) -> float:
    """CPU seconds of the rows' collapses and of their distinct pours."""
    pours = {(row["r0"], row["seed"]): float(row["pour_cpu_time"]) for row in rows}
    return sum(float(row["collapse_cpu_time"]) for row in rows) + sum(pours.values())


def three_seeds_line(design_widths) -> str:
    """The design's half-widths at mu_r = 0.15 beside those of the three seeds a size that ran there first
    (calibration-mu_r-0.15-runs.csv, the same method)."""
    earlier = calibration_runs(read_rows(HERE / "calibration-mu_r-0.15-runs.csv"))
    widths = half_widths(*limit_intervals(earlier, REPLICATES))[:, 0]
    return (f"- mu_r = 0.15 with three seeds at each r0 ({len(earlier.mu_r)} runs): half-widths {widths.min():.1%}-"
            f"{widths.max():.1%} (median {np.median(widths):.1%}), against the design's median "
            f"{np.median(design_widths):.1%}")


def each_mu_r(rows, mu_rs) -> tuple:
    """(limits, low ends, high ends, half-widths, half-widths with p kept at 1), each (2, n_mu, n_a):
    every mu_r's from its own runs (a mu_r's interval does not move while another's runs come in: the
    Student's t widening counts its own degrees of freedom)."""
    parts = []
    for mu_r in mu_rs:
        runs = calibration_runs([row for row in rows if np.isclose(float(row["mu_r"]), mu_r)])
        limits, low, high = limit_intervals(runs, REPLICATES)
        parts.append((limits, low, high, half_widths(limits, low, high),
                      half_widths(*limit_intervals(runs, REPLICATES, exponents=None))))
    return tuple(np.concatenate(arrays, axis=1) for arrays in zip(*parts))


def calibration_line(rows) -> str:
    """The design's runs at every mu_r as one calibration against Lube et al.
    (colsim.study.calibration.calibrate, the swept 0.12-0.2 only): the best mu_r for both measures,
    the minimax mu_r with its worst error, and the share of replicates in which some mu_r puts every a
    within 10 %."""
    result = calibrate(calibration_runs(rows), REPLICATES).sel(law="lube")
    sweep, best = (MU_RS[0], MU_RS[-1]), result.sel(measure="both")
    return (f"- the design's runs as one calibration against Lube et al. (mu_r = {MU_RS[0]:g}-{MU_RS[-1]:g} only): "
            f"both measures fit best at mu_r = {float(best.best_mu_r):.3f} "
            f"{mu_r_interval(float(best.best_mu_r_low), float(best.best_mu_r_high), sweep)}; the smallest worst-case "
            f"error, {float(result.minimax_error):.1%}, is at mu_r = {float(result.minimax_mu_r):.3f} "
            f"{mu_r_interval(float(result.minimax_mu_r_low), float(result.minimax_mu_r_high), sweep)}; some mu_r puts "
            f"every a within 10 % in {float(result.fitting_share):.1%} of the replicates")


def report(rows) -> str:
    rows = [row for row in rows if _in_design(float(row["r0"]), float(row["seed"]))]
    done = [mu_r for mu_r in MU_RS if complete(rows, mu_r)]
    lines = progress(rows)
    if not done:
        return "\n".join(lines + ["", "No mu_r has runs at two r0 or more for every a yet."])
    chosen = [row for row in rows if any(np.isclose(float(row["mu_r"]), done))]
    limits, low, high, widths, seeds_only = each_mu_r(chosen, done)
    ratios = np.unique(calibration_runs(chosen).aspect_ratio)
    header = " | ".join(f"mu_r = {mu_r:g} [95 %], half-width" for mu_r in done)
    lines += ["", f"| a | measure | {header} |", "|---|---|" + "---|" * len(done)]
    for j, a in enumerate(ratios):
        for q, measure in enumerate(MEASURES):
            cells = " | ".join(f"{limits[q, i, j]:.3f} [{low[q, i, j]:.3f}, {high[q, i, j]:.3f}], "
                               f"{widths[q, i, j]:.1%}" for i in range(len(done)))
            lines.append(f"| {a:g} | {measure} | {cells} |")
    lines.append("")
    for i, mu_r in enumerate(done):
        mine = [row for row in chosen if np.isclose(float(row["mu_r"]), mu_r)]
        hours = cost(mine) / 3600
        repeats = (seeds_only[:, i] / TARGET) ** 2
        lines.append(
            f"- mu_r = {mu_r:g}: {len(mine)} runs, {hours:.1f} h of CPU; half-widths {widths[:, i].min():.1%}-"
            f"{widths[:, i].max():.1%} (median {np.median(widths[:, i]):.1%}), {int((widths[:, i] <= TARGET).sum())} of "
            f"{widths[:, i].size} within {TARGET:.0%}; with p kept at 1 {seeds_only[:, i].min():.1%}-"
            f"{seeds_only[:, i].max():.1%}: seeds bring the median to {TARGET:.0%} after "
            f"{max(np.median(repeats) - 1, 0) * hours:.0f} h more and the widest after "
            f"{max(repeats.max() - 1, 0) * hours:.0f} h")
    if 0.15 in done:
        lines.append(three_seeds_line(widths[:, done.index(0.15)]))
    if all(runs_made(rows, mu_r, r0) == 6 * seeds for mu_r in MU_RS for r0, seeds in DESIGN.items()):
        lines.append(calibration_line(chosen))
    lines.append(f"\n{REPLICATES} replicates, bootstrap seed 0.")
    return "\n".join(lines)


if __name__ == "__main__":
    main(__doc__, write_runs, lambda: report(read_rows(RUNS)))
