"""The solver layer: the back-ends by name, warm starts across steps, and the automatic choice.

Every back-end solves a step's :class:`~colsim.program.ConeProgram` behind the contract of
:class:`~colsim.program.Solver` and returns a :class:`~colsim.program.ConeSolution`: the increments
u (6n,) and the contact forces (m, 5) = (p, q1, q2, r1, r2). A back-end that does not reach its
tolerance raises :class:`~colsim.program.SolverError`; it never returns an unconverged result.

Imports flow one way: program -> cones -> back-ends (clarabel, apgd, admm) -> solvers -> stepper.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from .admm import AdmmSolver
from .apgd import ApgdSolver
from .clarabel import ClarabelSolver
from .cones import project_coupled_cone
from .program import ROWS_PER_CONTACT, ConeSolution, Solver, SolverError, at_step

__all__ = ["SOLVERS", "AdmmSolver", "ApgdSolver", "AutoSolver", "ClarabelSolver", "ConeSolution",
           "Solver", "SolverError", "WarmStart", "at_step", "make_solver"]

#: the back-ends' names, as make_solver, the CLI and the config schema accept them
SOLVERS = ("clarabel", "clarabel-force", "apgd", "admm", "auto")

log = logging.getLogger(__name__)


@dataclass
class WarmStart:
    """A step's contact forces by pair key, in the global frame.

    keys: (m,) int64 (:meth:`colsim.contacts.Contacts.pair_keys`), sorted
    force: (m, 3) p n + q1 t1 + q2 t2; rolling: (m, 3) r1 t1 + r2 t2 (force units)
    """

    keys: np.ndarray
    force: np.ndarray
    rolling: np.ndarray

    @classmethod
    def from_step(cls, contacts, forces: np.ndarray, n_particles: int) -> "WarmStart":
        keys = contacts.pair_keys(n_particles)
        order = np.argsort(keys, kind="stable")
        f = (forces[:, :1] * contacts.normal + forces[:, 1:2] * contacts.tangent1
             + forces[:, 2:3] * contacts.tangent2)
        r = forces[:, 3:4] * contacts.tangent1 + forces[:, 4:5] * contacts.tangent2
        return cls(keys[order], f[order], r[order])

    def match(self, contacts, n_particles: int) -> np.ndarray:
        """(m, 5) the stored forces of the pairs in `contacts`, in their frames; zeros for new pairs."""
        keys = contacts.pair_keys(n_particles)
        out = np.zeros((contacts.m, ROWS_PER_CONTACT))
        if len(self.keys) == 0 or contacts.m == 0:
            return out
        pos = np.clip(np.searchsorted(self.keys, keys), 0, len(self.keys) - 1)
        found = self.keys[pos] == keys
        f, r = self.force[pos[found]], self.rolling[pos[found]]
        n, t1, t2 = contacts.normal[found], contacts.tangent1[found], contacts.tangent2[found]
        out[found, 0] = np.einsum("ij,ij->i", f, n)
        out[found, 1] = np.einsum("ij,ij->i", f, t1)
        out[found, 2] = np.einsum("ij,ij->i", f, t2)
        out[found, 3] = np.einsum("ij,ij->i", r, t1)
        out[found, 4] = np.einsum("ij,ij->i", r, t2)
        return project_coupled_cone(out, contacts.mu, contacts.mu_r)


def make_solver(name: str = "clarabel", **options) -> Solver:
    """A back-end by name (one of SOLVERS): 'clarabel' (displacement form), 'clarabel-force',
    'apgd' (first-order, :mod:`colsim.apgd`), 'admm' (operator splitting on the displacement form,
    :mod:`colsim.admm`) or 'auto' (:class:`AutoSolver`)."""
    makers = {"clarabel": ClarabelSolver, "clarabel-force": lambda **o: ClarabelSolver(form="force", **o),
              "apgd": ApgdSolver, "admm": AdmmSolver, "auto": AutoSolver}
    if name not in makers:
        raise ValueError(f"unknown solver {name!r}: choose one of {', '.join(SOLVERS)}")
    return makers[name](**options)


class AutoSolver(Solver):
    """Clarabel for programs with fewer than `threshold` contacts, APGD from there on.

    Clarabel was faster at every size measured on the project's 2-core machine (one step of a
    settled packing, tolerance 1e-8 vs APGD's 1e-5): 1k spheres / 3.3k contacts 1.6 s vs 6.2 s,
    4k / 13k 12 s vs 28 s, 16k / 53k 79 s CPU vs 154 s. What APGD saves is memory: 98 MB against
    Clarabel's 890 MB at 16k, and Clarabel's factor grows faster than N. The default threshold,
    150,000 contacts (about 45,000 spheres), is where Clarabel's factor is expected to pass several
    GB (an extrapolation: 64k spheres were not run).

    fallback: if APGD does not converge, log a warning and solve the step with Clarabel (the step
    is then exact but slow); with fallback=False the :class:`SolverError` propagates.
    """

    name = "auto"
    uses_warm_start = True

    def __init__(self, threshold: int = 150_000, fallback: bool = True, clarabel: dict | None = None,
                 apgd: dict | None = None):
        self.threshold = int(threshold)
        self.fallback = fallback
        self.clarabel = ClarabelSolver(**(clarabel or {}))
        self.apgd = ApgdSolver(**(apgd or {}))

    def solve(self, program, warm_start=None, step=None):
        if program.m < self.threshold:
            return self.clarabel.solve(program, warm_start=warm_start, step=step)
        try:
            return self.apgd.solve(program, warm_start=warm_start, step=step)
        except SolverError as error:
            if not self.fallback:
                raise
            log.warning("%s; solving this step with Clarabel instead", error)
            solution = self.clarabel.solve(program, step=step)
            solution.status = f"{solution.status} (APGD fallback)"
            return solution
