"""The mu_r calibration: which rolling resistance gives an experimental law in the large-column limit?

From runs over (mu_r, a, r0, seed), to rest:

1. For every mu_r and a, the large-column limits of h_inf/r0 and of the run-out (r_inf - r0)/r0,
   X(r0) = X_inf + k (d/r0)^p over the sizes (:func:`colsim.study.size_limit.choose_fit`: p = 1
   with three sizes).
2. The misfit of each mu_r to a law (Lube et al. or Lajeunesse et al.): the root-mean-square over
   the aspect ratios of the relative error of the limits, for the heights, the run-outs and both
   together (all 2 n_a errors).
3. The mu_r that minimises each misfit, between the swept values: each limit is interpolated over
   mu_r (monotone cubic, PCHIP, per a) on a fine grid, and the misfit minimised there. A minimum on
   the grid's edge is flagged: the best value may lie outside the sweep.
4. Its uncertainty, by a bootstrap that resamples the packing seeds within every r0 (the same pick
   for every mu_r and a, since they share the packings) and repeats 1-3: the percentile interval,
   widened about the estimate by sqrt(n/(n - 1)) for n seeds a size (a resample of n values has
   (n - 1)/n of their variance; with 3 seeds the plain percentile interval covers the true mu_r
   too rarely: docs/validation/calibration.md, tests/study/test_calibration.py).
5. Which mu_r fit every a within a tolerance (10 % by default): per mu_r and a, whether both limits
   are within it of the law, and the range of mu_r on the grid where every a fits.

Everything here is numpy on a table of runs; :func:`runs_from_analyses` builds the table from the
runs' analysis files.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import xarray as xr
from scipy.interpolate import PchipInterpolator

from .experimental_laws import lajeunesse_height, lajeunesse_runout, lube_height, lube_runout
from .size_limit import choose_fit

#: the laws a calibration is measured against: name -> (height law, run-out law), both of a
LAWS = {"lube": (lube_height, lube_runout), "lajeunesse": (lajeunesse_height, lajeunesse_runout)}
#: the misfits: of the heights, of the run-outs, and of both together
MEASURES = ("height", "runout", "both")
GRID_POINTS = 401      #: points of the fine mu_r grid between the smallest and largest swept value
FIT_TOLERANCE = 0.10   #: a limit "fits" a law within this relative error


@dataclass(frozen=True)
class Runs:
    """One row a run: mu_r, aspect_ratio, r0, seed (n,), d_over_r0 (n,) the mean diameter over r0,
    height and runout (n,) the deposit's h_inf/r0 and (r_inf - r0)/r0."""
    mu_r: np.ndarray
    aspect_ratio: np.ndarray
    r0: np.ndarray
    seed: np.ndarray
    d_over_r0: np.ndarray
    height: np.ndarray
    runout: np.ndarray

    def axes(self):
        """The swept mu_r, aspect ratios and radii, each sorted."""
        return (np.unique(self.mu_r), np.unique(self.aspect_ratio), np.unique(self.r0))


def runs_from_analyses(analyses) -> Runs:
    """The runs of analysis datasets (attributes mu_r, aspect_ratio, r0, seed; variables
    h_inf_over_r0, runout_over_r0, mean_diameter)."""
    from .collect import check_runs

    if not analyses:
        raise ValueError("no analysis files to calibrate from")
    rows = []
    for (mu_r, a, r0, seed), analysis in zip(check_runs(analyses, ("mu_r", "aspect_ratio", "r0", "seed")), analyses):
        rows.append((mu_r, a, r0, seed, float(analysis["mean_diameter"]) / r0,
                     float(analysis["h_inf_over_r0"]), float(analysis["runout_over_r0"])))
    return Runs(*(np.array(column) for column in zip(*rows)))


def _limits(runs: Runs, pick: dict | None = None, rng: np.random.Generator | None = None) -> np.ndarray:
    """(2, n_mu, n_a) limits of the height and the run-out per mu_r and a; pick {r0: seeds to use}
    (a bootstrap's resample, repeats allowed), else every seed. Where a (mu_r, a, r0) has runs but
    none of the picked seeds (a study still running, a seed missing), its own seeds are resampled
    with `rng` instead."""
    mu_rs, ratios, radii = runs.axes()
    out = np.full((2, len(mu_rs), len(ratios)), np.nan)
    for i, m in enumerate(mu_rs):
        for j, a in enumerate(ratios):
            cell = (runs.mu_r == m) & (runs.aspect_ratio == a)
            rows = []
            for r0 in radii:
                here = np.flatnonzero(cell & (runs.r0 == r0))
                if pick is not None and len(here):
                    by_seed = {int(runs.seed[k]): k for k in here}
                    picked = [by_seed[s] for s in pick[r0] if s in by_seed]
                    here = picked or list(rng.choice(here, size=len(here)))
                rows.extend(here)
            rows = np.array(rows, dtype=int)
            if len(np.unique(runs.r0[rows])) < 2:
                continue
            for q, values in enumerate((runs.height, runs.runout)):
                out[q, i, j] = choose_fit(runs.d_over_r0[rows], values[rows]).x_inf
    return out


def relative_errors(limits: np.ndarray, ratios: np.ndarray, law: str) -> np.ndarray:
    """(2, ..., n_a) relative errors (X_inf - law)/law of the height and run-out limits (2, ..., n_a)."""
    height_law, runout_law = LAWS[law]
    expected = np.stack([height_law(ratios), runout_law(ratios)])
    shape = (2,) + (1,) * (limits.ndim - 2) + (len(ratios),)
    return limits / expected.reshape(shape) - 1.0


def misfits(errors: np.ndarray) -> np.ndarray:
    """(3, ...) root-mean-square over a (last axis) of the relative errors (2, ..., n_a): heights,
    run-outs and both together."""
    height = np.sqrt(np.nanmean(errors[0] ** 2, axis=-1))
    runout = np.sqrt(np.nanmean(errors[1] ** 2, axis=-1))
    both = np.sqrt((height**2 + runout**2) / 2)
    return np.stack([height, runout, both])


def on_grid(limits: np.ndarray, mu_rs: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """(2, n_grid, n_a) the limits (2, n_mu, n_a) interpolated over mu_r by PCHIP (monotone between
    swept values where the limits are)."""
    return PchipInterpolator(mu_rs, limits, axis=1)(grid)


def best_mu_r(limits: np.ndarray, mu_rs: np.ndarray, ratios: np.ndarray, law: str, grid: np.ndarray):
    """((3,) the mu_r on `grid` minimising each misfit, (3,) its misfit)."""
    curves = misfits(relative_errors(on_grid(limits, mu_rs, grid), ratios, law))
    best = np.argmin(curves, axis=1)
    return grid[best], curves[np.arange(len(MEASURES)), best]


def fitting_range(limits, mu_rs, ratios, law, grid, tolerance=FIT_TOLERANCE) -> tuple[float, float]:
    """(low, high) of the mu_r on `grid` at which every a's height and run-out limits are within
    `tolerance` of the law; (NaN, NaN) where none is."""
    errors = relative_errors(on_grid(limits, mu_rs, grid), ratios, law)
    good = np.all(np.abs(errors) <= tolerance, axis=(0, 2))
    if not good.any():
        return float("nan"), float("nan")
    return float(grid[good].min()), float(grid[good].max())


def calibrate(runs: Runs, replicates: int = 1000, level: float = 0.95, seed: int = 0,
              tolerance: float = FIT_TOLERANCE) -> xr.Dataset:
    """The calibration of the module docstring as one dataset over (mu_r, aspect_ratio, law,
    measure); reproducible from `seed`."""
    mu_rs, ratios, radii = runs.axes()
    if len(mu_rs) < 2:
        raise ValueError("a calibration needs at least two values of mu_r")
    grid = np.linspace(mu_rs[0], mu_rs[-1], GRID_POINTS)
    limits = _limits(runs)
    if np.isnan(limits).any():
        raise ValueError("every (mu_r, a) needs runs at two r0 or more for its limit")
    seeds = {r0: np.unique(runs.seed[runs.r0 == r0]) for r0 in radii}
    rng = np.random.default_rng(seed)
    boot = np.array([_limits(runs, {r0: rng.choice(s, size=len(s)) for r0, s in seeds.items()}, rng)
                     for _ in range(replicates)])                     # (B, 2, n_mu, n_a)
    tail = 100 * (1 - level) / 2
    smallest = min(len(s) for s in seeds.values())
    widen = np.sqrt(smallest / (smallest - 1)) if smallest > 1 else 1.0

    def interval(estimate, replicates_, axis):
        """The percentile interval of the replicates (along `axis`), widened about the estimate."""
        low, high = np.nanpercentile(replicates_, [tail, 100 - tail], axis=axis)
        return estimate - widen * (estimate - low), estimate + widen * (high - estimate)

    laws = list(LAWS)
    data = {}
    for q, name in enumerate(("height", "runout")):
        data[f"{name}_limit"] = limits[q]
        data[f"{name}_low"], data[f"{name}_high"] = interval(limits[q], boot[:, q], 0)
    misfit = np.stack([misfits(relative_errors(limits, ratios, law)) for law in laws])        # (law, 3, n_mu)
    best = np.stack([best_mu_r(limits, mu_rs, ratios, law, grid)[0] for law in laws])         # (law, 3)
    best_boot = np.stack([[best_mu_r(b, mu_rs, ratios, law, grid)[0] for b in boot] for law in laws])  # (law, B, 3)
    best_low, best_high = (np.clip(end, grid[0], grid[-1]) for end in interval(best, best_boot, 1))  # within the sweep
    misfit_boot = np.stack([misfits(relative_errors(boot.transpose(1, 0, 2, 3), ratios, law)) for law in laws])
    misfit_low, misfit_high = interval(misfit, misfit_boot, 2)                                # (law, 3, n_mu)
    errors = np.stack([relative_errors(limits, ratios, law) for law in laws])                 # (law, 2, n_mu, n_a)
    fits = np.all(np.abs(errors) <= tolerance, axis=1)                                        # (law, n_mu, n_a)
    ranges = np.array([fitting_range(limits, mu_rs, ratios, law, grid, tolerance) for law in laws])
    edge = (np.isclose(best, grid[0]) | np.isclose(best, grid[-1]))

    dims, one = ("mu_r", "aspect_ratio"), {"units": "1"}
    variables = {
        name: (dims, values, {**one, "long_name": _LONG_NAMES[name]}) for name, values in data.items()}
    variables |= {
        "misfit": (("law", "measure", "mu_r"), misfit,
                   {**one, "long_name": "root-mean-square over a of the limits' relative error against the law"}),
        "misfit_low": (("law", "measure", "mu_r"), misfit_low, {**one, "long_name": "misfit, interval's lower end"}),
        "misfit_high": (("law", "measure", "mu_r"), misfit_high, {**one, "long_name": "misfit, interval's upper end"}),
        "best_mu_r": (("law", "measure"), best, {**one, "long_name": "mu_r minimising the misfit (interpolated)"}),
        "best_mu_r_low": (("law", "measure"), best_low, {**one, "long_name": "best mu_r, interval's lower end"}),
        "best_mu_r_high": (("law", "measure"), best_high, {**one, "long_name": "best mu_r, interval's upper end"}),
        "best_at_edge": (("law", "measure"), edge.astype(np.int8),
                         {"long_name": "the best mu_r is an end of the sweep (the minimum may lie beyond it)",
                          "flag_values": np.array([0, 1], dtype=np.int8), "flag_meanings": "inside at_edge"}),
        "fits_law": (("law", "mu_r", "aspect_ratio"), fits.astype(np.int8),
                     {"long_name": f"both limits within {tolerance:.0%} of the law",
                      "flag_values": np.array([0, 1], dtype=np.int8), "flag_meanings": "misses fits"}),
        "fitting_mu_r_low": (("law",), ranges[:, 0], {**one, "long_name": "lowest mu_r at which every a fits the law"}),
        "fitting_mu_r_high": (("law",), ranges[:, 1], {**one, "long_name": "highest mu_r at which every a fits the law"}),
    }
    coords = {"mu_r": ("mu_r", mu_rs, {**one, "long_name": "rolling resistance coefficient"}),
              "aspect_ratio": ("aspect_ratio", ratios, {**one, "long_name": "aspect ratio h0/r0"}),
              "law": ("law", laws, {"long_name": "experimental law"}),
              "measure": ("measure", list(MEASURES), {"long_name": "which limits the misfit takes"})}
    attrs = {"replicates": replicates, "level": level, "bootstrap_seed": seed, "fit_tolerance": tolerance,
             "interval_widening": widen,
             "radii": ", ".join(f"{r:g}" for r in radii),
             "seeds_per_radius": ", ".join(f"r0 {r:g}: {len(s)}" for r, s in seeds.items())}
    return xr.Dataset(variables, coords=coords, attrs=attrs)


_LONG_NAMES = {
    "height_limit": "large-column limit of h_inf/r0", "height_low": "h_inf/r0 limit, interval's lower end",
    "height_high": "h_inf/r0 limit, interval's upper end",
    "runout_limit": "large-column limit of (r_inf - r0)/r0", "runout_low": "run-out limit, interval's lower end",
    "runout_high": "run-out limit, interval's upper end"}


def calibration_markdown(result: xr.Dataset) -> str:
    """The calibration as Markdown: the best mu_r per law and measure, the misfit per mu_r, and which
    a each mu_r fits within the tolerance."""
    level = f"{100 * float(result.attrs['level']):g} %"
    lines = [f"Best mu_r (interpolated between the swept values; {level} bootstrap interval over the seeds):", "",
             "| law | measure | best mu_r | interval | misfit at the swept values |", "|---|---|---|---|---|"]
    for law in result.law.values:
        for measure in result.measure.values:
            part = result.sel(law=law, measure=measure)
            edge = " (an end of the sweep)" if int(part.best_at_edge) else ""
            curve = ", ".join(f"{float(m):g}: {100 * float(v):.1f} %" for m, v in zip(result.mu_r.values, part.misfit.values))
            lines.append(f"| {law} | {measure} | {float(part.best_mu_r):.3f}{edge} | "
                         f"[{float(part.best_mu_r_low):.3f}, {float(part.best_mu_r_high):.3f}] | {curve} |")
    tolerance = f"{100 * float(result.attrs['fit_tolerance']):g} %"
    lines += ["", f"Aspect ratios whose height and run-out limits both lie within {tolerance} of the law:", "",
              "| law | mu_r | a that fit | a that miss |", "|---|---|---|---|"]
    for law in result.law.values:
        for m in result.mu_r.values:
            fits = result.fits_law.sel(law=law, mu_r=m).values.astype(bool)
            ratios = result.aspect_ratio.values
            lines.append(f"| {law} | {float(m):g} | {', '.join(f'{a:g}' for a in ratios[fits]) or '-'} | "
                         f"{', '.join(f'{a:g}' for a in ratios[~fits]) or '-'} |")
        low, high = float(result.fitting_mu_r_low.sel(law=law)), float(result.fitting_mu_r_high.sel(law=law))
        verdict = (f"every a fits for mu_r in [{low:.3f}, {high:.3f}]" if np.isfinite(low)
                   else "no single mu_r in the sweep fits every a")
        lines.append(f"| {law} | one mu_r for all a | {verdict} | |")
    return "\n".join(lines) + "\n"
