"""The figures of single runs: deposit_profiles.png (deposit height against distance from the axis,
one panel per a, one line per mu_r, the lowest seed, bins drawn edge to edge), side_views.png (the
particles in a slab |y| < d_max from the side before release and at the end, coloured by their
initial height over h0: the paper's Figs. 3-5) and front_position.png (the front against
t/sqrt(h0/g), one column per mu_r, one colour per a; top row the radius holding 95 % of the mass,
bottom row the farthest the main mass's edge has reached so far)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ...io.netcdf import AT_REST_FLAGS
from ...stages.analyse import FRONT_MASS_SHARE, FRONT_MASS_VARIABLE, column_length, geometry_of
from ..collect import FLAGS, one_run, run_status
from .style import _by_key, _colours, _empty, _grid, _pyplot, _save


def _axis_names(run) -> tuple[str, str]:
    """(the run's length scale, its distance along the spread): ("r0", "r") for a cylinder, ("L0",
    "x") for a channel, whose distances run from the back wall."""
    return ("L0", "x") if geometry_of(run.attrs) == "channel" else ("r0", "r")


def _bin_edges(centres) -> np.ndarray:
    """The edges of equal radial bins from their centres (the first bin starts on the axis when its
    centre is half a width out, as colsim.stages.analyse.deposit_profile makes them)."""
    centres = np.asarray(centres, dtype=float)
    width = centres[1] - centres[0] if len(centres) > 1 else 2.0 * centres[0]
    return np.r_[centres - width / 2, centres[-1:] + width / 2]


def deposit_profile_figure(analyses, path: Path) -> Path:
    """Deposit height / r0 against r / r0 (a channel's: / L0 against x / L0 from the back wall): one
    panel per a, one line per mu_r, the lowest seed; each bin drawn over its whole width, from the
    first (at the axis) to the last; a run that :func:`colsim.study.collect.run_status` flags is
    dashed and its legend entry says why."""
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
            r0 = column_length(run.attrs)
            edges = _bin_edges(run["radial_bin"].values)
            height = run["deposit_height"].values
            flagged = [FLAGS[name] for name, flag in run_status(one_run(run)).items() if flag]
            ax.step(edges / r0, np.r_[height, height[-1:]] / r0, where="post", ls="--" if flagged else "-",
                    label=f"$\\mu_r$ = {m:g}" + (f" ({', '.join(flagged)})" if flagged else ""))
        ax.axhline(a, color="0.6", lw=0.8, ls=":")
        ax.axvline(1.0, color="0.6", lw=0.8, ls=":")
        ax.set_title(f"a = {a:g}", fontsize=9)
        scale, along = _axis_names(next(iter(chosen.values())))
        ax.set_xlabel(f"{along} / {scale}")
        ax.set_ylabel(f"deposit height / {scale}")
        ax.set_xlim(left=0)
        ax.set_ylim(bottom=0)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)   # each panel's: the flags differ from run to run
    return _save(fig, path)


def _slab(run, frame):
    """(x/r0, z/r0, R/r0, initial height/h0) of the particles with |y| < d_max in one frame (r0: a
    channel's L0)."""
    r0, h0 = column_length(run.attrs), float(run.attrs["h0"])
    radius = run["radius"].values
    position = run["position"].isel(time=frame).values
    inside = np.abs(position[:, 1]) < 2.0 * float(radius.max())
    return (position[inside, 0] / r0, position[inside, 2] / r0, radius[inside] / r0,
            run["initial_height"].values[inside] / h0)


def _end_name(trajectory) -> str:
    """"deposit" for the last frame of a run at rest, "end (still moving)" for one that
    :func:`colsim.study.collect.run_status` calls moving; "end" when it cannot tell (rest not checked
    and no step energies)."""
    run = one_run(trajectory)
    if int(run.at_rest) == AT_REST_FLAGS["not_checked"] and "final_to_peak_kinetic_energy" not in run:
        return "end"
    return "end (still moving)" if bool(run_status(run)["moving"]) else "deposit"


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
            ax.set_xlim(0 if geometry_of(run.attrs) == "channel" else -limit, limit)
            ax.set_ylim(0, top)
            ax.set_aspect("equal")
            time = float(run["scaled_time"].values[frame])
            ax.set_title(f"a = {a:g}, $\\mu_r$ = {m:g}, seed {seed}: {when}, t/$\\sqrt{{h_0/g}}$ = {time:.2f}",
                         fontsize=8)
            ax.set_ylabel(f"z / {_axis_names(run)[0]}")
    for ax in axes[-1]:
        ax.set_xlabel(f"x / {_axis_names(runs[-1][1])[0]}")
    fig.colorbar(collection, ax=axes, shrink=0.8, label="initial height / h0")
    return _save(fig, path)


def outward_front(front) -> np.ndarray:
    """The farthest a front has reached so far (running maximum, NaN frames skipped): it never moves back."""
    front = np.asarray(front, dtype=float)
    return np.fmax.accumulate(front) if front.size else front


#: the front_position figure's rows: the analysis variable, the y label ({r}, {r0}: the run's distance
#: along the spread and its length scale, _axis_names), whether to draw its running maximum
FRONT_ROWS = {
    FRONT_MASS_VARIABLE: (f"front ({{r}}_{FRONT_MASS_SHARE * 100:.0f} - {{r0}}) / {{r0}}\n"
                          f"(distance holding {FRONT_MASS_SHARE:.0%} of the mass)", False),
    "front_position": ("front ({r}_front - {r0}) / {r0}\n(farthest reach of the main mass so far)", True),
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
    # one y scale along each row, so that the mu_r panels compare at a glance
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
            scale, along = _axis_names(runs[keys[0]])
            ax.set_ylabel(label.format(r=along, r0=scale), fontsize=8)
            ax.grid(alpha=0.3)
    height = "H0" if runs and _axis_names(next(iter(runs.values())))[0] == "L0" else "h0"
    for ax in axes[-1]:
        ax.set_xlabel(f"t / sqrt({height}/g)")
    handles = axes.flat[0].get_legend_handles_labels()[0]
    if any(line.get_gid() == "end" for ax in axes.flat for line in ax.get_lines()):
        from matplotlib.lines import Line2D

        handles.append(Line2D([], [], marker="o", mfc="none", color="0.3", ls="none",
                              label="run-out at the end, where the\nfinal main mass is behind the front"))
    if handles:
        fig.legend(handles=handles, loc="outside right upper", fontsize=7)
    return _save(fig, path)
