"""The ADMM back-end (colsim.solvers.admm): agreement with Clarabel, warm start, errors (its cone's
projection: engine/test_cones.py)."""
import numpy as np
import pytest

from colsim.solvers.admm import AdmmSolver
from colsim.engine.program import cone_violation
from colsim.solvers import SolverError, WarmStart, make_solver
from solver_cases import against_clarabel, collapse_program, mid_collapse


@pytest.mark.parametrize("stage", ["release", "mid-collapse"])
def test_agrees_with_clarabel(solver_pile, stage):
    state = solver_pile if stage == "release" else mid_collapse(solver_pile)
    program, sol, du, net_error = against_clarabel(make_solver("admm"), state)
    assert du <= 1e-3, du
    violation = cone_violation(program, sol.increments, sol.forces)
    assert violation["dual"] <= 1e-12 * np.abs(sol.forces).max()  # forces: exact projections
    assert sol.info["primal"] <= 1e-3 and sol.info["dual"] <= 1e-3
    assert net_error <= 1e-2


def test_warm_start_from_the_solution_converges_at_once(solver_pile):
    program, found = collapse_program(solver_pile)
    solver = AdmmSolver()
    cold = solver.solve(program)
    guess = WarmStart.from_step(found, cold.forces).match(found)
    warm = solver.solve(program, warm_start=guess)
    assert warm.info["start"] == "warm" and warm.iterations < cold.iterations
    assert solver.uses_warm_start


def test_non_convergence_is_an_error(solver_pile):
    program, _ = collapse_program(solver_pile)
    with pytest.raises(SolverError, match="step 17"):
        AdmmSolver(max_iter=20, tolerance=1e-12).solve(program, step=17)
    with pytest.raises(ValueError):
        AdmmSolver(rho=0)
