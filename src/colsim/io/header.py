"""A netCDF-4 file's header, bounded before netCDF or xarray read it: how many
attributes each of its objects holds, asked of the HDF5 library itself.

netCDF reads attributes by name, at a cost quadratic in their number: 50,000 attributes take seconds
and 10^6 kept `collect` busy past 300 s, before any check could look at them. HDF5 counts them in
its object header at once, so the count is checked first, through the HDF5 library that netCDF4
loaded (HDF5 1.12 or newer, found among the process's libraries; where it is not found the count is
left to :func:`colsim.io.checks.check_header`'s bound on the file's size).
"""
from __future__ import annotations

import ctypes
from functools import lru_cache
from pathlib import Path

#: the first bytes of an HDF5 file (a netCDF-4 file is one)
HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"
#: H5O_INFO_BASIC | H5O_INFO_TIME | H5O_INFO_NUM_ATTRS: the fields of H5O_info2_t that are asked for
_INFO_FIELDS = 0x0007


class _Token(ctypes.Structure):
    _fields_ = [("data", ctypes.c_uint8 * 16)]


class _ObjectInfo(ctypes.Structure):
    """HDF5's H5O_info2_t (1.12 and newer)."""
    _fields_ = [("fileno", ctypes.c_ulong), ("token", _Token), ("type", ctypes.c_int), ("rc", ctypes.c_uint),
                ("atime", ctypes.c_long), ("mtime", ctypes.c_long), ("ctime", ctypes.c_long),
                ("btime", ctypes.c_long), ("num_attrs", ctypes.c_uint64)]


class _GroupInfo(ctypes.Structure):
    """HDF5's H5G_info_t."""
    _fields_ = [("storage_type", ctypes.c_int), ("nlinks", ctypes.c_uint64), ("max_corder", ctypes.c_int64),
                ("mounted", ctypes.c_bool)]


@lru_cache(maxsize=1)
def _hdf5():
    """The HDF5 library netCDF4 loaded (its functions typed), or None where it is not found."""
    import netCDF4  # noqa: F401  (loads the HDF5 library that it reads files with)

    try:
        with open("/proc/self/maps") as maps:
            paths = {line.split()[-1] for line in maps if "/libhdf5" in line}
    except OSError:
        return None
    paths = [path for path in paths if not Path(path).name.startswith("libhdf5_hl")]
    if not paths:
        return None
    try:
        library = ctypes.CDLL(paths[0])
        library.H5Oget_info_by_name3   # HDF5 1.12 and newer
    except (OSError, AttributeError):
        return None
    hid = ctypes.c_int64
    library.H5Fopen.restype = hid
    library.H5Fopen.argtypes = [ctypes.c_char_p, ctypes.c_uint, hid]
    library.H5Fclose.argtypes = [hid]
    library.H5Oget_info_by_name3.argtypes = [hid, ctypes.c_char_p, ctypes.POINTER(_ObjectInfo), ctypes.c_uint, hid]
    library.H5Oget_info_by_idx3.argtypes = [hid, ctypes.c_char_p, ctypes.c_int, ctypes.c_int, ctypes.c_uint64,
                                            ctypes.POINTER(_ObjectInfo), ctypes.c_uint, hid]
    library.H5Gget_info_by_name.argtypes = [hid, ctypes.c_char_p, ctypes.POINTER(_GroupInfo), hid]
    library.H5Eset_auto2.argtypes = [hid, ctypes.c_void_p, ctypes.c_void_p]
    return library


def is_hdf5(path) -> bool:
    """Whether the file at `path` starts as an HDF5 (netCDF-4) file does."""
    with open(path, "rb") as stream:
        return stream.read(len(HDF5_SIGNATURE)) == HDF5_SIGNATURE


def attribute_counts(path, most_objects: int) -> tuple[int, int, int] | None:
    """(objects in the root group, attributes of the root group, most attributes of one of its
    objects) of the netCDF-4 file `path`, read from HDF5's object headers without reading one
    attribute; the objects are counted up to `most_objects` + 1. None where the HDF5 library is not
    found or cannot read the file (netCDF then says why)."""
    library = _hdf5()
    if library is None:
        return None
    library.H5Eset_auto2(0, None, None)   # no error stack printed: a failure is told by its status
    handle = library.H5Fopen(str(path).encode(), 0, 0)   # read-only, default properties
    if handle < 0:
        return None
    try:
        info, group = _ObjectInfo(), _GroupInfo()
        if library.H5Oget_info_by_name3(handle, b"/", ctypes.byref(info), _INFO_FIELDS, 0) < 0 or \
                library.H5Gget_info_by_name(handle, b"/", ctypes.byref(group), 0) < 0:
            return None
        objects = min(group.nlinks, most_objects + 1)
        most = 0
        for index in range(objects):
            found = _ObjectInfo()
            if library.H5Oget_info_by_idx3(handle, b"/", 0, 0, index, ctypes.byref(found), _INFO_FIELDS, 0) < 0:
                return None
            most = max(most, found.num_attrs)
        return int(group.nlinks), int(info.num_attrs), int(most)
    finally:
        library.H5Fclose(handle)
