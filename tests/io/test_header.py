"""Issue 80.2: a file's header is bounded before netCDF or xarray decode it: its attributes (how many,
counted by HDF5, and their size), its variables' types, and what its values would take once
decoded, against its kind and its size on disk. Each refusal is one line naming the cause."""
from __future__ import annotations

import netCDF4
import numpy as np
import pytest
import xarray as xr

from colsim.io import checks, header
from colsim.io.files import InputError
from colsim.io.netcdf import ANALYSIS_KIND, STATE_KIND, open_dataset


@pytest.fixture
def plain(tmp_path):
    """A small netCDF-4 file as colsim writes one: a few attributes, a particle variable."""
    path = tmp_path / "plain.nc"
    xr.Dataset({"radius": ("particle", np.full(10, 0.2), {"units": "m"})},
               attrs={"colsim_kind": ANALYSIS_KIND, "r0": 1.0}).to_netcdf(path, engine="netcdf4")
    return path


def refused(path, kind, *words):
    with pytest.raises(checks.FileProblem) as caught:
        checks.check_header(path, kind)
    assert all(word in str(caught.value) for word in words), str(caught.value)
    assert "\n" not in str(caught.value)


def test_a_plain_file_passes_and_hdf5_counts_its_attributes(plain):
    checks.check_header(plain, ANALYSIS_KIND)
    objects, own, most = header.attribute_counts(plain, checks.MAX_OBJECTS)
    with netCDF4.Dataset(plain) as dataset:
        assert own == len(dataset.ncattrs()) + 1   # and netCDF's own _NCProperties, which it hides
        assert objects == len(dataset.variables) + len(set(dataset.dimensions) - set(dataset.variables))
        assert most == max(len(v.ncattrs()) for v in dataset.variables.values()) + 2  # + the dimension scale's


@pytest.mark.parametrize("where", ["global", "variable"])
def test_many_attributes_are_refused_before_netcdf_reads_them(plain, where):
    """20,000 attributes took netCDF 1.7 s to read by name (10^6: past 300 s); HDF5 counts them first."""
    with netCDF4.Dataset(plain, "a") as dataset:
        target = dataset if where == "global" else dataset["radius"]
        target.setncatts({f"a{i}": i for i in range(checks.MAX_ATTRIBUTES + 1)})
    refused(plain, ANALYSIS_KIND, "attributes on one object", f"({checks.MAX_ATTRIBUTES:,})")


def test_attributes_too_large_together_are_refused(plain):
    with netCDF4.Dataset(plain, "a") as dataset:
        dataset.comment = "x" * (checks.MAX_ATTRIBUTE_BYTES + 1)
    refused(plain, ANALYSIS_KIND, "its attributes hold", "MiB")


def test_a_small_file_declaring_gigabytes_is_refused(plain):
    """Issue 80.3: a 64 kB trajectory declaring an 8 GB variable (never written): within the
    trajectory kind's bound, yet far beyond what the file holds."""
    with netCDF4.Dataset(plain, "a") as dataset:
        dataset.createDimension("frame", 10**9)
        dataset.createVariable("position_huge", "f8", ("frame",), chunksizes=(1024,))
    assert plain.stat().st_size < 100_000
    refused(plain, "collapse-trajectory", "7.45 GiB once read", "uncompressed")


def test_a_small_integer_that_decodes_to_float_counts_as_its_float(plain):
    """Issue 80.3: a packing declaring a 1 GB int8 variable with a fill value, which xarray decodes
    to floats (a 5 GB peak in trim): counted at 8 bytes a value."""
    with netCDF4.Dataset(plain, "a") as dataset:
        dataset.createDimension("flag", 10**6)
        dataset.createVariable("flags", "i1", ("flag",), fill_value=-1)[:] = np.zeros(10**6, dtype=np.int8)
    assert plain.stat().st_size < 2 * 10**6
    checks.check_header(plain, STATE_KIND)   # 8 MB decoded from 1 MB on disk: as colsim's own flags may
    with netCDF4.Dataset(plain, "a") as dataset:
        dataset.createDimension("more", 2 * 10**6)
        dataset.createVariable("unwritten", "i1", ("more",), fill_value=-1, chunksizes=(1024,))
    refused(plain, STATE_KIND, "GiB once read")


def test_a_variable_of_another_type_is_refused(plain):
    with netCDF4.Dataset(plain, "a") as dataset:
        kind = dataset.createVLType(np.int32, "ragged")
        dataset.createVariable("ragged_values", kind, ("particle",))
    refused(plain, ANALYSIS_KIND, "ragged_values", "does not read")


def test_a_file_that_is_not_netcdf_4_is_refused_by_open_dataset(tmp_path):
    path = tmp_path / "foreign.nc"
    path.write_bytes(b"CDF\x01" + bytes(60))
    with pytest.raises(InputError, match="not a readable netCDF file"):
        open_dataset(path, ANALYSIS_KIND)
