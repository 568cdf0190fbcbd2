# The channel study's answer (docs/validation/channel.md) from its runs. From the repository root:
#   python docs/data/channel_tables.py [--figures docs/figures]
# It reads the runs, one row each, from docs/data/channel-runs.csv. For each sweep (a channel width and
# wall friction with runs over three a or more at the tables' box length L0 = 6; the study's walls,
# config/channel.yaml's wall_mu, first) it prints: the runs made against the study's plan (6 a by 2 mu_r
# a box length and seed) with their CPU; at L0 = 6, the run-outs (L_inf - L0)/L0 and heights H_inf/L0
# (the mean over the seeds, with a 95 % Student interval from two seeds on; "stood" where the mean
# run-out is under one mean diameter) beside Lube et al.'s and Lajeunesse et al.'s (2005) laws, the
# misfit to Lube et al. (2005) at each mu_r, and the exponents fitted over every run against Balmforth &
# Kerswell's (colsim.study.channel); and the run-outs by box length with the spread between the two
# largest. Then the boxes of the study's shape (W = L0/3, as W = 2 at L0 = 6) at each length with the
# study's walls, their run-outs by box length; the runs with other walls, each beside the runs of the
# same packing, a and mu_r; and the runs at another time step than the study's 1,000 steps to
# t/sqrt(H0/g) = 4, beside the same columns at 1,000 (the mean relative difference over seeds, with its
# paired 95 % Student interval). With --figures it draws each sweep's run-outs and heights against the laws at L0 = 6
# (colsim.study.figures.laws.law_figure) into that folder.
#   python docs/data/channel_tables.py --from-analyses results/r0_*/seed_*/pack_*/a_*/mu_r_*/run_*/analysis_*.nc
# writes their runs into that CSV first (any number of results folders), with each run's collapse and pour
# CPU time (the collapse.nc beside the analysis, its packing.nc); a run already there is replaced, the
# CSV's other runs are kept.
from pathlib import Path

import numpy as np
import xarray as xr
from scipy.stats import t as student_t

from colsim.study.channel import (exponents_markdown, length_convergence, length_convergence_markdown,
                                  paired_difference, stood)
from colsim.study.collect import run_settings
from colsim.study.experimental_laws import final_values
from runs_csv import main, read_rows, run_costs, write_rows

HERE = Path(__file__).parent
RUNS = HERE / "channel-runs.csv"
TABLE_LENGTH = 6.0                 #: the box length of the answer's tables (config/channel.yaml's channel_length)
TABLE_WIDTH = 2.0                  #: config/channel.yaml's channel_width: boxes of its shape have W = L0/3
STUDY_WALL_MU = 0.577              #: config/channel.yaml's wall_mu
STUDY_STEPS = 1000                 #: config/channel.yaml's collapse steps to t/sqrt(H0/g) = 4 (the default)
PLANNED = 12                       #: runs a (width, L0, seed): a = 0.5, 1, 2, 3, 4, 5 at mu_r = 0.12 and 0.15
VARIABLES = (("runout_over_r0", "run-out"), ("h_inf_over_r0", "height"))
LONG_NAMES = {"runout_over_r0": "run-out (L_inf - L0) over the box length L0",      # as the analysis names them
              "h_inf_over_r0": "final height at the back wall over the box length L0"}
COLUMNS = ("channel_width", "mu", "wall_mu", "channel_length", "seed", "aspect_ratio", "mu_r", "steps",
           "runout_over_r0", "h_inf_over_r0", "at_rest", "n_particles", "mean_diameter", "collapse_cpu_time",
           "pour_cpu_time", "commit")
RUN = slice(0, COLUMNS.index("steps") + 1)   #: the columns that name a run: width, walls, L0, seed, a, mu_r, steps
INTEGERS = {"seed", "steps", "at_rest", "n_particles"}
RUNS_COMMENT = ("config/channel.yaml (W = 2), its slot (W = 0.75) and runs with other walls or time steps, one\n"
                "row a run: the analysis file's collapse steps to t/sqrt(H0/g) = 4, run-out (L_inf - L0)/L0,\n"
                "height at the back wall H_inf/L0, whether it came to rest, its spheres and their mean diameter,\n"
                "the CPU seconds of its collapse and its packing's pour, and the commit of its collapse; written\n"
                "by channel_tables.py. Machine: the 2-core AMD EPYC.")


def write_runs(paths) -> None:
    """The channel runs among the analysis files `paths` into RUNS, beside the runs RUNS holds already (a
    study's runs may come from several machines): a file's run replaces RUNS' row of the same run."""
    rows = []
    for path in paths:
        analysis = xr.load_dataset(path)
        attrs = analysis.attrs
        if attrs.get("geometry") == "channel":
            rows.append((float(attrs["channel_width"]), float(attrs["mu"]), float(attrs.get("wall_mu", attrs["mu"])),
                         float(attrs["channel_length"]), int(attrs["seed"]), float(attrs["aspect_ratio"]),
                         float(attrs["mu_r"]), int(run_settings(analysis)["collapse.steps"]),
                         float(analysis["runout_over_r0"]), float(analysis["h_inf_over_r0"]), int(analysis["at_rest"]),
                         int(analysis["n_particles"]), float(analysis["mean_diameter"]), *run_costs(path)))
    kept = [typed_row(row) for row in read_rows(RUNS)] if RUNS.exists() else []
    write_rows(RUNS, RUNS_COMMENT, COLUMNS, merged_runs(kept, rows))


def typed_row(row: dict) -> tuple:
    """A row of RUNS as read (text) as write_runs makes it: a tuple in COLUMNS' order, counts as int."""
    return tuple(row[name] if name == "commit" else int(row[name]) if name in INTEGERS else float(row[name])
                 for name in COLUMNS)


def merged_runs(kept, new) -> list:
    """The rows `kept` and `new`, one a run (its columns RUN), a row of `new` in place of a kept one of the
    same run; sorted by run."""
    rows = {row[RUN]: row for row in kept}
    rows.update((row[RUN], row) for row in new)
    return sorted(rows.values(), key=lambda row: row[RUN])


def _value(row, name: str) -> float:
    return float(row[name])


def summary(rows, ratios, mu_rs) -> xr.Dataset:
    """The runs `rows` (one width, walls and L0) as a study summary over (aspect_ratio, mu_r, seed)."""
    seeds = sorted({int(row["seed"]) for row in rows})
    names = [name for name, _ in VARIABLES] + ["at_rest", "mean_diameter"]
    data = {name: np.full((len(ratios), len(mu_rs), len(seeds)), np.nan) for name in names}
    for row in rows:
        at = (ratios.index(_value(row, "aspect_ratio")), mu_rs.index(_value(row, "mu_r")), seeds.index(int(row["seed"])))
        for name in names:
            data[name][at] = _value(row, name)
    first = rows[0]
    attrs = {"geometry": "channel", "mu": _value(first, "mu"), "channel_length": _value(first, "channel_length"),
             "channel_width": _value(first, "channel_width"), "wall_mu": _value(first, "wall_mu")}
    dims = ("aspect_ratio", "mu_r", "seed")
    return xr.Dataset({name: (dims, values, {"units": "1", "long_name": LONG_NAMES.get(name, name)})
                       for name, values in data.items()},
                      coords={"aspect_ratio": ratios, "mu_r": mu_rs, "seed": seeds}, attrs=attrs)


def mean_interval(values) -> str:
    """'mean [95 %]' over the seeds' values (Student's t; the mean alone for one seed)."""
    values = values[np.isfinite(values)]
    if len(values) < 2:
        return f"{values.mean():.3f} (1 seed)" if len(values) else "-"
    half = student_t.ppf(0.975, len(values) - 1) * values.std(ddof=1) / np.sqrt(len(values))
    return f"{values.mean():.3f} [{values.mean() - half:.3f}, {values.mean() + half:.3f}]"


def _mean(values) -> float:
    return float(np.nanmean(values)) if np.isfinite(values).any() else np.nan


def _error(value: float, law: float) -> str:
    return f"{value / law - 1:+.0%}" if np.isfinite(law) and np.isfinite(value) else "-"


def laws_table(table: xr.Dataset) -> list:
    """Each (mu_r, a): the run-out ("stood" where its mean is under one mean diameter) and the height,
    with each law's value and the runs' error against it."""
    standing_runouts = stood(table, table.runout_over_r0.mean("seed"))
    lines = ["| mu_r | a | run-out [95 %] | Lube 2005 | Lajeunesse 2005 | height [95 %] | Lube 2005 | Lajeunesse 2005 |",
             "|---|---|---|---|---|---|---|---|"]
    for m in table.mu_r.values:
        for a in table.aspect_ratio.values:
            cells = []
            for name, _ in VARIABLES:
                values = table[name].sel(mu_r=m, aspect_ratio=a).values
                standing = name == "runout_over_r0" and bool(standing_runouts.sel(mu_r=m, aspect_ratio=a))
                cells.append("stood" if standing else mean_interval(values))
                cells += [f"{law:.3f} ({_error(_mean(values), law)})" if np.isfinite(law) else "-"
                          for law in final_values(name, float(a), "channel").values()]
            lines.append(f"| {m:g} | {a:g} | " + " | ".join(cells) + " |")
    return lines


def misfit_lines(table: xr.Dataset) -> list:
    """Per mu_r: the root-mean-square relative error of the seeds' means against Lube et al. (2005), over
    the a where the law gives a value."""
    lines = []
    for m in table.mu_r.values:
        parts = []
        for name, label in VARIABLES:
            errors = []
            for a in table.aspect_ratio.values:
                law = final_values(name, float(a), "channel")["Lube et al. (2005)"]
                mean = _mean(table[name].sel(mu_r=m, aspect_ratio=a).values)
                if np.isfinite(law) and np.isfinite(mean):
                    errors.append(mean / law - 1)
            errors = np.array(errors)
            worst = errors[np.argmax(np.abs(errors))] if len(errors) else np.nan
            parts.append(f"{label}s {np.sqrt(np.mean(errors ** 2)):.1%} over {len(errors)} a (worst {worst:+.1%})")
        lines.append(f"- mu_r = {m:g} against Lube et al. (2005): " + "; ".join(parts))
    return lines


def _of(rows, **values) -> list:
    return [row for row in rows if all(np.isclose(_value(row, name), value) for name, value in values.items())]


def sweeps(rows) -> list:
    """The (width, wall_mu) of every sweep: runs at TABLE_LENGTH over three a or more, the study's walls first."""
    groups = {(_value(row, "channel_width"), _value(row, "wall_mu")) for row in _of(rows, channel_length=TABLE_LENGTH)}
    full = [group for group in groups if len({row["aspect_ratio"] for row in _of(
        rows, channel_width=group[0], wall_mu=group[1], channel_length=TABLE_LENGTH)}) >= 3]
    return sorted(full, key=lambda group: (not np.isclose(group[1], STUDY_WALL_MU), group))


def progress_line(box: str, part) -> str:
    """The runs in one box (`box` names it): per seed against the plan, at rest, spheres and CPU."""
    seeds = sorted({int(row["seed"]) for row in part})
    counts = ", ".join(f"seed {s}: {sum(int(row['seed']) == s for row in part)} of {PLANNED}" for s in seeds)
    resting = sum(int(row["at_rest"]) for row in part)
    spheres = sorted({int(row["n_particles"]) for row in part})
    pours = sum({int(row["seed"]): _value(row, "pour_cpu_time") for row in part}.values())
    collapses = sum(_value(row, "collapse_cpu_time") for row in part)
    return (f"- {box}: {counts}; {resting} of {len(part)} at rest; {spheres[0]:,}-{spheres[-1]:,} spheres; "
            f"CPU {pours:,.0f} s of pours, {collapses:,.0f} s of collapses")


def _by_length(rows) -> tuple[list, list, dict]:
    """(aspect ratios, mu_r, {L0: runs}) of a sweep's runs, sorted."""
    ratios = sorted({_value(row, "aspect_ratio") for row in rows})
    mu_rs = sorted({_value(row, "mu_r") for row in rows})
    lengths = sorted({_value(row, "channel_length") for row in rows})
    return ratios, mu_rs, {length: _of(rows, channel_length=length) for length in lengths}


def sweep_section(rows, width: float, wall_mu: float) -> list:
    """One sweep: progress at each L0, the laws' table at TABLE_LENGTH, exponents, the run-outs by L0."""
    ratios, mu_rs, by_length = _by_length(_of(rows, channel_width=width, wall_mu=wall_mu))
    walls = "the study's walls" if np.isclose(wall_mu, STUDY_WALL_MU) else "other walls"
    lines = [f"#### W = {width:g}, wall_mu = {wall_mu:g} ({walls})", ""]
    lines += [progress_line(f"L0 = {length:g}", part) for length, part in by_length.items()]
    table = summary(by_length[TABLE_LENGTH], ratios, mu_rs)
    lines += ["", f"At L0 = {TABLE_LENGTH:g} (each law's value, and the runs' error against it):", ""]
    lines += laws_table(table) + [""] + misfit_lines(table) + ["", exponents_markdown(table).strip()]
    if len(by_length) >= 2:
        lines += [""] + by_length_lines(by_length, ratios, mu_rs)
    return lines + [""]


def convergence_in_length(by_length: dict, ratios, mu_rs) -> xr.Dataset:
    """colsim.study.channel.length_convergence of a sweep's runs by box length ({L0: runs}): the
    spread between the two largest lengths given."""
    return length_convergence({length: summary(part, ratios, mu_rs) for length, part in by_length.items()})


def by_length_lines(by_length: dict, ratios, mu_rs) -> list:
    """The run-outs by box length ({L0: runs}) with the spread between the two largest."""
    convergence = convergence_in_length(by_length, ratios, mu_rs)
    return ["Run-outs by box length (means over seeds):", "", length_convergence_markdown(convergence).strip()]


def similar_boxes(rows) -> list:
    """The runs with the study's walls in boxes of the study's shape, W/L0 = TABLE_WIDTH/TABLE_LENGTH."""
    return [row for row in _of(rows, wall_mu=STUDY_WALL_MU) if np.isclose(
        _value(row, "channel_width") / _value(row, "channel_length"), TABLE_WIDTH / TABLE_LENGTH)]


def similar_section(rows) -> list:
    """The boxes of the study's shape (W = L0/3) at two lengths or more: progress at each, and the run-outs
    by box length, a convergence in the grains' size d/L0 alone (at one W, L0 moves W/L0 as well)."""
    ratios, mu_rs, by_length = _by_length(similar_boxes(rows))
    if len(by_length) < 2:
        return []
    lines = [f"#### W = L0/3, wall_mu = {STUDY_WALL_MU:g} (boxes of the study's shape)", ""]
    lines += [progress_line(f"L0 = {length:g}, W = {_value(part[0], 'channel_width'):g}", part)
              for length, part in by_length.items()]
    return lines + [""] + by_length_lines(by_length, ratios, mu_rs) + [""]


def walls_table(rows, full) -> list:
    """The runs with walls of no sweep (nor boxes of the study's shape), each beside the runs of the same
    packing, a and mu_r with other walls."""
    similar = similar_boxes(rows)
    others = [row for row in rows
              if (_value(row, "channel_width"), _value(row, "wall_mu")) not in full and row not in similar]
    if not others:
        return []
    lines = ["| W | L0 | seed | mu_r | a | wall_mu | run-out | height | at rest |", "|---|---|---|---|---|---|---|---|---|"]
    keys = sorted({tuple(_value(row, name) for name in ("channel_width", "channel_length", "seed", "mu_r", "aspect_ratio"))
                   for row in others})
    for width, length, seed, mu_r, a in keys:
        same = _of(rows, channel_width=width, channel_length=length, seed=seed, mu_r=mu_r, aspect_ratio=a)
        for row in sorted(same, key=lambda row: _value(row, "wall_mu")):
            lines.append(f"| {width:g} | {length:g} | {seed:g} | {mu_r:g} | {a:g} | {_value(row, 'wall_mu'):g} | "
                         f"{_value(row, 'runout_over_r0'):.3f} | {_value(row, 'h_inf_over_r0'):.3f} | "
                         f"{'yes' if int(row['at_rest']) else 'no'} |")
    return ["#### The walls' friction", ""] + lines


def _difference_cell(values, references) -> str:
    """The mean relative difference of paired runs with its 95 % half-width (one pair: none)."""
    mean, half_width, pairs = paired_difference(values, references)
    return f"{100 * mean:+.1f} % (one seed)" if pairs < 2 else f"{100 * mean:+.1f} % +- {100 * half_width:.1f}"


def time_step_table(rows) -> list:
    """The runs at other steps than STUDY_STEPS, per column (width, walls, L0, mu_r, a) and steps: the
    means over seeds at both steps and the paired relative difference of the run-out and the height."""
    others = [row for row in rows if int(row["steps"]) != STUDY_STEPS]
    if not others:
        return []
    names = ("channel_width", "wall_mu", "channel_length", "mu_r", "aspect_ratio", "steps")
    study = f"at {STUDY_STEPS:,} steps"
    lines = [f"| W | wall_mu | L0 | mu_r | a | steps | seeds | run-out | {study} | difference [95 %] | height "
             f"| {study} | difference [95 %] |", "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for key in sorted({tuple(_value(row, name) for name in names) for row in others}):
        column = dict(zip(names, key))
        pairs = []   # (run, the same column at STUDY_STEPS)
        for row in _of(others, **column):
            same = _of(rows, seed=_value(row, "seed"), **(column | {"steps": STUDY_STEPS}))
            if same:
                pairs.append((row, same[0]))
        cells = []
        for name, _ in VARIABLES:
            values = np.array([_value(row, name) for row, _ in pairs])
            references = np.array([_value(reference, name) for _, reference in pairs])
            cells += [f"{values.mean():.3f}", f"{references.mean():.3f}", _difference_cell(values, references)]
        width, wall_mu, length, mu_r, a, steps = key
        lines.append(f"| {width:g} | {wall_mu:g} | {length:g} | {mu_r:g} | {a:g} | {steps:,.0f} | {len(pairs)} | "
                     + " | ".join(cells) + " |")
    return ["#### The time step", ""] + lines


def report(rows) -> str:
    study = _of(rows, steps=STUDY_STEPS)
    full = sweeps(study)
    lines = [line for width, wall_mu in full for line in sweep_section(study, width, wall_mu)]
    lines += similar_section(study) + walls_table(study, full)
    steps = time_step_table(rows)
    return "\n".join(lines + ([""] + steps if steps else [])).strip()


def figures(rows, folder: Path) -> None:
    """Each sweep's run-outs and heights at TABLE_LENGTH against the laws,
    channel_W{W}_wall_mu_{wall_mu}_{variable}.png."""
    from colsim.study.figures.laws import law_figure

    rows = _of(rows, steps=STUDY_STEPS)
    for width, wall_mu in sweeps(rows):
        part = _of(rows, channel_width=width, wall_mu=wall_mu, channel_length=TABLE_LENGTH)
        table = summary(part, sorted({_value(row, "aspect_ratio") for row in part}),
                        sorted({_value(row, "mu_r") for row in part}))
        for name, _ in VARIABLES:
            law_figure(table, name, folder / f"channel_W{width:g}_wall_mu_{wall_mu:g}_{name}.png")


if __name__ == "__main__":
    main(__doc__, write_runs, lambda: report(read_rows(RUNS)), lambda folder: figures(read_rows(RUNS), folder))
