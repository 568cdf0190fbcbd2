"""What each `colsim` subcommand does (argument parsing lives in :mod:`colsim.cli`)."""
from __future__ import annotations

import logging
from collections import Counter
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..stages import analyse as analysis

from .. import io
from ..engine.state import FRICTION_LAWS
from ..engine.threads import threading_layer, use_threads
from ..io.checkpoint import check_checkpoint_path, remove_checkpoint
from ..io.steps import step_variables
from ..io.trajectory import trajectory_dataset
from ..solvers import defaults
from ..engine.backend import HOST
from ..engine.backends import make_backend
from ..solvers.registry import make_solver
from ..stages.devices import device_for
from ..stages.collapse import collapse as run_collapse
from ..stages import pack as packing
from ..stages.pour_geometry import Channel, expected_spheres, footprint_of, geometry_attributes, solid_fraction
from ..stages.settings import (AnalysisSettings, CollapseSettings, PackSettings, SolverSettings, TrimSettings,
                               by_name, declared, external_name)
from ..stages.trim import kept_by_trim
from .flags import stage_settings
from .progress import progress_bar

log = logging.getLogger("colsim")


def _settings(args) -> dict:
    """The command's arguments as a configuration to store with its output."""
    return {k: v for k, v in vars(args).items() if k not in ("verbose",)}


INPUT_ARGUMENTS = ("input", "inputs", "summary", "analyses", "trajectories", "time_step", "end_time",
                   "column_size", "seeds", "associated", "coulomb")
OUTPUT_ARGUMENTS = ("output", "csv", "markdown", "figure", "checkpoint", "limits", "size_figure")


def _paths(args, names) -> list[Path]:
    """The paths the arguments `names` of a command hold (one path or a list each)."""
    found = []
    for name in names:
        value = getattr(args, name, None)
        if value:
            found += [Path(v) for v in (value if isinstance(value, list) else [value])]
    return found


def check_outputs(args) -> None:
    """Before any work: InputError (one line) unless every output of the command can be written
    (--output, --csv, --markdown, --figure, --checkpoint files and the --output-dir folder) and is
    absent, a regular file or a link (which the atomic rename replaces, never follows), no two
    outputs are one file (a collapse's checkpoint included), no output is one of its inputs, and a
    checkpoint path holds nothing but a colsim checkpoint. Then the temporaries of these outputs
    that a killed run left are removed."""
    outputs = _paths(args, OUTPUT_ARGUMENTS)
    if args.command in ("collapse", "pack") and not args.checkpoint:
        outputs.append(Path(f"{args.output}.checkpoint"))
    for path in outputs:
        io.check_writable(path)
        if path.exists() and not path.is_symlink() and not path.is_file() and not path.is_dir():
            raise io.InputError(f"cannot write {path}: it exists and is not a regular file (a device, a FIFO or"
                                " a socket), which colsim will not replace")
    if getattr(args, "output_dir", None):
        io.check_writable(args.output_dir, directory=True)
    seen = {}
    for path in outputs:
        key = path.resolve()
        if key in seen:
            raise io.InputError(f"{path} is given as two outputs ({seen[key]} and {path}): each needs a file of its own")
        seen[key] = path
    for path in _paths(args, INPUT_ARGUMENTS):
        if path.resolve() in seen:
            raise io.InputError(f"{path} is both an input and an output: the command would write over its input")
    if args.command in ("collapse", "pack"):
        check_checkpoint_path(args.checkpoint or f"{args.output}.checkpoint")
    for path in outputs:   # a killed run's temporaries of these outputs (nothing else's)
        for stale in io.remove_stale_temporaries(path):
            log.info("removed %s, a temporary a killed run left", stale)


def _recorded(args, *stage_settings) -> dict:
    """What a stage's file records of how it was made: the command, its files and every setting it
    ran with (by name, defaults included), so that a run is reproduced from its file alone."""
    recorded = {k: v for k, v in vars(args).items() if k in ("command", "settings", *INPUT_ARGUMENTS, *OUTPUT_ARGUMENTS)}
    for each in stage_settings:
        recorded |= by_name(each)
    return recorded


def _apgd_options(solver: SolverSettings, backend, tolerance=None) -> dict:
    """APGD's options the settings set (solver_tolerance, else `tolerance` when given;
    solver_length_floor, solver_overlap_tolerance, and on a back-end with a choice of storage the
    settings' gpu_storage) and the back-end its iterations run on; the rest keep the defaults."""
    options = {"backend": backend}
    if len(backend.storages) > 1:
        options["storage"] = solver.gpu_storage
    if solver.solver_tolerance is not None or tolerance is not None:
        options["tolerance"] = tolerance if solver.solver_tolerance is None else solver.solver_tolerance
    if solver.solver_length_floor is not None:
        options["length_floor"] = solver.solver_length_floor
    if solver.solver_overlap_tolerance is not None:
        options["overlap_tolerance"] = solver.solver_overlap_tolerance
    return options


def _backend(solver: SolverSettings):
    """The step's back-end (:mod:`colsim.engine.backend`) of the settings' device: APGD's (solver auto
    or apgd); the other solvers' steps run on the host (and :func:`_solver` refuses a device given them)."""
    return make_backend(solver.device if solver.solver in ("auto", "apgd") else "cpu")


def _solver(solver: SolverSettings, scaled_time_step: float, backend=HOST):
    """The back-end of a step's cone program the settings name, its APGD on `backend` (the step's);
    scaled_time_step: the stage's dt / sqrt(h0/g), for 'auto'. APGD's own options given to another
    back-end are refused: it would ignore them, yet the file would record them."""
    if solver.solver not in ("auto", "apgd"):
        ignored = [flag for flag, value in (("--solver-length-floor", solver.solver_length_floor),
                                            ("--solver-overlap-tolerance", solver.solver_overlap_tolerance))
                   if value is not None]
        if solver.device != "cpu":
            ignored.append(f"--device {solver.device}")
        if solver.gpu_storage != defaults.DEFAULT_GPU_STORAGE:
            ignored.append(f"--gpu-storage {solver.gpu_storage}")
        if ignored:
            raise io.InputError(f"{' and '.join(ignored)} {'are' if len(ignored) > 1 else 'is'} APGD's"
                                f" (--solver auto or apgd); --solver {solver.solver} would ignore it")
        return make_solver(solver.solver, **({} if solver.solver_tolerance is None
                                             else {"tolerance": solver.solver_tolerance}))
    options = _apgd_options(solver, backend)
    if solver.solver == "auto":   # the tolerance is APGD's; Clarabel keeps its own
        options = {"scaled_time_step": scaled_time_step, "apgd": options}
    return make_solver(solver.solver, **options)


def _what_runs(solving: SolverSettings, spheres: float) -> SolverSettings:
    """The back-end's settings as they run, and as the file records them: the device that runs a
    pour or collapse of about `spheres` spheres (auto: which), and the storage that runs. A GPU
    storage (--gpu-storage float32) with --device cpu is refused; under --device auto, where the CPU
    runs, it is dropped with a warning, and the file records float64, which the CPU stores."""
    device = device_for(solving.device, spheres, solving.solver)
    storage = solving.gpu_storage
    if device == "cpu" and storage != defaults.DEFAULT_GPU_STORAGE and solving.solver in ("auto", "apgd"):
        if solving.device == "cpu":
            raise io.InputError(f"--gpu-storage {storage} is a GPU's storage (--device cuda or auto); the CPU stores"
                                f" {defaults.DEFAULT_GPU_STORAGE}, so it would do nothing")
        log.warning("--device auto runs this on the CPU, which stores %s: --gpu-storage %s does nothing here,"
                    " and the file records %s", defaults.DEFAULT_GPU_STORAGE, storage, defaults.DEFAULT_GPU_STORAGE)
        storage = defaults.DEFAULT_GPU_STORAGE
    return replace(solving, device=device, gpu_storage=storage)


def _pack_solver(solver: SolverSettings, backend=HOST):
    """The packing's back-end, its APGD on `backend`: under auto, APGD for every step at the packing's
    own tolerance (:data:`colsim.solvers.defaults.PACK_APGD_TOLERANCE`, or solver_tolerance), Clarabel
    where APGD reaches its cap; no overlap tolerance unless asked for (the packing's tolerance is
    already as loose)."""
    if solver.solver != "auto":
        return _solver(solver, None, backend)
    return make_solver("auto", scaled_time_step=None,
                       apgd={"overlap_tolerance": defaults.PACK_APGD_OVERLAP_TOLERANCE,
                             **_apgd_options(solver, backend, defaults.PACK_APGD_TOLERANCE)})


def pack(args):
    settings, solving = stage_settings(args, PackSettings, SolverSettings)
    spheres = expected_spheres(settings.footprint, settings.height, (settings.diameter_min, settings.diameter_max))
    solving = _what_runs(solving, spheres)
    rng = np.random.default_rng([settings.seed, settings.root_seed])
    use_threads(solving.threads)
    backend = _backend(solving)
    solver = _pack_solver(solving, backend)
    checkpoint = Path(args.checkpoint or f"{args.output}.checkpoint")
    result = packing.pack(settings, rng, solver, checkpoint=checkpoint, backend=backend)
    attrs = io.global_attributes(io.STATE_KIND, "colsim packing",
                                 {**_recorded(args, settings, solving), "solver_settings": solver.describe()},
                                 settings.seed)
    attrs.update({"r0": settings.length_scale, **geometry_attributes(settings.footprint),
                  "packing_height": result.height, "solid_fraction": result.solid_fraction,
                  "steps": result.steps, "wall_time": result.wall_time, "cpu_time": result.cpu_time,
                  "gravity": settings.gravity,
                  "clouds": result.clouds, "most_fixed": result.most_fixed, "threading_layer": threading_layer(),
                  "colsim_commits": "; ".join(result.commits)})
    io.write_state(args.output, result.state, attrs,
                   {**io.contact_force_variables(result.contact_forces), **step_variables(result.diagnostics)})
    remove_checkpoint(checkpoint)
    log.info("packed %d spheres to height %.3f (solid fraction %.3f) in %d steps, %.1f s (CPU %.1f s)",
             result.state.n, result.height, result.solid_fraction, result.steps, result.wall_time,
             result.cpu_time)


def _poured_under(source) -> dict:
    """The settings of the pour a packing's or a column's file records ({} where it records none)."""
    config = io.config_of(source)
    while config and config.get("command") != "pack":
        config = config.get("input_config") or {}
    return config


def _read_state(path):
    """(state, dataset) of a packing's or a column's file (io.read_state), its gravity checked as
    `colsim pack` checks it: the gravity its pour recorded, and with the pour's step and smallest
    diameter (the defaults where the file records none) a step within the pour's range of the fall
    time across a diameter. InputError naming the file otherwise (gravity 1e-300 ran to a nonsense
    deposit)."""
    state, source = io.read_state(path)
    gravity = float(source.attrs.get("gravity", 9.81))
    recorded = _poured_under(source)
    poured = {**{external_name(item): item.default for item in declared(PackSettings)}, **recorded}
    try:
        packing.check_pour_step(float(poured["dt"]), gravity, float(poured["diameter_min"]))
    except ValueError as error:
        raise io.InputError(f"input file {path}: {error}") from None
    if "gravity" in recorded and float(recorded["gravity"]) != gravity:
        raise io.InputError(f"input file {path}: its gravity {gravity:g} is not the {float(recorded['gravity']):g}"
                            " its packing was poured under")
    return state, source


def trim(args):
    settings = stage_settings(args, TrimSettings)
    state, source = _read_state(args.input)
    r0 = float(source.attrs["r0"])
    h0 = settings.aspect_ratio * r0
    kept = kept_by_trim(state, h0)
    column = state.subset(kept)
    forces = io.contact_forces_of(source)
    attrs = io.global_attributes(io.STATE_KIND, "colsim column before release",
                                 {**_recorded(args, settings), "input_config": io.config_of(source)},
                                 source.attrs.get("seed"))
    footprint = footprint_of(source.attrs)
    fraction = solid_fraction(column, footprint, h0)
    attrs.update({"r0": r0, **geometry_attributes(footprint), "h0": h0, "aspect_ratio": settings.aspect_ratio,
                  "solid_fraction": fraction,
                  "gravity": float(source.attrs.get("gravity", 9.81)),
                  "packing_wall_time": float(source.attrs.get("wall_time", np.nan)),
                  "packing_cpu_time": float(source.attrs.get("cpu_time", np.nan))})
    extra = {} if forces is None else io.contact_force_variables(forces.subset(kept))
    io.write_state(args.output, column, attrs, extra)
    log.info("column a = %g: %d spheres, h0 = %.3f, solid fraction %.3f", settings.aspect_ratio, column.n, h0,
             fraction)


def collapse(args):
    settings, solving = stage_settings(args, CollapseSettings, SolverSettings)
    column, source = _read_state(args.input)
    if "h0" not in source.attrs:
        raise io.InputError(f"input file {args.input} is a packing, not a trimmed column (run colsim trim)")
    h0, r0 = float(source.attrs["h0"]), float(source.attrs["r0"])
    footprint = footprint_of(source.attrs)
    channel = footprint if isinstance(footprint, Channel) else None
    if channel is None and settings.wall_mu is not None:
        raise io.InputError(f"--wall-mu is the friction of a channel's walls, but {args.input} is a cylinder's column"
                            " (leave wall_mu out)")
    settings = replace(settings, gravity=float(source.attrs.get("gravity", 9.81)))
    solving = _what_runs(solving, column.n)
    use_threads(solving.threads)
    checkpoint = Path(args.checkpoint or f"{args.output}.checkpoint")
    law = "" if settings.friction_law == "associated" else f" {settings.friction_law}"
    progress = progress_bar(settings.max_steps,
                            f"collapse a={source.attrs['aspect_ratio']:g} mu_r={settings.mu_r:g}{law}")
    backend = _backend(solving)
    solver = _solver(solving, settings.scaled_step, backend)
    try:
        run = run_collapse(column, h0, settings, solver, io.contact_forces_of(source),
                           checkpoint=checkpoint, progress=progress, backend=backend, channel=channel)
    finally:
        progress.close()
    # the back-end's settings in full (defaults included), so that a summary never mixes runs
    # solved to different stopping rules (summary.check_same_settings)
    attrs = io.global_attributes(io.TRAJECTORY_KIND, "colsim collapse",
                                 {**_recorded(args, settings, solving), "solver_settings": solver.describe(),
                                  "input_config": io.config_of(source)},
                                 source.attrs.get("seed"))
    if channel is not None:   # the walls of a channel's run; a cylinder's file keeps its attributes
        attrs.update({**geometry_attributes(channel), "wall_mu": settings.law(channel=True).mu[2]})
    attrs.update({"column_solid_fraction": float(source.attrs["solid_fraction"]),
                  "n_particles": column.n, "resumed_from_step": run.resumed_from, "threading_layer": threading_layer(),
                  "colsim_commits": "; ".join(run.commits)})
    io.write_dataset(trajectory_dataset(run, h0, r0, settings, attrs), args.output)
    remove_checkpoint(checkpoint)
    backends = Counter(d.solver_backend for d in run.diagnostics)
    log.info("collapse done: %d steps in %.1f s (CPU %.1f s; %s)", len(run.diagnostics), run.wall_time,
             run.cpu_time,
             ", ".join(f"{count} by {name}" for name, count in sorted(backends.items())))
    if settings.friction_law == "coulomb":
        programs = [d.friction_iterations for d in run.diagnostics]
        log.info("coulomb fixed point: %.2f cone programs a step on average, %d at most",
                 float(np.mean(programs)), max(programs))
    if run.at_rest is not None:
        log.info("the deposit %s at t/sqrt(h0/g) = %g", "came to rest" if run.at_rest else "was still moving",
                 settings.scaled_time(len(run.diagnostics)))


def analyse(args):
    settings = stage_settings(args, AnalysisSettings)
    trajectory = io.open_dataset(args.input, io.TRAJECTORY_KIND)
    attrs = io.global_attributes(io.ANALYSIS_KIND, "colsim collapse analysis",
                                 {**_recorded(args, settings), "input_config": io.config_of(trajectory)},
                                 trajectory.attrs.get("seed"))
    result = analysis.analyse_trajectory(trajectory, settings, attrs)
    io.write_dataset(result, args.output)
    log.info("a = %g, mu_r = %g: h_inf/r0 = %.3f, (r_inf - r0)/r0 = %.3f", result.attrs["aspect_ratio"],
             result.attrs["mu_r"], float(result.h_inf_over_r0), float(result.runout_over_r0))


def collect(args):
    from ..study.collect import collect_analyses, one_row_per_run
    from ..study.markdown import lube_markdown

    summary = collect_analyses([io.open_dataset(p, io.ANALYSIS_KIND) for p in args.inputs])
    summary.attrs.update(io.global_attributes("collapse-summary", "colsim study summary", _settings(args)))
    writers = {args.output: lambda tmp: io.write_netcdf(summary, tmp)}
    if args.csv:
        writers[args.csv] = _csv_writer(one_row_per_run(summary))
    if args.markdown:
        writers[args.markdown] = _text_writer(lube_markdown(summary))
    io.write_all(writers)


def _text_writer(text: str):
    return lambda tmp: Path(tmp).write_text(text)


def _csv_writer(dataset):
    """A writer of a Dataset as a CSV table (one row per coordinate combination)."""
    frame = dataset.to_dataframe()
    return lambda tmp: frame.to_csv(tmp)


def convergence(args):
    from ..study import convergence as study

    groups = {name: [io.open_dataset(p, io.ANALYSIS_KIND) for p in getattr(args, name)]
              for name in study.SUB_STUDIES}
    table = study.runs_table(groups, args.default_end)
    table.attrs.update(io.global_attributes("convergence-table", "colsim convergence study", _settings(args)))
    limits = study.column_size_limits(table) if groups["column_size"] else None
    text = study.convergence_markdown(table)
    if groups["column_size"]:
        text += "\n" + study.column_size_limit_markdown(limits)
    log.info("convergence:\n%s", text)
    writers = {args.output: lambda tmp: io.write_netcdf(table, tmp)}
    if args.limits:
        if limits is None:
            import xarray as xr

            limits = xr.Dataset(attrs={"comment": "no aspect ratio has column-size runs of two r0 or more: "
                                                  "no limit fitted"})
        limits.attrs.update(io.global_attributes("column-size-limits", "colsim column-size limits", _settings(args)))
        writers[args.limits] = lambda tmp: io.write_netcdf(limits, tmp)
    if args.size_figure:
        from ..study.figures import column_size_limit_figure

        writers[args.size_figure] = lambda tmp: column_size_limit_figure(table, limits, tmp)
    if args.csv:
        writers[args.csv] = _csv_writer(table)
    if args.markdown:
        writers[args.markdown] = _text_writer(text)
    if args.figure:
        from ..study.figures import convergence_figure

        writers[args.figure] = lambda tmp: convergence_figure(table, tmp)
    io.write_all(writers)


def calibrate(args):
    from ..study.calibration import calibrate as run_calibration, calibration_markdown, runs_from_analyses

    analyses = [io.open_dataset(p, io.ANALYSIS_KIND) for p in args.inputs]
    if any(run.attrs.get("geometry") == "channel" for run in analyses):
        raise io.InputError("channel runs: the calibration fits the cylinder's laws (Lube et al. 2004); a channel "
                            "study's box lengths go to colsim length-convergence")
    runs = runs_from_analyses(analyses)
    result = run_calibration(runs, replicates=args.replicates, tolerance=args.fit_tolerance)
    result.attrs.update(io.global_attributes("mu-r-calibration", "colsim mu_r calibration", _settings(args)))
    from ..study.figures import calibration_figure

    _write_table_and_figure(args, "calibration", result, calibration_markdown(result), calibration_figure)


def length_convergence(args):
    from ..study.channel import length_convergence as converge, length_convergence_markdown
    from ..study.collect import collect_analyses

    analyses = [io.open_dataset(p, io.ANALYSIS_KIND) for p in args.inputs]
    by_length = {}
    for path, run in zip(args.inputs, analyses):
        if run.attrs.get("geometry") != "channel":
            raise io.InputError(f"{path}: not a channel run (geometry {run.attrs.get('geometry', 'cylinder')})")
        by_length.setdefault(float(run.attrs["channel_length"]), []).append(run)
    convergence = converge({length: collect_analyses(runs) for length, runs in by_length.items()})
    convergence.attrs.update(io.global_attributes("channel-length-convergence",
                                                  "colsim channel run-outs by box length", _settings(args)))
    text = length_convergence_markdown(convergence)
    log.info("run-outs by box length:\n%s", text)
    writers = {args.output: lambda tmp: io.write_netcdf(convergence, tmp)}
    if args.markdown:
        writers[args.markdown] = _text_writer(text)
    io.write_all(writers)


def compare_laws(args):
    from ..study.collect import collect_analyses, friction_law_comparison
    from ..study.markdown import friction_law_markdown

    summaries = {}
    for law in FRICTION_LAWS:
        analyses = [io.open_dataset(p, io.ANALYSIS_KIND) for p in getattr(args, law)]
        found = {run.attrs.get("friction_law", "associated") for run in analyses}
        if found != {law}:
            raise io.InputError(f"--{law} got runs of the {', '.join(sorted(found))} law")
        summaries[law] = collect_analyses(analyses)
    comparison = friction_law_comparison(summaries)
    comparison.attrs.update(io.global_attributes("friction-law-comparison", "colsim friction law comparison",
                                                 _settings(args)))
    from ..study.figures import friction_law_figure

    _write_table_and_figure(args, "friction laws", comparison, friction_law_markdown(comparison), friction_law_figure)


def _write_table_and_figure(args, what: str, dataset, text: str, figure) -> None:
    """Log `text` and write `dataset` to --output, `text` to --markdown and figure(dataset, path) to
    --figure where given, all or none (io.write_all)."""
    log.info("%s:\n%s", what, text)
    writers = {args.output: lambda tmp: io.write_netcdf(dataset, tmp)}
    if args.markdown:
        writers[args.markdown] = _text_writer(text)
    if args.figure:
        writers[args.figure] = lambda tmp: figure(dataset, tmp)
    io.write_all(writers)


def plot(args):
    from ..study import figures

    summary = io.open_dataset(args.summary, "collapse-summary")
    analyses = [io.open_dataset(p, io.ANALYSIS_KIND) for p in args.analyses]
    trajectories = [io.open_dataset(p, io.TRAJECTORY_KIND) for p in args.trajectories]
    figures.all_figures(summary, analyses, trajectories, Path(args.output_dir))


def export_vtk(args):
    from ..io.vtk import export_trajectory

    trajectory = io.open_dataset(args.input, io.TRAJECTORY_KIND)
    path = export_trajectory(trajectory, args.output_dir)
    log.info("wrote %s (%d frames)", path, trajectory.sizes["time"])


def status(args):
    """The runs under a results folder: how many packings and collapses are done, and for each run in
    progress (a checkpoint left by a running or a killed job) its step, simulated time, last kinetic
    energy, recent wall seconds a step, CPU and wall so far, and when the checkpoint was written."""
    import time
    from ..io.checkpoint import checkpoint_summary
    from ..study.collect import counted

    folder = Path(args.folder)
    if not folder.is_dir():
        raise io.InputError(f"{folder} is not a folder (the runs' folder: results/ by default)")
    packings, collapses = (sum(1 for _ in folder.rglob(name)) for name in ("packing.nc", "collapse.nc"))
    # regular files only: opening a FIFO named *.checkpoint would block
    checkpoints = sorted(path for path in folder.rglob("*.checkpoint") if path.is_file() and not path.is_symlink())
    print(f"{folder}: {counted(packings, 'packing')} and {counted(collapses, 'collapse')} done,"
          f" {len(checkpoints)} in progress")
    if not checkpoints:
        return
    print("| run | stage | spheres | step | t | kinetic energy | wall s a step (last 10) | CPU s | wall s | written |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    now = time.time()
    for path in checkpoints:
        run = path.parent.relative_to(folder)
        age = f"{(now - path.stat().st_mtime) / 60:.0f} min ago"
        try:
            found = checkpoint_summary(path)
        except Exception as error:   # a damaged or foreign file: say so and go on
            print(f"| {run} | not a colsim checkpoint ({type(error).__name__}) | | | | | | | | {age} |")
            continue
        print(f"| {run} | {found['stage']} | {found['spheres']:,} | {found['step']} | {found['time']:.3f} | "
              f"{found['kinetic_energy']:.3g} | {found['seconds_per_step']:.2f} | {found['cpu']:,.0f} | "
              f"{found['elapsed']:,.0f} | {age} |")


def mu_r(args):
    from ..study.polygon import polygon_rolling_coefficient

    print(f"{polygon_rolling_coefficient(args.polygon, args.method):.6f}")


def docs(args):
    """The results tables of README.md and docs/ made from docs/data (colsim.study.docs_tables):
    written in place, or with --check only compared (SystemExit 1 naming the files that differ)."""
    from ..study.docs_tables import DocsDataError, regenerate

    root = Path(args.root)
    if not (root / "docs" / "data").is_dir():
        raise io.InputError(f"{root} holds no docs/data: give the repository's root with --root")
    try:
        texts = regenerate(root)
    except DocsDataError as error:
        raise io.InputError(str(error)) from None
    stale = [path for path, text in texts.items() if path.read_text(encoding="utf-8") != text]
    if args.check:
        if stale:
            raise SystemExit(f"colsim docs: tables differ from docs/data in {', '.join(map(str, stale))}; "
                             "`colsim docs` remakes them")
        print("colsim docs: every table equals the data")
        return
    io.write_all({path: _text_writer(texts[path]) for path in stale})
    print(f"colsim docs: {len(stale)} of {len(texts)} files remade from docs/data")
