# The size law's predictions for columns beyond r0 = 6, stated before they are measured
# (docs/validation/column-size.md, "Beyond r0 = 6"). From the repository root:
#   python docs/data/beyond_r0_6.py
# For the columns a GPU pours and collapses (r0 = 8 and 10, a = 2 and 5, mu_r = 0.12, the default
# settings) it prints each measure's prediction two ways, then what was measured:
# - p = 1 through today's runs: the seed design's mu_r = 0.12 runs (docs/data/limits-design-runs.csv,
#   r0 = 2-4, the code the GPU runs), X = X_inf + k d/r0 by least squares over every run, with a 95 %
#   interval for one more run (Student's t on the fit's residuals, n - 2 degrees of freedom: a seed's
#   scatter as at the small sizes, so wide where a larger column scatters less);
# - p = 1 through the column-size study's r0 = 2-6 means (docs/data/column-size-limits.csv, their
#   runs made before the step's gap-term change of 79c109a: another realization of the same physics,
#   up to 7 % apart in run-out at equal size, docs/validation/calibration.md), with the interval of
#   docs/data/column_size_exponent.py's fit (t with its scatter's 6 degrees of freedom), and the range
#   of that fit's value over the one p's 95 % interval (the size law's exponent, not known);
# - the runs measured beyond r0 = 6 (docs/data/column-size-beyond-6.csv): their mean and its distance
#   from today's prediction in standard errors.
# Then how often today's intervals hold a run at r0 = 8 and 10 over synthetic studies of the design:
# where p = 1 holds, and where the values follow the run-outs' fitted p instead (0.445: what one run can see).
#   python docs/data/beyond_r0_6.py --from-analyses FILE ...
# writes column-size-beyond-6.csv from the analysis files of such runs (colsim analyse's output) first.
from pathlib import Path

import numpy as np
from scipy.stats import t as student_t

import column_size_exponent as exponent
from runs_csv import main, read_rows, write_rows

HERE = Path(__file__).parent
TODAY = HERE / "limits-design-runs.csv"
MEASURED = HERE / "column-size-beyond-6.csv"
MU_R = 0.12
TARGETS = ((2.0, (8, 10)), (5.0, (8, 10)))   #: (a, r0s) the GPU's columns
MEASURES = (("height", "h_inf_over_r0"), ("runout", "runout_over_r0"))
COLUMNS = ("r0", "seed", "aspect_ratio", "mu_r", "d_over_r0", "height", "runout", "commit")
STUDIES = 400
SEED = 83


def write_measured(paths) -> None:
    """The runs beyond r0 = 6 among the analysis files `paths` into MEASURED; a file of another mu_r is
    refused (the predictions are mu_r = 0.12's)."""
    import xarray as xr

    rows = []
    for path in paths:
        analysis = xr.load_dataset(path)
        attrs = analysis.attrs
        if not np.isclose(float(attrs["mu_r"]), MU_R):
            raise SystemExit(f"{path}: mu_r = {attrs['mu_r']}, but the predictions are for mu_r = {MU_R}")
        r0 = float(attrs["r0"])
        if r0 > 6:
            rows.append((r0, int(attrs["seed"]), float(attrs["aspect_ratio"]), MU_R,
                         float(analysis["mean_diameter"]) / r0, float(analysis["h_inf_over_r0"]),
                         float(analysis["runout_over_r0"]), str(attrs["colsim_commit"])[:7]))
    rows.sort()
    write_rows(MEASURED, "Columns beyond r0 = 6 at mu_r = 0.12 (the default settings), one row a run: its analysis\n"
               "file's h_inf/r0 (height), (r_inf - r0)/r0 (runout) and mean diameter over r0, and its commit;\n"
               "written by beyond_r0_6.py from the analyses of benchmarks/gpu_machine.sh's pours.", COLUMNS, rows)


def today_runs(measure: str, a: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(d/r0, the measure, r0) of today's mu_r = 0.12 runs at a."""
    rows = [row for row in read_rows(TODAY)
            if np.isclose(float(row["mu_r"]), MU_R) and float(row["aspect_ratio"]) == a]
    return tuple(np.array([float(row[name]) for row in rows]) for name in ("d_over_r0", measure, "r0"))


def line_prediction(x: np.ndarray, y: np.ndarray, at: float, runs: int = 1) -> tuple[float, float, int]:
    """(the value at `at`, the standard error of the mean of `runs` more runs there, degrees of
    freedom) of the least-squares line y = X_inf + k x over the runs."""
    design = np.column_stack([np.ones_like(x), x])
    coefficients, *_ = np.linalg.lstsq(design, y, rcond=None)
    dof = len(y) - 2
    variance = np.sum((y - design @ coefficients) ** 2) / dof
    point = np.array([1.0, at])
    spread = point @ np.linalg.inv(design.T @ design) @ point
    return float(point @ coefficients), float(np.sqrt(variance * (1 / runs + spread))), dof


def interval(value: float, error: float, dof: int) -> tuple[float, float]:
    half = student_t.ppf(0.975, dof) * error
    return value - half, value + half


def today(measure: str, a: float, r0: float, runs: int = 1):
    """(value, (low, high), standard error, sizes) of today's p = 1 prediction at r0 for the mean of
    `runs` runs, or None where fewer than two sizes were run."""
    x, y, radii = today_runs(measure, a)
    if len(np.unique(radii)) < 2:
        return None
    diameter = float(np.mean(x * radii))
    value, error, dof = line_prediction(x, y, diameter / r0, runs)
    return value, interval(value, error, dof), error, sorted({int(r) for r in radii})


def column_size(variable: str, measure: str, a: float, r0: float) -> tuple[float, tuple, tuple]:
    """(value, its 95 % interval, (lowest, highest) over the one p's interval) of the column-size
    means' fit at r0."""
    fit = next(item for item in exponent.series(variable, measure) if item[0] == a)
    _, inverse_r0, means, seeds, scatter, scale = fit
    line, covariance = exponent.fitted(1.0, inverse_r0, means, seeds, scatter)
    point = np.array([1.0, 1.0 / r0])
    value, error = point @ line, np.sqrt(point @ covariance @ point + scatter**2)
    exponents = exponent.pooled_inside(variable, measure)
    (limits, slopes), _ = exponent.fitted(exponents, inverse_r0, means, seeds, scatter)
    values = limits + slopes * r0**-exponents
    return (scale * value, tuple(scale * np.array(interval(value, error, exponent.SCATTER_DOF))),
            (scale * min(values), scale * max(values)))


def measured(measure: str, a: float, r0: float) -> np.ndarray:
    if not MEASURED.exists():
        return np.array([])
    return np.array([float(row[measure]) for row in read_rows(MEASURED)
                     if float(row["aspect_ratio"]) == a and float(row["r0"]) == r0])


def prediction_table() -> str:
    lines = ["| measure | a | r0 | p = 1, today's runs [95 %, one run] | p = 1, r0 = 2-6 before 79c109a [95 %] "
             "| over the fitted p's interval | measured (runs) | measured - today's, in standard errors |",
             "|---|---|---|---|---|---|---|---|"]
    for measure, variable in MEASURES:
        for a, radii in TARGETS:
            for r0 in radii:
                ours = today(measure, a, r0)
                mine = (f"{ours[0]:.3f} [{ours[1][0]:.3f}, {ours[1][1]:.3f}] (r0 = {', '.join(map(str, ours[3]))})"
                        if ours else "fewer than two sizes run")
                theirs, (low, high), (least, most) = column_size(variable, measure, a, r0)
                runs = measured(measure, a, r0)
                seen = f"{runs.mean():.3f} ({len(runs)})" if len(runs) else "not yet"
                distance = (f"{(runs.mean() - ours[0]) / today(measure, a, r0, len(runs))[2]:+.1f}"
                            if len(runs) and ours else "")
                lines.append(f"| {measure} | {a:g} | {r0} | {mine} | {theirs:.3f} [{low:.3f}, {high:.3f}] "
                             f"| {least:.3f}-{most:.3f} | {seen} | {distance} |")
    return "\n".join(lines)


def held(measure: str, a: float, true_p: float, rng) -> dict:
    """{r0: the share of STUDIES synthetic studies of today's design in which today's p = 1 interval
    holds one more run at r0}: each study the runs' d/r0 as they are, values on the curve X_inf + k
    (d/r0)^true_p fitted to the runs, plus Gaussian noise of the fit's residual scatter."""
    x, y, radii = today_runs(measure, a)
    diameter = float(np.mean(x * radii))
    design = np.column_stack([np.ones_like(x), x**true_p])
    truth, *_ = np.linalg.lstsq(design, y, rcond=None)
    noise = np.sqrt(np.sum((y - design @ truth) ** 2) / (len(y) - 2))
    shares = {}
    for r0 in (8, 10):
        at = diameter / r0
        hits = 0
        for _ in range(STUDIES):
            runs = design @ truth + rng.normal(0.0, noise, len(y))
            value, error, dof = line_prediction(x, runs, at)
            low, high = interval(value, error, dof)
            hits += low <= truth[0] + truth[1] * at**true_p + rng.normal(0.0, noise) <= high
        shares[r0] = hits / STUDIES
    return shares


def coverage_table() -> str:
    rng = np.random.default_rng(SEED)
    lines = ["| measure | a | true p | holds a run at r0 = 8 | at r0 = 10 |", "|---|---|---|---|---|"]
    for measure, _ in MEASURES:
        for a, _ in TARGETS:
            if today(measure, a, 8) is None:
                continue
            for true_p in (1.0, exponent.pooled_exponent("runout_over_r0", "runout")):
                shares = held(measure, a, true_p, rng)
                lines.append(f"| {measure} | {a:g} | {true_p:.3g} | {shares[8]:.1%} | {shares[10]:.1%} |")
    return "\n".join(lines)


if __name__ == "__main__":
    main("The size law's predictions beyond r0 = 6 beside what was measured there.", write_measured,
         lambda: prediction_table() + "\n\n" + coverage_table())
