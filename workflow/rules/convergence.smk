# The convergence study (config key `convergence`, e.g. config/convergence.yaml): collapses with their own
# number of steps and end time (the rules collapse and analyse, at the folders their settings name),
# then one table, its relative changes and a figure.


rule convergence:
    input:
        **convergence_runs("analysis.nc"),
    output:
        nc=f"{STUDY_DIR}/convergence.nc",
        csv=f"{STUDY_DIR}/convergence.csv",
        markdown=report(
            f"{STUDY_DIR}/convergence.md",
            caption="../report/convergence_table.rst",
            category="Convergence",
            labels={"table": "relative changes per refinement"},
        ),
        figure=report(
            f"{STUDY_DIR}/figures/convergence.png",
            caption="../report/convergence.rst",
            category="Convergence",
            labels={"figure": "Convergence"},
        ),
        limits=f"{STUDY_DIR}/column_size_limits.nc",
        size_figure=report(
            f"{STUDY_DIR}/figures/column_size_limits.png",
            caption="../report/column_size_limits.rst",
            category="Convergence",
            labels={"figure": "Column-size limits"},
        ),
    params:
        default_end=config["collapse"]["duration"],
    log:
        f"{STUDY_DIR}/logs/convergence.log",
    benchmark:
        f"{STUDY_DIR}/benchmarks/convergence.tsv"
    shell:
        "colsim convergence --time-step {input.time_step:q} --end-time {input.end_time:q}"
        " --column-size {input.column_size:q} --seeds {input.seeds:q} --default-end {params.default_end}"
        " --output {output.nc:q} --csv {output.csv:q} --markdown {output.markdown:q}"
        " --figure {output.figure:q} --limits {output.limits:q} --size-figure {output.size_figure:q} > {log:q} 2>&1"
