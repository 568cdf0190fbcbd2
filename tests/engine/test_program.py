"""One step's cone program (colsim.engine.program): the contact Jacobian by property."""
from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from colsim.engine.contacts import WALL, Contacts, tangent_basis
from colsim.engine.program import contact_jacobian
from colsim.engine.state import FLOOR, PARTICLE

finite = st.floats(-1.0, 1.0, allow_nan=False)
vectors = st.tuples(finite, finite, finite).map(np.array).filter(lambda v: np.linalg.norm(v) > 1e-3)


def _contacts(i, j, normal, radius):
    i, j = np.asarray(i), np.asarray(j)
    normal = np.asarray(normal, float).reshape(-1, 3)
    t1, t2 = tangent_basis(normal)
    ri = radius[i]
    rj = np.where(j >= 0, radius[np.maximum(j, 0)], 0.0)
    reff = np.where(j >= 0, ri * rj / (ri + rj), ri)
    m = len(i)
    return Contacts(i=i, j=j, family=np.where(j >= 0, PARTICLE, FLOOR), normal=normal, tangent1=t1,
                    tangent2=t2, gap=np.zeros(m), radius_i=ri, radius_j=rj, lever=reff,
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
        expected = [n @ du, t1 @ du, t2 @ du, contacts.lever[k] * (t1 @ rot),
                    contacts.lever[k] * (t2 @ rot)]
        np.testing.assert_allclose(local[k], expected, atol=1e-12)
    np.testing.assert_allclose(local[0, 0], normal @ (dx[2] - dx[0]), atol=1e-12)
    # Newton's third law: any pair force lam acts on the two particles with opposite net forces
    lam = np.zeros(10)
    lam[:5] = rng.normal(size=5)
    generalised = B.T @ lam
    np.testing.assert_allclose(generalised[0:3] + generalised[6:9], 0.0, atol=1e-12)


def test_the_assembly_s_masses_and_free_forces_are_the_formulas_bit_for_bit():
    """assemble fills Mbar = diag(m, m, m, ..., I, I, I, ...)/dt^2 and fbar = [m v/dt + m g; I w/dt]
    in one compiled pass over the bodies: the same operations as the formulas written out, so the
    same bits (and the program shares the contacts' gaps and coefficients, not copies)."""
    from colsim.engine.program import assemble
    from colsim.engine.state import ParticleState

    rng = np.random.default_rng(11)
    n, dt, gravity = 37, 1.7e-3, np.array([0.1, -0.2, -9.81])
    state = ParticleState(rng.uniform(size=(n, 3)), rng.normal(size=(n, 3)), rng.normal(size=(n, 3)),
                          rng.uniform(0.3, 0.7, n), density=2.5)
    contacts = Contacts(*(np.zeros(0, np.int64) for _ in range(3)), *(np.zeros((0, 3)) for _ in range(3)),
                        *(np.zeros(0) for _ in range(6)))
    program = assemble(state, contacts, dt, gravity)
    m, inertia = state.mass, 0.4 * state.mass * state.radius**2
    assert np.array_equal(program.mass, np.concatenate([np.repeat(m, 3), np.repeat(inertia, 3)]) / dt**2)
    translation = m[:, None] * state.velocity / dt + m[:, None] * gravity[None, :]
    assert np.array_equal(program.fbar, np.concatenate([translation.ravel(),
                                                        (inertia[:, None] * state.angular_velocity / dt).ravel()]))
    assert program.gap is contacts.gap and program.mu is contacts.mu and program.mu_r is contacts.mu_r
