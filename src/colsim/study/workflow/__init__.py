"""What the Snakemake workflow (Snakefile, workflow/rules/*.smk) calls, as plain functions of the
configuration: its checks (checks.py), the folders and settings of its packings, columns and runs
(plan.py), the values and options of its command lines and cluster resources (command_lines.py), and the
study's files for the report (report.py). No Snakemake here; the rules call the `colsim` command.
checks.py and the writers read and write YAML and JSON Schema with PyYAML, jsonschema and Jinja2,
which come with Snakemake, not with colsim."""
