"""The study held to itself and to the experiments, as tables.

Four sub-studies, each a list of collapse analyses (:func:`runs_table` stacks them along `run`):

- time_step: the same columns with more steps over the same t/sqrt(h0/g);
- end_time: the same columns run on past the default end at the same dt; its deposit is measured
  on every frame, so the change from the default end to the last frame is read off one run;
- column_size: the same a at several r0 (reported as r0 over the mean diameter), possibly run on
  past the default end, where it is also measured;
- seeds: the same column from several packings.

:func:`convergence_markdown` turns the table into the relative changes docs/validation/ quotes (the
column-size runs averaged over seeds by :func:`colsim.study.collect.means_per_size`).
"""
from __future__ import annotations

import numpy as np

from ..stages.settings import scaled_step
from .collect import SHARED, SHARED_ACROSS_STEPS, check_runs, means_per_size

SUB_STUDIES = ("time_step", "end_time", "column_size", "seeds")
#: what tells two runs of one sub-study apart
RUN_IDENTITY = ("r0", "aspect_ratio", "mu_r", "seed", "n_steps", "duration")
RUN_VARIABLES = ("h_inf_over_r0", "runout_over_r0", "final_to_peak_kinetic_energy", "n_particles",
                 "wall_time")


def runs_table(groups: dict, default_end: float) -> "xarray.Dataset":  # noqa: F821
    """One Dataset over `run` from {sub-study: [analysis Datasets]}; default_end: the study's end
    time t/sqrt(h0/g), where the runs that go on are measured a second time.

    Coordinates per run: study, r0, aspect_ratio, mu_r, seed, n_steps, duration (t/sqrt(h0/g) at the
    end), scaled_dt (dt/sqrt(h0/g)), r0_over_mean_diameter. For the end_time study the deposit at the
    default end is added as h_inf_over_r0_at_default_end and runout_over_r0_at_default_end.
    """
    import xarray as xr

    unknown = set(groups) - set(SUB_STUDIES)
    if unknown:
        raise ValueError(f"unknown convergence sub-studies {sorted(unknown)}; choose from {SUB_STUDIES}")
    rows = [(study, analysis) for study in SUB_STUDIES for analysis in groups.get(study, [])]
    if not rows:
        raise ValueError("no analyses to tabulate")
    for study in SUB_STUDIES:
        if groups.get(study):
            check_runs(groups[study], RUN_IDENTITY, SHARED_ACROSS_STEPS if study == "time_step" else SHARED)
    coords = {
        "study": [s for s, _ in rows],
        "r0": [float(a.attrs["r0"]) for _, a in rows],
        "aspect_ratio": [float(a.attrs["aspect_ratio"]) for _, a in rows],
        "mu_r": [float(a.attrs["mu_r"]) for _, a in rows],
        "seed": [int(a.attrs.get("seed", 0)) for _, a in rows],
        "n_steps": [int(a.attrs["n_steps"]) for _, a in rows],
        "duration": [float(a.attrs["duration"]) for _, a in rows],
        "r0_over_mean_diameter": [float(a.attrs["r0"]) / float(a["mean_diameter"]) for _, a in rows],
    }
    coords["scaled_dt"] = list(scaled_step(np.array(coords["duration"]), np.array(coords["n_steps"])))
    long_names = {"study": "convergence sub-study", "r0": "cylinder radius", "aspect_ratio": "aspect ratio h0/r0",
                  "mu_r": "rolling resistance coefficient", "seed": "packing seed",
                  "n_steps": "number of time steps", "duration": "end time over sqrt(h0/g)",
                  "r0_over_mean_diameter": "r0 over the mean particle diameter",
                  "scaled_dt": "time step over sqrt(h0/g)"}
    data = {}
    for name in RUN_VARIABLES:
        data[name] = ("run", [float(a[name]) for _, a in rows], dict(rows[0][1][name].attrs))
    for name, history in (("h_inf_over_r0", "height_history"), ("runout_over_r0", "front_position")):
        data[f"{name}_at_default_end"] = (
            "run", [_at_time(a, history, default_end) for _, a in rows],
            {"units": "1", "long_name": f"{rows[0][1][name].attrs['long_name']} at the default end time"})
    coords = {k: ("run", v, {"long_name": long_names[k], "units": "length" if k == "r0" else "1"})
              for k, v in coords.items()}
    return xr.Dataset(data, coords=coords, attrs={"default_end_time": float(default_end)})


def _at_time(analysis, history: str, scaled_time: float) -> float:
    """A history variable of an analysis at the frame nearest scaled_time (NaN if not covered)."""
    t = analysis["scaled_time"].values
    if not np.isfinite(scaled_time) or len(t) == 0 or scaled_time > t.max() + 1e-9:
        return np.nan
    values = analysis[history].values
    if history == "height_history":
        values = values / float(analysis.attrs["r0"])
    return float(values[np.argmin(np.abs(t - scaled_time))])


def _relative(new, old) -> float:
    return abs(new - old) / max(abs(old), 1e-12)


def _with_changes(rows):
    """(k, h_inf/r0, run-out, change of each from the row before as text) along `rows`' runs."""
    previous = None
    for k in range(rows.sizes["run"]):
        h, r = float(rows.h_inf_over_r0[k]), float(rows.runout_over_r0[k])
        changes = ("", "") if previous is None else (
            f"{100 * _relative(h, previous[0]):.1f} %", f"{100 * _relative(r, previous[1]):.1f} %")
        yield k, h, r, changes
        previous = (h, r)


#: the criterion of the time-step study: within this relative difference of the finest step ...
CONVERGED_RELATIVE = 0.03
#: ... or within this share of the seed standard deviation, when that is larger
CONVERGED_SEED_SHARE = 1.0 / 3.0


def time_step_means(study) -> list[dict]:
    """The time-step runs averaged over seeds: one dict per (aspect_ratio, r0, n_steps), sorted, with
    a, r0, steps, dt (scaled), seeds, h, h_sd, runout, runout_sd (sample sd; 0 for one seed)."""
    keys = sorted({(float(a), float(r), int(n)) for a, r, n in
                   zip(study.aspect_ratio.values, study.r0.values, study.n_steps.values)})
    rows = []
    for a, r0, n in keys:
        pick = np.flatnonzero((study.aspect_ratio.values == a) & (study.r0.values == r0) & (study.n_steps.values == n))
        h, r = study.h_inf_over_r0.values[pick], study.runout_over_r0.values[pick]
        rows.append({"a": a, "r0": r0, "steps": n, "dt": float(study.scaled_dt.values[pick[0]]),
                     "seeds": len(pick), "h": float(h.mean()), "h_sd": _sample_sd(h),
                     "runout": float(r.mean()), "runout_sd": _sample_sd(r)})
    return rows


def _sample_sd(values) -> float:
    """Sample standard deviation (ddof 1); 0 for a single value."""
    return float(np.std(values, ddof=1)) if len(values) > 1 else 0.0


def converged_steps(rows: list[dict]) -> int | None:
    """The fewest steps of one column's refinement (`rows` of :func:`time_step_means`, one a and r0)
    whose mean h_inf/r0 and run-out are both within 3 % of the finest step's, or within a third of
    the finest's seed sd where that is larger; None with a single level."""
    if len(rows) < 2:
        return None
    finest = max(rows, key=lambda row: row["steps"])
    for row in sorted(rows, key=lambda row: row["steps"]):
        if all(abs(row[q] - finest[q]) <= max(CONVERGED_RELATIVE * abs(finest[q]),
                                              CONVERGED_SEED_SHARE * finest[f"{q}_sd"])
               for q in ("h", "runout")):
            return row["steps"]
    return finest["steps"]


def fit_converged_steps(rows: list[dict]) -> int | None:
    """The fewest steps of one column's refinement at which the straight-line fit X = X0 (1 + c dt)
    over all levels (:func:`_linear_fit`) is within 3 % of its dt -> 0 value X0, for h_inf/r0 and
    the run-out; None with fewer than three levels. Less sensitive to one level's seed noise than
    :func:`converged_steps`, which compares with the finest level's mean alone."""
    if len(rows) < 3:
        return None
    fits = [_linear_fit(rows, q) for q in ("h", "runout")]
    for row in sorted(rows, key=lambda row: row["steps"]):
        if all(abs(c * row["dt"]) <= CONVERGED_RELATIVE for _, c in fits):
            return row["steps"]
    return None


def _linear_fit(rows, quantity) -> tuple[float, float]:
    """(value at dt -> 0, slope over it) of quantity = X0 + C dt fitted to the levels (least squares)."""
    dt = np.array([row["dt"] for row in rows])
    values = np.array([row[quantity] for row in rows])
    slope, intercept = np.polyfit(dt, values, 1)
    return float(intercept), float(slope / intercept) if intercept else np.nan


def _time_step_lines(study) -> list[str]:
    lines = ["### Time step (same end time, more steps; mean over seeds, sd = sample standard deviation)", "",
             "| a | r0 | steps | dt/sqrt(h0/g) | seeds | h_inf/r0 | sd | change | vs finest "
             "| (r_inf - r0)/r0 | sd | change | vs finest |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    means = time_step_means(study)
    verdicts = []
    for a, r0 in sorted({(row["a"], row["r0"]) for row in means}):
        rows = [row for row in means if (row["a"], row["r0"]) == (a, r0)]
        finest, previous = rows[-1], None
        for row in rows:
            change = ["", ""] if previous is None else [
                f"{100 * _relative(row[q], previous[q]):.1f} %" for q in ("h", "runout")]
            versus = [f"{100 * (row[q] - finest[q]) / max(abs(finest[q]), 1e-12):+.1f} %" for q in ("h", "runout")]
            lines.append(f"| {a:g} | {r0:g} | {row['steps']} | {row['dt']:.3g} | {row['seeds']} | {row['h']:.3f} | "
                         f"{row['h_sd']:.3f} | {change[0]} | {versus[0]} | {row['runout']:.3f} | "
                         f"{row['runout_sd']:.3f} | {change[1]} | {versus[1]} |")
            previous = row
        steps = converged_steps(rows)
        if steps is not None:
            (h0, ch), (r_0, cr) = _linear_fit(rows, "h"), _linear_fit(rows, "runout")
            fitted = fit_converged_steps(rows)
            verdicts.append(f"- a = {a:g}, r0 = {r0:g}: converged at {steps} steps (within "
                            f"{100 * CONVERGED_RELATIVE:g} % of the finest, or a third of its seed sd); "
                            f"fit X = X0 (1 + c dt/sqrt(h0/g)): h_inf/r0 X0 = {h0:.3f}, c = {ch:+.2f}; "
                            f"run-out X0 = {r_0:.3f}, c = {cr:+.2f}; the fit is within "
                            f"{100 * CONVERGED_RELATIVE:g} % of X0 from {fitted or '-'} steps")
    return lines + ([""] + verdicts if verdicts else [])


def _end_time_lines(study) -> list[str]:
    lines = ["### End time (run on at the same dt)", "",
             "| a | end t/sqrt(h0/g) | h_inf/r0 at default end | at end | change | run-out at default end "
             "| at end | change | final/peak kinetic energy |", "|---|---|---|---|---|---|---|---|---|"]
    for k in range(study.sizes["run"]):
        h0, h1 = float(study.h_inf_over_r0_at_default_end[k]), float(study.h_inf_over_r0[k])
        r0, r1 = float(study.runout_over_r0_at_default_end[k]), float(study.runout_over_r0[k])
        lines.append(f"| {float(study.aspect_ratio[k]):g} | {float(study.duration[k]):g} | {h0:.3f} | {h1:.3f} | "
                     f"{100 * _relative(h1, h0):.1f} % | {r0:.3f} | {r1:.3f} | {100 * _relative(r1, r0):.1f} % | "
                     f"{float(study.final_to_peak_kinetic_energy[k]):.2g} |")
    return lines


def _column_size_lines(study) -> list[str]:
    end = study.attrs["default_end_time"]
    lines = ["### Column size (mean over seeds; spread = max - min)", "",
             "| a | r0 | r0/mean d | seeds | spheres | end t/sqrt(h0/g) | h_inf/r0 | change | (r_inf - r0)/r0 "
             f"| spread | change | run-out at t/sqrt(h0/g) = {end:g} |", "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    means = means_per_size(study)
    for a in np.unique(means.aspect_ratio.values):
        rows = means.isel(run=np.flatnonzero(means.aspect_ratio.values == a))
        for k, h, r, changes in _with_changes(rows):
            lines.append(f"| {a:g} | {float(rows.r0[k]):g} | {float(rows.r0_over_mean_diameter[k]):.1f} | "
                         f"{int(rows.n_seeds[k])} | {float(rows.n_particles[k]):.0f} | {float(rows.duration[k]):g} | "
                         f"{h:.3f} | {changes[0]} | {r:.3f} | {float(rows.runout_spread[k]):.3f} | {changes[1]} | "
                         f"{float(rows.runout_over_r0_at_default_end[k]):.3f} |")
    return lines


def _seed_lines(study) -> list[str]:
    def spread(values):
        std = values.std(ddof=1) if len(values) > 1 else 0.0
        return f"{values.mean():.3f} | {std:.3f} | {100 * std / max(abs(values.mean()), 1e-12):.1f} %"

    h, r = study.h_inf_over_r0.values, study.runout_over_r0.values
    return ["### Seeds", "", "| a | seeds | h_inf/r0 mean | std | std/mean | (r_inf - r0)/r0 mean | std | std/mean |",
            "|---|---|---|---|---|---|---|---|",
            f"| {float(study.aspect_ratio[0]):g} | {len(h)} | {spread(h)} | {spread(r)} |"]


def convergence_markdown(table) -> str:
    """Markdown tables of the relative change of h_inf/r0 and the run-out per refinement."""
    lines = []
    for name, section in (("time_step", _time_step_lines), ("end_time", _end_time_lines),
                          ("column_size", _column_size_lines), ("seeds", _seed_lines)):
        study = table.where(table.study == name, drop=True)
        if study.sizes.get("run", 0):
            lines += section(study) + [""]
    return "\n".join(lines)


LIMIT_MEASURES = ("h_inf_over_r0", "runout_over_r0")
#: Accuracies for which :func:`column_size_limits` states the r0 a study needs.
LIMIT_ACCURACIES = (0.05, 0.02)
#: Points of d/r0 at which the fit's bootstrap band is stored.
BAND_POINTS = 41
#: the lowest and highest share of synthetic column-size studies in which the 95 % intervals of the
#: limits held the truth, over the cases of colsim.study.coverage.SIZE_CASES (200 studies each;
#: `python -m colsim.study.coverage sizes`, the table in docs/validation/column-size.md): 94 % where
#: the size law has p = 0.5, 99.9 % where it has p = 1 (too wide there: the range that holds p = 0.5)
MEASURED_SIZE_COVERAGE = (0.94, 0.999)
#: the size law's exponents a replicate of the column-size limits draws from: wider than the
#: calibration's 0.5-1.5 since four or five sizes shrink the seeds' share of the interval, and an
#: exponent at the range's edge is then missed: drawn from 0.5-1.5, the intervals held a true p = 0.5
#: in 83 % of synthetic studies of this design (docs/validation/column-size.md)
SIZE_EXPONENTS = (0.3, 1.6)


def column_size_limits(table, replicates: int = 2000, level: float = 0.95, seed: int = 0):
    """The column-size limit X_inf of h_inf/r0 and the run-out at each aspect ratio of the
    column_size sub-study with at least 2 sizes (:func:`colsim.study.size_limit.size_limit`: X(r0) =
    X_inf + k d/r0, its interval by bootstrap over the seeds and the size law's exponent p drawn from
    SIZE_EXPONENTS, the calibration's method), beside Lube's and Lajeunesse's laws, how far the largest r0's mean is from
    X_inf, and the r0 (length) at which the fit is within 5 % and 2 % of X_inf; with 4 sizes or more
    the exponent p fitted with its interval; and the fit's pointwise band over d/r0 (BAND_POINTS from
    0 to 1.05 times the largest).

    Returns a Dataset over (aspect_ratio, measure) (the band also over d_over_r0); None when no
    aspect ratio has 2 sizes."""
    import xarray as xr

    from .experimental_laws import final_values
    from .size_limit import size_limit

    study = table.where(table.study == "column_size", drop=True)
    if study.sizes.get("run", 0) == 0:
        return None
    rows, bands = {}, {}
    d_over_r0 = np.linspace(0.0, 1.05 * float(np.max(1.0 / study.r0_over_mean_diameter.values)), BAND_POINTS)
    for a in np.unique(study.aspect_ratio.values):
        part = study.isel(run=np.flatnonzero(study.aspect_ratio.values == a))
        r0 = part.r0.values
        if len(np.unique(r0)) < 2:
            continue
        diameter = float(np.mean(r0 / part.r0_over_mean_diameter.values))
        for measure in LIMIT_MEASURES:
            values = part[measure].values
            runs = {float(r): values[r0 == r] for r in np.unique(r0)}
            limit = size_limit(runs, diameter, replicates, level, seed, exponents=SIZE_EXPONENTS)
            fit = limit.fit
            laws = {name.split()[0]: value for name, value in final_values(measure, a).items()}
            needed = [diameter * (abs(fit.k) / (accuracy * abs(fit.x_inf))) ** (1.0 / fit.p)
                      if fit.x_inf else np.nan for accuracy in LIMIT_ACCURACIES]
            largest = float(np.mean(runs[max(runs)]))
            free_p = limit.free.p if limit.free else np.nan
            rows[(float(a), measure)] = [fit.x_inf, limit.low, limit.high, fit.k, fit.p, laws["Lube"],
                                         laws["Lajeunesse"], len(runs), float(max(runs)),
                                         largest / fit.x_inf - 1.0 if fit.x_inf else np.nan, diameter, *needed,
                                         free_p, limit.p_low, limit.p_high]
            bands[(float(a), measure)] = limit.band(d_over_r0)
    if not rows:
        return None
    names = ["limit", "limit_low", "limit_high", "slope", "exponent", "lube", "lajeunesse", "n_sizes",
             "largest_r0", "largest_r0_off", "mean_diameter", "r0_for_5_percent", "r0_for_2_percent",
             "fitted_exponent", "fitted_exponent_low", "fitted_exponent_high"]
    long_names = {
        "limit": "column-size limit X_inf of the fit X = X_inf + k (d/r0)^p",
        "limit_low": f"lower end of the {level:.0%} interval of X_inf (bootstrap over the seeds and p in 0.5-1.5)",
        "limit_high": f"upper end of the {level:.0%} interval of X_inf (bootstrap over the seeds and p in 0.5-1.5)",
        "slope": "k of the fit", "exponent": "p of the fit (1)",
        "lube": "Lube et al. (2004) at this a",
        "lajeunesse": "Lajeunesse et al. (2004) at this a (no height above a = 0.74: its printed law is none)",
        "n_sizes": "column sizes fitted", "largest_r0": "largest r0 measured",
        "largest_r0_off": "the seeds' mean at the largest r0, relative to X_inf (X / X_inf - 1)",
        "mean_diameter": "mean particle diameter d",
        "r0_for_5_percent": "r0 at which the fit is within 5 % of X_inf",
        "r0_for_2_percent": "r0 at which the fit is within 2 % of X_inf",
        "fitted_exponent": "p fitted with X_inf and k (4 sizes or more; not used in the limit)",
        "fitted_exponent_low": f"lower end of the {level:.0%} percentile bootstrap interval of the fitted p",
        "fitted_exponent_high": f"upper end of the {level:.0%} percentile bootstrap interval of the fitted p"}
    lengths = {"largest_r0", "mean_diameter", "r0_for_5_percent", "r0_for_2_percent"}
    aspect = sorted({a for a, _ in rows})
    data = {}
    for k, name in enumerate(names):
        grid = np.full((len(aspect), len(LIMIT_MEASURES)), np.nan)
        for (a, measure), values in rows.items():
            grid[aspect.index(a), LIMIT_MEASURES.index(measure)] = values[k]
        data[name] = (("aspect_ratio", "measure"), grid,
                      {"long_name": long_names[name], "units": "length" if name in lengths else "1"})
    for end, name in enumerate(("band_low", "band_high")):
        band = np.full((len(aspect), len(LIMIT_MEASURES), len(d_over_r0)), np.nan)
        for (a, measure), values in bands.items():
            band[aspect.index(a), LIMIT_MEASURES.index(measure)] = values[end]
        data[name] = (("aspect_ratio", "measure", "d_over_r0"), band,
                      {"long_name": f"{('lower', 'upper')[end]} end of the fit's pointwise {level:.0%} band",
                       "units": "1"})
    limits = xr.Dataset(data, coords={
        "aspect_ratio": ("aspect_ratio", aspect, {"long_name": "aspect ratio h0/r0", "units": "1"}),
        "measure": ("measure", list(LIMIT_MEASURES), {"long_name": "deposit measure X"}),
        "d_over_r0": ("d_over_r0", d_over_r0, {"long_name": "mean particle diameter over r0", "units": "1"})})
    limits.attrs.update(replicates=replicates, level=level, bootstrap_seed=seed,
                        size_law_exponents=f"{SIZE_EXPONENTS[0]:g} to {SIZE_EXPONENTS[1]:g}")
    return limits


def column_size_limit_markdown(limits) -> str:
    """The limits of :func:`column_size_limits` as a Markdown table, the measured coverage of such
    intervals (MEASURED_SIZE_COVERAGE) beside them."""
    if limits is None:
        return "### Column-size limits\n\nFewer than two column sizes at every aspect ratio: no limit fitted.\n"
    level = float(limits.attrs["level"])
    low, high = MEASURED_SIZE_COVERAGE
    lines = ["### Column-size limits (X = X_inf + k d/r0 over every seed)", "",
             f"X_inf's {level:.0%} interval: bootstrap over the seeds and the size law's exponent, p = "
             f"{limits.attrs['size_law_exponents']}; such intervals held the true limit in {100 * low:.0f}-"
             f"{100 * high:.0f} % of synthetic studies of this design (docs/validation/column-size.md). The fitted p "
             "(4 sizes or more) is a check of p = 1, not used in the limit; its percentile interval's coverage was "
             "not measured.", "",
             f"| a | X | sizes | largest r0 | X_inf [{level:.0%} interval] | fitted p [{level:.0%}] | "
             "Lube | X_inf vs Lube | Lajeunesse | X_inf vs Lajeunesse | largest r0 vs X_inf | r0 for 5 % | r0 for 2 % |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for a in limits.aspect_ratio.values:
        for measure in limits.measure.values:
            row = limits.sel(aspect_ratio=a, measure=measure)
            if np.isnan(float(row.limit)):
                continue
            x, lube, laj = float(row.limit), float(row.lube), float(row.lajeunesse)
            p = ("-" if np.isnan(float(row.fitted_exponent)) else
                 f"{float(row.fitted_exponent):.2f} [{float(row.fitted_exponent_low):.2f}, "
                 f"{float(row.fitted_exponent_high):.2f}]")
            lines.append(f"| {a:g} | {measure} | {int(row.n_sizes)} | {float(row.largest_r0):g} | {x:.3f} "
                         f"[{float(row.limit_low):.3f}, {float(row.limit_high):.3f}] | {p} | {lube:.3f} | "
                         f"{100 * (x / lube - 1):+.0f} % | {_or_dash(laj, '.3f')} | {_or_dash(100 * (x / laj - 1), '+.0f', ' %')} | "
                         f"{_or_dash(100 * float(row.largest_r0_off), '+.1f', ' %')} | "
                         f"{float(row.r0_for_5_percent):.2g} | {float(row.r0_for_2_percent):.2g} |")
    return "\n".join(lines) + "\n"


def _or_dash(value: float, spec: str, suffix: str = "") -> str:
    """`value` formatted, or '-' when it is NaN."""
    return "-" if np.isnan(value) else f"{value:{spec}}{suffix}"
