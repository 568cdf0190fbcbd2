# Stage 5: one dataset over (aspect_ratio, mu_r, seed), the comparison figures and the study's
# configuration for the report.


rule collect:
    input:
        runs("analysis.nc"),
    output:
        nc="results/summary.nc",
        csv=report(
            "results/summary.csv",
            caption="../report/summary.rst",
            category="Summary",
            labels={"table": "summary over (aspect_ratio, mu_r, seed)"},
        ),
    log:
        "results/logs/collect.log",
    benchmark:
        "results/benchmarks/collect.tsv"
    shell:
        "colsim collect {input} --output {output.nc} --csv {output.csv} > {log} 2>&1"


rule plot:
    input:
        summary="results/summary.nc",
        analyses=runs("analysis.nc"),
        trajectories=runs("collapse.nc", mu_r=side_view_mu_r(), seeds=SEEDS[:1]),
    output:
        **{
            name: report(
                f"results/figures/{name}.png",
                caption=f"../report/{name}.rst",
                category="Figures",
                labels={"figure": title},
            )
            for name, title in FIGURES.items()
        },
    params:
        directory=output_directory,
    log:
        "results/logs/plot.log",
    benchmark:
        "results/benchmarks/plot.tsv"
    shell:
        "colsim plot --summary {input.summary} --analyses {input.analyses}"
        " --trajectories {input.trajectories} --output-dir {params.directory} > {log} 2>&1"


rule study_config:
    output:
        report(
            "results/study_config.yaml",
            caption="../report/study_config.rst",
            category="Configuration",
            labels={"file": "study configuration"},
        ),
    params:
        config=config,
    log:
        "results/logs/study_config.log",
    benchmark:
        "results/benchmarks/study_config.tsv"
    run:
        import yaml

        with open(output[0], "w") as stream:
            yaml.safe_dump(dict(params.config), stream, sort_keys=False)
        with open(log[0], "w") as stream:
            print(f"wrote {output[0]}", file=stream)
