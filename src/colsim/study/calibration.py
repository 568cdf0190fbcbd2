"""The mu_r calibration: which rolling resistance gives an experimental law in the large-column limit?

From runs over (mu_r, a, r0, seed), to rest:

1. For every mu_r and a, the large-column limits of h_inf/r0 and of the run-out (r_inf - r0)/r0,
   X(r0) = X_inf + k d/r0 fitted by least squares over every run (p = 1: :func:`table_limits`).
2. The misfit of each mu_r to a law (Lube et al. or Lajeunesse et al.): the root-mean-square over
   the aspect ratios of the relative error of the limits, for the heights, the run-outs and both
   together (all 2 n_a errors).
3. The mu_r that minimises each misfit, between the swept values: each limit is interpolated over
   mu_r (monotone cubic, PCHIP, per a) on a fine grid, and the misfit minimised there. A minimum on
   the grid's edge is flagged: the best value may lie outside the sweep.
4. Whether one mu_r puts every a within a tolerance (10 % by default): on the estimates, the range
   of mu_r on the grid where every a's height and run-out limits do; and the minimax mu_r, whose
   worst relative error over them is smallest, with that error.
5. Their uncertainty, by a bootstrap that resamples the packing seeds within every r0 (the same pick
   for every mu_r and a, since they share the packings) and draws the size law's exponent p
   uniformly from EXPONENT_RANGE (three sizes cannot tell p = 1 from 0.5 or 1.5, and the limit moves
   with it), then repeats 1-4. Each (mu_r, a, r0)'s runs are first moved from their mean by
   sqrt(n/(n - 1)) for n runs (a resample of n values has (n - 1)/n of their variance); the
   percentile interval is widened about the estimate by Student's t over the normal quantile
   (n_runs - n_sizes degrees of freedom: the spread is estimated from three seeds, not known). The
   share of replicates in which some mu_r fits every a is the probability that one does.

Measured coverage of the 95 % intervals (colsim.study.coverage, 200 synthetic studies a case, some
breaking the fit's assumptions): docs/validation/calibration.md. The plain percentile interval with
p = 1 held the true limits in 87-88 % of studies whose size law has p = 1 and in 53-59 % of those
where it has 1.5 or 0.5; this one holds them in 88-99 % and the best mu_r in 91-100 %.

Everything here is numpy on a table of runs; :func:`runs_from_analyses` builds the table from the
runs' analysis files.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import xarray as xr
from scipy.interpolate import PchipInterpolator

from .experimental_laws import lajeunesse_height, lajeunesse_runout, lube_height, lube_runout
from .size_limit import EXPONENT_RANGE, RunTable, bootstrap_draws, inflated, interval_widening, table_limits, widened

#: the laws a calibration is measured against: name -> (height law, run-out law), both of a
LAWS = {"lube": (lube_height, lube_runout), "lajeunesse": (lajeunesse_height, lajeunesse_runout)}
#: the misfits: of the heights, of the run-outs, and of both together
MEASURES = ("height", "runout", "both")
GRID_POINTS = 401      #: points of the fine mu_r grid between the smallest and largest swept value
FIT_TOLERANCE = 0.10   #: a limit "fits" a law within this relative error
#: the lowest and highest share of synthetic studies in which the 95 % intervals held the truth, over
#: the cases of colsim.study.coverage (200 studies each; `python -m colsim.study.coverage`, the table
#: in docs/validation/calibration.md): no one method holds 90-99 % in every case (three sizes cannot
#: tell the size law's exponent), so the tables print these beside the intervals
MEASURED_COVERAGE = {"limits": (0.88, 0.993), "best mu_r": (0.91, 1.0), "minimax mu_r": (0.96, 1.0)}


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


def run_table(runs: Runs) -> RunTable:
    """The runs of `runs` on the grid of their swept values (each r0's seeds in slots)."""
    mu_rs, ratios, radii = runs.axes()
    seeds = tuple(tuple(int(s) for s in np.unique(runs.seed[runs.r0 == r0])) for r0 in radii)
    slots = max(len(s) for s in seeds)
    values = np.full((2, len(mu_rs), len(ratios), len(radii), slots), np.nan)
    x = np.full(values.shape[1:], np.nan)
    i, j, r = (np.searchsorted(axis, column) for axis, column in
               zip((mu_rs, ratios, radii), (runs.mu_r, runs.aspect_ratio, runs.r0)))
    k = np.array([seeds[rr].index(int(s)) for rr, s in zip(r, runs.seed)])
    values[0, i, j, r, k], values[1, i, j, r, k], x[i, j, r, k] = runs.height, runs.runout, runs.d_over_r0
    return RunTable(values, x, seeds)


def limit_replicates(table: RunTable, replicates: int, seed: int, exponents=EXPONENT_RANGE):
    """(limits (2, n_mu, n_a) of height and run-out, their bootstrap replicates (B, 2, n_mu, n_a)) by
    the module docstring's steps 1 and 5; reproducible from `seed`."""
    limits = table_limits(table)
    if np.isnan(limits).any():
        raise ValueError("every (mu_r, a) needs runs at two r0 or more for its limit")
    counts, exponent = bootstrap_draws(table, replicates, np.random.default_rng(seed), exponents)
    return limits, table_limits(inflated(table), counts, exponent)


def limit_intervals(runs: Runs, replicates: int = 1000, level: float = 0.95, seed: int = 0,
                    exponents=EXPONENT_RANGE) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(limits, low ends, high ends), each (2, n_mu, n_a): the large-column limits of height and
    run-out with the calibration's intervals (exponents None: p kept at 1, the seeds' part alone)."""
    table = run_table(runs)
    limits, boot = limit_replicates(table, replicates, seed, exponents)
    low, high = widened(limits, boot, level, interval_widening(table, level))
    return limits, low, high


def relative_errors(limits: np.ndarray, ratios: np.ndarray, law: str) -> np.ndarray:
    """(..., 2, n, n_a) relative errors (X_inf - law)/law of the height and run-out limits (..., 2, n, n_a)."""
    height_law, runout_law = LAWS[law]
    expected = np.stack([height_law(ratios), runout_law(ratios)])
    return limits / expected[:, None, :] - 1.0


def misfits(errors: np.ndarray) -> np.ndarray:
    """(..., 3, n) root-mean-square over a (last axis) of the relative errors (..., 2, n, n_a): heights,
    run-outs and both together."""
    height = np.sqrt(np.nanmean(errors[..., 0, :, :] ** 2, axis=-1))
    runout = np.sqrt(np.nanmean(errors[..., 1, :, :] ** 2, axis=-1))
    both = np.sqrt((height**2 + runout**2) / 2)
    return np.stack([height, runout, both], axis=-2)


def on_grid(limits: np.ndarray, mu_rs: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """(..., 2, n_grid, n_a) the limits (..., 2, n_mu, n_a) interpolated over mu_r by PCHIP (monotone
    between swept values where the limits are)."""
    return PchipInterpolator(mu_rs, limits, axis=-2)(grid)


def best_mu_r(limits: np.ndarray, mu_rs: np.ndarray, ratios: np.ndarray, law: str, grid: np.ndarray):
    """((..., 3) the mu_r on `grid` minimising each misfit, (..., 3) its misfit)."""
    curves = misfits(relative_errors(on_grid(limits, mu_rs, grid), ratios, law))
    best = np.argmin(curves, axis=-1)
    return grid[best], np.take_along_axis(curves, best[..., None], axis=-1)[..., 0]


def worst_errors(limits, mu_rs, ratios, law, grid) -> np.ndarray:
    """(..., n_grid) the largest |relative error| over every a's height and run-out at each mu_r of
    `grid` (the limits interpolated)."""
    return np.nanmax(np.abs(relative_errors(on_grid(limits, mu_rs, grid), ratios, law)), axis=(-3, -1))


def fitting_range(limits, mu_rs, ratios, law, grid, tolerance=FIT_TOLERANCE) -> tuple[float, float]:
    """(low, high) of the mu_r on `grid` at which every a's height and run-out limits are within
    `tolerance` of the law; (NaN, NaN) where none is."""
    good = worst_errors(limits, mu_rs, ratios, law, grid) <= tolerance
    if not good.any():
        return float("nan"), float("nan")
    return float(grid[good].min()), float(grid[good].max())


def calibrate(runs: Runs, replicates: int = 1000, level: float = 0.95, seed: int = 0,
              tolerance: float = FIT_TOLERANCE, exponents=EXPONENT_RANGE, student: bool = True) -> xr.Dataset:
    """The calibration of the module docstring as one dataset over (mu_r, aspect_ratio, law,
    measure); reproducible from `seed`. exponents: the range (low, high) of the size law's exponent
    that each bootstrap replicate draws its p from, or None to keep p = 1 in every replicate;
    student: widen the interval by Student's t over the normal quantile (interval_widening; False:
    the percentile interval of the inflated runs alone)."""
    mu_rs, ratios, radii = runs.axes()
    if len(mu_rs) < 2:
        raise ValueError("a calibration needs at least two values of mu_r")
    grid = np.linspace(mu_rs[0], mu_rs[-1], GRID_POINTS)
    table = run_table(runs)
    limits, boot = limit_replicates(table, replicates, seed, exponents)     # (2, n_mu, n_a), (B, 2, n_mu, n_a)
    widen = interval_widening(table, level) if student else 1.0

    def interval(estimate, replicates_, axis=0):
        return widened(estimate, replicates_, level, widen, axis)

    laws = list(LAWS)
    data = {}
    for q, name in enumerate(("height", "runout")):
        data[f"{name}_limit"] = limits[q]
        data[f"{name}_low"], data[f"{name}_high"] = interval(limits[q], boot[:, q])
    misfit = np.stack([misfits(relative_errors(limits, ratios, law)) for law in laws])        # (law, 3, n_mu)
    misfit_low, misfit_high = interval(misfit, np.stack(
        [misfits(relative_errors(boot, ratios, law)) for law in laws], axis=1), axis=0)
    best = np.stack([best_mu_r(limits, mu_rs, ratios, law, grid)[0] for law in laws])         # (law, 3)
    best_boot = np.stack([best_mu_r(boot, mu_rs, ratios, law, grid)[0] for law in laws], axis=1)  # (B, law, 3)
    best_low, best_high = (np.clip(end, grid[0], grid[-1]) for end in interval(best, best_boot))  # within the sweep
    worst = np.stack([worst_errors(limits, mu_rs, ratios, law, grid) for law in laws])       # (law, G)
    worst_boot = np.stack([worst_errors(boot, mu_rs, ratios, law, grid) for law in laws], axis=1)  # (B, law, G)
    minimax = grid[np.argmin(worst, axis=-1)]
    minimax_low, minimax_high = (np.clip(end, grid[0], grid[-1]) for end in
                                 interval(minimax, grid[np.argmin(worst_boot, axis=-1)]))
    minimax_error = worst.min(axis=-1)
    fitting_share = (worst_boot.min(axis=-1) <= tolerance).mean(axis=0)                     # (law,)
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
        "fitting_share": (("law",), fitting_share,
                          {**one, "long_name": "share of bootstrap replicates in which some mu_r puts every a's "
                                               "limits within the tolerance of the law"}),
        "minimax_mu_r": (("law",), minimax, {**one, "long_name": "mu_r with the smallest worst-case relative "
                                                                 "error over every a's limits (interpolated)"}),
        "minimax_mu_r_low": (("law",), minimax_low, {**one, "long_name": "minimax mu_r, interval's lower end"}),
        "minimax_mu_r_high": (("law",), minimax_high, {**one, "long_name": "minimax mu_r, interval's upper end"}),
        "minimax_error": (("law",), minimax_error, {**one, "long_name": "worst-case relative error at the minimax mu_r"}),
    }
    coords = {"mu_r": ("mu_r", mu_rs, {**one, "long_name": "rolling resistance coefficient"}),
              "aspect_ratio": ("aspect_ratio", ratios, {**one, "long_name": "aspect ratio h0/r0"}),
              "law": ("law", laws, {"long_name": "experimental law"}),
              "measure": ("measure", list(MEASURES), {"long_name": "which limits the misfit takes"})}
    attrs = {"replicates": replicates, "level": level, "bootstrap_seed": seed, "fit_tolerance": tolerance,
             "interval_widening": widen,
             "size_law_exponents": "1" if not exponents else f"{exponents[0]:g} to {exponents[1]:g}",
             "radii": ", ".join(f"{r:g}" for r in radii),
             "seeds_per_radius": ", ".join(f"r0 {r:g}: {len(s)}" for r, s in zip(radii, table.seeds))}
    return xr.Dataset(variables, coords=coords, attrs=attrs)


_LONG_NAMES = {
    "height_limit": "large-column limit of h_inf/r0", "height_low": "h_inf/r0 limit, interval's lower end",
    "height_high": "h_inf/r0 limit, interval's upper end",
    "runout_limit": "large-column limit of (r_inf - r0)/r0", "runout_low": "run-out limit, interval's lower end",
    "runout_high": "run-out limit, interval's upper end"}


def mu_r_interval(low: float, high: float, sweep: tuple[float, float]) -> str:
    """An interval of mu_r as text, an end at the sweep's edge (where the interval was cut: the true
    end may lie beyond) printed as "<= 0.060" or ">= 0.300"."""
    def end(value, edge, sign):
        return f"{sign} {value:.3f}" if np.isclose(value, edge) else f"{value:.3f}"
    return f"[{end(low, sweep[0], '<=')}, {end(high, sweep[1], '>=')}]"


def _coverage(target: str) -> str:
    """The measured coverage of `target`'s intervals, as a table prints it beside them."""
    low, high = MEASURED_COVERAGE[target]
    return f"such intervals held the truth in {100 * low:.0f}-{100 * high:.0f} % of synthetic studies"


def calibration_markdown(result: xr.Dataset) -> str:
    """The calibration as Markdown: the best mu_r per law and measure, the misfit per mu_r, whether
    one mu_r puts every a within the tolerance (the bootstrap's share, the minimax mu_r), and which
    a each mu_r fits."""
    level = f"{100 * float(result.attrs['level']):g} %"
    sweep = (float(result.mu_r.min()), float(result.mu_r.max()))
    lines = [f"Best mu_r (interpolated between the swept values; {level} bootstrap interval over the seeds"
             f" and the size law's exponent, p = {result.attrs['size_law_exponents']}; {_coverage('best mu_r')}):", "",
             "| law | measure | best mu_r | interval | misfit at the swept values |", "|---|---|---|---|---|"]
    for law in result.law.values:
        for measure in result.measure.values:
            part = result.sel(law=law, measure=measure)
            edge = " (an end of the sweep)" if int(part.best_at_edge) else ""
            curve = ", ".join(f"{float(m):g}: {100 * float(v):.1f} %" for m, v in zip(result.mu_r.values, part.misfit.values))
            lines.append(f"| {law} | {measure} | {float(part.best_mu_r):.3f}{edge} | "
                         f"{mu_r_interval(float(part.best_mu_r_low), float(part.best_mu_r_high), sweep)} | {curve} |")
    tolerance = f"{100 * float(result.attrs['fit_tolerance']):g} %"
    lines += ["", f"One mu_r for every a: the share of bootstrap replicates in which some mu_r puts every a's height"
                  f" and run-out limits within {tolerance} of the law, and the mu_r whose worst error over them is"
                  f" smallest (minimax; {_coverage('minimax mu_r')}):", "",
              "| law | some mu_r fits every a | minimax mu_r | interval | its worst error |", "|---|---|---|---|---|"]
    for law in result.law.values:
        part = result.sel(law=law)
        lines.append(f"| {law} | {100 * float(part.fitting_share):.0f} % of replicates | {float(part.minimax_mu_r):.3f} | "
                     f"{mu_r_interval(float(part.minimax_mu_r_low), float(part.minimax_mu_r_high), sweep)} | "
                     f"{100 * float(part.minimax_error):.1f} % |")
    lines += ["", f"Aspect ratios whose height and run-out limits both lie within {tolerance} of the law (on the"
                  " estimates):", "",
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
