"""ParaView export: one VTK UnstructuredGrid (.vtu) of points per frame and a .pvd time collection.

Point data: radius, velocity, angular_velocity, initial_height; field data: TimeValue (the frame's
time, in the file's time unit: seconds with g = 9.81) and scaled_time (t/sqrt(h0/g), the time of
colsim's figures). The .pvd's timesteps are t/sqrt(h0/g), so ParaView's time bar reads like the
figures. In ParaView, open the .pvd and use a Glyph filter (sphere, scale by `radius`, scale factor
2) to see the grains.
"""
from __future__ import annotations

import base64
from pathlib import Path

import numpy as np

from .files import write_all


def _data_array(name: str, values: np.ndarray, components: int, dtype: str = "Float64",
                tuples: int | None = None) -> str:
    """A base64 'binary' DataArray: a UInt32 byte count, then the little-endian values (tuples:
    the count a FieldData array states)."""
    raw = np.ascontiguousarray(values, dtype={"Float64": "<f8", "Int64": "<i8", "UInt8": "u1"}[dtype])
    payload = base64.b64encode(np.uint32(raw.nbytes).tobytes() + raw.tobytes()).decode("ascii")
    count = "" if tuples is None else f'NumberOfTuples="{tuples}" '
    return (f'        <DataArray type="{dtype}" Name="{name}" {count}NumberOfComponents="{components}" '
            f'format="binary">{payload}</DataArray>\n')


def write_vtu(path, position, point_data: dict, field_data: dict | None = None) -> None:
    """One point set at `path` (as it is: the caller makes it atomic): positions (n, 3), point data
    {name: (n,) or (n, 3)} and field data {name: number} (one value for the whole frame)."""
    n = len(position)
    body = ['<?xml version="1.0"?>\n',
            '<VTKFile type="UnstructuredGrid" version="1.0" byte_order="LittleEndian" header_type="UInt32">\n',
            '  <UnstructuredGrid>\n']
    if field_data:
        body += ['    <FieldData>\n']
        body += [_data_array(name, np.array([value]), 1, tuples=1) for name, value in field_data.items()]
        body += ['    </FieldData>\n']
    body += [f'    <Piece NumberOfPoints="{n}" NumberOfCells="{n}">\n',
            '      <PointData Scalars="radius">\n']
    for name, values in point_data.items():
        values = np.asarray(values)
        body.append(_data_array(name, values, 1 if values.ndim == 1 else values.shape[1]))
    body += ['      </PointData>\n', '      <Points>\n', _data_array("Points", position, 3),
             '      </Points>\n', '      <Cells>\n',
             _data_array("connectivity", np.arange(n), 1, "Int64"),
             _data_array("offsets", np.arange(1, n + 1), 1, "Int64"),
             _data_array("types", np.ones(n), 1, "UInt8"),
             '      </Cells>\n', '    </Piece>\n', '  </UnstructuredGrid>\n', '</VTKFile>\n']
    Path(path).write_text("".join(body))


def export_trajectory(dataset, directory, name: str = "collapse") -> Path:
    """Write every frame of a trajectory dataset as NAME_kkkk.vtu plus NAME.pvd; return the .pvd path.
    All or nothing (:func:`colsim.io.write_all`, the .pvd renamed last), so a failed export leaves
    the earlier series as it was. Frames NAME_kkkk.vtu of an earlier export that this one did not
    write are removed, so the directory holds exactly this export's frames."""
    directory = Path(directory)
    radius = dataset["radius"].values
    initial_height = dataset["initial_height"].values
    scaled = dataset["scaled_time"].values

    def frame_writer(k: int, t: float):
        return lambda tmp: write_vtu(tmp, dataset["position"].values[k], {
            "radius": radius, "velocity": dataset["velocity"].values[k],
            "angular_velocity": dataset["angular_velocity"].values[k], "initial_height": initial_height,
        }, {"TimeValue": float(t), "scaled_time": float(scaled[k])})

    writers, entries = {}, []
    for k, t in enumerate(dataset["time"].values):
        frame = f"{name}_{k:04d}.vtu"
        writers[directory / frame] = frame_writer(k, t)
        entries.append(f'    <DataSet timestep="{scaled[k]:.9g}" group="" part="0" file="{frame}"/>\n')
    collection = directory / f"{name}.pvd"
    writers[collection] = lambda tmp: Path(tmp).write_text(
        '<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n  <Collection>\n'
        + "".join(entries) + '  </Collection>\n</VTKFile>\n')
    write_all(writers)
    written = {path.name for path in writers}
    for stale in directory.glob(f"{name}_[0-9][0-9][0-9][0-9].vtu"):
        if stale.name not in written:
            stale.unlink()
    return collection
