"""`colsim collect` on analyses that differ in what a study may and may not sweep."""
from __future__ import annotations

import pytest
import xarray as xr

from colsim import io
from colsim.study.collect import SUMMARY_VARIABLES

from helpers import main_in


def _analysis_file(path, r0=1.0, aspect_ratio=1.0, steps=40, pack=None, **collapse):
    """A small analysis file as `colsim analyse` writes it, with its configuration chain (collapse:
    more `colsim collapse` options; pack: the `colsim pack` options, if any)."""
    trim = {"command": "trim", "aspect_ratio": aspect_ratio}
    if pack is not None:
        trim["input_config"] = {"command": "pack", **pack}
    config = {"command": "analyse", "contact_tolerance": 0.01, "input": "collapse.nc",
              "input_config": {"command": "collapse", "steps": steps, "mu_r": 0.12, "output": "collapse.nc",
                               **collapse, "input_config": trim}}
    attrs = {**io.global_attributes(io.ANALYSIS_KIND, "t", config, seed=1), "aspect_ratio": aspect_ratio,
             "mu_r": 0.12, "mu": 0.577, "r0": r0, "h0": aspect_ratio * r0, "duration": 4.0, "n_steps": steps}
    data = {name: ((), 1.0, {"units": "1", "long_name": name}) for name in SUMMARY_VARIABLES}
    io.write_dataset(xr.Dataset(data, attrs=attrs), path)


@pytest.mark.parametrize("first, second, field", [
    ({"r0": 1.5}, {"r0": 1.0}, "runs differ in r0: 1.5 in"),
    ({"steps": 40}, {"steps": 80}, "runs differ in collapse.steps: 40 in"),
    ({"friction_law": "coulomb", "friction_tolerance": 1e-5}, {"friction_law": "coulomb", "friction_tolerance": 1e-4},
     "runs differ in collapse.friction_tolerance: 1e-05 in"),
    # a run made before the length floor records no solver settings: not one study with one after
    ({"solver_settings": {"name": "auto", "apgd": {"length_floor": 0.1}}}, {},
     "runs differ in collapse.solver_settings: {"),
])
def test_collect_refuses_runs_that_differ_in_an_unswept_setting(tmp_path, capsys, first, second, field):
    """Issue 16, defect 5: collecting an r0 = 1.5 analysis with an r0 = 1 one names the field."""
    _analysis_file(tmp_path / "a.nc", aspect_ratio=1.0, **first)
    _analysis_file(tmp_path / "b.nc", aspect_ratio=2.0, **second)
    assert main_in(tmp_path, ["collect", "a.nc", "b.nc", "--output", "summary.nc"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and field in err and "a.nc" in err and "b.nc" in err, err
    assert not (tmp_path / "summary.nc").exists()
    _analysis_file(tmp_path / "b.nc", aspect_ratio=2.0, **first)      # same settings: collected
    assert main_in(tmp_path, ["collect", "a.nc", "b.nc", "--output", "summary.nc"]) == 0


def test_associated_runs_are_collected_whatever_their_unused_friction_tolerance(tmp_path):
    """The Coulomb fixed point's tolerance does not touch an associated run (its CLI default changed
    from 1e-4 to 1e-5): runs made before and after are one study."""
    _analysis_file(tmp_path / "a.nc", aspect_ratio=1.0, friction_law="associated", friction_tolerance=1e-4)
    _analysis_file(tmp_path / "b.nc", aspect_ratio=2.0, friction_law="associated", friction_tolerance=1e-5)
    assert main_in(tmp_path, ["collect", "a.nc", "b.nc", "--output", "summary.nc"]) == 0


def test_packings_poured_in_one_cloud_before_and_after_layers_are_one_study(tmp_path, capsys):
    """A packing made before layers existed (no layer_height, no max_spheres bound) and one poured in
    one cloud since (layer_height None, its unused freeze depth, the bound) are the same filling: one
    study. A packing filled in layers is not."""
    _analysis_file(tmp_path / "a.nc", aspect_ratio=1.0, pack={"mu": 0.0, "dt": 0.02})
    _analysis_file(tmp_path / "b.nc", aspect_ratio=2.0, pack={"mu": 0.0, "dt": 0.02, "layer_height": None,
                                                              "freeze_depth": 3.5, "max_spheres": 500000})
    assert main_in(tmp_path, ["collect", "a.nc", "b.nc", "--output", "summary.nc"]) == 0
    _analysis_file(tmp_path / "c.nc", aspect_ratio=3.0, pack={"mu": 0.0, "dt": 0.02, "layer_height": 2.5,
                                                              "freeze_depth": 3.5, "max_spheres": 500000})
    assert main_in(tmp_path, ["collect", "a.nc", "c.nc", "--output", "summary2.nc"]) == 2
    assert "runs differ in pack.freeze_depth: None in" in capsys.readouterr().err   # the first named


def test_runs_on_a_gpu_on_the_cpu_and_from_settings_files_are_one_study(tmp_path):
    """The device, like the thread count, changes a result by rounding only; the settings file a run
    read and the logging flags are not settings either: runs that differ in them alone, or that
    predate them (no such key), are collected together."""
    _analysis_file(tmp_path / "a.nc", aspect_ratio=1.0, device="cuda", settings="run_a/settings.yaml",
                   pack={"mu": 0.0, "device": "cuda"})
    _analysis_file(tmp_path / "b.nc", aspect_ratio=2.0, device="cpu", quiet=True, pack={"mu": 0.0, "device": "cpu"})
    _analysis_file(tmp_path / "c.nc", aspect_ratio=3.0, pack={"mu": 0.0})
    assert main_in(tmp_path, ["collect", "a.nc", "b.nc", "c.nc", "--output", "summary.nc"]) == 0



#: the commands that read runs: each the same checks (issue 80.3)
READERS = {"collect": ["collect", "a.nc", "{second}", "--output", "out.nc"],
           "calibrate": ["calibrate", "a.nc", "{second}", "--output", "out.nc", "--replicates", "10"],
           "column-size fit": ["convergence", "--column-size", "a.nc", "{second}", "--default-end", "4",
                               "--output", "out.nc"]}


@pytest.mark.parametrize("command", READERS)
@pytest.mark.parametrize("second, words", [
    ({}, "two analyses share the same"),   # the same run given twice: counted twice in a calibration
    ({"friction_law": "coulomb"}, "runs differ in collapse.friction_law: None in"),
    ({"rolling_lever": "paper"}, "runs differ in collapse.rolling_lever: effective in"),
    ({"solver_tolerance": 1e-3}, "runs differ in collapse.solver_tolerance: None in"),
])
def test_every_command_that_reads_runs_refuses_what_collect_refuses(tmp_path, capsys, command, second, words):
    """Issue 80.3: `colsim calibrate` counted a duplicated analysis twice (the height limit moved from
    0.99203 to 0.99361) and took runs of another friction law, lever or solver tolerance; it and the
    column-size fit now run collect's checks and name the odd run in one line."""
    _analysis_file(tmp_path / "a.nc")
    if second:
        _analysis_file(tmp_path / "b.nc", aspect_ratio=2.0, **second)
    arguments = [word.format(second="b.nc" if second else "a.nc") for word in READERS[command]]
    assert main_in(tmp_path, arguments) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and words in err and "a.nc" in err, err
    assert not (tmp_path / "out.nc").exists()


@pytest.mark.parametrize("command", READERS)
def test_a_run_result_of_two_values_is_refused_in_one_line(tmp_path, capsys, command):
    """Issue 80.7: an analysis whose h_inf_over_r0 has shape (2,) ended `collect` in a traceback."""
    _analysis_file(tmp_path / "a.nc")
    _analysis_file(tmp_path / "b.nc", aspect_ratio=2.0)
    with xr.open_dataset(tmp_path / "b.nc") as dataset:
        bad = dataset.load()
    bad["h_inf_over_r0"] = ("two", [1.0, 2.0], {"units": "1", "long_name": "h"})
    io.write_dataset(bad, tmp_path / "b.nc")
    assert main_in(tmp_path, [word.format(second="b.nc") for word in READERS[command]]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "b.nc" in err and "h_inf_over_r0 has shape (2,)" in err, err
