"""The warm start's matching on the GPU (colsim.engine.cuda_warm_start, issue 46.3) is the CPU's
(WarmStart.match): the same pairs found, the same forces in the new frames, projected onto the same
cones. On numba's CUDA simulator here (conftest sets NUMBA_ENABLE_CUDASIM=1 unless told otherwise).

Bound 1e-14 of the largest force: the same products, summed over three components in the same order,
and the same projection (the CPU's vectorised, the GPU's the scalar code it mirrors)."""
import numpy as np
import pytest

from colsim.solvers import WarmStart

from solver_cases import collapse_program

pytest.importorskip("colsim.engine.cuda_warm_start", reason="numba.cuda is not importable")


def _both(warm: WarmStart, contacts, n: int):
    gpu, cpu = warm.match(contacts, n, "cuda"), warm.match(contacts, n)
    np.testing.assert_allclose(gpu, cpu, rtol=0, atol=1e-14 * max(np.abs(cpu).max(), 1.0))
    return gpu, cpu


def test_the_gpu_matches_the_cpu_s_pairs_and_forces(solver_pile):
    """The 90-sphere pile's contacts (particles, floor, cylinder) with forces partly outside their
    cones (so the projection acts), matched to the same contacts, then with a fifth of the stored
    pairs gone (those start from zero on both), then after a renumbering that drops a third of the
    particles (the trim's)."""
    _, found = collapse_program(solver_pile)
    rng = np.random.default_rng(46)
    forces = rng.uniform(0.0, 1.0, (found.m, 5)) * [1.0, 0.8, 0.8, 0.2, 0.2]
    warm = WarmStart.from_step(found, forces)
    gpu, cpu = _both(warm, found, solver_pile.n)
    assert not np.allclose(cpu, forces)                    # some were outside their cones
    keep = rng.uniform(size=warm.m) > 0.2
    fewer = WarmStart(warm.i[keep], warm.j[keep], warm.family[keep], warm.force[keep], warm.rolling[keep])
    gpu, _ = _both(fewer, found, solver_pile.n)
    assert np.all(gpu[~keep] == 0.0) and np.any(gpu[keep] != 0.0)
    particles = np.ones(solver_pile.n, dtype=bool)
    particles[::3] = False
    column = solver_pile.subset(particles)
    _, found_after = collapse_program(column)
    _both(warm.subset(particles), found_after, column.n)


def test_nothing_stored_or_no_contacts_give_zeros(solver_pile):
    _, found = collapse_program(solver_pile)
    empty = WarmStart(*(np.zeros(0, dtype=np.int64) for _ in range(3)), np.zeros((0, 3)), np.zeros((0, 3)))
    assert np.all(empty.match(found, solver_pile.n, "cuda") == 0.0)
