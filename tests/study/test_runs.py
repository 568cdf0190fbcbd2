"""A study's runs as one Dataset (colsim.study.open_runs), and the runs' scalar coordinates."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
import xarray as xr

import colsim.study


def _colsim(*args, cwd):
    done = subprocess.run([sys.executable, "-m", "colsim.cli", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    """results/ with two runs of one column (mu_r 0 and 0.12) in the study's folder layout, a
    third of 20 steps, which has frames the others lack, and a fourth of a shorter column (a = 0.6:
    fewer spheres, and its frames' times t/sqrt(h0/g) made from another h0); a study "two" whose
    summary collected the first two."""
    root = tmp_path_factory.mktemp("study")
    pack = root / "results" / "r0_1" / "seed_1" / "pack_0123456789"
    pack.mkdir(parents=True)
    _colsim("pack", "--r0", "1", "--height", "1", "--seed", "1", "--output", str(pack / "packing.nc"), cwd=root)
    for a, mu_r, steps in (("1", "0", 10), ("1", "0.12", 10), ("1", "0.12", 20), ("0.6", "0.12", 10)):
        column = pack / f"a_{a}"
        if not (column / "column.nc").exists():
            column.mkdir()
            _colsim("trim", "--input", str(pack / "packing.nc"), "--aspect-ratio", a, "--output",
                    str(column / "column.nc"), cwd=root)
        run = column / f"mu_r_{mu_r}" / f"run_{steps:010d}"
        run.mkdir(parents=True)
        _colsim("collapse", "--input", str(column / "column.nc"), "--mu-r", mu_r, "--steps", str(steps), "--duration",
                str(0.01 * steps), "--frame-every", "5", "--output", str(run / "collapse.nc"), cwd=root)
        _colsim("analyse", "--input", str(run / "collapse.nc"), "--output", str(run / "analysis.nc"), cwd=root)
    (root / "results" / "two").mkdir()
    _colsim("collect", *(str(p.relative_to(root)) for p in sorted(pack.glob("a_1/mu_r_*/run_0000000010/analysis.nc"))),
            "--output", "results/two/summary.nc", cwd=root)
    return root / "results"


def test_the_runs_stack_along_run_with_their_values_as_coordinates(results):
    """Issue 48.5: every analysis along `run`, with aspect_ratio, mu_r, seed, r0 and path as its
    coordinates; frames aligned on t/sqrt(h0/g), NaN where a run has none."""
    runs = colsim.study.open_runs(results).where(lambda r: r.aspect_ratio == 1, drop=True)
    assert runs.sizes["run"] == 3
    np.testing.assert_allclose(sorted(runs.mu_r.values), [0.0, 0.12, 0.12])
    assert set(runs.seed.values) == {1} and set(runs.aspect_ratio.values) == {1.0} and set(runs.r0.values) == {1.0}
    assert runs.front_position.dims == ("run", "scaled_time")
    short = runs.where(runs.path.str.contains("run_0000000010"), drop=True)
    assert np.isnan(short.front_position.sel(scaled_time=0.2, method="nearest")).all()   # no frame at 0.2
    np.testing.assert_allclose(runs.h_inf_over_r0.values,
                               [float(xr.load_dataset(p).h_inf_over_r0) for p in runs.path.values])
    with pytest.raises(ValueError, match="no analysis.nc"):
        colsim.study.open_runs(results / "r0_9")


def test_each_file_names_its_run_by_scalar_coordinates(results):
    """The values are scalar coordinates of collapse.nc and analysis.nc (with units), so xarray's own
    nested combine stacks files of one length."""
    paths = sorted(str(p) for p in results.glob("r0_*/seed_*/pack_*/a_1/mu_r_*/run_000000001[0]/analysis.nc"))
    for path in paths:
        analysis = xr.load_dataset(path)
        assert {"aspect_ratio", "mu_r", "seed", "r0"} <= set(analysis.coords) and analysis.seed.ndim == 0
        assert analysis.r0.attrs["units"] == "m"
    combined = xr.combine_nested([xr.load_dataset(p) for p in paths], concat_dim="run")
    np.testing.assert_allclose(sorted(combined.mu_r.values), [0.0, 0.12])
    trajectory = xr.load_dataset(sorted(results.glob("r0_*/seed_*/pack_*/a_1/mu_r_0/run_*/collapse.nc"))[0])
    assert float(trajectory.mu_r) == 0.0 and int(trajectory.seed) == 1


def test_runs_of_one_step_share_their_frames_times(results):
    """Issue 79.3: the frames of runs of one time step fall on one scaled_time (before: a column of
    another h0 put its frames at 0.049999999999999996 beside 0.05, and half of every series was NaN)."""
    runs = colsim.study.open_runs(results)
    ten_steps = runs.where(runs.n_steps == 10, drop=True)
    assert ten_steps.sizes["run"] == 3 and set(ten_steps.aspect_ratio.values) == {0.6, 1.0}
    frames = ten_steps.front_position.dropna("scaled_time", how="all")
    assert frames.sizes["scaled_time"] == 3 and not frames.isnull().any()   # t = 0, 0.05, 0.1: 10 steps, a frame every 5
    assert runs.sizes["scaled_time"] == 5   # and the 20-step run's two more
    lines = ten_steps.front_position.plot.line(x="scaled_time", hue="path")
    assert len(lines) == 3


def test_a_study_gives_the_runs_its_summary_collected(results, tmp_path):
    """Issue 79.3: open_runs(study=...) by name or by configuration file: only the runs that study's
    summary collected, with friction law, lever and steps as coordinates."""
    config = tmp_path / "two.yaml"
    config.write_text("study: two\n")
    for study in ("two", str(config)):
        runs = colsim.study.open_runs(results, study=study)
        assert runs.sizes["run"] == 2 and sorted(runs.mu_r.values.tolist()) == [0.0, 0.12]
        assert set(runs.friction_law.values) == {"associated"} and set(runs.n_steps.values) == {10}
        assert runs.rolling_lever.size == 2
    with pytest.raises(ValueError, match="no summary of study 'none'"):
        colsim.study.open_runs(results, study="none")


def test_profiles_share_one_grid_of_r_over_r0(results):
    """Every run's deposit profile on one r/r0 grid: at the file's own bins its heights unchanged,
    beyond its deposit 0 (no grain of its main mass there), no bin left without a value by the grid."""
    runs = colsim.study.open_runs(results)
    assert runs.deposit_height.dims == ("run", "radial_bin_over_r0")
    for k, path in enumerate(runs.path.values):
        own = xr.load_dataset(path)
        on_grid = runs.deposit_height.isel(run=k).sel(radial_bin_over_r0=own.radial_bin.values / float(own.r0),
                                                      method="nearest")
        np.testing.assert_allclose(on_grid.values, own.deposit_height.values, rtol=0, atol=1e-12)
        beyond = runs.radial_bin_over_r0 > own.radial_bin.values[-1] / float(own.r0) + 1e-9
        assert (runs.deposit_height.isel(run=k).where(beyond, drop=True) == 0).all()


def test_trajectories_stack_with_their_particles_padded(results):
    """Issue 79.3: open_runs(name="collapse.nc") stacks columns of different sizes (it raised
    AlignmentError on `particle`): the smaller column's missing particles are NaN."""
    runs = colsim.study.open_runs(results, name="collapse.nc")
    sizes = [xr.load_dataset(p).sizes["particle"] for p in runs.path.values]
    assert runs.sizes["particle"] == max(sizes) > min(sizes)
    small = runs.position.isel(run=int(np.argmin(sizes))).dropna("scaled_time", how="all")   # its own frames
    assert small.isel(particle=slice(min(sizes), None)).isnull().all()
    assert not small.isel(particle=slice(0, min(sizes))).isnull().any()


def test_analyses_named_by_their_settings_key_are_found(results, tmp_path):
    """Issue 79.4: a study's analysis is analysis_KEY.nc (KEY: its analysis settings'); open_runs reads
    those beside an older study's analysis.nc, each one run."""
    import shutil
    copy = tmp_path / "results"
    shutil.copytree(results, copy)
    older = sorted(copy.glob("r0_*/seed_*/pack_*/a_1/mu_r_0/run_*/analysis.nc"))[0]
    older.rename(older.with_name("analysis_0123456789.nc"))
    runs = colsim.study.open_runs(copy)
    assert runs.sizes["run"] == 4 and sum(p.endswith("/analysis_0123456789.nc") for p in runs.path.values) == 1
