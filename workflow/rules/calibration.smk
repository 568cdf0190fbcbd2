# The mu_r calibration (config key `calibration`, config/calibration.yaml): every mu_r and aspect
# ratio of the study at several cylinder radii (the rules pack, trim, collapse and analyse, at the
# folders their settings name), then the limits per mu_r and a, the misfit to Lube's and
# Lajeunesse's laws and the mu_r that minimises it (colsim calibrate).


# the runs alone (a target to start or resume them with, before the calibration is wanted)
rule calibration_runs:
    input:
        PLAN.calibration_runs("analysis.nc"),


rule calibration:
    input:
        PLAN.calibration_runs("analysis.nc"),
    output:
        nc=f"{STUDY_DIR}/calibration.nc",
        markdown=report(
            f"{STUDY_DIR}/calibration.md",
            caption="../report/calibration_table.rst",
            category="Calibration",
            labels={"table": "best mu_r and the a each fits"},
        ),
        figure=report(
            f"{STUDY_DIR}/figures/calibration.png",
            caption="../report/calibration.rst",
            category="Calibration",
            labels={"figure": "mu_r calibration"},
        ),
    log:
        f"{STUDY_DIR}/logs/calibration.log",
    benchmark:
        f"{STUDY_DIR}/benchmarks/calibration.tsv"
    shell:
        "colsim calibrate {input:q} --output {output.nc:q} --markdown {output.markdown:q}"
        " --figure {output.figure:q} > {log:q} 2>&1"


# a channel study (geometry: channel): the same runs at each box length L0 (calibration's r0), and
# the run-outs' spread between the two largest (colsim length-convergence)
rule length_convergence:
    input:
        PLAN.calibration_runs("analysis.nc"),
    output:
        nc=f"{STUDY_DIR}/length_convergence.nc",
        markdown=report(
            f"{STUDY_DIR}/length_convergence.md",
            caption="../report/length_convergence.rst",
            category="Convergence in L0",
            labels={"table": "run-outs by box length"},
        ),
    log:
        f"{STUDY_DIR}/logs/length_convergence.log",
    benchmark:
        f"{STUDY_DIR}/benchmarks/length_convergence.tsv"
    shell:
        "colsim length-convergence {input:q} --output {output.nc:q} --markdown {output.markdown:q} > {log:q} 2>&1"
