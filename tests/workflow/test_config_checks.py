"""colsim.study.workflow.checks without Snakemake: each check returns one line naming the culprit, or None."""
from __future__ import annotations

import math
import re

import pytest

from colsim.study.workflow.checks import (before_validation, cross_field_problem, cuda_gpu_count, device_problem,
                                          duplicate_key, link_out_of, load_schema, non_finite_number, schema_problem,
                                          size_problem)
from helpers import ROOT, copy_workflow, snakemake
from test_study_plan import study_config

SCHEMA = load_schema(ROOT / "workflow" / "schemas" / "config.schema.yaml")


def test_the_schema_names_an_unknown_key_and_a_wrong_value():
    assert schema_problem({"r0": 1}, SCHEMA) is None
    assert schema_problem({"collapse": {"stepz": 5}}, SCHEMA).startswith(
        "config: unknown key collapse.stepz; allowed in collapse: threads, duration, steps")
    assert schema_problem({"solver": "simplex"}, SCHEMA).startswith("config: solver: 'simplex' is not one of")


def test_a_configuration_too_large_once_expanded_is_refused_before_the_schema():
    layer = [1] * 10
    for _ in range(5):
        layer = [layer] * 10   # 10^6 leaves, shared as YAML's aliases share them
    assert size_problem({"a": layer}).startswith("config: more than 100,000 keys and values")
    assert size_problem({"r0": 1}) is None
    assert before_validation({"a": layer}, SCHEMA).startswith("config: more than")
    assert before_validation({"bogus": 1}, SCHEMA).startswith("config: unknown key bogus")


def test_a_nan_or_an_infinity_is_named_by_its_key():
    assert non_finite_number({"mu_r": [0.1, math.nan]}) == "mu_r.1"
    assert non_finite_number({"collapse": {"max_duration": math.inf}}) == "collapse.max_duration"
    assert non_finite_number({"r0": 1, "study": "x"}) is None


def test_settings_that_contradict_each_other():
    assert cross_field_problem(study_config()) is None
    assert cross_field_problem(study_config({"r0": 0.2})) == (
        "config: r0 0.2 is below diameter_max 0.5: the largest particle does not fit in the cylinder")
    assert cross_field_problem(study_config({"friction_law": "coulomb", "friction_law_comparison": True})
                               ).startswith("config: friction_law_comparison needs friction_law: associated")
    assert cross_field_problem(study_config({"r0": 1000})).startswith("config: a packing of r0 1000 for a = 1")


def test_a_link_in_results_to_a_file_elsewhere_is_refused(tmp_path):
    """Issue 45.2: Snakemake writes a job's log and benchmark through a link planted in results/
    (results/STUDY/benchmarks/collect.tsv -> a file elsewhere); the study refuses to start, naming
    it. A link within results/, and results/ itself being a link, are fine."""
    results = tmp_path / "results"
    (results / "tiny" / "benchmarks").mkdir(parents=True)
    outside = tmp_path / "precious.txt"
    outside.write_text("keep me\n")
    assert link_out_of(str(results)) is None and link_out_of(str(tmp_path / "absent")) is None
    (results / "tiny" / "inside").symlink_to(results / "tiny" / "benchmarks")
    assert link_out_of(str(results)) is None
    planted = results / "tiny" / "benchmarks" / "collect.tsv"
    planted.symlink_to(outside)
    problem = link_out_of(str(results))
    assert str(planted) in problem and "outside" in problem and outside.read_text() == "keep me\n"
    planted.unlink()
    scratch = tmp_path / "scratch"
    scratch.mkdir()
    (tmp_path / "linked").symlink_to(scratch)
    assert link_out_of(str(tmp_path / "linked")) is None


@pytest.mark.parametrize("extra, words", [
    ({"collapse": {"duration": 5.0, "max_duration": 4.0}}, ["collapse.duration 5 exceeds collapse.max_duration 4"]),
    ({"collapse": {"steps": 100, "duration": 4.0}, "convergence": {"end_time": {"duration": 0.01}}},
     ["convergence.end_time.duration 0.01", "rounds to no step"]),
    ({"collapse": {"steps": 100, "duration": 4.0},
      "convergence": {"column_size": [{"aspect_ratio": 1, "r0": [2], "duration": 0.001}]}},
     ["convergence.column_size.0.duration", "rounds to no step"]),
    ({"pack": {"dt": 10**400}}, ["pack.dt", "finite number"]),
    ({"r0": 10**400}, ["r0", "finite number"]),
    ({"density": 10**400}, ["density", "finite number"]),
    ({"gravity": 1e-300}, ["pack.dt", "sqrt(diameter_min / gravity)"]),
])
def test_settings_that_would_fail_mid_study_are_refused_first(extra, words):
    """Issue 45.5: each of these passed the study's first check and failed 6 jobs later (or ran to a
    nonsense result); now the first check names it."""
    problem = cross_field_problem(study_config(extra))
    assert problem is not None and all(word in problem for word in words), problem


@pytest.mark.parametrize("config, words", [
    ({"seeds": [10**30]}, ["seeds.0", "maximum"]),
    ({"root_seed": 2**32}, ["root_seed", "maximum"]),
    ({"study": "x" * 300}, ["study", "too long"]),
])
def test_seeds_and_names_out_of_range_are_refused_by_the_schema(config, words):
    problem = schema_problem(config, SCHEMA)
    assert problem is not None and all(word in problem for word in words), problem


def test_a_key_given_twice_in_one_file_is_refused(tmp_path):
    """Issue 45.5: YAML keeps the later of two equal keys silently; the study refuses, naming the
    file, the line and the key. A nested mapping is checked as well."""
    good, top, nested = tmp_path / "good.yaml", tmp_path / "top.yaml", tmp_path / "nested.yaml"
    good.write_text("r0: 2\ncollapse: {steps: 10}\n")
    top.write_text("r0: 2\nmu: 0.5\nr0: 3\n")
    nested.write_text("collapse:\n  steps: 10\n  steps: 20\n")
    assert duplicate_key([good, ROOT / "config.yaml"]) is None
    assert duplicate_key([good, top]) == (f"config: {top}, line 3: the key 'r0' is given twice; the later value"
                                          " would win silently")
    assert "line 3: the key 'steps' is given twice" in duplicate_key([nested])


#: the modules whose refusals a workflow job can meet: the stages, the commands, the study's tables
JOB_SOURCES = ("stages/settings.py", "stages/pack.py", "stages/trim.py", "stages/analyse.py", "stages/pour_geometry.py",
               "stages/collapse.py", "cli/commands.py", "study/calibration.py", "study/convergence.py")
#: each job-time refusal (its message's first 32 characters) and its planning twin: a configuration
#: that cross_field_problem refuses ("config", over the tiny study), one the schema refuses ("schema"),
#: or the reason a configuration cannot meet it ("reason")
JOB_TIME_REFUSALS = {
    "unknown kind {kind!r} of a setti": ("reason", "a declaration in colsim.stages.settings, never an input"),
    "a packing needs its height (--he": ("reason", "the plan gives every packing its height (plan.pack_height)"),
    "diameter_min {self.diameter_min}": ("config", {"diameter_min": 0.5, "diameter_max": 0.4}),
    "a trim needs its aspect ratio (-": ("reason", "the trim rule gives the column's a"),
    "friction coefficient {name} must": ("schema", {"mu": -1}),
    "need duration > 0, n_steps >= 1,": ("schema", {"collapse": {"frame_every": 0}}),
    "the step dt/sqrt(h0/g) = {self.s": ("config", {"collapse": {"steps": 10**11, "duration": 1.0}}),
    "gravity must be positive, got {s": ("schema", {"gravity": 0}),
    "max_duration {self.max_duration}": ("config", {"collapse": {"duration": 5.0, "max_duration": 4.0}}),
    "need rest_window, rest_tolerance": ("schema", {"collapse": {"rest_window": 0}}),
    "diameter range must satisfy 0 < ": ("config", {"diameter_min": 0.5, "diameter_max": 0.4}),
    "cylinder radius r0 = {settings.r": ("config", {"r0": 0.2}),
    "packing height must be positive,": ("schema", {"aspect_ratios": [0]}),
    "the pour's step dt = {dt:g} is {": ("config", {"gravity": 1e-300}),
    "input file {path}: {error}": ("reason", "a file's gravity: the workflow's files come from its own pours, whose"
                                             " gravity and step the planning check refused already"),
    "input file {path}: its gravity {": ("reason", "a file's gravity against its pour's: the workflow writes both"),
    "layer height must be positive (o": ("schema", {"pack": {"layer_height": 0}}),
    "freeze depth must be >= 0, got {": ("schema", {"pack": {"freeze_depth": -1}}),
    "the packing of {size} to height ": ("config", {"r0": 1000}),
    "geometry must be one of {', '.jo": ("schema", {"geometry": "sphere"}),
    "{' and '.join(given)} set a chan": ("config", {"channel_length": 2.0}),
    "geometry channel needs channel_l": ("config", {"geometry": "channel", "channel_width": 1.0}),
    "channel_length L0 must be positi": ("schema", {"channel_length": 0}),
    "{name} = {value} is below {LATTI": ("config", {"geometry": "channel", "channel_length": 2.0,
                                                    "channel_width": 0.51}),
    "the channel's box ({r0.length:g}": ("config", {"geometry": "channel", "channel_length": 0.4,
                                                    "channel_width": 1.0}),
    "wall_mu is the friction of a cha": ("config", {"wall_mu": 0.3}),
    "--wall-mu is the friction of a c": ("config", {"wall_mu": 0.3}),
    "packing not at rest after {max_s": ("reason", "the pour's dynamics decide it, known only once it ran"),
    "a settling sphere overlaps a fix": ("reason", "the pour's dynamics decide it, known only once it ran"),
    "column height h0 must be positiv": ("schema", {"aspect_ratios": [0]}),
    "the packing (height {column_heig": ("reason", "the plan pours every packing taller than the largest a r0 cut"
                                                   " from it; only a finished pour's height can fall short"),
    "h0 = {h0:g} leaves {n_kept} sphe": ("config", {"aspect_ratios": [0.01]}),
    "mass share must be in (0, 1], go": ("schema", {"analysis": {"mass_shares": [1.5]}}),
    "--bin-width {bin_width:g} cuts t": ("reason", "the deposit's radius decides it, known only after the collapse"),
    "cylinder radius r0 = {r0} is too": ("config", {"r0": 0.2}),
    "cannot write {path}: it exists a": ("reason", "the workflow names each output, a file of its own below results/"),
    "{path} is given as two outputs (": ("reason", "the workflow names each output, a file of its own below results/"),
    "{path} is both an input and an o": ("reason", "the workflow names each output, a file of its own below results/"),
    "{' and '.join(ignored)} {'are' i": ("config", {"solver": "clarabel", "device": "cuda"}),
    "--gpu-storage {storage} is a GPU": ("config", {"gpu_storage": "float32", "device": "cpu"}),
    "input file {args.input} is a pac": ("reason", "the collapse rule's input is the trim rule's column"),
    "--{law} got runs of the {', '.jo": ("reason", "the rule gives each law its own runs (plan.study_runs(law=...))"),
    "{folder} is not a folder (the ru": ("reason", "`colsim status` is no workflow job"),
    "{root} holds no docs/data: give ": ("reason", "`colsim docs` is no workflow job"),
    "colsim docs: tables differ from ": ("reason", "`colsim docs` is no workflow job"),
    "no analysis files to calibrate f": ("schema", {"calibration": {"r0": [2.0]}}),
    "a calibration needs at least two": ("config", {"calibration": {"r0": [2.0, 3.0]}, "mu_r": [0.12]}),
    "every (mu_r, a) needs runs at tw": ("schema", {"calibration": {"r0": [2.0]}}),
    "unknown convergence sub-studies ": ("reason", "the convergence rule names the sub-studies itself"),
    "channel runs: the calibration fi": ("reason", "a channel study's box lengths go to the length_convergence rule"
                                                   " (plan.calibration_outputs), never to the calibration"),
    "{path}: not a channel run (geome": ("reason", "the length_convergence rule runs only for geometry: channel,"
                                                   " whose runs are all the channel's"),
    "geometry {geometry[:60]!r} is no": ("reason", "the analyses read files colsim wrote, whose geometry the"
                                                   " schema's enum allowed"),
    "a {geometry_of(attrs)} file need": ("reason", "the pour writes r0 or channel_length into every file"),
    "a channel file needs attribute {": ("reason", "the collapse writes a channel's width and wall friction"
                                                   " into its file"),
    "attribute {name} is {value:g}, n": ("schema", {"channel_length": 0}),
    "no analyses to tabulate": ("reason", "the convergence rule runs only for a convergence section, whose"
                                          " sub-studies the schema requires to name runs"),
}


def job_time_refusals() -> set[str]:
    """The first 32 characters of each refusal message raised in JOB_SOURCES."""
    package = ROOT / "src" / "colsim"
    return {match.group(1)[:32] for name in JOB_SOURCES
            for match in re.finditer(r'raise (?:io\.)?\w+\(f?"([^"]*)"', (package / name).read_text())}


def test_every_job_time_refusal_is_listed_with_its_planning_twin_or_a_reason():
    """Issue 80.4: a refusal added to a stage, a command or the study's tables must be listed here,
    with the configuration the planning check refuses in its place, or why none can be."""
    assert job_time_refusals() == set(JOB_TIME_REFUSALS)


@pytest.mark.parametrize("refusal", [name for name, (kind, _) in JOB_TIME_REFUSALS.items() if kind != "reason"])
def test_each_job_time_refusal_has_a_planning_twin(refusal):
    """Issue 80.4: a calibration with one mu_r planned 14.7 h of runs and failed at the last job;
    device cuda or gpu_storage float32 with solver clarabel failed at the first pour. Each such
    configuration is now refused before any job."""
    kind, extra = JOB_TIME_REFUSALS[refusal]
    if kind == "schema":
        problem = schema_problem(extra, SCHEMA)
    else:
        problem = cross_field_problem(study_config(extra))
    assert problem is not None and problem.startswith("config:") and "\n" not in problem, (refusal, problem)


@pytest.mark.parametrize("extra, words", [
    ({"calibration": {"r0": [2.0, 3.0]}, "mu_r": [0.12]}, ["calibration", "mu_r holds 1"]),
    ({"solver": "clarabel", "device": "cuda"}, ["device cuda is APGD's", "solver clarabel would ignore it"]),
    ({"solver": "clarabel", "gpu_storage": "float32", "device": "auto"}, ["gpu_storage float32 is APGD's"]),
    ({"solver": "admm", "solver_overlap_tolerance": 0.01}, ["solver_overlap_tolerance 0.01 is APGD's"]),
    ({"gpu_storage": "float32", "device": "cpu"}, ["gpu_storage float32 is a GPU's storage", "device is cpu"]),
])
def test_contradictions_a_job_would_meet_are_named_before_any_job(extra, words):
    problem = cross_field_problem(study_config(extra))
    assert problem is not None and all(word in problem for word in words), problem


def test_device_cuda_without_a_gpu_is_named_in_one_line():
    """Issue 79.7: device: cuda where no GPU is, one line naming the setting; cpu and auto pass, and
    so does cuda with a GPU. numba's simulator (on in the tests' own process) is no GPU to plan for."""
    problem = device_problem({"device": "cuda"}, gpus=lambda: 0)
    assert problem.startswith("config: device: cuda, but this machine has no CUDA GPU") and "\n" not in problem
    assert device_problem({"device": "cuda"}, gpus=lambda: 1) is None
    for device in ("cpu", "auto"):
        assert device_problem({"device": device}, gpus=lambda: 0) is None


def test_the_gpu_count_asks_the_driver_without_numba():
    """A count (0 where no NVIDIA driver is), made in a fresh interpreter without importing numba:
    planning a study stays quick."""
    import subprocess
    import sys
    probe = ("import sys; from colsim.study.workflow.checks import cuda_gpu_count; n = cuda_gpu_count(); "
             "print(n, 'numba' in sys.modules)")
    count, numba_loaded = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                                         check=True).stdout.split()
    assert int(count) >= 0 and numba_loaded == "False"


@pytest.mark.skipif(cuda_gpu_count() > 0, reason="this machine has a GPU: device: cuda is right here")
def test_a_study_on_cuda_without_a_gpu_is_refused_before_any_job(tmp_path):
    """The tiny study with device: cuda run here, without a GPU: Snakemake stops before its first job
    with the one line (before: every pack and collapse failed, its cause only in each job's log).
    numba's simulator, on in the tests, does not stand for a GPU when a study is planned."""
    copy_workflow(tmp_path)
    done = snakemake(tmp_path, "-j1", "--configfile", "config/tiny.yaml", "--config", "device=cuda", timeout=120)
    assert done.returncode != 0
    assert "config: device: cuda, but this machine has no CUDA GPU" in done.stdout + done.stderr
    assert not (tmp_path / "results").exists() or not any((tmp_path / "results").rglob("*.nc"))
