"""Contact forces carried by pair (colsim.engine.warm_start): from step to step and through a renumbering."""
import numpy as np

from colsim.solvers import WarmStart
from colsim.solvers.apgd import ApgdSolver

from solver_cases import collapse_program


def test_warm_start_by_pair(solver_pile):
    program, found = collapse_program(solver_pile)
    cold = ApgdSolver().solve(program)
    warm = WarmStart.from_step(found, cold.forces)
    # the stored forces come back in the same frames, and a restart from them is immediate
    np.testing.assert_allclose(warm.match(found), cold.forces, atol=1e-12 * np.abs(cold.forces).max())
    again = ApgdSolver().solve(program, warm_start=warm.match(found))
    assert again.info["start"] == "warm" and again.iterations < cold.iterations / 3
    # contacts that were not there before start from zero
    fewer = WarmStart(warm.i[:-5], warm.j[:-5], warm.family[:-5], warm.force[:-5], warm.rolling[:-5])
    guess = fewer.match(found)
    assert np.count_nonzero(np.all(guess == 0, axis=1)) >= 5


def test_warm_start_survives_renumbering(solver_pile):
    """Removing particles (as trim does) keeps the forces of the pairs that stay, in the new numbers."""
    _, found = collapse_program(solver_pile)
    forces = np.random.default_rng(3).uniform(0.5, 1.0, (found.m, 5)) * [1, 0.1, 0.1, 0.01, 0.01]  # in the cones
    warm = WarmStart.from_step(found, forces)
    keep = np.ones(solver_pile.n, dtype=bool)
    keep[::3] = False
    column = solver_pile.subset(keep)
    _, found_after = collapse_program(column)
    guess = warm.subset(keep).match(found_after)
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


def test_forces_go_to_the_moving_spheres_numbering_and_back():
    """A pour in layers steps only its moving spheres, on fixed supports: for_moving numbers the pairs
    as that step does (moving in order, supports as fixed spheres j = -2 - k, walls as they are) and
    drops those with a fixed sphere that is no support; in_whole numbers them back exactly; among
    keeps the pairs of fixed spheres and walls alone. Five particles: 1 and 3 move, 0 and 4 are fixed
    supports, 2 is fixed and no support."""
    i = np.array([1, 3, 0, 1, 2, 3, 2])
    j = np.array([3, 0, 4, -1, 4, 2, -1])
    family = np.array([0, 0, 0, 1, 0, 0, 1])
    force = np.arange(21.0).reshape(7, 3)
    warm = WarmStart(i, j, family, force, -force)
    moving, supports = np.array([1, 3]), np.array([0, 4])
    local = warm.for_moving(moving, supports, 5)
    # kept: (1, 3), (3, 0) and (1, wall); the others have a fixed particle first or a fixed non-support
    np.testing.assert_array_equal(local.i, [0, 1, 0])
    np.testing.assert_array_equal(local.j, [1, -2, -1])
    np.testing.assert_array_equal(local.force, force[[0, 1, 3]])
    back = local.in_whole(moving, supports)
    for name in ("i", "j", "family", "force", "rolling"):
        np.testing.assert_array_equal(getattr(back, name), getattr(warm, name)[[0, 1, 3]])
    fixed = np.array([True, False, True, False, True])
    held = warm.among(fixed)
    np.testing.assert_array_equal(held.i, [0, 2, 2])
    np.testing.assert_array_equal(held.j, [4, 4, -1])
    assert held.joined(back).m == 6


def test_from_step_is_the_frames_sum_to_the_bit(solver_pile):
    """The compiled global frame gives numpy's broadcast sum p n + q1 t1 + q2 t2 (and r1 t1 + r2 t2)
    bit for bit: the same sums in the same order, so a run's warm starts did not change."""
    _, found = collapse_program(solver_pile)
    forces = np.random.default_rng(5).normal(size=(found.m, 5))
    warm = WarmStart.from_step(found, forces)
    expected_force = forces[:, :1] * found.normal + forces[:, 1:2] * found.tangent1 + forces[:, 2:3] * found.tangent2
    expected_rolling = forces[:, 3:4] * found.tangent1 + forces[:, 4:5] * found.tangent2
    assert np.array_equal(warm.force, expected_force) and np.array_equal(warm.rolling, expected_rolling)
    assert np.array_equal(warm.i, found.i) and np.array_equal(warm.j, found.j)


def test_pair_keys_tell_every_pair_apart():
    """One key a pair of bodies, whatever the particles' number: particle pairs, the floor and the
    cylinder (wall j = -1, told apart by family) and fixed spheres (j = -2 - k) of the same particle
    all differ, and the same pair gives the same key; the scalar code that the GPU compiles
    (pair_key) gives each one exactly."""
    from colsim.engine.state import CYLINDER, FLOOR, PARTICLE, fixed_code, pair_key, pair_keys

    i = np.array([0, 0, 0, 0, 0, 0, 1, 7, 2**31 - 9])
    j = np.array([1, 2, -1, -1, fixed_code(0), fixed_code(1), 0, fixed_code(2**31 - 11), 2**31 - 10])
    family = np.array([PARTICLE, PARTICLE, FLOOR, CYLINDER, PARTICLE, PARTICLE, PARTICLE, PARTICLE, PARTICLE])
    keys = pair_keys(i, j, family)
    assert keys.dtype == np.int64 and len(np.unique(keys)) == len(keys) and np.all(keys >= 0)
    assert np.array_equal(pair_keys(i, j, family), keys)
    assert [pair_key(int(a), int(b), int(c)) for a, b, c in zip(i, j, family)] == keys.tolist()
