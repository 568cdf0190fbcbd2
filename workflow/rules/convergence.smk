# The convergence study (config key `convergence`, e.g. config/convergence.yaml): collapses with their own
# number of steps and end time, then one table, its relative changes and a figure.


# The study's own collapse and analyse rules at the variant's path; collapse takes its steps and end
# time from the {steps} and {duration} wildcards (common.smk: collapse_steps, collapse_duration).
use rule collapse as collapse_variant with:
    output:
        f"{VARIANT}/collapse.nc",
    log:
        logged(f"{VARIANT}/collapse.log"),
    benchmark:
        benchmarked(f"{VARIANT}/collapse.tsv")


use rule analyse as analyse_variant with:
    input:
        f"{VARIANT}/collapse.nc",
    output:
        f"{VARIANT}/analysis.nc",
    log:
        logged(f"{VARIANT}/analyse.log"),
    benchmark:
        benchmarked(f"{VARIANT}/analyse.tsv")


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
    params:
        default_end=config["collapse"]["duration"],
    log:
        f"{STUDY_DIR}/logs/convergence.log",
    benchmark:
        f"{STUDY_DIR}/benchmarks/convergence.tsv"
    shell:
        "colsim convergence --time-step {input.time_step} --end-time {input.end_time}"
        " --column-size {input.column_size} --seeds {input.seeds} --default-end {params.default_end}"
        " --output {output.nc} --csv {output.csv} --markdown {output.markdown}"
        " --figure {output.figure} > {log} 2>&1"
