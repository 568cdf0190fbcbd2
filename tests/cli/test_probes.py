"""Issue 28's probes, kept: each bad input, path or file gets one line naming the cause and its exit
status (2: the input, 1: the computation), and nothing is lost or written half.

The workflow's probes (studies that share folders, NaN in a configuration) are in workflow/test_workflow.py.
"""
from __future__ import annotations

import os
import pickle
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from colsim import io
from colsim.io.vtk import export_trajectory


def colsim(*args, cwd):
    return subprocess.run([sys.executable, "-m", "colsim.cli", *args], cwd=cwd, capture_output=True,
                          text=True, timeout=300)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """A folder with pack.nc (r0 = 1), column.nc (a = 1), collapse.nc (10 steps) and analysis.nc."""
    folder = tmp_path_factory.mktemp("probes")
    for args in (["pack", "--r0", "1", "--height", "1", "--seed", "3", "--output", "pack.nc"],
                 ["trim", "--input", "pack.nc", "--aspect-ratio", "1", "--output", "column.nc"],
                 ["collapse", "--input", "column.nc", "--steps", "10", "--output", "collapse.nc"],
                 ["analyse", "--input", "collapse.nc", "--output", "analysis.nc"]):
        assert colsim(*args, cwd=folder).returncode == 0
    return folder


@pytest.fixture
def work(files, tmp_path):
    for name in ("pack.nc", "column.nc", "collapse.nc", "analysis.nc"):
        shutil.copy2(files / name, tmp_path / name)
    return tmp_path


def one_line_error(done, status: int, *words):
    """The command failed with `status` and a last line naming each of `words`, without a traceback."""
    assert done.returncode == status, done.stderr[-2000:]
    assert "Traceback" not in done.stderr, done.stderr[-2000:]
    last = done.stderr.strip().splitlines()[-1]
    assert all(word in last for word in words), last


class Planted:
    """Unpickling this writes a file: a checkpoint that runs code when read."""

    def __reduce__(self):
        return (os.system, ("touch planted_code_ran",))


def test_a_planted_pickle_checkpoint_runs_no_code(work):
    """The checkpoint is an .npz of plain arrays read with allow_pickle=False; a pickle in its place
    is refused in one line (issue 45.2: it is not colsim's to replace), runs nothing and stays."""
    planted = pickle.dumps({"fingerprint": Planted()})
    (work / "out.nc.checkpoint").write_bytes(planted)
    done = colsim("collapse", "--input", "column.nc", "--steps", "5", "--output", "out.nc", cwd=work)
    one_line_error(done, 2, "out.nc.checkpoint", "not a colsim checkpoint")
    assert not (work / "planted_code_ran").exists() and not (work / "out.nc").exists()
    assert (work / "out.nc.checkpoint").read_bytes() == planted


@pytest.mark.parametrize("command", [["collapse", "--input", "column.nc", "--steps", "2"],
                                     ["pack", "--r0", "1", "--height", "1", "--max-steps", "3"]])
def test_a_checkpoint_path_naming_another_file_leaves_it_alone(work, command):
    """Issue 45.2: `--checkpoint notes.txt` (or another run's analysis) is refused before any step;
    the file is as it was."""
    (work / "notes.txt").write_text("my notes\n")
    done = colsim(*command, "--checkpoint", "notes.txt", "--output", "x.nc", cwd=work)
    one_line_error(done, 2, "notes.txt", "not a colsim checkpoint")
    assert (work / "notes.txt").read_text() == "my notes\n" and not (work / "x.nc").exists()


def test_an_output_onto_a_device_or_a_fifo_is_refused(work):
    """Issue 45.2: colsim replaces only regular files (or links, by rename): /dev/null and a FIFO stay."""
    os.mkfifo(work / "fifo")
    for target in ("/dev/null", "fifo"):
        done = colsim("trim", "--input", "pack.nc", "--aspect-ratio", "1", "--output", target, cwd=work)
        one_line_error(done, 2, target, "not a regular file")
    assert (work / "fifo").is_fifo() and Path("/dev/null").is_char_device()


@pytest.mark.parametrize("args, words", [
    (["collapse", "--input", "column.nc", "--checkpoint", "out.nc", "--output", "out.nc"], ["two outputs"]),
    (["collapse", "--input", "column.nc", "--checkpoint", "column.nc", "--output", "out.nc"],
     ["column.nc", "both an input and an output"]),
    (["collapse", "--input", "column.nc", "--output", "column.nc"], ["both an input and an output"]),
    (["trim", "--input", "pack.nc", "--aspect-ratio", "1", "--output", "pack.nc"], ["both an input and an output"]),
    (["analyse", "--input", "collapse.nc", "--output", "collapse.nc"], ["both an input and an output"]),
    (["collect", "analysis.nc", "--output", "analysis.nc"], ["both an input and an output"]),
    (["collect", "analysis.nc", "--output", "s.nc", "--csv", "s.nc"], ["two outputs"]),
])
def test_no_command_writes_over_its_input_or_one_path_twice(work, args, words):
    before = {p.name: p.read_bytes() for p in work.iterdir()}
    one_line_error(colsim(*args, cwd=work), 2, *words)
    assert {p.name: p.read_bytes() for p in work.iterdir()} == before


def spoil(path, how: str):
    """Rewrite the column file at `path` into an impossible one."""
    column = xr.load_dataset(path)
    position, radius = column["position"].values.copy(), column["radius"].values.copy()
    if how == "overlap":        # sphere 1, made sphere 0's size, overlaps it by 96 % of its diameter
        inward = np.array([-position[0, 0], -position[0, 1], 0.0])     # towards the axis: inside the wall
        radius[1] = radius[0]
        position[1] = position[0] + 0.04 * 2 * radius[0] * inward / np.linalg.norm(inward)
    elif how == "below":
        position[3, 2] = -1.0
    elif how == "huge":
        radius[2] = 100.0
    elif how == "nan":
        position[4, 0] = np.nan
    column["position"].values[:], column["radius"].values[:] = position, radius
    if how == "empty":
        column = column.isel(particle=[])
        for variable in column.variables.values():
            variable.encoding = {}          # the stored chunking does not fit an empty dimension
    if how == "no-radius":
        column = column.drop_vars("radius")
    path.unlink()
    column.to_netcdf(path)


@pytest.mark.parametrize("how, words", [
    ("overlap", ["spheres 0 and 1 overlap"]),
    ("below", ["sphere 3", "below the floor"]),
    ("huge", ["sphere 2", "diameter 200", "outside the stated 0.25-0.5"]),
    ("nan", ["sphere 4", "non-finite position"]),
    ("empty", ["holds no spheres"]),
    ("no-radius", ["lacks the variable", "radius"]),
])
def test_an_impossible_column_is_refused_before_any_step(work, how, words):
    spoil(work / "column.nc", how)
    one_line_error(colsim("collapse", "--input", "column.nc", "--steps", "5", "--output", "out.nc", cwd=work), 2, *words)
    assert not (work / "out.nc").exists() and not (work / "out.nc.checkpoint").exists()


@pytest.mark.parametrize("args, status, words", [
    (["pack", "--height", "inf", "--output", "x.nc"], 2, ["--height", "finite"]),
    (["pack", "--height", "nan", "--output", "x.nc"], 2, ["--height", "finite"]),
    (["pack", "--height", "1", "--dt", "1e300", "--output", "x.nc"], 2, ["dt = 1e+300", "time to fall"]),
    (["collapse", "--input", "column.nc", "--max-duration", "inf", "--output", "x.nc"], 2, ["--max-duration", "finite"]),
    (["pack", "--r0", "1e6", "--height", "1", "--output", "x.nc"], 2, ["spheres", "--max-spheres"]),
    (["pack", "--r0", "20", "--height", "100", "--output", "x.nc"], 2, ["spheres", "--max-spheres"]),
    (["analyse", "--input", "collapse.nc", "--bin-width", "1e-12", "--output", "x.nc"], 2, ["--bin-width"]),
])
def test_numbers_out_of_reach_get_one_line(work, args, status, words):
    one_line_error(colsim(*args, cwd=work), status, *words)
    assert not (work / "x.nc").exists()


def test_outputs_of_one_command_are_written_all_or_none(tmp_path):
    """io.write_all renames nothing unless every writer finished: a failing third writer leaves the
    first two files as they were and no temporary file behind."""
    (tmp_path / "a.txt").write_text("old a")

    def fail(path):
        raise OSError(28, "No space left on device", str(path))

    with pytest.raises(OSError):
        io.write_all({tmp_path / "a.txt": lambda p: p.write_text("new a"),
                      tmp_path / "b.txt": lambda p: p.write_text("new b"), tmp_path / "c.txt": fail})
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt"]
    assert (tmp_path / "a.txt").read_text() == "old a"


def test_a_failed_vtk_export_leaves_the_earlier_series(files, tmp_path, monkeypatch):
    trajectory = io.open_dataset(files / "collapse.nc", io.TRAJECTORY_KIND)
    export_trajectory(trajectory, tmp_path)
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    calls = {"n": 0}
    from colsim.io import vtk

    original = vtk.write_vtu

    def fails_on_the_second(path, *args):
        calls["n"] += 1
        if calls["n"] == 2:
            raise OSError(28, "No space left on device", str(path))
        original(path, *args)

    monkeypatch.setattr(vtk, "write_vtu", fails_on_the_second)
    moved = trajectory.assign(position=trajectory["position"] + 1.0)
    with pytest.raises(OSError):
        export_trajectory(moved, tmp_path)
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before


def test_a_full_disk_is_one_line(work):
    """An OSError from the file system (here: the output's folder is a file) is one line, exit 2
    before any work; at run time it would be exit 1."""
    (work / "blocked").write_text("")
    one_line_error(colsim("trim", "--input", "pack.nc", "--aspect-ratio", "1", "--output", "blocked/c.nc", cwd=work),
                   2, "blocked")


def _rewrite(path, change):
    """Load the netCDF file at `path`, apply change(dataset) (which returns the new dataset), write it back."""
    dataset = xr.load_dataset(path)
    dataset = change(dataset)
    for variable in dataset.variables.values():
        variable.encoding = {}
    path.unlink()
    dataset.to_netcdf(path)


def _set_attr(name, value):
    def change(dataset):
        dataset.attrs[name] = value
        return dataset
    return change


def _set_values(name, spoil):
    def change(dataset):
        values = dataset[name].values.copy()
        spoil(values)
        dataset[name] = (dataset[name].dims, values, dataset[name].attrs)
        return dataset
    return change


@pytest.mark.parametrize("file, change, command, words", [
    ("column.nc", _set_attr("r0", np.array([1.0, 2.0])), "collapse", ["attribute r0", "not one number"]),
    ("analysis.nc", _set_attr("config", "[1, 2, 3]"), "collect", ["attribute config is not a JSON object"]),
    ("collapse.nc", _set_attr("r0", 0.0), "analyse", ["attribute r0 is 0", "positive"]),
    ("collapse.nc", lambda d: d.isel(frame=[]), "analyse", ["holds no frame"]),   # frames as stored: io.cf.FRAME
    ("column.nc", _set_values("contact_first", lambda v: v.__setitem__(0, 10**6)), "collapse",
     ["contact names a sphere outside"]),
    ("column.nc", _set_values("contact_force", lambda v: v.__setitem__((0, 0), np.nan)), "collapse",
     ["contact force is not finite"]),
    ("column.nc", lambda d: d.assign(position=d.position.assign_attrs(units="mm")), "collapse", ["'mm'", "'m'"]),
    ("analysis.nc", _set_attr("seed", 1.7), "collect", ["seed", "integer"]),
    ("collapse.nc", _set_values("position", lambda v: v.__setitem__((0, 0, 0), np.nan)), "export-vtk",
     ["position is not finite"]),
    ("collapse.nc", _set_values("radius", lambda v: v.__setitem__(0, -0.1)), "export-vtk", ["radius"]),
])
def test_a_damaged_file_is_refused_in_one_line(work, file, change, command, words):
    """Issue 45.6: each of these gave a traceback or was used silently; now the command names the file
    and what is wrong with it, before any work, and writes nothing."""
    _rewrite(work / file, change)
    arguments = {"collapse": ["collapse", "--input", "column.nc", "--steps", "2", "--output", "out.nc"],
                 "collect": ["collect", "analysis.nc", "--output", "out.nc"],
                 "analyse": ["analyse", "--input", "collapse.nc", "--output", "out.nc"],
                 "export-vtk": ["export-vtk", "--input", "collapse.nc", "--output-dir", "vtk"]}[command]
    one_line_error(colsim(*arguments, cwd=work), 2, file, *words)
    assert not (work / "out.nc").exists() and not (work / "vtk").exists()


def test_a_small_file_declaring_a_huge_dimension_is_refused_before_it_is_read(work):
    """Issue 45.6: an analysis of a few kB whose variable spans 10^8 values (compressed, never
    written) made `collect` allocate GiBs; its size is checked before anything is read."""
    import netCDF4

    path = work / "analysis.nc"
    with netCDF4.Dataset(path, "a") as dataset:
        dataset.createDimension("huge", 10**8)
        dataset.createVariable("mass_front_over_r0_huge", "f8", ("huge",), zlib=True)
    assert path.stat().st_size < 1_000_000
    one_line_error(colsim("collect", "analysis.nc", "--output", "out.nc", cwd=work), 2, "analysis.nc", "GiB once read")


@pytest.mark.parametrize("args, words", [
    (["collapse", "--input", "column.nc", "--duration", "1e-300", "--steps", "3", "--output", "x.nc"],
     ["dt/sqrt(h0/g)", "below 1e-09"]),
    (["collapse", "--input", "column.nc", "--solver", "clarabel", "--solver-overlap-tolerance", "1e-3",
      "--output", "x.nc"], ["--solver-overlap-tolerance is APGD's", "ignore"]),
    (["pack", "--r0", "1", "--height", "1", "--gravity", "1e-300", "--output", "x.nc"],
     ["sqrt(d_min/g)", "gravity 1e-300"]),
])
def test_settings_a_run_cannot_honour_are_refused(work, args, words):
    """Issue 45.6: a step too small for its arithmetic, APGD's options given to Clarabel (ignored, yet
    recorded) and a gravity at which the spheres fly off."""
    one_line_error(colsim(*args, cwd=work), 2, *words)
    assert not (work / "x.nc").exists()


@pytest.mark.parametrize("gravity, words", [
    (1e-300, ["column.nc", "sqrt(d_min/g)", "gravity 1e-300"]),   # as `colsim pack --gravity 1e-300`
    (1.0, ["column.nc", "its gravity 1 is not the 9.81 its packing was poured under"]),
])
def test_a_column_s_gravity_is_checked_as_the_pour_checks_it(work, gravity, words):
    """Issue 80.6: a column whose gravity was 1e-300 collapsed to h_inf/r0 = 23.5, exit 0, where
    `colsim pack` refuses the same gravity; trim and collapse now check a file's gravity so."""
    for name, command in (("column.nc", ["collapse", "--input", "column.nc", "--steps", "2", "--output", "x.nc"]),
                          ("pack.nc", ["trim", "--input", "pack.nc", "--aspect-ratio", "1", "--output", "x.nc"])):
        _rewrite(work / name, _set_attr("gravity", gravity))
        one_line_error(colsim(*command, cwd=work), 2, name, *words[1:])
        assert not (work / "x.nc").exists()


def test_a_trajectory_whose_times_go_back_is_refused(work):
    """Issue 80.6: the frames' times are checked as the collapse's steps are: finite and increasing."""
    def back(dataset):   # the frames' seconds since release, along `frame`
        times = dataset["elapsed_time"].values.copy()
        times[-1] = times[0]
        return dataset.assign_coords(elapsed_time=("frame", times, dict(dataset["elapsed_time"].attrs)))
    _rewrite(work / "collapse.nc", back)
    one_line_error(colsim("analyse", "--input", "collapse.nc", "--output", "out.nc", cwd=work), 2, "collapse.nc",
                   "times are not finite and increasing")


@pytest.mark.parametrize("change, words", [
    (lambda dataset: dataset.assign(at_rest=("two", np.array([1, 1], dtype=np.int8))), "at_rest flag has shape (2,)"),
    (lambda dataset: dataset.isel(step=slice(0, 0)), "holds no step"),
])
def test_a_trajectory_of_an_odd_shape_is_refused_in_one_line(work, change, words):
    """Issue 80.7: a trajectory whose at_rest has shape (2,), or one with no steps, ended `analyse`
    in a traceback."""
    _rewrite(work / "collapse.nc", change)
    one_line_error(colsim("analyse", "--input", "collapse.nc", "--output", "out.nc", cwd=work), 2, "collapse.nc",
                   words)
    assert not (work / "out.nc").exists()


def test_numba_s_thread_count_zero_is_refused_in_one_line(work):
    """Issue 80.7: NUMBA_NUM_THREADS=0 made numba's import raise, a traceback before any command ran."""
    done = subprocess.run([sys.executable, "-m", "colsim.cli", "collapse", "--input", "column.nc", "--steps", "2",
                           "--output", "x.nc"], cwd=work, capture_output=True, text=True, timeout=300,
                          env={**os.environ, "NUMBA_NUM_THREADS": "0"})
    one_line_error(done, 2, "NUMBA_NUM_THREADS='0'", "whole number >= 1")
    assert not (work / "x.nc").exists()


def _tbb_loads() -> bool:
    """Whether numba starts its threads on TBB in a fresh interpreter, as colsim would: numba opens
    libtbb by name first, so an interpreter whose own lib/ holds it (its run path; a base Python that
    pip installed tbb into) loads the layer, and a virtual environment's lib/ alone does not."""
    probe = "import numba; numba.set_num_threads(1); assert numba.threading_layer() == 'tbb'"
    return subprocess.run([sys.executable, "-c", probe], capture_output=True,
                          env={**os.environ, "NUMBA_THREADING_LAYER": "tbb"}).returncode == 0


def test_a_tbb_layer_numba_cannot_load_is_explained_in_one_line(work):
    """Issue 80.9: NUMBA_THREADING_LAYER=tbb in a plain venv failed with "Intel TBB is required, try:
    pip install tbb" though tbb was installed: the loader does not search the venv's lib/. colsim says
    which library failed to load and how to point the loader at it."""
    if _tbb_loads():
        pytest.skip("numba loads TBB here")
    done = subprocess.run([sys.executable, "-m", "colsim.cli", "collapse", "--input", "column.nc", "--steps", "2",
                           "--output", "x.nc"], cwd=work, capture_output=True, text=True, timeout=300,
                          env={**os.environ, "NUMBA_THREADING_LAYER": "tbb"})
    one_line_error(done, 2, "numba cannot load its TBB threading layer", "libtbb", "LD_LIBRARY_PATH",
                   "unset NUMBA_THREADING_LAYER")
    assert not (work / "x.nc").exists()


def test_a_command_removes_the_temporaries_a_killed_run_left_of_its_outputs(work):
    """Issue 80.8: SIGKILL left hidden .part temporaries that nothing removed; `colsim analyse`
    removes those of its own output as it starts, and leaves another output's."""
    mine, other = work / ".out.nc.k1ll3d00.part", work / ".analysis.nc.k1ll3d00.part"
    for path in (mine, other):
        path.write_bytes(b"half a file")
    done = colsim("analyse", "--input", "collapse.nc", "--output", "out.nc", cwd=work)
    assert done.returncode == 0, done.stderr[-2000:]
    assert not mine.exists() and other.exists() and (work / "out.nc").is_file()
