# The colsim study: pack -> trim -> collapse -> analyse -> collect -> plot -> report.
# Rules call the `colsim` command line; see README.md and config.yaml.
from snakemake.utils import min_version

min_version("8.0")


configfile: "config.yaml"


report: "workflow/report/workflow.rst"


include: "workflow/rules/common.smk"
include: "workflow/rules/simulate.smk"
include: "workflow/rules/summarise.smk"
include: "workflow/rules/convergence.smk"


rule all:
    input:
        f"{STUDY_DIR}/summary.nc",
        f"{STUDY_DIR}/summary.csv",
        f"{STUDY_DIR}/lube_table.md",
        f"{STUDY_DIR}/study_config.yaml",
        figures(),
        convergence_outputs(),
