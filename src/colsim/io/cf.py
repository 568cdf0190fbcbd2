"""CF-1.8 as colsim writes it: SI units (`unit_system`: gravity 9.81 makes lengths metres and times
seconds, the density in kg m-3 masses kilograms; scaled quantities have units "1"), 32-bit integers,
no _FillValue on coordinates, text labels of a dimension as an auxiliary coordinate; and the writer
that applies them, atomically."""
from __future__ import annotations

import numpy as np

from .files import atomic_path

#: dimensions that the stages write as units; :func:`write_dataset` turns each into units "1" and a comment
#: the units colsim's code writes (dimensions) and the SI units they are stored with
SI_UNITS = {"length": "m", "time": "s", "length/time": "m s-1", "rad/time": "rad s-1",
            "length/time^2": "m s-2", "mass": "kg", "mass/length^3": "kg m-3",
            "mass length/time^2": "kg m s-2", "mass length^2/time^2": "kg m2 s-2"}


UNIT_SYSTEM = ("SI: with gravity 9.81 m s-2 (the default) lengths are metres (particle diameters 0.25-0.5 m "
               "by default) and times seconds; masses are kilograms for the density in kg m-3 (1 by default); "
               "dimensionless and scaled quantities (over r0, t/sqrt(h0/g)) have units '1'")


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


#: how a file stores its frames: the dimension FRAME, and their times (seconds since release) as the
#: auxiliary coordinate ELAPSED_TIME along it. A dimension and coordinate variable named `time` would be
#: taken by CF checkers for a calendar time axis (they ask for standard_name "time" and units
#: "s since <date>", and xarray would then read the times as dates).
FRAME, ELAPSED_TIME = "frame", "elapsed_time"


def cf_time(dataset):
    """`dataset` with its dimension `time` stored as :data:`FRAME` and its `time` coordinate (seconds
    since release) as the auxiliary coordinate :data:`ELAPSED_TIME` (:func:`time_as_index` puts them back)."""
    if "time" not in dataset.dims or "time" not in dataset.coords:
        return dataset
    stored = dataset.drop_indexes("time").rename_vars({"time": ELAPSED_TIME}).swap_dims(time=FRAME)
    stored[ELAPSED_TIME].attrs["long_name"] = "time since release"
    return stored


def time_as_index(dataset):
    """The inverse of :func:`cf_time`: the dimension :data:`FRAME` becomes `time` again, indexed by
    :data:`ELAPSED_TIME` renamed `time` (a file written before, with `time` itself, is left as it is)."""
    if FRAME not in dataset.dims or ELAPSED_TIME not in dataset.coords or "time" in dataset.variables:
        return dataset
    restored = dataset.rename_dims({FRAME: "time"}).rename_vars({ELAPSED_TIME: "time"}).set_xindex("time")
    restored["time"].attrs["long_name"] = "time"
    return restored


def write_netcdf(dataset, path) -> None:
    """Write an xarray Dataset to netCDF4 at `path` as it is (no temporary name), units, time and
    text labels made CF (:func:`cf_units`, :func:`cf_time`, :func:`cf_labels`)."""
    dataset = cf_units(cf_time(cf_labels(dataset.copy())))
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
