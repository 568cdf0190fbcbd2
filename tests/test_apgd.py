"""The first-order back-end (colsim.solvers.apgd): exact cone projection, agreement with Clarabel, errors."""
import clarabel
import numpy as np
import pytest
import scipy.sparse as sp
from scipy.optimize import minimize_scalar

from colsim.solvers.apgd import ApgdSolver
from colsim.engine.cones import project_compiled, project_coupled_cone, relative_residuals, scaled_residuals
from colsim.engine.program import cone_violation
from colsim.solvers import AutoSolver, ClarabelSolver, SolverError, WarmStart, make_solver
from colsim.engine.state import StepSettings
from colsim.engine.stepper import run
from solver_cases import COLLAPSE, against_clarabel, collapse_program, mid_collapse, small_pile


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
    A = sp.csc_matrix(np.array(rows, dtype=float))
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    settings.tol_gap_abs = settings.tol_gap_rel = settings.tol_feas = 1e-12
    scale = max(np.linalg.norm(x), 1e-300)  # Clarabel's tolerances are absolute: solve at unit scale
    result = clarabel.DefaultSolver(sp.identity(5, format="csc"), -x / scale, A, np.zeros(A.shape[0]),
                                    cones, settings).solve()
    return scale * np.asarray(result.x)


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


@pytest.fixture(scope="module")
def pile():
    return small_pile()


@pytest.mark.parametrize("stage", ["release", "mid-collapse"])
def test_agrees_with_clarabel(pile, stage):
    state = pile if stage == "release" else mid_collapse(pile)
    program, sol, du, net_error = against_clarabel(ApgdSolver(), state)
    assert du <= 1e-3, du
    # forces inside their cones (exactly: they are projections) and the residuals reached
    violation = cone_violation(program, sol.increments, sol.forces)
    assert violation["dual"] <= 1e-12 * np.abs(sol.forces).max()
    assert sol.info["primal"] <= 1e-5 and sol.info["complementarity"] <= 1e-5
    # forces are not unique in a hyperstatic packing, but the net contact force on each particle is
    assert net_error <= 1e-3


def test_non_convergence_is_an_error(pile):
    program, _ = collapse_program(pile)
    with pytest.raises(SolverError, match="step 17"):
        ApgdSolver(max_iter=5).solve(program, step=17)


def test_warm_start_by_pair(pile):
    program, found = collapse_program(pile)
    cold = ApgdSolver().solve(program)
    warm = WarmStart.from_step(found, cold.forces)
    # the stored forces come back in the same frames, and a restart from them is immediate
    np.testing.assert_allclose(warm.match(found, pile.n), cold.forces, atol=1e-12 * np.abs(cold.forces).max())
    again = ApgdSolver().solve(program, warm_start=warm.match(found, pile.n))
    assert again.info["start"] == "warm" and again.iterations < cold.iterations / 3
    # contacts that were not there before start from zero
    fewer = WarmStart(warm.i[:-5], warm.j[:-5], warm.family[:-5], warm.force[:-5], warm.rolling[:-5])
    guess = fewer.match(found, pile.n)
    assert np.count_nonzero(np.all(guess == 0, axis=1)) >= 5


def test_warm_start_survives_renumbering(pile):
    """Removing particles (as trim does) keeps the forces of the pairs that stay, in the new numbers."""
    _, found = collapse_program(pile)
    forces = np.random.default_rng(3).uniform(0.5, 1.0, (found.m, 5)) * [1, 0.1, 0.1, 0.01, 0.01]  # in the cones
    warm = WarmStart.from_step(found, forces)
    keep = np.ones(pile.n, dtype=bool)
    keep[::3] = False
    column = pile.subset(keep)
    _, found_after = collapse_program(column)
    guess = warm.subset(keep).match(found_after, column.n)
    # the same pair before and after, by the particles' old numbers
    old = np.flatnonzero(keep)
    before = {(i, j, f): row for i, j, f, row in zip(found.i, found.j, found.family, forces)}
    compared = 0
    for k in range(found_after.m):
        j = old[found_after.j[k]] if found_after.j[k] >= 0 else -1
        row = before.get((old[found_after.i[k]], j, found_after.family[k]))
        if row is not None:
            np.testing.assert_allclose(guess[k], row, rtol=0, atol=1e-12)  # same positions, same frames
            compared += 1
    assert compared > found_after.m // 2
    # pairs with a removed particle are gone
    assert warm.subset(keep).m < warm.m


def test_auto_picks_apgd_only_for_warm_small_steps(pile):
    program, found = collapse_program(pile)
    reference = ClarabelSolver().solve(program)
    warm = WarmStart.from_step(found, reference.forces).match(found, pile.n)
    assert AutoSolver().solve(program).backend == "clarabel"                 # no warm start
    assert AutoSolver().solve(program, warm_start=warm).backend == "apgd"
    assert AutoSolver(scaled_time_step=0.04).solve(program, warm_start=warm).backend == "apgd"
    assert AutoSolver(scaled_time_step=0.08).solve(program, warm_start=warm).backend == "clarabel"
    assert AutoSolver().solve(program, warm_start=np.zeros_like(warm)).backend == "clarabel"
    assert isinstance(make_solver("auto"), AutoSolver)


def test_stepper_records_the_backend_of_each_step(pile):
    results = list(run(pile, COLLAPSE, 3, make_solver("apgd")))
    assert [r.solution.info["start"] for r in results] == ["cold", "warm", "warm"]
    backends = [r.diagnostics.solver_backend for r in run(pile, COLLAPSE, 3, AutoSolver())]
    assert backends == ["clarabel", "apgd", "apgd"]


def test_auto_falls_back_to_clarabel_at_the_iteration_cap(pile):
    """A warm-started step that APGD cannot finish within the cap is solved by Clarabel, and the
    step's diagnostics say so."""
    backends = [r.diagnostics.solver_backend for r in run(pile, COLLAPSE, 3, AutoSolver(max_iter=3))]
    assert backends == ["clarabel", "clarabel-fallback", "clarabel-fallback"]


def test_numba_and_numpy_kernels_agree(pile):
    """Both kernels solve the same step to the solver's tolerance: each within the bound of
    test_agrees_with_clarabel of the reference. (Their iteration counts may differ by a few: the
    stopping check lands at a different point below the tolerance when rounding differs.)"""
    pytest.importorskip("numba")
    for kernel in ("numba", "numpy"):
        _, sol, du, net_error = against_clarabel(ApgdSolver(kernel=kernel), pile)
        assert sol.info["primal"] <= 1e-5 and sol.info["complementarity"] <= 1e-5, kernel
        assert du <= 1e-3 and net_error <= 1e-3, (kernel, du, net_error)


def test_collapse_ends_the_same_with_both_solvers(pile):
    """A small column collapse (100 steps to t/sqrt(h0/g) = 4): h_inf and r_inf within 2 % of r0."""
    r0 = 1.2
    h0 = float(np.max(pile.position[:, 2] + pile.radius))
    settings = StepSettings(dt=0.04 * np.sqrt(h0 / 9.81), law=COLLAPSE.law)
    ends = {}
    for name in ("clarabel", "apgd"):
        state = pile
        for result in run(pile, settings, 100, make_solver(name)):
            state = result.state
        ends[name] = np.array([np.max(state.position[:, 2] + state.radius),
                               np.max(np.hypot(state.position[:, 0], state.position[:, 1]) + state.radius)])
    assert ends["clarabel"][1] > 1.5 * r0  # it did collapse
    assert np.all(np.abs(ends["apgd"] - ends["clarabel"]) <= 0.02 * r0), ends


def test_length_floor_bounds_each_gap_in_diameters(pile):
    """With a length floor the residuals are measured against max(free flight, floor x mean
    diameter): the step stops sooner, and no contact's end-of-step gap is off by more than the
    tolerance times that length (here 1e-5 x 0.1 d = 1e-6 d, far inside the 1 % overlap check)."""
    program, found = collapse_program(pile)
    exact = ClarabelSolver(tolerance=1e-10).solve(program)
    warm = WarmStart.from_step(found, exact.forces).match(found, pile.n) * 0.9   # an imperfect start
    d = 2 * pile.radius.mean()
    free = ApgdSolver().solve(program, warm_start=warm)
    floored = ApgdSolver(length_floor=0.1).solve(program, warm_start=warm)
    assert floored.iterations < free.iterations
    assert floored.info["length_scale"] == pytest.approx(0.1 * d, rel=1e-12)
    violation = cone_violation(program, floored.increments, floored.forces)
    assert violation["primal"] <= 1e-5 * 0.1 * d
    assert violation["dual"] <= 1e-12 * np.abs(floored.forces).max()
    # each sphere's motion is the reference's to within 1e-4 d, rotations times the mean radius
    # likewise: the stopping rule bounds residuals, not the motion, so the bound is the collapse's
    # own overlap tolerance under auto (1e-4 d: a motion error it accepts in every step), a
    # fiftieth of the largest step here (5e-3 d); measured 1.5e-5 d under the paper's lever
    n = pile.n
    error = np.abs(floored.increments - exact.increments)
    assert error[:3 * n].max() <= 1e-4 * d and error[3 * n:].max() * d / 2 <= 1e-4 * d
    with pytest.raises(ValueError, match="length_floor"):
        ApgdSolver(length_floor=-1.0)


def test_overlap_tolerance_bounds_the_largest_violation_in_diameters(pile):
    """An overlap tolerance lets the primal residual stop at a violation of that many mean
    diameters (here 1e-4 d, a hundredth of the 1 % overlap check) while complementarity keeps the
    relative tolerance; the step stops no later, and no gap is off by more than the tolerance."""
    program, found = collapse_program(pile)
    exact = ClarabelSolver(tolerance=1e-10).solve(program)
    warm = WarmStart.from_step(found, exact.forces).match(found, pile.n) * 0.9
    d = 2 * pile.radius.mean()
    tight = ApgdSolver(length_floor=0.1).solve(program, warm_start=warm)
    loose = ApgdSolver(length_floor=0.1, overlap_tolerance=1e-4).solve(program, warm_start=warm)
    assert loose.iterations <= tight.iterations
    assert cone_violation(program, loose.increments, loose.forces)["primal"] <= 1e-4 * d
    assert loose.info["complementarity"] <= 1e-5
    # below the relative tolerance's own bound (1e-5 x 0.1 d) it changes nothing
    same = ApgdSolver(length_floor=0.1, overlap_tolerance=1e-7).solve(program, warm_start=warm)
    assert same.iterations == tight.iterations
    assert np.array_equal(same.forces, tight.forces)
    with pytest.raises(ValueError, match="overlap_tolerance"):
        ApgdSolver(overlap_tolerance=-1.0)


def test_auto_uses_the_length_floor_in_both_stages():
    from colsim.cli import build_parser
    from colsim.cli.commands import _pack_solver, _solver
    assert AutoSolver().apgd.length_floor == AutoSolver.APGD_LENGTH_FLOOR > 0
    assert ApgdSolver().length_floor == 0.0
    parser = build_parser()
    collapse_args = parser.parse_args(["collapse", "--input", "c.nc", "--output", "t.nc"])
    assert _solver(collapse_args, 0.004).apgd.length_floor == AutoSolver.APGD_LENGTH_FLOOR
    pack_args = parser.parse_args(["pack", "--height", "2", "--output", "p.nc"])
    assert _pack_solver(pack_args).apgd.length_floor == AutoSolver.APGD_LENGTH_FLOOR
    chosen = parser.parse_args(["collapse", "--input", "c.nc", "--output", "t.nc", "--solver", "apgd",
                                "--solver-length-floor", "0.5"])
    assert _solver(chosen, 0.004).length_floor == 0.5


def test_auto_loosens_only_the_collapse_primal_by_its_overlap_tolerance():
    """Under auto the collapse's APGD may stop at a largest violation of 1e-4 mean diameters; the
    packing's own primal bound (tolerance 1e-3 x at least 0.1 d) is already that loose, so the
    packing goes without it, and records its settings as before the option existed."""
    from colsim.cli import build_parser
    from colsim.cli.commands import _pack_solver, _solver
    from colsim.solvers.defaults import PACK_APGD_TOLERANCE as APGD_TOLERANCE
    assert AutoSolver().apgd.overlap_tolerance == AutoSolver.APGD_OVERLAP_TOLERANCE > 0
    assert ApgdSolver().overlap_tolerance == 0.0
    assert AutoSolver.APGD_OVERLAP_TOLERANCE <= APGD_TOLERANCE * AutoSolver.APGD_LENGTH_FLOOR
    parser = build_parser()
    collapse_args = parser.parse_args(["collapse", "--input", "c.nc", "--output", "t.nc"])
    assert _solver(collapse_args, 0.004).apgd.overlap_tolerance == AutoSolver.APGD_OVERLAP_TOLERANCE
    pack_args = parser.parse_args(["pack", "--height", "2", "--output", "p.nc"])
    packing = _pack_solver(pack_args)
    assert packing.apgd.overlap_tolerance == 0.0
    assert "overlap_tolerance" not in packing.describe()["apgd"]
    assert _solver(collapse_args, 0.004).describe()["apgd"]["overlap_tolerance"] == 1e-4
    chosen = parser.parse_args(["pack", "--height", "2", "--output", "p.nc", "--solver-overlap-tolerance", "1e-5"])
    assert _pack_solver(chosen).apgd.overlap_tolerance == 1e-5


def test_compiled_residuals_match_numpy(pile):
    """The residual check's one-sweep kernel gives relative_residuals' values to rounding (1e-12),
    on a mid-solve iterate where every residual is non-zero."""
    program, _ = collapse_program(pile)
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
