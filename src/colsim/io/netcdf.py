"""Reading and writing colsim's netCDF files through xarray.

Every file is CF-style: global `Conventions`, `title`, `source` ("colsim X.Y"), `history`, the
versions of colsim, Clarabel and numpy, the run's configuration as JSON in `config` and its `seed`;
every variable has `units` and `long_name`; `colsim_commit` names the git commit of the source
that wrote the file (" (modified)" when its tracked files differed from it), where colsim runs from
a git checkout. The simulation's lengths, times and masses are in SI
units (`unit_system`): gravity 9.81 makes lengths metres and times seconds, and the density (in
kg m-3) makes masses kilograms; scaled quantities (over r0, t/sqrt(h0/g)) have units "1". Wall-clock
times are "s" too, and their long names say "wall-clock".
Files are written to a temporary name beside the target and renamed
when complete, so a killed run never leaves a file that looks finished.
"""
from __future__ import annotations

import contextlib
import functools
import importlib.metadata
import json
import os
import tempfile
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import xarray as xr

from .. import __version__
from ..engine.state import ParticleState
from ..engine.warm_start import WarmStart
from . import checks
from .git import git_state

STATE_KIND = "particle-state"
TRAJECTORY_KIND = "collapse-trajectory"
ANALYSIS_KIND = "collapse-analysis"

PARTICLE_VARIABLES = {
    "position": ("length", "particle centre position"),
    "velocity": ("length/time", "particle velocity"),
    "angular_velocity": ("rad/time", "particle angular velocity"),
}


#: dimensions that the stages write as units; :func:`write_dataset` turns each into units "1" and a comment
#: the units colsim's code writes (dimensions) and the SI units they are stored with
SI_UNITS = {"length": "m", "time": "s", "length/time": "m s-1", "rad/time": "rad s-1",
            "length/time^2": "m s-2", "mass": "kg", "mass/length^3": "kg m-3",
            "mass length/time^2": "kg m s-2", "mass length^2/time^2": "kg m2 s-2"}
UNIT_SYSTEM = ("SI: with gravity 9.81 m s-2 (the default) lengths are metres (particle diameters 0.25-0.5 m "
               "by default) and times seconds; masses are kilograms for the density in kg m-3 (1 by default); "
               "dimensionless and scaled quantities (over r0, t/sqrt(h0/g)) have units '1'")


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
    found = {"aspect_ratio": ("1", "aspect ratio h0/r0"), "mu_r": ("1", "rolling resistance coefficient"),
             "seed": ("1", "packing seed"), "r0": ("length", "cylinder radius")}
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


class InputError(ValueError):
    """An input file that is missing, unreadable or of the wrong kind."""


@contextlib.contextmanager
def atomic_path(path):
    """Yield a temporary path beside `path`; rename it to `path` only if the block succeeds."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part", dir=path.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


def write_all(writers: dict) -> None:
    """All or nothing: writers maps each output path to a callable that writes it to the path it is
    given. Each writes to a temporary name beside its path (:func:`atomic_path`); the files are
    renamed into place, in the dict's order, only once every one of them is complete, so a failure
    leaves none of them new."""
    with contextlib.ExitStack() as stack:   # exits last-entered first: enter in reverse order
        temporaries = {path: stack.enter_context(atomic_path(path)) for path in reversed(list(writers))}
        for path, write in writers.items():
            write(temporaries[path])


def check_writable(path, directory: bool = False) -> None:
    """InputError (one line) unless a file `path` (or files in the directory `path`) can be written:
    the nearest existing folder on the way must take a new file. Leaves nothing behind."""
    path = Path(path)
    if path.is_dir() != directory and path.exists():
        raise InputError(f"cannot write {path}: it is {'not ' if directory else ''}a directory")
    folder = path if directory else path.parent
    while not folder.exists():
        folder = folder.parent
    if not folder.is_dir():
        raise InputError(f"cannot write {path}: {folder} is not a directory")
    try:
        fd, probe = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".probe", dir=folder)
    except OSError as error:
        raise InputError(f"cannot write {path}: {folder} takes no new files ({error.strerror})") from None
    os.close(fd)
    os.remove(probe)


def global_attributes(kind: str, title: str, config: dict, seed=None) -> dict:
    """CF global attributes with colsim's version, the configuration (JSON) and the seed."""
    attrs = {
        "Conventions": "CF-1.8",
        "title": title,
        "source": f"colsim {__version__}",
        "history": f"{datetime.now(timezone.utc).isoformat(timespec='seconds')} created by colsim {__version__}",
        "colsim_kind": kind,
        "config": json.dumps(config, sort_keys=True, default=_json_default),
        "unit_system": UNIT_SYSTEM,
        **versions(),
    }
    if seed is not None:
        attrs["seed"] = int(seed)
    return attrs


def versions() -> dict:
    """{colsim_version, colsim_commit, clarabel_version, numpy_version} of this process (installed
    distributions; the commit from :func:`source_commit`)."""
    found = {"colsim_version": __version__, "colsim_commit": source_commit(), "numpy_version": np.__version__}
    try:
        found["clarabel_version"] = importlib.metadata.version("clarabel")
    except importlib.metadata.PackageNotFoundError:
        found["clarabel_version"] = "not installed"
    return found


@functools.lru_cache(maxsize=1)
def source_commit() -> str:
    """The git commit of the checkout colsim's source lies in, with " (modified)" when its tracked
    files differ from it; "unknown (not a git checkout)" for an installed copy or without git.
    Asked once a process: a run's files all name the code it started with."""
    state = git_state(Path(__file__).parent)
    if not state["commit"]:
        return "unknown (not a git checkout)"
    return state["commit"] + (" (modified)" if state["dirty"] else "")


def cf_units(dataset):
    """`dataset` with every variable's dimension ("length", "mass/length^3", ...) written as its SI
    unit (:data:`SI_UNITS`, UDUNITS strings), text variables given units "1" (CF leaves their units
    free; colsim gives every variable some), and the unit system in the global attributes."""
    for variable in dataset.variables.values():
        dimension = variable.attrs.get("units")
        if dimension in SI_UNITS:
            variable.attrs["units"] = SI_UNITS[dimension]
        elif dimension is None and variable.dtype.kind in "OUS":
            variable.attrs["units"] = "1"
    dataset.attrs["unit_system"] = UNIT_SYSTEM
    return dataset


def _json_default(value):
    if isinstance(value, (np.integer, np.floating)):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"cannot store {type(value).__name__} in the configuration")


def write_dataset(dataset, path) -> None:
    """Write an xarray Dataset to netCDF4 atomically, its units made CF (:func:`cf_units`)."""
    with atomic_path(path) as tmp:
        write_netcdf(dataset, tmp)


LABEL_SUFFIX = "_label"


def cf_labels(dataset):
    """`dataset` with each dimension labelled by text (law: 'lube', 'lajeunesse') as CF-1.8 has it:
    a coordinate variable must be numeric, so the labels become the auxiliary coordinate
    DIM_label along the dimension, which has no coordinate variable (:func:`labels_as_index` puts
    them back; in plain xarray, ``ds.swap_dims(law="law_label")``)."""
    text = [name for name in dataset.dims if name in dataset.coords and dataset[name].dtype.kind in "OUS"]
    if not text:
        return dataset
    return dataset.drop_indexes(text).rename_vars({name: name + LABEL_SUFFIX for name in text})


def labels_as_index(dataset):
    """The inverse of :func:`cf_labels`: each DIM_label along a dimension DIM without a coordinate
    variable becomes DIM's index again, so that ``.sel(law="lube")`` works."""
    for name in list(dataset.coords):
        dim = name[: -len(LABEL_SUFFIX)]
        if name.endswith(LABEL_SUFFIX) and dataset[name].dims == (dim,) and dim not in dataset.coords:
            dataset = dataset.rename_vars({name: dim}).set_xindex(dim)
    return dataset


def write_netcdf(dataset, path) -> None:
    """Write an xarray Dataset to netCDF4 at `path` as it is (no temporary name), units and text
    labels made CF (:func:`cf_units`, :func:`cf_labels`)."""
    dataset = cf_units(cf_labels(dataset.copy()))
    encoding = cf_encoding(dataset)
    for name, variable in dataset.variables.items():   # CF: flag_values of the type stored
        if "flag_values" in variable.attrs:
            stored = encoding.get(name, {}).get("dtype", variable.dtype)
            variable.attrs["flag_values"] = np.asarray(variable.attrs["flag_values"], dtype=stored)
    dataset.to_netcdf(path, engine="netcdf4", encoding=encoding)


INT32 = np.iinfo(np.int32)


def cf_encoding(dataset) -> dict:
    """The encodings that keep a file CF-1.8: 64-bit integers stored as 32-bit ones (CF-1.8 has no
    int64; colsim's counts, steps and indices fit), and no _FillValue on a coordinate (xarray gives
    every float one; CF forbids missing values in coordinate variables)."""
    encoding = {}
    for name, variable in dataset.variables.items():
        wanted = {}
        if variable.dtype == np.int64:
            values = variable.values
            if values.size and (values.min() < INT32.min or values.max() > INT32.max):
                raise ValueError(f"{name} holds integers beyond 32 bits, which CF-1.8 cannot store")
            wanted["dtype"] = "int32"
        if name in dataset.coords and variable.dtype.kind == "f":
            wanted["_FillValue"] = None
        if wanted:
            encoding[name] = wanted
    return encoding


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
        lazy = xr.open_dataset(path, engine="netcdf4")
    except Exception as error:  # netCDF4 raises OSError, ValueError, ... for foreign files
        raise InputError(f"input file {path} is not a readable netCDF file ({error})") from None
    with lazy:
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


def config_of(dataset) -> dict:
    """The configuration stored in a colsim dataset's attributes."""
    return json.loads(dataset.attrs.get("config", "{}"))


def state_dataset(state: ParticleState, attrs: dict, extra: dict | None = None):
    """An xarray Dataset holding one particle state (dims particle, xyz)."""
    data = {
        name: (("particle", "xyz"), getattr(state, name), {"units": units, "long_name": long_name})
        for name, (units, long_name) in PARTICLE_VARIABLES.items()
    }
    data["radius"] = ("particle", state.radius, {"units": "length", "long_name": "particle radius"})
    for name, (dims, values, var_attrs) in (extra or {}).items():
        data[name] = (dims, values, var_attrs)
    dataset = xr.Dataset(data, coords=component_coordinate(), attrs=dict(attrs))
    dataset.attrs["density"] = float(state.density)
    dataset.attrs["time"] = float(state.time)
    return dataset


def component_coordinate() -> dict:
    """The labels of the dimension xyz: an auxiliary coordinate `component` ("x", "y", "z"; CF labels),
    not a coordinate variable named xyz (CF's coordinate variables are numeric and monotonic)."""
    return {"component": ("xyz", np.array(["x", "y", "z"], dtype=object),
                          {"units": "1", "long_name": "Cartesian component"})}


def state_from_dataset(dataset, frame: int | None = None) -> ParticleState:
    """The particle state of a state dataset, or of frame `frame` of a trajectory dataset."""
    pick = (lambda v: v.values) if frame is None else (lambda v: v.isel(time=frame).values)
    time = float(dataset.attrs.get("time", 0.0)) if frame is None else float(dataset["time"].values[frame])
    return ParticleState(
        position=pick(dataset["position"]), velocity=pick(dataset["velocity"]),
        angular_velocity=pick(dataset["angular_velocity"]), radius=dataset["radius"].values,
        density=float(dataset.attrs.get("density", 1.0)), time=time,
    )


def write_state(path, state: ParticleState, attrs: dict, extra: dict | None = None) -> None:
    write_dataset(state_dataset(state, attrs, extra), path)


def read_state(path) -> tuple[ParticleState, object]:
    """(state, dataset) of a particle-state file, its geometry checked (:func:`check_geometry`)."""
    dataset = open_dataset(path, STATE_KIND)
    try:
        state = state_from_dataset(dataset)
    except KeyError as error:
        raise InputError(f"input file {path} lacks the variable {error}") from None
    except ValueError as error:   # a radius <= 0, arrays of the wrong shape
        raise InputError(f"input file {path}: {error}") from None
    check_geometry(state, dataset, path)
    return state, dataset


OVERLAP_TOLERANCE = 0.01   # of the smallest diameter: the stepper's own (StepSettings.overlap_tolerance)


def stated_diameters(dataset) -> tuple[float, float] | None:
    """(diameter_min, diameter_max) from the configuration chain of a file (the packing's), or None."""
    config = config_of(dataset)
    while config:
        if "diameter_min" in config and "diameter_max" in config:
            return float(config["diameter_min"]), float(config["diameter_max"])
        config = config.get("input_config") or {}
    return None


def check_geometry(state: ParticleState, dataset, path) -> None:
    """InputError naming the first offending sphere unless the spheres are a possible column: at
    least one; finite positions, velocities and radii; diameters within the file's stated range;
    nothing below the floor or (r0 given) outside the cylinder, and no two spheres overlapping, by
    more than 1 % of the smallest diameter (the stepper's own tolerance; the deepest pair is named)."""
    from ..engine.contacts import overlaps
    from ..engine.state import Walls

    if state.n == 0:
        raise InputError(f"input file {path} holds no spheres")
    for name in ("position", "velocity", "angular_velocity", "radius"):
        bad = ~np.isfinite(getattr(state, name).reshape(state.n, -1)).all(axis=1)
        if bad.any():
            raise InputError(f"input file {path}: sphere {int(np.argmax(bad))} has a non-finite {name}")
    diameters = stated_diameters(dataset)
    if diameters is not None:
        low, high = (d * (1 + s * 1e-9) for d, s in zip(diameters, (-1, 1)))
        bad = (2 * state.radius < low) | (2 * state.radius > high)
        if bad.any():
            k = int(np.argmax(bad))
            raise InputError(f"input file {path}: sphere {k} has diameter {2 * state.radius[k]:g}, outside the "
                             f"stated {diameters[0]:g}-{diameters[1]:g}")
    tolerance = OVERLAP_TOLERANCE * 2 * float(state.radius.min())
    below = state.position[:, 2] - state.radius < -tolerance
    if below.any():
        k = int(np.argmax(below))
        raise InputError(f"input file {path}: sphere {k} reaches below the floor (z = {state.position[k, 2]:g},"
                         f" radius {state.radius[k]:g})")
    if "r0" in dataset.attrs:
        r0 = float(dataset.attrs["r0"])
        outside = np.hypot(state.position[:, 0], state.position[:, 1]) + state.radius > r0 + tolerance
        if outside.any():
            raise InputError(f"input file {path}: sphere {int(np.argmax(outside))} reaches outside the cylinder r0 = {r0:g}")
    pairs = overlaps(state, Walls(floor=False), tolerance).pairs
    if len(pairs[0]):
        gaps = (np.linalg.norm(state.position[pairs[1]] - state.position[pairs[0]], axis=1)
                - state.radius[pairs[0]] - state.radius[pairs[1]])
        k = int(np.argmin(gaps))
        i, j, gap = int(pairs[0][k]), int(pairs[1][k]), float(gaps[k])
        raise InputError(f"input file {path}: spheres {i} and {j} overlap by {-gap:g} (length), more than"
                         f" 1 % of the smallest diameter")


def contact_force_variables(forces: WarmStart) -> dict:
    """The variables (over dims contact, xyz) that store a stage's last contact forces, as `extra`
    for :func:`state_dataset`."""
    def variable(dims, values, units, long_name, **more):
        return (dims, values, {"units": units, "long_name": long_name, **more})

    return {
        "contact_first": variable("contact", forces.i, "1", "first particle of the contact pair"),
        "contact_second": variable("contact", forces.j, "1", "second particle of the contact pair",
                                   comment="-1: a wall (see contact_family)"),
        "contact_family": variable("contact", forces.family, "1", "kind of contact",
                                   flag_values=np.array([0, 1, 2]), flag_meanings="particle floor cylinder"),
        "contact_force": variable(("contact", "xyz"), forces.force, "mass length/time^2",
                                  "contact force of the pair (normal from the first to the second body)"),
        "contact_rolling_force": variable(("contact", "xyz"), forces.rolling, "mass length/time^2",
                                          "rolling resistance of the pair (moment over the rolling radius)"),
    }


def contact_forces_of(dataset) -> WarmStart | None:
    """The contact forces stored by :func:`contact_force_variables`, or None (older files);
    InputError if they name spheres the file does not hold or are not finite."""
    if "contact_force" not in dataset:
        return None
    arrays = [dataset[name].values for name in ("contact_first", "contact_second", "contact_family",
                                                 "contact_force", "contact_rolling_force")]
    n = dataset.sizes.get("particle", 0)
    try:
        checks.check_contacts(*arrays, n=n, fixed=n)
    except checks.FileProblem as problem:
        source = dataset.encoding.get("source", "the input file")
        raise InputError(f"input file {source}: {problem}") from None
    first, second, family, force, rolling = arrays
    return WarmStart(first.astype(np.int64), second.astype(np.int64), family.astype(np.int64), force, rolling)
