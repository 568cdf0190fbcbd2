"""What a channel study adds to a cylinder's tables: the exponents of its run-outs and heights
against a, beside those of the channel laws (Balmforth & Kerswell's, which give exponents only,
and the 2/3 of Lube et al. and Lajeunesse et al. 2005), and the convergence of the run-outs in the
box length L0 (the relative spread between the two largest L0), and the change the same columns
show at another time step (:func:`paired_difference`).

Both take summaries as :func:`colsim.study.collect.collect_analyses` makes them, one per box length,
with r0 standing for L0 in the variables' names (colsim.stages.analyse)."""
from __future__ import annotations

import warnings

import numpy as np
import xarray as xr
from scipy.stats import ttest_1samp, ttest_ind

from .experimental_laws import (BALMFORTH_KERSWELL, LUBE_2005_HEIGHT_BREAK, LUBE_2005_POWER_ABOVE,
                                power_law_exponent)

#: the aspect ratios an exponent is fitted over, from Lube et al.'s (2005) power-law regimes: the
#: run-out's from a = 2.8, the height's from a = 1.15 (below them both grow as a)
FIT_FROM = {"runout_over_r0": LUBE_2005_POWER_ABOVE, "h_inf_over_r0": LUBE_2005_HEIGHT_BREAK}
#: the exponent of Lube et al.'s and Lajeunesse et al.'s (2005) run-out in its power-law regime
TWO_THIRDS = 2.0 / 3.0
#: the goal for the run-outs' spread between the two largest box lengths
CONVERGED_SPREAD = 0.02


def stood(summary, runout=None) -> xr.DataArray:
    """Where a column stood: its run-out (`runout`, default the summary's runs) shorter than one mean
    diameter, the settling of the front rather than a spread (False where the summary lacks the
    diameters or L0)."""
    runout = summary.runout_over_r0 if runout is None else runout
    if "mean_diameter" not in summary or "channel_length" not in summary.attrs:
        return xr.zeros_like(runout, dtype=bool)
    diameter = summary.mean_diameter.mean("seed") if "seed" not in runout.dims else summary.mean_diameter
    return runout < diameter / float(summary.attrs["channel_length"])


def fitted_exponent(summary, variable: str, mu_r: float, a_min: float | None = None) -> tuple[float, int]:
    """(b, number of aspect ratios) of `variable` ~ c a^b fitted over every run (each seed a point)
    at `mu_r` with a >= a_min (default FIT_FROM[variable]); NaN where fewer than two a have runs. A
    run-out shorter than one mean diameter (where the summary has the diameters and L0) is left out:
    the column stood, and its run-out is the settling of the front, not a spread with a power of a."""
    a_min = FIT_FROM[variable] if a_min is None else a_min
    part = summary[variable]
    if variable == "runout_over_r0":
        part = part.where(~stood(summary))
    part = part.sel(mu_r=mu_r).transpose("aspect_ratio", "seed")
    ratios = part.aspect_ratio.values
    keep = ratios >= a_min
    values = part.values[keep]
    a = np.broadcast_to(ratios[keep][:, None], values.shape)
    used = int(np.isfinite(values).any(axis=-1).sum()) if values.size else 0
    return power_law_exponent(a, values), used


def exponents_markdown(summary) -> str:
    """Markdown table per mu_r: the fitted exponents of the run-out and of the height (over
    FIT_FROM's aspect ratios) beside Balmforth & Kerswell's for narrow slots and wide channels and,
    for the run-out, Lube's and Lajeunesse's 2/3."""
    narrow, wide = BALMFORTH_KERSWELL["narrow"], BALMFORTH_KERSWELL["wide"]
    lines = ["| mu_r | run-out exponent (a >= {r:g}, run-outs of a grain or more; a values) | B&K narrow | B&K wide | Lube, Lajeunesse 2005 "
             "| height exponent (a >= {h:g}; a values) | B&K narrow | B&K wide |".format(
                 r=FIT_FROM["runout_over_r0"], h=FIT_FROM["h_inf_over_r0"]),
             "|---|---|---|---|---|---|---|---|"]
    for m in summary.mu_r.values:
        runout, n_runout = fitted_exponent(summary, "runout_over_r0", float(m))
        height, n_height = fitted_exponent(summary, "h_inf_over_r0", float(m))
        lines.append(f"| {float(m):g} | {_exponent(runout, n_runout)} | {_law(narrow['runout_over_r0'])} | "
                     f"{_law(wide['runout_over_r0'])} | {TWO_THIRDS:.2f} | {_exponent(height, n_height)} | "
                     f"{_law(narrow['h_inf_over_r0'])} | {_law(wide['h_inf_over_r0'])} |")
    return "\n".join(lines) + "\n"


def _exponent(value: float, count: int) -> str:
    return f"{value:.2f} ({count})" if np.isfinite(value) else f"- ({count})"


def _law(exponent: tuple) -> str:
    value, error = exponent
    return f"{value:g}" if error is None else f"{value:g} +- {error:g}"


def length_convergence(summaries: dict) -> xr.Dataset:
    """The run-outs' convergence in the box length: {L0: summary} -> a Dataset over (aspect_ratio,
    mu_r) of the mean run-out over seeds at each L0 (`runout_by_length`, over `channel_length`), where
    the column stood (`stood`: :func:`stood` of the mean), `relative_spread`, |R(L_max) - R(L_next)|
    / |R(L_max)| between the two largest L0 (NaN where either has no run or stood: a spread of
    settlings is no convergence), and `spread_half_width`, the 95 % half-width of that difference
    from the seeds' scatter (:func:`difference_half_width`; NaN with fewer than two seeds at either).
    ValueError with fewer than two lengths or aspect ratios and mu_r that differ."""
    if len(summaries) < 2:
        raise ValueError(f"the convergence in L0 needs two box lengths or more, got {len(summaries)}")
    summaries = {float(length): summary for length, summary in summaries.items()}
    lengths = sorted(summaries)
    first = summaries[lengths[0]]
    means, stands = [], []
    for length in lengths:
        summary = summaries[length]
        for dim in ("aspect_ratio", "mu_r"):
            if not np.array_equal(summary[dim].values, first[dim].values):
                raise ValueError(f"the summary at L0 = {length:g} has other {dim} values than at L0 = {lengths[0]:g}")
        mean = summary.runout_over_r0.mean("seed", skipna=True)
        means.append(mean.reset_coords(drop=True))   # r0 differs
        stands.append(stood(summary, mean).reset_coords(drop=True))
    length = xr.DataArray(lengths, dims="channel_length", name="channel_length",
                          attrs={"units": "length", "long_name": "box length L0"})
    stacked, standing = xr.concat(means, dim=length), xr.concat(stands, dim=length)
    largest, next_largest = stacked.isel(channel_length=-1), stacked.isel(channel_length=-2)
    either_stood = standing.isel(channel_length=slice(-2, None)).any("channel_length")
    spread = (abs(largest - next_largest) / abs(largest)).where(~either_stood)
    half_width = (difference_half_width(summaries[lengths[-1]].runout_over_r0,
                                        summaries[lengths[-2]].runout_over_r0).reset_coords(drop=True)
                  / abs(largest)).where(~either_stood)
    return xr.Dataset({
        "runout_by_length": stacked.assign_attrs(units="1", long_name="run-out (L_inf - L0)/L0, mean over seeds"),
        "stood": standing.astype(np.int8).assign_attrs(
            long_name="the mean run-out is shorter than one mean diameter: the column stood"),
        "relative_spread": spread.assign_attrs(
            units="1", long_name=f"|run-out at L0 = {lengths[-1]:g} - at {lengths[-2]:g}| over the first (NaN "
                                 "where either stood)"),
        "spread_half_width": half_width.assign_attrs(
            units="1", long_name="95 % half-width of that difference over the same run-out, from the seeds' "
                                 "scatter (Welch; NaN with fewer than two seeds at either length)"),
    })


def difference_half_width(first: xr.DataArray, second: xr.DataArray, level: float = 0.95) -> xr.DataArray:
    """The `level` half-width of the difference of the seeds' means of `first` and `second` (over
    "seed"; the seeds of two box lengths are independent pours): Welch's interval, scipy's
    (`ttest_ind` with unequal variances). NaN where either has fewer than two finite seeds; 0 where
    neither scatters."""
    def half_width(one, other):
        with warnings.catch_warnings():   # scipy's words on the cases the docstring gives
            warnings.filterwarnings("ignore", "Precision loss occurred", RuntimeWarning)   # seeds alike: 0
            warnings.filterwarnings("ignore", "After omitting NaNs", RuntimeWarning)       # one seed: NaN
            interval = ttest_ind(one, other, axis=-1, equal_var=False, nan_policy="omit").confidence_interval(level)
        return (interval.high - interval.low) / 2

    return xr.apply_ufunc(half_width, first, second, input_core_dims=[["seed"], ["seed"]], exclude_dims={"seed"})


def paired_difference(values, references, level: float = 0.95) -> tuple[float, float, int]:
    """(mean, `level` half-width, number of pairs) of the relative difference values/references - 1
    over the pairs where both are finite: the same columns run twice (one packing seed, a and mu_r,
    at two time steps), so each pair's difference removes the seeds' scatter. The interval is
    Student's, scipy's (`ttest_1samp`); the half-width is NaN for one pair."""
    values, references = np.asarray(values, dtype=float), np.asarray(references, dtype=float)
    both = np.isfinite(values) & np.isfinite(references)
    differences = values[both] / references[both] - 1
    if len(differences) < 2:
        return (float(differences.mean()) if len(differences) else np.nan), np.nan, len(differences)
    with warnings.catch_warnings():   # pairs alike (columns that stood at both steps): no scatter
        warnings.filterwarnings("ignore", "Precision loss occurred", RuntimeWarning)
        interval = ttest_1samp(differences, 0.0).confidence_interval(level)
    return float(differences.mean()), float((interval.high - interval.low) / 2), len(differences)


def length_convergence_markdown(convergence: xr.Dataset) -> str:
    """Markdown table per mu_r and a: the mean run-out at each box length ("stood" where the column
    stood) and the relative spread between the two largest with its 95 % half-width where both have
    two seeds or more. The verdict: "converged" where the whole interval lies within
    CONVERGED_SPREAD, "above 2 %" where it lies beyond, "within the seeds' scatter" where it holds
    both; with one seed at either length, the spread alone decides and the verdict says "one seed"."""
    lengths = convergence.channel_length.values
    header = ["mu_r", "a"] + [f"L0 = {length:g}" for length in lengths] + ["spread, two largest [95 %]", ""]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for m in convergence.mu_r.values:
        for a in convergence.aspect_ratio.values:
            values = convergence.runout_by_length.sel(mu_r=m, aspect_ratio=a).values
            standing = convergence.stood.sel(mu_r=m, aspect_ratio=a).values
            spread = float(convergence.relative_spread.sel(mu_r=m, aspect_ratio=a))
            half_width = float(convergence.spread_half_width.sel(mu_r=m, aspect_ratio=a))
            cells = ["stood" if s else f"{v:.3f}" if np.isfinite(v) else "-" for v, s in zip(values, standing)]
            spread_cell, verdict = _spread_cells(spread, half_width)
            lines.append(f"| {float(m):g} | {a:g} | " + " | ".join(cells) + f" | {spread_cell} | {verdict} |")
    return "\n".join(lines) + "\n"


def _spread_cells(spread: float, half_width: float) -> tuple[str, str]:
    """(the spread's cell, the verdict) for one a and mu_r."""
    if not np.isfinite(spread):
        return "-", "-"
    goal = f"{100 * CONVERGED_SPREAD:g} %"
    if not np.isfinite(half_width):
        return f"{100 * spread:.1f} % (one seed)", ("converged" if spread <= CONVERGED_SPREAD else f"above {goal}") + ", one seed"
    cell = f"{100 * spread:.1f} % +- {100 * half_width:.1f}"
    if spread + half_width <= CONVERGED_SPREAD:
        return cell, "converged"
    if spread - half_width > CONVERGED_SPREAD:
        return cell, f"above {goal}"
    return cell, "within the seeds' scatter"
