"""How many packing seeds each column size should get: the design that buys the smallest variance
of a large-column limit for its CPU time.

The limit X_inf of X(r0) = X_inf + k (d/r0)^p, fitted by least squares over every run, is a
weighted sum of the runs, X_inf = sum_i w_i X_i, so with n_r seeds at radius r0_r, each run
scattering by sigma_r, Var(X_inf) = sum_r n_r w_r^2 sigma_r^2 (w_r the weight of one run at r0_r,
itself depending on every n). A seed at r0_r costs c_r of CPU (its collapses, and its pour shared
by the mu_r it serves). For a fixed number of CPU hours C the study repeats the design C / cost
times, and the variance falls as 1/repeats, so the design to choose minimises Var(X_inf) x cost.
"""
from __future__ import annotations

import itertools

import numpy as np


def limit_variance(radii, seeds, spread, diameter: float, p: float = 1.0) -> float:
    """Var(X_inf) of the least-squares fit over `seeds[r]` runs at each of `radii`, each run with
    standard deviation `spread[r]` (mean particle diameter `diameter`, size law exponent p)."""
    radii, seeds, spread = (np.asarray(v, dtype=float) for v in (radii, seeds, spread))
    if len(radii) < 2 or np.any(seeds < 1):
        raise ValueError("a limit needs at least one seed at each of two radii or more")
    x = np.repeat(diameter / radii, seeds.astype(int)) ** p
    weights = np.linalg.pinv(np.column_stack([np.ones_like(x), x]))[0]
    return float(np.sum(weights**2 * np.repeat(spread, seeds.astype(int)) ** 2))


def best_seeds(radii, cost, spread, diameter: float, choices=range(2, 6), p: float = 1.0):
    """[(Var(X_inf) x cost, seeds per radius)] over every design with seeds from `choices` at each
    radius, the best first; cost[r] the CPU time of one seed at radii[r]."""
    cost = np.asarray(cost, dtype=float)
    designs = itertools.product(choices, repeat=len(radii))
    scored = [(limit_variance(radii, n, spread, diameter, p) * float(np.dot(n, cost)), tuple(n)) for n in designs]
    return sorted(scored)
