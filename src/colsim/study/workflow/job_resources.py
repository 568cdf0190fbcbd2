"""A workflow job's cluster resources (time limit, memory) and scheduling priority, from a packing's
or a run's settings (plan.py) and about how many spheres it holds."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ...solvers.defaults import GPU_FROM_SPHERES


#: Cluster sizing by the column's spheres: reference sizes, times, growth exponents and memory of
#: measured one-thread jobs, doubled for slower cores (docs/slurm.md, "Resources", which gives the
#: measurements and why the requests still cover the column-size study's larger columns). A job that
#: runs out of time resumes from its checkpoint (the SLURM profile's retries); none asks for more than
#: LONGEST_RUNTIME.
COLLAPSE_REFERENCE_SPHERES, COLLAPSE_GROWTH = 20_400, 1.43
PACK_REFERENCE_SPHERES, PACK_REFERENCE_S, PACK_GROWTH = 22_000, 2_190.0, 2.0
PACK_MB_PER_SPHERE = 2 * 1_561 / 22_330
SLOWER_CORES = 2.0
LONGEST_RUNTIME = 2880   # minutes: 48 hours, a common partition's limit


def collapse_runtime(run: dict, study_length: tuple[int, float], spheres: float = 0.0) -> int:
    """A collapse's time limit on a cluster (minutes; SLURM's runtime), from its settings, the
    study's (steps, end time) and about how many spheres its column holds: 120 at the study's
    length; 300 for more steps or a later end; 1440 under the Coulomb law; each times
    (spheres / COLLAPSE_REFERENCE_SPHERES)^COLLAPSE_GROWTH for a larger column than the reference,
    at most LONGEST_RUNTIME (docs/slurm.md gives the measured jobs behind these). A collapse that
    runs out of time resumes from its checkpoint (the profile's retries)."""
    if run["friction_law"] == "coulomb":
        base = 1440
    else:
        longer = run["steps"] > study_length[0] or run["duration"] > study_length[1]
        base = 300 if longer else 120
    larger = max(1.0, spheres / COLLAPSE_REFERENCE_SPHERES) ** COLLAPSE_GROWTH
    return min(LONGEST_RUNTIME, int(np.ceil(base * larger)))


def spheres_of(r0, height: float, diameter_range) -> float:
    """About how many spheres a pour of radius r0 (or a channel's box, the footprint r0:
    colsim.stages.pour_geometry.Channel) to `height` (lengths) holds: the pack stage's own count of
    its cloud (imported here, when a job's resources are asked for)."""
    from colsim.stages.pour_geometry import Channel, expected_spheres

    return float(expected_spheres(r0 if isinstance(r0, Channel) else float(r0), float(height), diameter_range))


def pack_resources(spheres: float) -> dict:
    """A packing's time limit (minutes) and memory (MB) on a cluster for a pour of about `spheres`
    (colsim.stages.pour_geometry.expected_spheres): twice the reference pour's time grown as
    N^PACK_GROWTH, at least 120 minutes and at most LONGEST_RUNTIME; twice its memory a sphere, at
    least 4,000 MB (docs/slurm.md gives the reference and the requests of r0 = 4-8)."""
    seconds = SLOWER_CORES * PACK_REFERENCE_S * (spheres / PACK_REFERENCE_SPHERES) ** PACK_GROWTH
    runtime = min(LONGEST_RUNTIME, max(120, int(np.ceil(seconds / 60))))
    return {"runtime": runtime, "mem_mb": max(4000, int(np.ceil(PACK_MB_PER_SPHERE * spheres)))}


#: Scheduling priorities (Snakemake runs the ready job of highest priority first): a settings file,
#: written in a moment, before the job it gates; a pour before any collapse, the largest first
#: (:func:`pack_priority`); an analysis as soon as it can; then collapses by cost
#: (:func:`collapse_priority`). Without them an r0 = 6 pour waited for its settings behind every
#: ready collapse, to run alone for hours at the end.
SETTINGS_PRIORITY = 10_000
PACK_PRIORITY = 1_000
#: an analysis (seconds) runs as soon as its collapse ends, before the next collapse: a long study's
#: results can be read, and calibrated, as they come in, not only once every collapse is done
ANALYSIS_PRIORITY = 900


def pack_priority(spheres: float) -> int:
    """A pour's scheduling priority: PACK_PRIORITY plus its spheres in thousands (the longest job
    first), below SETTINGS_PRIORITY up to 9 million spheres."""
    return PACK_PRIORITY + int(spheres // 1_000)


def collapse_priority(a: float, run: dict, study_length: tuple[int, float]) -> int:
    """Scheduling priority of the collapse of a column of aspect ratio `a`: 10 a (times its steps
    over the study's), so that the costliest columns run first."""
    return int(round(10 * a * run["steps"] / study_length[0]))


#: present where the machine has an NVIDIA GPU and its driver (read without loading numba: planning stays light)
NVIDIA_CONTROL = Path("/dev/nvidiactl")


def gpus_a_job(device: str, spheres: float) -> int:
    """GPUs a pour or a collapse of about `spheres` spheres asks for: 1 on device cuda; on auto, 1
    when it is large enough for auto to take a GPU (GPU_FROM_SPHERES) and the machine planning the
    study has one; else 0."""
    if device == "cuda":
        return 1
    return int(device == "auto" and spheres >= GPU_FROM_SPHERES and NVIDIA_CONTROL.exists())
