"""colsim.cli.flags: each stage's flags and settings file come from its settings dataclass (issue 47)."""
import re

import pytest

from colsim.cli import build_parser
from colsim.cli.flags import stage_settings
from colsim.stages import settings as stage

FILES = {"pack": ["--output", "p.nc"], "trim": ["--input", "p.nc", "--output", "c.nc"],
         "collapse": ["--input", "c.nc", "--output", "o.nc"], "analyse": ["--input", "o.nc", "--output", "a.nc"]}
REQUIRED = {"pack": ["--height", "2"], "trim": ["--aspect-ratio", "2"]}


def _classes(command):
    return (stage.STAGES[command], stage.SolverSettings) if command in stage.SOLVING_STAGES else (stage.STAGES[command],)


def _parsed(command, *extra):
    return build_parser().parse_args([command, *FILES[command], *REQUIRED.get(command, []), *extra])


def _flag_text(item, value) -> list[str]:
    values = value if item.metadata["many"] else [value]
    return ["--" + stage.external_name(item).replace("_", "-"), *["none" if v is None else str(v) for v in values]]


@pytest.mark.parametrize("command", list(stage.STAGES))
def test_every_setting_is_a_flag_with_its_default_and_a_file_key(command, tmp_path):
    """Each declared field is a flag: given its default as text it changes nothing; written in a
    settings file, the same; the help shows each flag."""
    defaults = stage_settings(_parsed(command), *_classes(command))
    defaults = defaults if isinstance(defaults, tuple) else (defaults,)
    text = " ".join(build_parser()._subparsers._group_actions[0].choices[command].format_help().split())
    for cls, made in zip(_classes(command), defaults):
        for item in stage.declared(cls):
            flag = _flag_text(item, getattr(made, item.name))
            assert flag[0] in text
            again = stage_settings(_parsed(command, *flag), *_classes(command))
            assert again == (made if len(defaults) == 1 else defaults), flag


def test_a_settings_file_is_read_by_name_flags_override_it_and_nulls_keep_the_default(tmp_path):
    path = tmp_path / "settings.yaml"
    path.write_text("mu_r: 0.3\nsteps: 200\nduration: 2\nfriction_tolerance: null\n"
                    "rest: {max_duration: 8.0, rest_window: 0.5}\nsolver: apgd\n")
    settings, solver = stage_settings(_parsed("collapse", "--settings", str(path), "--mu-r", "0.06"),
                                      stage.CollapseSettings, stage.SolverSettings)
    assert (settings.mu_r, settings.n_steps, settings.duration, settings.max_duration) == (0.06, 200, 2.0, 8.0)
    assert settings.rest_window == 0.5 and settings.friction_tolerance == stage.CollapseSettings().friction_tolerance
    assert solver.solver == "apgd"


@pytest.mark.parametrize("text, message", [
    ("mu_r: 0.3\nspeed: 2\n", "names speed, which colsim collapse does not take"),
    ("mu_r: -1\n", "mu_r must be >= 0"),
    ("steps: 2.5\n", "steps must be an integer"),
    ("rolling_lever: lever\n", "rolling_lever must be one of paper, effective"),
    ("mu_r: 0.3\nrest: {mu_r: 0.2}\n", "gives mu_r twice"),
    ("- mu_r\n", "not a mapping"),
    ("mu_r: [0.3\n", "not YAML"),
])
def test_a_bad_settings_file_is_refused_naming_the_file_and_the_setting(tmp_path, text, message):
    path = tmp_path / "settings.yaml"
    path.write_text(text)
    with pytest.raises(ValueError, match=re.escape(message)) as refused:
        stage_settings(_parsed("collapse", "--settings", str(path)), stage.CollapseSettings, stage.SolverSettings)
    assert str(path) in str(refused.value)


@pytest.mark.parametrize("make", ["fifo", "device", "large"])
def test_a_settings_file_must_be_a_regular_file_of_bounded_size(tmp_path, make):
    """Issue 80.2: --settings on a FIFO blocked forever, and /dev/zero was read until memory ran out
    (1.4 GB); both are refused before they are opened, as is a file over the bound."""
    import os

    from colsim.cli.flags import MAX_SETTINGS_BYTES

    path = {"fifo": tmp_path / "settings.fifo", "device": "/dev/zero", "large": tmp_path / "large.yaml"}[make]
    if make == "fifo":
        os.mkfifo(path)
    elif make == "large":
        path.write_text("# " + "x" * MAX_SETTINGS_BYTES + "\n")
    args = build_parser().parse_args(["analyse", "--input", "c.nc", "--output", "a.nc", "--settings", str(path)])
    words = "more than a settings file may" if make == "large" else "is not a regular file (a FIFO, a device"
    with pytest.raises(ValueError, match=re.escape(words)):
        stage_settings(args, stage.AnalysisSettings)
