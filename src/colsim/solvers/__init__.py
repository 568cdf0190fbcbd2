"""The back-ends of a step's cone program: Clarabel (the reference), APGD, ADMM, and the automatic
choice between them; one module each, their defaults in :mod:`colsim.solvers.defaults`."""
from .registry import (SOLVERS, AdmmSolver, ApgdSolver, AutoSolver, ClarabelSolver, ConeSolution, Solver,
                       SolverError, WarmStart, at_step, make_solver)

__all__ = ["SOLVERS", "AdmmSolver", "ApgdSolver", "AutoSolver", "ClarabelSolver", "ConeSolution",
           "Solver", "SolverError", "WarmStart", "at_step", "make_solver"]
