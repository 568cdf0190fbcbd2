"""The column-size limit of a result: X(r0) = X_inf + k (d/r0)^p fitted over the column sizes.

X is a deposit measure (h_inf/r0, the run-out over r0) measured at several cylinder radii r0 with
one or more packing seeds each; d is the mean particle diameter, so d/r0 -> 0 is the infinitely
large column. Two models are fitted by least squares over every run (each seed one point):

- p fixed at 1 (the leading finite-size correction of a smooth boundary effect): linear in
  (X_inf, k);
- p fitted (at least 4 sizes): for each p, linear in (X_inf, k); p by a bounded scalar search on
  [P_BOUNDS], the residual sum of squares being smooth in p.

The better model is chosen by the small-sample Akaike criterion AICc = n ln(SSE/n) + 2 q +
2 q (q + 1)/(n - q - 1) (q parameters, n runs): the free p only when its AICc is lower by more than
2 (a free exponent must earn its parameter). The uncertainty of X_inf is a percentile bootstrap:
each replicate resamples the seeds within every size (with replacement) and, when more than 3 sizes
were measured, leaves one size out at random, then chooses and fits the model again. Beside that
interval, the same replicates give the interval with p kept at 1 in every one (the seeds' and sizes'
share of the uncertainty, without the model's choice), the share of replicates that chose the free p,
and a pointwise band of the fitted curve.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize_scalar

P_BOUNDS = (0.25, 4.0)   #: the exponents a fitted p may take
AICC_MARGIN = 2.0        #: how much lower the free p's AICc must be to be chosen


@dataclass(frozen=True)
class LimitFit:
    """X(r0) = x_inf + k (d/r0)^p fitted to n runs; p_fitted says whether p was fitted (else 1)."""
    x_inf: float
    k: float
    p: float
    p_fitted: bool
    sse: float
    n: int

    @property
    def parameters(self) -> int:
        return 3 if self.p_fitted else 2

    @property
    def aicc(self) -> float:
        """The small-sample Akaike criterion (module docstring); inf when n <= q + 1."""
        n, q = self.n, self.parameters
        if n <= q + 1:
            return np.inf
        return n * np.log(max(self.sse, 1e-300) / n) + 2 * q + 2 * q * (q + 1) / (n - q - 1)

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


def choose_fit(d_over_r0, values) -> LimitFit:
    """The p = 1 fit, or the fitted-p one where there are 4 sizes or more and its AICc is lower by
    more than AICC_MARGIN."""
    linear = fit_limit(d_over_r0, values, p=1.0)
    if len(np.unique(d_over_r0)) < 4:
        return linear
    free = fit_limit(d_over_r0, values, p=None)
    return free if free.aicc < linear.aicc - AICC_MARGIN else linear


@dataclass(frozen=True, eq=False)
class Limit:
    """The chosen fit and the bootstrap's percentile interval [low, high] of x_inf (level, e.g. 0.95);
    [linear_low, linear_high] the interval when every replicate keeps p = 1; free_share the share of
    replicates whose criterion chose the fitted p; replicate_fits the chosen (x_inf, k, p) of every
    replicate, shape (replicates, 3)."""
    fit: LimitFit
    low: float
    high: float
    level: float
    replicates: int
    linear_low: float
    linear_high: float
    free_share: float
    replicate_fits: np.ndarray

    def band(self, d_over_r0) -> tuple[np.ndarray, np.ndarray]:
        """The pointwise percentile band (low, high) of the replicates' fitted X at d_over_r0 (1-D);
        at d/r0 = 0 it is [low, high] of x_inf."""
        x = np.asarray(d_over_r0, dtype=float)
        x_inf, k, p = (column[:, None] for column in self.replicate_fits.T)
        curves = x_inf + k * x[None, :] ** p
        tail = 100 * (1 - self.level) / 2
        low, high = np.percentile(curves, [tail, 100 - tail], axis=0)
        return low, high


def size_limit(runs: dict, diameter: float, replicates: int = 2000, level: float = 0.95,
               seed: int = 0) -> Limit:
    """X_inf with its bootstrap interval from runs {r0: values of X over the seeds at that r0}
    (length units of r0 and `diameter`, the mean particle diameter). Reproducible from `seed`."""
    sizes = sorted(runs)
    values = {r0: np.asarray(runs[r0], dtype=float) for r0 in sizes}

    def flat(chosen: dict) -> tuple[np.ndarray, np.ndarray]:
        x = np.concatenate([np.full(len(v), diameter / r0) for r0, v in chosen.items()])
        return x, np.concatenate(list(chosen.values()))

    fit = choose_fit(*flat(values))
    rng = np.random.default_rng(seed)
    fits, linear = [], []
    for _ in range(replicates):
        kept = sizes
        if len(sizes) > 3:
            left_out = sizes[rng.integers(len(sizes))]
            kept = [r0 for r0 in sizes if r0 != left_out]
        sample = {r0: rng.choice(values[r0], size=len(values[r0])) for r0 in kept}
        chosen = choose_fit(*flat(sample))
        fits.append((chosen.x_inf, chosen.k, chosen.p, chosen.p_fitted))
        linear.append(chosen.x_inf if not chosen.p_fitted else fit_limit(*flat(sample), p=1.0).x_inf)
    fits = np.array(fits)
    tail = 100 * (1 - level) / 2
    low, high = np.percentile(fits[:, 0], [tail, 100 - tail])
    linear_low, linear_high = np.percentile(linear, [tail, 100 - tail])
    return Limit(fit, float(low), float(high), level, replicates, float(linear_low), float(linear_high),
                 float(fits[:, 3].mean()), fits[:, :3])
