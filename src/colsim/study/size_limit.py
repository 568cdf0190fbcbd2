"""The large-column limit of a deposit measure and its interval, one method for the mu_r calibration
(colsim.study.calibration: every mu_r and a at once) and the column-size study (:func:`size_limit`:
one measure at one a).

X is a deposit measure (h_inf/r0, the run-out over r0) measured at several cylinder radii r0 with
one or more packing seeds each; d is the mean particle diameter, so d/r0 -> 0 is the infinitely
large column. The limit X_inf is the least-squares fit of X(r0) = X_inf + k (d/r0)^p over every run
(each seed one point) with p = 1, the leading finite-size correction of a smooth boundary effect
(:func:`table_limits`, linear in X_inf and k).

Its interval is a bootstrap (:func:`bootstrap_draws`, :func:`inflated`, :func:`widened`):

- each replicate resamples the seeds within every size (with replacement) and draws the exponent p
  uniformly from EXPONENT_RANGE: sizes up to r0 = 6 cannot tell p = 1 from 0.5 or 1.5, and the
  limit moves with it;
- each size's runs are first moved from their mean by sqrt(n/(n - 1)) for n runs (a resample of n
  values has (n - 1)/n of their variance);
- the percentile interval is widened about the estimate by Student's t over the normal quantile
  (n_runs - n_sizes degrees of freedom: the spread is estimated from two or three seeds, not known).

Its coverage was measured on synthetic studies of each design (colsim.study.coverage): the
calibration's in docs/validation/calibration.md, the column-size study's in
docs/validation/column-size.md. Where 4 sizes or more were measured, :func:`size_limit` also fits p
itself (a bounded search on P_BOUNDS, the residual sum of squares being smooth in p) with a
percentile interval over the same resampled seeds: a check of the size law, not used in the limit
(its coverage not measured).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize_scalar
from scipy.stats import norm
from scipy.stats import t as student_t

#: the size law's exponents p a bootstrap replicate draws from (uniformly): sizes up to r0 = 6 fit the
#: run-outs' p as 0.45 [<= 0.25, 1.47] (docs/validation/column-size.md), so they cannot test p = 1
EXPONENT_RANGE = (0.5, 1.5)
P_BOUNDS = (0.25, 4.0)   #: the exponents a fitted p may take


@dataclass(frozen=True)
class RunTable:
    """The runs as arrays over (mu_r, a, r0, seed slot): values (n_q, n_mu, n_a, n_r, n_s) the
    measures (the calibration's: height and run-out), d_over_r0 (n_mu, n_a, n_r, n_s), NaN where a
    run is missing; seeds[r] the seed labels of radius r's slots (radii may have different seeds)."""
    values: np.ndarray
    d_over_r0: np.ndarray
    seeds: tuple

    @property
    def present(self) -> np.ndarray:
        return np.isfinite(self.d_over_r0)


def table_fits(table: RunTable, counts=None, p=1.0) -> tuple[np.ndarray, np.ndarray]:
    """((..., n_q, n_mu, n_a) limits X_inf, the same shape slopes k) of X = X_inf + k (d/r0)^p fitted
    by least squares over every run; counts (..., n_r, n_s) how often each seed slot enters (a
    bootstrap's resample; default: each run once), p a number or one per leading index of counts.
    Where none of the counted seeds of a size ran in a cell (a study part way, a seed missing), that
    size enters with the cell's own runs, once each; a cell with runs at fewer than two sizes is NaN."""
    counts = np.ones(table.d_over_r0.shape[-2:]) if counts is None else np.asarray(counts, dtype=float)
    lead = counts.shape[:-2]
    p = np.broadcast_to(np.asarray(p, dtype=float), lead)
    present = table.present
    weight = counts[..., None, None, :, :] * present                        # (..., n_mu, n_a, n_r, n_s)
    weight = np.where(weight.sum(-1, keepdims=True) > 0, weight, present)  # no picked seed ran: its own runs
    u = np.where(present, np.nan_to_num(table.d_over_r0, nan=1.0), 1.0) ** p[(...,) + (None,) * 4]
    y = np.nan_to_num(table.values)
    n, su, suu = weight.sum((-2, -1)), (weight * u).sum((-2, -1)), (weight * u * u).sum((-2, -1))
    wy = weight[..., None, :, :, :, :]
    sy, suy = (wy * y).sum((-2, -1)), (wy * u[..., None, :, :, :, :] * y).sum((-2, -1))
    sizes = (weight.sum(-1) > 0).sum(-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        k = (n[..., None, :, :] * suy - su[..., None, :, :] * sy) / (n * suu - su**2)[..., None, :, :]
        limits = (sy - k * su[..., None, :, :]) / n[..., None, :, :]
    enough = (sizes >= 2)[..., None, :, :]
    return np.where(enough, limits, np.nan), np.where(enough, k, np.nan)


def table_limits(table: RunTable, counts=None, p=1.0) -> np.ndarray:
    """(..., n_q, n_mu, n_a) the limits X_inf of :func:`table_fits`."""
    return table_fits(table, counts, p)[0]


def bootstrap_counts(table: RunTable, replicates: int, rng: np.random.Generator) -> np.ndarray:
    """(replicates, n_r, n_s) how often each seed enters a replicate: each r0's seeds resampled with
    replacement, the same pick for every mu_r and a (they share the packings)."""
    counts = np.zeros((replicates,) + table.d_over_r0.shape[-2:])
    for r, seeds in enumerate(table.seeds):
        counts[:, r, :len(seeds)] = rng.multinomial(len(seeds), np.full(len(seeds), 1 / len(seeds)), replicates)
    return counts


def bootstrap_draws(table: RunTable, replicates: int, rng: np.random.Generator, exponents=EXPONENT_RANGE):
    """(counts (replicates, n_r, n_s) of :func:`bootstrap_counts`, the exponent p of each replicate
    drawn uniformly from `exponents`, or 1.0 when exponents is None)."""
    counts = bootstrap_counts(table, replicates, rng)
    return counts, rng.uniform(*exponents, replicates) if exponents else 1.0


def inflated(table: RunTable) -> RunTable:
    """The table with every (mu_r, a, r0)'s runs moved away from their mean by sqrt(n/(n - 1)), n its
    runs: a bootstrap resample of n values has (n - 1)/n of their variance, and so the resampled
    table's has theirs, whatever the seeds a size."""
    present = table.present
    n = present.sum(-1, keepdims=True)
    mean = np.where(present, table.values, 0.0).sum(-1, keepdims=True) / np.maximum(n, 1)
    factor = np.sqrt(n / np.maximum(n - 1, 1))
    return RunTable(mean + factor * (table.values - mean), table.d_over_r0, table.seeds)


def interval_widening(table: RunTable, level: float) -> float:
    """The factor by which the bootstrap's percentile interval is widened about the estimate:
    Student's quantile with n_runs - n_sizes degrees of freedom over the normal one, since the seeds'
    spread is estimated from them, not known (the median (mu_r, a)'s, at least 1: a study part way
    has cells of one run a size)."""
    freedom = np.median(table.present.sum((-2, -1)) - table.present.any(-1).sum(-1))
    tail = (1 + level) / 2
    return float(student_t.ppf(tail, max(freedom, 1)) / norm.ppf(tail))


def widened(estimate, replicates, level: float, widen: float, axis=0):
    """The percentile interval of the replicates (along `axis`) widened about the estimate by `widen`."""
    tail = 100 * (1 - level) / 2
    low, high = np.nanpercentile(replicates, [tail, 100 - tail], axis=axis)
    return estimate - widen * (estimate - low), estimate + widen * (high - estimate)


@dataclass(frozen=True)
class LimitFit:
    """X(r0) = x_inf + k (d/r0)^p fitted to n runs; p_fitted says whether p was fitted (else given)."""
    x_inf: float
    k: float
    p: float
    p_fitted: bool
    sse: float
    n: int

    def at(self, d_over_r0) -> np.ndarray:
        """The fitted X at d/r0."""
        return self.x_inf + self.k * np.asarray(d_over_r0, dtype=float) ** self.p


def _fixed_p(x: np.ndarray, y: np.ndarray, p: float) -> tuple[float, float, float]:
    """(x_inf, k, SSE) of y = x_inf + k x^p by linear least squares."""
    design = np.column_stack([np.ones_like(x), x**p])
    (x_inf, k), *_ = np.linalg.lstsq(design, y, rcond=None)
    return float(x_inf), float(k), float(np.sum((design @ [x_inf, k] - y) ** 2))


def fit_limit(d_over_r0, values, p: float | None = 1.0) -> LimitFit:
    """Least-squares fit of values = x_inf + k (d_over_r0)^p over the runs (arrays of one length;
    p None: fitted in P_BOUNDS, which needs at least 4 distinct sizes)."""
    x, y = np.asarray(d_over_r0, dtype=float), np.asarray(values, dtype=float)
    if x.shape != y.shape or x.ndim != 1:
        raise ValueError("d_over_r0 and values must be 1-D arrays of one length")
    if np.any(x <= 0) or not np.all(np.isfinite(y)):
        raise ValueError("d/r0 must be positive and every value finite")
    sizes = len(np.unique(x))
    if p is not None:
        if sizes < 2:
            raise ValueError("a limit needs at least 2 column sizes")
        x_inf, k, sse = _fixed_p(x, y, p)
        return LimitFit(x_inf, k, float(p), False, sse, len(x))
    if sizes < 4:
        raise ValueError(f"fitting the exponent needs at least 4 column sizes, got {sizes}")
    found = minimize_scalar(lambda q: _fixed_p(x, y, q)[2], bounds=P_BOUNDS, method="bounded",
                            options={"xatol": 1e-6})
    x_inf, k, sse = _fixed_p(x, y, float(found.x))
    return LimitFit(x_inf, k, float(found.x), True, sse, len(x))


@dataclass(frozen=True, eq=False)
class Limit:
    """The p = 1 fit and the interval [low, high] of its x_inf (level, e.g. 0.95; the module
    docstring's method, its percentile interval widened by `widening`); replicate_fits the (x_inf, k,
    p) of every replicate, shape (replicates, 3); free the fit with p fitted and [p_low, p_high] the
    percentile interval of p over the same resampled seeds (None and NaN under 4 sizes)."""
    fit: LimitFit
    low: float
    high: float
    level: float
    widening: float
    replicate_fits: np.ndarray
    free: LimitFit | None = None
    p_low: float = np.nan
    p_high: float = np.nan

    def band(self, d_over_r0) -> tuple[np.ndarray, np.ndarray]:
        """The pointwise band (low, high) of the fitted X at d_over_r0 (1-D): the replicates' curves'
        percentiles widened about the fit's as the interval is; at d/r0 = 0 it is [low, high]."""
        x = np.asarray(d_over_r0, dtype=float)
        x_inf, k, p = (column[:, None] for column in self.replicate_fits.T)
        return widened(self.fit.at(x), x_inf + k * x[None, :] ** p, self.level, self.widening)


def size_table(runs: dict, diameter: float) -> RunTable:
    """The RunTable of one measure at one (mu_r, a) from runs {r0: values over the seeds at r0}."""
    sizes = sorted(runs)
    slots = max(len(runs[r0]) for r0 in sizes)
    values = np.full((1, 1, 1, len(sizes), slots), np.nan)
    d_over_r0 = np.full(values.shape[1:], np.nan)
    for r, r0 in enumerate(sizes):
        seeds = np.asarray(runs[r0], dtype=float)
        values[0, 0, 0, r, :len(seeds)], d_over_r0[0, 0, r, :len(seeds)] = seeds, diameter / r0
    return RunTable(values, d_over_r0, tuple(tuple(range(len(runs[r0]))) for r0 in sizes))


def size_limit(runs: dict, diameter: float, replicates: int = 2000, level: float = 0.95, seed: int = 0,
               exponents=EXPONENT_RANGE, student: bool = True, fit_exponent: bool = True) -> Limit:
    """X_inf with its interval (module docstring) from runs {r0: values of X over the seeds at that
    r0} (length units of r0 and `diameter`, the mean particle diameter); exponents and student as
    colsim.study.calibration.calibrate takes them; fit_exponent: with 4 sizes or more, fit p too.
    Reproducible from `seed`."""
    table = size_table(runs, diameter)
    present = table.present[0, 0]
    x, y = table.d_over_r0[0, 0][present], table.values[0, 0, 0][present]
    fit = fit_limit(x, y, p=1.0)
    rng = np.random.default_rng(seed)
    counts, p = bootstrap_draws(table, replicates, rng, exponents)
    p = np.broadcast_to(np.asarray(p, dtype=float), (replicates,))
    x_inf, k = (part[:, 0, 0, 0] for part in table_fits(inflated(table), counts, p))
    widen = interval_widening(table, level) if student else 1.0
    low, high = widened(fit.x_inf, x_inf, level, widen)
    limit = Limit(fit, float(low), float(high), level, widen, np.column_stack([x_inf, k, p]))
    if not fit_exponent or len(runs) < 4:
        return limit
    spread = inflated(table).values[0, 0, 0][present]
    exponents_ = [fit_limit(np.repeat(x, c), np.repeat(spread, c), p=None).p
                  for c in counts[:, present].astype(int)]
    tail = 100 * (1 - level) / 2
    p_low, p_high = np.percentile(exponents_, [tail, 100 - tail])
    return Limit(fit, limit.low, limit.high, level, widen, limit.replicate_fits, fit_limit(x, y, p=None),
                 float(p_low), float(p_high))
