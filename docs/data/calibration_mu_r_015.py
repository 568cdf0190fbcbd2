# mu_r = 0.15 run directly, beside the value the calibration interpolated there
# (docs/validation/calibration.md, "mu_r = 0.15, run directly"). From the repository root:
#   python docs/data/calibration_mu_r_015.py
# It reads the runs, one row each, from docs/data/calibration-mu_r-0.15-runs.csv, fits their
# large-column limits by the calibration's method (colsim.study.calibration: X = X_inf + k d/r0 over
# every run, the seeds resampled within each r0, the exponent p drawn from 0.5-1.5, Student's t), and
# sets them beside the page's limits at 0.06, 0.12, 0.2 and 0.3 (calibration_limits.csv) interpolated to
# 0.15 by PCHIP, as the calibration interpolates them. It prints the page's table in Markdown.
#   python docs/data/calibration_mu_r_015.py --from-analyses results/r0_*/seed_*/pack_*/a_*/mu_r_0.15/run_*/analysis_*.nc
# writes that CSV from the study's analysis files first (colsim.study.calibration.runs_from_analyses).
from pathlib import Path

import numpy as np

from colsim.study.calibration import LAWS, limit_intervals, misfits, on_grid, relative_errors
from runs_csv import calibration_runs, main, read_rows, write_rows

HERE = Path(__file__).parent
RUNS = HERE / "calibration-mu_r-0.15-runs.csv"
LIMITS = HERE / "calibration_limits.csv"
COLUMNS = ("mu_r", "aspect_ratio", "r0", "seed", "d_over_r0", "height", "runout")
MU_R, REPLICATES, LEVEL = 0.15, 1000, 0.95
#: where the runs came from (docs/validation/calibration.md, "mu_r = 0.15, run directly")
PROVENANCE = ("runs at commits 34ac28f (r0 = 2), 868d642 (r0 = 3) and 90faf5c (r0 = 4), 2026-12-06 15:51 to "
              "2026-12-07 00:11 UTC, the 2-core AMD EPYC; 15,219 s of CPU (pours 5,284 s, collapses 9,935 s)")


def write_runs(paths) -> None:
    """The runs of the analysis files `paths` (one mu_r) into RUNS, sorted by r0, seed and a."""
    import xarray as xr

    from colsim.study.calibration import runs_from_analyses

    analyses = [xr.load_dataset(path) for path in paths]
    runs = runs_from_analyses(analyses)
    rows = sorted(zip(*(getattr(runs, name) for name in COLUMNS)), key=lambda row: (row[2], row[3], row[1]))
    write_rows(RUNS, "mu_r = 0.15 of config/calibration.yaml, one row a run: its analysis file's h_inf/r0 (height),\n"
               "(r_inf - r0)/r0 (runout) and mean diameter over r0; written by calibration_mu_r_015.py.\n"
               f"provenance: {PROVENANCE}", COLUMNS, rows)


def read_runs():
    return calibration_runs(read_rows(RUNS))


def measured_limits(runs):
    """((2, n_a) limits, (2, n_a) low ends, (2, n_a) high ends) of height and run-out at the one mu_r."""
    return tuple(part[:, 0] for part in limit_intervals(runs, REPLICATES, LEVEL))


def interpolated_limits(ratios):
    """(2, n_a) the page's limits interpolated to MU_R (PCHIP over its four mu_r, per a and measure)."""
    rows = read_rows(LIMITS)
    mu_rs = np.unique([float(row["mu_r"]) for row in rows])
    table = np.full((2, len(mu_rs), len(ratios)), np.nan)
    for row in rows:
        if float(row["aspect_ratio"]) in ratios:
            q = 0 if row["measure"] == "height" else 1
            j = list(ratios).index(float(row["aspect_ratio"]))
            table[q, np.searchsorted(mu_rs, float(row["mu_r"])), j] = float(row["limit"])
    return on_grid(table, mu_rs, np.array([MU_R]))[:, 0]


def report(runs) -> str:
    ratios = np.unique(runs.aspect_ratio)
    limits, low, high = measured_limits(runs)
    guess = interpolated_limits(ratios)
    lines = ["| a | measure | measured limit [95 %] | interpolated | Lube | error, measured | error, interpolated |",
             "|---|---|---|---|---|---|---|"]
    for j, a in enumerate(ratios):
        for q, name in enumerate(("height", "runout")):
            law = LAWS["lube"][q](np.array([a]))[0]
            lines.append(f"| {a:g} | {name} | {limits[q, j]:.3f} [{low[q, j]:.3f}, {high[q, j]:.3f}] | "
                         f"{guess[q, j]:.3f} | {law:.3f} | {limits[q, j] / law - 1:+.1%} | {guess[q, j] / law - 1:+.1%} |")
    lines.append("")
    for law in LAWS:
        measured = relative_errors(limits[:, None], ratios, law)                # (2, 1, n_a)
        interpolated = relative_errors(guess[:, None], ratios, law)
        for label, errors in (("measured", measured), ("interpolated", interpolated)):
            rms = misfits(errors)[:, 0]
            lines.append(f"- {law}, {label}: root-mean-square {rms[2]:.1%} (heights {rms[0]:.1%}, run-outs "
                         f"{rms[1]:.1%}); worst {np.nanmax(np.abs(errors)):.1%}")
    sizes = ", ".join(f"r0 = {r:g}: {len(np.unique(runs.seed[runs.r0 == r]))} seeds" for r in np.unique(runs.r0))
    lines.append(f"\n{len(runs.mu_r)} runs ({sizes}); {REPLICATES} replicates, bootstrap seed 0.")
    return "\n".join(lines)


if __name__ == "__main__":
    main(__doc__, write_runs, lambda: report(read_runs()))
