"""colsim's netCDF files through xarray: their kinds, the particle variables, the at-rest flag, and
reading a file back (:func:`open_dataset`), the one place that also reads the files of older
versions (their text coordinates, their at_rest). Writing: :mod:`.cf`, :mod:`.provenance`,
:mod:`.files`; the state file: :mod:`.state_file`.

The files in general:

Every file is CF-style: global `Conventions`, `title`, `source` ("colsim X.Y"), `history`, the
versions of colsim, Clarabel and numpy, the run's configuration as JSON in `config` and its `seed`;
every variable has `units` and `long_name`; `colsim_commit` names the git commit of the source
that wrote the file (" (modified)" when its code, not a study's configuration, differed from it),
where colsim runs from a git checkout. The simulation's lengths, times and masses are in SI
units (`unit_system`): gravity 9.81 makes lengths metres and times seconds, and the density (in
kg m-3) makes masses kilograms; scaled quantities (over r0, t/sqrt(h0/g)) have units "1". Wall-clock
times are "s" too, and their long names say "wall-clock".
Files are written to a temporary name beside the target and renamed
when complete, so a killed run never leaves a file that looks finished.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import xarray as xr

from . import checks
from .cf import SI_UNITS, labels_as_index, time_as_index
from .files import InputError

STATE_KIND = "particle-state"


TRAJECTORY_KIND = "collapse-trajectory"


ANALYSIS_KIND = "collapse-analysis"


PARTICLE_VARIABLES = {
    "position": ("length", "particle centre position"),
    "velocity": ("length/time", "particle velocity"),
    "angular_velocity": ("rad/time", "particle angular velocity"),
}


#: whether a run came to rest: a CF flag variable (int8, never a float with NaN) in trajectories,
#: analyses and summaries. not_checked: a fixed end time (no max_duration), or no run (a summary's gap)
AT_REST_FLAGS = {"not_checked": -1, "still_moving": 0, "at_rest": 1}


def at_rest_variable(dims, values) -> tuple:
    """The (dims, values, attrs) of an `at_rest` flag variable (:data:`AT_REST_FLAGS`)."""
    return (dims, np.asarray(values, dtype=np.int8),
            {"units": "1", "long_name": "whether the run came to rest before its end",
             "flag_values": np.array(list(AT_REST_FLAGS.values()), dtype=np.int8),
             "flag_meanings": " ".join(AT_REST_FLAGS)})


def run_coordinates(attrs) -> dict:
    """The run's swept values as scalar coordinates (aspect_ratio, mu_r, seed, r0), so that xarray
    combines many runs' files along a new dimension by them (:func:`colsim.study.runs.open_runs`)."""
    channel = attrs.get("geometry") == "channel"
    found = {"aspect_ratio": ("1", "aspect ratio H0/L0" if channel else "aspect ratio h0/r0"),
             "mu_r": ("1", "rolling resistance coefficient"), "seed": ("1", "packing seed"),
             "r0": ("length", "the channel's box length L0 (r0's role)" if channel else "cylinder radius")}
    return {name: ((), int(attrs[name]) if name == "seed" else float(attrs[name]), {"units": units, "long_name": long})
            for name, (units, long) in found.items() if name in attrs}


def at_rest_flag(dataset) -> int:
    """The at_rest flag (:data:`AT_REST_FLAGS`) of a trajectory or analysis: its `at_rest` variable,
    or in files written before the variable existed the attribute (0 or 1, absent when not checked)."""
    if "at_rest" in dataset.variables:
        return int(dataset["at_rest"].values)
    if "at_rest" in dataset.attrs:
        return int(bool(int(dataset.attrs["at_rest"])))
    return AT_REST_FLAGS["not_checked"]


#: the units colsim stores the particle variables in (an input in others is refused, not converted)
PARTICLE_UNITS = {**{name: SI_UNITS[units] for name, (units, _) in PARTICLE_VARIABLES.items()},
                  "radius": SI_UNITS["length"]}


def open_dataset(path, kind: str):
    """Open a colsim netCDF file and check that it holds `kind`, within the bounds of
    :mod:`colsim.io.checks` (its size before reading it, its attributes, units, a trajectory's
    frames); InputError (one line) otherwise."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"input file {path} does not exist")
    try:
        checks.check_header(path, kind)        # before netCDF or xarray decode anything
    except checks.FileProblem as problem:
        raise InputError(f"input file {path}: {problem}") from None
    except Exception as error:  # netCDF4 raises OSError, ValueError, ... for foreign files
        raise InputError(f"input file {path} is not a readable netCDF file ({error})") from None
    try:
        stored = xr.open_dataset(path, engine="netcdf4")
    except Exception as error:  # netCDF4 raises OSError, ValueError, ... for foreign files
        raise InputError(f"input file {path} is not a readable netCDF file ({error})") from None
    with stored:
        lazy = time_as_index(stored)
        found = lazy.attrs.get("colsim_kind")
        if found != kind:
            raise InputError(f"input file {path} holds {found or 'no colsim data'!r}, expected {kind!r}")
        try:
            checks.check_size(lazy, kind)          # before anything is read into memory
            checks.check_attributes(lazy.attrs)
            checks.check_units(lazy, PARTICLE_UNITS)
            dataset = lazy.load()
            if kind == TRAJECTORY_KIND:
                checks.check_trajectory(dataset)
        except checks.FileProblem as problem:
            raise InputError(f"input file {path}: {problem}") from None
    return labels_as_index(dataset)
