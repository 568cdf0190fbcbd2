"""The contract between the stepper and a solver of one step's cone program.

A back-end (:mod:`colsim.solvers`) subclasses :class:`Solver`: `solve` returns a
:class:`ConeSolution` or raises :class:`SolverError`, never an unconverged result. The engine calls
it through this contract alone, so the engine imports no back-end.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .program import ROWS_PER_CONTACT, ConeProgram

#: a contact is active when its normal force exceeds this fraction of the largest one
ACTIVE_FRACTION = 1e-8


@dataclass
class ConeSolution:
    """increments: (6n,) u = [dx; dth]; forces: (m, 5) (p, q1, q2, r1, r2), force units.
    setup_time, solve_time: seconds; info: the back-end's residuals and counters; backend: the
    name of the back-end that solved it, where a solver delegates (''; the solver's own name)."""

    increments: np.ndarray
    forces: np.ndarray
    status: str
    iterations: int
    setup_time: float
    solve_time: float
    info: dict = field(default_factory=dict)
    backend: str = ""

    def resident_forces(self):
        """The forces (m, 5) where the solver left them: here, the host's array (a solution made on a
        GPU gives its device array, :class:`colsim.engine.cuda_apgd.DeviceSolution`)."""
        return self.forces

    def resident_increments(self):
        """The increments (6n,) where the solver left them: here, the host's array (see
        :meth:`resident_forces`)."""
        return self.increments

    def active_contacts(self) -> int:
        """Contacts carrying a normal force above ACTIVE_FRACTION of the largest one."""
        if len(self.forces) == 0:
            return 0
        p = self.forces[:, 0]
        return int(np.count_nonzero(p > ACTIVE_FRACTION * max(float(p.max()), 0.0)))


class SolverError(RuntimeError):
    """A cone program that was not solved to tolerance."""

    def __init__(self, message: str, status: str = "", step: int | None = None, residuals=None):
        self.status = status
        self.step = step
        self.residuals = residuals or {}
        super().__init__(message)


def at_step(step: int | None) -> str:
    """' at step N' for an error message, or '' when the step is not known."""
    return f" at step {step}" if step is not None else ""


class Solver:
    """A back-end: `solve(program, warm_start=None, step=None) -> ConeSolution`.

    warm_start: forces (m, 5) aligned with the program's contacts, or None.
    step: the step number, for error messages."""

    name = "base"
    #: whether solve() uses `warm_start` (the stepper then passes the previous step's forces)
    uses_warm_start = False

    def solve(self, program: ConeProgram, warm_start: np.ndarray | None = None,
              step: int | None = None) -> ConeSolution:
        raise NotImplementedError

    def describe(self) -> dict:
        """The back-end's name and settings (JSON-able), for output attributes and checkpoints."""
        settings = {k: v for k, v in vars(self).items() if isinstance(v, (bool, int, float, str))}
        return {"name": self.name, **settings}

    @staticmethod
    def no_contacts(program: ConeProgram) -> ConeSolution:
        """The solution of a program without contacts: free motion."""
        return ConeSolution(program.free_motion(), np.zeros((0, ROWS_PER_CONTACT)), "Solved", 0, 0.0, 0.0)
