"""Engine kernels by property (tangent basis, contact Jacobian) and the engine's two failure modes:
a missed contact (redo or OverlapError) and a solver that does not converge (SolverError)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from colsim.engine.contacts import WALL, Contacts, overlaps, tangent_basis
from colsim.engine.program import contact_jacobian
from colsim.solvers import ClarabelSolver, SolverError
from colsim.engine.state import FLOOR, PARTICLE, ContactLaw, ParticleState, StepSettings, Walls
from colsim.engine.stepper import OverlapError, base_margin, next_margin, step

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


def _contacts(i, j, normal, radius):
    i, j = np.asarray(i), np.asarray(j)
    normal = np.asarray(normal, float).reshape(-1, 3)
    t1, t2 = tangent_basis(normal)
    ri = radius[i]
    rj = np.where(j >= 0, radius[np.maximum(j, 0)], 0.0)
    reff = np.where(j >= 0, ri * rj / (ri + rj), ri)
    m = len(i)
    return Contacts(i=i, j=j, family=np.where(j >= 0, PARTICLE, FLOOR), normal=normal, tangent1=t1,
                    tangent2=t2, gap=np.zeros(m), radius_i=ri, radius_j=rj, rolling_radius=reff,
                    mu=np.full(m, 0.5), mu_r=np.full(m, 0.1))


@settings(max_examples=50, deadline=None)
@given(n_dir=vectors, radii=st.tuples(st.floats(0.1, 0.3), st.floats(0.1, 0.3), st.floats(0.1, 0.3)),
       seed=st.integers(0, 2**31 - 1))
def test_jacobian_rows_are_the_relative_displacement(n_dir, radii, seed):
    """Rows of B for a pair (0, 2) and a wall contact of 1 against SPEC section 2, to 1e-12:
    du = (dx_j - R_j dth_j x n) - (dx_i + R_i dth_i x n), B u = (n.du, T'du, R_eff T'(dth_j - dth_i)).
    The normal row of the pair is n.(dx_j - dx_i): rotations do not move a contact along n."""
    radius = np.array(radii)
    normal = n_dir / np.linalg.norm(n_dir)
    contacts = _contacts([0, 1], [2, WALL], [normal, [0.0, 0.0, -1.0]], radius)
    B = contact_jacobian(contacts, 3)
    rng = np.random.default_rng(seed)
    u = rng.normal(size=18)
    dx, dth = u[:9].reshape(3, 3), u[9:].reshape(3, 3)
    local = (B @ u).reshape(-1, 5)
    for k, (a, b) in enumerate([(0, 2), (1, WALL)]):
        n, t1, t2 = contacts.normal[k], contacts.tangent1[k], contacts.tangent2[k]
        du = -(dx[a] + radius[a] * np.cross(dth[a], n))
        rot = -dth[a]
        if b >= 0:
            du += dx[b] - radius[b] * np.cross(dth[b], n)
            rot = rot + dth[b]
        expected = [n @ du, t1 @ du, t2 @ du, contacts.rolling_radius[k] * (t1 @ rot),
                    contacts.rolling_radius[k] * (t2 @ rot)]
        np.testing.assert_allclose(local[k], expected, atol=1e-12)
    np.testing.assert_allclose(local[0, 0], normal @ (dx[2] - dx[0]), atol=1e-12)
    # Newton's third law: any pair force lam acts on the two particles with opposite net forces
    lam = np.zeros(10)
    lam[:5] = rng.normal(size=5)
    generalised = B.T @ lam
    np.testing.assert_allclose(generalised[0:3] + generalised[6:9], 0.0, atol=1e-12)


# --- missed contacts ---------------------------------------------------------------------------

def _train(max_redo: int):
    """Sphere C (x = 0) flies at 2 along +x into A (resting, gap 0.001); B rests 0.01 beyond A.

    Gravity off, no walls, detection margin 1e-6 d and no slack: A-B is not predicted (neither
    moves in free flight), but C pushes A about 0.02 in the step, into B.
    """
    radius = np.full(3, 0.2)
    position = np.array([[0.0, 0, 0], [0.401, 0, 0], [0.811, 0, 0]])
    velocity = np.array([[2.0, 0, 0], [0, 0, 0], [0, 0, 0]])
    state = ParticleState(position, velocity, np.zeros((3, 3)), radius)
    settings = StepSettings(dt=0.02, gravity=(0.0, 0.0, 0.0), walls=Walls(floor=False),
                            law=ContactLaw.uniform(0.3, 0.0), detection_margin_fraction=1e-6,
                            detection_slack=0.0, max_redo=max_redo)
    return state, settings


def test_missed_contact_is_redone():
    """The first attempt overlaps A and B by ~0.009 (> tolerance 0.004); the step is redone with
    the missed pair and ends within the tolerance, conserving momentum (1e-9 relative: no external
    force; Clarabel's tolerance)."""
    state, settings = _train(max_redo=3)
    result = step(state, settings, ClarabelSolver(), step_number=5)
    tolerance = settings.overlap_tolerance * 0.4
    assert result.diagnostics.redone >= 1
    assert result.diagnostics.largest_overlap <= tolerance
    assert overlaps(result.state, settings.walls).largest <= tolerance
    assert result.contacts.m >= 2  # C-A and the added A-B
    momentum = (result.state.mass[:, None] * result.state.velocity).sum(axis=0)
    np.testing.assert_allclose(momentum, (state.mass[:, None] * state.velocity).sum(axis=0),
                               rtol=1e-9, atol=1e-9 * state.mass[0] * 2.0)
    assert result.state.velocity[2, 0] > 0.1  # B was pushed: the contact was really taken


def test_next_step_starts_from_the_margin_that_caught_the_missed_pair():
    """The redone step records the missed pair and its grown margin; the next step starts there,
    and each clean step after that halves it, down to the base margin (here 1e-6 d)."""
    state, settings = _train(max_redo=3)
    result = step(state, settings, ClarabelSolver(), step_number=5)
    base = base_margin(state, settings)
    d = result.diagnostics
    assert d.missed_contacts >= 1
    assert d.detection_margin == pytest.approx(base * settings.margin_growth ** d.redone)
    assert next_margin(d, base) == d.detection_margin
    clean = replace(d, redone=0, missed_contacts=0)
    assert next_margin(clean, base) == pytest.approx(0.5 * d.detection_margin)
    assert next_margin(replace(clean, detection_margin=base), base) == base


def test_missed_contact_without_redo_raises():
    """With no redo allowed the overlapping step is an OverlapError naming the step, not a result."""
    state, settings = _train(max_redo=0)
    with pytest.raises(OverlapError, match="step 5"):
        step(state, settings, ClarabelSolver(), step_number=5)


# --- solver failure ----------------------------------------------------------------------------

def test_unconverged_solver_raises_with_step_and_status():
    """Clarabel stopped after one iteration: SolverError names the step (17) and the status."""
    state = ParticleState.at_rest([[0.0, 0.0, 0.2]], [0.2])
    settings = StepSettings(dt=0.02, law=ContactLaw.uniform(0.5, 0.1))
    with pytest.raises(SolverError) as caught:
        step(state, settings, ClarabelSolver(max_iter=1), step_number=17)
    error = caught.value
    assert error.step == 17
    assert error.status == "MaxIterations"
    assert "step 17" in str(error) and "MaxIterations" in str(error)
