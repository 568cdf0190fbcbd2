"""The cones (colsim.engine.cones): the exact projections onto the coupled cone and onto the gap cone
(ADMM's) against Clarabel, the compiled kernels against numpy, the residuals."""
import clarabel
import numpy as np
import pytest
import scipy.sparse as sp
from scipy.optimize import minimize_scalar

from colsim.engine.cones import (
    _residual_parts,
    project_compiled,
    project_coupled_cone,
    project_gap_cone,
    relative_residuals,
    scaled_residuals,
)
from colsim.solvers.apgd import ApgdSolver

from solver_cases import collapse_program


def _reference_projection(x, a, b):
    """Projection of x (5,) onto {||q|| <= a p, ||r|| <= b p} by Clarabel (a or b = 0: zero cone)."""
    rows, cones = [[-1, 0, 0, 0, 0]], [clarabel.NonnegativeConeT(1)]
    for coef, first in ((a, 1), (b, 3)):
        if coef > 0:
            rows += [[-coef, 0, 0, 0, 0], [0] * 5, [0] * 5]
            rows[-2][first], rows[-1][first + 1] = -1, -1
            cones.append(clarabel.SecondOrderConeT(3))
        else:
            rows += [[0] * 5, [0] * 5]
            rows[-2][first], rows[-1][first + 1] = 1, 1
            cones.append(clarabel.ZeroConeT(2))
    return _nearest_point(x, sp.identity(5, format="csc"), sp.csc_matrix(np.array(rows, dtype=float)), cones)


def _nearest_point(x, P, A, cones):
    """The first 5 unknowns of min 1/2 v'P v - x'v[:5] subject to -A v in the cones (v = (y, ...)),
    by Clarabel at 1e-12, solved at unit scale (its tolerances are absolute)."""
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    settings.tol_gap_abs = settings.tol_gap_rel = settings.tol_feas = 1e-12
    scale = max(np.linalg.norm(x), 1e-300)
    q = np.zeros(P.shape[0])
    q[:5] = -x / scale
    result = clarabel.DefaultSolver(P, q, A, np.zeros(A.shape[0]), cones, settings).solve()
    return scale * np.asarray(result.x)[:5]


def test_projection_is_exact():
    rng = np.random.default_rng(3)
    m = 240
    x = rng.standard_normal((m, 5)) * rng.choice([1e-3, 1.0, 1e3], (m, 1))
    a = rng.choice([0.0, 0.3, 0.577, 2.0], m)
    b = rng.choice([0.0, 0.12, 0.5], m)
    x[:40, 0] = -10 * np.abs(x[:40, 0])               # deep in the polar cone or near it
    x[40:70, 1:] *= 1e-4                              # inside the cone: unchanged
    # on the edges: ||q|| = a p exactly, r inside, and the reverse
    edge = slice(70, 100)
    a[70:130] = np.maximum(a[70:130], 0.1)
    b[70:130] = np.maximum(b[70:130], 0.05)
    x[edge, 0] = np.abs(x[edge, 0])
    x[edge, 1:3] *= (a[edge] * x[edge, 0] / np.maximum(np.linalg.norm(x[edge, 1:3], axis=1), 1e-300))[:, None]
    x[edge, 3:5] *= 1e-3
    # just outside an edge: the sliding part pushed out by 1e-3, the rolling part on its boundary
    out = slice(100, 130)
    x[out, 0] = np.abs(x[out, 0])
    for coef, first, factor in ((a, 1, 1.001), (b, 3, 1.0)):
        norm = np.maximum(np.linalg.norm(x[out, first:first + 2], axis=1), 1e-300)
        x[out, first:first + 2] *= (factor * coef[out] * x[out, 0] / norm)[:, None]
    z = project_coupled_cone(x, a, b)
    scale = np.maximum(1.0, np.linalg.norm(x, axis=1))
    # feasible ...
    assert np.all(np.linalg.norm(z[:, 1:3], axis=1) <= a * z[:, 0] + 1e-12 * scale)
    assert np.all(np.linalg.norm(z[:, 3:5], axis=1) <= b * z[:, 0] + 1e-12 * scale)
    assert np.all(z[:, 0] >= 0)
    for k in range(m):
        # ... the brute-force minimiser of the distance over p (radial clips of q and r for each p)
        def phi(p, k=k):
            return ((p - x[k, 0]) ** 2 + np.maximum(np.hypot(*x[k, 1:3]) - a[k] * p, 0.0) ** 2
                    + np.maximum(np.hypot(*x[k, 3:5]) - b[k] * p, 0.0) ** 2)
        grid = np.linspace(0.0, 2 * scale[k], 4001)
        p0 = grid[np.argmin(phi(grid))]
        brute = minimize_scalar(phi, bounds=(max(p0 - scale[k] / 1000, 0), p0 + scale[k] / 1000),
                                method="bounded", options={"xatol": 1e-13 * scale[k]}).x
        assert abs(z[k, 0] - brute) <= 1e-7 * scale[k], (k, x[k], a[k], b[k])
        # ... and never farther from x than Clarabel's projection (which is imprecise on edges)
        ref = _reference_projection(x[k], a[k], b[k])
        assert np.sum((z[k] - x[k]) ** 2) <= np.sum((ref - x[k]) ** 2) + 1e-9 * scale[k] ** 2
        if not 70 <= k < 130:
            assert np.linalg.norm(z[k] - ref) <= 1e-7 * scale[k], (k, x[k], a[k], b[k])
    np.testing.assert_allclose(z[edge], x[edge], rtol=1e-12, atol=1e-12 * np.abs(x[edge]).max())
    inside = slice(40, 70)
    ok = (np.linalg.norm(x[inside, 1:3], axis=1) <= a[inside] * x[inside, 0]) & \
         (np.linalg.norm(x[inside, 3:5], axis=1) <= b[inside] * x[inside, 0])
    np.testing.assert_array_equal(z[inside][ok], x[inside][ok])


def test_compiled_projection_matches():
    """The scalar kernel of the compiled iterations gives the same projection, mu = 0 included."""

    rng = np.random.default_rng(5)
    x = rng.standard_normal((2000, 5))
    x[:300, 1:] = 0.0                                  # pure normal, either sign
    a = rng.choice([0.0, 0.577, 1.5], len(x))
    b = rng.choice([0.0, 0.12], len(x))
    np.testing.assert_allclose(project_compiled(x, a, b), project_coupled_cone(x, a, b), rtol=0, atol=1e-13)
    assert np.all(project_compiled(x, a, b)[:, 0] >= 0)


@pytest.mark.parametrize("kernel", [project_coupled_cone, project_compiled])
@pytest.mark.parametrize("sliding_first", [True, False])
def test_projection_exact_next_to_a_breakpoint(kernel, sliding_first):
    """Points whose projection has p a hair (1e-12 to 1e-6 relative) above the first breakpoint
    ||q0||/mu (or ||r0||/mu_r): the piece must be chosen exactly, so p is right to rounding
    (1e-12 relative), not only to sqrt(eps) as when nearly equal distances are compared."""
    rng = np.random.default_rng(11)
    n = 400
    mu, mu_r = np.full(n, 0.577), np.full(n, 0.12)
    first, second = (mu, mu_r) if sliding_first else (mu_r, mu)
    t1 = rng.uniform(0.5, 2.0, n)                       # the first breakpoint
    p_star = t1 * (1.0 + 10.0 ** rng.uniform(-12, -6, n))
    n1, n2 = first * t1, second * 3.0 * t1               # the second breakpoint is at 3 t1
    p0 = p_star * (1.0 + second**2) - second * n2         # the middle piece's minimiser is p_star
    u1, u2 = (v / np.linalg.norm(v, axis=1, keepdims=True) for v in rng.standard_normal((2, n, 2)))
    x = np.empty((n, 5))
    x[:, 0] = p0
    x[:, 1:3], x[:, 3:5] = (n1[:, None] * u1, n2[:, None] * u2) if sliding_first else \
        (n2[:, None] * u2, n1[:, None] * u1)
    z = kernel(x, mu, mu_r)
    np.testing.assert_allclose(z[:, 0], p_star, rtol=1e-12, atol=0)
    kept, clipped = (slice(1, 3), slice(3, 5)) if sliding_first else (slice(3, 5), slice(1, 3))
    np.testing.assert_array_equal(z[:, kept], x[:, kept])   # that term is inactive: left alone
    np.testing.assert_allclose(np.linalg.norm(z[:, clipped], axis=1), second * p_star, rtol=1e-12)


def test_projection_polar_cone_goes_to_zero():
    x = np.array([[-1.0, 0.1, 0.0, 0.0, 0.05], [-2.0, 0.0, 0.0, 0.0, 0.0]])
    z = project_coupled_cone(x, np.array([0.5, 0.5]), np.array([0.1, 0.1]))
    np.testing.assert_allclose(z, 0.0, atol=1e-15)


def test_compiled_residuals_match_numpy(solver_pile):
    """The residual check's one-sweep kernel gives relative_residuals' values to rounding (1e-12),
    on a mid-solve iterate where every residual is non-zero."""
    program, _ = collapse_program(solver_pile)
    run = ApgdSolver().prepare(program)
    run.iterate(30)
    g, x, s = run.gradient_at_x(), run.x, run.scaling.ravel()
    m = program.m
    numpy_values = relative_residuals((g / s).reshape(m, 5), (s * x).reshape(m, 5), program.mu,
                                      program.mu_r, 0.01, 2.0)
    compiled = scaled_residuals(g, x, s, program.mu, program.mu_r, 0.01, 2.0)
    assert numpy_values["primal"] > 0 and numpy_values["complementarity"] > 0
    for name, value in numpy_values.items():
        assert compiled[name] == pytest.approx(value, rel=1e-12, abs=1e-300), name


def test_residual_blocks_change_only_the_sums_order(solver_pile):
    """The residual sweep split over blocks of contacts (one a thread): the largest violations are
    the same to the bit, the sums the same to rounding (1e-12), whatever the block count, more
    blocks than contacts included; and one block is the plain serial sweep."""
    program, _ = collapse_program(solver_pile)
    run = ApgdSolver().prepare(program)
    run.iterate(30)
    g, x, s = run.gradient_at_x(), run.x, run.scaling.ravel()
    mu, mu_r = np.asarray(program.mu, float), np.asarray(program.mu_r, float)
    serial = _residual_parts(g, x, s, mu, mu_r, 1)
    lam = (s * x).reshape(-1, 5)
    assert serial[2] == pytest.approx(np.sum(np.maximum(lam[:, 0], 0.0)), rel=1e-12)
    for blocks in (2, 3, 7, program.m + 5):
        split = _residual_parts(g, x, s, mu, mu_r, blocks)
        assert split[:2] == serial[:2], blocks
        assert split[2:] == pytest.approx(serial[2:], rel=1e-12), blocks


def _reference_gap_projection(x, a, b):
    """Projection of x (5,) onto {y_n >= a ||y_t|| + b ||y_r||} by Clarabel: variables (y, s, t)
    with y_n - s - t >= 0, (s, a y_t) and (t, b y_r) in second-order cones."""
    rows = [[-1, 0, 0, 0, 0, 1, 1],
            [0, 0, 0, 0, 0, -1, 0], [0, -a, 0, 0, 0, 0, 0], [0, 0, -a, 0, 0, 0, 0],
            [0, 0, 0, 0, 0, 0, -1], [0, 0, 0, -b, 0, 0, 0], [0, 0, 0, 0, -b, 0, 0]]
    cones = [clarabel.NonnegativeConeT(1), clarabel.SecondOrderConeT(3), clarabel.SecondOrderConeT(3)]
    return _nearest_point(x, sp.diags([1.0] * 5 + [0.0, 0.0], format="csc"),
                          sp.csc_matrix(np.array(rows, dtype=float)), cones)


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
        np.testing.assert_allclose(z[k], _reference_gap_projection(x[k], a[k], b[k]), atol=1e-7 * size[k])
