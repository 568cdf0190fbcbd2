"""The first-order back-end (colsim.solvers.apgd): exact cone projection, agreement with Clarabel, errors."""
import numpy as np
import pytest

from colsim.solvers.apgd import ApgdSolver
from colsim.engine.program import cone_violation
from colsim.solvers import ClarabelSolver, SolverError, WarmStart, make_solver
from colsim.engine.state import StepSettings
from colsim.engine.stepper import run
from solver_cases import COLLAPSE, against_clarabel, collapse_program, mid_collapse
from apgd_oracle import NumpyBackend

BACKENDS = {"numba": None, "numpy": NumpyBackend()}


@pytest.mark.parametrize("stage", ["release", "mid-collapse"])
def test_agrees_with_clarabel(solver_pile, stage):
    state = solver_pile if stage == "release" else mid_collapse(solver_pile)
    program, sol, du, net_error = against_clarabel(ApgdSolver(), state)
    assert du <= 1e-3, du
    # forces inside their cones (exactly: they are projections) and the residuals reached
    violation = cone_violation(program, sol.increments, sol.forces)
    assert violation["dual"] <= 1e-12 * np.abs(sol.forces).max()
    assert sol.info["primal"] <= 1e-5 and sol.info["complementarity"] <= 1e-5
    # forces are not unique in a hyperstatic packing, but the net contact force on each particle is
    assert net_error <= 1e-3


def test_non_convergence_is_an_error(solver_pile):
    program, _ = collapse_program(solver_pile)
    with pytest.raises(SolverError, match="step 17"):
        ApgdSolver(max_iter=5).solve(program, step=17)


def test_numba_and_numpy_kernels_agree(solver_pile):
    """Both kernels solve the same step to the solver's tolerance: each within the bound of
    test_agrees_with_clarabel of the reference. (Their iteration counts may differ by a few: the
    stopping check lands at a different point below the tolerance when rounding differs.)"""
    pytest.importorskip("numba")
    for kernel in ("numba", "numpy"):
        _, sol, du, net_error = against_clarabel(ApgdSolver(backend=BACKENDS[kernel]), solver_pile)
        assert sol.info["primal"] <= 1e-5 and sol.info["complementarity"] <= 1e-5, kernel
        assert du <= 1e-3 and net_error <= 1e-3, (kernel, du, net_error)


def test_the_iterations_carry_their_momentum_from_one_call_to_the_next(solver_pile):
    """The compiled iteration keeps the extrapolation (the last two iterates and beta), not a stored
    point: 7 + 13 + 20 iterations in three calls end on the same bits as 40 in one, and on the
    numpy kernel's iterate (matrices, other sums) to rounding (1e-9 of the largest force)."""
    pytest.importorskip("numba")
    program, _ = collapse_program(mid_collapse(solver_pile))
    runs = {name: ApgdSolver(backend=BACKENDS[kernel]).prepare(program)
            for name, kernel in (("whole", "numba"), ("parts", "numba"), ("numpy", "numpy"))}
    runs["whole"].iterate(40)
    for n in (7, 13, 20):
        runs["parts"].iterate(n)
    runs["numpy"].iterate(40)
    np.testing.assert_array_equal(runs["parts"].x, runs["whole"].x)
    np.testing.assert_array_equal(runs["parts"].hx, runs["whole"].hx)
    scale = np.abs(runs["whole"].x).max()
    np.testing.assert_allclose(runs["numpy"].x, runs["whole"].x, rtol=0, atol=1e-9 * scale)


def test_apgd_s_one_loop_makes_exactly_the_iterations_asked_in_rounds_of_trial_steps(solver_pile):
    """run_iterations, the loop of every back-end: a round of k trial steps adds k to the iterations
    and backtracks together; iterate(n) ends with exactly n more iterations, however many of its
    trial steps backtracked (a cold start from a Lipschitz estimate that halves every step, so that
    steps are rejected), and on the bits of the same trial steps made one round at a time."""
    program, _ = collapse_program(mid_collapse(solver_pile))
    solver = ApgdSolver(lipschitz_decay=0.5)
    whole, rounds = solver.prepare(program), solver.prepare(program)
    whole.iterate(60)
    assert whole.iterations == 60 and whole.backtracks > 0
    while rounds.iterations < 60:
        before = rounds.iterations + rounds.backtracks
        rounds.trial_round(1, check=False)
        assert rounds.iterations + rounds.backtracks == before + 1
    assert (rounds.iterations, rounds.backtracks, rounds.restarts) == (60, whole.backtracks, whole.restarts)
    np.testing.assert_array_equal(rounds.x, whole.x)


def test_collapse_ends_the_same_with_both_solvers(solver_pile):
    """A small column collapse (100 steps to t/sqrt(h0/g) = 4): h_inf and r_inf within 2 % of r0."""
    r0 = 1.2
    h0 = float(np.max(solver_pile.position[:, 2] + solver_pile.radius))
    settings = StepSettings(dt=0.04 * np.sqrt(h0 / 9.81), law=COLLAPSE.law)
    ends = {}
    for name in ("clarabel", "apgd"):
        state = solver_pile
        for result in run(solver_pile, settings, 100, make_solver(name)):
            state = result.state
        ends[name] = np.array([np.max(state.position[:, 2] + state.radius),
                               np.max(np.hypot(state.position[:, 0], state.position[:, 1]) + state.radius)])
    assert ends["clarabel"][1] > 1.5 * r0  # it did collapse
    assert np.all(np.abs(ends["apgd"] - ends["clarabel"]) <= 0.02 * r0), ends


def test_length_floor_bounds_each_gap_in_diameters(solver_pile):
    """With a length floor the residuals are measured against max(free flight, floor x mean
    diameter): the step stops sooner, and no contact's end-of-step gap is off by more than the
    tolerance times that length (here 1e-5 x 0.1 d = 1e-6 d, far inside the 1 % overlap check)."""
    program, found = collapse_program(solver_pile)
    exact = ClarabelSolver(tolerance=1e-10).solve(program)
    warm = WarmStart.from_step(found, exact.forces).match(found) * 0.9   # an imperfect start
    d = 2 * solver_pile.radius.mean()
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
    n = solver_pile.n
    error = np.abs(floored.increments - exact.increments)
    assert error[:3 * n].max() <= 1e-4 * d and error[3 * n:].max() * d / 2 <= 1e-4 * d
    with pytest.raises(ValueError, match="length_floor"):
        ApgdSolver(length_floor=-1.0)


def test_overlap_tolerance_bounds_the_largest_violation_in_diameters(solver_pile):
    """An overlap tolerance lets the primal residual stop at a violation of that many mean
    diameters (here 1e-4 d, a hundredth of the 1 % overlap check) while complementarity keeps the
    relative tolerance; the step stops no later, and no gap is off by more than the tolerance."""
    program, found = collapse_program(solver_pile)
    exact = ClarabelSolver(tolerance=1e-10).solve(program)
    warm = WarmStart.from_step(found, exact.forces).match(found) * 0.9
    d = 2 * solver_pile.radius.mean()
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




def test_the_power_iterations_start_is_the_same_whatever_was_asked_before():
    """power_start keeps its longest draw and hands out prefixes: each equals a fresh draw of its
    size (numpy's generator fills in sequence), whatever sizes came before, and is the caller's own."""
    from colsim.engine.apgd_iteration import power_start

    for size in (7, 3, 5000, 12, 20001, 1):
        start = power_start(size)
        assert np.array_equal(start, np.random.default_rng(0).standard_normal(size))
        start[:] = 0.0   # lipschitz_estimate overwrites its start
    assert np.array_equal(power_start(20001), np.random.default_rng(0).standard_normal(20001))
