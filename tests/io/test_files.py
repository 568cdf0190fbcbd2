"""Every stage's file: CF units, versions and long names; the VTK export's frames."""
from __future__ import annotations

import subprocess
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
