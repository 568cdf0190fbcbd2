"""A study's runs as one xarray Dataset: every run's analysis (or trajectory) stacked along a `run`
dimension with its aspect_ratio, mu_r, seed, r0, friction_law, rolling_lever and steps as
coordinates, for fronts, profiles and histories across runs without globbing hashed folders by hand.

    import colsim.study
    runs = colsim.study.open_runs(study="tiny")                   # the runs results/tiny/summary.nc collected
    runs.front_position.plot.line(x="scaled_time", hue="mu_r")    # over (run, scaled_time)

A study (its name, or its configuration file) picks the runs its summary collected; without one,
every run below the results folder, whichever study made it, and each of its analyses (one a set of
analysis settings: analysis_KEY.nc; analysis.nc in older studies). Frames are aligned on t/sqrt(h0/g)
(`scaled_time`), rounded to 1e-9 so that the frames of runs of one time step fall on the same values
(a frame's time is a sum of steps, 0.39999999999999997 in one run and 0.4 in the next); a run that has
no frame at a time holds NaN there. A deposit profile is on one grid of r/r0 (`radial_bin_over_r0`),
the finest run's bins over the widest deposit: each grid point the height of the run's bin it lies
in, 0 beyond the run's main mass. Trajectories (collapse.nc) stack with `particle` padded by NaN to the largest column.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import xarray as xr

from .. import io
from ..engine.state import LEVER_OF_OLDER_FILES

#: where a run's files lie below a results folder (docs/study-config.md, "Run folders and their keys")
RUN_FILES = "r0_*/seed_*/pack_*/a_*/mu_r_*/run_*/{name}"
#: a run's analyses: one a key of analysis settings (analysis_KEY.nc), or one analysis.nc (older studies)
ANALYSIS_FILES = ("analysis.nc", "analysis_??????????.nc")
RUN_DEPTH = 7   # the parts of RUN_FILES
KINDS = {"analysis.nc": io.ANALYSIS_KIND, "collapse.nc": io.TRAJECTORY_KIND}
#: the decimals scaled_time is rounded to, far below any time step (dt/sqrt(h0/g) >= 1e-6)
TIME_DECIMALS = 9
#: what tells runs of one column apart beyond (aspect_ratio, mu_r, seed, r0): from each file's attributes
RUN_VALUES = {"aspect_ratio": "aspect ratio h0/r0", "mu_r": "rolling resistance coefficient",
              "seed": "packing seed", "r0": "initial column radius", "friction_law": "friction law",
              "rolling_lever": "rolling lever", "n_steps": "time steps of the collapse"}


def open_runs(results="results", name: str = "analysis.nc", study=None) -> xr.Dataset:
    """The runs' `name` (analysis.nc or collapse.nc) along a dimension `run` (coordinates those of
    :data:`RUN_VALUES` and path), frames on a common scaled_time, profiles on a common r/r0 grid.

    study: a study's name (its summary is results/STUDY/summary.nc) or its configuration file (a
    .yaml, whose `study` key names it): the runs that study's summary collected; None: every run below
    `results`. A ValueError when there is none."""
    if name not in KINDS:
        raise ValueError(f"open_runs reads {' or '.join(KINDS)}, not {name!r}")
    names = ANALYSIS_FILES if name == "analysis.nc" else (name,)
    paths = sorted(p for file in names for p in Path(results).glob(RUN_FILES.format(name=file))) \
        if study is None else study_runs(results, study, name)
    if not paths:
        raise ValueError(f"no {name} under {results}/{RUN_FILES.format(name='')}")
    runs = [_one_run(io.open_dataset(path, KINDS[name]), path) for path in paths]
    if name == "analysis.nc":
        runs = _on_one_grid(runs)
    return xr.concat(runs, dim="run", join="outer", coords="different", compat="equals",
                     combine_attrs="drop_conflicts")


def study_runs(results, study, name: str = "analysis.nc") -> list[Path]:
    """The files `name` of the runs a study's summary collected (its `colsim collect` inputs), below
    `results`. study: its name, or its configuration file."""
    if str(study).endswith((".yaml", ".yml")):
        import yaml

        with open(study) as stream:
            study = (yaml.safe_load(stream) or {}).get("study", "")
    summary = Path(results) / study / "summary.nc" if study else Path(results) / "summary.nc"
    if not summary.is_file():
        raise ValueError(f"no summary of study {study!r} at {summary}: run the study (snakemake) first")
    with xr.open_dataset(summary) as dataset:
        inputs = json.loads(dataset.attrs.get("config", "{}")).get("inputs", [])
    paths = [Path(results, *Path(path).parts[-RUN_DEPTH:]) for path in inputs]   # the analyses it collected
    paths = paths if name == "analysis.nc" else [path.with_name(name) for path in paths]
    missing = [str(path) for path in paths if not path.is_file()]
    if missing:
        raise ValueError(f"{summary} collected runs whose {name} is missing: {', '.join(missing[:3])}")
    return paths


def _one_run(dataset: xr.Dataset, path: Path) -> xr.Dataset:
    """One run, its frames indexed by scaled_time (rounded), its particles by their index, with a run
    dimension of one and its values as coordinates along it."""
    values = {"friction_law": "associated", "rolling_lever": LEVER_OF_OLDER_FILES}   # what older files meant
    values |= {key: dataset.attrs[key] for key in RUN_VALUES if key in dataset.attrs}
    dataset = dataset.drop_vars([key for key in values if key in dataset.coords])
    if "scaled_time" in dataset.coords and "time" in dataset.dims:
        rounded = np.round(dataset["scaled_time"].values, TIME_DECIMALS)
        dataset = dataset.assign_coords(scaled_time=("time", rounded, dataset["scaled_time"].attrs))
        dataset = dataset.swap_dims(time="scaled_time")
    if "particle" in dataset.dims and "particle" not in dataset.coords:
        dataset = dataset.assign_coords(particle=("particle", np.arange(dataset.sizes["particle"]),
                                                  {"units": "1", "long_name": "particle index"}))
    run = dataset.expand_dims("run")
    coords = {key: ("run", [value], {"long_name": RUN_VALUES[key]}) for key, value in values.items()}
    coords["path"] = ("run", [str(path)], {"long_name": "the run's file"})
    return run.assign_coords(coords)


def _on_one_grid(runs: list[xr.Dataset]) -> list[xr.Dataset]:
    """The runs' deposit profiles on one grid of r/r0, the bin centres of the finest run's width over
    the widest deposit: a grid point takes the height of the run's bin it lies in (a bin's height is
    its highest grain), NaN where that bin is empty, 0 beyond the run's last bin (no grain of its main
    mass lies there)."""
    widths = [_bin_width(run) for run in runs if "radial_bin" in run.dims]
    if not widths:
        return runs
    width = min(widths)
    widest = max(float(run.radial_bin.values[-1] / run.r0.values[0]) for run in runs if "radial_bin" in run.dims)
    grid = np.round((np.arange(int(np.rint(widest / width + 0.5))) + 0.5) * width, TIME_DECIMALS)
    return [_profiles_on(run, grid) if "radial_bin" in run.dims else run for run in runs]


def _bin_width(run: xr.Dataset) -> float:
    """A run's profile bin width over r0 (its bins start at the axis)."""
    return 2 * float(run.radial_bin.values[0] / run.r0.values[0])


def _profiles_on(run: xr.Dataset, grid: np.ndarray) -> xr.Dataset:
    """`run` with its variables over radial_bin moved to `grid` (r/r0)."""
    which = np.floor(grid / _bin_width(run)).astype(int)
    inside = which < run.sizes["radial_bin"]
    moved = {}
    for key, variable in run.data_vars.items():
        if "radial_bin" not in variable.dims:
            continue
        values = variable.transpose(..., "radial_bin").values
        on_grid = np.where(inside, values[..., np.minimum(which, values.shape[-1] - 1)], 0.0)
        dims = tuple(d for d in variable.dims if d != "radial_bin") + ("radial_bin_over_r0",)
        moved[key] = (dims, on_grid, variable.attrs)
    run = run.drop_dims("radial_bin").assign(moved)
    return run.assign_coords(radial_bin_over_r0=("radial_bin_over_r0", grid,
                                                 {"units": "1", "long_name": "distance from the axis over r0"}))
