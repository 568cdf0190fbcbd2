"""colsim's netCDF files against the CF conventions (issue 32, item 4): the files of every stage
pass an independent CF checker (the IOOS compliance checker, CF-1.8, offline); whether a run came to
rest is a CF flag variable (int8, never a float with NaN) in trajectories, analyses and summaries,
and older files with the attribute still read; the per-step wall-clock time is named for what it
holds. Fast: columns of two spheres, a few dozen steps each (seconds in all)."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from colsim import io
from colsim.cli import main
from colsim.engine.state import FLOOR, PARTICLE, ParticleState
from colsim.engine.warm_start import WarmStart
from colsim.study.collect import run_status

from helpers import cf_check_failures

NOT_CHECKED, STILL_MOVING, AT_REST = (io.AT_REST_FLAGS[name] for name in ("not_checked", "still_moving", "at_rest"))
#: run on to rest within t/sqrt(h0/g) = 3, at rest once h_inf and r_inf held still over 0.5
TO_REST = ["--duration", "0.5", "--steps", "10", "--max-duration", "3", "--rest-window", "0.5", "--frame-every", "2"]


def _column(path, top_offset: float, h0: float) -> None:
    """Two spheres of diameter 0.5 on the axis of a cylinder r0 = 1, the upper one `top_offset` off
    the axis (resting on the lower one: 0 stands still, 0.1 rolls off and away without rolling
    resistance); h0 and a = h0 as the column's attributes."""
    lift = np.sqrt(0.25 - top_offset ** 2) + 1e-3
    state = ParticleState.at_rest([[0, 0, 0.25], [top_offset, 0, 0.25 + lift]], [0.25, 0.25])
    weight = state.mass * 9.81   # the contact forces a column carries from its packing: sphere on sphere, on floor
    forces = WarmStart(np.array([0, 0]), np.array([1, -1]), np.array([PARTICLE, FLOOR]),
                       np.array([[0, 0, -weight[1]], [0, 0, weight.sum()]]), np.zeros((2, 3)))
    io.write_state(path, state, {**io.global_attributes(io.STATE_KIND, "two spheres", {}), "r0": 1.0, "h0": h0,
                                 "aspect_ratio": h0, "solid_fraction": 0.1}, io.contact_force_variables(forces))


def _cli(directory, *args) -> None:
    cwd = os.getcwd()
    os.chdir(directory)
    try:
        assert main(list(args)) == 0, args
    finally:
        os.chdir(cwd)


@pytest.fixture(scope="module")
def outputs(tmp_path_factory):
    """still.nc (a = 1, the stack stands) and rolling.nc (a = 2, the top sphere rolls away); collapses
    of them run on to rest at mu_r = 0 (rest: at rest; moving: still moving at the end), at rest at
    mu_r = 0.12 (rest_012), and one with a fixed end time (fixed); an analysis of each; the summary
    of the three run on to rest, over a = 1, 2 and mu_r = 0, 0.12, the fourth cell (a = 2, mu_r =
    0.12) missing."""
    directory = tmp_path_factory.mktemp("cf")
    _column(directory / "still.nc", 0.0, 1.0)
    _column(directory / "rolling.nc", 0.1, 2.0)
    for name, column, extra in (("rest", "still.nc", [*TO_REST, "--mu-r", "0"]),
                                ("moving", "rolling.nc", [*TO_REST, "--mu-r", "0"]),
                                ("rest_012", "still.nc", [*TO_REST, "--mu-r", "0.12"]),
                                ("fixed", "still.nc", ["--duration", "0.5", "--steps", "10"])):
        _cli(directory, "collapse", "--input", column, *extra, "--output", f"{name}.collapse.nc")
        _cli(directory, "analyse", "--input", f"{name}.collapse.nc", "--output", f"{name}.analysis.nc")
    _cli(directory, "collect", "rest.analysis.nc", "moving.analysis.nc", "rest_012.analysis.nc",
         "--output", "summary.nc")
    return directory


@pytest.mark.parametrize("name", ["still.nc", "moving.collapse.nc", "fixed.collapse.nc", "moving.analysis.nc",
                                  "fixed.analysis.nc", "summary.nc"])
def test_files_pass_the_cf_checker(outputs, name):
    """Bound: no error, warning or suggestion of the IOOS checker's CF-1.8 suite, and no check of it
    raising; and its command line, as a user runs it (`--criteria strict`), exits 0 (issue 79.6: it
    exited 1 on every collapse.nc and analysis.nc, asking `time` for a calendar's standard name)."""
    assert cf_check_failures(outputs / name) == []
    checker = Path(sys.executable).with_name("compliance-checker")
    if checker.exists():
        done = subprocess.run([str(checker), "--test", "cf:1.8", "--criteria", "strict", str(outputs / name)],
                              capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, done.stdout[-3000:]


def test_frames_keep_their_time_in_seconds_and_older_files_read(outputs, tmp_path):
    """A trajectory stores its frames along `frame`, their seconds since release as the auxiliary
    coordinate elapsed_time (not a time axis of dates); colsim reads them back along `time`, indexed
    by it, and a file written before, with `time` itself, reads the same."""
    stored = xr.load_dataset(outputs / "moving.collapse.nc")
    assert "time" not in stored.variables and "time" not in stored.dims and stored.elapsed_time.dims == ("frame",)
    assert stored.elapsed_time.attrs["units"] == "s" and stored.elapsed_time.dtype.kind == "f"
    read = io.open_dataset(outputs / "moving.collapse.nc", io.TRAJECTORY_KIND)
    np.testing.assert_array_equal(read.indexes["time"].values, stored.elapsed_time.values)
    assert float(read.sel(time=read.time.values[-1]).time) == float(stored.elapsed_time[-1])
    older = stored.rename_dims(frame="time").rename_vars(elapsed_time="time").set_xindex("time")
    older.to_netcdf(tmp_path / "older.collapse.nc")
    again = io.open_dataset(tmp_path / "older.collapse.nc", io.TRAJECTORY_KIND)
    np.testing.assert_array_equal(again.time.values, read.time.values)
    assert set(again.variables) == set(read.variables)


def test_the_cf_check_sees_what_breaks_cf(outputs, tmp_path):
    """The check is not blind: a coordinate with a _FillValue, a 64-bit integer (not in CF-1.8) and
    a flag variable whose meanings do not match its values are each reported."""
    broken = xr.load_dataset(outputs / "moving.analysis.nc")
    broken["at_rest"].attrs["flag_meanings"] = "still_moving at_rest"
    broken["n_particles"] = broken["n_particles"].astype(np.int64)
    encoding = {"radial_bin": {"_FillValue": -1.0}, "n_particles": {"dtype": "int64"}}
    broken.to_netcdf(tmp_path / "broken.nc", encoding=encoding)
    failures = "\n".join(cf_check_failures(tmp_path / "broken.nc"))
    assert "radial_bin" in failures and "_FillValue" in failures
    assert "n_particles" in failures and "int64" in failures
    assert "flag_meanings" in failures


def test_flag_values_are_stored_with_their_variable_s_type(outputs):
    """CF: flag_values of the variable's own type, as stored (contact_family: int32, at_rest: int8)."""
    column = io.open_dataset(outputs / "still.nc", io.STATE_KIND)
    assert column.sizes["contact"] == 2
    for variable in (column["contact_family"], xr.load_dataset(outputs / "summary.nc")["at_rest"]):
        assert variable.attrs["flag_values"].dtype == variable.dtype
        assert len(variable.attrs["flag_values"]) == len(variable.attrs["flag_meanings"].split())


def test_at_rest_is_a_flag_variable_in_every_output(outputs):
    """-1 not checked (a fixed end time, or no run), 0 still moving at max_duration, 1 at rest: an
    int8 with flag_values and flag_meanings of equal length, in trajectory, analysis and summary."""
    expected = {"rest": AT_REST, "moving": STILL_MOVING, "rest_012": AT_REST, "fixed": NOT_CHECKED}
    for name, flag in expected.items():
        for kind, stage in ((io.TRAJECTORY_KIND, "collapse"), (io.ANALYSIS_KIND, "analysis")):
            dataset = io.open_dataset(outputs / f"{name}.{stage}.nc", kind)
            assert dataset["at_rest"].dtype == np.int8 and int(dataset["at_rest"]) == flag, (name, stage)
            assert "at_rest" not in dataset.attrs
    summary = xr.load_dataset(outputs / "summary.nc")
    variable = summary["at_rest"]
    assert variable.dtype == np.int8 and variable.dims == ("aspect_ratio", "mu_r", "seed")
    # a = 1: at rest at both mu_r; a = 2: still moving at mu_r = 0, no run at mu_r = 0.12
    np.testing.assert_array_equal(variable.values[..., 0], [[AT_REST, AT_REST], [STILL_MOVING, NOT_CHECKED]])
    values, meanings = variable.attrs["flag_values"], variable.attrs["flag_meanings"].split()
    assert list(values) == [NOT_CHECKED, STILL_MOVING, AT_REST] and meanings == list(io.AT_REST_FLAGS)
    assert variable.attrs["long_name"] and variable.attrs["units"] == "1"
    # the summary's flags read the variable: the run still moving is flagged, the missing one is not
    moving = run_status(summary)["moving"].values[..., 0]
    np.testing.assert_array_equal(moving, [[False, False], [True, False]])


def test_older_files_with_the_at_rest_attribute_still_read(outputs, tmp_path):
    """Files written before the variable stored at_rest as an attribute (0 or 1; absent when not
    checked): they read as the same flags, and a summary collected from them holds the variable."""
    for name in ("rest", "moving", "rest_012"):
        old = io.open_dataset(outputs / f"{name}.analysis.nc", io.ANALYSIS_KIND)
        flag = int(old["at_rest"])
        old = old.drop_vars("at_rest")
        old.attrs["at_rest"] = flag
        io.write_dataset(old, tmp_path / f"{name}.nc")
        assert io.at_rest_flag(io.open_dataset(tmp_path / f"{name}.nc", io.ANALYSIS_KIND)) == flag
    fixed = io.open_dataset(outputs / "fixed.analysis.nc", io.ANALYSIS_KIND).drop_vars("at_rest")
    assert io.at_rest_flag(fixed) == NOT_CHECKED
    _cli(tmp_path, "collect", "rest.nc", "moving.nc", "rest_012.nc", "--output", "summary.nc")
    old_style = xr.load_dataset(tmp_path / "summary.nc")
    xr.testing.assert_identical(old_style["at_rest"], xr.load_dataset(outputs / "summary.nc")["at_rest"])


def test_the_step_wall_clock_time_is_named_for_what_it_holds(outputs):
    """step_wall_time (wall-clock seconds of each step, at least the solver's share of it) beside
    step_time (the simulation's time at the end of the step); no step_step_time."""
    trajectory = io.open_dataset(outputs / "moving.collapse.nc", io.TRAJECTORY_KIND)
    assert "step_step_time" not in trajectory
    wall, simulated = trajectory["step_wall_time"], trajectory["step_time"]
    assert wall.attrs == {"units": "s", "long_name": "wall-clock time of the step"}
    assert simulated.attrs["units"] == "s" and "simulation" in simulated.attrs["long_name"]
    assert np.all(wall.values > 0) and np.all(wall.values >= trajectory["step_solve_time"].values)
    np.testing.assert_allclose(simulated.values[-1], trajectory["time"].values[-1])


def test_a_channels_run_coordinates_name_the_box_length():
    """Issue 82: a channel's r0 coordinate holds its box length L0, and its long names say so (the
    aspect ratio is H0/L0); a cylinder's are the radius and h0/r0."""
    from colsim.io.netcdf import run_coordinates

    channel = run_coordinates({"geometry": "channel", "r0": 6.0, "aspect_ratio": 2.0, "mu_r": 0.12, "seed": 1})
    cylinder = run_coordinates({"r0": 3.0, "aspect_ratio": 2.0, "mu_r": 0.12, "seed": 1})
    assert "L0" in channel["r0"][2]["long_name"] and channel["aspect_ratio"][2]["long_name"] == "aspect ratio H0/L0"
    assert cylinder["r0"][2]["long_name"] == "cylinder radius"
    assert cylinder["aspect_ratio"][2]["long_name"] == "aspect ratio h0/r0"
    assert channel["r0"][1] == 6.0 and channel["r0"][2]["units"] == "length"
