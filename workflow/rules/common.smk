# The workflow's wiring: check the configuration, then name the study's files. The logic is plain
# Python in colsim.study.workflow (docs/architecture.md, "The workflow"): checks.py (the
# configuration's checks), plan.py (folders, keys and settings of packings, columns and runs),
# job_resources.py (jobs' cluster resources and priorities), report.py (the study's files for the
# report). Here only what needs Snakemake: its validation, its errors, the rules' wildcards.
import functools

from snakemake.exceptions import WorkflowError
from snakemake.utils import validate

from colsim.study.figure_names import FIGURES   # the figures `colsim plot` writes: name -> title of its report label
from colsim.study.workflow import job_resources
from colsim.study.workflow import report as study_report
from colsim.study.workflow.checks import (before_validation, cross_field_problem, device_problem, duplicate_key,
                                          link_out_of, load_schema)
from colsim.study.workflow.plan import (ANALYSIS, ANALYSIS_SETTINGS, COLUMN, PACKING_DIR, RESULTS, RUN_DIR,
                                        StudyPlan, UnknownFolder, WRITE_SETTINGS, benchmarked, edited_setting,
                                        fmt, logged, settings_key, settings_text)

SCHEMA = os.path.join(workflow.basedir, "workflow", "schemas", "config.schema.yaml")

problem = duplicate_key(workflow.configfiles) or before_validation(config, load_schema(SCHEMA))
if problem is None:
    validate(config, SCHEMA)   # fills in the defaults
    problem = cross_field_problem(config) or link_out_of(RESULTS)
if problem:
    raise WorkflowError(problem)


PLAN = StudyPlan(config)   # the study's packings, columns and runs, by key (registered as they are named)
SEEDS = PLAN.seeds
STUDY_DIR = PLAN.study_dir   # the study's summary, tables and figures (runs are shared between studies)
# the report's description of the study, written with its summary (rule study_config)
DESCRIPTION = f"{STUDY_DIR}/report_description.rst"
DESCRIPTION_TEMPLATE = os.path.join(workflow.basedir, "workflow", "report", "workflow.rst")
# the study's whole configuration, in a file named by its key (rule study_settings)
STUDY_SETTINGS = f"{STUDY_DIR}/settings/{settings_key(dict(config))}.yaml"

wildcard_constraints:
    r0=r"[0-9][0-9.e+-]*",
    a=r"[0-9][0-9.e+-]*",
    mu_r=r"[0-9][0-9.e+-]*",
    seed=r"[0-9]+",
    packing=r"[0-9a-f]{10}",
    run=r"[0-9a-f]{10}",
    analysis=r"[0-9a-f]{10}",


def _settings_lookup(lookup):
    """`lookup(wildcards)` of a folder's settings, a folder this study does not name a WorkflowError."""
    @functools.wraps(lookup)
    def settings(wildcards):
        try:
            return lookup(wildcards)
        except UnknownFolder as error:
            raise WorkflowError(str(error)) from None
    return settings


# a folder's settings from its key: every value of a rule comes from these, never from a folder's name
packing_of = _settings_lookup(PLAN.packing_of)
column_of = _settings_lookup(PLAN.column_of)
run_of = _settings_lookup(PLAN.run_of)
analysis_settings_of = _settings_lookup(PLAN.analysis_settings_of)


def settings_file(folder, lookup):
    """The input function of the settings.yaml of a packing's or a run's folder: its path, or a
    WorkflowError naming the setting where the file there holds other settings than its folder's key
    names (edited by hand after planning; plan.edited_setting)."""
    def path(wildcards):
        file = f"{folder}/settings.yaml".format(**dict(wildcards.items()))
        problem = edited_setting(file, lookup(wildcards))
        if problem:
            raise WorkflowError(problem)
        return file
    return path


# the study's analysis settings file, named by their key: refused before any job where it was edited
problem = edited_setting(ANALYSIS_SETTINGS.format(analysis=settings_key(PLAN.analysis_settings())),
                         PLAN.analysis_settings())
if problem:
    raise WorkflowError(problem)
# the study's files (naming one registers its packing, column and run)
runs = PLAN.study_runs
side_view_mu_r = PLAN.side_view_mu_r
convergence_runs = PLAN.convergence_runs
convergence_outputs = PLAN.convergence_outputs
friction_law_outputs = PLAN.friction_law_outputs
calibration_outputs = PLAN.calibration_outputs


DIAMETERS = (config["diameter_min"], config["diameter_max"])


def column_spheres(wildcards):
    """About how many spheres a column holds (job_resources.py)."""
    return job_resources.spheres_of(PLAN.footprint(float(wildcards.r0)), column_of(wildcards) * float(wildcards.r0),
                                    DIAMETERS)


def collapse_runtime(wildcards):
    """A collapse's time limit on a cluster (minutes), from its run's settings and its column's
    size (job_resources.py)."""
    return job_resources.collapse_runtime(run_of(wildcards), PLAN.length, column_spheres(wildcards))


def pack_spheres(wildcards):
    """About how many spheres a packing's pour holds (job_resources.py)."""
    packing = packing_of(wildcards)
    return job_resources.spheres_of(PLAN.footprint(float(wildcards.r0)), packing["height"], DIAMETERS)


def pack_gpus(wildcards):
    """GPUs a pour asks for: one where APGD runs on a GPU (device: cuda, or auto for a large pour on
    a machine with a GPU; job_resources.py)."""
    return job_resources.gpus_a_job(config["device"], pack_spheres(wildcards))


def collapse_gpus(wildcards):
    """GPUs a collapse asks for, as a pour's (pack_gpus), from its column's size."""
    return job_resources.gpus_a_job(config["device"], column_spheres(wildcards))


def pack_resource(name):
    """A packing's time limit (minutes) or memory (MB) on a cluster, from its size (job_resources.py)."""
    def resource(wildcards):
        return job_resources.pack_resources(pack_spheres(wildcards))[name]
    return resource


def pack_priority(wildcards):
    """A pour's scheduling priority, from its size (job_resources.py): the largest first."""
    return job_resources.pack_priority(pack_spheres(wildcards))


def collapse_priority(wildcards):
    """A collapse's scheduling priority, from its column's a and its run's steps (job_resources.py)."""
    run = run_of(wildcards)
    return job_resources.collapse_priority(column_of(wildcards), run, PLAN.length)


def report_description():
    """The report's description: the study's own once its summary exists, else a note (report.py)."""
    return study_report.report_description(DESCRIPTION)


def output_directory(wildcards, output):
    """The directory of a rule's first output (for commands that take --output-dir)."""
    return os.path.dirname(output[0])


def figures():
    return expand(f"{STUDY_DIR}/figures/{{figure}}.png", figure=FIGURES)


# cheap jobs that a cluster run keeps on the submitting node
localrules:
    all,
    paraview,
    study_config,
    study_settings,
    packing_settings,
    run_settings,
    analysis_settings,


# Studies share their runs' folders: with the lock, a second snakemake in this folder is refused
# while the first runs; without it, each takes the other's running jobs for incomplete files. So a
# run (not a dry run) refuses --nolock before its first job. The jobs Snakemake spawns (a cluster's)
# run with --nolock and --no-hooks: onstart is the main process's alone.
# And where the jobs run here, device: cuda without a GPU is refused before the first job: only here, once
# the executor is known (a study sent to a cluster, --executor slurm, plans on a login node with no GPU).
# One handler a workflow (a later onstart replaces an earlier one), so both checks live in it.
onstart:
    if not workflow.execution_settings.lock:
        raise WorkflowError("--nolock: studies here share their runs, and a second snakemake without the lock takes"
                            " the first one's running jobs for incomplete files; run without --nolock, one study"
                            " after the other")
    if workflow.local_exec and device_problem(config):
        raise WorkflowError(device_problem(config))
