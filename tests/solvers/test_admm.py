"""The ADMM back-end (colsim.solvers.admm): exact projection onto the gap cone, agreement with Clarabel,
warm start, errors."""
import clarabel
import numpy as np
import pytest

from colsim.solvers.admm import AdmmSolver
from colsim.engine.cones import project_gap_cone
from colsim.engine.program import cone_violation
from colsim.solvers import SolverError, WarmStart, make_solver
from solver_cases import against_clarabel, collapse_program, mid_collapse


def _reference_projection(x, a, b):
    """Projection of x (5,) onto {y_n >= a ||y_t|| + b ||y_r||} by Clarabel: variables (y, s, t)
    with y_n - s - t >= 0, (s, a y_t) and (t, b y_r) in second-order cones."""
    import scipy.sparse as sp

    rows = [[-1, 0, 0, 0, 0, 1, 1],
            [0, 0, 0, 0, 0, -1, 0], [0, -a, 0, 0, 0, 0, 0], [0, 0, -a, 0, 0, 0, 0],
            [0, 0, 0, 0, 0, 0, -1], [0, 0, 0, -b, 0, 0, 0], [0, 0, 0, 0, -b, 0, 0]]
    A = sp.csc_matrix(np.array(rows, dtype=float))
    P = sp.diags([1.0] * 5 + [0.0, 0.0], format="csc")
    scale = max(np.linalg.norm(x), 1e-300)
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    settings.tol_gap_abs = settings.tol_gap_rel = settings.tol_feas = 1e-12
    cones = [clarabel.NonnegativeConeT(1), clarabel.SecondOrderConeT(3), clarabel.SecondOrderConeT(3)]
    result = clarabel.DefaultSolver(P, np.r_[-x / scale, 0, 0], A, np.zeros(7), cones, settings).solve()
    return scale * np.asarray(result.x)[:5]


def test_projection_onto_gap_cone_is_exact():
    """Moreau: z = Proj_C(x) iff z in C, z - x in K = C* and z . (z - x) = 0; and Clarabel agrees."""
    rng = np.random.default_rng(5)
    m = 300
    x = rng.standard_normal((m, 5)) * rng.choice([1e-3, 1.0, 1e3], (m, 1))
    a = rng.choice([0.0, 0.3, 0.577, 2.0], m)
    b = rng.choice([0.0, 0.12, 0.5], m)
    inner = slice(0, 50)  # inside C: unchanged
    x[inner, 0] = (2 * (a[inner] * np.linalg.norm(x[inner, 1:3], axis=1)
                        + b[inner] * np.linalg.norm(x[inner, 3:5], axis=1)) + np.abs(x[inner, 0]))
    x[50:80, 0] = -50 * np.abs(x[50:80, 0])                                  # near or in -K
    z = project_gap_cone(x, a, b)
    size = np.linalg.norm(x, axis=1)
    slack = z[:, 0] - a * np.linalg.norm(z[:, 1:3], axis=1) - b * np.linalg.norm(z[:, 3:5], axis=1)
    assert np.all(slack >= -1e-12 * size)
    lam = z - x  # in K
    assert np.all(np.linalg.norm(lam[:, 1:3], axis=1) <= a * lam[:, 0] + 1e-12 * size)
    assert np.all(np.linalg.norm(lam[:, 3:5], axis=1) <= b * lam[:, 0] + 1e-12 * size)
    assert np.all(np.abs(np.einsum("ij,ij->i", z, lam)) <= 1e-12 * size**2)
    np.testing.assert_allclose(z[:50], x[:50], rtol=1e-14)
    for k in rng.choice(np.arange(50, m), 25, replace=False):
        np.testing.assert_allclose(z[k], _reference_projection(x[k], a[k], b[k]), atol=1e-7 * size[k])


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
    guess = WarmStart.from_step(found, cold.forces).match(found, solver_pile.n)
    warm = solver.solve(program, warm_start=guess)
    assert warm.info["start"] == "warm" and warm.iterations < cold.iterations
    assert solver.uses_warm_start


def test_non_convergence_is_an_error(solver_pile):
    program, _ = collapse_program(solver_pile)
    with pytest.raises(SolverError, match="step 17"):
        AdmmSolver(max_iter=20, tolerance=1e-12).solve(program, step=17)
    with pytest.raises(ValueError):
        AdmmSolver(rho=0)
