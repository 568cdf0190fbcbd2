"""colsim.stages.settings: each setting is declared once, with its default, unit and help, and the
workflow's config schema and config.yaml agree with it (issue 47)."""
import pytest
import yaml

from colsim.stages import settings as stage
from colsim.study.collect import REST_ENERGY
from helpers import ROOT

#: where a stage's settings sit in config.yaml: its section, else the top level
SECTIONS = {"pack": "pack", "collapse": "collapse", "analyse": "analysis", "trim": None}
#: settings the study sets to its own values, not the stage's default, and why (the help says so)
STUDY_CHOICES = {"mu_r": "the sweep", "max_duration": "the study's runs go on to rest"}
#: settings the workflow does not take from config.yaml, and why
NOT_IN_CONFIG = {"height": "from the study's largest a", "seed": "the seeds swept", "aspect_ratio": "swept",
                 "checkpoint_every": "the pour's (the collapse's is in config.yaml)", "floor_mu": "the command line's only",
                 "floor_mu_r": "the command line's only", "bin_width": "the command line's only",
                 "solver_tolerance": "the command line's only", "solver_length_floor": "the command line's only"}

SCHEMA = yaml.safe_load((ROOT / "workflow/schemas/config.schema.yaml").read_text())["properties"]
CONFIG = yaml.safe_load((ROOT / "config.yaml").read_text())


def _every_setting():
    for name, cls in [*stage.STAGES.items(), *[(s, stage.SolverSettings) for s in stage.SOLVING_STAGES]]:
        for item in stage.declared(cls):
            yield name, item


@pytest.mark.parametrize("name, item", list(_every_setting()),
                         ids=lambda v: v if isinstance(v, str) else stage.external_name(v))
def test_the_schema_and_config_yaml_say_the_stage_s_default(name, item):
    """Each setting's schema default and config.yaml value are its dataclass default, unless the
    study chooses its own (STUDY_CHOICES) or the workflow does not set it (NOT_IN_CONFIG)."""
    key = stage.external_name(item)
    assert item.metadata["help"] and item.metadata["unit"], key
    section = SECTIONS[name]
    if section and key in SCHEMA[section]["properties"]:
        schema, config = SCHEMA[section]["properties"][key], CONFIG[section][key]
    elif key in SCHEMA:
        schema, config = SCHEMA[key], CONFIG[key]
    else:
        assert key in NOT_IN_CONFIG, f"{name}'s {key} is neither in the config schema nor listed as not in it"
        return
    default = list(item.default) if item.metadata["many"] else item.default
    if key in STUDY_CHOICES:
        assert "default study" in item.metadata["help"], f"{key}'s help does not give the study's value"
        return
    assert schema.get("default") == default, f"the schema's default of {key} is not {name}'s {default}"
    assert config == default, f"config.yaml's {key} is not {name}'s default {default}"


def test_the_summary_s_rest_test_is_the_collapse_s():
    assert REST_ENERGY == stage.CollapseSettings().rest_energy


def test_required_settings_and_bad_combinations_are_refused():
    with pytest.raises(ValueError, match="height"):
        stage.PackSettings()
    with pytest.raises(ValueError, match="aspect ratio"):
        stage.TrimSettings()
    with pytest.raises(ValueError, match="diameter_min"):
        stage.PackSettings(height=2.0, diameter_min=0.6)
    with pytest.raises(ValueError, match="max_duration"):
        stage.CollapseSettings(max_duration=1.0)
    assert stage.CollapseSettings(duration=2.0, n_steps=500).scaled_step == 0.004
