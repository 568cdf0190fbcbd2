# Configuration check and the helpers that name the study's files (no physics here).
import jsonschema
import yaml
from snakemake.exceptions import WorkflowError
from snakemake.utils import validate

from colsim.io import atomic_path
from colsim.plots import FIGURES   # the figures `colsim plot` writes: name -> title of its report label

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


def cross_field_problem(config):
    """One line naming the first pair of settings that contradict each other, or None."""
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
    return None


with open(SCHEMA) as stream:
    SCHEMA_TREE = yaml.safe_load(stream)
problem = schema_problem(config, SCHEMA_TREE)
if problem is None:
    validate(config, SCHEMA)   # fills in the defaults
    problem = cross_field_problem(config)
if problem:
    raise WorkflowError(problem)


def fmt(value):
    """A number as it appears in paths and on the colsim command line: 1 -> '1', 0.06 -> '0.06'."""
    return f"{float(value):g}"


R0 = fmt(config["r0"])
ASPECT_RATIOS = [fmt(a) for a in config["aspect_ratios"]]
MU_R = [fmt(m) for m in config["mu_r"]]
SEEDS = [str(s) for s in config["seeds"]]
PACK_ASPECT_RATIO = config["pack_aspect_ratio"] or max(config["aspect_ratios"])


# A run's folder depends on the run alone, never on the study asking for it, so no two studies
# overwrite each other's runs: a run with the schema's default steps and end time (CANONICAL) that
# goes on to rest (the default study's) is BASE_RUN; one that stops at its end time, or has other
# steps or end time, is VARIANT below it (so the default study and a study with max_duration: null
# at the same r0 keep both runs); a run under the Coulomb law is in a folder `coulomb` below either.
# The rest settings themselves (max_duration, rest_window, ...) are not in the name: changing them
# reruns the runs, as Snakemake's "Params have changed" says.
# A packing filled with friction (pack.mu > 0) and its runs are another tree, results/pack_mu_{mu}/,
# so they never overwrite the default packings' runs.
RUNS = "results" if config["pack"]["mu"] == 0 else f"results/pack_mu_{fmt(config['pack']['mu'])}"
PACKING_DIR = RUNS + "/r0_{r0}/seed_{seed}"
BASE_RUN = PACKING_DIR + "/a_{a}/mu_r_{mu_r}"
VARIANT = BASE_RUN + "/steps_{steps}_t_{duration}"
_COLLAPSE_SCHEMA = SCHEMA_TREE["properties"]["collapse"]["properties"]
CANONICAL = (int(_COLLAPSE_SCHEMA["steps"]["default"]), float(_COLLAPSE_SCHEMA["duration"]["default"]))
FRICTION_LAW = config["friction_law"]
STUDY_LENGTH = (int(config["collapse"]["steps"]), float(config["collapse"]["duration"]))
RUN_TO_REST = config["collapse"]["max_duration"] is not None


def logged(path):
    """The log file of a job whose output is `path` (below RUNS): the same path below RUNS/logs."""
    return f"{RUNS}/logs{path[len(RUNS):]}"


def benchmarked(path):
    """The benchmark file of a job whose output is `path` (below RUNS): below RUNS/benchmarks."""
    return f"{RUNS}/benchmarks{path[len(RUNS):]}"


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
    steps=r"[0-9]+",
    duration=r"[0-9][0-9.e+-]*",


def runs(name, mu_r=None, seeds=None, law=None):
    """Paths of one file `name` of every run of the study (optionally one mu_r, some seeds, another
    friction law than the study's)."""
    return [run_path(name, R0, seed, a, m, law=law or FRICTION_LAW)
            for seed in seeds or SEEDS for a in ASPECT_RATIOS for m in (MU_R if mu_r is None else [mu_r])]


def side_view_mu_r():
    """The swept mu_r nearest to figures.side_view_mu_r."""
    target = config["figures"]["side_view_mu_r"]
    return min(MU_R, key=lambda m: abs(float(m) - target))


def pack_height(wildcards):
    """Height the packing of radius r0 must exceed: pack_aspect_ratio (or the largest a) times r0.
    A packing only the convergence study uses (another r0, or a seed outside `seeds`) is packed
    just tall enough for its sub-study's (largest) aspect ratio."""
    study = config.get("convergence")
    sizes = [entry["aspect_ratio"] for entry in (study or {}).get("column_size", [])
             if wildcards.r0 != R0 and wildcards.r0 in [fmt(r0) for r0 in entry["r0"]]]
    if sizes:
        return fmt(max(sizes) * float(wildcards.r0))
    if study and wildcards.seed not in SEEDS:   # tall enough for every sub-study using the seed
        seed = int(wildcards.seed)
        needs = [study["seeds"]["aspect_ratio"]] if seed in study["seeds"]["seeds"] else []
        needs += study["time_step"]["aspect_ratios"] if seed in study["time_step"].get("seeds", []) else []
        return fmt(max(needs or [PACK_ASPECT_RATIO]) * float(wildcards.r0))
    return fmt(PACK_ASPECT_RATIO * float(wildcards.r0))


def mu_r_value(wildcards):
    """The configured mu_r whose path string is {mu_r}, at full precision (pi/24 stays
    0.1308996938995747; its path is mu_r_0.1309)."""
    values = list(config["mu_r"]) + ([config["convergence"]["mu_r"]] if config.get("convergence") else [])
    return next((m for m in values if fmt(m) == wildcards.mu_r), float(wildcards.mu_r))


def collapse_steps(wildcards):
    """Steps of a collapse: a variant's {steps}, else the canonical ones (its folder says which)."""
    return int(wildcards.get("steps", CANONICAL[0]))


def collapse_duration(wildcards):
    """End time t/sqrt(h0/g) of a collapse: a variant's {duration}, else the canonical one."""
    return float(wildcards.get("duration", CANONICAL[1]))


def goes_to_rest(steps, duration):
    """Whether a run of these steps and end time goes on to rest: only the study's own runs, and
    only when the study sets max_duration; a convergence run of other steps or end time stops."""
    return RUN_TO_REST and (steps, duration) == STUDY_LENGTH


def run_to_rest_options(wildcards):
    """colsim collapse options that run a collapse on to rest ("" for one that stops at its end)."""
    collapse = config["collapse"]
    if not goes_to_rest(collapse_steps(wildcards), collapse_duration(wildcards)):
        return ""
    return (f"--max-duration {collapse['max_duration']} --rest-window {collapse['rest_window']}"
            f" --rest-tolerance {collapse['rest_tolerance']} --rest-energy {collapse['rest_energy']}")


def run_path(name, r0, seed, a, mu_r, steps=None, duration=None, law="associated"):
    """Path of file `name` of one run (steps and end time: the study's unless given; a run of the
    study's own length goes on to rest if the study does, any other stops at its end time)."""
    steps = STUDY_LENGTH[0] if steps is None else int(steps)
    duration = STUDY_LENGTH[1] if duration is None else float(duration)
    pattern = BASE_RUN if (steps, duration) == CANONICAL and goes_to_rest(steps, duration) else VARIANT
    pattern += "" if law == "associated" else f"/{law}"
    return pattern.format(r0=fmt(r0), seed=seed, a=fmt(a), mu_r=fmt(mu_r), steps=steps,
                          duration=fmt(duration)) + f"/{name}"


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


def collapse_solver_options():
    """What follows --solver on a collapse's command line: the back-end, and the overlap tolerance
    when the study sets one (so that the default leaves the command, and the runs, as they were)."""
    overlap = config.get("solver_overlap_tolerance")
    return config["solver"] if overlap is None else f"{config['solver']} --solver-overlap-tolerance {overlap}"


def friction_options(wildcards, output):
    """What follows --friction-law on a collapse's command line: the law, from the run's path (a
    folder `coulomb` holds the Coulomb runs), and for a Coulomb run the fixed point's tolerance (so
    that changing it reruns the Coulomb runs only)."""
    if "/coulomb/" not in output[0]:
        return "associated"
    return f"coulomb --friction-tolerance {config['friction_tolerance']}"


def convergence_outputs():
    """The convergence study's products, or none."""
    if not config.get("convergence"):
        return []
    return [f"{STUDY_DIR}/convergence.nc", f"{STUDY_DIR}/convergence.md", f"{STUDY_DIR}/figures/convergence.png"]


def collapse_priority(wildcards):
    """Scheduling priority of a collapse: 10 a (times its steps over the study's), so that the
    costliest columns run first."""
    return int(round(10 * float(wildcards.a) * collapse_steps(wildcards) / STUDY_LENGTH[0]))


def write_study_files(study, summary_path, template, config_path, description_path):
    """Write the study's configuration (YAML) and the report's description rendered from it and from
    the summary's attributes (r0, mu), each to a temporary name and then renamed."""
    import jinja2
    import xarray

    with xarray.open_dataset(summary_path) as summary:
        attrs = dict(summary.attrs)
    with open(template) as stream:
        text = jinja2.Template(stream.read(), undefined=jinja2.StrictUndefined, keep_trailing_newline=True).render(
            study=study, summary=attrs, study_dir=STUDY_DIR)
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
    study_config,
