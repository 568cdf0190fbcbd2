"""The values and options of the workflow's `colsim` command lines and its jobs' cluster resources,
from a packing's or a run's settings (plan.py): a value is formatted once, here, as it appears on
the command line, and never read back from a folder's name."""
from __future__ import annotations

from .plan import fmt


def numbers(values) -> str:
    """A list option's values, each without loss (fmt): [0.1, 0.5, 1.0] -> '0.1 0.5 1'."""
    return " ".join(fmt(value) for value in values)


def collapse_options(run: dict) -> str:
    """What follows --mu-r on a run's collapse command line, from its settings: the rolling lever,
    the friction law (and a Coulomb run's fixed-point tolerance), steps, end time, frames, the rest
    options, the solver (and its overlap tolerance when the study sets one)."""
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


def collapse_runtime(run: dict, study_length: tuple[int, float]) -> int:
    """A collapse's time limit on a cluster (minutes; SLURM's runtime), from its settings and the
    study's (steps, end time), by config/paper.yaml's measured jobs (r0 = 4,
    docs/validation/paper-scale.md): 623 s to rest at a = 5 and 773 s at mu_r = 0
    (t/sqrt(h0/g) = 12), so 120 at the study's length; 300 for more steps or a later end (a
    convergence study's 2,000 steps cost twice); 1440 under the Coulomb law (8-18x the CPU). A
    collapse that runs out of time resumes from its checkpoint (the profile's retries)."""
    if run["friction_law"] == "coulomb":
        return 1440
    longer = run["steps"] > study_length[0] or run["duration"] > study_length[1]
    return 300 if longer else 120


def collapse_priority(a: float, run: dict, study_length: tuple[int, float]) -> int:
    """Scheduling priority of the collapse of a column of aspect ratio `a`: 10 a (times its steps
    over the study's), so that the costliest columns run first."""
    return int(round(10 * a * run["steps"] / study_length[0]))
