"""Stage 5: one xarray Dataset over (aspect_ratio, mu_r, seed) from many collapse analyses."""
from __future__ import annotations

import json

import numpy as np

SUMMARY_VARIABLES = ("h_inf_over_r0", "runout_over_r0", "h_inf", "r_inf", "n_particles",
                     "solid_fraction", "final_to_peak_kinetic_energy", "wall_time",
                     "undisturbed_top_radius", "n_main_mass")
# per-run checks with a dimension of their own (kept only when every analysis has them)
CHECK_VARIABLES = {"runout_over_r0_by_tolerance": "contact_tolerance", "mass_front_over_r0": "mass_share"}

# attributes of an analysis that become summary variables (NaN where a run does not have them):
# attribute -> (variable, its attributes)
RUN_ATTRIBUTES = {
    "duration": ("end_time", {"units": "1", "long_name": "end time of the collapse over sqrt(h0/g)"}),
    "at_rest": ("at_rest", {"units": "1", "long_name": "1: the run went on to rest, 0: it stopped at "
                                                       "max_duration still moving, NaN: fixed end time"}),
}


def one_row_per_run(summary) -> "xarray.Dataset":  # noqa: F821
    """The summary over (aspect_ratio, mu_r, seed) only: each check variable becomes one variable per
    value of its own dimension, e.g. mass_front_over_r0_0.95 (for a CSV with a row per run)."""
    flat = summary.drop_vars([name for name in CHECK_VARIABLES if name in summary])
    for name, dim in CHECK_VARIABLES.items():
        if name in summary:
            for value in summary[dim].values:
                flat[f"{name}_{value:g}"] = summary[name].sel({dim: value}, drop=True)
    return flat.drop_dims([dim for dim in CHECK_VARIABLES.values() if dim in flat.dims])


def collect_analyses(analyses) -> "xarray.Dataset":  # noqa: F821
    """Stack analysis datasets by their (aspect_ratio, mu_r, seed); NaN where a run is missing."""
    import xarray as xr

    if not analyses:
        raise ValueError("no analysis files to collect")
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

    data = {name: (dims, grid(lambda a, name=name: float(a[name].values)), dict(analyses[0][name].attrs))
            for name in SUMMARY_VARIABLES}
    coords = {}
    reference = analyses[0]
    for name, dim in CHECK_VARIABLES.items():
        if all(name in a and np.array_equal(a[dim].values, reference[dim].values) for a in analyses):
            data[name] = (dims + (dim,), grid(lambda a, name=name: a[name].values, (reference.sizes[dim],)),
                          dict(reference[name].attrs))
            coords[dim] = reference[dim]
    for name, (variable, attrs) in RUN_ATTRIBUTES.items():
        data[variable] = (dims, grid(lambda a, name=name: float(a.attrs.get(name, np.nan))), dict(attrs))
    coords |= {
        "aspect_ratio": ("aspect_ratio", ratios, {"units": "1", "long_name": "aspect ratio h0/r0"}),
        "mu_r": ("mu_r", mu_rs, {"units": "1", "long_name": "rolling resistance coefficient"}),
        "seed": ("seed", seeds, {"units": "1", "long_name": "packing seed"}),
    }
    first = analyses[0].attrs
    attrs = {"r0": float(first["r0"]), "mu": float(first["mu"]),
             "run_configs": json.dumps([json.loads(a.attrs.get("config", "{}")) for a in analyses])}
    return xr.Dataset(data, coords=coords, attrs=attrs)
