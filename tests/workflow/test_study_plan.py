"""colsim.study.workflow.plan without Snakemake: the folders of a study's packings, columns and runs
(the same keys as the workflow's dry runs), and the settings a folder's key names, values read back
from them and never parsed from a name."""
from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace

import pytest
import yaml
from snakemake.utils import validate

from colsim.study.workflow.plan import (COLUMN, PACKING_DIR, RUN_DIR, StudyPlan, UnknownFolder, benchmarked,
                                        fmt, logged, settings_key, study_dir)
from helpers import ROOT, RUN_PATH

SCHEMA = ROOT / "workflow" / "schemas" / "config.schema.yaml"


def study_config(*extra: dict) -> dict:
    """config.yaml, then config/tiny.yaml and `extra` over it (as snakemake merges them), with the
    schema's defaults filled in."""
    config = yaml.safe_load((ROOT / "config.yaml").read_text())

    def merge(into, update):
        for key, value in update.items():
            if isinstance(value, dict) and isinstance(into.get(key), dict):
                merge(into[key], value)
            else:
                into[key] = value

    for update in (yaml.safe_load((ROOT / "config" / "tiny.yaml").read_text()), *extra):
        merge(config, update)
    validate(config, str(SCHEMA))
    return config


def wildcards_of(path: str) -> SimpleNamespace:
    """The wildcards of a run's collapse.nc, as Snakemake gives them to a rule."""
    return SimpleNamespace(**RUN_PATH.match(path).groupdict())


@pytest.mark.parametrize("value, text", [(1, "1"), (1.0, "1"), (0.06, "0.06"), (0, "0"), (1e-5, "1e-05"),
                                         (math.pi / 24, "0.1308996938995747"), (0.1000001, "0.1000001")])
def test_a_number_names_a_folder_without_loss(value, text):
    assert fmt(value) == text and float(fmt(value)) == value


def test_a_key_is_ten_hex_digits_of_the_settings_in_any_order():
    key = settings_key({"a": 1, "b": [1, 2]})
    assert len(key) == 10 and int(key, 16) >= 0
    assert key == settings_key({"b": [1, 2], "a": 1}) != settings_key({"a": 1.5, "b": [1, 2]})


def test_the_tiny_study_names_the_folders_of_its_dry_run():
    """The keys are those the workflow planned before the helpers left common.smk."""
    plan = StudyPlan(study_config())
    assert plan.study_runs("collapse.nc") == [
        f"results/r0_1/seed_1/pack_af320959e1/a_{a}/mu_r_{m}/run_{run}/collapse.nc"
        for a in ("0.5", "1") for m, run in (("0", "2874ba662f"), ("0.12", "a1e8f1b7ba"))]
    assert plan.study_dir == "results/tiny" and study_dir({"study": ""}) == "results"
    assert set(plan.packings) == {"af320959e1"} and set(plan.runs) == {"2874ba662f", "a1e8f1b7ba"}
    assert RUN_DIR.startswith(PACKING_DIR) and COLUMN.startswith(PACKING_DIR)
    assert logged("results/r0_1/x.log") == "results/logs/r0_1/x.log"
    assert benchmarked("results/r0_1/x.tsv") == "results/benchmarks/r0_1/x.tsv"


def test_a_folder_gives_back_the_values_that_named_it():
    """mu_r = pi/24, r0, seed and a come back from the settings as numbers, not from the folder's name."""
    plan = StudyPlan(study_config({"mu_r": [math.pi / 24]}))
    path = plan.study_runs("collapse.nc")[0]
    wildcards = wildcards_of(path)
    assert wildcards.mu_r == "0.1308996938995747"
    run = plan.run_of(wildcards)
    assert run["mu_r"] == math.pi / 24 and run["friction_law"] == "associated" and run["steps"] == 100
    packing = plan.packing_of(wildcards)
    assert (packing["r0"], packing["seed"], packing["height"]) == (1.0, 1, 1.0)
    assert plan.column_of(wildcards) == 0.5 and isinstance(plan.column_of(wildcards), float)


def test_the_friction_law_comes_from_the_run_settings_not_its_path():
    """A Coulomb run's folder does not name its law: the rules read it from the settings its key names."""
    plan = StudyPlan(study_config({"friction_law_comparison": True}))
    associated = plan.study_runs("collapse.nc", law="associated")
    coulomb = plan.study_runs("collapse.nc", law="coulomb")
    assert not set(associated) & set(coulomb) and not any("coulomb" in path for path in coulomb)
    assert {plan.run_of(wildcards_of(p))["friction_law"] for p in coulomb} == {"coulomb"}
    assert {plan.run_of(wildcards_of(p))["friction_tolerance"] for p in coulomb} == {1e-5}
    assert {plan.run_of(wildcards_of(p))["friction_tolerance"] for p in associated} == {None}
    assert plan.friction_law_outputs() == ["results/tiny/friction_law.nc", "results/tiny/friction_law.md",
                                           "results/tiny/figures/friction_law.png"]


def test_a_folder_the_study_does_not_name_is_unknown():
    plan = StudyPlan(study_config())
    wildcards = wildcards_of(plan.study_runs("collapse.nc")[1])
    for change, lookup in (({"run": "0123456789"}, plan.run_of), ({"mu_r": "0.3"}, plan.run_of),
                           ({"packing": "0123456789"}, plan.packing_of), ({"r0": "2"}, plan.packing_of),
                           ({"a": "7"}, plan.column_of)):
        with pytest.raises(UnknownFolder, match="of this study has the folder"):
            lookup(SimpleNamespace(**{**vars(wildcards), **change}))


def test_the_side_view_takes_the_nearest_swept_mu_r_as_a_number():
    plan = StudyPlan(study_config({"mu_r": [0, 0.06, 0.2], "figures": {"side_view_mu_r": 0.12}}))
    assert plan.side_view_mu_r() == 0.06
    assert all("/mu_r_0.06/" in p for p in plan.study_runs("collapse.nc", mu_r=plan.side_view_mu_r()))


def test_the_study_runs_to_rest_only_at_its_own_length():
    plan = StudyPlan(study_config({"collapse": {"max_duration": 8.0}}))
    assert plan.goes_to_rest(100, 4.0) and not plan.goes_to_rest(200, 4.0) and not plan.goes_to_rest(100, 8.0)
    assert plan.run_settings(0.12, 100, 4.0, "associated")["rest"]["max_duration"] == 8.0
    assert plan.run_settings(0.12, 200, 4.0, "associated")["rest"] is None


def test_a_convergence_packing_is_just_tall_enough():
    convergence = {"convergence": {"mu_r": 0.12, "time_step": {"aspect_ratios": [0.5], "steps": [200]},
                                   "end_time": {"aspect_ratios": [0.5], "duration": 6.0},
                                   "column_size": [{"aspect_ratio": 0.5, "r0": [1, 1.25]}],
                                   "seeds": {"aspect_ratio": 0.5, "seeds": [1, 2]}}}
    plan = StudyPlan(study_config(convergence))
    assert plan.pack_height(1, 1) == 1.0             # the study's own packing: its largest a
    assert plan.pack_height(1.25, 1) == 0.5 * 1.25   # another r0: the size study's a
    assert plan.pack_height(1, 2) == 0.5             # a seed of the seed study only
    runs = plan.convergence_runs("analysis.nc")
    assert {name: len(paths) for name, paths in runs.items()} == {
        "time_step": 1, "end_time": 1, "column_size": 2, "seeds": 2}
    assert "/r0_1.25/" in runs["column_size"][1] and plan.run_of(wildcards_of(
        str(Path(runs["end_time"][0]).with_name("collapse.nc"))))["steps"] == 150
    assert StudyPlan(study_config()).convergence_runs("analysis.nc") == {}
    assert len(plan.convergence_outputs()) == 5 and StudyPlan(study_config()).convergence_outputs() == []


def test_the_default_cylinder_study_keeps_its_keys():
    """config.yaml's own study (the cylinder, no channel setting) names the packings and runs it
    named before the channel geometry existed: its keys, and so its folders and files, are unchanged."""
    config = yaml.safe_load((ROOT / "config.yaml").read_text())
    validate(config, str(SCHEMA))
    plan = StudyPlan(config)
    paths = plan.study_runs("collapse.nc")
    assert len(paths) == 48
    assert paths[0] == "results/r0_3/seed_1/pack_3d781f786e/a_0.5/mu_r_0/run_f56bf2a142/collapse.nc"
    assert paths[-1] == "results/r0_3/seed_2/pack_2d924268af/a_5/mu_r_0.2/run_01bd302409/collapse.nc"
    assert sorted(plan.packings) == ["2d924268af", "3d781f786e"]
    assert sorted(plan.runs) == ["01bd302409", "078ce84642", "404261461e", "f56bf2a142"]


def test_a_channel_study_names_its_length_where_a_cylinder_s_names_r0():
    """geometry channel: a packing's settings hold channel_length L0 (the folder's r0_ names it) and
    channel_width, not the cylinder's r0; its height is the largest a times L0; a run's hold wall_mu;
    the folder gives L0 back, and a job's size is the box's (L0 W), not a cylinder's (pi L0^2)."""
    from colsim.stages.pour_geometry import Channel

    plan = StudyPlan(study_config({"geometry": "channel", "channel_length": 2.0, "channel_width": 0.8,
                                   "wall_mu": 0.3}))
    path = plan.study_runs("collapse.nc")[0]
    assert path.startswith("results/r0_2/seed_1/pack_")
    wildcards = wildcards_of(path)
    packing = plan.packing_of(wildcards)
    assert "r0" not in packing and (packing["geometry"], packing["channel_length"], packing["channel_width"],
                                    packing["height"]) == ("channel", 2.0, 0.8, 2.0)
    assert plan.run_of(wildcards)["wall_mu"] == 0.3
    assert plan.footprint(2.0) == Channel(2.0, 0.8) and StudyPlan(study_config()).footprint(2.0) == 2.0
