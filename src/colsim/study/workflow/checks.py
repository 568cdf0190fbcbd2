"""The configuration's checks beyond Snakemake's validation: one line naming the first key or value
the schema rejects, an alias bomb, a NaN or an infinity, and settings that contradict each other.
Each returns that line, or None when the configuration passes."""
from __future__ import annotations

import math
import os
import re

import jsonschema
import yaml

from ...solvers.defaults import DEFAULT_GPU_STORAGE
from ...stages.settings import POUR_STEP_RANGE, SMALLEST_SCALED_STEP, check_geometry
from ...stages.pour_geometry import Channel, expected_spheres

#: far above any study's configuration (the default has about 100)
CONFIG_MAX_ITEMS = 100_000


def load_schema(path) -> dict:
    """The configuration schema (YAML) at `path`, as a tree."""
    with open(path) as stream:
        return yaml.safe_load(stream)


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


#: the largest magnitude a setting may have: far beyond any study, far within a float's range, so
#: that products of settings (a step count, a volume) stay finite
LARGEST_SETTING = 1e12


def non_finite_number(tree, where=""):
    """The dotted key of the first number in the configuration that is NaN, infinite or beyond
    LARGEST_SETTING in magnitude (a 400-digit integer overflows a float), or None (the schema's
    minimum and maximum let NaN through). Seeds have their own bound (0..2^32-1, the schema's)."""
    if isinstance(tree, dict):
        items = tree.items()
    elif isinstance(tree, list):
        items = enumerate(tree)
    elif isinstance(tree, bool) or not isinstance(tree, (int, float)) or "seed" in where:
        return None
    else:
        try:
            return None if math.isfinite(float(tree)) and abs(float(tree)) <= LARGEST_SETTING else where
        except OverflowError:
            return where
    for key, value in items:
        found = non_finite_number(value, f"{where}.{key}" if where else str(key))
        if found is not None:
            return found
    return None


def before_validation(config, schema):
    """The first problem the configuration as given has (its size, then the schema's), or None;
    the checks that need the schema's defaults filled in are cross_field_problem's."""
    return size_problem(config) or schema_problem(config, schema)


def cross_field_problem(config):
    """One line naming the first pair of settings that contradict each other, or None (on a
    configuration whose defaults the schema has filled in)."""

    bad = non_finite_number(config)
    if bad is not None:
        return f"config: {bad}: must be a finite number of magnitude at most {LARGEST_SETTING:g}"
    if not re.fullmatch(r"[A-Za-z0-9_-]*", config["study"]):
        return f"config: study: {config['study']!r} may hold only letters, digits, _ and -"
    d_min, d_max, r0 = config["diameter_min"], config["diameter_max"], config["r0"]
    if d_min > d_max:
        return f"config: diameter_min {d_min} exceeds diameter_max {d_max}"
    problem = geometry_problem(config)
    if problem:
        return problem
    channel = config["geometry"] == "channel"
    if channel:   # L0 in r0's place
        r0 = config["channel_length"]
    elif r0 < d_max:
        return f"config: r0 {r0} is below diameter_max {d_max}: the largest particle does not fit in the cylinder"
    columns = [(a, r0) for a in config["aspect_ratios"]]
    study = config.get("convergence") or {}
    columns += [(entry["aspect_ratio"], r) for entry in study.get("column_size", []) for r in entry["r0"]]
    columns += [(a, r0) for a in study.get("time_step", {}).get("aspect_ratios", [])]
    columns += [(a, r0) for a in study.get("end_time", {}).get("aspect_ratios", [])]
    columns += [(study["seeds"]["aspect_ratio"], r0)] if "seeds" in study else []
    calibration = config.get("calibration") or {}
    columns += [(a, r) for r in calibration.get("r0", []) for a in config["aspect_ratios"]]
    for a, radius in columns:
        if radius < d_max and not channel:
            return f"config: convergence r0 {radius} is below diameter_max {d_max}"
        if a * radius < d_max:
            return (f"config: aspect ratio {a} at r0 {radius} gives h0 = {a * radius:g}, below diameter_max {d_max}:"
                    f" the column would hold less than one layer of particles (diameters {d_min}-{d_max})")
    problem = time_problem(config) or solver_problem(config)
    if problem:
        return problem
    calibrated = config.get("calibration") and config.get("geometry", "cylinder") == "cylinder"   # a channel's: its L0
    if calibrated and len(set(config["mu_r"])) < 2:
        return (f"config: the calibration finds the best mu_r between the swept ones and needs two or more;"
                f" mu_r holds {len(set(config['mu_r']))}")
    if config["friction_law"] != "associated" and config["friction_law_comparison"]:
        return "config: friction_law_comparison needs friction_law: associated (it adds the coulomb runs itself)"
    if config["friction_law"] != "associated" and config.get("convergence"):
        return "config: the convergence study runs the associated law only; leave out convergence with friction_law: coulomb"
    pack = config["pack_aspect_ratio"]
    if pack is not None and pack < max(config["aspect_ratios"]):
        return f"config: pack_aspect_ratio {pack} is below the largest aspect ratio {max(config['aspect_ratios'])}"
    limit = config["pack"]["max_spheres"]
    for a, radius in [(pack or max(config["aspect_ratios"]), r0)] + columns:
        spheres = expected_spheres(Channel(radius, config["channel_width"]) if channel else radius, a * radius,
                                   (d_min, d_max))
        if spheres > limit:
            return (f"config: a packing of r0 {radius:g} for a = {a:g} would hold about {spheres:,.0f} spheres,"
                    f" above pack.max_spheres {limit:,} (raise it if the machine has the memory)")
    return None


def geometry_problem(config):
    """One line naming the first channel setting the study's geometry cannot take (a channel's length
    or width with geometry cylinder, a channel without them, a width below diameter_max, wall_mu on a
    cylinder), or None (colsim.stages.settings.check_geometry, the stages' own check)."""
    try:
        check_geometry(config["geometry"], config["channel_length"], config["channel_width"], config["diameter_max"])
    except ValueError as error:
        return f"config: {error}"
    if config["geometry"] == "cylinder" and config["wall_mu"] is not None:
        return "config: wall_mu is the friction of a channel's walls, but geometry is cylinder (set geometry: channel)"
    return None


def link_out_of(folder):
    """One line naming the first symbolic link below `folder` (results/) whose target lies outside
    it, or None: Snakemake writes logs and benchmarks through such a link into the file it points
    to, so a link planted there would have a study overwrite a file elsewhere. The
    folder itself may be a link (to scratch storage, say)."""
    if not os.path.isdir(folder):
        return None
    root = os.path.realpath(folder)
    for here, folders, files in os.walk(folder):
        for name in folders + files:
            path = os.path.join(here, name)
            if os.path.islink(path):
                target = os.path.realpath(path)
                if os.path.commonpath([root, target]) != root:
                    return (f"{path} is a link to {target}, outside {folder}/: the study would write through it;"
                            " remove the link")
    return None


def time_problem(config):
    """One line if the study's times contradict each other or the physics, or None: the collapse's
    end time beyond its max_duration, a convergence run that rounds to no step, a pour step out of
    POUR_STEP_RANGE of the fall time across a diameter."""
    collapse = config["collapse"]
    if collapse["max_duration"] is not None and collapse["duration"] > collapse["max_duration"]:
        return (f"config: collapse.duration {collapse['duration']:g} exceeds collapse.max_duration"
                f" {collapse['max_duration']:g}: the run would stop before its end time")
    steps, end = collapse["steps"], collapse["duration"]
    study = config.get("convergence") or {}
    durations = [("convergence.end_time.duration", study.get("end_time", {}).get("duration"))]
    durations += [(f"convergence.column_size.{k}.duration", entry.get("duration"))
                  for k, entry in enumerate(study.get("column_size", []))]
    for key, duration in durations:
        if duration is not None and round(steps * duration / end) < 1:
            return (f"config: {key} {duration:g} at the study's step (collapse.duration / collapse.steps ="
                    f" {end / steps:g}) rounds to no step")
    for key, n in [("collapse.steps", steps)] + [("convergence.time_step.steps", n)
                                                 for n in study.get("time_step", {}).get("steps", [])]:
        if n < 1:
            return f"config: {key} {n}: a run needs at least one step"
        if end / n < SMALLEST_SCALED_STEP:
            return (f"config: {key} {n} over collapse.duration {end:g} makes a step dt/sqrt(h0/g) of {end / n:.3g},"
                    f" below {SMALLEST_SCALED_STEP:g}: too small for a step's arithmetic")
    scaled = config["pack"]["dt"] * math.sqrt(config["gravity"] / config["diameter_min"])
    low, high = POUR_STEP_RANGE
    if not low <= scaled <= high:
        return (f"config: pack.dt {config['pack']['dt']:g} is {scaled:.3g} times sqrt(diameter_min / gravity),"
                f" the time to fall about a diameter; it must lie within {low:g}-{high:g} (the default is 0.125)")
    return None


#: the back-ends that APGD's options (a device, a GPU storage, the overlap tolerance) reach
APGD_SOLVERS = ("auto", "apgd")


def solver_problem(config):
    """One line if the solver's settings contradict each other, or None: APGD's options (device cuda,
    a GPU storage, solver_overlap_tolerance) given to another back-end, which would ignore them, and
    a GPU storage on the CPU, which stores float64 (the pour's and the collapse's own refusals)."""
    solver, device, storage = config["solver"], config["device"], config["gpu_storage"]
    if solver not in APGD_SOLVERS:
        given = ["device cuda"] if device == "cuda" else []
        given += [f"gpu_storage {storage}"] if storage != DEFAULT_GPU_STORAGE else []
        if config.get("solver_overlap_tolerance") is not None:
            given.append(f"solver_overlap_tolerance {config['solver_overlap_tolerance']:g}")
        if given:
            return (f"config: {' and '.join(given)} {'are' if len(given) > 1 else 'is'} APGD's (solver auto or"
                    f" apgd); solver {solver} would ignore it")
    if device == "cpu" and storage != DEFAULT_GPU_STORAGE:
        return (f"config: gpu_storage {storage} is a GPU's storage, and device is cpu, which stores"
                f" {DEFAULT_GPU_STORAGE}: use device cuda (or auto), or leave gpu_storage out")
    return None


class _NoDuplicateKeys(yaml.SafeLoader):
    """A YAML loader that refuses a key given twice in one mapping (PyYAML keeps the later silently)."""


def _mapping(loader, node, deep=False):
    keys = set()
    for key_node, _ in node.value:
        key = loader.construct_object(key_node, deep=deep)
        if key in keys:
            raise yaml.constructor.ConstructorError(None, None, f"the key {key!r} is given twice",
                                                    key_node.start_mark)
        keys.add(key)
    return loader.construct_mapping(node, deep)


_NoDuplicateKeys.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _mapping)


def duplicate_key(paths):
    """One line naming the first configuration file (of `paths`) that gives a key twice in one
    mapping, with the line, or None."""
    for path in paths:
        try:
            with open(path) as stream:
                yaml.load(stream, Loader=_NoDuplicateKeys)
        except yaml.constructor.ConstructorError as error:
            if "given twice" in str(error.problem):
                mark = error.problem_mark
                return f"config: {path}, line {mark.line + 1}: {error.problem}; the later value would win silently"
        except (OSError, yaml.YAMLError):
            continue    # Snakemake has read it already and says what is wrong with it
    return None


def cuda_gpu_count() -> int:
    """The CUDA GPUs the NVIDIA driver sees here (0 without a driver), asked of libcuda directly as
    numba.cuda does (its NUMBA_CUDA_DRIVER, else libcuda.so.1 from the loader's path), without
    importing numba: planning a study stays quick."""
    import ctypes

    for library in filter(None, (os.environ.get("NUMBA_CUDA_DRIVER"), "libcuda.so.1", "libcuda.so")):
        try:
            driver = ctypes.CDLL(library)
        except OSError:
            continue
        count = ctypes.c_int(0)
        if driver.cuInit(0) != 0 or driver.cuDeviceGetCount(ctypes.byref(count)) != 0:
            return 0
        return count.value
    return 0


def device_problem(config, gpus=cuda_gpu_count):
    """One line when `device: cuda` is set and the jobs would run where no GPU is (their every
    pack and collapse would fail), or None. `gpus`: how many GPUs this machine has, asked only when
    needed (numba's CUDA simulator, a test tool, is no GPU here: a study is planned for real cards)."""
    if config["device"] != "cuda" or gpus() > 0:
        return None
    return ("config: device: cuda, but this machine has no CUDA GPU (no NVIDIA driver sees one): set device: cpu"
            " or auto, or run the study on a GPU node (--executor slurm)")
