"""The rolling lever L of the moment L r between two spheres (SPEC sections 2 and 7).

The paper's lever (its Eqs. 6 and 9) is the particle radius: L = 2 R_i R_j / (R_i + R_j) between
spheres, each radius when the two are equal; the DEM convention `effective` is R_eff = R_i R_j /
(R_i + R_j), half of it. At a wall both are R_i, so the incline cases of engine/test_analytic hold
under either lever.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from colsim.solvers.apgd import ApgdSolver
from colsim.engine.contacts import detect
from colsim.engine.program import assemble
from colsim.solvers import ClarabelSolver
from colsim.engine.state import ROLLING_LEVERS, ContactLaw, ParticleState, StepSettings, Walls, rolling_lever
from colsim.engine.stepper import run

from solver_cases import against_clarabel, mid_collapse

G = 9.81


def test_lever_formulas():
    """Equal spheres: the paper's lever is R, R_eff is R/2; unequal: the ratio is 2 as well
    (harmonic mean against half of it); at a wall (radius_j = 0) both are R_i."""
    ri, rj = np.array([0.2, 0.2, 0.125, 0.2]), np.array([0.2, 0.3, 0.25, 0.0])
    paper, effective = rolling_lever(ri, rj, "paper"), rolling_lever(ri, rj, "effective")
    np.testing.assert_allclose(paper, [0.2, 0.24, 1 / 6, 0.2], rtol=1e-15)
    np.testing.assert_allclose(effective, [0.1, 0.12, 1 / 12, 0.2], rtol=1e-15)
    with pytest.raises(ValueError, match="rolling lever"):
        rolling_lever(ri, rj, "radius")
    with pytest.raises(ValueError, match="rolling_lever"):
        ContactLaw(rolling_lever="R")


def test_the_compiled_levers_are_the_definition_to_the_bit():
    """detect's compiled levers (contact_levers) give rolling_lever's numbers bit for bit, walls
    (radius_j = 0) included, and refuse an unknown lever alike."""
    from colsim.engine.contacts import contact_levers

    rng = np.random.default_rng(4)
    ri, rj = rng.uniform(0.05, 0.5, 1000), rng.uniform(0.05, 0.5, 1000)
    rj[::7] = 0.0
    for lever in ROLLING_LEVERS:
        assert np.array_equal(contact_levers(ri, rj, lever), rolling_lever(ri, rj, lever))
    assert contact_levers(ri[:0], rj[:0], "paper").shape == (0,)
    with pytest.raises(ValueError, match="rolling lever"):
        contact_levers(ri, rj, "radius")


def _pair(lever, radii=(0.2, 0.3)):
    """Contacts and program of two touching spheres of `radii` (and the floor under the first)."""
    state = ParticleState.at_rest([[0.0, 0.0, radii[0]], [0.0, 0.0, 0.0]], list(radii))
    d = np.array([0.3, -0.4, 0.8]) / np.linalg.norm([0.3, -0.4, 0.8])
    state.position[1] = state.position[0] + d * sum(radii)
    settings = StepSettings(dt=0.01, walls=Walls(floor=True), law=ContactLaw.uniform(0.5, 0.1, rolling_lever=lever))
    found = detect(state, settings.walls, settings.law, np.zeros((2, 3)), 0.05)
    return state, found, assemble(state, found, settings.dt, settings.gravity)


@pytest.mark.parametrize("lever", ROLLING_LEVERS)
def test_a_pair_turning_rigidly_does_not_roll_and_the_rolling_moments_balance(lever):
    """u of a rigid rotation of the pair (dx = dth x (x - c), the same dth for both): every row of
    B u vanishes (no gap change, no slip, no rolling), to rounding; and a rolling force puts
    opposite moments L r on the two spheres, the same lever for both (one couple)."""
    state, found, program = _pair(lever)
    k = int(np.flatnonzero(found.j >= 0)[0])
    dth = np.array([0.3, -0.7, 0.2])
    centre = np.array([0.05, -0.1, 0.3])
    u = np.concatenate([np.cross(dth, state.position - centre).ravel(), np.tile(dth, 2)])
    rows = program.jacobian @ u
    np.testing.assert_allclose(rows.reshape(-1, 5)[k], 0.0, atol=1e-14)
    rolling = np.zeros(program.jacobian.shape[0])
    rolling[5 * k + 3] = 1.0
    moment = (program.jacobian.T @ rolling)[6:].reshape(2, 3)   # dth block of the two spheres
    np.testing.assert_allclose(moment[0] + moment[1], 0.0, atol=1e-15)
    assert np.linalg.norm(moment[1]) == pytest.approx(rolling_lever(0.2, 0.3, lever), rel=1e-14)


def stack(theta, lever, radii, steps=80, dt=0.005):
    """Largest speed of the top sphere of a two-sphere stack on the floor over `steps` steps, gravity
    tilted by theta towards +x. The bottom sphere is held by the floor (mu = mu_r = 10 there), the
    spheres do not slip on each other (mu = 10) and resist rolling with mu_r = 0.12."""
    bottom, top = radii
    state = ParticleState.at_rest([[0.0, 0.0, bottom], [0.0, 0.0, 2 * bottom + top]], [bottom, top])
    settings = StepSettings(dt=dt, gravity=(G * math.sin(theta), 0.0, -G * math.cos(theta)),
                            walls=Walls(floor=True),
                            law=ContactLaw(mu=(10.0, 10.0, 0.0), mu_r=(0.12, 10.0, 0.0), rolling_lever=lever))
    speeds = [np.linalg.norm(r.state.velocity[1]) for r in run(state, settings, steps, ClarabelSolver(tolerance=1e-12))]
    return max(speeds), steps * dt


@pytest.mark.parametrize("radii", [(0.2, 0.2), (0.3, 0.2)], ids=["equal", "bottom-1.5x"])
@pytest.mark.parametrize("lever", ROLLING_LEVERS)
def test_the_top_sphere_rolls_off_at_mu_r_times_its_lever(lever, radii):
    """The top sphere (radius R_t) in equilibrium: tangential force q = m g sin at its contact, moment
    R_t q against the rolling moment L |r| <= L mu_r p, p = m g cos: at rest iff tan(theta) <= mu_r
    L / R_t. Equal spheres: mu_r under the paper's lever, mu_r / 2 under R_eff. Checked at 0.9 and
    1.1 times that threshold: below, the speed stays within 1e-6 g T (the solver runs at 1e-12, as in
    the incline cases); above, it rolls (the torque left, 0.1 of the threshold's, gives speeds of
    order 1e-2 g T within T; 1e-3 g T is asserted)."""
    threshold = 0.12 * rolling_lever(radii[1], radii[0], lever) / radii[1]
    held, duration = stack(math.atan(0.9 * threshold), lever, radii)
    assert held <= 1e-6 * G * duration
    rolled, duration = stack(math.atan(1.1 * threshold), lever, radii)
    assert rolled >= 1e-3 * G * duration


@pytest.mark.parametrize("lever", ROLLING_LEVERS)
@pytest.mark.parametrize("stage", ["release", "mid-collapse"])
def test_apgd_agrees_with_clarabel_under_each_lever(solver_pile, stage, lever):
    """The bounds of test_apgd.test_agrees_with_clarabel (APGD at its 1e-5 tolerance against Clarabel
    at 1e-10), on the same solver_pile under each lever."""
    law = ContactLaw.uniform(0.577, 0.12, rolling_lever=lever)
    state = solver_pile if stage == "release" else mid_collapse(solver_pile, law=law)
    program, sol, du, net_error = against_clarabel(ApgdSolver(), state, law=law)
    assert du <= 1e-3 and net_error <= 1e-3, (du, net_error)
    assert sol.info["primal"] <= 1e-5 and sol.info["complementarity"] <= 1e-5
