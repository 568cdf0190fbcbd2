# The size law's exponent p fitted to the column-size study (docs/validation/column-size.md, "The size
# law's exponent, fitted"). From the repository root:
#   python docs/data/column_size_exponent.py
# X(r0) = X_inf + k (d/r0)^p is fitted to each size's mean (docs/data/column-size-limits.csv, r0 = 2-6,
# three seeds up to r0 = 4 and two above), weighted by its seeds over a run's variance. The runs
# themselves were not kept, so a run's scatter comes from the calibration's mu_r = 0.15 runs
# (docs/data/calibration-mu_r-0.15-runs.csv: three seeds at each r0 = 2, 3, 4 and a, their relative
# sample variance pooled over r0, 6 degrees of freedom). p's 95 % interval is the profile of chi^2:
# every p within a critical value of the least chi^2, searched on P_BOUNDS; an end at a bound prints
# as "<= 0.25" or ">= 4". Each a's critical value is chi^2_1's 3.84. Pooled, one p for every a of a
# measure (X_inf and k per a), it is measured on synthetic studies of the design (pooled_critical),
# and the last table checks both on fresh ones.
# It also prints the p = 1 line through r0 = 2-4's means extrapolated to r0 = 5 and 6, beside their
# measured means: the direct test of p = 1.
from functools import cache
from pathlib import Path

import numpy as np
from scipy.stats import chi2

from colsim.study.size_limit import P_BOUNDS
from runs_csv import read_rows

HERE = Path(__file__).parent
SIZES = (2, 3, 4, 5, 6)
MEASURES = (("h_inf_over_r0", "height"), ("runout_over_r0", "runout"))
GRID = np.linspace(*P_BOUNDS, 1501)
CRITICAL = chi2.ppf(0.95, 1)
SCATTER_DOF = 6   #: the degrees of freedom of a run's scatter (:func:`run_scatter`)
TRUE_EXPONENTS = (0.5, 1.0, 1.5)   #: the synthetic studies' exponents (:func:`coverage_table`)
COVERAGE_STUDIES = 400   #: synthetic studies a measure and exponent: a 95 % coverage to about 1.1 %
CALIBRATION_SEED, COVERAGE_SEED = 81, 82   #: the synthetic studies' streams: the critical value's, the check's


def run_scatter(measure: str, a: float) -> float:
    """A run's relative scatter at a: the mu_r = 0.15 runs' sample variance within each r0, pooled."""
    runs = [row for row in read_rows(HERE / "calibration-mu_r-0.15-runs.csv") if float(row["aspect_ratio"]) == a]
    squares, dof = 0.0, 0
    for r0 in sorted({row["r0"] for row in runs}):
        values = np.array([float(row[measure]) for row in runs if row["r0"] == r0])
        squares, dof = squares + np.sum((values / values.mean() - 1) ** 2), dof + len(values) - 1
    return float(np.sqrt(squares / dof))


def series(variable: str, measure: str) -> list:
    """[(a, 1/r0, the means over their scale, seeds a size, a run's relative scatter, the scale: the means'
    mean)] of one measure."""
    out = []
    for row in read_rows(HERE / "column-size-limits.csv"):
        if row["variable"] == variable:
            sizes = [r0 for r0 in SIZES if row[f"r0_{r0}"]]
            means = np.array([float(row[f"r0_{r0}"]) for r0 in sizes])
            seeds = np.array([3 if r0 <= 4 else 2 for r0 in sizes])
            a = float(row["aspect_ratio"])
            scale = np.average(means, weights=seeds)
            out.append((a, 1.0 / np.array(sizes), means / scale, seeds, run_scatter(measure, a), scale))
    return out


def fitted(p, inverse_r0, means, seeds, scatter) -> tuple[np.ndarray, np.ndarray]:
    """((X_inf, k), their covariance) of the least-squares fit of means = X_inf + k (1/r0)^p, each mean
    weighted by its seeds over a run's variance (colsim's fit_limit weighs runs alike and gives no
    covariance); p a number, or an array of them (then (2, *p's shape) and (2, 2, *p's shape))."""
    weight, x = seeds / scatter**2, inverse_r0 ** np.asarray(p, dtype=float)[..., None]
    total, sum_x, sum_y = weight.sum(), (weight * x).sum(-1), (weight * means).sum()
    sum_xx, sum_xy = (weight * x * x).sum(-1), (weight * x * means).sum(-1)
    determinant = total * sum_xx - sum_x**2
    k = (total * sum_xy - sum_x * sum_y) / determinant
    covariance = np.array([[sum_xx, -sum_x], [-sum_x, np.full_like(sum_xx, total)]]) / determinant
    return np.array([(sum_y - k * sum_x) / total, k]), covariance


def chi_squared_curve(inverse_r0, means, seeds, scatter) -> np.ndarray:
    """chi^2 of :func:`fitted` at every p of GRID (d's scale moves k only)."""
    (limit, k), _ = fitted(GRID, inverse_r0, means, seeds, scatter)
    x = inverse_r0 ** GRID[:, None]
    return (seeds / scatter**2 * (means - limit[:, None] - k[:, None] * x) ** 2).sum(axis=1)


def inside(curve, critical: float = CRITICAL) -> np.ndarray:
    """The p of GRID within `critical` of the least chi^2: the profile interval's points."""
    return GRID[curve - curve.min() <= critical]


def pooled_inside(variable: str, measure: str) -> np.ndarray:
    """The points of the one p's interval of a measure (its critical value :func:`pooled_critical`)."""
    pooled = sum(curve for *_, curve in chi_squared_curves(variable, measure))
    return inside(pooled, pooled_critical(variable, measure))


def profile(curve, critical: float = CRITICAL) -> str:
    """'p [low, high]' from chi^2 over GRID: every p within `critical` of the least."""
    points = inside(curve, critical)
    low = f"<= {P_BOUNDS[0]:g}" if points[0] == GRID[0] else f"{points[0]:.2f}"
    high = f">= {P_BOUNDS[1]:g}" if points[-1] == GRID[-1] else f"{points[-1]:.2f}"
    best = curve.argmin()
    estimate = low if best == 0 else high if best == len(GRID) - 1 else f"{GRID[best]:.2f}"
    return f"{estimate} [{low}, {high}]"


def chi_squared_curves(variable: str, measure: str) -> list:
    """[(a, number of sizes, chi^2 over GRID)] of one measure's series."""
    return [(a, len(means), chi_squared_curve(inverse_r0, means, seeds, scatter))
            for a, inverse_r0, means, seeds, scatter, _ in series(variable, measure)]


def pooled_exponent(variable: str, measure: str) -> float:
    """The one p that fits every a of a measure best."""
    return float(GRID[sum(curve for *_, curve in chi_squared_curves(variable, measure)).argmin()])


def exponent_table() -> str:
    lines = ["| measure | a | a run's scatter | sizes | fitted p [95 %] | least chi^2 (dof) |", "|---|---|---|---|---|---|"]
    for variable, measure in MEASURES:
        curves = chi_squared_curves(variable, measure)
        for (a, sizes, curve), fit in zip(curves, series(variable, measure)):
            lines.append(f"| {measure} | {a:g} | {fit[4]:.1%} | {sizes} | {profile(curve)} | "
                         f"{curve.min():.1f} ({sizes - 3}) |")
        pooled, points = sum(curve for *_, curve in curves), sum(sizes for _, sizes, _ in curves)
        lines.append(f"| {measure} | all, one p | | {points} | **{profile(pooled, pooled_critical(variable, measure))}** | "
                     f"{pooled.min():.1f} ({points - 2 * len(curves) - 1}) |")
    return "\n".join(lines)


def prediction_table() -> str:
    """The p = 1 line through r0 = 2-4's means at r0 = 5 and 6 against their means, the difference over
    its standard error (the line's and the two seeds' mean's, in a run's scatter). The line is printed
    to 4 decimals: through three means of 3 decimals, its value at r0 = 6 often ends in a 5 at the 4th,
    where 3 decimals would round by the last bit."""
    lines = ["| measure | a | r0 | p = 1 from r0 = 2-4 | measured | measured - predicted | in standard errors |",
             "|---|---|---|---|---|---|---|"]
    for variable, measure in MEASURES:
        for a, inverse_r0, means, seeds, scatter, scale in series(variable, measure):
            small = inverse_r0 >= 1 / 4
            line, covariance = fitted(1.0, inverse_r0[small], means[small], seeds[small], scatter)
            for x, mean, n in zip(inverse_r0[~small], means[~small], seeds[~small]):
                at = np.array([1.0, x])
                predicted, error = at @ line, np.sqrt(at @ covariance @ at + scatter**2 / n)
                lines.append(f"| {measure} | {a:g} | {1 / x:.0f} | {scale * predicted:.4f} | {scale * mean:.3f} | "
                             f"{mean / predicted - 1:+.1%} | {(mean - predicted) / error:+.1f} |")
    return "\n".join(lines)


def runout_limits(p: float) -> str:
    """The run-outs' limits from r0 = 2-6's means at p = 1 and at p, relative to their own mean."""
    lines = [f"| a | limit at p = 1 | limit at p = {p:g} | difference |", "|---|---|---|---|"]
    for a, inverse_r0, means, seeds, scatter, scale in series("runout_over_r0", "runout"):
        one, other = (scale * fitted(q, inverse_r0, means, seeds, scatter)[0][0] for q in (1.0, p))
        lines.append(f"| {a:g} | {one:.3f} | {other:.3f} | {other / one - 1:+.1%} |")
    return "\n".join(lines)


def truth_of(variable: str, measure: str, p: float) -> list:
    """[(inverse_r0, seeds, scatter, X_inf, k)] a synthetic study of one measure draws from: each a's
    design and scatter, its X_inf and k the real means' fit at p."""
    return [(inverse_r0, seeds, scatter, *fitted(p, inverse_r0, means, seeds, scatter)[0])
            for _, inverse_r0, means, seeds, scatter, _ in series(variable, measure)]


def distances_from_truth(truth: list, p: float, studies: int, rng) -> tuple[np.ndarray, np.ndarray]:
    """(each a's (studies, n_a), the one p's (studies,)) chi^2 at the true p above the least, over
    synthetic studies: for each a of `truth`, means X_inf + k (1/r0)^p plus Gaussian noise of the seeds'
    mean (a run's scatter over the root of the seeds), fitted with a scatter estimated as the real one
    was, from 6 degrees of freedom (scatter^2 chi^2_6 / 6). An interval holds p where its distance is
    within the interval's critical value."""
    at_truth = np.argmin(np.abs(GRID - p))
    each, pooled = np.empty((studies, len(truth))), np.empty(studies)
    for study in range(studies):
        curves = []
        for inverse_r0, seeds, scatter, limit, k in truth:
            means = limit + k * inverse_r0**p + rng.normal(0.0, scatter / np.sqrt(seeds))
            estimated = scatter * np.sqrt(rng.chisquare(SCATTER_DOF) / SCATTER_DOF)
            curves.append(chi_squared_curve(inverse_r0, means, seeds, estimated))
        each[study] = [curve[at_truth] - curve.min() for curve in curves]
        total = sum(curves)
        pooled[study] = total[at_truth] - total.min()
    return each, pooled


@cache
def pooled_critical(variable: str, measure: str) -> float:
    """The one p's critical value: the 95th percentile of its distance from the true p over
    COVERAGE_STUDIES synthetic studies, the largest over TRUE_EXPONENTS. chi^2_1's 3.84 is too small
    for it: the scatter is estimated from 6 degrees of freedom, and an a whose estimate falls low
    outweighs the others."""
    rng = np.random.default_rng(CALIBRATION_SEED)
    return max(float(np.quantile(distances_from_truth(truth_of(variable, measure, p), p, COVERAGE_STUDIES, rng)[1],
                                 0.95)) for p in TRUE_EXPONENTS)


def coverage_table() -> str:
    """How often p's 95 % intervals hold the true p over COVERAGE_STUDIES synthetic studies drawn
    afresh (not those that set the critical value): each a's at 3.84, the one p's at 3.84 and at
    :func:`pooled_critical`."""
    rng = np.random.default_rng(COVERAGE_SEED)
    lines = ["| measure | true p | each a's interval (3.84) | one p's interval (3.84) | one p's interval "
             "(critical value) |", "|---|---|---|---|---|"]
    for variable, measure in MEASURES:
        critical = pooled_critical(variable, measure)
        for p in TRUE_EXPONENTS:
            each, pooled = distances_from_truth(truth_of(variable, measure, p), p, COVERAGE_STUDIES, rng)
            lines.append(f"| {measure} | {p:g} | {np.mean(each <= CRITICAL):.1%} | {np.mean(pooled <= CRITICAL):.1%} "
                         f"| {np.mean(pooled <= critical):.1%} ({critical:.2f}) |")
    return "\n".join(lines)


if __name__ == "__main__":
    print(exponent_table())
    print()
    print(prediction_table())
    print()
    print(runout_limits(pooled_exponent("runout_over_r0", "runout")))
    print()
    print(coverage_table())
