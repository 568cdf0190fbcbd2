"""A study's runs as one xarray Dataset: every run's analysis (or trajectory) under a results folder,
stacked along a `run` dimension with its aspect_ratio, mu_r, seed and r0 as coordinates, for fronts,
profiles and histories across runs without globbing hashed folders by hand.

    import colsim.study
    runs = colsim.study.open_runs("results")                      # every analysis.nc
    runs.front_position.where(runs.mu_r == 0.12, drop=True)       # over (run, scaled_time)

Frames are aligned on t/sqrt(h0/g) (`scaled_time`), which runs of one study share; a run that has no
frame at a time holds NaN there. The files carry the four values as scalar coordinates themselves,
so `xr.combine_nested([xr.load_dataset(p) for p in paths], concat_dim="run")` (or open_mfdataset,
with dask) works on files of one length too.
"""
from __future__ import annotations

from pathlib import Path

import xarray as xr

from .. import io

#: where a run's files lie below a results folder (docs/study-config.md, "Run folders and their keys")
RUN_FILES = "r0_*/seed_*/pack_*/a_*/mu_r_*/run_*/{name}"
KINDS = {"analysis.nc": io.ANALYSIS_KIND, "collapse.nc": io.TRAJECTORY_KIND}


def open_runs(results="results", name: str = "analysis.nc") -> xr.Dataset:
    """Every run's `name` (analysis.nc or collapse.nc) below `results`, along a dimension `run`
    (coordinates aspect_ratio, mu_r, seed, r0 and path), frames aligned on scaled_time; a
    ValueError when there is none."""
    if name not in KINDS:
        raise ValueError(f"open_runs reads {' or '.join(KINDS)}, not {name!r}")
    paths = sorted(Path(results).glob(RUN_FILES.format(name=name)))
    if not paths:
        raise ValueError(f"no {name} under {results}/{RUN_FILES.format(name='')}")
    runs = [_one_run(io.open_dataset(path, KINDS[name]), path) for path in paths]
    return xr.concat(runs, dim="run", join="outer", coords="different", compat="equals",
                     combine_attrs="drop_conflicts")


def _one_run(dataset: xr.Dataset, path: Path) -> xr.Dataset:
    """One run, its frames indexed by scaled_time, with a run dimension of one and its values as
    coordinates along it."""
    values = {name: dataset.attrs[name] for name in ("aspect_ratio", "mu_r", "seed", "r0") if name in dataset.attrs}
    dataset = dataset.drop_vars([name for name in values if name in dataset.coords])
    if "scaled_time" in dataset.coords and "time" in dataset.dims:
        dataset = dataset.swap_dims(time="scaled_time")
    run = dataset.expand_dims("run")
    coords = {name: ("run", [value], {"long_name": name.replace("_", " ")}) for name, value in values.items()}
    coords["path"] = ("run", [str(path)], {"long_name": "the run's file"})
    return run.assign_coords(coords)
