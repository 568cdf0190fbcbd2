# Stages 1-4 of the study, one job per file: pack per (r0, seed), trim per a, collapse per mu_r,
# analyse per collapse. A packing's, a run's and the analyses' settings reach `colsim` as the
# settings.yaml their folder's key names (common.smk: packing_of, column_of, run_of;
# colsim.study.workflow.plan), read by `colsim STAGE --settings`, never parsed back from the folder's
# name, so a changed setting is a new folder and never an overwrite. The command lines add only
# what does not change a result: threads, the device and its storage, checkpoints, the packing's size bound. A job
# on a GPU (device cuda, or auto for a large column where a GPU is) asks for resources gpu=1
# (profiles/default: one GPU, so such jobs run one at a time; SLURM: a GPU request).


# A packing's and a run's settings, readable beside its files (one line of JSON, which is YAML;
# `snakemake -n -p` shows each); the simulation rules take them as input and pass them to colsim,
# so they exist before the file they describe.
rule packing_settings:
    output:
        f"{PACKING_DIR}/settings.yaml",
    log:
        logged(f"{PACKING_DIR}/settings.log"),
    priority: job_resources.SETTINGS_PRIORITY
    params:
        text=lambda wildcards: settings_text(packing_of(wildcards)),
    shell:
        WRITE_SETTINGS


rule run_settings:
    output:
        f"{RUN_DIR}/settings.yaml",
    log:
        logged(f"{RUN_DIR}/settings.log"),
    priority: job_resources.SETTINGS_PRIORITY
    params:
        text=lambda wildcards: settings_text(run_of(wildcards)),
    shell:
        WRITE_SETTINGS


rule pack:
    input:
        settings_file(PACKING_DIR, packing_of),
    output:
        f"{PACKING_DIR}/packing.nc",
    priority: pack_priority
    threads: config["pack"]["threads"]
    resources:
        mem_mb=pack_resource("mem_mb"),
        runtime=pack_resource("runtime"),
        gpu=pack_gpus,
    params:
        max_spheres=config["pack"]["max_spheres"],
        device=config["device"],
        gpu_storage=config["gpu_storage"],
    log:
        logged(f"{PACKING_DIR}/pack.log"),
    benchmark:
        benchmarked(f"{PACKING_DIR}/pack.tsv")
    shell:
        "colsim pack --settings {input:q} --settings-key {wildcards.packing} --max-spheres {params.max_spheres} --threads {threads}"
        " --device {params.device} --gpu-storage {params.gpu_storage} --output {output:q} > {log:q} 2>&1"


# A trim takes a second and unblocks collapses: it goes before any of them (priorities are not
# passed up the DAG, so without this the columns of the tallest collapses were cut last).
rule trim:
    input:
        f"{PACKING_DIR}/packing.nc",
    output:
        COLUMN,
    priority: job_resources.PACK_PRIORITY
    params:
        a=lambda wildcards: fmt(column_of(wildcards)),
    log:
        logged(f"{PACKING_DIR}/a_{{a}}/trim.log"),
    benchmark:
        benchmarked(f"{PACKING_DIR}/a_{{a}}/trim.tsv")
    shell:
        "colsim trim --input {input:q} --aspect-ratio {params.a} --output {output:q} > {log:q} 2>&1"


# `colsim collapse` keeps OUTPUT.checkpoint (and its .frames) while it runs and deletes them on success;
# a job that was killed resumes from them when rerun (snakemake --rerun-incomplete). Not declared outputs.
# Taller columns start first (their cost grows like a^2): the longest jobs do not end up last, alone.
rule collapse:
    input:
        column=COLUMN,
        settings=settings_file(RUN_DIR, run_of),
    output:
        f"{RUN_DIR}/collapse.nc",
    priority: collapse_priority
    threads: config["collapse"]["threads"]
    resources:
        mem_mb=4000,
        runtime=collapse_runtime,
        gpu=collapse_gpus,
    params:
        checkpoint_every=config["collapse"]["checkpoint_every"],
        device=config["device"],
        gpu_storage=config["gpu_storage"],
    log:
        logged(f"{RUN_DIR}/collapse.log"),
    benchmark:
        benchmarked(f"{RUN_DIR}/collapse.tsv")
    shell:
        "colsim collapse --settings {input.settings:q} --settings-key {wildcards.run} --input {input.column:q}"
        " --checkpoint-every {params.checkpoint_every} --threads {threads} --device {params.device}"
        " --gpu-storage {params.gpu_storage} --output {output:q} > {log:q} 2>&1"


rule analysis_settings:
    output:
        ANALYSIS_SETTINGS,
    log:
        logged(ANALYSIS_SETTINGS[: -len(".yaml")] + ".log"),
    params:
        text=lambda wildcards: settings_text(analysis_settings_of(wildcards)),
    shell:
        WRITE_SETTINGS


rule analyse:
    input:
        collapse=f"{RUN_DIR}/collapse.nc",
        settings=ANALYSIS_SETTINGS,   # {analysis}: the key of the settings, which names the output too
    output:
        ANALYSIS,
    priority: job_resources.ANALYSIS_PRIORITY
    log:
        logged(ANALYSIS[: -len(".nc")] + ".log"),
    benchmark:
        benchmarked(ANALYSIS[: -len(".nc")] + ".tsv")
    shell:
        "colsim analyse --settings {input.settings:q} --settings-key {wildcards.analysis} --input {input.collapse:q}"
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
