# The colsim study: pack -> trim -> collapse -> analyse -> collect -> plot -> report.
# Rules call the `colsim` command line; see README.md and config.yaml.
# `snakemake --lint` exits 1 asking for one thing more, a conda environment or container a rule, and
# is left so on purpose: the environment is the pip lock the README installs (environment.txt with
# constraints.txt), the same for every rule, which a conda file a rule would repeat untested
# (docs/study-config.md, "The workflow's files"; tests/workflow/test_workflow.py holds the lint to that).
from snakemake.utils import min_version

min_version("8.0")


configfile: "config.yaml"


include: "workflow/rules/common.smk"
include: "workflow/rules/simulate.smk"
include: "workflow/rules/summarise.smk"
include: "workflow/rules/convergence.smk"
include: "workflow/rules/friction_law.smk"
include: "workflow/rules/calibration.smk"


# the study's own description (written with its summary), so a report describes the files it shows
report: report_description()


rule all:
    input:
        f"{STUDY_DIR}/summary.nc",
        f"{STUDY_DIR}/summary.csv",
        f"{STUDY_DIR}/lube_table.md",
        f"{STUDY_DIR}/study_config.yaml",
        figures(),
        convergence_outputs(),
        friction_law_outputs(),
        calibration_outputs(),
