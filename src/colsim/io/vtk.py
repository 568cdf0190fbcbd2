"""ParaView export: one VTK UnstructuredGrid (.vtu) of points per frame and a .pvd time collection.

Point data: radius, velocity, angular_velocity, initial_height; field data: TimeValue (the frame's
time, in the file's time unit: seconds with g = 9.81) and scaled_time (t/sqrt(h0/g), the time of
colsim's figures). The .pvd's timesteps are t/sqrt(h0/g), so ParaView's time bar reads like the
figures. In ParaView, open the .pvd and use a Glyph filter (sphere, scale by `radius`, scale factor
2) to see the grains.

A channel's run (geometry channel) adds its walls, NAME_walls.vtu: four quadrilaterals (the floor,
the back wall x = 0 and the sidewalls y = -W/2 and +W/2) as far along the channel as any grain goes
and as high as the column, part 1 of every time step of the .pvd (the grains are part 0).
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


def write_quads(path, corners: np.ndarray) -> None:
    """Quadrilaterals at `path` (as it is: the caller makes it atomic): corners (k, 4, 3), each
    quadrilateral's corners in order around it (VTK_QUAD)."""
    k = len(corners)
    body = ['<?xml version="1.0"?>\n',
            '<VTKFile type="UnstructuredGrid" version="1.0" byte_order="LittleEndian" header_type="UInt32">\n',
            '  <UnstructuredGrid>\n', f'    <Piece NumberOfPoints="{4 * k}" NumberOfCells="{k}">\n',
            '      <Points>\n', _data_array("Points", corners.reshape(-1, 3), 3), '      </Points>\n',
            '      <Cells>\n', _data_array("connectivity", np.arange(4 * k), 1, "Int64"),
            _data_array("offsets", 4 * np.arange(1, k + 1), 1, "Int64"),
            _data_array("types", np.full(k, 9), 1, "UInt8"),
            '      </Cells>\n', '    </Piece>\n', '  </UnstructuredGrid>\n', '</VTKFile>\n']
    Path(path).write_text("".join(body))


def channel_walls(dataset) -> np.ndarray | None:
    """The corners (4, 4, 3) of a channel run's floor, back wall and sidewalls (:func:`write_quads`):
    along x from the back wall to the farthest reach of any grain in any frame (at least L0), up to
    the column's height h0 (or its tallest grain); None for a run that is not a channel's."""
    if dataset.attrs.get("geometry") != "channel":
        return None
    half = 0.5 * float(dataset.attrs["channel_width"])
    position, radius = dataset["position"].values, dataset["radius"].values
    far = max(float(dataset.attrs["channel_length"]), float(np.max(position[..., 0] + radius)))
    high = float(dataset.attrs.get("h0", np.max(position[..., 2] + radius)))
    floor = [(0, -half, 0), (far, -half, 0), (far, half, 0), (0, half, 0)]
    back = [(0, -half, 0), (0, half, 0), (0, half, high), (0, -half, high)]
    sides = [[(0, y, 0), (far, y, 0), (far, y, high), (0, y, high)] for y in (-half, half)]
    return np.array([floor, back, *sides], dtype=float)


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
    walls = channel_walls(dataset)
    if walls is not None:
        writers[directory / f"{name}_walls.vtu"] = lambda tmp: write_quads(tmp, walls)
    for k, t in enumerate(dataset["time"].values):
        frame = f"{name}_{k:04d}.vtu"
        writers[directory / frame] = frame_writer(k, t)
        entries.append(f'    <DataSet timestep="{scaled[k]:.9g}" group="" part="0" file="{frame}"/>\n')
        if walls is not None:
            entries.append(f'    <DataSet timestep="{scaled[k]:.9g}" group="" part="1" file="{name}_walls.vtu"/>\n')
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
