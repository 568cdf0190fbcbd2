"""Contact detection (colsim.engine.contacts): what is found and its gaps, on arrangements whose
geometry is known exactly; the overlaps after a step; the tangent basis by property."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from colsim.engine.contacts import WALL, detect, overlaps, row_lengths, tangent_basis, touching_pairs
from colsim.engine.state import CYLINDER, FLOOR, PARTICLE, ContactLaw, ParticleState, Walls

finite = st.floats(-1.0, 1.0, allow_nan=False)
vectors = st.tuples(finite, finite, finite).map(np.array).filter(lambda v: np.linalg.norm(v) > 1e-3)


@given(st.lists(vectors, min_size=1, max_size=8))
def test_tangent_basis_is_orthonormal_and_right_handed(raw):
    """(t1, t2, n) orthonormal with det +1, i.e. t1 x t2 = n, to 1e-12 (rounding of unit vectors)."""
    n = np.array([v / np.linalg.norm(v) for v in raw])
    t1, t2 = tangent_basis(n)
    frame = np.stack([t1, t2, n], axis=2)  # columns t1, t2, n
    gram = np.einsum("kia,kib->kab", frame, frame)
    np.testing.assert_allclose(gram, np.broadcast_to(np.eye(3), gram.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(frame), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.cross(t1, t2), n, atol=1e-12)


def test_row_lengths_are_numpy_s_norms_bit_for_bit():
    """The detection's row lengths equal np.linalg.norm(axis=1) exactly: the same squares summed in
    the same order (x, y, z), so the contacts' gaps and normals keep their bits; also over a
    strided view, and for no rows."""
    rows = np.random.default_rng(3).normal(size=(10_001, 3)) * np.array([1e-8, 1.0, 1e8])
    for vectors in (rows, rows[::3], rows[:0], np.asfortranarray(rows)):
        assert np.array_equal(row_lengths(vectors), np.linalg.norm(vectors, axis=1))


def _three_spheres():
    """A (r = 0.2) and B (r = 0.3) on the floor, centres 0.55 apart in x; C (r = 0.25) far
    above; a cylinder of radius 1 whose wall is 0.15 from B."""
    position = [[0.0, 0.0, 0.2], [0.55, 0.0, 0.3], [0.0, 0.0, 5.0]]
    return ParticleState.at_rest(position, [0.2, 0.3, 0.25]), Walls(floor=True, cylinder_radius=1.0)


def test_detect_finds_the_pairs_and_walls_within_the_margin_with_exact_gaps():
    state, walls = _three_spheres()
    found = detect(state, walls, ContactLaw.uniform(0.5, 0.1), np.zeros((3, 3)), margin=0.16, slack=0.0)
    by_body = {(int(i), int(j), int(f)): k for k, (i, j, f) in enumerate(zip(found.i, found.j, found.family))}
    assert set(by_body) == {(0, 1, PARTICLE), (0, WALL, FLOOR), (1, WALL, FLOOR), (1, WALL, CYLINDER)}
    pair, floor_b, cylinder_b = by_body[(0, 1, PARTICLE)], by_body[(1, WALL, FLOOR)], by_body[(1, WALL, CYLINDER)]
    assert found.gap[pair] == pytest.approx(np.hypot(0.55, 0.1) - 0.5, abs=1e-15)
    np.testing.assert_allclose(found.normal[pair], np.array([0.55, 0.0, 0.1]) / np.hypot(0.55, 0.1),
                               atol=1e-15)                                      # from i towards j
    assert found.gap[floor_b] == pytest.approx(0.0, abs=1e-15)
    np.testing.assert_allclose(found.normal[floor_b], [0.0, 0.0, -1.0], atol=1e-15)  # towards the wall
    assert found.gap[cylinder_b] == pytest.approx(1.0 - 0.55 - 0.3, abs=1e-15)
    # the paper's lever between spheres (2 R_i R_j / (R_i + R_j)), R_i at a wall; the floor's mu, the cylinder's 0
    assert found.lever[pair] == pytest.approx(2 * 0.2 * 0.3 / 0.5)
    assert found.lever[floor_b] == pytest.approx(0.3)
    assert found.mu[floor_b] == 0.5 and found.mu[cylinder_b] == 0.0


def test_a_smaller_margin_leaves_the_far_pair_out_and_predicted_motion_brings_it_back():
    state, walls = _three_spheres()
    law = ContactLaw.uniform(0.5, 0.1)
    found = detect(state, walls, law, np.zeros((3, 3)), margin=0.01, slack=0.0)
    assert not np.any(found.family == PARTICLE)
    moving = np.zeros((3, 3))
    moving[0, 0] = 0.07                       # A predicted to close the 0.059 gap
    found = detect(state, walls, law, moving, margin=0.01, slack=0.0)
    assert np.count_nonzero(found.family == PARTICLE) == 1


def test_the_pairs_come_sorted_and_are_every_pair_within_the_margin():
    """300 spheres at random, at rest: the particle pairs are exactly those whose gap is below the
    margin (brute force over all pairs), listed in increasing (i, j) (the order the solver's
    kernels read memory best in)."""
    rng = np.random.default_rng(4)
    radius = rng.uniform(0.125, 0.25, 300)
    state = ParticleState.at_rest(rng.uniform(0.0, 3.0, (300, 3)), radius)
    found = detect(state, Walls(floor=False), ContactLaw.uniform(0.5, 0.1), np.zeros((300, 3)), margin=0.05,
                   slack=0.0)
    i, j = found.i[found.family == PARTICLE], found.j[found.family == PARTICLE]
    keys = i * 300 + j
    assert np.all(i < j) and np.all(np.diff(keys) > 0)
    gap = np.linalg.norm(state.position[:, None] - state.position[None], axis=2) - radius[:, None] - radius[None]
    want = {(a, b) for a, b in zip(*np.nonzero(gap < 0.05)) if a < b}
    assert set(zip(i.tolist(), j.tolist())) == want


def test_moving_pairs_are_every_pair_whose_swept_segment_comes_within_reach():
    """300 spheres at random with random predicted motions up to 0.6 (twice the largest radius, as
    in a pour's impacts): the particle pairs are exactly those whose relative segment d0 + tau du,
    tau in [0, 1], comes within margin + slack |du| of contact (brute force over all pairs in numpy;
    the detection tests it in a compiled loop over the k-d tree's candidates)."""
    rng = np.random.default_rng(5)
    radius = rng.uniform(0.125, 0.25, 300)
    state = ParticleState.at_rest(rng.uniform(0.0, 3.0, (300, 3)), radius)
    predicted = rng.uniform(-0.3, 0.3, (300, 3))
    margin, slack = 0.05, 0.5
    found = detect(state, Walls(floor=False), ContactLaw.uniform(0.5, 0.1), predicted, margin=margin,
                   slack=slack)
    i, j = found.i[found.family == PARTICLE], found.j[found.family == PARTICLE]
    assert np.all(np.diff(i * 300 + j) > 0)
    a, b = np.triu_indices(300, 1)
    d0 = state.position[b] - state.position[a]
    du = predicted[b] - predicted[a]
    du2 = np.sum(du * du, axis=1)
    tau = np.clip(-np.sum(d0 * du, axis=1) / du2, 0.0, 1.0)
    closest = np.linalg.norm(d0 + tau[:, None] * du, axis=1) - radius[a] - radius[b]
    within = closest < margin + slack * np.sqrt(du2)
    assert 100 < np.count_nonzero(within) < len(a) // 10      # a test with pairs both in and out
    # exact: the kernel does the same arithmetic in the same order; only a pair within rounding
    # (1e-16 relative) of its reach could differ, and these seeded spheres have none
    assert set(zip(i.tolist(), j.tolist())) == set(zip(a[within].tolist(), b[within].tolist()))


def test_overlaps_measure_each_body_and_touching_pairs_use_the_tolerance():
    position = [[0.0, 0.0, 0.19], [0.39, 0.0, 0.2], [0.0, 0.75, 0.3]]
    state = ParticleState.at_rest(position, [0.2, 0.2, 0.3])
    measured = overlaps(state, Walls(floor=True, cylinder_radius=1.0), tolerance=0.001)
    assert measured.largest_pair == pytest.approx(0.4 - np.hypot(0.39, 0.01))
    assert measured.largest_floor == pytest.approx(0.01)
    np.testing.assert_allclose(measured.cylinder, [0.0, 0.0, 0.05], atol=1e-15)
    assert measured.largest == pytest.approx(0.05)
    assert list(zip(*measured.pairs[:2])) == [(0, 1)]
    i, j = touching_pairs(state, tolerance=0.1)
    assert list(zip(i, j)) == [(0, 1)]                  # A-C: gap 0.758 - 0.5 > 0.1
