"""The particle-state file (a packing, a column): positions, velocities, radii and the contact
forces carried to the next stage, with the check that the spheres are a possible column."""
from __future__ import annotations

import numpy as np
import xarray as xr

from ..engine.state import CYLINDER, ParticleState, channel_planes
from ..engine.warm_start import WarmStart
from . import checks
from .cf import write_dataset
from .files import InputError
from .netcdf import PARTICLE_VARIABLES, STATE_KIND, open_dataset
from .provenance import config_of


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
    if dataset.attrs.get("geometry") == "channel":
        check_inside_channel(state, dataset.attrs, tolerance, path)
    elif "r0" in dataset.attrs:
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


def check_inside_channel(state: ParticleState, attrs, tolerance: float, path) -> None:
    """InputError naming the first sphere that reaches through a wall of the channel's box (its
    back wall, sidewalls or gate: attributes channel_length, channel_width) by more than `tolerance`."""
    length, width = float(attrs["channel_length"]), float(attrs["channel_width"])
    for plane in channel_planes(length, width, gate=True):
        outside = state.position @ np.array(plane[:3]) - plane[3] - state.radius < -tolerance
        if outside.any():
            raise InputError(f"input file {path}: sphere {int(np.argmax(outside))} reaches outside the channel's "
                             f"box (length {length:g}, width {width:g})")


def family_flags(family) -> dict:
    """The CF flags of the contact families (colsim.engine.state): particle, floor, cylinder, and
    plane_0 ... for a channel's plane walls (PLANE + p) where the contacts hold any."""
    most = int(np.max(family, initial=CYLINDER))
    meanings = ["particle", "floor", "cylinder"] + [f"plane_{p}" for p in range(most - CYLINDER)]
    return {"flag_values": np.arange(len(meanings)), "flag_meanings": " ".join(meanings)}


def contact_force_variables(forces: WarmStart) -> dict:
    """The variables (over dims contact, xyz) that store a stage's last contact forces, as `extra`
    for :func:`state_dataset`."""
    def variable(dims, values, units, long_name, **more):
        return (dims, values, {"units": units, "long_name": long_name, **more})

    return {
        "contact_first": variable("contact", forces.i, "1", "first particle of the contact pair"),
        "contact_second": variable("contact", forces.j, "1", "second particle of the contact pair",
                                   comment="-1: a wall (see contact_family)"),
        "contact_family": variable("contact", forces.family, "1", "kind of contact", **family_flags(forces.family)),
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
