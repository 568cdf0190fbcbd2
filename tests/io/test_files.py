"""Every stage's file: CF units, versions and long names; the VTK export's frames."""
from __future__ import annotations

import subprocess

import pytest
from pathlib import Path

import numpy as np
import xarray as xr

from colsim import io

from helpers import assert_cf_units, tiny_state_files


def test_files_carry_cf_units_versions_and_long_names(tmp_path):
    tiny_state_files(tmp_path)
    column = io.open_dataset(tmp_path / "column.nc", io.STATE_KIND)
    assert column["position"].attrs["units"] == "m" and column["velocity"].attrs["units"] == "m s-1"
    assert column["component"].attrs["units"] == "1" and list(column["component"].values) == ["x", "y", "z"]
    assert "SI" in column.attrs["unit_system"]
    assert_cf_units(column)
    for name in ("colsim_version", "clarabel_version", "numpy_version"):
        assert column.attrs[name] and column.attrs[name] != "not installed", name
    assert column.attrs["numpy_version"] == np.__version__
    # the commit of the checkout the package was imported from, as git itself reports it
    done = subprocess.run(["git", "-C", str(Path(io.__file__).parent), "rev-parse", "HEAD"],
                          capture_output=True, text=True)
    expected = done.stdout.strip() if done.returncode == 0 else "unknown (not a git checkout)"
    assert column.attrs["colsim_commit"].split(" ")[0] == expected.split(" ")[0]


def test_export_vtk_removes_its_own_earlier_frames(tmp_path):
    from colsim.io.vtk import export_trajectory

    def trajectory(frames):
        n = 3
        return xr.Dataset({"position": (("time", "particle", "xyz"), np.zeros((frames, n, 3))),
                           "velocity": (("time", "particle", "xyz"), np.zeros((frames, n, 3))),
                           "angular_velocity": (("time", "particle", "xyz"), np.zeros((frames, n, 3))),
                           "radius": ("particle", np.full(n, 0.2)), "initial_height": ("particle", np.ones(n)),
                           "scaled_time": ("time", np.arange(frames, dtype=float) / 0.3)},
                          coords={"time": np.arange(frames, dtype=float)})

    (tmp_path / "notes.vtu").write_text("not ours")
    export_trajectory(trajectory(5), tmp_path)
    export_trajectory(trajectory(2), tmp_path)
    assert sorted(p.name for p in tmp_path.glob("*.vtu")) == ["collapse_0000.vtu", "collapse_0001.vtu", "notes.vtu"]


def test_a_stage_removes_the_temporaries_a_killed_run_left_of_its_own_outputs(tmp_path):
    """Issue 80.8: SIGKILL left hidden .part temporaries that nothing removed (11 after 8 kills); a
    stage removes those of its own outputs as it starts, and nothing else."""
    import tempfile

    from colsim.io.files import remove_stale_temporaries, temporary_prefix

    output = tmp_path / "collapse.nc"
    left = [Path(tempfile.mkstemp(prefix=temporary_prefix(output, ".part"), suffix=".part", dir=tmp_path)[1])
            for _ in range(3)]
    others = [tmp_path / ".analysis.nc.abcdefgh.part", tmp_path / ".collapse.nc.abcdefgh.part.keep",
              tmp_path / "collapse.nc.part"]
    for path in others:
        path.write_text("not collapse.nc's temporary")
    assert sorted(remove_stale_temporaries(output)) == sorted(left)
    assert not any(path.exists() for path in left) and all(path.exists() for path in others)


def test_a_legal_output_name_of_any_length_has_a_temporary(tmp_path):
    """Issue 80.8: a legal 243-byte output name was refused: its temporary's name was too long."""
    from colsim.io.files import NAME_MAX, check_writable, write_all

    output = tmp_path / ("x" * (NAME_MAX - 3) + ".nc")
    check_writable(output)
    write_all({output: lambda tmp: Path(tmp).write_text("done")})
    assert output.read_text() == "done" and [p.name for p in tmp_path.iterdir()] == [output.name]


def test_a_full_disk_names_the_file_it_could_not_write(tmp_path):
    """Issue 80.8: a full disk ended with "(no file)": netCDF's error names none. The writer's error
    comes back naming the output (here the writer raises the no-space error a full disk gives)."""
    import errno

    from colsim.io.files import write_all

    def full(tmp):
        raise OSError(errno.ENOSPC, "No space left on device")

    output = tmp_path / "analysis.nc"
    with pytest.raises(OSError) as caught:
        write_all({output: full})
    assert caught.value.filename == str(output) and caught.value.errno == errno.ENOSPC
    assert list(tmp_path.iterdir()) == []


def test_a_channel_s_paraview_series_shows_its_walls(tmp_path):
    """A channel's run (geometry channel, L0 = 1, W = 0.6, h0 = 0.8) exports its floor, back wall and
    sidewalls as four quadrilaterals, as far as its farthest grain (x + R = 2.2 in the second frame),
    part 1 of each time step; meshio (an independent reader) reads them back on their planes. A
    cylinder's run has none."""
    import meshio

    from colsim.io.vtk import export_trajectory

    position = np.array([[[0.5, 0.0, 0.2]], [[2.0, 0.1, 0.2]]])
    attrs = {"geometry": "channel", "channel_length": 1.0, "channel_width": 0.6, "h0": 0.8}
    trajectory = xr.Dataset({"position": (("time", "particle", "xyz"), position),
                             "velocity": (("time", "particle", "xyz"), np.zeros_like(position)),
                             "angular_velocity": (("time", "particle", "xyz"), np.zeros_like(position)),
                             "radius": ("particle", [0.2]), "initial_height": ("particle", [0.2]),
                             "scaled_time": ("time", [0.0, 1.0])}, coords={"time": [0.0, 0.3]}, attrs=attrs)
    pvd = export_trajectory(trajectory, tmp_path).read_text()
    assert pvd.count('part="1" file="collapse_walls.vtu"') == 2
    walls = meshio.read(tmp_path / "collapse_walls.vtu")
    quads = walls.points[walls.cells_dict["quad"]]
    assert quads.shape == (4, 4, 3)
    np.testing.assert_array_equal(quads[0, :, 2], 0.0)                  # the floor
    np.testing.assert_array_equal(quads[1, :, 0], 0.0)                  # the back wall
    np.testing.assert_array_equal(quads[2:, :, 1], [[-0.3] * 4, [0.3] * 4])   # the sidewalls
    assert walls.points[:, 0].max() == pytest.approx(2.2) and walls.points[:, 2].max() == 0.8
    cylinder = tmp_path / "cylinder"
    cylinder.mkdir()
    trajectory.attrs = {}
    assert 'part="1"' not in export_trajectory(trajectory, cylinder).read_text()
    assert not (cylinder / "collapse_walls.vtu").exists()
