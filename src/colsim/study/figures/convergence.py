"""The convergence studies' figures: the relative changes over the time step, end time, column
size and seeds, and the column-size limits X_inf with their intervals against Lube and Lajeunesse."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..collect import means_per_size
from ..experimental_laws import final_values, lube_runout
from .style import QUANTITY_LABELS, _empty, _pyplot, _save


def _time_step_panel(ax, part) -> None:
    """h_inf/r0 (filled) and the run-out (open) against dt/sqrt(h0/g), mean over seeds, sd as bars."""
    from ..convergence import time_step_means

    means = time_step_means(part)
    for k, (a, r0) in enumerate(sorted({(row["a"], row["r0"]) for row in means})):
        rows = [row for row in means if (row["a"], row["r0"]) == (a, r0)]
        dt = [row["dt"] for row in rows]
        for quantity, variable, fill in (("h", "h_inf_over_r0", f"C{k}"), ("runout", "runout_over_r0", "none")):
            ax.errorbar(dt, [row[quantity] for row in rows], yerr=[row[f"{quantity}_sd"] for row in rows],
                        fmt="o-", color=f"C{k}", mfc=fill, capsize=3,
                        label=f"a = {a:g}, r0 = {r0:g}, {QUANTITY_LABELS[variable]}")
    ax.set_xscale("log")
    ax.set_xlabel("time step dt / sqrt(h0/g)")
    ax.set_ylabel("h_inf/r0 (filled), (r_inf - r0)/r0 (open)")
    ax.set_title("time step (mean over seeds, bars: seed sd)", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)


def convergence_figure(table, path: Path) -> Path:
    """The convergence study (a table from :func:`colsim.study.convergence.runs_table`) in four panels:
    both quantities against dt/sqrt(h0/g), at the default and the later end time, against r0 over
    the mean diameter (mean over seeds; runs that go on past the default end also show their
    run-out there, dotted; Lube's run-out as a thin dashed line), and per seed with the mean.
    Filled markers: h_inf/r0; open: the run-out."""
    plt = _pyplot()
    fig, axes = plt.subplots(2, 2, figsize=(10, 8), layout="constrained")
    panels = (("time_step", "scaled_dt", "time step dt / sqrt(h0/g)"),
              ("end_time", "duration", "time t / sqrt(h0/g)"),
              ("column_size", "r0_over_mean_diameter", "r0 / mean diameter"),
              ("seeds", "seed", "packing seed"))
    for ax, (study, x_name, x_label) in zip(axes.ravel(), panels):
        part = table.where(table.study == study, drop=True)
        if part.sizes.get("run", 0) == 0:
            _empty(ax, f"no {study.replace('_', ' ')} runs")
            continue
        if study == "column_size":   # the mean over seeds at each r0
            part = means_per_size(part)
        if study == "time_step":     # the mean over seeds at each dt, the seed sd as error bars
            _time_step_panel(ax, part)
            continue
        for k, a in enumerate(np.unique(part.aspect_ratio.values)):
            rows = part.where(part.aspect_ratio == a, drop=True).sortby(x_name)
            x = rows[x_name].values
            colour = f"C{k}"
            for variable, fill in (("h_inf_over_r0", colour), ("runout_over_r0", "none")):
                y = rows[variable].values
                if study == "end_time":  # one run, measured at the default end and at its own end
                    x = np.r_[table.attrs["default_end_time"], rows.duration.values[0]]
                    y = np.r_[rows[f"{variable}_at_default_end"].values[0], y[0]]
                ax.plot(x, y, "o-", color=colour, mfc=fill, label=f"a = {a:g}, {QUANTITY_LABELS[variable]}")
                if study == "seeds":
                    ax.axhline(np.mean(y), color=colour, lw=0.8, ls="--")
            if study == "column_size":
                end = table.attrs["default_end_time"]
                if bool((rows.duration > end + 1e-9).any()):
                    ax.plot(x, rows.runout_over_r0_at_default_end.values, "s:", color=colour, mfc="none",
                            label=f"a = {a:g}, run-out at t/sqrt(h0/g) = {end:g}")
                ax.axhline(float(lube_runout(a)), color=colour, lw=0.8, ls="--")
        ax.set_xlabel(x_label)
        ax.set_ylabel("h_inf/r0 (filled), (r_inf - r0)/r0 (open)")
        ax.set_title(study.replace("_", " "), fontsize=10)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    return _save(fig, path)


def column_size_limit_figure(table, limits, path: Path) -> Path:
    """h_inf/r0 (top) and the run-out (bottom) against d/r0, one column per aspect ratio of the
    column_size sub-study: each run (one point per seed), the fit X_inf + k (d/r0)^p with its
    pointwise bootstrap band, X_inf at d/r0 = 0 with its bootstrap interval, and Lube's and
    Lajeunesse's values there (the experiments' columns held thousands of grains across: d/r0 about
    0; Lajeunesse's height only up to a = 0.74, where its printed law is a height). `limits`: from
    :func:`colsim.study.convergence.column_size_limits` (None: points only)."""
    plt = _pyplot()
    study = table.where(table.study == "column_size", drop=True)
    aspect = np.unique(study.aspect_ratio.values) if study.sizes.get("run", 0) else np.array([])
    fig, axes = plt.subplots(2, max(len(aspect), 1), figsize=(3.2 * max(len(aspect), 1) + 1, 6.5),
                             layout="constrained", squeeze=False)
    if not len(aspect):
        for ax in axes.ravel():
            _empty(ax, "no column-size runs")
        return _save(fig, path)
    for col, a in enumerate(aspect):
        part = study.isel(run=np.flatnonzero(study.aspect_ratio.values == a))
        x = 1.0 / part.r0_over_mean_diameter.values
        for row, measure in enumerate(("h_inf_over_r0", "runout_over_r0")):
            ax = axes[row, col]
            ax.plot(x, part[measure].values, "o", color="C0", mfc="none", label="runs (one per seed)")
            fitted = limits is not None and "aspect_ratio" in limits.coords and a in limits.aspect_ratio.values
            fit = limits.sel(aspect_ratio=a, measure=measure) if fitted else None
            if fit is not None and np.isfinite(float(fit.limit)):
                grid = np.linspace(0.0, 1.05 * x.max(), 100)
                curve = float(fit.limit) + float(fit.slope) * grid ** float(fit.exponent)
                ax.plot(grid, curve, "-", color="C0", lw=1, label=f"fit, p = {float(fit.exponent):.2f}")
                if "band_low" in fit:
                    ax.fill_between(limits.d_over_r0.values, fit.band_low.values, fit.band_high.values,
                                    color="C0", alpha=0.15, lw=0, label=f"fit's {float(limits.attrs['level']):.0%} band")
                low, high = float(fit.limit_low), float(fit.limit_high)
                ax.errorbar([0.0], [float(fit.limit)], yerr=[[float(fit.limit) - low], [high - float(fit.limit)]],
                            fmt="D", color="C0", capsize=3, label=f"X_inf, {float(limits.attrs['level']):.0%} interval")
            for offset, (name, value) in zip((-0.004, 0.004), final_values(measure, a).items()):
                ax.plot([offset], [value], "s" if "Lube" in name else "^", color="k" if "Lube" in name else "C3",
                        label=name)
            ax.set_xlim(-0.01, 1.1 * x.max())
            ax.set_title(f"a = {a:g}", fontsize=10)
            ax.set_xlabel("mean diameter / r0")
            ax.set_ylabel(QUANTITY_LABELS[measure])
            ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=7)
    return _save(fig, path)
