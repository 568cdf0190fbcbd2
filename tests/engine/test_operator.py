"""B without the matrix (colsim.engine.operator): B u, B' lam and diag(B Mbar^-1 B') from the
contacts' frames equal the products with the assembled matrix, to rounding (1e-12 relative: the
same sums in another order), on a pile with particle, floor, cylinder and fixed-sphere contacts;
and a program solved by APGD never forms the matrix."""
import numpy as np
import pytest

from colsim.engine.cones import row_scaling, scales_of_diagonal
from colsim.engine.operator import ContactOperator
from colsim.engine.program import assemble, contact_jacobian
from colsim.solvers.apgd import ApgdSolver
from solver_cases import COLLAPSE

pytest.importorskip("numba")


def test_products_equal_the_matrix_s(pile_with_every_contact):
    state, found, program = pile_with_every_contact
    B = contact_jacobian(found, state.n)
    operator = ContactOperator(found, state.n)
    rng = np.random.default_rng(1)
    u, lam = rng.standard_normal(6 * state.n), rng.standard_normal(5 * found.m)
    np.testing.assert_allclose(operator.apply(u), B @ u, rtol=1e-12, atol=1e-12 * np.abs(B @ u).max())
    np.testing.assert_allclose(operator.transpose(lam), B.T @ lam, rtol=1e-12,
                               atol=1e-12 * np.abs(B.T @ lam).max())
    inv_mass = 1.0 / program.mass
    diagonal = operator.diagonal(inv_mass)
    np.testing.assert_allclose(diagonal, (B.multiply(B) @ inv_mass).reshape(-1, 5), rtol=1e-12)
    np.testing.assert_allclose(scales_of_diagonal(diagonal), row_scaling(B, inv_mass), rtol=1e-12)


def test_a_program_solved_by_apgd_never_forms_the_matrix(pile_with_every_contact):
    state, found, _ = pile_with_every_contact
    program = assemble(state, found, COLLAPSE.dt, COLLAPSE.gravity)
    solution = ApgdSolver().solve(program)
    assert program.matrix is None
    with_matrix = (program.fbar + program.jacobian.T @ solution.forces.ravel()) / program.mass
    np.testing.assert_allclose(solution.increments, with_matrix, rtol=0, atol=1e-12 * np.abs(with_matrix).max())
