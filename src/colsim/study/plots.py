"""The study's comparison figures (PNG), from the collected summary, analyses and trajectories.

:func:`all_figures` writes the files named in :data:`FIGURES` into one directory:

- final_height.png: h_inf/r0 against a, one marker per mu_r (mean over seeds; bars: the standard error
  of the mean with 3 seeds or more, the lowest to the highest seed with 2, as the legend says), with
  the laws of Lube et al. and Lajeunesse et al. (the paper's Fig. 6). The frame fits the data and
  Lube's laws; a law that would squeeze them (Lajeunesse's height law as printed, 0.74 a) leaves it,
  and a note under the axes says where;
- runout.png: (r_inf - r0)/r0 against a, the same way (the paper's Fig. 7);
- mu_r_effect.png: both quantities against mu_r, one colour per a, Lube's laws (which do not depend on
  mu_r) as dashed lines in the same colour, one legend for both panels;
- deposit_profiles.png: deposit height against distance from the axis, one panel per a, one line
  per mu_r (the lowest seed), bins drawn from edge to edge (the first from the axis);
- side_views.png: the particles in a slab |y| < d_max seen from the side before release and at the
  end, coloured by their initial height over h0 (the paper's Figs. 3-5), one row per trajectory;
- front_position.png: the front against t/sqrt(h0/g), one column per mu_r, one colour per a; top
  row: (r_95 - r0)/r0, the radius holding 95 % of the mass at each frame (the analysis's
  mass_front_95_over_r0), which moves outward as the grains spread; bottom row: (r_front - r0)/r0,
  the farthest the main mass's edge has reached so far (the running maximum of front_position: the
  main mass, the largest cluster, can shrink and its edge recede). Analyses made before the mass
  front existed get the bottom row only.

In the figures against a and against mu_r, a point whose runs :func:`colsim.study.collect.run_flags` flags
is drawn distinctly, with a legend entry: an open marker where a seed was still moving at the end, a
black cross where a seed's main mass holds less than half the grains.

matplotlib is imported inside the functions (Agg back-end), so colsim imports without it. Every
function takes xarray Datasets as colsim writes them and tolerates missing runs (NaN in the summary)
and sweeps of a single value.
"""
from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from ..io.netcdf import AT_REST_FLAGS, at_rest_flag
from ..stages.analyse import FRONT_MASS_SHARE, FRONT_MASS_VARIABLE
from .collect import FLAGS, means_per_size, run_flags
from .figure_names import FIGURES  # noqa: F401 - the figures all_figures writes
from .experimental_laws import (LAJEUNESSE_BREAK, LAWS, LUBE_HEIGHT_BREAK, LUBE_RUNOUT_BREAK, final_values, lube_height,
                   lube_runout)

log = logging.getLogger(__name__)


MARKERS = "osD^vP*X<>"
QUANTITY_LABELS = {"h_inf_over_r0": "$h_\\infty/r_0$", "runout_over_r0": "$(r_\\infty - r_0)/r_0$"}
BREAKPOINTS = (LAJEUNESSE_BREAK, LUBE_HEIGHT_BREAK, LUBE_RUNOUT_BREAK)
LAW_STYLES = ("-", "--", ":", "-.")
LUBE = "Lube et al. (2004)"
LUBE_LAWS = {"h_inf_over_r0": lube_height, "runout_over_r0": lube_runout}
STANDARD_ERROR_SEEDS = 3
"""From this many seeds on, error bars are the standard error of the mean; below, the range."""
SQUEEZE = 2.0
"""A law whose curve rises above SQUEEZE times the top of the data and Lube's laws would squeeze them:
it leaves the frame (Lajeunesse's height law as printed, 0.74 a, reaches 4.1 at a = 5.5 where the
heights are about 1)."""


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _label(variable, fallback: str) -> str:
    """An axis label from a variable's long_name and units (units "1" are left out)."""
    name = variable.attrs.get("long_name", fallback) if variable is not None else fallback
    units = variable.attrs.get("units", "1") if variable is not None else "1"
    return name if units in ("1", "") else f"{name} [{units}]"


def _save(fig, path: Path) -> Path:
    from ..io.netcdf import atomic_path

    with atomic_path(path) as tmp:   # a killed plot leaves no PNG that looks finished
        fig.savefig(tmp, format="png", dpi=120, bbox_inches="tight")
    _pyplot().close(fig)
    log.info("wrote %s", path)
    return path


def _seed_spread(values):
    """(mean, lower error, upper error) over the last axis, ignoring NaN (missing seeds)."""
    import warnings

    values = np.asarray(values, dtype=float)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN rows: a run that is missing
        mean = np.nanmean(values, axis=-1)
        low = mean - np.nanmin(values, axis=-1)
        high = np.nanmax(values, axis=-1) - mean
    return mean, np.nan_to_num(low), np.nan_to_num(high)


def _bar_kind(*arrays) -> tuple[str, int, int]:
    """("se" or "range", fewest, most seeds) over the points of `arrays` (each (..., seed)) that have
    a run: "se" when every such point has STANDARD_ERROR_SEEDS seeds or more."""
    counts = np.concatenate([np.isfinite(np.asarray(v, dtype=float)).sum(axis=-1).ravel() for v in arrays])
    counts = counts[counts > 0]
    fewest, most = (int(counts.min()), int(counts.max())) if counts.size else (0, 0)
    return ("se" if fewest >= STANDARD_ERROR_SEEDS else "range"), fewest, most


def _bars(values, kind: str):
    """(mean, lower error, upper error) over the last axis, ignoring NaN: the standard error of the
    mean (sample sd / sqrt(n)) on both sides for kind "se", the spread to the lowest and the highest
    seed for "range"."""
    import warnings

    mean, low, high = _seed_spread(values)
    if kind == "se":
        values = np.asarray(values, dtype=float)
        n = np.isfinite(values).sum(axis=-1)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            error = np.nanstd(values, axis=-1, ddof=1) / np.sqrt(n)
        low = high = np.nan_to_num(error)
    return mean, low, high


def _bar_note(kind: str, fewest: int, most: int) -> str:
    """What the error bars are, for a legend's title."""
    seeds = f"{fewest}" if fewest == most else f"{fewest}-{most}"
    if most <= 1:
        return f"{seeds} seed: no error bars"
    if kind == "se":
        return f"mean of {seeds} seeds, bars: standard error"
    return f"mean of {seeds} seeds, bars: lowest to highest seed"


def _flags_of(summary) -> dict:
    """{flag: bool array over the summary's other dimensions}: any seed of the point flagged."""
    return {name: flag.any("seed") if "seed" in flag.dims else flag for name, flag in run_flags(summary).items()}


def _draw_flags(ax, x, y, flags: dict, colour, marker: str, ms: float = 6) -> None:
    """Over the markers (x, y) already drawn: open markers where flags["moving"], a black cross where
    flags["fragment"]."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    moving, fragment = (np.asarray(flags.get(name, np.zeros(len(x), bool)), bool) for name in ("moving", "fragment"))
    if moving.any():
        ax.plot(x[moving], y[moving], marker, ls="none", ms=ms, color=colour, mfc="white", zorder=3,
                label="_flag moving")
    if fragment.any():
        ax.plot(x[fragment], y[fragment], "x", ls="none", ms=ms + 1, mew=1.3, color="k", zorder=4,
                label="_flag fragment")


def _flag_handles(flags: dict) -> list:
    """Legend entries for the flags that are set anywhere in `flags` ({flag: bool array})."""
    from matplotlib.lines import Line2D

    handles = []
    if np.any(flags.get("moving", False)):
        handles.append(Line2D([], [], marker="o", ls="none", mfc="white", mec="0.3",
                              label=f"open: a seed {FLAGS['moving']} at the end"))
    if np.any(flags.get("fragment", False)):
        handles.append(Line2D([], [], marker="x", ls="none", color="k", mew=1.3,
                              label=f"cross: a seed's {FLAGS['fragment']}"))
    return handles


def _law_abscissa(end: float):
    """Values of a from 0 to `end`, with NaN at the laws' breakpoints so the jumps are not drawn as lines."""
    edges = sorted({0.0, end, *(b for b in BREAKPOINTS if b < end)})
    pieces = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        pieces += [np.linspace(lo, hi - 1e-9 * (hi < end), 100), [np.nan]]
    return np.concatenate(pieces[:-1])


def _against_aspect_ratio(ax, ratios, span, series, outside: bool = False) -> float:
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
    ax.set_xlabel("aspect ratio a = h0/r0")
    ax.set_xlim(0, span[-1])
    ax.set_ylim(bottom=0.0 if bottom >= 0 else 1.1 * bottom)   # a run-out below 0: a main mass inside r0
    ax.grid(alpha=0.3)
    handles, _ = ax.get_legend_handles_labels()
    handles += _flag_handles({name: np.concatenate([np.ravel(f[name]) for _, _, f in series])
                              for name in FLAGS})
    where = {"loc": "upper left", "bbox_to_anchor": (1.02, 1.0)} if outside else {}
    ax.legend(handles=handles, fontsize=7, title=_bar_note(kind, fewest, most), title_fontsize=7, **where)
    return float(top)


def _fit_laws(ax, span, laws: dict, top: float, variable: str) -> None:
    """Set the top of `ax` to hold the data (up to `top`) and Lube's law; a law rising above SQUEEZE
    times that is left outside the frame, with a note under the axes saying from where."""
    values = {name: np.asarray(law(span), dtype=float) for name, law in laws.items()}
    base = np.nanmax([top, *(np.nanmax(v, initial=0.0) for n, v in values.items() if n == LUBE)])
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
    """`variable` (h_inf_over_r0 or runout_over_r0) against a: markers per mu_r, laws as curves."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(5.5, 4.2))
    ratios = summary["aspect_ratio"].values
    span = _law_abscissa(max(float(np.max(ratios)) * 1.1, 1.0))
    for (name, law), style in zip(LAWS[variable].items(), LAW_STYLES):
        ax.plot(span, law(span), style, color="0.35", lw=1.2, label=name)
    data = summary[variable].transpose("aspect_ratio", "mu_r", "seed")
    flags = {name: flag.transpose("aspect_ratio", "mu_r").values for name, flag in _flags_of(summary).items()}
    top = _against_aspect_ratio(ax, ratios, span,
                                [(f"colsim, $\\mu_r$ = {mu_r:g}", data.isel(mu_r=k).values,
                                  {name: flag[:, k] for name, flag in flags.items()})
                                 for k, mu_r in enumerate(summary["mu_r"].values)], outside=True)
    _fit_laws(ax, span, LAWS[variable], top, variable)
    ax.set_ylabel(_label(summary[variable], variable))
    ax.set_title(f"r0 = {summary.attrs.get('r0', float('nan')):g}, mu = {summary.attrs.get('mu', float('nan')):g}, "
                 f"{summary.sizes['seed']} seed(s)", fontsize=9)
    return _save(fig, path)


def friction_law_figure(comparison, path: Path) -> Path:
    """h_inf/r0 and the run-out against a under each friction law (mean over seeds, bars as in
    :func:`_against_aspect_ratio`), at the comparison's first mu_r, with Lube's laws drawn."""
    plt = _pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.2), layout="constrained")
    ratios = comparison["aspect_ratio"].values
    span = _law_abscissa(max(float(np.max(ratios)) * 1.1, 1.0))
    mu_r = float(comparison["mu_r"].values[0])
    flags = {name: flag.sel(mu_r=mu_r).transpose("friction_law", "aspect_ratio")
             for name, flag in _flags_of(comparison).items()}
    for ax, variable in zip(axes, ("h_inf_over_r0", "runout_over_r0")):
        ax.plot(span, LAWS[variable][LUBE](span), "-", color="0.35", lw=1.2, label=LUBE)
        data = comparison[variable].sel(mu_r=mu_r).transpose("friction_law", "aspect_ratio", "seed")
        _against_aspect_ratio(ax, ratios, span,
                              [(f"colsim, {name}", data.sel(friction_law=name).values,
                                {flag: value.sel(friction_law=name).values for flag, value in flags.items()})
                               for name in comparison["friction_law"].values])
        ax.set_ylabel(_label(comparison[variable], variable))
    fig.suptitle(f"friction laws, r0 = {comparison.attrs.get('r0', float('nan')):g}, mu_r = {mu_r:g}", fontsize=10)
    return _save(fig, path)


def _colours(n: int) -> list:
    """n colours that read on white: tab10's, then tab20's (no pale yellow)."""
    plt = _pyplot()
    palette = list(plt.cm.tab10.colors) + [c for k, c in enumerate(plt.cm.tab20.colors) if k % 2]
    return [palette[k % len(palette)] for k in range(n)]


def mu_r_figure(summary, path: Path) -> Path:
    """h_inf/r0 and run-out against mu_r, one colour per aspect ratio (mean over seeds, bars as in
    :func:`_against_aspect_ratio`), Lube's law for each a as a dashed line of its colour (the laws do
    not depend on mu_r), flagged points as :func:`_draw_flags` draws them; one legend for both panels."""
    from matplotlib.lines import Line2D

    plt = _pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(10, 4), layout="constrained")
    mu_r = summary["mu_r"].values
    ratios = summary["aspect_ratio"].values
    colours = _colours(len(ratios))
    variables = ("h_inf_over_r0", "runout_over_r0")
    kind, fewest, most = _bar_kind(*(summary[v].values for v in variables))
    flags = {name: flag.transpose("aspect_ratio", "mu_r").values for name, flag in _flags_of(summary).items()}
    for ax, variable in zip(axes, variables):
        data = summary[variable].transpose("aspect_ratio", "mu_r", "seed")
        for k, a in enumerate(ratios):
            law = float(LUBE_LAWS[variable](a))
            if np.isfinite(law):
                ax.axhline(law, color=colours[k], ls="--", lw=1.0, label=f"{LUBE}, a = {a:g}")
            mean, low, high = _bars(data.isel(aspect_ratio=k).values, kind)
            ax.errorbar(mu_r, mean, yerr=[low, high], fmt="o-", color=colours[k], ms=5, capsize=3, label=f"a = {a:g}")
            _draw_flags(ax, mu_r, mean, {name: flag[k] for name, flag in flags.items()}, colours[k], "o", ms=5)
        ax.set_xlabel("rolling resistance coefficient $\\mu_r$")
        ax.set_ylabel(_label(summary[variable], variable))
        ax.set_ylim(bottom=min(0.0, ax.get_ylim()[0]))   # from 0, unless a run-out is below it
        ax.grid(alpha=0.3)
    handles = [Line2D([], [], color=colours[k], marker="o", ms=5, label=f"a = {a:g}") for k, a in enumerate(ratios)]
    handles += [Line2D([], [], color="0.3", marker="o", ms=5, label="colsim"),
                Line2D([], [], color="0.3", ls="--", label=f"{LUBE}\n(independent of $\\mu_r$)")]
    handles += _flag_handles(flags)
    fig.legend(handles=handles, loc="outside right upper", fontsize=8, title=_bar_note(kind, fewest, most),
               title_fontsize=8)
    return _save(fig, path)


def _by_key(datasets):
    """{(aspect_ratio, mu_r, seed): dataset}."""
    return {(float(d.attrs["aspect_ratio"]), float(d.attrs["mu_r"]), int(d.attrs.get("seed", 0))): d
            for d in datasets}


def _empty(ax, text: str):
    ax.text(0.5, 0.5, text, ha="center", va="center", transform=ax.transAxes)
    ax.set_axis_off()


def _grid(plt, n: int, width: float, height: float):
    columns = min(n, 3)
    rows = max(1, int(np.ceil(n / columns)))
    fig, axes = plt.subplots(rows, columns, figsize=(width * columns, height * rows), squeeze=False,
                             layout="constrained")
    for ax in axes.flat[n:]:
        ax.set_axis_off()
    return fig, axes.flat


def _bin_edges(centres) -> np.ndarray:
    """The edges of equal radial bins from their centres (the first bin starts on the axis when its
    centre is half a width out, as colsim.stages.analyse.deposit_profile makes them)."""
    centres = np.asarray(centres, dtype=float)
    width = centres[1] - centres[0] if len(centres) > 1 else 2.0 * centres[0]
    return np.r_[centres - width / 2, centres[-1:] + width / 2]


def _analysis_flags(run) -> dict:
    """{flag: bool} of one analysis, as :func:`colsim.study.collect.run_flags` flags a run ({} when the
    analysis lacks h_inf_over_r0)."""
    import json

    import xarray as xr

    if "h_inf_over_r0" not in run:
        return {}
    names = ("h_inf_over_r0", "final_to_peak_kinetic_energy", "n_main_mass", "n_particles")
    one = xr.Dataset({name: run[name] for name in names if name in run},
                     attrs={"run_configs": json.dumps([json.loads(run.attrs.get("config", "{}"))])})
    one["at_rest"] = at_rest_flag(run)
    return {name: bool(flag) for name, flag in run_flags(one).items()}


def deposit_profile_figure(analyses, path: Path) -> Path:
    """Deposit height / r0 against r / r0: one panel per a, one line per mu_r, the lowest seed; each
    bin drawn over its whole width, from the first (at the axis) to the last; a run that
    :func:`colsim.study.collect.run_flags` flags is dashed and its legend entry says why."""
    plt = _pyplot()
    runs = _by_key(analyses)
    ratios = sorted({a for a, _, _ in runs}) or [np.nan]
    mu_rs = sorted({m for _, m, _ in runs})
    fig, axes = _grid(plt, len(ratios), 4.2, 3.2)
    for ax, a in zip(axes, ratios):
        chosen = {m: runs[min(k for k in runs if k[:2] == (a, m))] for m in mu_rs if any(k[:2] == (a, m) for k in runs)}
        if not chosen:
            _empty(ax, "no analyses")
            continue
        for m, run in chosen.items():
            r0 = float(run.attrs["r0"])
            edges = _bin_edges(run["radial_bin"].values)
            height = run["deposit_height"].values
            flagged = [FLAGS[name] for name, flag in _analysis_flags(run).items() if flag]
            ax.step(edges / r0, np.r_[height, height[-1:]] / r0, where="post", ls="--" if flagged else "-",
                    label=f"$\\mu_r$ = {m:g}" + (f" ({', '.join(flagged)})" if flagged else ""))
        ax.axhline(a, color="0.6", lw=0.8, ls=":")
        ax.axvline(1.0, color="0.6", lw=0.8, ls=":")
        ax.set_title(f"a = {a:g}", fontsize=9)
        ax.set_xlabel("r / r0")
        ax.set_ylabel("deposit height / r0")
        ax.set_xlim(left=0)
        ax.set_ylim(bottom=0)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)   # each panel's: the flags differ from run to run
    return _save(fig, path)


def _slab(run, frame):
    """(x/r0, z/r0, R/r0, initial height/h0) of the particles with |y| < d_max in one frame."""
    r0, h0 = float(run.attrs["r0"]), float(run.attrs["h0"])
    radius = run["radius"].values
    position = run["position"].isel(time=frame).values
    inside = np.abs(position[:, 1]) < 2.0 * float(radius.max())
    return (position[inside, 0] / r0, position[inside, 2] / r0, radius[inside] / r0,
            run["initial_height"].values[inside] / h0)


def _end_name(trajectory) -> str:
    """"deposit" for the last frame of a run at rest, "end (still moving)" otherwise (as
    :func:`colsim.study.collect.run_flags` decides: at_rest 0, or with a fixed end time, no at_rest, the
    kinetic energy at the end above the run's rest_energy of its peak); "end" when it cannot tell."""
    import json

    from .collect import rest_energy

    flag = at_rest_flag(trajectory)
    if flag != AT_REST_FLAGS["not_checked"]:
        return "deposit" if flag == AT_REST_FLAGS["at_rest"] else "end (still moving)"
    if "step_kinetic_energy" not in trajectory:
        return "end"
    energy = trajectory["step_kinetic_energy"].values
    if "step_rotational_energy" in trajectory:
        energy = energy + trajectory["step_rotational_energy"].values
    limit = rest_energy([json.loads(trajectory.attrs.get("config", "{}"))])
    return "end (still moving)" if energy.size and energy[-1] > limit * np.max(energy) else "deposit"


def side_view_figure(trajectories, path: Path) -> Path:
    """Slab |y| < d_max seen from the side, before release and at the end, coloured by initial height / h0.

    Discs are drawn at the particles' true size (a cut through the middle of a sphere), so the
    packing looks as in the paper's Figs. 3-5.
    """
    plt = _pyplot()
    from matplotlib.collections import EllipseCollection

    runs = sorted(_by_key(trajectories).items())
    if not runs:
        fig, ax = plt.subplots(figsize=(6, 2))
        _empty(ax, "no trajectories")
        return _save(fig, path)
    views = [[_slab(run, 0), _slab(run, -1)] for _, run in runs]
    limits = [max(1.0, *(float(np.max(np.abs(x) + r, initial=0.0)) for x, _, r, _ in row)) * 1.05 for row in views]
    tops = [max(0.5, float(np.max(z + r, initial=0.0))) * 1.1 for row in views for (_, z, r, _) in row[:1]]
    ratios = [top / (2 * limit) for top, limit in zip(tops, limits)]
    fig, axes = plt.subplots(len(runs), 2, figsize=(11, 0.9 + 5.0 * sum(ratios) + 0.35 * len(runs)),
                             squeeze=False, gridspec_kw={"height_ratios": ratios})
    collection = None
    for row, ((a, m, seed), run), view, limit, top in zip(axes, runs, views, limits, tops):
        for ax, frame, (x, z, r, colour), when in zip(row, (0, -1), view, ("before release", _end_name(run))):
            collection = EllipseCollection(2 * r, 2 * r, np.zeros_like(r), units="xy", offsets=np.c_[x, z],
                                           offset_transform=ax.transData, cmap="viridis", linewidths=0)
            collection.set_array(colour)
            collection.set_clim(0, 1)
            ax.add_collection(collection)
            ax.set_xlim(-limit, limit)
            ax.set_ylim(0, top)
            ax.set_aspect("equal")
            time = float(run["scaled_time"].values[frame])
            ax.set_title(f"a = {a:g}, $\\mu_r$ = {m:g}, seed {seed}: {when}, t/$\\sqrt{{h_0/g}}$ = {time:.2f}",
                         fontsize=8)
            ax.set_ylabel("z / r0")
    for ax in axes[-1]:
        ax.set_xlabel("x / r0")
    fig.colorbar(collection, ax=axes, shrink=0.8, label="initial height / h0")
    return _save(fig, path)


def outward_front(front) -> np.ndarray:
    """The farthest a front has reached so far (running maximum, NaN frames skipped): it never moves back."""
    front = np.asarray(front, dtype=float)
    return np.fmax.accumulate(front) if front.size else front


#: the front_position figure's rows: the analysis variable, the y label, whether to draw its running maximum
FRONT_ROWS = {
    FRONT_MASS_VARIABLE: (f"front (r_{FRONT_MASS_SHARE * 100:.0f} - r0) / r0\n"
                          f"(radius holding {FRONT_MASS_SHARE:.0%} of the mass)", False),
    "front_position": ("front (r_front - r0) / r0\n(farthest reach of the main mass so far)", True),
}


def front_figure(analyses, path: Path) -> Path:
    """The front against t/sqrt(h0/g): one column of panels per mu_r (one y scale along a row), one
    colour per a, one line per seed. Top row (when the analyses have it): the radius holding 95 % of the mass, frame by frame
    (FRONT_MASS_VARIABLE: every grain counts, no contact graph); it moves outward as the grains
    spread. Bottom row: :func:`outward_front` of the main mass's edge (front_position), the run-out's
    own measure, with an open circle at the end where the final main mass is behind that front."""
    plt = _pyplot()
    runs = _by_key(analyses)
    mu_rs = sorted({m for _, m, _ in runs}) or [np.nan]
    ratios = sorted({a for a, _, _ in runs})
    colours = dict(zip(ratios, _colours(len(ratios))))
    rows = [name for name in FRONT_ROWS if name == "front_position" or any(name in run for run in runs.values())]
    # one y scale along each row, so that the mu_r panels compare at a glance (issue 48.6)
    fig, axes = plt.subplots(len(rows), len(mu_rs), figsize=(4.2 * len(mu_rs), 3.2 * len(rows)), squeeze=False,
                             layout="constrained", sharex="col", sharey="row")
    for row, name in zip(axes, rows):
        label, outward = FRONT_ROWS[name]
        for ax, m in zip(row, mu_rs):
            keys = sorted(k for k in runs if k[1] == m and name in runs[k])
            if not keys:
                _empty(ax, "no analyses")
                continue
            labelled = set()
            for a, _, seed in keys:
                run = runs[(a, m, seed)]
                time, front = run["scaled_time"].values, run[name].values
                ax.plot(time, outward_front(front) if outward else front, color=colours[a], lw=1.2,
                        label=None if a in labelled else f"a = {a:g}")
                if outward and len(front) and np.isfinite(front[-1]) and front[-1] < np.nanmax(front):
                    ax.plot(time[-1:], front[-1:], "o", mfc="none", color=colours[a], ms=5, gid="end")
                labelled.add(a)
            ax.set_title(f"$\\mu_r$ = {m:g}", fontsize=9)
            ax.set_ylabel(label, fontsize=8)
            ax.grid(alpha=0.3)
    for ax in axes[-1]:
        ax.set_xlabel("t / sqrt(h0/g)")
    handles = axes.flat[0].get_legend_handles_labels()[0]
    if any(line.get_gid() == "end" for ax in axes.flat for line in ax.get_lines()):
        from matplotlib.lines import Line2D

        handles.append(Line2D([], [], marker="o", mfc="none", color="0.3", ls="none",
                              label="run-out at the end, where the\nfinal main mass is behind the front"))
    if handles:
        fig.legend(handles=handles, loc="outside right upper", fontsize=7)
    return _save(fig, path)


def all_figures(summary, analyses, trajectories, output_dir) -> list[Path]:
    """Write every figure of :data:`FIGURES` into `output_dir` (created); return their paths."""
    output_dir = Path(output_dir)
    output_dir.mkdir(parents=True, exist_ok=True)
    analyses, trajectories = list(analyses), list(trajectories)
    draw = {"final_height": lambda path: law_figure(summary, "h_inf_over_r0", path),
            "runout": lambda path: law_figure(summary, "runout_over_r0", path),
            "mu_r_effect": lambda path: mu_r_figure(summary, path),
            "deposit_profiles": lambda path: deposit_profile_figure(analyses, path),
            "side_views": lambda path: side_view_figure(trajectories, path),
            "front_position": lambda path: front_figure(analyses, path)}
    return [draw[name](output_dir / f"{name}.png") for name in FIGURES]


def _time_step_panel(ax, part) -> None:
    """h_inf/r0 (filled) and the run-out (open) against dt/sqrt(h0/g), mean over seeds, sd as bars."""
    from .convergence import time_step_means

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
