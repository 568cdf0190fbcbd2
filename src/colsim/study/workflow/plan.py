"""A study's files: the folder of each packing, column and run, and the settings that its key names.

A run's identity is every setting that changes its result. Its folder names the swept values for a
reader (r0, seed, a, mu_r) and a key: the first ten hex digits of the SHA-256 of its settings
(settings_key), written out beside it as settings.yaml. The settings come from the stages'
dataclasses (colsim.stages.settings): every declared setting of the stage and of its solver that
the configuration holds (in the stage's section, else at the top level), but NOT_IDENTITY, which
does not change a result. So a setting added to a dataclass, the schema and config.yaml reaches
the key and settings.yaml with no change here. Two studies share a file only when it is the same
computation; the key of a setting changed means a new folder, never an overwrite.

Values travel as numbers: a folder's name is written from a value (fmt), and a rule reads the value
back from the settings its folder's key names (packing_of, column_of, run_of), never by parsing the
name.
"""
from __future__ import annotations

import json

from ...stages.pour_geometry import Channel
from ...stages.settings import STAGES, SOLVING_STAGES, SolverSettings, declared, external_name, settings_key, unrecorded

RESULTS = "results"
PACKING_DIR = RESULTS + "/r0_{r0}/seed_{seed}/pack_{packing}"
COLUMN = PACKING_DIR + "/a_{a}/column.nc"
RUN_DIR = PACKING_DIR + "/a_{a}/mu_r_{mu_r}/run_{run}"
#: the analysis settings a run's analysis was made with, by key: an input of every analysis, so
#: that changed settings (a new key, a new input) rerun the analyses and what follows them
ANALYSIS_SETTINGS = RESULTS + "/analysis_settings/{analysis}.yaml"
#: a run's analysis, named by the key of its settings as the run's folder is by the run's: two studies
#: that analyse one run differently keep both (the plan's paths ask for it as "analysis.nc")
ANALYSIS = RUN_DIR + "/analysis_{analysis}.nc"

#: settings that do not change a result (threads: by rounding only), so no key holds them
NOT_IDENTITY = ("max_spheres", "threads", "checkpoint_every", "device", "gpu_storage")
#: ... nor do the layers' settings of a packing poured in one cloud (layer_height null), which so
#: keeps the folder it had before layers existed
ONE_CLOUD_NOT_IDENTITY = NOT_IDENTITY + ("layer_height", "freeze_depth")
#: the collapse's settings that its key holds as one group, "rest", and only for a run that goes on to rest
REST_SETTINGS = ("max_duration", "rest_window", "rest_tolerance", "rest_energy")
#: the section of the configuration that holds each stage's own settings
SECTIONS = {"pack": "pack", "collapse": "collapse", "analyse": "analysis"}
#: top-level settings of the configuration that are one stage's alone (the schema says so): the
#: others' keep their own default
ONE_STAGE = {"solver_overlap_tolerance": "collapse"}


def configured(config, stage: str, given: dict, skip=NOT_IDENTITY) -> tuple[dict, dict]:
    """The settings of `stage` (and of its solver) as the configuration holds them:
    ({name: value} from the stage's section, {name: value} from the top level), each value as its
    setting's kind has it (integers int, numbers float, lists lists); `given` values (a sweep's,
    a folder's) come first, in the top level; names in `skip` are left out, and so is a setting
    added later at its default (:func:`colsim.stages.settings.unrecorded`: a cylinder's geometry, a
    channel's settings unset), which keeps the keys made before it."""
    section = config.get(SECTIONS[stage]) or {}
    classes = (STAGES[stage], SolverSettings) if stage in SOLVING_STAGES else (STAGES[stage],)
    own, top = {}, {}
    for item in (item for cls in classes for item in declared(cls)):
        name = external_name(item)
        if name in skip:
            continue
        if name in given:
            value, into = given[name], top
        elif name in section:
            value, into = section[name], own
        elif name in config and ONE_STAGE.get(name, stage) == stage:
            value, into = config[name], top
        else:
            continue
        if not unrecorded(item, value):
            into[name] = _as_kind(item, value)
    return own, top


def _as_kind(item, value):
    """A configured value as its setting declares it: None, int, float, a list of floats, or as is (a choice)."""
    kind = item.metadata["kind"]
    if value is None or kind == "choice":
        return value
    if item.metadata["many"]:
        return [float(v) for v in value]
    return int(value) if kind in ("integer", "positive_int") else float(value)


def fmt(value) -> str:
    """A number as it appears in paths and on the colsim command line, without loss: 1 -> '1',
    0.06 -> '0.06', pi/24 -> '0.1308996938995747' (%g where it gives the same number back)."""
    short = f"{float(value):g}"
    return short if float(short) == float(value) else repr(float(value))


def logged(path: str) -> str:
    """The log file of a job whose output is `path` (below results/): the same path below results/logs."""
    return f"{RESULTS}/logs{path[len(RESULTS):]}"


def benchmarked(path: str) -> str:
    """The benchmark file of a job whose output is `path` (below results/): below results/benchmarks."""
    return f"{RESULTS}/benchmarks{path[len(RESULTS):]}"


def study_dir(config) -> str:
    """Where the study's summary, tables and figures go (runs are shared between studies)."""
    return f"{RESULTS}/{config['study']}" if config["study"] else RESULTS


def settings_text(settings) -> str:
    """A packing's, a run's or the analyses' settings (their identity) as the text of their
    settings.yaml: one line of JSON, keys sorted (JSON is YAML; the dry run's -p shows it whole)."""
    return json.dumps(settings, sort_keys=True)


def _flat(settings: dict, where: str = "") -> dict:
    """{dotted name: value} of a settings mapping, its sections' settings as section.name."""
    flat = {}
    for name, value in settings.items():
        flat |= _flat(value, f"{where}{name}.") if isinstance(value, dict) else {f"{where}{name}": value}
    return flat


def edited_setting(path, planned: dict) -> str | None:
    """One line naming the first setting that the settings file `path` holds other than `planned`
    (the settings its folder's key names), or None where the file is absent or holds them: a
    settings.yaml edited by hand would otherwise run under a key that names other settings."""
    try:
        with open(path) as stream:
            found = json.loads(stream.read(2**20))
    except FileNotFoundError:
        return None
    except (OSError, ValueError):
        found = None
    if not isinstance(found, dict):
        return f"{path} is not the settings its folder's key names (not a JSON mapping): delete it to write it back"
    found, expected = _flat(found), _flat(json.loads(settings_text(planned)))
    for name in sorted(set(found) | set(expected)):
        if found.get(name, "absent") != expected.get(name, "absent"):
            return (f"{path} holds {name} {found.get(name, 'absent')}, but its folder's key names"
                    f" {name} {expected.get(name, 'absent')}: it was changed after planning; delete it to write it"
                    " back, or change the configuration to make a run of other settings")
    return None


#: the settings rules' command: the text to a temporary file, then renamed (never half-written)
WRITE_SETTINGS = "(printf '%s\\n' {params.text:q} > {output:q}.tmp && mv {output:q}.tmp {output:q}) 2> {log:q}"


class UnknownFolder(LookupError):
    """A folder whose key this study does not name: its settings are not in this configuration, so
    the file cannot be made again from it."""


class StudyPlan:
    """The packings, columns and runs of one (validated) configuration. Naming a run's file
    (run_path, runs, convergence_runs) registers its packing, column and run by key, so that the
    rules read their settings back (packing_of, column_of, run_of)."""

    def __init__(self, config):
        self.config = config
        #: a channel's study: its L0 takes r0's place (the folders' r0_ names it, h0 = a L0)
        self.channel = config.get("geometry", "cylinder") == "channel"
        self.r0 = float(config["channel_length"] if self.channel else config["r0"])
        self.aspect_ratios = [float(a) for a in config["aspect_ratios"]]
        self.mu_r = [float(m) for m in config["mu_r"]]
        self.seeds = list(config["seeds"])
        self.pack_aspect_ratio = float(config["pack_aspect_ratio"] or max(config["aspect_ratios"]))
        self.friction_law = config["friction_law"]
        #: (steps, end time) of the study's own runs
        self.length = (int(config["collapse"]["steps"]), float(config["collapse"]["duration"]))
        self.to_rest = config["collapse"]["max_duration"] is not None
        self.study_dir = study_dir(config)
        self.packings = {}   # key -> packing settings, of every packing this study names
        self.columns = {}    # (packing key, a as in its folder) -> a, of every column this study names
        self.runs = {}       # key -> collapse settings, of every run this study names

    # -- packings

    def footprint(self, r0: float):
        """What a packing of this study named r0 fills: the cylinder of radius r0, or in a channel's
        study the box of length r0 (L0) and the study's channel_width (colsim.stages.pour_geometry)."""
        return Channel(float(r0), float(self.config["channel_width"])) if self.channel else float(r0)

    def pack_height(self, r0: float, seed: int) -> float:
        """Height (length) the packing of radius r0 and seed `seed` must exceed: pack_aspect_ratio
        (or the largest a) times r0. A packing only the convergence study uses (another r0, or a seed
        outside `seeds`) is packed just tall enough for its sub-study's (largest) aspect ratio."""
        r0, seed = float(r0), int(seed)
        study = self.config.get("convergence")
        sizes = [entry["aspect_ratio"] for entry in (study or {}).get("column_size", [])
                 if r0 != self.r0 and r0 in [float(size) for size in entry["r0"]]]
        if sizes:
            return max(sizes) * r0
        if study and seed not in self.seeds:   # tall enough for every sub-study using the seed
            needs = [study["seeds"]["aspect_ratio"]] if seed in study["seeds"]["seeds"] else []
            needs += study["time_step"]["aspect_ratios"] if seed in study["time_step"].get("seeds", []) else []
            return max(needs or [self.pack_aspect_ratio]) * r0
        return self.pack_aspect_ratio * r0

    def packing_settings(self, r0: float, seed: int) -> dict:
        """Everything `colsim pack` is given for the packing of (r0, seed): its identity, the pack
        section's settings under "pack" (as the configuration writes them), the others at the top."""
        config = self.config
        not_identity = NOT_IDENTITY if config["pack"]["layer_height"] is not None else ONE_CLOUD_NOT_IDENTITY
        given = {"seed": seed, "height": self.pack_height(r0, seed)}
        if self.channel:   # r0 (L0 here) is the channel's length, and the cylinder's radius has no part
            given["channel_length"], not_identity = r0, not_identity + ("r0",)
        else:
            given["r0"] = r0
        own, top = configured(config, "pack", given, not_identity)
        return {**top, "pack": {key: config["pack"][key] for key in own}}

    def packing_key(self, r0: float, seed: int) -> str:
        """The key of the packing of (r0, seed) under this study's settings (registered)."""
        settings = self.packing_settings(r0, seed)
        key = settings_key(settings)
        self.packings[key] = settings
        return key

    def packing_dir(self, r0: float, seed: int) -> str:
        """The folder of the packing of (r0, seed) under this study's settings (registered)."""
        return PACKING_DIR.format(r0=fmt(r0), seed=seed, packing=self.packing_key(r0, seed))

    # -- runs

    def goes_to_rest(self, steps: int, duration: float) -> bool:
        """Whether a run of these steps and end time goes on to rest: only the study's own runs, and
        only when the study sets max_duration; a convergence run of other steps or end time stops."""
        return self.to_rest and (steps, duration) == self.length

    def run_settings(self, mu_r: float, steps: int, duration: float, law: str) -> dict:
        """Everything `colsim collapse` is given for one run of a column (its identity, with the column)."""
        given = {"mu_r": mu_r, "steps": steps, "duration": duration, "friction_law": law}
        own, top = configured(self.config, "collapse", given)
        settings = {**own, **top}
        rest = {key: settings.pop(key) for key in REST_SETTINGS if key in settings}
        settings["rest"] = rest if self.goes_to_rest(steps, duration) else None
        if law != "coulomb":   # only the Coulomb law's fixed point has a tolerance
            settings["friction_tolerance"] = None
        return settings

    def run_path(self, name: str, r0: float, seed: int, a: float, mu_r: float,
                 steps=None, duration=None, law=None) -> str:
        """Path of file `name` of one run (steps and end time: the study's unless given; a run of the
        study's own length goes on to rest if the study does, any other stops at its end time; the
        friction law: the study's unless given). Its packing, column and run are registered.
        "analysis.nc" names the run's analysis under the study's analysis settings (:data:`ANALYSIS`)."""
        steps = self.length[0] if steps is None else int(steps)
        duration = self.length[1] if duration is None else float(duration)
        settings = self.run_settings(mu_r, steps, duration, law or self.friction_law)
        key = settings_key(settings)
        self.runs[key] = settings
        packing = self.packing_key(r0, seed)
        self.columns[(packing, fmt(a))] = float(a)
        if name == "analysis.nc":   # the analysis under this study's analysis settings
            name = f"analysis_{settings_key(self.analysis_settings())}.nc"
        return (PACKING_DIR.format(r0=fmt(r0), seed=seed, packing=packing)
                + f"/a_{fmt(a)}/mu_r_{fmt(mu_r)}/run_{key}/{name}")

    def study_runs(self, name: str, mu_r=None, seeds=None, law=None) -> list[str]:
        """Paths of one file `name` of every run of the study (optionally one mu_r, some seeds,
        another friction law than the study's)."""
        return [self.run_path(name, self.r0, seed, a, m, law=law or self.friction_law)
                for seed in seeds or self.seeds for a in self.aspect_ratios
                for m in (self.mu_r if mu_r is None else [mu_r])]

    def calibration_runs(self, name: str) -> list[str]:
        """Paths of file `name` of every run of the mu_r calibration (config key calibration; none
        without one): each r0 and seed of it, each of the study's aspect ratios and mu_r."""
        study = self.config.get("calibration")
        if not study:
            return []
        return [self.run_path(name, r0, seed, a, m) for r0 in study["r0"]
                for seed in study.get("seeds") or self.seeds for a in self.aspect_ratios for m in self.mu_r]

    def side_view_mu_r(self) -> float:
        """The swept mu_r nearest to figures.side_view_mu_r."""
        target = self.config["figures"]["side_view_mu_r"]
        return min(self.mu_r, key=lambda m: abs(m - target))

    def convergence_runs(self, name: str) -> dict:
        """{sub-study: [paths of file `name`]} of the convergence study (empty without one)."""
        study = self.config.get("convergence")
        if not study:
            return {}
        mu_r, seed, (steps, end) = study["mu_r"], self.seeds[0], self.length
        longer = study["end_time"]["duration"]

        def same_dt(duration):
            """(steps, end time) of a run to `duration` at the study's dt."""
            return round(steps * duration / end), duration

        run_path = self.run_path
        return {
            "time_step": [run_path(name, self.r0, s, a, mu_r, n, end)
                          for a in study["time_step"]["aspect_ratios"] for n in study["time_step"]["steps"]
                          for s in study["time_step"].get("seeds", [seed])],
            "end_time": [run_path(name, self.r0, seed, a, mu_r, *same_dt(longer))
                         for a in study["end_time"]["aspect_ratios"]],
            "column_size": [run_path(name, r0, s, entry["aspect_ratio"], mu_r, *same_dt(entry.get("duration", end)))
                            for entry in study["column_size"] for r0 in entry["r0"]
                            for s in entry.get("seeds", [seed])],
            "seeds": [run_path(name, self.r0, s, study["seeds"]["aspect_ratio"], mu_r)
                      for s in study["seeds"]["seeds"]],
        }

    # -- the study's own products

    def convergence_outputs(self) -> list[str]:
        """The convergence study's products, or none."""
        if not self.config.get("convergence"):
            return []
        where = self.study_dir
        return [f"{where}/convergence.nc", f"{where}/convergence.md", f"{where}/figures/convergence.png",
                f"{where}/column_size_limits.nc", f"{where}/figures/column_size_limits.png"]

    def calibration_outputs(self) -> list[str]:
        """The mu_r calibration's products (config key calibration), or none; a channel study's, its
        run-outs' convergence in the box length."""
        if not self.config.get("calibration"):
            return []
        where = self.study_dir
        if self.config.get("geometry") == "channel":   # the run-outs' convergence in the box length
            return [f"{where}/length_convergence.nc", f"{where}/length_convergence.md"]
        return [f"{where}/calibration.nc", f"{where}/calibration.md", f"{where}/figures/calibration.png"]

    def friction_law_outputs(self) -> list[str]:
        """The friction-law comparison's products (friction_law_comparison: true), or none."""
        if not self.config["friction_law_comparison"]:
            return []
        where = self.study_dir
        return [f"{where}/friction_law.nc", f"{where}/friction_law.md", f"{where}/figures/friction_law.png"]

    # -- the analyses' settings

    def analysis_settings(self) -> dict:
        """Everything `colsim analyse` is given besides its run: the study's analysis settings."""
        own, top = configured(self.config, "analyse", {})
        return {**top, **own}

    def analysis_settings_of(self, wildcards) -> dict:
        """This study's analysis settings, if {analysis} is their key; an UnknownFolder otherwise."""
        settings = self.analysis_settings()
        if wildcards.analysis != settings_key(settings):
            raise UnknownFolder(f"analysis settings {wildcards.analysis} are not this study's")
        return settings

    # -- a folder's settings, from its key

    def packing_of(self, wildcards) -> dict:
        """The settings of the packing that {packing} names (wildcards: r0, seed, packing, as in
        its folder); a key this study does not name is an UnknownFolder."""
        settings = self.packings.get(wildcards.packing)
        length = None if settings is None else settings["channel_length" if self.channel else "r0"]
        if settings is None or fmt(length) != wildcards.r0 or str(settings["seed"]) != wildcards.seed:
            raise UnknownFolder(f"no packing of this study has the folder r0_{wildcards.r0}/seed_{wildcards.seed}/"
                                f"pack_{wildcards.packing}: its settings.yaml says what made it")
        return settings

    def column_of(self, wildcards) -> float:
        """The aspect ratio of the column that {a} names below the packing {packing}."""
        a = self.columns.get((wildcards.packing, wildcards.a))
        if a is None:
            raise UnknownFolder(f"no column of this study has the folder pack_{wildcards.packing}/a_{wildcards.a}")
        return a

    def run_of(self, wildcards) -> dict:
        """The settings of the run that {run} names (wildcards: mu_r, run); an UnknownFolder for a
        key this study does not name."""
        settings = self.runs.get(wildcards.run)
        if settings is None or fmt(settings["mu_r"]) != wildcards.mu_r:
            raise UnknownFolder(f"no run of this study has the folder mu_r_{wildcards.mu_r}/run_{wildcards.run}:"
                                " its settings.yaml says what made it")
        return settings
