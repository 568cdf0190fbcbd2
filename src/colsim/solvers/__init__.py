"""The back-ends of a step's cone program: Clarabel (the reference), APGD, ADMM, and the automatic
choice between them; one module each, their defaults in :mod:`colsim.solvers.defaults`.

The registry's names (make_solver, SOLVERS, the back-ends) are loaded on first use, so that
`colsim.solvers.defaults` can be read without loading a back-end.
"""
from .defaults import SOLVERS

__all__ = ["SOLVERS", "AdmmSolver", "ApgdSolver", "AutoSolver", "ClarabelSolver", "ConeSolution",
           "Solver", "SolverError", "WarmStart", "at_step", "make_solver"]


def __getattr__(name):
    if name in __all__:
        from . import registry
        return getattr(registry, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
