"""Reading and writing colsim's netCDF files through xarray.

Every file is CF-style: global `Conventions`, `title`, `source` ("colsim X.Y"), `history`, the
run's configuration as JSON in `config` and its `seed`; every variable has `units` ("1" when
dimensionless) and `long_name`. Files are written to a temporary name beside the target and renamed
when complete, so a killed run never leaves a file that looks finished.
"""
from __future__ import annotations

import contextlib
import json
import os
import tempfile
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from . import __version__
from .state import ParticleState
from .warm_start import WarmStart

STATE_KIND = "particle-state"
TRAJECTORY_KIND = "collapse-trajectory"
ANALYSIS_KIND = "collapse-analysis"

PARTICLE_VARIABLES = {
    "position": ("length", "particle centre position"),
    "velocity": ("length/time", "particle velocity"),
    "angular_velocity": ("rad/time", "particle angular velocity"),
}


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


def global_attributes(kind: str, title: str, config: dict, seed=None) -> dict:
    """CF global attributes with colsim's version, the configuration (JSON) and the seed."""
    attrs = {
        "Conventions": "CF-1.8",
        "title": title,
        "source": f"colsim {__version__}",
        "history": f"{datetime.now(timezone.utc).isoformat(timespec='seconds')} created by colsim {__version__}",
        "colsim_kind": kind,
        "config": json.dumps(config, sort_keys=True, default=_json_default),
    }
    if seed is not None:
        attrs["seed"] = int(seed)
    return attrs


def _json_default(value):
    if isinstance(value, (np.integer, np.floating)):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"cannot store {type(value).__name__} in the configuration")


def write_dataset(dataset, path) -> None:
    """Write an xarray Dataset to netCDF4 atomically."""
    with atomic_path(path) as tmp:
        dataset.to_netcdf(tmp, engine="netcdf4")


def open_dataset(path, kind: str):
    """Open a colsim netCDF file and check that it holds `kind`; InputError otherwise."""
    import xarray as xr

    path = Path(path)
    if not path.is_file():
        raise InputError(f"input file {path} does not exist")
    try:
        dataset = xr.load_dataset(path, engine="netcdf4")
    except Exception as error:  # netCDF4 raises OSError, ValueError, ... for foreign files
        raise InputError(f"input file {path} is not a readable netCDF file ({error})") from None
    found = dataset.attrs.get("colsim_kind")
    if found != kind:
        raise InputError(f"input file {path} holds {found or 'no colsim data'!r}, expected {kind!r}")
    return dataset


def config_of(dataset) -> dict:
    """The configuration stored in a colsim dataset's attributes."""
    return json.loads(dataset.attrs.get("config", "{}"))


def state_dataset(state: ParticleState, attrs: dict, extra: dict | None = None):
    """An xarray Dataset holding one particle state (dims particle, xyz)."""
    import xarray as xr

    data = {
        name: (("particle", "xyz"), getattr(state, name), {"units": units, "long_name": long_name})
        for name, (units, long_name) in PARTICLE_VARIABLES.items()
    }
    data["radius"] = ("particle", state.radius, {"units": "length", "long_name": "particle radius"})
    for name, (dims, values, var_attrs) in (extra or {}).items():
        data[name] = (dims, values, var_attrs)
    dataset = xr.Dataset(data, coords={"xyz": ["x", "y", "z"]}, attrs=dict(attrs))
    dataset.attrs["density"] = float(state.density)
    dataset.attrs["time"] = float(state.time)
    return dataset


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
    """(state, dataset) of a particle-state file."""
    dataset = open_dataset(path, STATE_KIND)
    return state_from_dataset(dataset), dataset


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
    """The contact forces stored by :func:`contact_force_variables`, or None (older files)."""
    if "contact_force" not in dataset:
        return None
    return WarmStart(dataset["contact_first"].values.astype(np.int64),
                     dataset["contact_second"].values.astype(np.int64),
                     dataset["contact_family"].values.astype(np.int64),
                     dataset["contact_force"].values, dataset["contact_rolling_force"].values)
