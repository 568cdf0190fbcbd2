# Stages 1-4 of the study, one job per file: pack per (r0, seed), trim per a, collapse per mu_r,
# analyse per collapse. Every value reaches `colsim` through params, so editing config.yaml reruns
# exactly the jobs whose settings changed.


rule pack:
    output:
        f"{PACKING_DIR}/packing.nc",
    priority: 1000
    params:
        height=pack_height,
        root_seed=config["root_seed"],
        diameter_min=config["diameter_min"],
        diameter_max=config["diameter_max"],
        density=config["density"],
        gravity=config["gravity"],
        dt=config["pack"]["dt"],
        rest_energy=config["pack"]["rest_energy"],
        max_steps=config["pack"]["max_steps"],
        mu=config["pack"]["mu"],
        solver=config["solver"],
    log:
        logged(f"{PACKING_DIR}/pack.log"),
    benchmark:
        benchmarked(f"{PACKING_DIR}/pack.tsv")
    shell:
        "colsim pack --r0 {wildcards.r0} --height {params.height} --seed {wildcards.seed}"
        " --root-seed {params.root_seed} --diameter-min {params.diameter_min}"
        " --diameter-max {params.diameter_max} --density {params.density} --gravity {params.gravity}"
        " --dt {params.dt} --rest-energy {params.rest_energy} --max-steps {params.max_steps} --mu {params.mu}"
        " --solver {params.solver} --output {output} > {log} 2>&1"


# A trim takes a second and unblocks collapses: it goes before any of them (priorities are not
# passed up the DAG, so without this the columns of the tallest collapses were cut last).
rule trim:
    input:
        f"{PACKING_DIR}/packing.nc",
    output:
        f"{PACKING_DIR}/a_{{a}}/column.nc",
    priority: 1000
    log:
        logged(f"{PACKING_DIR}/a_{{a}}/trim.log"),
    benchmark:
        benchmarked(f"{PACKING_DIR}/a_{{a}}/trim.tsv")
    shell:
        "colsim trim --input {input} --aspect-ratio {wildcards.a} --output {output} > {log} 2>&1"


# `colsim collapse` keeps OUTPUT.checkpoint while it runs and deletes it on success; a job that was
# killed resumes from it when rerun (snakemake --rerun-incomplete). It is not a declared output.
# Taller columns start first (their cost grows like a^2): the longest jobs do not end up last, alone.
rule collapse:
    input:
        f"{PACKING_DIR}/a_{{a}}/column.nc",
    output:
        f"{BASE_RUN}/collapse.nc",
    priority: collapse_priority
    params:
        mu=config["mu"],
        mu_r=mu_r_value,
        duration=collapse_duration,
        steps=collapse_steps,
        frame_every=config["collapse"]["frame_every"],
        checkpoint_every=config["collapse"]["checkpoint_every"],
        to_rest=run_to_rest_options,
        solver=collapse_solver_options(),
        friction_law=friction_options,
    log:
        logged(f"{BASE_RUN}/collapse.log"),
    benchmark:
        benchmarked(f"{BASE_RUN}/collapse.tsv")
    shell:
        "colsim collapse --input {input} --mu {params.mu} --mu-r {params.mu_r}"
        " --duration {params.duration} --steps {params.steps} --frame-every {params.frame_every}"
        " --checkpoint-every {params.checkpoint_every} {params.to_rest} --solver {params.solver}"
        " --friction-law {params.friction_law}"
        " --output {output} > {log} 2>&1"


rule analyse:
    input:
        f"{BASE_RUN}/collapse.nc",
    output:
        f"{BASE_RUN}/analysis.nc",
    params:
        contact_tolerance=config["analysis"]["contact_tolerance"],
        check_tolerances=" ".join(fmt(t) for t in config["analysis"]["check_tolerances"]),
        mass_shares=" ".join(fmt(s) for s in config["analysis"]["mass_shares"]),
    log:
        logged(f"{BASE_RUN}/analyse.log"),
    benchmark:
        benchmarked(f"{BASE_RUN}/analyse.tsv")
    shell:
        "colsim analyse --input {input} --contact-tolerance {params.contact_tolerance}"
        " --check-tolerances {params.check_tolerances} --mass-shares {params.mass_shares}"
        " --output {output} > {log} 2>&1"


# Not part of `all`: a ParaView time series of one collapse, on request, e.g.
#   snakemake -j1 results/r0_2/seed_1/a_2/mu_r_0.12/vtk/collapse.pvd
rule export_vtk:
    input:
        f"{BASE_RUN}/collapse.nc",
    output:
        f"{BASE_RUN}/vtk/collapse.pvd",
    params:
        directory=output_directory,
    log:
        logged(f"{BASE_RUN}/export_vtk.log"),
    benchmark:
        benchmarked(f"{BASE_RUN}/export_vtk.tsv")
    shell:
        "colsim export-vtk --input {input} --output-dir {params.directory} > {log} 2>&1"
