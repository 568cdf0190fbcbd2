"""The reference back-end (colsim.solvers.clarabel): its settings, its two forms and two
factorisations against each other, and a failure that names its status and step."""
import numpy as np
import pytest

from colsim.engine.program import cone_violation
from colsim.solvers import ClarabelSolver, SolverError, defaults

from solver_cases import collapse_program

#: the agreement asked of two exact solutions of one program, both solved to 1e-10: the step's
#: increments are unique (the objective is strictly convex in them), but where contacts are
#: degenerate (active with zero force) an interior point's primal error goes as the square root of
#: its gap tolerance, sqrt(1e-10) = 1e-5 (measured: 2e-6 on the pile poured with the bounded overlap
#: recovery of 2026-11-26, 1e-7 or less before)
AGREEMENT = 1e-5


def test_defaults_come_from_the_defaults_module():
    solver = ClarabelSolver()
    assert solver.tolerance == defaults.CLARABEL_TOLERANCE
    assert solver.max_iter == defaults.CLARABEL_MAX_ITER
    assert solver.form == "displacement" and solver.direct_solve_method == "faer"


@pytest.mark.parametrize("settings, message", [({"form": "dual"}, "form"),
                                               ({"direct_solve_method": "mkl"}, "direct_solve_method"),
                                               ({"tolerance": 0.0}, "tolerance")])
def test_bad_settings_are_refused(settings, message):
    with pytest.raises(ValueError, match=message):
        ClarabelSolver(**settings)


@pytest.mark.parametrize("other", [{"form": "force"}, {"direct_solve_method": "qdldl"}])
def test_forms_and_factorisations_give_one_solution(solver_pile, other):
    """The displacement form with faer against the force form, and against qdldl: the same
    increments (AGREEMENT) and, each of them, forces inside the cones to the tolerance."""
    program, _ = collapse_program(solver_pile)
    reference = ClarabelSolver(tolerance=1e-10).solve(program)
    solution = ClarabelSolver(tolerance=1e-10, **other).solve(program)
    assert reference.status == solution.status == "Solved"
    difference = np.linalg.norm(solution.increments - reference.increments) / np.linalg.norm(reference.increments)
    assert difference <= AGREEMENT
    force_scale = np.abs(reference.forces[:, 0]).max()
    length_scale = np.abs(reference.increments).max()
    for result in (reference, solution):
        violation = cone_violation(program, result.increments, result.forces)
        assert violation["primal"] <= 1e-6 * length_scale
        assert violation["dual"] <= 1e-6 * force_scale


def test_iteration_cap_is_an_error_naming_the_status_and_the_step(solver_pile):
    program, _ = collapse_program(solver_pile)
    with pytest.raises(SolverError, match="step 9") as failure:
        ClarabelSolver(max_iter=2, retry=False).solve(program, step=9)
    assert failure.value.status == "MaxIterations" and failure.value.step == 9
