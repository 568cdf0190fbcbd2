"""What a step reports (:class:`StepDiagnostics`) and hands to the next (:class:`Carry`): plain
records, read by the trajectory's file and the checkpoint without loading the engine's numerics."""
from __future__ import annotations

from dataclasses import dataclass

from .warm_start import WarmStart

#: diagnostics that are text, with their long names
TEXT_DIAGNOSTICS = {"solver_status": "solver status per step",
                    "solver_backend": "back-end that solved the step (apgd, clarabel, clarabel-fallback or "
                                      "apgd-float64-fallback)"}


@dataclass
class StepDiagnostics:
    """What one step reports. Times in seconds (wall clock); energies in mass length^2/time^2.

    The detection, assembly, matching (the warm start's forces matched to the contacts), setup, solve
    and check (the overlap check of the new positions, which makes the next step's first detection;
    a step that takes that detection spends almost no detection time) times are those of the
    accepted attempt; wall_time is the whole step, redone attempts included (matching and check: NaN
    in steps saved by a commit before they were timed). detection_margin: of the accepted attempt
    (length).
    solver_backend: the back-end that solved the accepted attempt (see :class:`colsim.solvers.AutoSolver`).
    solver_iterations: summed over the cone programs of the step; friction_iterations: how many
    cone programs the friction law solved (1, or the Coulomb fixed point's, :mod:`colsim.engine.friction`)."""

    step: int
    time: float
    n_contacts: int
    n_active: int
    largest_overlap: float
    kinetic_energy: float
    rotational_energy: float
    solver_status: str
    solver_backend: str
    solver_iterations: int
    friction_iterations: int
    detection_time: float
    assembly_time: float
    setup_time: float
    solve_time: float
    redone: int
    missed_contacts: int
    detection_margin: float
    wall_time: float
    matching_time: float = float("nan")
    check_time: float = float("nan")


@dataclass
class Carry:
    """What one step hands to the next: the contact forces by pair (None when the solver takes no
    warm start) and the detection margin to start from (length; None: :func:`base_margin`)."""

    warm_start: WarmStart | None = None
    margin: float | None = None
