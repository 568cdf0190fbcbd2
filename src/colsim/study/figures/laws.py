"""The figures against the experimental laws: final_height.png and runout.png (h_inf/r0 and
(r_inf - r0)/r0 against a, one marker per mu_r, mean over seeds with the seeds' spread, beside the
laws of Lube et al. and Lajeunesse et al.: the paper's Figs. 6 and 7; the frame fits the data and
Lube's laws, and a law that would squeeze them leaves it with a note), mu_r_effect.png (both against
mu_r, one colour per a, Lube's laws dashed), and the friction-law comparison's figure."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..collect import FLAGS
from ...stages.pour_geometry import geometry_of
from ..experimental_laws import BREAKPOINTS, REFERENCE, laws_for
from .style import (MARKERS, QUANTITY_LABELS, _bar_kind, _bar_note, _bars, _colours, _draw_flags, _flag_handles,
                    _flags_of, _label, _pyplot, _save)


LAW_STYLES = ("-", "--", ":", "-.")


ASPECT_RATIO_LABELS = {"cylinder": "aspect ratio a = h0/r0", "channel": "aspect ratio a = H0/L0"}


SQUEEZE = 2.0
"""A law whose curve rises above SQUEEZE times the top of the data and Lube's laws would squeeze them:
it leaves the frame (Lajeunesse's height law as printed, 0.74 a, reaches 4.1 at a = 5.5 where the
heights are about 1)."""


def _law_abscissa(end: float, geometry: str = "cylinder"):
    """Values of a from 0 to `end`, with NaN at the `geometry`'s laws' breakpoints so the jumps are
    not drawn as lines."""
    edges = sorted({0.0, end, *(b for b in BREAKPOINTS[geometry] if b < end)})
    pieces = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        pieces += [np.linspace(lo, hi - 1e-9 * (hi < end), 100), [np.nan]]
    return np.concatenate(pieces[:-1])


def _against_aspect_ratio(ax, ratios, span, series, outside: bool = False, geometry: str = "cylinder") -> float:
    """Draw `series`, [(label, values (aspect_ratio, seed), flags {flag: bool (aspect_ratio,)})],
    against a on `ax`: the mean over seeds with error bars (the standard error or the range, as
    :func:`_bar_kind` chooses for all of them; the legend's title says which), side by side so the
    bars stay readable, flagged points drawn as :func:`_draw_flags` does; then the axes, with the
    legend right of them if `outside` (where it hides no point). Returns the top of the bars (NaN
    where nothing was drawn)."""
    kind, fewest, most = _bar_kind(*(values for _, values, _ in series))
    top, bottom = np.nan, 0.0
    for k, (label, values, flags) in enumerate(series):
        mean, low, high = _bars(values, kind)
        dodge = (k - (len(series) - 1) / 2) * 0.012 * span[-1]
        marker = MARKERS[k % len(MARKERS)]
        bars = ax.errorbar(ratios + dodge, mean, yerr=[low, high], fmt=marker, ms=6, capsize=3, label=label)
        _draw_flags(ax, ratios + dodge, mean, flags, bars.lines[0].get_color(), marker)
        if np.isfinite(mean).any():
            top = np.fmax(top, np.nanmax(mean + high))
            bottom = min(bottom, float(np.nanmin(mean - low)))
    ax.set_xlabel(ASPECT_RATIO_LABELS[geometry])
    ax.set_xlim(0, span[-1])
    ax.set_ylim(bottom=0.0 if bottom >= 0 else 1.1 * bottom)   # a run-out below 0: a main mass inside r0
    ax.grid(alpha=0.3)
    handles, _ = ax.get_legend_handles_labels()
    handles += _flag_handles({name: np.concatenate([np.ravel(f[name]) for _, _, f in series])
                              for name in FLAGS})
    where = {"loc": "upper left", "bbox_to_anchor": (1.02, 1.0)} if outside else {}
    ax.legend(handles=handles, fontsize=7, title=_bar_note(kind, fewest, most), title_fontsize=7, **where)
    return float(top)


def _fit_laws(ax, span, laws: dict, top: float, variable: str, reference: str = REFERENCE["cylinder"]) -> None:
    """Set the top of `ax` to hold the data (up to `top`) and the `reference` law; a law rising
    above SQUEEZE times that is left outside the frame, with a note under the axes saying from where."""
    values = {name: np.asarray(law(span), dtype=float) for name, law in laws.items()}
    base = np.nanmax([top, *(np.nanmax(v, initial=0.0) for n, v in values.items() if n == reference)])
    if not np.isfinite(base) or base <= 0:
        return
    frame = base
    notes = []
    for name, curve in values.items():
        highest = np.nanmax(curve, initial=0.0)
        if highest <= SQUEEZE * base:
            frame = max(frame, highest)
            continue
        leaves = span[np.flatnonzero(np.nan_to_num(curve) > 1.05 * frame)[0]]
        peak = span[np.nanargmax(curve)]
        notes.append(f"The law of {name} leaves the frame above a = {leaves:.2g}\n(it reaches "
                     f"{QUANTITY_LABELS.get(variable, variable)} = {highest:.2g} at a = {peak:.2g}).")
    ax.set_ylim(ax.get_ylim()[0], 1.05 * frame)
    if notes:
        ax.annotate("\n".join(notes), xy=(0, -0.17), xycoords="axes fraction", va="top", fontsize=8)


def law_figure(summary, variable: str, path: Path) -> Path:
    """`variable` (h_inf_over_r0 or runout_over_r0) against a: markers per mu_r, the laws of the
    summary's geometry as curves (a channel's: Lube et al. 2005 and Lajeunesse et al. 2005, r0
    standing for L0)."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(5.5, 4.2))
    geometry = geometry_of(summary.attrs)
    laws = laws_for(geometry)[variable]
    ratios = summary["aspect_ratio"].values
    span = _law_abscissa(max(float(np.max(ratios)) * 1.1, 1.0), geometry)
    for (name, law), style in zip(laws.items(), LAW_STYLES):
        ax.plot(span, law(span), style, color="0.35", lw=1.2, label=name)
    data = summary[variable].transpose("aspect_ratio", "mu_r", "seed")
    flags = {name: flag.transpose("aspect_ratio", "mu_r").values for name, flag in _flags_of(summary).items()}
    top = _against_aspect_ratio(ax, ratios, span,
                                [(f"colsim, $\\mu_r$ = {mu_r:g}", data.isel(mu_r=k).values,
                                  {name: flag[:, k] for name, flag in flags.items()})
                                 for k, mu_r in enumerate(summary["mu_r"].values)], outside=True,
                                geometry=geometry)
    _fit_laws(ax, span, laws, top, variable, REFERENCE[geometry])
    ax.set_ylabel(_label(summary[variable], variable))
    ax.set_title(f"{_size(summary)}, mu = {summary.attrs.get('mu', float('nan')):g}, "
                 f"{summary.sizes['seed']} seed(s)", fontsize=9)
    return _save(fig, path)


def _size(summary) -> str:
    """The column's size for a title: "r0 = 3", or a channel's "L0 = 6, W = 2, wall_mu = 0.577" (its
    walls' friction, which sets a channel's run-out as much as mu_r: docs/validation/channel.md)."""
    if geometry_of(summary.attrs) == "channel":
        walls = f", wall_mu = {summary.attrs['wall_mu']:g}" if "wall_mu" in summary.attrs else ""
        return (f"L0 = {summary.attrs.get('channel_length', float('nan')):g}, "
                f"W = {summary.attrs.get('channel_width', float('nan')):g}{walls}")
    return f"r0 = {summary.attrs.get('r0', float('nan')):g}"


def friction_law_figure(comparison, path: Path) -> Path:
    """h_inf/r0 and the run-out against a under each friction law (mean over seeds, bars as in
    :func:`_against_aspect_ratio`), at the comparison's first mu_r, with Lube's laws drawn."""
    plt = _pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.2), layout="constrained")
    geometry = geometry_of(comparison.attrs)
    reference = REFERENCE[geometry]
    ratios = comparison["aspect_ratio"].values
    span = _law_abscissa(max(float(np.max(ratios)) * 1.1, 1.0), geometry)
    mu_r = float(comparison["mu_r"].values[0])
    flags = {name: flag.sel(mu_r=mu_r).transpose("friction_law", "aspect_ratio")
             for name, flag in _flags_of(comparison).items()}
    for ax, variable in zip(axes, ("h_inf_over_r0", "runout_over_r0")):
        ax.plot(span, laws_for(geometry)[variable][reference](span), "-", color="0.35", lw=1.2, label=reference)
        data = comparison[variable].sel(mu_r=mu_r).transpose("friction_law", "aspect_ratio", "seed")
        _against_aspect_ratio(ax, ratios, span,
                              [(f"colsim, {name}", data.sel(friction_law=name).values,
                                {flag: value.sel(friction_law=name).values for flag, value in flags.items()})
                               for name in comparison["friction_law"].values], geometry=geometry)
        ax.set_ylabel(_label(comparison[variable], variable))
    fig.suptitle(f"friction laws, {_size(comparison)}, mu_r = {mu_r:g}", fontsize=10)
    return _save(fig, path)


def mu_r_figure(summary, path: Path) -> Path:
    """h_inf/r0 and run-out against mu_r, one colour per aspect ratio (mean over seeds, bars as in
    :func:`_against_aspect_ratio`), Lube's law for each a as a dashed line of its colour (the laws do
    not depend on mu_r), flagged points as :func:`_draw_flags` draws them; one legend for both panels."""
    from matplotlib.lines import Line2D

    plt = _pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(10, 4), layout="constrained")
    geometry = geometry_of(summary.attrs)
    reference = REFERENCE[geometry]
    mu_r = summary["mu_r"].values
    ratios = summary["aspect_ratio"].values
    colours = _colours(len(ratios))
    variables = ("h_inf_over_r0", "runout_over_r0")
    kind, fewest, most = _bar_kind(*(summary[v].values for v in variables))
    flags = {name: flag.transpose("aspect_ratio", "mu_r").values for name, flag in _flags_of(summary).items()}
    for ax, variable in zip(axes, variables):
        data = summary[variable].transpose("aspect_ratio", "mu_r", "seed")
        for k, a in enumerate(ratios):
            law = float(laws_for(geometry)[variable][reference](a))
            if np.isfinite(law):
                ax.axhline(law, color=colours[k], ls="--", lw=1.0, label=f"{reference}, a = {a:g}")
            mean, low, high = _bars(data.isel(aspect_ratio=k).values, kind)
            ax.errorbar(mu_r, mean, yerr=[low, high], fmt="o-", color=colours[k], ms=5, capsize=3, label=f"a = {a:g}")
            _draw_flags(ax, mu_r, mean, {name: flag[k] for name, flag in flags.items()}, colours[k], "o", ms=5)
        ax.set_xlabel("rolling resistance coefficient $\\mu_r$")
        ax.set_ylabel(_label(summary[variable], variable))
        ax.set_ylim(bottom=min(0.0, ax.get_ylim()[0]))   # from 0, unless a run-out is below it
        ax.grid(alpha=0.3)
    handles = [Line2D([], [], color=colours[k], marker="o", ms=5, label=f"a = {a:g}") for k, a in enumerate(ratios)]
    handles += [Line2D([], [], color="0.3", marker="o", ms=5, label="colsim"),
                Line2D([], [], color="0.3", ls="--", label=f"{reference}\n(independent of $\\mu_r$)")]
    handles += _flag_handles(flags)
    fig.legend(handles=handles, loc="outside right upper", fontsize=8, title=_bar_note(kind, fewest, most),
               title_fontsize=8)
    return _save(fig, path)
