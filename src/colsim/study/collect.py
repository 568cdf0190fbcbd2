"""A study's runs in one xarray Dataset over (aspect_ratio, mu_r, seed), from their collapse
analyses; the means per column size (:func:`means_per_size`), the status of runs that did not settle
(:func:`run_status`: the one place a run is called moving or a fragment, for tables and figures) and the runs under both friction laws side by side. Its tables in Markdown:
:mod:`colsim.study.markdown`."""
from __future__ import annotations

import json
from collections import Counter

import numpy as np
import xarray as xr

from ..engine.state import FRICTION_LAWS, LEVER_OF_OLDER_FILES, ROLLING_LEVERS
from ..io.checks import FileProblem, check_attributes
from ..io.netcdf import AT_REST_FLAGS, at_rest_flag, at_rest_variable
from ..solvers.defaults import FLOAT64_FALLBACK, SOLVERS
from ..stages.pour_geometry import geometry_of
from ..stages.settings import CollapseSettings

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
# checkpointing, threads, the device, its storage and the packing's size bound (none of which changes
# a result beyond rounding), and the logging
SWEPT = ("aspect_ratio", "mu_r", "seed")
NOT_SETTINGS = set(SWEPT) | {"input", "output", "checkpoint", "checkpoint_every", "command", "threads", "device",
                             "gpu_storage", "max_spheres", "settings", "verbose", "quiet"}


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


#: what a run's attributes of a fixed vocabulary may say (they reach the tables and the report)
VOCABULARY = {"friction_law": FRICTION_LAWS, "rolling_lever": ROLLING_LEVERS}
#: the back-ends a step may name (colsim.solvers.AutoSolver adds clarabel-fallback, APGD with float32
#: storage its float64 retry)
BACKENDS = set(SOLVERS) | {"clarabel-fallback", FLOAT64_FALLBACK}


def run_key(analysis) -> tuple[float, float, int]:
    """(aspect_ratio, mu_r, seed) of one analysis, checked: its numeric attributes and seed by
    :func:`colsim.io.checks.check_attributes` (as every input file is), aspect_ratio and mu_r
    present, and its fixed-vocabulary attributes from their vocabularies (else ValueError naming the
    run)."""
    try:
        check_attributes(analysis.attrs)
    except FileProblem as problem:
        raise ValueError(f"{_run_name(analysis)}: {problem}") from None
    for name in ("aspect_ratio", "mu_r"):
        if name not in analysis.attrs:
            raise ValueError(f"{_run_name(analysis)}: attribute {name} is missing, not a finite number")
    a, mu_r = (float(np.asarray(analysis.attrs[name]).reshape(-1)[0]) for name in ("aspect_ratio", "mu_r"))
    seed = int(np.asarray(analysis.attrs.get("seed", 0)).reshape(-1)[0])
    for name, allowed in VOCABULARY.items():
        if name in analysis.attrs and analysis.attrs[name] not in allowed:
            raise ValueError(f"{_run_name(analysis)}: {name} {str(analysis.attrs[name])[:80]!r} is not one of {', '.join(allowed)}")
    try:
        backends = json.loads(analysis.attrs.get("solver_backends", "{}"))
    except (TypeError, ValueError):
        backends = None
    if not isinstance(backends, dict) or not set(backends) <= BACKENDS or not all(
            isinstance(v, int) and v >= 0 for v in backends.values()):
        raise ValueError(f"{_run_name(analysis)}: solver_backends is not a count of steps by back-end "
                         f"({', '.join(sorted(BACKENDS))})")
    return a, mu_r, seed


#: what every run of one study shares, whatever it sweeps: its friction law, its rolling lever and
#: its solver's stopping rule (a run of another joins no summary, calibration or fit)
SHARED = ("collapse.friction_law", "collapse.rolling_lever", "collapse.solver_tolerance",
          "collapse.solver_settings")
#: what runs of different time steps share: auto's solver settings follow the step (its scaled step,
#: and APGD's lengths below defaults.AUTO_APGD_LENGTHS_AT), so a time-step study does not compare them
SHARED_ACROSS_STEPS = tuple(name for name in SHARED if name != "collapse.solver_settings")


def check_runs(analyses, swept=SWEPT, shared=SHARED) -> list[tuple]:
    """The one set of checks of every command that reads runs (collect, calibrate, the column-size
    fit): each run's attributes (:func:`run_key`), its scalar results one number each, no two runs
    of the same `swept` values (the same run given twice would count twice), and one friction law,
    rolling lever and solver tolerance (`shared`: SHARED, or SHARED_ACROSS_STEPS where the runs'
    time steps differ) among them. Returns each run's `swept` values; ValueError naming the odd run
    otherwise."""
    keys = []
    for analysis in analyses:
        run_key(analysis)
        for name in (*SUMMARY_VARIABLES, "mean_diameter", "at_rest"):
            if name in analysis.variables and analysis[name].size != 1:
                raise ValueError(f"{_run_name(analysis)}: {name} has shape {analysis[name].shape}, not one number")
        try:
            keys.append(tuple(float(np.asarray(analysis.attrs.get(name, 0) if name == "seed" else analysis.attrs[name])
                                    .reshape(-1)[0]) for name in swept))
        except (KeyError, IndexError, TypeError, ValueError):
            raise ValueError(f"{_run_name(analysis)}: its {', '.join(swept)} are not numbers") from None
    first = {}
    for key, analysis in zip(keys, analyses):
        if key in first:
            raise ValueError(f"two analyses share the same ({', '.join(swept)}): {_run_name(first[key])} and"
                             f" {_run_name(analysis)}; each run counts once")
        first[key] = analysis
    reference = {name: run_settings(analyses[0]).get(name) for name in shared}
    for analysis in analyses[1:]:
        settings = run_settings(analysis)
        for name in shared:
            if settings.get(name) != reference[name]:
                raise ValueError(f"runs differ in {name}: {reference[name]} in {_run_name(analyses[0])},"
                                 f" {settings.get(name)} in {_run_name(analysis)}; one study has one")
    return keys


def collect_analyses(analyses) -> xr.Dataset:
    """Stack analysis datasets by their (aspect_ratio, mu_r, seed); NaN where a run is missing."""
    if not analyses:
        raise ValueError("no analysis files to collect")
    keys = [(a, m, int(s)) for a, m, s in check_runs(analyses)]
    column = _geometry_attributes(analyses)
    check_same_settings(analyses)
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
    attrs = {**column, "mu": float(first["mu"]),
             "friction_law": str(first.get("friction_law", "associated")),
             "rolling_lever": str(first.get("rolling_lever", LEVER_OF_OLDER_FILES)),
             "solver_backends": json.dumps(solver_backends(analyses)),
             "run_configs": json.dumps([json.loads(a.attrs.get("config", "{}")) for a in analyses])}
    return xr.Dataset(data, coords=coords, attrs=attrs)


GEOMETRY_ATTRIBUTES = {"cylinder": ("r0",), "channel": ("channel_length", "channel_width", "wall_mu")}
"""The attributes of a run's column that its summary carries, by geometry (a cylinder's radius; a
channel's box length L0, width and wall friction)."""


def _geometry_attributes(analyses) -> dict:
    """The runs' geometry ("cylinder" where an analysis has no attribute, as every file written
    before channels) and its GEOMETRY_ATTRIBUTES, from the first run; ValueError where the runs
    hold more than one geometry (a study compares one with its own laws)."""
    geometries = {geometry_of(a.attrs) for a in analyses}
    if len(geometries) > 1:
        raise ValueError(f"the runs hold more than one geometry ({', '.join(sorted(geometries))}); "
                         "a summary holds one")
    geometry = geometries.pop()
    if geometry not in GEOMETRY_ATTRIBUTES:
        raise ValueError(f"geometry {geometry[:60]!r} is not one of {', '.join(GEOMETRY_ATTRIBUTES)}")
    first = analyses[0].attrs
    attrs = {name: float(first[name]) for name in GEOMETRY_ATTRIBUTES[geometry]}
    return attrs | ({"geometry": geometry} if geometry == "channel" else {})


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


REST_ENERGY = CollapseSettings.rest_energy
"""The collapse's default rest test on the kinetic energy, for runs whose settings do not say it."""
MAIN_MASS_SHARE = 0.5
"""A main mass (the largest connected cluster) with fewer than this share of the grains is a fragment:
its h_inf and r_inf do not describe the deposit."""
def counted(fewest: int, noun: str, most: int | None = None) -> str:
    """'1 seed', '3 seeds', '1-3 seeds': a count (or the range of counts) with its noun."""
    most = fewest if most is None else most
    number = f"{fewest}" if fewest == most else f"{fewest}-{most}"
    return f"{number} {noun}" if number == "1" else f"{number} {noun}s"


FLAGS = {"moving": "still moving", "fragment": "main mass < half the grains"}
"""The flags of :func:`run_status` -> how tables and figures name them."""


def rest_energy(configs) -> float:
    """The collapse's rest_energy in a list of configurations (a file's `config` attribute, read as
    JSON, and the chain of its input_config; the first found), else :data:`REST_ENERGY`."""
    for config in configs:
        while isinstance(config, dict) and config:
            if config.get("command") == "collapse" and config.get("rest_energy") is not None:
                return float(config["rest_energy"])
            config = config.get("input_config") or {}
    return REST_ENERGY


def rest_energy_of(summary) -> float:
    """:func:`rest_energy` of the summary's run configurations."""
    return rest_energy(json.loads(summary.attrs.get("run_configs", "[]")))


def run_status(runs) -> dict:
    """{flag: bool DataArray} of the runs whose numbers do not describe a deposit at rest: the one
    rule the tables and the figures read. runs: a summary (shaped like its h_inf_over_r0; False
    where a run is missing or the summary lacks what the flag needs) or one run (:func:`one_run`).

    - "moving": still moving at the end: at_rest is 0 (the run reached max_duration moving), or, where
      rest was not checked (a fixed end time: at_rest -1, or in older summaries NaN or absent), its
      kinetic energy at the end is above the collapse's rest_energy (its run configurations', else
      the default's) of its peak;
    - "fragment": the main mass, the largest connected cluster, holds less than half the grains.
    """
    ran = np.isfinite(runs.h_inf_over_r0) if "h_inf_over_r0" in runs else xr.DataArray(True)
    none = xr.zeros_like(ran, dtype=bool)
    checked = none
    moving = none
    if "at_rest" in runs:
        at_rest = runs.at_rest.astype(float)
        checked = (at_rest == 0) | (at_rest == 1)
        moving = at_rest == 0
    if "final_to_peak_kinetic_energy" in runs:
        energy = runs.final_to_peak_kinetic_energy
        moving = moving | (~checked & (energy > rest_energy_of(runs)))
    fragment = none
    if "n_main_mass" in runs and "n_particles" in runs:
        fragment = runs.n_main_mass < MAIN_MASS_SHARE * runs.n_particles
    return {"moving": (moving & ran).transpose(*ran.dims), "fragment": (fragment & ran).transpose(*ran.dims)}


def one_run(run) -> xr.Dataset:
    """One run's analysis or trajectory as :func:`run_status` reads it: its at_rest flag, its kinetic
    energy at the end over its peak (from a trajectory's steps, translation and rotation, as the
    analysis computes it), its main mass and particle count when it has them, and its configuration."""
    names = ("h_inf_over_r0", "final_to_peak_kinetic_energy", "n_main_mass", "n_particles")
    data = {name: run[name] for name in names if name in run.variables}
    if "final_to_peak_kinetic_energy" not in data and "step_kinetic_energy" in run.variables:
        energy = run["step_kinetic_energy"].values
        if "step_rotational_energy" in run.variables:
            energy = energy + run["step_rotational_energy"].values
        if energy.size:
            data["final_to_peak_kinetic_energy"] = xr.DataArray(energy[-1] / max(energy.max(), 1e-300))
    data["at_rest"] = xr.DataArray(at_rest_flag(run))
    return xr.Dataset(data, attrs={"run_configs": json.dumps([json.loads(run.attrs.get("config", "{}"))])})


def friction_law_comparison(summaries) -> xr.Dataset:
    """Summaries of the same runs under each friction law ({law: summary}), stacked along a
    `friction_law` dimension (NaN where a run is missing under one law)."""
    laws = list(summaries)
    stacked = xr.concat([summaries[law] for law in laws], dim="friction_law", join="outer",
                        combine_attrs="drop_conflicts")
    stacked = stacked.assign_coords(friction_law=("friction_law", laws, {"long_name": "friction law"}))
    stacked.attrs.pop("friction_law", None)
    return stacked


