"""The workflow's settings files are what `colsim STAGE --settings` runs with, and the rules'
command lines name no setting that changes a result (issue 47)."""
import json
import re
from dataclasses import dataclass

import pytest
import yaml
from snakemake.exceptions import WorkflowError
from snakemake.utils import validate

from colsim.cli import build_parser
from colsim.cli.flags import stage_settings
from colsim.stages import settings as stage
from colsim.study.workflow import plan as plan_module
from colsim.study.workflow.plan import StudyPlan, settings_text
from helpers import ROOT, copy_workflow, snakemake
from test_study_plan import SCHEMA, study_config

FILES = {"pack": ["--output", "p.nc"], "collapse": ["--input", "c.nc", "--output", "o.nc"],
         "analyse": ["--input", "o.nc", "--output", "a.nc"]}


def _read(command, path):
    classes = (stage.STAGES[command], stage.SolverSettings) if command in stage.SOLVING_STAGES else (stage.STAGES[command],)
    return stage_settings(build_parser().parse_args([command, *FILES[command], "--settings", str(path)]), *classes)


def test_the_workflow_s_settings_files_are_what_the_stages_run_with(tmp_path):
    """A packing's, a run's and the analyses' settings.yaml, as the workflow writes them, read by
    `colsim STAGE --settings` into the stage's settings: each value the plan gives, nothing else."""
    plan = StudyPlan(study_config({"collapse": {"max_duration": 8, "rest_tolerance": 0.2}, "rolling_lever": "effective"}))
    cases = {"pack": plan.packing_settings(3.0, 2), "collapse": plan.run_settings(0.2, 100, 4.0, "coulomb"),
             "analyse": plan.analysis_settings()}
    made = {}
    for command, written in cases.items():
        path = tmp_path / f"{command}.yaml"
        path.write_text(settings_text(written) + "\n")
        made[command] = _read(command, path)
    packing, pack_solver = made["pack"]
    config = plan.config
    assert (packing.r0, packing.seed, packing.height, packing.root_seed) == (3.0, 2, cases["pack"]["height"],
                                                                            config["root_seed"])
    assert (packing.dt, packing.max_steps, pack_solver.solver) == (config["pack"]["dt"], config["pack"]["max_steps"],
                                                                 config["solver"])
    run, solver = made["collapse"]
    assert (run.mu, run.mu_r, run.n_steps, run.duration, run.friction_law) == (config["mu"], 0.2, 100, 4.0, "coulomb")
    assert (run.rolling_lever, run.max_duration, run.rest_tolerance, run.frame_every) == (
        "effective", 8.0, 0.2, config["collapse"]["frame_every"])
    assert run.friction_tolerance == config["friction_tolerance"] and solver.solver == config["solver"]
    analysis = made["analyse"]
    assert analysis.check_tolerances == tuple(config["analysis"]["check_tolerances"])
    assert analysis.contact_tolerance == config["analysis"]["contact_tolerance"]


def test_the_rules_command_lines_name_no_setting_that_changes_a_result():
    """A setting reaches a stage in its settings.yaml alone: adding one touches its dataclass, the
    schema and config.yaml, not a rule. The rules' flags are files, threads, the device and its
    storage, checkpoints and the packing's size bound, and the trim's swept a."""
    rules = (ROOT / "workflow/rules/simulate.smk").read_text()
    flags = set(re.findall(r'colsim [a-z-]+[^\n]*|^\s+" --[^\n]*', rules, flags=re.M))
    named = {flag for line in flags for flag in re.findall(r"--([a-z-]+)", line)}
    assert named <= {"settings", "settings-key", "input", "output", "output-dir", "threads", "device", "gpu-storage",
                     "checkpoint-every", "max-spheres", "aspect-ratio"}, named
    for command in ("pack", "collapse", "analyse"):
        assert re.search(rf"colsim {command} --settings", rules), command


#: settings in config.yaml that do not decide a result, so no key hashes them: plan.NOT_IDENTITY's
#: and the collapse's checkpoints and threads
NOT_IDENTITY = set(plan_module.NOT_IDENTITY) | {"checkpoint_every", "threads", "device"}
ONE_STAGE = plan_module.ONE_STAGE


def _names(settings: dict) -> set:
    """The setting names a settings dictionary holds, its sections' included."""
    return {key for key, value in settings.items() if not isinstance(value, dict)} | {
        key for value in settings.values() if isinstance(value, dict) for key in value}


@pytest.mark.parametrize("geometry", [{}, {"geometry": "channel", "channel_length": 2.0, "channel_width": 1.0,
                                           "wall_mu": 0.3}], ids=["cylinder", "channel"])
def test_every_setting_the_config_holds_is_in_its_key_or_said_not_to_change_a_result(geometry):
    """Adding a setting to a stage and config.yaml but not to the plan's settings (the run's key)
    fails here: the run would be made with it, yet two values would share one folder. A setting
    added later stays out at its default (a cylinder's geometry, a channel's settings unset:
    colsim.stages.settings.unrecorded), and a channel's study leaves out the cylinder's r0."""
    config = study_config({"collapse": {"max_duration": 8}, "pack": {"layer_height": 2.5}, **geometry})
    plan = StudyPlan(config)
    places = {"pack": ("pack", plan.packing_settings(3.0, 1)), "collapse": ("collapse", plan.run_settings(
        0.12, 100, 4.0, "coulomb")), "analyse": ("analysis", plan.analysis_settings())}
    for command, (section, identity) in places.items():
        classes = (stage.STAGES[command], stage.SolverSettings) if command in stage.SOLVING_STAGES else (stage.STAGES[command],)
        for cls in classes:
            for item in stage.declared(cls):
                name = stage.external_name(item)
                if name in config.get(section, {}) or name in config and ONE_STAGE.get(name, command) == command:
                    value = config.get(section, {}).get(name, config.get(name))
                    unused = stage.unrecorded(item, value) or (geometry and name == "r0")
                    assert (name in _names(identity)) != (unused or name in NOT_IDENTITY), (
                        f"{command}'s {name} is in the configuration but not in its settings' key (plan.py)")


def test_the_cli_defaults_make_the_default_study_s_packing(tmp_path):
    """`colsim pack --height 15 --seed 1` (docs/cli.md's first line) runs with the settings of the
    default study's packing of seed 1: the CLI's defaults are config.yaml's."""
    import yaml
    from snakemake.utils import validate

    config = yaml.safe_load((ROOT / "config.yaml").read_text())
    validate(config, str(ROOT / "workflow/schemas/config.schema.yaml"))
    path = tmp_path / "settings.yaml"
    path.write_text(settings_text(StudyPlan(config).packing_settings(config["r0"], 1)))
    by_hand = stage_settings(build_parser().parse_args(["pack", "--height", "15", "--seed", "1", "--output", "p.nc"]),
                             stage.PackSettings, stage.SolverSettings)
    assert _read("pack", path) == by_hand


def test_a_setting_added_to_its_dataclass_the_schema_and_config_yaml_reaches_the_key_the_file_and_the_stage(
        tmp_path, monkeypatch):
    """Issue 47.1: a collapse setting declared in its dataclass (here a subclass of CollapseSettings with
    one more field), the schema and config.yaml, and nowhere else. The schema refuses it until it is
    declared there; then the run's key and settings.yaml hold it (another value: another folder), and
    `colsim collapse` has its flag and reads it from the settings file: the plan, the rules and the
    CLI needed no change."""
    @dataclass
    class Extended(stage.CollapseSettings):
        grain_roughness: float = stage.setting(1.0, "a setting this test adds", kind="non_negative")

    monkeypatch.setitem(stage.STAGES, "collapse", Extended)
    config = study_config()
    config["collapse"]["grain_roughness"] = 0.5            # config.yaml
    with pytest.raises(WorkflowError, match="grain_roughness"):
        validate(config, str(SCHEMA))
    schema = yaml.safe_load(SCHEMA.read_text())            # the schema
    schema["properties"]["collapse"]["properties"]["grain_roughness"] = {
        "type": "number", "minimum": 0, "default": 1.0, "description": "a setting this test adds"}
    extended = tmp_path / "schema.yaml"
    extended.write_text(yaml.safe_dump(schema))
    validate(config, str(extended))
    plan = StudyPlan(config)
    run = plan.run_settings(0.12, 100, 4.0, "associated")
    assert run["grain_roughness"] == 0.5
    config["collapse"]["grain_roughness"] = 1.0
    assert plan_module.settings_key(StudyPlan(config).run_settings(0.12, 100, 4.0, "associated")) != \
        plan_module.settings_key(run)
    path = tmp_path / "settings.yaml"
    path.write_text(settings_text(run) + "\n")
    made, _ = _read("collapse", path)
    assert isinstance(made, Extended) and made.grain_roughness == 0.5
    flags = build_parser().parse_args(["collapse", *FILES["collapse"], "--grain-roughness", "0.25"])
    assert stage_settings(flags, Extended, stage.SolverSettings)[0].grain_roughness == 0.25


#: one setting of each kind of settings file, edited by hand: (the file's section or None, name, new value)
EDITS = {"pack": ("pack", "dt", 0.5), "collapse": (None, "mu_r", 0.3), "analyse": (None, "contact_tolerance", 0.2)}


@pytest.mark.parametrize("command", EDITS)
def test_a_settings_file_edited_after_planning_is_refused_by_its_stage_and_its_plan(tmp_path, command):
    """Issue 80.1: a packing's, a run's and the analyses' settings file, edited after planning. The
    stage given its folder's key refuses it in one line naming both keys; the plan names the setting."""
    plan = StudyPlan(study_config())
    planned = {"pack": plan.packing_settings(3.0, 1), "collapse": plan.run_settings(0.12, 100, 4.0, "associated"),
               "analyse": plan.analysis_settings()}[command]
    key = plan_module.settings_key(planned)
    path = tmp_path / "settings.yaml"
    path.write_text(settings_text(planned) + "\n")
    assert plan_module.edited_setting(path, planned) is None
    keyed = build_parser().parse_args([command, *FILES[command], "--settings", str(path), "--settings-key", key])
    classes = (stage.STAGES[command], stage.SolverSettings) if command in stage.SOLVING_STAGES else (stage.STAGES[command],)
    stage_settings(keyed, *classes)
    section, name, value = EDITS[command]
    edited = json.loads(settings_text(planned))
    (edited[section] if section else edited)[name] = value
    path.write_text(json.dumps(edited))
    with pytest.raises(ValueError, match=f"settings of key {plan_module.settings_key(edited)}, not {key}"):
        stage_settings(keyed, *classes)
    assert f"holds {name if section is None else section + '.' + name} {value}," in plan_module.edited_setting(
        path, planned)


def test_a_run_s_settings_edited_between_planning_and_running_stop_the_workflow(tmp_path):
    """Issue 80.1's reproduction: the tiny study's settings files written (--until run_settings),
    mu_r edited in one run's settings.yaml; the study then stops before any job, naming the file and
    mu_r, instead of computing the run under the key of another mu_r."""
    directory = copy_workflow(tmp_path)
    written = snakemake(directory, "-j1", "--configfile", "config/tiny.yaml", "--until", "run_settings",
                        timeout=300)
    assert written.returncode == 0, written.stderr[-2000:]
    settings = sorted(directory.glob("results/**/run_*/settings.yaml"))[0]
    run = json.loads(settings.read_text())
    run["mu_r"] = 0.3
    settings.write_text(json.dumps(run))
    result = snakemake(directory, "-n", "all", "--configfile", "config/tiny.yaml", timeout=300)
    assert result.returncode != 0
    assert f"{settings.relative_to(directory)} holds mu_r 0.3, but its folder's key names mu_r" in result.stdout + result.stderr
