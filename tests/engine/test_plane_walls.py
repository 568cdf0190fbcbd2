"""Plane walls (a channel's back wall, sidewalls and gate: colsim.engine.state.Walls.planes): their
contacts, their friction and rolling as the floor's, a box at rest between them, and APGD against
Clarabel on them."""
from __future__ import annotations

import math

import numpy as np
import pytest

from colsim.engine.contacts import detect, overlaps
from colsim.engine.program import assemble
from colsim.engine.state import (CYLINDER, FLOOR, PLANE, ContactLaw, ParticleState, StepSettings, Walls,
                                 channel_planes, law_family, pair_keys)
from colsim.engine.stepper import run
from colsim.solvers import ClarabelSolver
from colsim.solvers.apgd import ApgdSolver

G = 9.81
RADIUS = 0.2


def test_a_channel_s_planes_face_into_the_box():
    """channel_planes: the back wall x = 0, the sidewalls y = -W/2 and y = +W/2 and the gate x = L0,
    each normal into the box; a point of the box is on the inner side of each."""
    planes = np.array(channel_planes(2.0, 0.8, gate=True))
    inside = np.array([1.0, 0.1, 0.3])
    np.testing.assert_array_equal(planes @ np.append(inside, -1.0) > 0, True)
    assert [tuple(p) for p in planes] == [(1, 0, 0, 0), (0, 1, 0, -0.4), (0, -1, 0, -0.4), (-1, 0, 0, -2.0)]
    assert len(channel_planes(2.0, 0.8, gate=False)) == 3


@pytest.mark.parametrize("planes", [((0.0, 0.0, 2.0, 0.0),), ((1.0, 0.0, 0.0, math.inf),), ((1.0, 0.0, 0.0),),
                                    ((1.0, 0.0, 0.0, 0.0),) * 6])
def test_a_plane_that_is_no_wall_is_refused(planes):
    with pytest.raises(ValueError, match="plane"):
        Walls(planes=planes)


def test_a_sphere_in_a_corner_has_a_contact_with_each_wall_told_apart():
    """A sphere in the corner of the back wall, a sidewall and the floor: three wall contacts, the
    planes' families PLANE + p with the wall's coefficients (law_family), the floor's its own; every
    contact's normal out of the sphere, its gap the distance less the radius; three distinct keys."""
    state = ParticleState.at_rest([[RADIUS + 0.01, -0.4 + RADIUS + 0.02, RADIUS + 0.03]], [RADIUS])
    walls = Walls(floor=True, planes=channel_planes(2.0, 0.8, gate=True))
    law = ContactLaw(mu=(0.5, 0.6, 0.3), mu_r=(0.1, 0.12, 0.05))
    found = detect(state, walls, law, np.zeros((1, 3)), margin=0.05)
    assert sorted(found.family.tolist()) == [FLOOR, PLANE, PLANE + 1]
    by_family = {int(f): k for k, f in enumerate(found.family)}
    np.testing.assert_allclose(found.gap[[by_family[FLOOR], by_family[PLANE], by_family[PLANE + 1]]],
                               [0.03, 0.01, 0.02], rtol=0, atol=1e-15)
    np.testing.assert_array_equal(found.normal[by_family[PLANE]], [-1.0, 0.0, 0.0])
    np.testing.assert_array_equal(found.normal[by_family[PLANE + 1]], [0.0, -1.0, 0.0])
    np.testing.assert_array_equal(found.mu, np.where(found.family == FLOOR, 0.6, 0.3))
    np.testing.assert_array_equal(found.mu_r, np.where(found.family == FLOOR, 0.12, 0.05))
    np.testing.assert_array_equal(found.lever, RADIUS)   # at a wall the lever is R_i
    assert len(set(pair_keys(found.i, found.j, found.family).tolist())) == 3
    assert law_family(PLANE + 3) == CYLINDER


def test_an_overlap_with_a_plane_is_measured():
    """The plane overlap R - (n . x - offset) of the deepest sphere; none where all are clear."""
    state = ParticleState.at_rest([[1.0, 0.4 - RADIUS + 0.003, 1.0], [1.0, -0.1, 0.5]], [RADIUS, RADIUS])
    walls = Walls(floor=True, planes=channel_planes(2.0, 0.8, gate=True))
    found = overlaps(state, walls)
    assert found.largest_plane == pytest.approx(0.003, abs=1e-15) and found.largest == found.largest_plane
    assert found.largest_pair == 0.0 and found.largest_floor == 0.0
    assert overlaps(state.subset([1]), walls).largest_plane == 0.0


def _box(nx: int, ny: int, nz: int) -> ParticleState:
    """Equal spheres of RADIUS on a simple cubic lattice filling the channel box of nx by ny by nz
    diameters exactly: each touches its neighbours, the floor and the walls beside it."""
    d = 2.0 * RADIUS
    grid = np.stack(np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij"), -1).reshape(-1, 3)
    position = (grid + 0.5) * d - [0.0, 0.5 * ny * d, 0.0]
    return ParticleState.at_rest(position, np.full(len(position), RADIUS))


def test_a_settled_box_between_the_walls_stays_at_rest():
    """12 spheres in a 3 x 2 x 2 box, touching the back wall, both sidewalls, the gate and the floor,
    under the collapse's friction: 20 steps of dt = 0.01 move none of them. Bound: 1e-6 of the free
    fall over the run (g T), as the engine's rest cases (engine/test_analytic); Clarabel at 1e-12."""
    state = _box(3, 2, 2)
    walls = Walls(floor=True, planes=channel_planes(3 * 2 * RADIUS, 2 * 2 * RADIUS, gate=True))
    settings = StepSettings(dt=0.01, walls=walls, law=ContactLaw(mu=(0.577, 0.577, 0.3), mu_r=(0.12, 0.12, 0.12)))
    steps = 20
    results = list(run(state, settings, steps, ClarabelSolver(tolerance=1e-12)))
    last = results[-1].state
    assert {int(f) for f in results[-1].contacts.family} == {0, FLOOR, PLANE, PLANE + 1, PLANE + 2, PLANE + 3}
    bound = 1e-6 * G * steps * settings.dt
    assert np.abs(last.velocity).max() <= bound
    assert np.abs(last.angular_velocity).max() * RADIUS <= bound
    assert np.abs(last.position - state.position).max() <= bound * steps * settings.dt


def _rolling(mu: float, mu_r: float, theta: float, against_wall: bool, steps: int = 20, dt: float = 0.02):
    """Velocities and angular velocities (steps, 3) of one sphere on a tilted floor, or against a
    sidewall with gravity turned onto it: the floor's case turned by -90 degrees about x, which takes
    (a, b, c) to (a, c, -b) (z onto y). The floor's own coefficients (9.0) differ from the sidewall's,
    so that the sidewall's case uses the wall's."""
    gravity = np.array([G * math.sin(theta), 0.0, -G * math.cos(theta)])
    start = np.array([0.0, 0.0, RADIUS])
    law = ContactLaw(mu=(mu, 9.0, mu), mu_r=(mu_r, 9.0, mu_r))
    if against_wall:
        gravity, start = _turned(gravity), _turned(start)
        walls = Walls(floor=False, planes=((0.0, 1.0, 0.0, 0.0),))
    else:
        law = ContactLaw(mu=(mu, mu, 0.0), mu_r=(mu_r, mu_r, 0.0))
        walls = Walls(floor=True)
    settings = StepSettings(dt=dt, gravity=tuple(gravity), walls=walls, law=law)
    state = ParticleState.at_rest([start], [RADIUS])
    out = [(r.state.velocity[0], r.state.angular_velocity[0]) for r in run(state, settings, steps,
                                                                            ClarabelSolver(tolerance=1e-12))]
    return tuple(np.array(x) for x in zip(*out))


def _turned(vectors):
    """Vectors (..., 3) turned by -90 degrees about x: (a, b, c) -> (a, c, -b)."""
    vectors = np.asarray(vectors)
    return np.stack([vectors[..., 0], vectors[..., 2], -vectors[..., 1]], axis=-1)


@pytest.mark.parametrize("mu, mu_r, ratio", [(10.0, 0.12, 2.0), (0.577, 10.0, 1.5), (10.0, 0.12, 0.5)],
                         ids=["rolls", "slides", "rests"])
def test_a_sphere_against_a_sidewall_moves_as_on_the_floor(mu, mu_r, ratio):
    """The sidewall y = 0 with gravity turned onto it: the sphere rolls (mu_r active, tan theta =
    2 mu_r), slides (mu active, 1.5 mu) or rests (0.5 mu_r) exactly as on the floor, its velocities
    and angular velocities the floor's turned. Both cones have the same local coordinates up to the
    tangents' orientation (different helpers make them), so the programs are the same up to that
    rotation: 1e-8 of the speed g T (Clarabel at 1e-12; the interior point's iterates differ by
    rounding). The rolling case is checked against a = 5/7 g (sin - mu_r cos) too, to 1e-2 (the
    first steps' transient of engine/test_analytic at dt = 0.02 is within 2e-3)."""
    threshold = mu_r if mu > mu_r else mu
    theta = math.atan(ratio * threshold)
    floor_v, floor_w = _rolling(mu, mu_r, theta, against_wall=False)
    wall_v, wall_w = _rolling(mu, mu_r, theta, against_wall=True)
    scale = G * 20 * 0.02
    np.testing.assert_allclose(wall_v, _turned(floor_v), rtol=0, atol=1e-8 * scale)
    np.testing.assert_allclose(wall_w * RADIUS, _turned(floor_w) * RADIUS, rtol=0, atol=1e-8 * scale)
    if ratio > 1 and mu > mu_r:
        a_star = 5.0 / 7.0 * G * (math.sin(theta) - mu_r * math.cos(theta))
        assert wall_v[-1, 0] / (20 * 0.02) == pytest.approx(a_star, rel=1e-2)
    if ratio < 1:
        assert np.abs(wall_v).max() <= 1e-6 * scale


def test_a_sidewall_s_friction_is_clarabel_s_and_apgd_s():
    """Spheres pressed onto a sidewall (gravity toward it) and driven along it hard enough to slide:
    Clarabel's solution carries, at each sliding sphere's wall contact, a friction force of wall_mu
    times its normal force (the cone's edge, to 1e-6 relative: Clarabel at 1e-10), and APGD at 1e-8
    finds the same increments and net contact forces to 1e-4 (APGD's relative tolerance, less a margin
    as test_apgd's bounds)."""
    wall_mu = 0.3
    n = 4
    position = np.c_[np.arange(n) * 3.0 * RADIUS, np.full(n, RADIUS), np.full(n, 1.0)]
    state = ParticleState(position, np.tile([1.0, 0.0, 0.0], (n, 1)), np.zeros((n, 3)), np.full(n, RADIUS))
    walls = Walls(floor=False, planes=((0.0, 1.0, 0.0, 0.0),))
    law = ContactLaw(mu=(0.5, 0.5, wall_mu), mu_r=(0.0, 0.0, 0.0))
    dt = 0.01
    gravity = (2.0, -G, 0.0)
    found = detect(state, walls, law, np.zeros((n, 3)), margin=0.05)
    program = assemble(state, found, dt, gravity)
    clarabel = ClarabelSolver(tolerance=1e-10).solve(program)
    forces = clarabel.forces
    assert found.m == n and np.all(found.family == PLANE)
    np.testing.assert_allclose(np.linalg.norm(forces[:, 1:3], axis=1), wall_mu * forces[:, 0], rtol=1e-6)
    assert np.all(forces[:, 0] > 0)
    apgd = ApgdSolver(tolerance=1e-8).solve(program)
    du = np.linalg.norm(apgd.increments - clarabel.increments) / np.linalg.norm(clarabel.increments)
    net, net_ref = (program.jacobian.T @ f.ravel() for f in (apgd.forces, clarabel.forces))
    assert du <= 1e-4 and np.linalg.norm(net - net_ref) / np.linalg.norm(net_ref) <= 1e-4


def test_an_overlap_up_to_the_kept_one_is_kept_and_not_asked_back():
    """recovery_relaxation with kept: an overlap up to `kept` is kept as it is (g_eff = 0), a larger
    one shrinks towards it by at most most_recovered, a gap is left alone; kept 0 is the plain
    relaxation, bit for bit."""
    from colsim.engine.contacts import recovery_relaxation

    gap = np.array([0.01, -0.001, -0.003, -0.01])
    np.testing.assert_array_equal(gap + recovery_relaxation(gap, 0.002, kept=0.003), [0.01, 0.0, 0.0, -0.002])
    np.testing.assert_array_equal(recovery_relaxation(gap, 0.002, kept=0.0), np.maximum(0.0, -gap - 0.002))


def test_a_chain_from_sidewall_to_sidewall_keeps_its_overlap_instead_of_failing():
    """Two spheres on the floor of a slot just under two diameters wide, each touching a sidewall,
    overlapping each other by 1e-4 of a diameter along the slot's width. Under the associated law with
    wall friction, each sphere can leave its wall only by dilating, so the walls' constraints allow
    no motion that parts the two: asking their overlap back leaves the step no solution (Clarabel:
    infeasible). With the overlap kept (overlap_kept 0.005 of a diameter, a channel's collapse's), the
    step keeps it as it is (to Clarabel's 1e-8) and the spheres stay at rest."""
    from colsim.engine.solver_contract import SolverError

    overlap = 1e-4 * 2 * RADIUS
    width = 4 * RADIUS - overlap
    state = ParticleState.at_rest([[1.0, -width / 2 + RADIUS, RADIUS], [1.0, width / 2 - RADIUS, RADIUS]],
                                  [RADIUS, RADIUS])
    walls = Walls(floor=True, planes=channel_planes(2.0, width, gate=False)[1:])
    law = ContactLaw(mu=(0.577, 0.577, 0.577), mu_r=(0.12, 0.12, 0.12))
    asked_back = StepSettings(dt=0.01, walls=walls, law=law, overlap_recovery=None)
    with pytest.raises(SolverError, match="nfeasible"):
        list(run(state, asked_back, 1, ClarabelSolver()))
    kept = StepSettings(dt=0.01, walls=walls, law=law, overlap_recovery=None, overlap_kept=0.005)
    last = list(run(state, kept, 3, ClarabelSolver(tolerance=1e-10)))[-1].state
    distance = np.linalg.norm(last.position[1] - last.position[0])
    assert 2 * RADIUS - distance == pytest.approx(overlap, abs=1e-8 * RADIUS)
    assert np.abs(last.velocity).max() <= 1e-6 * G * 0.03
