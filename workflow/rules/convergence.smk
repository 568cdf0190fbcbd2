# The convergence study (config key `convergence`, e.g. config/paper.yaml): collapses with their own
# number of steps and end time, then one table, its relative changes and a figure.


rule collapse_variant:
    input:
        "results/r0_{r0}/seed_{seed}/a_{a}/column.nc",
    output:
        f"{VARIANT}/collapse.nc",
    priority: collapse_priority
    params:
        mu=config["mu"],
        frame_every=config["collapse"]["frame_every"],
        checkpoint_every=config["collapse"]["checkpoint_every"],
        solver=config["solver"],
    log:
        "results/logs/r0_{r0}/seed_{seed}/a_{a}/mu_r_{mu_r}/steps_{steps}_t_{duration}/collapse.log",
    benchmark:
        "results/benchmarks/r0_{r0}/seed_{seed}/a_{a}/mu_r_{mu_r}/steps_{steps}_t_{duration}/collapse.tsv"
    shell:
        "colsim collapse --input {input} --mu {params.mu} --mu-r {wildcards.mu_r}"
        " --duration {wildcards.duration} --steps {wildcards.steps} --frame-every {params.frame_every}"
        " --checkpoint-every {params.checkpoint_every} --solver {params.solver}"
        " --output {output} > {log} 2>&1"


rule analyse_variant:
    input:
        f"{VARIANT}/collapse.nc",
    output:
        f"{VARIANT}/analysis.nc",
    params:
        contact_tolerance=config["analysis"]["contact_tolerance"],
        check_tolerances=" ".join(fmt(t) for t in config["analysis"]["check_tolerances"]),
        mass_shares=" ".join(fmt(s) for s in config["analysis"]["mass_shares"]),
    log:
        "results/logs/r0_{r0}/seed_{seed}/a_{a}/mu_r_{mu_r}/steps_{steps}_t_{duration}/analyse.log",
    benchmark:
        "results/benchmarks/r0_{r0}/seed_{seed}/a_{a}/mu_r_{mu_r}/steps_{steps}_t_{duration}/analyse.tsv"
    shell:
        "colsim analyse --input {input} --contact-tolerance {params.contact_tolerance}"
        " --check-tolerances {params.check_tolerances} --mass-shares {params.mass_shares}"
        " --output {output} > {log} 2>&1"


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
