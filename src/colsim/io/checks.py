"""What an input file must hold before any command uses it: one line naming the first
thing wrong, never a traceback, silent nonsense or a huge allocation.

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

import numpy as np

#: the most bytes the variables of one file of each kind may take once read
MAX_BYTES = {"collapse-analysis": 256 * 2**20, "particle-state": 8 * 2**30, "collapse-trajectory": 64 * 2**30}
#: the largest sizes of an analysis's own dimensions (contact tolerances, mass shares, profile bins)
MAX_ANALYSIS_DIMENSION = 100_000
#: numeric attributes colsim reads -> whether they must be positive (else >= 0)
NUMERIC_ATTRIBUTES = {"r0": True, "h0": True, "aspect_ratio": True, "gravity": True, "density": True,
                      "mu": False, "mu_r": False, "time": False}


class FileProblem(ValueError):
    """What is wrong with an input file (the caller adds the file's name)."""


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
    """FileProblem unless a trajectory has a frame, finite positions and radii > 0, and r0, h0 > 0."""
    for name in ("position", "radius", "time"):
        if name not in dataset.variables:
            raise FileProblem(f"it lacks the variable {name!r}")
    if dataset.sizes.get("time", 0) < 1:
        raise FileProblem("it holds no frame")
    if not np.all(np.isfinite(dataset["position"].values)):
        raise FileProblem("a position is not finite")
    radius = dataset["radius"].values
    if radius.size == 0 or not np.all(np.isfinite(radius)) or radius.min() <= 0:
        raise FileProblem("it holds no spheres, or a radius that is not positive and finite")
    for name in ("r0", "h0"):
        if name not in dataset.attrs:
            raise FileProblem(f"it lacks the attribute {name}")
