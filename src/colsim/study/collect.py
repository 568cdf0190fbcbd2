"""Stage 5: one xarray Dataset over (aspect_ratio, mu_r, seed) from many collapse analyses, and its
tables: the mean over seeds against Lube et al.'s laws (:func:`lube_markdown`, with the other run-out
measures and the paper's qualitative claims) and the means per column size (:func:`means_per_size`)."""
from __future__ import annotations

import json
from collections import Counter

import numpy as np
import xarray as xr

from ..io.netcdf import AT_REST_FLAGS, at_rest_flag, at_rest_variable
from .experimental_laws import lajeunesse_height, lajeunesse_runout, lube_height, lube_runout
from ..engine.state import LEVER_OF_OLDER_FILES

SUMMARY_VARIABLES = ("h_inf_over_r0", "runout_over_r0", "h_inf", "r_inf", "n_particles",
                     "solid_fraction", "final_to_peak_kinetic_energy", "wall_time",
                     "undisturbed_top_radius", "n_main_mass", "apgd_steps", "fallback_steps",
                     "cone_programs_per_step")
# per-run checks with a dimension of their own (kept only when every analysis has them)
CHECK_VARIABLES = {"runout_over_r0_by_tolerance": "contact_tolerance", "mass_front_over_r0": "mass_share"}

# attributes of an analysis that become summary variables (NaN where a run does not have them):
# attribute -> (variable, its attributes)
RUN_ATTRIBUTES = {
    "duration": ("end_time", {"units": "1", "long_name": "end time of the collapse over sqrt(h0/g)"}),
}


# what a run's settings may differ in between the runs of one summary: the swept values, file names,
# checkpointing, threads and the packing's size bound (none of which changes a result)
SWEPT = ("aspect_ratio", "mu_r", "seed")
NOT_SETTINGS = set(SWEPT) | {"input", "output", "checkpoint", "checkpoint_every", "command", "threads",
                             "max_spheres"}


def run_settings(analysis) -> dict:
    """A run's settings, flattened: r0 and mu, and each stage's options from the configuration
    chain in the file (analyse, collapse, trim, pack: "collapse.steps"), less NOT_SETTINGS, the
    Coulomb fixed point's tolerance of an associated run and the freeze depth of a packing poured in
    one cloud (which do not use them)."""
    settings = {name: float(analysis.attrs[name]) for name in ("r0", "mu") if name in analysis.attrs}
    config = json.loads(analysis.attrs.get("config", "{}"))
    while config:
        stage = config.get("command", "stage")
        if stage == "collapse":   # runs made before the option existed used R_eff
            config = {"rolling_lever": LEVER_OF_OLDER_FILES, **config}
        if stage == "pack":       # packings made before layers were poured in one cloud
            config = {"layer_height": None, **config}
        unused = {"friction_tolerance"} if config.get("friction_law") == "associated" else set()
        if stage == "pack" and config["layer_height"] is None:
            unused |= {"freeze_depth"}
        settings |= {f"{stage}.{key}": value for key, value in config.items()
                     if key not in NOT_SETTINGS | unused and key != "input_config"}
        config = config.get("input_config") or {}
    return settings


def _run_name(analysis) -> str:
    key = ", ".join(f"{name} {analysis.attrs.get(name, '?')}" for name in SWEPT)
    source = analysis.encoding.get("source")
    return f"{source} ({key})" if source else key


def check_same_settings(analyses) -> None:
    """ValueError naming the first setting in which two runs differ, other than the swept values."""
    reference = run_settings(analyses[0])
    for analysis in analyses[1:]:
        settings = run_settings(analysis)
        for name in sorted(set(reference) | set(settings)):
            if reference.get(name) != settings.get(name):
                raise ValueError(f"runs differ in {name}: {reference.get(name)} in {_run_name(analyses[0])}, "
                                 f"{settings.get(name)} in {_run_name(analysis)}; a summary sweeps only "
                                 f"{', '.join(SWEPT)}")


def one_row_per_run(summary) -> xr.Dataset:
    """The summary over (aspect_ratio, mu_r, seed) only: each check variable becomes one variable per
    value of its own dimension, e.g. mass_front_over_r0_0.95 (for a CSV with a row per run)."""
    flat = summary.drop_vars([name for name in CHECK_VARIABLES if name in summary])
    for name, dim in CHECK_VARIABLES.items():
        if name in summary:
            for value in summary[dim].values:
                flat[f"{name}_{value:g}"] = summary[name].sel({dim: value}, drop=True)
    return flat.drop_dims([dim for dim in CHECK_VARIABLES.values() if dim in flat.dims])


def collect_analyses(analyses) -> xr.Dataset:
    """Stack analysis datasets by their (aspect_ratio, mu_r, seed); NaN where a run is missing."""
    if not analyses:
        raise ValueError("no analysis files to collect")
    check_same_settings(analyses)
    keys = [(float(a.attrs["aspect_ratio"]), float(a.attrs["mu_r"]), int(a.attrs.get("seed", 0)))
            for a in analyses]
    if len(set(keys)) != len(keys):
        raise ValueError("two analyses share the same (aspect_ratio, mu_r, seed)")
    ratios, mu_rs, seeds = (sorted(set(values)) for values in zip(*keys))
    dims = ("aspect_ratio", "mu_r", "seed")

    def grid(value, extra=()):
        """An array over (aspect_ratio, mu_r, seed) + extra of value(analysis); NaN where none."""
        values = np.full((len(ratios), len(mu_rs), len(seeds)) + extra, np.nan)
        for (a, m, s), analysis in zip(keys, analyses):
            values[ratios.index(a), mu_rs.index(m), seeds.index(s)] = value(analysis)
        return values

    present = [name for name in SUMMARY_VARIABLES if any(name in a for a in analyses)]  # older files lack some
    data = {name: (dims, grid(lambda a, name=name: float(a[name].values) if name in a else np.nan),
                   dict(next(a[name].attrs for a in analyses if name in a)))
            for name in present}
    coords = {}
    reference = analyses[0]
    for name, dim in CHECK_VARIABLES.items():
        if all(name in a and np.array_equal(a[dim].values, reference[dim].values) for a in analyses):
            data[name] = (dims + (dim,), grid(lambda a, name=name: a[name].values, (reference.sizes[dim],)),
                          dict(reference[name].attrs))
            coords[dim] = reference[dim]
    for name, (variable, attrs) in RUN_ATTRIBUTES.items():
        data[variable] = (dims, grid(lambda a, name=name: float(a.attrs.get(name, np.nan))), dict(attrs))
    # the at_rest flag: not_checked where a run is missing (a flag variable holds no NaN)
    at_rest = np.full((len(ratios), len(mu_rs), len(seeds)), AT_REST_FLAGS["not_checked"], dtype=np.int8)
    for (a, m, s), analysis in zip(keys, analyses):
        at_rest[ratios.index(a), mu_rs.index(m), seeds.index(s)] = at_rest_flag(analysis)
    data["at_rest"] = at_rest_variable(dims, at_rest)
    coords |= {
        "aspect_ratio": ("aspect_ratio", ratios, {"units": "1", "long_name": "aspect ratio h0/r0"}),
        "mu_r": ("mu_r", mu_rs, {"units": "1", "long_name": "rolling resistance coefficient"}),
        "seed": ("seed", seeds, {"units": "1", "long_name": "packing seed"}),
    }
    first = analyses[0].attrs
    attrs = {"r0": float(first["r0"]), "mu": float(first["mu"]),
             "friction_law": str(first.get("friction_law", "associated")),
             "rolling_lever": str(first.get("rolling_lever", LEVER_OF_OLDER_FILES)),
             "solver_backends": json.dumps(solver_backends(analyses)),
             "run_configs": json.dumps([json.loads(a.attrs.get("config", "{}")) for a in analyses])}
    return xr.Dataset(data, coords=coords, attrs=attrs)


def solver_backends(analyses) -> dict:
    """{back-end: steps it solved} over the runs (runs written before the count existed add none)."""
    total = Counter()
    for analysis in analyses:
        total.update(json.loads(analysis.attrs.get("solver_backends", "{}")))
    return dict(sorted(total.items()))


def means_per_size(study) -> xr.Dataset:
    """The column-size runs averaged over seeds: one `run` per (aspect_ratio, r0), with the numeric
    variables and coordinates as means, plus n_seeds and runout_spread (max - min of the run-out)."""
    pairs = sorted({(float(a), float(r)) for a, r in zip(study.aspect_ratio.values, study.r0.values)})
    parts = []
    for a, r0 in pairs:
        rows = study.isel(run=np.flatnonzero((study.aspect_ratio.values == a) & (study.r0.values == r0)))
        numeric = rows.drop_vars([n for n in rows.coords if not np.issubdtype(rows[n].dtype, np.number)])
        mean = numeric.reset_coords().mean("run", keep_attrs=True)
        mean["n_seeds"] = rows.sizes["run"]
        mean["runout_spread"] = float(rows.runout_over_r0.max() - rows.runout_over_r0.min())
        parts.append(mean)
    means = xr.concat(parts, dim="run")
    return means.set_coords([n for n in ("r0", "aspect_ratio", "r0_over_mean_diameter", "duration") if n in means])


def claims_markdown(summary) -> str:
    """Markdown table of the paper's qualitative claims, per mu_r and a (mean over seeds): the final
    height over h0 (1 where the top is undisturbed, below 1 where it was eroded), the radius of the
    top disc that did not move, over r0, and the share of grains in the main mass."""
    lines = ["| mu_r | a | h_inf/h0 | undisturbed top radius/r0 | main mass / grains |", "|---|---|---|---|---|"]
    for m in summary.mu_r.values:
        for a in summary.aspect_ratio.values:
            part = summary.sel(mu_r=m, aspect_ratio=a)
            if not _has_runs(part):
                continue
            kept = np.nanmean(part.n_main_mass.values / part.n_particles.values)
            lines.append(f"| {float(m):g} | {a:g} | {np.nanmean(part.h_inf_over_r0.values) / a:.2f} | "
                         f"{np.nanmean(part.undisturbed_top_radius.values):.2f} | {kept:.2f} |")
    return "\n".join(lines) + "\n"


def runout_measures_markdown(summary) -> str:
    """Markdown table per mu_r and a: Lube's run-out, r_inf at each contact tolerance and the radius
    holding each share of the mass, as (r - r0)/r0, mean over seeds, with the error against Lube."""
    tolerances = summary.contact_tolerance.values
    shares = summary.mass_share.values
    header = (["mu_r", "a", "Lube"] + [f"connected, gap <= {100 * t:g} % d_min" for t in tolerances]
              + [f"{100 * s:g} % of the mass" for s in shares])
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for m in summary.mu_r.values:
        for a in summary.aspect_ratio.values:
            part = summary.sel(mu_r=m, aspect_ratio=a)
            if not _has_runs(part):
                continue
            law = lube_runout(a)
            values = list(np.nanmean(part.runout_over_r0_by_tolerance.values, axis=0)) + list(
                np.nanmean(part.mass_front_over_r0.values, axis=0))
            cells = [f"{v:.2f} ({_error(v, law)})" for v in values]
            lines.append(f"| {float(m):g} | {a:g} | {law:.2f} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


REST_ENERGY = 1e-2
"""The collapse's default rest test on the kinetic energy (colsim.stages.collapse.CollapseSettings.rest_energy):
at rest only below this share of its peak."""
MAIN_MASS_SHARE = 0.5
"""A main mass (the largest connected cluster) with fewer than this share of the grains is a fragment:
its h_inf and r_inf do not describe the deposit."""
FLAGS = {"moving": "still moving", "fragment": "main mass < half the grains"}
"""The flags of :func:`run_flags` -> how tables and figures name them."""


def rest_energy(configs) -> float:
    """The collapse's rest_energy in a list of configurations (a file's `config` attribute, read as
    JSON, and the chain of its input_config; the first found), else :data:`REST_ENERGY`."""
    for config in configs:
        while isinstance(config, dict) and config:
            if config.get("command") == "collapse" and config.get("rest_energy") is not None:
                return float(config["rest_energy"])
            config = config.get("input_config") or {}
    return REST_ENERGY


def _rest_energy(summary) -> float:
    """:func:`rest_energy` of the summary's run configurations."""
    return rest_energy(json.loads(summary.attrs.get("run_configs", "[]")))


def run_flags(summary) -> dict:
    """{flag: bool DataArray shaped like h_inf_over_r0} for the runs whose numbers do not describe a
    deposit at rest (False where a run is missing or the summary lacks what the flag needs):

    - "moving": still moving at the end: at_rest is 0 (the run reached max_duration moving), or, where
      rest was not checked (a fixed end time: at_rest -1, or in older summaries NaN or absent), its
      kinetic energy at the end is above the collapse's rest_energy (1e-2 unless the run
      configurations say otherwise) of its peak;
    - "fragment": the main mass, the largest connected cluster, holds less than half the grains.
    """
    ran = np.isfinite(summary.h_inf_over_r0)
    none = xr.zeros_like(ran, dtype=bool)
    checked = none
    moving = none
    if "at_rest" in summary:
        at_rest = summary.at_rest.astype(float)
        checked = (at_rest == 0) | (at_rest == 1)
        moving = at_rest == 0
    if "final_to_peak_kinetic_energy" in summary:
        energy = summary.final_to_peak_kinetic_energy
        moving = moving | (~checked & (energy > _rest_energy(summary)))
    fragment = none
    if "n_main_mass" in summary and "n_particles" in summary:
        fragment = summary.n_main_mass < MAIN_MASS_SHARE * summary.n_particles
    return {"moving": (moving & ran).transpose(*ran.dims), "fragment": (fragment & ran).transpose(*ran.dims)}


def _flag_cell(flags, seeds) -> str:
    """The flags of one (mu_r, a) row over its seeds: "still moving (seeds 1, 2)"; "" when none."""
    cells = []
    for name, flagged in flags.items():
        which = [f"{int(s)}" for s, f in zip(seeds, np.atleast_1d(flagged)) if f]
        if which:
            cells.append(f"{FLAGS[name]} (seed{'s' if len(which) > 1 else ''} {', '.join(which)})")
    return "; ".join(cells)


def lube_markdown(summary) -> str:
    """Markdown table: mean over seeds of h_inf/r0 and the run-out against Lube et al., per mu_r and
    a, with the error against Lajeunesse et al. beside (its height law as the paper prints it), and a
    flags column naming the seeds whose runs :func:`run_flags` flags (explained under the tables)."""
    lines = []
    flags = run_flags(summary)
    seed_values = summary.seed.values if "seed" in summary.coords else [0]
    for m in summary.mu_r.values:
        part = summary.sel(mu_r=m)
        counts = np.isfinite(part.h_inf_over_r0.values).sum(axis=-1)
        counts = counts[counts > 0]   # a partial study: the aspect ratios run (every mu_r has one)
        seeds = f"{counts.min()}" if counts.min() == counts.max() else f"{counts.min()}-{counts.max()}"
        lines += [f"### mu_r = {float(m):g} (mean of {seeds} seeds; spread = max - min)", "",
                  "| a | h_inf/r0 | spread | Lube | error | (r_inf - r0)/r0 | spread | Lube | error "
                  "| Lajeunesse h_inf/r0 | error | Lajeunesse run-out | error | flags |",
                  "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for a in part.aspect_ratio.values:
            if not _has_runs(part.sel(aspect_ratio=a)):
                continue
            h = part.h_inf_over_r0.sel(aspect_ratio=a).values
            r = part.runout_over_r0.sel(aspect_ratio=a).values
            h_mean, r_mean = np.nanmean(h), np.nanmean(r)
            cells = [f"{a:g}"]
            for mean, values, law in ((h_mean, h, lube_height(a)), (r_mean, r, lube_runout(a))):
                cells += [f"{mean:.3f}", f"{np.nanmax(values) - np.nanmin(values):.3f}", f"{law:.3f}",
                          _error(mean, law)]
            for mean, law in ((h_mean, lajeunesse_height(a)), (r_mean, lajeunesse_runout(a))):
                cells += [f"{law:.3f}", _error(mean, law)]
            cells.append(_flag_cell({name: flag.sel(mu_r=m, aspect_ratio=a).values for name, flag in flags.items()},
                                    seed_values))
            lines.append("| " + " | ".join(cells) + " |")
        lines.append("")
    if any(bool(flag.any()) for flag in flags.values()):
        lines += [f"Flags: *{FLAGS['moving']}*: the run was not at rest at its end (it reached max_duration "
                  f"moving or, with a fixed end time, its kinetic energy was still above {_rest_energy(summary):g} "
                  f"of its peak), so its h_inf and run-out are not those of a final deposit; "
                  f"*{FLAGS['fragment']}*: the main mass (the largest connected cluster) holds less than "
                  f"{100 * MAIN_MASS_SHARE:g} % of the grains, so its h_inf and run-out describe a fragment. The means "
                  f"include these runs; the figures draw them with open markers (moving) or a cross (fragment).",
                  ""]
    if "runout_over_r0_by_tolerance" in summary and "mass_front_over_r0" in summary:
        lines += ["### Run-out by other measures (mean over seeds; error against Lube)", "",
                  runout_measures_markdown(summary)]
    if "undisturbed_top_radius" in summary and "n_main_mass" in summary:
        lines += ["### The paper's qualitative claims", "", claims_markdown(summary)]
    return "\n".join(lines)


def lube_rst(summary, mu_r: float) -> str:
    """reStructuredText list-table of the report's landing page: at the swept mu_r nearest `mu_r`,
    per a, the mean over seeds of h_inf/r0 and the run-out with Lube's values and the errors."""
    m = summary.mu_r.values[np.argmin(np.abs(summary.mu_r.values - mu_r))]
    part = summary.sel(mu_r=m)
    rows = [["a", "h_inf/r0", "Lube", "error", "(r_inf - r0)/r0", "Lube", "error"]]
    for a in part.aspect_ratio.values:
        if not _has_runs(part.sel(aspect_ratio=a)):
            continue
        h = float(np.nanmean(part.h_inf_over_r0.sel(aspect_ratio=a).values))
        r = float(np.nanmean(part.runout_over_r0.sel(aspect_ratio=a).values))
        rows.append([f"{a:g}", f"{h:.3f}", f"{lube_height(a):.3f}", _error(h, lube_height(a)),
                     f"{r:.3f}", f"{lube_runout(a):.3f}", _error(r, lube_runout(a))])
    lines = [f".. list-table:: mu_r = {float(m):g}, mean over seeds, against Lube et al. (2004)",
             "   :header-rows: 1", ""]
    for row in rows:
        lines += [f"   * - {row[0]}"] + [f"     - {cell}" for cell in row[1:]]
    return "\n".join(lines) + "\n"


def _has_runs(part) -> bool:
    """Whether any seed of this part of a summary ran (a partial study leaves NaN rows out)."""
    return bool(np.isfinite(part.h_inf_over_r0.values).any())


def _error(value: float, law: float) -> str:
    """The relative error of value against law, in percent, signed."""
    return f"{100 * (value - law) / law:+.0f} %"


def friction_law_comparison(summaries) -> xr.Dataset:
    """Summaries of the same runs under each friction law ({law: summary}), stacked along a
    `friction_law` dimension (NaN where a run is missing under one law)."""
    laws = list(summaries)
    stacked = xr.concat([summaries[law] for law in laws], dim="friction_law", join="outer",
                        combine_attrs="drop_conflicts")
    stacked = stacked.assign_coords(friction_law=("friction_law", laws, {"long_name": "friction law"}))
    stacked.attrs.pop("friction_law", None)
    return stacked


def friction_law_markdown(comparison) -> str:
    """Markdown table per mu_r and a: each law's h_inf/r0 and run-out (mean and sd over seeds) against
    Lube's laws, its main-mass share, cone programs per step and wall time per collapse."""
    lines = []
    for m in comparison.mu_r.values:
        lines += [f"### mu_r = {float(m):g} (mean over seeds, sd = sample standard deviation)", "",
                  "| a | law | seeds | h_inf/r0 (sd) | Lube | error | (r_inf - r0)/r0 (sd) | Lube | error "
                  "| main mass / grains | cone programs a step | wall s a collapse |",
                  "|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for a in comparison.aspect_ratio.values:
            for law in comparison.friction_law.values:
                part = comparison.sel(mu_r=m, aspect_ratio=a, friction_law=law)
                h, r = part.h_inf_over_r0.values, part.runout_over_r0.values
                seeds = int(np.isfinite(h).sum())
                if seeds == 0:
                    continue
                sd = (lambda v: np.nanstd(v, ddof=1) if np.isfinite(v).sum() > 1 else np.nan)
                h_law, r_law = lube_height(a), lube_runout(a)
                share = np.nanmean(part.n_main_mass.values / part.n_particles.values)
                programs = (np.nanmean(part.cone_programs_per_step.values)
                            if "cone_programs_per_step" in part else np.nan)
                lines.append(
                    f"| {a:g} | {law} | {seeds} | {np.nanmean(h):.3f} ({sd(h):.3f}) | {h_law:.3f} | "
                    f"{_error(np.nanmean(h), h_law)} | {np.nanmean(r):.3f} ({sd(r):.3f}) | "
                    f"{r_law:.3f} | {_error(np.nanmean(r), r_law)} | {share:.2f} | "
                    f"{programs:.1f} | {np.nanmean(part.wall_time.values):.0f} |")
        lines.append("")
    return "\n".join(lines)
