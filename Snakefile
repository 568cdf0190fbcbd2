# The colsim study: pack -> trim -> collapse -> analyse -> collect -> plot -> report.
# Rules call the `colsim` command line; see README.md and config.yaml.
from snakemake.utils import min_version

min_version("8.0")


configfile: "config.yaml"


report: "workflow/report/workflow.rst"


include: "workflow/rules/common.smk"
include: "workflow/rules/simulate.smk"
include: "workflow/rules/summarise.smk"


rule all:
    input:
        "results/summary.nc",
        "results/summary.csv",
        "results/study_config.yaml",
        figures(),
