"""Issue 48.7: the study-level files colsim writes pass the IOOS checker's CF-1.8 suite at strict
level, as the stages' files do (tests/io/test_netcdf.py): the convergence table and the column-size
limits (`colsim convergence`) and the friction-law comparison (`colsim compare-laws`), made by the
commands from analysis files written through colsim's own writer."""
from __future__ import annotations

from colsim import io
from helpers import cf_check_failures, main_in
from test_collect_cli import _analysis_file
from test_convergence import analysis


def test_the_convergence_table_and_the_column_size_limits_pass_the_cf_checker(tmp_path):
    paths = []
    for r0 in (2.0, 3.0):
        for seed in (1, 2):
            run = analysis(a=2.0, r0=r0, seed=seed, h=0.9 - 0.4 / r0, runout=3.5 - 1.5 / r0)
            run.attrs.update(io.global_attributes(io.ANALYSIS_KIND, "synthetic analysis", {"command": "analyse"}, seed))
            for variable in run.variables.values():
                variable.attrs.setdefault("long_name", "x")
            paths.append(str(tmp_path / f"analysis_{r0:g}_{seed}.nc"))
            io.write_dataset(run, paths[-1])
    assert main_in(tmp_path, ["convergence", "--column-size", *paths, "--default-end", "4",
                              "--output", "table.nc", "--limits", "limits.nc"]) == 0
    for name in ("table.nc", "limits.nc"):
        assert cf_check_failures(tmp_path / name) == [], name


def test_the_friction_law_comparison_passes_the_cf_checker(tmp_path):
    laws = {}
    for law in ("associated", "coulomb"):
        laws[law] = []
        for a in (1.0, 2.0):
            path = tmp_path / f"{law}_{a:g}.nc"
            _analysis_file(path, aspect_ratio=a, friction_law=law, friction_tolerance=1e-5)
            run = io.open_dataset(path, io.ANALYSIS_KIND)
            run.attrs["friction_law"] = law   # as `colsim analyse` copies it from the collapse
            io.write_dataset(run, path)
            laws[law].append(str(path))
    assert main_in(tmp_path, ["compare-laws", "--associated", *laws["associated"], "--coulomb", *laws["coulomb"],
                              "--output", "friction_law.nc"]) == 0
    assert cf_check_failures(tmp_path / "friction_law.nc") == []
    assert list(io.open_dataset(tmp_path / "friction_law.nc", "friction-law-comparison").friction_law.values) == [
        "associated", "coulomb"]
