# The Coulomb (non-associated) friction law (config key friction_law; docs/method.md, "Friction law"): its runs
# are the rules collapse and analyse at the folders their settings name (the law is one of them);
# with friction_law_comparison: true, the same runs under both laws in one table and figure.


rule friction_law_comparison:
    input:
        associated=runs("analysis.nc", law="associated"),
        coulomb=runs("analysis.nc", law="coulomb"),
    output:
        nc=f"{STUDY_DIR}/friction_law.nc",
        markdown=report(
            f"{STUDY_DIR}/friction_law.md",
            caption="../report/friction_law_table.rst",
            category="Friction law",
            labels={"table": "both laws against Lube's laws"},
        ),
        figure=report(
            f"{STUDY_DIR}/figures/friction_law.png",
            caption="../report/friction_law.rst",
            category="Friction law",
            labels={"figure": "Friction laws"},
        ),
    log:
        f"{STUDY_DIR}/logs/friction_law.log",
    benchmark:
        f"{STUDY_DIR}/benchmarks/friction_law.tsv"
    shell:
        "colsim compare-laws --associated {input.associated:q} --coulomb {input.coulomb:q}"
        " --output {output.nc:q} --markdown {output.markdown:q} --figure {output.figure:q} > {log:q} 2>&1"
