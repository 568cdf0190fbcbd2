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
    """results/ with two runs of one column (mu_r 0 and 0.12) in the study's folder layout, and a
    third of 20 steps, which has frames the others lack."""
    root = tmp_path_factory.mktemp("study")
    pack = root / "results" / "r0_1" / "seed_1" / "pack_0123456789"
    column = pack / "a_1"
    column.mkdir(parents=True)
    _colsim("pack", "--r0", "1", "--height", "1", "--seed", "1", "--output", str(pack / "packing.nc"), cwd=root)
    _colsim("trim", "--input", str(pack / "packing.nc"), "--aspect-ratio", "1", "--output", str(column / "column.nc"),
            cwd=root)
    for mu_r, steps in (("0", 10), ("0.12", 10), ("0.12", 20)):
        run = column / f"mu_r_{mu_r}" / f"run_{steps:010d}"
        run.mkdir(parents=True)
        _colsim("collapse", "--input", str(column / "column.nc"), "--mu-r", mu_r, "--steps", str(steps), "--duration",
                str(0.01 * steps), "--frame-every", "5", "--output", str(run / "collapse.nc"), cwd=root)
        _colsim("analyse", "--input", str(run / "collapse.nc"), "--output", str(run / "analysis.nc"), cwd=root)
    return root / "results"


def test_the_runs_stack_along_run_with_their_values_as_coordinates(results):
    """Issue 48.5: every analysis along `run`, with aspect_ratio, mu_r, seed, r0 and path as its
    coordinates; frames aligned on t/sqrt(h0/g), NaN where a run has none."""
    runs = colsim.study.open_runs(results)
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
    paths = sorted(str(p) for p in results.glob("r0_*/seed_*/pack_*/a_*/mu_r_*/run_000000001[0]/analysis.nc"))
    for path in paths:
        analysis = xr.load_dataset(path)
        assert {"aspect_ratio", "mu_r", "seed", "r0"} <= set(analysis.coords) and analysis.seed.ndim == 0
        assert analysis.r0.attrs["units"] == "m"
    combined = xr.combine_nested([xr.load_dataset(p) for p in paths], concat_dim="run")
    np.testing.assert_allclose(sorted(combined.mu_r.values), [0.0, 0.12])
    trajectory = xr.load_dataset(sorted(results.glob("r0_*/seed_*/pack_*/a_*/mu_r_0/run_*/collapse.nc"))[0])
    assert float(trajectory.mu_r) == 0.0 and int(trajectory.seed) == 1
