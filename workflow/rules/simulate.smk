# Stages 1-4 of the study, one job per file: pack per (r0, seed), trim per a, collapse per mu_r,
# analyse per collapse. Every swept value reaches `colsim` from the settings its folder's key names
# (common.smk: packing_of, column_of, run_of; colsim.study.workflow.plan), never parsed back from the
# folder's name, so a changed setting is a new folder and never an overwrite.


# A packing's and a run's settings, readable beside its files; the simulation rules take them as
# input, so they exist before the file they describe.
rule packing_settings:
    output:
        f"{PACKING_DIR}/settings.yaml",
    priority: command_lines.SETTINGS_PRIORITY
    params:
        settings=packing_of,
    run:
        write_settings(params.settings, output[0])


rule run_settings:
    output:
        f"{RUN_DIR}/settings.yaml",
    priority: command_lines.SETTINGS_PRIORITY
    params:
        settings=run_of,
    run:
        write_settings(params.settings, output[0])


rule pack:
    input:
        f"{PACKING_DIR}/settings.yaml",
    output:
        f"{PACKING_DIR}/packing.nc",
    priority: pack_priority
    threads: config["pack"]["threads"]
    resources:
        mem_mb=pack_resource("mem_mb"),
        runtime=pack_resource("runtime"),
    params:
        r0=lambda wildcards: fmt(packing_of(wildcards)["r0"]),
        seed=lambda wildcards: packing_of(wildcards)["seed"],
        height=lambda wildcards: fmt(packing_of(wildcards)["height"]),
        root_seed=config["root_seed"],
        diameter_min=config["diameter_min"],
        diameter_max=config["diameter_max"],
        density=config["density"],
        gravity=config["gravity"],
        dt=config["pack"]["dt"],
        rest_energy=config["pack"]["rest_energy"],
        max_steps=config["pack"]["max_steps"],
        max_spheres=config["pack"]["max_spheres"],
        mu=config["pack"]["mu"],
        layer_height=config["pack"]["layer_height"],
        freeze_depth=config["pack"]["freeze_depth"],
        solver=config["solver"],
    log:
        logged(f"{PACKING_DIR}/pack.log"),
    benchmark:
        benchmarked(f"{PACKING_DIR}/pack.tsv")
    shell:
        "colsim pack --r0 {params.r0} --height {params.height} --seed {params.seed}"
        " --root-seed {params.root_seed} --diameter-min {params.diameter_min}"
        " --diameter-max {params.diameter_max} --density {params.density} --gravity {params.gravity}"
        " --dt {params.dt} --rest-energy {params.rest_energy} --max-steps {params.max_steps} --mu {params.mu}"
        " --max-spheres {params.max_spheres} --layer-height {params.layer_height} --freeze-depth {params.freeze_depth}"
        " --solver {params.solver} --threads {threads} --output {output:q} > {log:q} 2>&1"


# A trim takes a second and unblocks collapses: it goes before any of them (priorities are not
# passed up the DAG, so without this the columns of the tallest collapses were cut last).
rule trim:
    input:
        f"{PACKING_DIR}/packing.nc",
    output:
        COLUMN,
    priority: command_lines.PACK_PRIORITY
    params:
        a=lambda wildcards: fmt(column_of(wildcards)),
    log:
        logged(f"{PACKING_DIR}/a_{{a}}/trim.log"),
    benchmark:
        benchmarked(f"{PACKING_DIR}/a_{{a}}/trim.tsv")
    shell:
        "colsim trim --input {input:q} --aspect-ratio {params.a} --output {output:q} > {log:q} 2>&1"


# `colsim collapse` keeps OUTPUT.checkpoint while it runs and deletes it on success; a job that was
# killed resumes from it when rerun (snakemake --rerun-incomplete). It is not a declared output.
# Taller columns start first (their cost grows like a^2): the longest jobs do not end up last, alone.
rule collapse:
    input:
        column=COLUMN,
        settings=f"{RUN_DIR}/settings.yaml",
    output:
        f"{RUN_DIR}/collapse.nc",
    priority: collapse_priority
    threads: config["collapse"]["threads"]
    resources:
        mem_mb=4000,
        runtime=collapse_runtime,
    params:
        mu=lambda wildcards: run_of(wildcards)["mu"],
        mu_r=lambda wildcards: run_of(wildcards)["mu_r"],
        options=lambda wildcards: collapse_options(run_of(wildcards)),
        checkpoint_every=config["collapse"]["checkpoint_every"],
    log:
        logged(f"{RUN_DIR}/collapse.log"),
    benchmark:
        benchmarked(f"{RUN_DIR}/collapse.tsv")
    shell:
        "colsim collapse --input {input.column:q} --mu {params.mu} --mu-r {params.mu_r} {params.options}"
        " --checkpoint-every {params.checkpoint_every} --threads {threads} --output {output:q} > {log:q} 2>&1"


rule analysis_settings:
    output:
        ANALYSIS_SETTINGS,
    params:
        settings=analysis_settings_of,
    run:
        write_settings(params.settings, output[0])


rule analyse:
    input:
        collapse=f"{RUN_DIR}/collapse.nc",
        settings=PLAN.analysis_settings_path(),   # changed analysis settings: a new input, and a rerun
    output:
        f"{RUN_DIR}/analysis.nc",
    params:
        contact_tolerance=config["analysis"]["contact_tolerance"],
        check_tolerances=numbers(config["analysis"]["check_tolerances"]),
        mass_shares=numbers(config["analysis"]["mass_shares"]),
    log:
        logged(f"{RUN_DIR}/analyse.log"),
    benchmark:
        benchmarked(f"{RUN_DIR}/analyse.tsv")
    shell:
        "colsim analyse --input {input.collapse:q} --contact-tolerance {params.contact_tolerance}"
        " --check-tolerances {params.check_tolerances} --mass-shares {params.mass_shares}"
        " --output {output:q} > {log:q} 2>&1"


# Not part of `all`: a ParaView time series of one collapse, on request, e.g.
#   snakemake -j1 results/r0_3/seed_1/pack_<key>/a_2/mu_r_0.12/run_<key>/vtk/collapse.pvd
# (the folder of any run of the study: `ls results/r0_3/seed_1/pack_*/a_2/mu_r_0.12/`).
rule export_vtk:
    input:
        f"{RUN_DIR}/collapse.nc",
    output:
        f"{RUN_DIR}/vtk/collapse.pvd",
    params:
        directory=output_directory,
    log:
        logged(f"{RUN_DIR}/export_vtk.log"),
    benchmark:
        benchmarked(f"{RUN_DIR}/export_vtk.tsv")
    shell:
        "colsim export-vtk --input {input:q} --output-dir {params.directory:q} > {log:q} 2>&1"


# `snakemake -j2 paraview` (with the study's --configfile): the ParaView series of the runs the
# side-view figure shows (the first seed, figures.side_view_mu_r, every a), made from their
# collapse.nc; a run already computed is only read, never run again. Any other run's series is its
# folder's vtk/collapse.pvd as a target.
rule paraview:
    input:
        runs("vtk/collapse.pvd", mu_r=side_view_mu_r(), seeds=SEEDS[:1]),
