# Stage 5: one dataset over (aspect_ratio, mu_r, seed), the comparison figures and the study's
# configuration for the report.


rule collect:
    input:
        runs("analysis.nc"),
    output:
        nc=f"{STUDY_DIR}/summary.nc",
        markdown=report(
            f"{STUDY_DIR}/lube_table.md",
            caption="../report/lube_table.rst",
            category="Summary",
            labels={"table": "against Lube's laws (Markdown)"},
        ),
        csv=report(
            f"{STUDY_DIR}/summary.csv",
            caption="../report/summary.rst",
            category="Summary",
            labels={"table": "summary over (aspect_ratio, mu_r, seed)"},
        ),
    log:
        f"{STUDY_DIR}/logs/collect.log",
    benchmark:
        f"{STUDY_DIR}/benchmarks/collect.tsv"
    shell:
        "colsim collect {input:q} --output {output.nc:q} --csv {output.csv:q}"
        " --markdown {output.markdown:q} > {log:q} 2>&1"


rule plot:
    input:
        summary=f"{STUDY_DIR}/summary.nc",
        analyses=runs("analysis.nc"),
        trajectories=runs("collapse.nc", mu_r=side_view_mu_r(), seeds=SEEDS[:1]),
    output:
        **{
            name: report(
                f"{STUDY_DIR}/figures/{name}.png",
                caption=f"../report/{name}.rst",
                category="Figures",
                labels={"figure": title},
            )
            for name, title in FIGURES.items()
        },
    params:
        directory=output_directory,
    log:
        f"{STUDY_DIR}/logs/plot.log",
    benchmark:
        f"{STUDY_DIR}/benchmarks/plot.tsv"
    shell:
        "colsim plot --summary {input.summary:q} --analyses {input.analyses:q}"
        " --trajectories {input.trajectories:q} --output-dir {params.directory:q} > {log:q} 2>&1"


# The study's configuration in a file named by its key: any setting changed (figures.side_view_mu_r
# included) names another file, so study_config runs again. Snakemake's own record of a parameter did
# not rerun it: the report kept the landing table of the old mu_r.
rule study_settings:
    output:
        STUDY_SETTINGS,
    log:
        logged(STUDY_SETTINGS[: -len(".yaml")] + ".log"),
    params:
        text=settings_text(dict(config)),
    shell:
        WRITE_SETTINGS


# The study's configuration and the report's description, written only once the summary they
# describe exists (a failed run leaves the previous pair in place). The report shows these files,
# so its text describes the study that made them, whatever configuration builds the report.
rule study_config:
    input:
        summary=f"{STUDY_DIR}/summary.nc",
        settings=STUDY_SETTINGS,
        template=DESCRIPTION_TEMPLATE,   # an edit of the landing page's text rewrites it
    output:
        config=report(
            f"{STUDY_DIR}/study_config.yaml",
            caption="../report/study_config.rst",
            category="Configuration",
            labels={"file": "study configuration"},
        ),
        description=DESCRIPTION,
    log:
        f"{STUDY_DIR}/logs/study_config.log",
    benchmark:
        f"{STUDY_DIR}/benchmarks/study_config.tsv"
    run:
        study_report.write_study_files(input.settings, input.summary, input.template, output.config,
                                       output.description, STUDY_DIR, log[0])
