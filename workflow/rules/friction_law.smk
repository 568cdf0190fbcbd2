# The Coulomb (non-associated) friction law (config key friction_law; README, "Friction law"): the
# study's collapse and analyse rules at a folder `coulomb` below each run, and, with
# friction_law_comparison: true, the same runs under both laws in one table and figure.


use rule collapse as collapse_coulomb with:
    output:
        f"{BASE_RUN}/coulomb/collapse.nc",
    log:
        logged(f"{BASE_RUN}/coulomb/collapse.log"),
    benchmark:
        benchmarked(f"{BASE_RUN}/coulomb/collapse.tsv")


use rule analyse as analyse_coulomb with:
    input:
        f"{BASE_RUN}/coulomb/collapse.nc",
    output:
        f"{BASE_RUN}/coulomb/analysis.nc",
    log:
        logged(f"{BASE_RUN}/coulomb/analyse.log"),
    benchmark:
        benchmarked(f"{BASE_RUN}/coulomb/analyse.tsv")


use rule export_vtk as export_vtk_coulomb with:
    input:
        f"{BASE_RUN}/coulomb/collapse.nc",
    output:
        f"{BASE_RUN}/coulomb/vtk/collapse.pvd",
    log:
        logged(f"{BASE_RUN}/coulomb/export_vtk.log"),
    benchmark:
        benchmarked(f"{BASE_RUN}/coulomb/export_vtk.tsv")


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
        "colsim compare-laws --associated {input.associated} --coulomb {input.coulomb}"
        " --output {output.nc} --markdown {output.markdown} --figure {output.figure} > {log} 2>&1"


use rule collapse as collapse_variant_coulomb with:
    output:
        f"{VARIANT}/coulomb/collapse.nc",
    log:
        logged(f"{VARIANT}/coulomb/collapse.log"),
    benchmark:
        benchmarked(f"{VARIANT}/coulomb/collapse.tsv")


use rule analyse as analyse_variant_coulomb with:
    input:
        f"{VARIANT}/coulomb/collapse.nc",
    output:
        f"{VARIANT}/coulomb/analysis.nc",
    log:
        logged(f"{VARIANT}/coulomb/analyse.log"),
    benchmark:
        benchmarked(f"{VARIANT}/coulomb/analyse.tsv")
