"""The back-ends by name and the automatic choice between them.

Every back-end solves a step's :class:`~colsim.engine.program.ConeProgram` behind the engine's
contract (:mod:`colsim.engine.solver_contract`) and returns a ConeSolution: the increments u (6n,)
and the contact forces (m, 5) = (p, q1, q2, r1, r2). A back-end that does not reach its tolerance
raises SolverError; it never returns an unconverged result. The stepper sees only the contract.
"""
from __future__ import annotations

import logging


from ..engine.solver_contract import ConeSolution, Solver, SolverError, at_step
from ..engine.warm_start import WarmStart
from . import defaults
from .admm import AdmmSolver
from .apgd import ApgdSolver
from .clarabel import ClarabelSolver

__all__ = ["SOLVERS", "AdmmSolver", "ApgdSolver", "AutoSolver", "ClarabelSolver", "ConeSolution",
           "Solver", "SolverError", "WarmStart", "at_step", "make_solver"]

SOLVERS = defaults.SOLVERS

log = logging.getLogger(__name__)


def make_solver(name: str = "clarabel", **options) -> Solver:
    """A back-end by name (one of SOLVERS): 'clarabel' (displacement form), 'clarabel-force',
    'apgd' (first-order, :mod:`colsim.solvers.apgd`), 'admm' (operator splitting on the displacement form,
    :mod:`colsim.solvers.admm`) or 'auto' (:class:`AutoSolver`)."""
    makers = {"clarabel": ClarabelSolver, "clarabel-force": lambda **o: ClarabelSolver(form="force", **o),
              "apgd": ApgdSolver, "admm": AdmmSolver, "auto": AutoSolver}
    if name not in makers:
        raise ValueError(f"unknown solver {name!r}: choose one of {', '.join(SOLVERS)}")
    return makers[name](**options)


class AutoSolver(Solver):
    """APGD where it is the faster back-end, Clarabel elsewhere, decided step by step.

    The rule: APGD solves a step when the stage's time step dt / sqrt(h0/g), `scaled_time_step`,
    is at most `apgd_below`, from the warm start where there is one (the previous step's forces,
    or the packing's at the first step of a collapse) and from zero forces where there is none (a
    cold step: a column that comes without its packing's forces, the first contacts of a pour).
    APGD then has `max_iter` iterations; a step that reaches them is solved again by Clarabel.
    Larger steps go to Clarabel. The solution's `backend` says which back-end solved the step:
    'apgd', 'clarabel', 'clarabel-fallback' (APGD reached its cap), or 'apgd-float64-fallback' (APGD
    with float32 storage reached its cap, and then solved the step in float64).

    Why APGD up to the paper's step and no further, why cold steps too, and why the cap: the
    measurements are in docs/solvers.md ("Why APGD, and where: the auto rule").

    scaled_time_step: None when the stage has no such scale (then only the warm start decides).
    apgd, clarabel: options of the two back-ends (:class:`ApgdSolver`, :class:`ClarabelSolver`).
    """

    name = "auto"
    uses_warm_start = True
    #: APGD's settings under auto: :mod:`colsim.solvers.defaults`
    APGD_TOLERANCE = defaults.AUTO_APGD_TOLERANCE
    APGD_LENGTH_FLOOR = defaults.AUTO_APGD_LENGTH_FLOOR
    APGD_OVERLAP_TOLERANCE = defaults.AUTO_APGD_OVERLAP_TOLERANCE

    def __init__(self, scaled_time_step: float | None = None, apgd_below: float = defaults.AUTO_APGD_BELOW,
                 max_iter: int = defaults.AUTO_MAX_ITER, clarabel: dict | None = None, apgd: dict | None = None):
        if max_iter < 1:
            raise ValueError(f"the APGD iteration cap must be >= 1, got {max_iter}")
        self.scaled_time_step = None if scaled_time_step is None else float(scaled_time_step)
        self.apgd_below = float(apgd_below)
        self.max_iter = int(max_iter)
        self.clarabel = ClarabelSolver(**(clarabel or {}))
        lengths = self.length_scale()
        self.apgd = ApgdSolver(**{"max_iter": self.max_iter, "tolerance": self.APGD_TOLERANCE,
                                  "length_floor": lengths * self.APGD_LENGTH_FLOOR,
                                  "overlap_tolerance": lengths * self.APGD_OVERLAP_TOLERANCE, **(apgd or {})})

    def length_scale(self) -> float:
        """The factor on APGD's length floor and overlap tolerance: 1 at steps of at least
        defaults.AUTO_APGD_LENGTHS_AT, the step over it below (so they bound a velocity error)."""
        if self.scaled_time_step is None:
            return 1.0
        return min(1.0, self.scaled_time_step / defaults.AUTO_APGD_LENGTHS_AT)

    def describe(self) -> dict:
        # which back-end solved each step is the trajectory's step_solver_backend, not a setting:
        # both solve the same program to their tolerances
        return {**super().describe(), "apgd": self.apgd.describe(), "clarabel": self.clarabel.describe()}

    def apgd_allowed(self) -> bool:
        """Whether the time step is small enough for APGD (the first half of the rule)."""
        return self.scaled_time_step is None or self.scaled_time_step <= self.apgd_below * (1 + 1e-9)

    def solve(self, program, warm_start=None, step=None):
        if not self.apgd_allowed():
            return _by(self.clarabel, self.clarabel.solve(program, step=step))
        try:
            return _by(self.apgd, self.apgd.solve(program, warm_start=warm_start, step=step))
        except SolverError as error:
            log.info("%s; solving this step with Clarabel", error)
            solution = self.clarabel.solve(program, step=step)
            solution.backend = "clarabel-fallback"
            solution.info["apgd_iterations"] = self.apgd.max_iter
            return solution


def _by(solver: Solver, solution: ConeSolution) -> ConeSolution:
    solution.backend = solution.backend or solver.name   # kept where the back-end named its own fallback
    return solution
