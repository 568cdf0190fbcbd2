"""What the Snakemake workflow (Snakefile, workflow/rules/*.smk) calls, as plain functions of the
configuration: its checks (checks.py), the folders and settings of its packings, columns and runs
(plan.py), its jobs' cluster resources and priorities (job_resources.py), and the study's files for
the report (report.py). No Snakemake here; the rules call the `colsim` command, with each stage's
settings.yaml. checks.py and the writers use JSON Schema and Jinja2, which come with Snakemake."""
