# Configuration check and the helpers that name the study's files (no physics here).
import hashlib
import json
import math
import re

import jsonschema
import yaml
from snakemake.exceptions import WorkflowError
from snakemake.utils import validate

from colsim.io import atomic_path
from colsim.stages.pack import expected_spheres
from colsim.study.plots import FIGURES   # the figures `colsim plot` writes: name -> title of its report label

SCHEMA = os.path.join(workflow.basedir, "workflow", "schemas", "config.schema.yaml")


def schema_problem(config, schema):
    """One line naming the first key or value of `config` that the schema rejects, or None."""
    errors = sorted(jsonschema.Draft202012Validator(schema).iter_errors(config), key=lambda e: list(e.path))
    if not errors:
        return None
    error = errors[0]
    where = ".".join(str(p) for p in error.path)
    if error.validator == "additionalProperties":
        allowed = list(error.schema.get("properties", {}))
        unknown = sorted(set(error.instance) - set(allowed))
        return (f"config: unknown key {', '.join(f'{where}.{k}' if where else k for k in unknown)};"
                f" allowed{' in ' + where if where else ''}: {', '.join(allowed)}")
    return f"config: {where or 'the configuration'}: {error.message}"


CONFIG_MAX_ITEMS = 100_000   # far above any study's configuration (the default has about 100)


def size_problem(tree, limit=CONFIG_MAX_ITEMS):
    """One line if `tree` holds more than `limit` keys and values once YAML's aliases are expanded
    (an alias bomb, a configuration that refers to itself), else None: the validator never walks it."""
    stack, seen = [tree], 0
    while stack:
        node = stack.pop()
        seen += 1
        if seen > limit:
            return (f"config: more than {limit:,} keys and values once YAML's aliases are expanded;"
                    " is an alias repeated, or does the configuration refer to itself?")
        if isinstance(node, dict):
            stack.extend(node.values())
        elif isinstance(node, list):
            stack.extend(node)
    return None


def non_finite_number(tree, where=""):
    """The dotted key of the first number in the configuration that is NaN or infinite (the schema's
    minimum and maximum let NaN through), or None."""
    if isinstance(tree, dict):
        items = tree.items()
    elif isinstance(tree, list):
        items = enumerate(tree)
    else:
        return where if isinstance(tree, float) and not math.isfinite(tree) else None
    for key, value in items:
        found = non_finite_number(value, f"{where}.{key}" if where else str(key))
        if found is not None:
            return found
    return None


def cross_field_problem(config):
    """One line naming the first pair of settings that contradict each other, or None."""
    bad = non_finite_number(config)
    if bad is not None:
        return f"config: {bad}: must be a finite number"
    if not re.fullmatch(r"[A-Za-z0-9_-]*", config["study"]):
        return f"config: study: {config['study']!r} may hold only letters, digits, _ and -"
    d_min, d_max, r0 = config["diameter_min"], config["diameter_max"], config["r0"]
    if d_min > d_max:
        return f"config: diameter_min {d_min} exceeds diameter_max {d_max}"
    if r0 < d_max:
        return f"config: r0 {r0} is below diameter_max {d_max}: the largest particle does not fit in the cylinder"
    columns = [(a, r0) for a in config["aspect_ratios"]]
    study = config.get("convergence") or {}
    columns += [(entry["aspect_ratio"], r) for entry in study.get("column_size", []) for r in entry["r0"]]
    columns += [(a, r0) for a in study.get("time_step", {}).get("aspect_ratios", [])]
    columns += [(a, r0) for a in study.get("end_time", {}).get("aspect_ratios", [])]
    columns += [(study["seeds"]["aspect_ratio"], r0)] if "seeds" in study else []
    for a, radius in columns:
        if radius < d_max:
            return f"config: convergence r0 {radius} is below diameter_max {d_max}"
        if a * radius < d_max:
            return (f"config: aspect ratio {a} at r0 {radius} gives h0 = {a * radius:g}, below diameter_max {d_max}:"
                    f" the column would hold less than one layer of particles (diameters {d_min}-{d_max})")
    if config["friction_law"] != "associated" and config["friction_law_comparison"]:
        return "config: friction_law_comparison needs friction_law: associated (it adds the coulomb runs itself)"
    if config["friction_law"] != "associated" and config.get("convergence"):
        return "config: the convergence study runs the associated law only; leave out convergence with friction_law: coulomb"
    pack = config["pack_aspect_ratio"]
    if pack is not None and pack < max(config["aspect_ratios"]):
        return f"config: pack_aspect_ratio {pack} is below the largest aspect ratio {max(config['aspect_ratios'])}"
    limit = config["pack"]["max_spheres"]
    for a, radius in [(pack or max(config["aspect_ratios"]), r0)] + columns:
        spheres = expected_spheres(radius, a * radius, (d_min, d_max))
        if spheres > limit:
            return (f"config: a packing of r0 {radius:g} for a = {a:g} would hold about {spheres:,.0f} spheres,"
                    f" above pack.max_spheres {limit:,} (raise it if the machine has the memory)")
    return None


with open(SCHEMA) as stream:
    SCHEMA_TREE = yaml.safe_load(stream)
problem = size_problem(config) or schema_problem(config, SCHEMA_TREE)
if problem is None:
    validate(config, SCHEMA)   # fills in the defaults
    problem = cross_field_problem(config)
if problem:
    raise WorkflowError(problem)


def fmt(value):
    """A number as it appears in paths and on the colsim command line, without loss: 1 -> '1',
    0.06 -> '0.06', pi/24 -> '0.1308996938995747' (%g where it gives the same number back)."""
    short = f"{float(value):g}"
    return short if float(short) == float(value) else repr(float(value))


R0 = fmt(config["r0"])
ASPECT_RATIOS = [fmt(a) for a in config["aspect_ratios"]]
MU_R = [fmt(m) for m in config["mu_r"]]
SEEDS = [str(s) for s in config["seeds"]]
PACK_ASPECT_RATIO = config["pack_aspect_ratio"] or max(config["aspect_ratios"])


# A run's identity is every setting that changes its result. Its folder names the swept values for
# a reader (r0, seed, a, mu_r) and a key: the first ten hex digits of the SHA-256 of its settings
# (settings_key), written out beside it as settings.yaml. A packing's key covers its height, seeds,
# diameters, density, gravity, pack.* but NOT_IDENTITY, and the solver; a collapse's covers mu, mu_r, the rolling lever,
# the friction law, steps, end time, the rest settings, the solver and frame_every (not
# checkpoint_every, which does not change a result). Two studies share a file only when it is the
# same computation; the key of a setting changed means a new folder, never an overwrite.
RESULTS = "results"
PACKING_DIR = RESULTS + "/r0_{r0}/seed_{seed}/pack_{packing}"
COLUMN = PACKING_DIR + "/a_{a}/column.nc"
RUN_DIR = PACKING_DIR + "/a_{a}/mu_r_{mu_r}/run_{run}"
PACKINGS = {}   # key -> packing settings, of every packing this study names
RUNS = {}       # key -> collapse settings, of every run this study names
_COLLAPSE_SCHEMA = SCHEMA_TREE["properties"]["collapse"]["properties"]
FRICTION_LAW = config["friction_law"]
STUDY_LENGTH = (int(config["collapse"]["steps"]), float(config["collapse"]["duration"]))
RUN_TO_REST = config["collapse"]["max_duration"] is not None


NOT_IDENTITY = ("max_spheres", "threads")   # pack.* settings that do not change a packing
# ... nor do the layers' settings of a packing poured in one cloud (layer_height null), which so
# keeps the folder it had before layers existed
ONE_CLOUD_NOT_IDENTITY = NOT_IDENTITY + ("layer_height", "freeze_depth")


def settings_key(settings):
    """Ten hex digits of the SHA-256 of `settings` as canonical JSON (a folder name)."""
    text = json.dumps(settings, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:10]


def logged(path):
    """The log file of a job whose output is `path` (below results/): the same path below results/logs."""
    return f"{RESULTS}/logs{path[len(RESULTS):]}"


def benchmarked(path):
    """The benchmark file of a job whose output is `path` (below results/): below results/benchmarks."""
    return f"{RESULTS}/benchmarks{path[len(RESULTS):]}"


# where the study's summary, tables and figures go (runs are shared between studies)
STUDY_DIR = f"results/{config['study']}" if config["study"] else "results"
# the report's description of the study, written with its summary (rule study_config)
DESCRIPTION = f"{STUDY_DIR}/report_description.rst"
DESCRIPTION_TEMPLATE = os.path.join(workflow.basedir, "workflow", "report", "workflow.rst")

wildcard_constraints:
    r0=r"[0-9][0-9.e+-]*",
    a=r"[0-9][0-9.e+-]*",
    mu_r=r"[0-9][0-9.e+-]*",
    seed=r"[0-9]+",
    packing=r"[0-9a-f]{10}",
    run=r"[0-9a-f]{10}",


def runs(name, mu_r=None, seeds=None, law=None):
    """Paths of one file `name` of every run of the study (optionally one mu_r, some seeds, another
    friction law than the study's)."""
    return [run_path(name, R0, seed, a, m, law=law or FRICTION_LAW)
            for seed in seeds or SEEDS for a in ASPECT_RATIOS for m in (MU_R if mu_r is None else [mu_r])]


def side_view_mu_r():
    """The swept mu_r nearest to figures.side_view_mu_r."""
    target = config["figures"]["side_view_mu_r"]
    return min(MU_R, key=lambda m: abs(float(m) - target))


def pack_height(r0, seed):
    """Height (length) the packing of radius r0 and seed `seed` must exceed: pack_aspect_ratio (or
    the largest a) times r0. A packing only the convergence study uses (another r0, or a seed outside
    `seeds`) is packed just tall enough for its sub-study's (largest) aspect ratio."""
    r0, seed = fmt(r0), str(seed)
    study = config.get("convergence")
    sizes = [entry["aspect_ratio"] for entry in (study or {}).get("column_size", [])
             if r0 != R0 and r0 in [fmt(size) for size in entry["r0"]]]
    if sizes:
        return max(sizes) * float(r0)
    if study and seed not in SEEDS:   # tall enough for every sub-study using the seed
        needs = [study["seeds"]["aspect_ratio"]] if int(seed) in study["seeds"]["seeds"] else []
        needs += study["time_step"]["aspect_ratios"] if int(seed) in study["time_step"].get("seeds", []) else []
        return max(needs or [PACK_ASPECT_RATIO]) * float(r0)
    return PACK_ASPECT_RATIO * float(r0)


def packing_settings(r0, seed):
    """Everything `colsim pack` is given for the packing of (r0, seed): its identity."""
    not_identity = NOT_IDENTITY if config["pack"]["layer_height"] is not None else ONE_CLOUD_NOT_IDENTITY
    return {"r0": float(r0), "seed": int(seed), "height": float(pack_height(r0, seed)),
            "root_seed": config["root_seed"], "diameter_min": float(config["diameter_min"]),
            "diameter_max": float(config["diameter_max"]), "density": float(config["density"]),
            "gravity": float(config["gravity"]), "solver": config["solver"],
            "pack": {key: value for key, value in config["pack"].items() if key not in not_identity}}


def packing_dir(r0, seed):
    """The folder of the packing of (r0, seed) under this study's settings (registered in PACKINGS)."""
    settings = packing_settings(r0, seed)
    key = settings_key(settings)
    PACKINGS[key] = settings
    return PACKING_DIR.format(r0=fmt(r0), seed=seed, packing=key)


def goes_to_rest(steps, duration):
    """Whether a run of these steps and end time goes on to rest: only the study's own runs, and
    only when the study sets max_duration; a convergence run of other steps or end time stops."""
    return RUN_TO_REST and (steps, duration) == STUDY_LENGTH


def run_settings(mu_r, steps, duration, law):
    """Everything `colsim collapse` is given for one run of a column (its identity, with the column)."""
    collapse = config["collapse"]
    rest = None
    if goes_to_rest(steps, duration):
        rest = {key: float(collapse[key]) for key in ("max_duration", "rest_window", "rest_tolerance", "rest_energy")}
    return {"mu": float(config["mu"]), "mu_r": float(mu_r), "rolling_lever": config["rolling_lever"],
            "friction_law": law, "friction_tolerance": config["friction_tolerance"] if law == "coulomb" else None,
            "steps": int(steps), "duration": float(duration), "rest": rest, "solver": config["solver"],
            "solver_overlap_tolerance": config["solver_overlap_tolerance"],
            "frame_every": int(collapse["frame_every"])}


def run_path(name, r0, seed, a, mu_r, steps=None, duration=None, law=None):
    """Path of file `name` of one run (steps and end time: the study's unless given; a run of the
    study's own length goes on to rest if the study does, any other stops at its end time; the
    friction law: the study's unless given). The run is registered in RUNS."""
    steps = STUDY_LENGTH[0] if steps is None else int(steps)
    duration = STUDY_LENGTH[1] if duration is None else float(duration)
    settings = run_settings(mu_r, steps, duration, law or FRICTION_LAW)
    key = settings_key(settings)
    RUNS[key] = settings
    return f"{packing_dir(r0, seed)}/a_{fmt(a)}/mu_r_{fmt(mu_r)}/run_{key}/{name}"


def packing_of(wildcards):
    """The settings of the packing that {packing} names; a key this study does not name is an error
    (its settings are not in this configuration, so the file cannot be made again from it)."""
    settings = PACKINGS.get(wildcards.packing)
    if settings is None or fmt(settings["r0"]) != wildcards.r0 or str(settings["seed"]) != wildcards.seed:
        raise WorkflowError(f"no packing of this study has the folder r0_{wildcards.r0}/seed_{wildcards.seed}/"
                            f"pack_{wildcards.packing}: its settings.yaml says what made it")
    return settings


def run_of(wildcards):
    """The settings of the run that {run} names (an error for a key this study does not name)."""
    settings = RUNS.get(wildcards.run)
    if settings is None or fmt(settings["mu_r"]) != wildcards.mu_r:
        raise WorkflowError(f"no run of this study has the folder mu_r_{wildcards.mu_r}/run_{wildcards.run}:"
                            " its settings.yaml says what made it")
    return settings


def write_settings(settings, path):
    """Write a run's or packing's settings (its identity) as YAML, atomically."""
    with atomic_path(path) as tmp, open(tmp, "w") as stream:
        yaml.safe_dump(settings, stream, sort_keys=True)


def convergence_runs(name):
    """{sub-study: [paths of file `name`]} of the convergence study (empty without one)."""
    study = config.get("convergence")
    if not study:
        return {}
    mu_r, seed, steps, end = study["mu_r"], SEEDS[0], config["collapse"]["steps"], config["collapse"]["duration"]
    longer = study["end_time"]["duration"]

    def same_dt(duration):
        """(steps, end time) of a run to `duration` at the study's dt."""
        return round(steps * duration / end), duration

    return {
        "time_step": [run_path(name, R0, s, a, mu_r, n, end)
                      for a in study["time_step"]["aspect_ratios"] for n in study["time_step"]["steps"]
                      for s in study["time_step"].get("seeds", [seed])],
        "end_time": [run_path(name, R0, seed, a, mu_r, *same_dt(longer))
                     for a in study["end_time"]["aspect_ratios"]],
        "column_size": [run_path(name, r0, s, entry["aspect_ratio"], mu_r, *same_dt(entry.get("duration", end)))
                        for entry in study["column_size"] for r0 in entry["r0"]
                        for s in entry.get("seeds", [seed])],
        "seeds": [run_path(name, R0, s, study["seeds"]["aspect_ratio"], mu_r)
                  for s in study["seeds"]["seeds"]],
    }


def friction_law_outputs():
    """The friction-law comparison's products (friction_law_comparison: true), or none."""
    if not config["friction_law_comparison"]:
        return []
    return [f"{STUDY_DIR}/friction_law.nc", f"{STUDY_DIR}/friction_law.md", f"{STUDY_DIR}/figures/friction_law.png"]


def collapse_options(wildcards):
    """What follows --mu-r on a run's collapse command line, from its settings: the rolling lever,
    the friction law (and a Coulomb run's fixed-point tolerance), steps, end time, frames, the rest
    options, the solver (and its overlap tolerance when the study sets one)."""
    run = run_of(wildcards)
    options = (f"--rolling-lever {run['rolling_lever']} --friction-law {run['friction_law']}"
               f" --steps {run['steps']} --duration {fmt(run['duration'])} --frame-every {run['frame_every']}")
    if run["friction_law"] == "coulomb":
        options += f" --friction-tolerance {run['friction_tolerance']}"
    if run["rest"] is not None:
        rest = run["rest"]
        options += (f" --max-duration {fmt(rest['max_duration'])} --rest-window {fmt(rest['rest_window'])}"
                    f" --rest-tolerance {fmt(rest['rest_tolerance'])} --rest-energy {fmt(rest['rest_energy'])}")
    options += f" --solver {run['solver']}"
    if run["solver_overlap_tolerance"] is not None:
        options += f" --solver-overlap-tolerance {run['solver_overlap_tolerance']}"
    return options


def convergence_outputs():
    """The convergence study's products, or none."""
    if not config.get("convergence"):
        return []
    return [f"{STUDY_DIR}/convergence.nc", f"{STUDY_DIR}/convergence.md", f"{STUDY_DIR}/figures/convergence.png",
            f"{STUDY_DIR}/column_size_limits.nc", f"{STUDY_DIR}/figures/column_size_limits.png"]


def collapse_runtime(wildcards):
    """A collapse's time limit on a cluster (minutes; SLURM's runtime), from config/paper.yaml's
    measured jobs (r0 = 4, docs/validation/paper-scale.md): 623 s to rest at a = 5 and 773 s at
    mu_r = 0 (t/sqrt(h0/g) = 12), so 120 at the study's length; 300 for more steps or a later end
    (a convergence study's 2,000 steps cost twice); 1440 under the Coulomb law (8-18x the CPU).
    A collapse that runs out of time resumes from its checkpoint (the profile's retries)."""
    run = run_of(wildcards)
    if run["friction_law"] == "coulomb":
        return 1440
    longer = run["steps"] > STUDY_LENGTH[0] or run["duration"] > STUDY_LENGTH[1]
    return 300 if longer else 120


def collapse_priority(wildcards):
    """Scheduling priority of a collapse: 10 a (times its steps over the study's), so that the
    costliest columns run first."""
    return int(round(10 * float(wildcards.a) * run_of(wildcards)["steps"] / STUDY_LENGTH[0]))


def write_study_files(study, summary_path, template, config_path, description_path):
    """Write the study's configuration (YAML) and the report's description rendered from it and from
    the summary (its attributes, and the table against Lube at figures.side_view_mu_r), each to a
    temporary name and then renamed."""
    import jinja2
    import xarray

    from colsim.study.markdown import lube_rst

    with xarray.open_dataset(summary_path) as summary:
        attrs = dict(summary.attrs)
        table = lube_rst(summary, study["figures"]["side_view_mu_r"])
    with open(template) as stream:
        text = jinja2.Template(stream.read(), undefined=jinja2.StrictUndefined, keep_trailing_newline=True).render(
            study=study, summary=attrs, study_dir=STUDY_DIR, lube_table=table)
    for path, write in ((config_path, lambda s: yaml.safe_dump(study, s, sort_keys=False)),
                        (description_path, lambda s: s.write(text))):
        with atomic_path(path) as tmp, open(tmp, "w") as stream:
            write(stream)


def report_description():
    """The description of the report: the study's own (written with its summary), or a note that the
    study has not been run."""
    if os.path.exists(DESCRIPTION):
        return os.path.abspath(DESCRIPTION)
    return "workflow/report/not_run.rst"


def output_directory(wildcards, output):
    """The directory of a rule's first output (for commands that take --output-dir)."""
    return os.path.dirname(output[0])


def figures():
    return expand(f"{STUDY_DIR}/figures/{{figure}}.png", figure=FIGURES)


# cheap jobs that a cluster run keeps on the submitting node
localrules:
    all,
    paraview,
    study_config,
    packing_settings,
    run_settings,
