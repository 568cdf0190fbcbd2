"""Engine tests on the session's poured pile (the conftest fixture `pile`): rest, cones, balance, forms, overlaps."""
from __future__ import annotations


import numpy as np
import pytest

from colsim.engine.contacts import detect, overlaps
from colsim.engine.program import assemble, cone_violation
from colsim.solvers import ClarabelSolver
from colsim.engine.state import FLOOR, PARTICLE, FixedSpheres, ParticleState, StepSettings, Walls
from colsim.engine.backend import predicted_displacement
from colsim.engine.stepper import base_margin, next_margin, run, step
from colsim.engine.warm_start import WarmStart

from helpers import COLLAPSE_LAW, DT, G, max_speed


def collapse_settings(pile, cylinder=True) -> StepSettings:
    walls = Walls(floor=True, cylinder_radius=pile.cylinder_radius if cylinder else None)
    return StepSettings(dt=DT, walls=walls, law=COLLAPSE_LAW)


def test_pour_never_overlaps(pile):
    """Every one of the 150 pour steps ends with its largest overlap (measured afresh, not taken
    from the diagnostics) within the stepper's tolerance, 1 % of the smallest diameter."""
    assert len(pile.pour_overlaps) == 150
    assert max(pile.pour_overlaps) <= pile.overlap_tolerance
    # the pile really formed: the cloud started 0.16..7.1 high and spheres fell onto each other
    assert pile.poured.position[:, 2].max() < pile.cloud.position[:, 2].max() - 1.0


def test_settled_pile_does_not_creep(pile):
    """With the collapse's friction and the cylinder on, a settled pile stays put over 20 steps.

    Bound: max translational speed <= 1e-4 sqrt(g d) on every step (the speed at which the fixture
    called it settled), and not growing: the last step's is at most the first's (a wedged sphere may
    still sink at ~1e-5..1e-4 sqrt(g d), decaying by a few % a step; the interior point's own noise
    is ~1e-7 sqrt(g d)). No sphere drifts more than 5e-4 d in all (20 dt at that bound is 2e-4 d).
    Spin about contact normals is not resisted (r.n = 0), so rotation is not part of the criterion.
    """
    assert pile.lock_steps < 100, "the pile did not come to rest while the fixture locked it"
    state = pile.settled
    speeds = []
    for result in run(state, collapse_settings(pile), 20, ClarabelSolver()):
        speeds.append(max_speed(result.state))
    assert max(speeds) <= 1e-4 * pile.speed_scale
    assert speeds[-1] <= speeds[0]
    drift = np.linalg.norm(result.state.position - state.position, axis=1).max()
    assert drift <= 5e-4 * pile.mean_diameter


@pytest.fixture(scope="module")
def collapse_step(pile):
    """The first collapse step: cylinder removed, mu = 0.577, mu_r = 0.12. Contacts slide and roll."""
    settings = collapse_settings(pile, cylinder=False)
    result = step(pile.settled, settings, ClarabelSolver(), step_number=1)
    program = assemble(pile.settled, result.contacts, DT, settings.gravity)
    return result, program


def test_forces_inside_cones_and_complementary(pile, collapse_step):
    """p >= 0, ||q|| <= mu p, ||r|| <= mu_r p, and p = 0 where the gap stays open.

    Tolerances: 1e-6 m g (force, m g of a mean sphere) for the cones, 1e-6 d for the primal
    constraint, 1e-6 m g d for p times the constraint's slack; an open contact (slack > 1e-3 d)
    carries p <= 1e-6 m g. The interior point's tolerance is 1e-8 relative.
    """
    result, program = collapse_step
    u, forces = result.solution.increments, result.solution.forces
    violation = cone_violation(program, u, forces)
    mg, d = pile.weight_scale, pile.mean_diameter
    assert violation["dual"] <= 1e-6 * mg
    assert violation["primal"] <= 1e-6 * d
    assert violation["complementarity"] <= 1e-6 * mg * d
    local = program.local_displacement(u)
    slack = (program.gap + local[:, 0] - program.mu * np.linalg.norm(local[:, 1:3], axis=1)
             - program.mu_r * np.linalg.norm(local[:, 3:5], axis=1))
    open_ = slack > 1e-3 * d
    assert open_.sum() > 20 and (~open_).sum() > 100  # both kinds are there to test
    assert np.abs(forces[open_, 0]).max() <= 1e-6 * mg
    # the step is a real collapse step: some contacts slide (|q| = mu p) and some roll (|r| = mu_r p)
    p = forces[:, 0]
    loaded = p > 1e-3 * mg
    sliding = np.linalg.norm(forces[:, 1:3], axis=1) >= (1 - 1e-4) * program.mu * p
    rolling = np.linalg.norm(forces[:, 3:5], axis=1) >= (1 - 1e-4) * program.mu_r * p
    assert (loaded & sliding).sum() > 0 and (loaded & rolling).sum() > 0


def test_floor_carries_the_weight(pile):
    """Global force balance of the resting pile (cylinder on): sum of floor p = total m g.

    The cylinder is frictionless and vertical and friction on the floor is horizontal, so the floor's
    normal forces alone balance gravity and the pile's change of vertical momentum. Exactly (1e-8 of
    the weight: solver tolerance) sum p_floor = W + sum m (v_z' - v_z)/dt; and since the pile is at
    rest, sum p_floor = W within 1e-5 relative.
    """
    settings = collapse_settings(pile)
    state = pile.settled
    result = step(state, settings, ClarabelSolver(), step_number=1)
    floor = result.contacts.family == FLOOR
    floor_load = result.solution.forces[floor, 0].sum()
    weight = state.mass.sum() * G
    momentum_change = np.sum(state.mass * (result.state.velocity[:, 2] - state.velocity[:, 2])) / DT
    assert floor_load == pytest.approx(weight + momentum_change, rel=1e-8)
    assert floor_load == pytest.approx(weight, rel=1e-5)
    # and the floor contacts are many, not one sphere holding the pile
    assert np.count_nonzero(result.solution.forces[floor, 0] > 1e-3 * pile.weight_scale) > 10


def test_displacement_and_force_forms_agree(pile, collapse_step):
    """Both forms of Clarabel on the same program (the collapse step: friction and rolling resistance).

    The increments u are unique (strictly convex objective). The forces of a hyperstatic pile are
    not, so they are compared through what is unique: the generalised contact force B' lam on every
    particle. An interior point reaches the solution of these degenerate cone programs only to about
    sqrt(tolerance) (measured on this step, |du|/max|u|: 4e-4 at 1e-8, 4e-5 at 1e-10), so both run
    at 1e-10 and must agree to 2e-4 of max|u| and 1e-5 m g; each form's forces lie in their cones.
    """
    result, program = collapse_step
    displacement = ClarabelSolver(form="displacement", tolerance=1e-10).solve(program)
    force = ClarabelSolver(form="force", tolerance=1e-10).solve(program)
    scale = np.abs(displacement.increments).max()
    np.testing.assert_allclose(force.increments, displacement.increments, rtol=0, atol=2e-4 * scale)
    B = program.jacobian
    np.testing.assert_allclose(B.T @ force.forces.ravel(), B.T @ displacement.forces.ravel(),
                               rtol=0, atol=1e-5 * pile.weight_scale)
    for solution in (displacement, force):
        assert cone_violation(program, solution.increments, solution.forces)["dual"] <= 1e-6 * pile.weight_scale


def test_forms_agree_on_forces_of_a_determinate_stack():
    """Two spheres stacked on the floor under tilted gravity (2 contacts, 10 force unknowns, 12
    degrees of freedom: the forces are unique): both forms give the same (p, q, r).

    As above the agreement is about sqrt(tolerance): measured 2.6e-5, 6e-6, 1.4e-6 (force units,
    m g = 0.64) at 1e-8, 1e-10, 1e-12. Asserted: 1e-4 m g at 1e-10, and the gap at 1e-12 at least
    5x smaller than at 1e-8 (both forms converge to one solution; a formulation error would not
    shrink). The top sphere sits off-centre, so both contacts carry sliding and rolling forces.
    """
    from colsim.engine.state import ContactLaw, ParticleState

    radius = np.array([0.25, 0.15])
    position = np.array([[0.0, 0.0, 0.25], [0.1, 0.05, 0.25 + np.sqrt(0.4**2 - 0.1**2 - 0.05**2)]])
    state = ParticleState.at_rest(position, radius)
    gravity = (2.0, -1.0, -G)
    law = ContactLaw.uniform(0.3, 0.05)
    contacts = detect(state, Walls(floor=True), law, predicted_displacement(
        state, StepSettings(dt=DT, gravity=gravity)), margin=0.01)
    assert contacts.m == 2
    program = assemble(state, contacts, DT, gravity)
    mg = float(state.mass.max() * G)
    gaps = {}
    for tolerance in (1e-8, 1e-10, 1e-12):
        a = ClarabelSolver(form="displacement", tolerance=tolerance).solve(program)
        b = ClarabelSolver(form="force", tolerance=tolerance).solve(program)
        gaps[tolerance] = np.abs(a.forces - b.forces).max()
        if tolerance == 1e-10:
            np.testing.assert_allclose(a.forces, b.forces, rtol=0, atol=1e-4 * mg)
            np.testing.assert_allclose(a.increments, b.increments, rtol=0,
                                       atol=1e-3 * np.abs(a.increments).max())
    assert gaps[1e-12] <= gaps[1e-8] / 5
    assert np.all(np.abs(a.forces[:, 1:]) > 1e-3 * mg)  # every component is exercised


def test_fixed_spheres_carry_the_weight_of_what_rests_on_them(pile):
    """The settled pile with its lower half fixed (colsim.engine.state.FixedSpheres, as the packing's
    buried part while it fills): the upper half steps on them as on walls.

    Force balance as in test_floor_carries_the_weight: the frictionless vertical cylinder takes no
    vertical load, so the vertical support of the fixed spheres and the floor on the moving ones
    equals their weight plus their change of momentum, to 1e-8 (Clarabel's tolerance), and the
    weight within 1e-5 (the pile is at rest). Contacts with fixed sphere k have j = -2 - k, the
    particle law's family and the fixed sphere's radius; nothing passes into a fixed sphere."""
    state = pile.settled
    fixed = state.position[:, 2] < np.median(state.position[:, 2])
    upper = state.subset(~fixed)
    walls = Walls(floor=True, cylinder_radius=pile.cylinder_radius,
                  fixed=FixedSpheres(state.position[fixed], state.radius[fixed]))
    settings = StepSettings(dt=DT, walls=walls, law=COLLAPSE_LAW)
    result = step(upper, settings, ClarabelSolver(), step_number=1)
    c, forces = result.contacts, result.solution.forces
    on_fixed = c.j <= -2
    assert np.count_nonzero(on_fixed & (forces[:, 0] > 1e-3 * pile.weight_scale)) > 10
    k = -2 - c.j[on_fixed]
    assert np.all(c.family[on_fixed] == PARTICLE)
    np.testing.assert_array_equal(c.radius_j[on_fixed], state.radius[fixed][k])
    below = on_fixed | (c.family == FLOOR)
    force = forces[:, :1] * c.normal + forces[:, 1:2] * c.tangent1 + forces[:, 2:3] * c.tangent2
    support = -force[below, 2].sum()
    weight = upper.mass.sum() * G
    momentum_change = np.sum(upper.mass * (result.state.velocity[:, 2] - upper.velocity[:, 2])) / DT
    assert support == pytest.approx(weight + momentum_change, rel=1e-8)
    assert support == pytest.approx(weight, rel=1e-5)
    assert result.diagnostics.largest_overlap <= settings.overlap_tolerance * 2 * state.radius.min()
    # a warm start tells apart the fixed spheres a particle touches (many touch two or more)
    assert np.bincount(c.i[on_fixed]).max() >= 2
    again = WarmStart.from_step(c, forces).match(c)
    np.testing.assert_allclose(again, forces, rtol=0, atol=1e-12 * np.abs(forces).max())


def test_a_sphere_never_passes_into_a_fixed_one():
    """A sphere dropped at 3 sqrt(g d) onto a fixed sphere of the same radius, off-centre: the
    stepper's overlap check counts fixed spheres, so every step ends within 1 % of the diameter."""
    radius = 0.2
    fixed = FixedSpheres(np.array([[0.0, 0.0, radius]]), np.array([radius]))
    state = ParticleState(np.array([[0.1, 0.0, 3.0 * radius + 0.05]]),
                          np.array([[0.0, 0.0, -3.0 * np.sqrt(G * 2 * radius)]]), np.zeros((1, 3)), np.array([radius]))
    settings = StepSettings(dt=0.02, walls=Walls(floor=True, fixed=fixed), law=COLLAPSE_LAW)
    touched = False
    for result in run(state, settings, 30, ClarabelSolver()):
        gap = np.linalg.norm(result.state.position[0] - fixed.position[0]) - 2 * radius
        assert gap >= -0.01 * 2 * radius
        touched |= bool(np.any(result.contacts.j == -2) and result.solution.forces[:, 0].max() > 0)
    assert touched


def test_the_next_step_s_detection_holds_every_overlapping_pair(pile):
    """The stepper's check measures the pairs of the next step's first detection instead of searching
    (:func:`overlaps` of a detection): on the poured pile with three spheres pushed into their
    neighbours, moving under gravity, both give the same overlapping pairs, normals and largest
    overlaps, to the bit (the same arithmetic on the same pairs)."""
    state = pile.poured
    position = state.position.copy()
    for k in (5, 40, 77):   # a tenth of a diameter into its nearest neighbour
        nearest = np.argsort(np.linalg.norm(position - position[k], axis=1))[1]
        position[k] += 0.1 * (position[nearest] - position[k])
    moved = ParticleState(position, state.velocity + [0.0, 0.0, -0.3], state.angular_velocity, state.radius)
    settings = collapse_settings(pile)
    found = detect(moved, settings.walls, settings.law, predicted_displacement(moved, settings),
                   0.05 * 2 * state.radius.min(), settings.detection_slack)
    tolerance = 1e-3 * 2 * state.radius.min()
    searched = overlaps(moved, settings.walls, tolerance)
    measured = overlaps(moved, settings.walls, tolerance, detected=found)
    assert measured.largest_pair == searched.largest_pair > 0.05 * state.radius.min()
    assert measured.largest == searched.largest
    order = np.lexsort((searched.pairs[1], searched.pairs[0]))   # the k-d tree's order; detection's is (i, j)
    assert len(order) >= 3
    for ours, theirs in zip(measured.pairs, searched.pairs):
        np.testing.assert_array_equal(ours, theirs[order])


def test_run_hands_each_step_its_first_contacts_and_takes_the_same_steps(pile):
    """run() gives each step the detection its predecessor's check made (the same object, so no
    search of its own), and the steps are those of step() detecting afresh each time, to the bit:
    10 steps of the pile's collapse with the cylinder gone, warm-started APGD."""
    from colsim.solvers.apgd import ApgdSolver

    settings = collapse_settings(pile, cylinder=False)
    solver = ApgdSolver(tolerance=1e-8)
    handed = list(run(pile.settled, settings, 10, solver))
    base = base_margin(pile.settled, settings)
    state, warm, margin, taken = pile.settled, None, None, 0
    for k, result in enumerate(handed, start=1):
        alone = step(state, settings, solver, k, warm, margin)
        np.testing.assert_array_equal(result.state.position, alone.state.position)
        np.testing.assert_array_equal(result.solution.forces, alone.solution.forces)
        if k > 1 and not handed[k - 2].diagnostics.redone and not result.diagnostics.redone:
            assert result.contacts is handed[k - 2].upcoming.contacts
            taken += 1
        state, warm = alone.state, WarmStart.from_step(alone.contacts, alone.solution.forces)
        margin = next_margin(alone.diagnostics, base)
    assert taken >= 5
