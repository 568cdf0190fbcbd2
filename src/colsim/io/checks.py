"""What an input file must hold before any command uses it: one line naming the first
thing wrong, never a traceback, silent nonsense or a huge allocation.

- The header, before netCDF or xarray decode anything (:func:`check_header`): how many objects and
  attributes it holds (counted by HDF5, :mod:`.header`), their attributes' total size, each
  variable's type, and the memory its variables would take once decoded, against the file's kind
  and against its size on disk (colsim writes its files uncompressed: a 64 kB file declaring 8 GB
  is refused).
- Size: the memory its variables would take once read is bounded per kind (a 33 kB analysis file
  declaring a dimension of 10^8 values made `collect` allocate 6 GiB).
- Attributes: the numbers colsim reads (r0, h0, aspect_ratio, mu_r, gravity, density, ...) are
  finite scalars of their range, a seed an integer in 0..2^32-1, `config` a JSON object.
- Units: the particle variables are stored in the units colsim writes (a position in mm is not read
  as metres).
- Contact forces: indices that name spheres of the file, finite forces.
- Trajectories: at least one frame, finite positions, positive radii.
"""
from __future__ import annotations

import json
import os

import numpy as np

from . import header

#: the most bytes the variables of one file of each kind may take once read
MAX_BYTES = {"collapse-analysis": 256 * 2**20, "particle-state": 8 * 2**30, "collapse-trajectory": 64 * 2**30}
#: the largest sizes of an analysis's own dimensions (contact tolerances, mass shares, profile bins)
MAX_ANALYSIS_DIMENSION = 100_000
#: numeric attributes colsim reads -> whether they must be positive (else >= 0)
NUMERIC_ATTRIBUTES = {"r0": True, "h0": True, "aspect_ratio": True, "gravity": True, "density": True,
                      "mu": False, "mu_r": False, "time": False}


#: the most objects (variables, dimensions) a file's root group, and attributes one object, may hold:
#: colsim's files hold about 30 of each
MAX_OBJECTS = 1000
MAX_ATTRIBUTES = 1000
#: the most bytes a file's attributes may hold together (a run's configuration is a few kB)
MAX_ATTRIBUTE_BYTES = 16 * 2**20
#: what a file's values may take once decoded, beyond its size on disk: an integer decoded to float64
#: takes 8 times its byte, and a small file's header and labels some room
DECODED_PER_BYTE_ON_DISK = 8
DECODED_ALLOWANCE = 2**20


class FileProblem(ValueError):
    """What is wrong with an input file (the caller adds the file's name)."""


def check_header(path, kind: str) -> None:
    """FileProblem (within a second, whatever the file declares) unless the netCDF-4 file `path` holds
    at most MAX_OBJECTS objects and MAX_ATTRIBUTES attributes on each, MAX_ATTRIBUTE_BYTES of
    attributes, variables of numbers or text only, and values that once decoded take no more than
    MAX_BYTES[kind] nor DECODED_PER_BYTE_ON_DISK times the file's size (+ DECODED_ALLOWANCE).
    Nothing but the header is read."""
    import netCDF4

    if not header.is_hdf5(path):
        raise FileProblem("it is not a readable netCDF file: not netCDF-4, which colsim writes and reads")
    counts = header.attribute_counts(path, MAX_OBJECTS)
    if counts is not None:
        objects, own, most = counts
        if objects > MAX_OBJECTS:
            raise FileProblem(f"it holds {objects:,} variables and dimensions, more than a colsim file may"
                              f" ({MAX_OBJECTS:,})")
        if max(own, most) > MAX_ATTRIBUTES:
            raise FileProblem(f"it holds {max(own, most):,} attributes on one object, more than a colsim file"
                              f" may ({MAX_ATTRIBUTES:,})")
    with netCDF4.Dataset(path) as dataset:
        dataset.set_auto_mask(False)
        variables = list(dataset.variables.values())
        if len(variables) > MAX_OBJECTS:
            raise FileProblem(f"it holds {len(variables):,} variables, more than a colsim file may ({MAX_OBJECTS:,})")
        attributes = [dataset.__dict__] + [variable.__dict__ for variable in variables]
        if max(len(each) for each in attributes) > MAX_ATTRIBUTES:
            raise FileProblem(f"it holds more than {MAX_ATTRIBUTES:,} attributes on one object")
        size = sum(_bytes_of(value) for each in attributes for value in each.values())
        if size > MAX_ATTRIBUTE_BYTES:
            raise FileProblem(f"its attributes hold {size / 2**20:.3g} MiB, more than a colsim file's may"
                              f" ({MAX_ATTRIBUTE_BYTES / 2**20:g} MiB)")
        decoded = sum(_decoded_bytes(variable) for variable in variables)
    limit = min(MAX_BYTES.get(kind, np.inf),
                DECODED_PER_BYTE_ON_DISK * os.path.getsize(path) + DECODED_ALLOWANCE)
    if decoded > limit:
        raise FileProblem(f"its variables would take {decoded / 2**30:.3g} GiB once read, more than a {kind} file"
                          f" of {os.path.getsize(path) / 2**20:.3g} MiB may ({limit / 2**30:.3g} GiB): colsim"
                          " writes its files uncompressed, and never declares more values than it holds")


def _bytes_of(value) -> int:
    """The bytes an attribute's value takes."""
    return len(value.encode()) if isinstance(value, str) else int(np.asarray(value).nbytes)


def _decoded_bytes(variable) -> int:
    """The bytes a netCDF4 variable takes once xarray decodes it (an integer with a fill value or a
    scale becomes float64); FileProblem if it holds neither numbers nor text."""
    elements = int(np.prod(variable.shape, dtype=np.float64))
    if variable.dtype is str:   # text labels (variable-length strings)
        return 8 * elements
    dtype = variable.datatype
    if not isinstance(dtype, np.dtype) or dtype.kind not in "iufbS":
        raise FileProblem(f"its variable {variable.name} is of type {dtype}, which colsim does not read")
    scaled = dtype.kind in "iub" and {"_FillValue", "missing_value", "scale_factor", "add_offset"} & set(
        variable.ncattrs())
    return elements * (8 if scaled else dtype.itemsize)


def check_size(dataset, kind: str) -> None:
    """FileProblem if the variables would take more than MAX_BYTES[kind] once read."""
    total = sum(int(np.prod(v.shape, dtype=np.float64)) * v.dtype.itemsize for v in dataset.variables.values())
    limit = MAX_BYTES.get(kind)
    if limit is not None and total > limit:
        raise FileProblem(f"its variables would take {total / 2**30:.3g} GiB once read, more than a {kind} file"
                          f" may ({limit / 2**30:g} GiB)")
    if kind == "collapse-analysis":
        for name, size in dataset.sizes.items():
            if size > MAX_ANALYSIS_DIMENSION:
                raise FileProblem(f"its dimension {name} has {size:,} values (an analysis has at most"
                                  f" {MAX_ANALYSIS_DIMENSION:,})")


def check_attributes(attrs) -> None:
    """FileProblem naming the first attribute colsim reads that is not what it must be."""
    for name, positive in NUMERIC_ATTRIBUTES.items():
        if name not in attrs:
            continue
        value = np.asarray(attrs[name])
        if value.shape not in ((), (1,)) or value.dtype.kind not in "iuf":
            raise FileProblem(f"attribute {name} is {str(attrs[name])[:60]!r}, not one number: colsim reads one"
                              " finite number")
        number = float(value.reshape(-1)[0])
        if not np.isfinite(number) or number < 0 or (positive and number == 0):
            raise FileProblem(f"attribute {name} is {number:g}, not a {'positive' if positive else 'non-negative'}"
                              " finite number")
    if "seed" in attrs:
        seed = np.asarray(attrs["seed"])
        number = float(seed.reshape(-1)[0]) if seed.size == 1 and seed.dtype.kind in "iuf" else np.nan
        if not (np.isfinite(number) and number == int(number) and 0 <= number < 2**32):
            raise FileProblem(f"attribute seed {str(attrs['seed'])[:60]} is not an integer in 0..2^32-1")
    if "config" in attrs:
        try:
            config = json.loads(str(attrs["config"]))
        except ValueError:
            config = None
        if not isinstance(config, dict):
            raise FileProblem("attribute config is not a JSON object")


def check_units(dataset, expected: dict) -> None:
    """FileProblem if a variable of `expected` {name: units} is stored in other units."""
    for name, units in expected.items():
        if name in dataset.variables:
            found = dataset[name].attrs.get("units")
            if found is not None and found != units:
                raise FileProblem(f"variable {name} is in {found!r}; colsim reads {units!r} (convert the file)")


def check_contacts(first, second, family, force, rolling, n: int, fixed: int = 0) -> None:
    """FileProblem unless the contact arrays are of one length, name spheres 0..n-1 (second: also a
    wall, -1, or a fixed sphere, -2 - k for k < fixed) and hold finite forces."""
    m = len(first)
    if not all(len(array) == m for array in (second, family, force, rolling)):
        raise FileProblem("its contact variables differ in length")
    if m and (first.min() < 0 or first.max() >= n or second.max() >= n or second.min() < -1 - max(fixed, 0)):
        raise FileProblem(f"a contact names a sphere outside 0..{n - 1}")
    if not (np.all(np.isfinite(force)) and np.all(np.isfinite(rolling))):
        raise FileProblem("a contact force is not finite")


def check_trajectory(dataset) -> None:
    """FileProblem unless a trajectory has a frame, a step (where it has step diagnostics), finite
    positions, frame times finite and increasing, one at_rest flag, radii > 0, and r0, h0."""
    for name in ("position", "radius", "time"):
        if name not in dataset.variables:
            raise FileProblem(f"it lacks the variable {name!r}")
    if dataset.sizes.get("time", 0) < 1:
        raise FileProblem("it holds no frame")
    if "step" in dataset.dims and dataset.sizes["step"] < 1:
        raise FileProblem("it holds no step (its step diagnostics are empty)")
    if "at_rest" in dataset.variables and dataset["at_rest"].shape not in ((), (1,)):
        raise FileProblem(f"its at_rest flag has shape {dataset['at_rest'].shape}, not one value")
    if not np.all(np.isfinite(dataset["position"].values)):
        raise FileProblem("a position is not finite")
    time = dataset["time"].values
    if time.ndim != 1 or not np.all(np.isfinite(time)) or np.any(np.diff(time) <= 0):
        raise FileProblem("its frames' times are not finite and increasing")
    radius = dataset["radius"].values
    if radius.size == 0 or not np.all(np.isfinite(radius)) or radius.min() <= 0:
        raise FileProblem("it holds no spheres, or a radius that is not positive and finite")
    for name in ("r0", "h0"):
        if name not in dataset.attrs:
            raise FileProblem(f"it lacks the attribute {name}")
