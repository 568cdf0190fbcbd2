"""Analytic cases of SPEC section 7 on one sphere: free fall, the sliding and the rolling threshold.

Incline: the floor z = 0 stays horizontal and gravity is tilted by theta towards +x,
g = 9.81 (sin theta, 0, -cos theta), so "down the slope" is +x.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from colsim.solvers import ClarabelSolver
from colsim.engine.state import FRICTION_LAWS, ContactLaw, FrictionLaw, ParticleState, StepSettings, Walls
from colsim.engine.stepper import run

G = 9.81
RADIUS = 0.2


# --- free fall ------------------------------------------------------------------------------------

@pytest.mark.parametrize("walls", [Walls(floor=False), Walls(floor=True)], ids=["no-walls", "floor-far"])
def test_free_fall_matches_the_implicit_scheme(walls):
    """x_{k+1} = x_k + v_k dt + g dt^2, v_{k+1} = (x_{k+1} - x_k)/dt, w constant, so in closed form
    v_k = v_0 + k g dt and x_k = x_0 + k v_0 dt + g dt^2 k (k + 1)/2."""
    dt, steps = 0.01, 100
    gravity = np.array([0.3, -0.2, -G])
    x0, v0, w0 = np.array([0.5, -1.0, 50.0]), np.array([0.7, 0.1, 1.5]), np.array([1.0, -2.0, 3.0])
    state = ParticleState(x0[None], v0[None], w0[None], [RADIUS])
    settings = StepSettings(dt=dt, gravity=tuple(gravity), walls=walls)
    for result in run(state, settings, steps, ClarabelSolver()):
        k = result.diagnostics.step
        assert result.diagnostics.n_contacts == 0  # the floor is 45 below the lowest point it reaches
        x_exact = x0 + k * v0 * dt + gravity * dt**2 * k * (k + 1) / 2
        v_exact = v0 + k * gravity * dt
        # 1e-12 relative: the scheme is reproduced up to rounding of ~k additions of O(1) numbers
        np.testing.assert_allclose(result.state.position[0], x_exact, rtol=1e-12, atol=1e-12 * 50)
        np.testing.assert_allclose(result.state.velocity[0], v_exact, rtol=1e-12, atol=1e-12 * 10)
        np.testing.assert_array_equal(result.state.angular_velocity[0], w0)
        assert result.state.time == pytest.approx(k * dt, rel=1e-12)


# --- one sphere on a tilted floor -------------------------------------------------------------------

def incline(theta: float, mu: float, mu_r: float, dt: float, duration: float):
    """Velocities (N, 3), angular velocities (N, 3) and floor gaps (N,) after each of N steps."""
    state = ParticleState.at_rest([[0.0, 0.0, RADIUS]], [RADIUS])
    settings = StepSettings(
        dt=dt, gravity=(G * math.sin(theta), 0.0, -G * math.cos(theta)), walls=Walls(floor=True),
        law=ContactLaw(mu=(mu, mu, 0.0), mu_r=(mu_r, mu_r, 0.0)))
    # tolerance 1e-12 (one sphere: cheap): at the default 1e-8 the interior point's early steps are
    # off by ~1e-4 g dt in velocity, which would hide the scheme's own O(dt) lag near the threshold
    out = [(r.state.velocity[0], r.state.angular_velocity[0], r.state.position[0, 2] - RADIUS)
           for r in run(state, settings, int(round(duration / dt)), ClarabelSolver(tolerance=1e-12))]
    v, w, gap = (np.array(x) for x in zip(*out))
    return v, w, gap


MU, MU_R = 0.577, 0.12
DURATION = 0.4


@pytest.mark.parametrize("mu, mu_r, ratio", [(MU, 10.0, 0.5), (MU, 10.0, 0.95),
                                             (10.0, MU_R, 0.5), (10.0, MU_R, 0.95)],
                         ids=["slide-0.5", "slide-0.95", "roll-0.5", "roll-0.95"])
@pytest.mark.parametrize("dt", [0.02, 0.005])
def test_stays_at_rest_below_threshold(mu, mu_r, ratio, dt):
    """tan(theta) = ratio * (the active coefficient) <= it: the sphere neither slides nor rolls.

    Bound: 1e-6 g T, i.e. 1e-6 of the speed of free fall over T (measured: below 5e-8 m/s, constant,
    not growing); the solver runs at 1e-12.
    """
    threshold = mu if mu_r > mu else mu_r
    v, w, gap = incline(math.atan(ratio * threshold), mu, mu_r, dt, DURATION)
    assert np.abs(v).max() <= 1e-6 * G * DURATION
    assert np.abs(w).max() * RADIUS <= 1e-6 * G * DURATION
    # no hop either: the gap stays at the interior point's offset, far below any dilation of a
    # sliding step (mu |du_t| >= 1e-5 here)
    assert np.abs(gap).max() <= 1e-6 * RADIUS


def sliding_velocity(theta, mu, dt, steps):
    """The scheme's exact velocity after `steps` steps of sliding from rest (rolling locked).

    Each step projects the free displacement onto the cone g + dz >= mu |dx_t| (mass metric). The
    gap then equals mu |dx_t| (the associated law's dilation: the sphere hops by mu |du_t| per step),
    and the tangential acceleration obeys (1 + mu^2) a_k = mu^2 a_{k-1} + a*, a* = g (sin - mu cos),
    a_{-1} = 0: a_k = a* (1 - r^(k+1)), r = mu^2 / (1 + mu^2). Summed: v_N = a* (N dt - mu^2 dt (1 - r^N)).
    """
    a_star = G * (math.sin(theta) - mu * math.cos(theta))
    r = mu**2 / (1 + mu**2)
    return a_star * (steps * dt - mu**2 * dt * (1 - r**steps))


@pytest.mark.parametrize("ratio", [1.05, 1.5, 2.5])
def test_sliding_above_threshold(ratio):
    """tan(theta) = ratio mu > mu: slides down with a = g (sin - mu cos), rolling locked (mu_r = 10).

    The associated law makes the sliding sphere hop by mu |du_t| per step, and its first step's
    upward velocity is paid for by the tangential motion: the velocity at time T lags the exact
    a* T by a* mu^2 dt (sliding_velocity). So: the engine matches the scheme's own prediction to
    1e-6 relative (solver tolerance 1e-12; measured 5e-8), the late acceleration matches a* to
    1e-6 relative (the lag is transient, decaying as 0.25^k), and the error in the mean
    acceleration is mu^2 dt / T and falls 4x with dt/4.
    """
    theta = math.atan(ratio * MU)
    a_star = G * (math.sin(theta) - MU * math.cos(theta))
    errors = []
    for dt in (0.02, 0.005):
        v, w, gap = incline(theta, MU, 10.0, dt, DURATION)
        n = len(v)
        assert v[-1, 0] == pytest.approx(sliding_velocity(theta, MU, dt, n), rel=1e-6)
        late = (v[-1, 0] - v[n // 2 - 1, 0]) / (DURATION / 2)
        assert late == pytest.approx(a_star, rel=1e-6)
        # the hop: the gap after a step is mu |dx_t| of that step (1e-6 of it: solver tolerance)
        np.testing.assert_allclose(gap, MU * v[:, 0] * dt, rtol=1e-6, atol=1e-9 * RADIUS)
        assert np.abs(v[:, 1]).max() <= 1e-9 * a_star * DURATION  # no sideways drift
        assert np.abs(w).max() * RADIUS <= 1e-6 * a_star * DURATION  # rolling locked by mu_r = 10
        errors.append(abs(v[-1, 0] / DURATION - a_star) / a_star)
    # mean-acceleration error: mu^2 dt / T (1.7 % at dt = 0.02), first order in dt
    # (1e-3 relative: (1 - r^N) and the 1e-6 above)
    assert errors[0] == pytest.approx(MU**2 * 0.02 / DURATION, rel=1e-3)
    assert errors[1] == pytest.approx(errors[0] / 4, rel=1e-3)


@pytest.mark.parametrize("ratio", [1.5, 3.0])
def test_rolling_above_threshold(ratio):
    """tan(theta) = ratio mu_r > mu_r, mu = 10 (no slip): rolls with a = 5/7 g (sin - mu_r cos).

    Rigid body: m a = m g sin - q, I alpha = q R - R_eff |r| with R_eff = R on a wall, |r| = mu_r p,
    p = m g cos, a = R alpha and I = 2/5 m R^2 give a = g (sin - mu_r cos) / (1 + 2/5). The scheme
    dilates by mu_r |dphi| per step; once the hop's vertical velocity is steady, p = m g cos again,
    so the late acceleration matches to 1e-6 relative (solver tolerance 1e-12); the mean acceleration to T
    lags by the first steps' transient: within 2e-3 at dt = 0.02, and at least 3x smaller at dt/4.
    """
    theta = math.atan(ratio * MU_R)
    a_star = 5.0 / 7.0 * G * (math.sin(theta) - MU_R * math.cos(theta))
    errors = []
    for dt in (0.02, 0.005):
        v, w, gap = incline(theta, 10.0, MU_R, dt, DURATION)
        n = len(v)
        late = (v[-1, 0] - v[n // 2 - 1, 0]) / (DURATION / 2)
        assert late == pytest.approx(a_star, rel=1e-6)
        # no slip at the contact point: v_x = R w_y (1e-8 of the speed: solver tolerance)
        np.testing.assert_allclose(v[:, 0], RADIUS * w[:, 1], rtol=1e-8, atol=1e-12)
        # the hop: the gap after a step is mu_r R_eff |dth_t| of that step
        np.testing.assert_allclose(gap, MU_R * RADIUS * w[:, 1] * dt, rtol=1e-6, atol=1e-9 * RADIUS)
        errors.append(abs(v[-1, 0] / DURATION - a_star) / a_star)
    assert errors[0] <= 2e-3
    assert errors[1] <= errors[0] / 3


# --- the Coulomb (non-associated) law on the same incline ---------------------------------------------

def incline_run(theta, mu, mu_r, dt, duration, friction, solver=None):
    """Velocities (N, 3), floor gaps (N,) and cone programs per step (N,) of a sphere released at
    rest on the tilted floor, under `friction` (a FrictionLaw)."""
    state = ParticleState.at_rest([[0.0, 0.0, RADIUS]], [RADIUS])
    settings = StepSettings(
        dt=dt, gravity=(G * math.sin(theta), 0.0, -G * math.cos(theta)), walls=Walls(floor=True),
        law=ContactLaw(mu=(mu, mu, 0.0), mu_r=(mu_r, mu_r, 0.0)), friction=friction)
    results = list(run(state, settings, int(round(duration / dt)), solver or ClarabelSolver(tolerance=1e-12)))
    v = np.array([r.state.velocity[0] for r in results])
    gap = np.array([r.state.position[0, 2] - RADIUS for r in results])
    programs = np.array([r.diagnostics.friction_iterations for r in results])
    forces = [r.solution.forces for r in results]
    return v, gap, programs, forces


@pytest.mark.parametrize("mu, mu_r", [(MU, 10.0), (0.1, 0.0)], ids=["rolling-locked", "slide-and-spin"])
@pytest.mark.parametrize("solver", ["clarabel", "apgd"])
def test_coulomb_slides_without_opening(mu, mu_r, solver):
    """Coulomb law, tan(theta) = 1.5 x 0.577: the sphere keeps touching the floor and slides with
    a* = g (sin - mu cos) from the first step, v_N = N a* dt exactly (no hop to pay for).

    With rolling locked (mu_r = 10) or free (mu_r = 0, mu = 0.1 < 2/7 tan(theta), so it slides
    while it spins up), the friction force is mu p either way. Bounds: the gap within 1e-8 of the
    diameter (the fixed point's tolerance, 1e-9 d, plus the solver's 1e-12 relative), the velocity
    within 1e-7 a* T of N a* dt (a gap error e moves the velocity by about e/dt = 2e-8 here), the
    force on its cone to 1e-8 relative."""
    from colsim.solvers import make_solver
    theta = math.atan(1.5 * MU)
    a_star = G * (math.sin(theta) - mu * math.cos(theta))
    dt = 0.02
    back_end = ClarabelSolver(tolerance=1e-12) if solver == "clarabel" else make_solver("apgd", tolerance=1e-10)
    v, gap, programs, forces = incline_run(theta, mu, mu_r, dt, DURATION,
                                           FrictionLaw("coulomb", tolerance=1e-9), back_end)
    steps = np.arange(1, len(v) + 1)
    np.testing.assert_allclose(v[:, 0], steps * a_star * dt, rtol=0, atol=1e-7 * a_star * DURATION)
    assert np.abs(gap).max() <= 1e-8 * 2 * RADIUS
    assert np.abs(v[:, 2]).max() <= 1e-8 * 2 * RADIUS / dt   # the gap moves by at most 1e-8 d a step
    for lam in forces:
        p, q = lam[0, 0], np.hypot(lam[0, 1], lam[0, 2])
        assert p > 0 and q == pytest.approx(mu * p, rel=1e-8)
    assert programs.min() >= 2   # it slides: the fixed point needs more than the associated program


def test_associated_law_hops_where_coulomb_does_not():
    """The same sliding sphere under the associated law hops by mu |du_t| a step (as
    test_sliding_above_threshold derives), one cone program a step."""
    theta = math.atan(1.5 * MU)
    v, gap, programs, _ = incline_run(theta, MU, 10.0, 0.02, DURATION, FrictionLaw("associated"))
    np.testing.assert_allclose(gap, MU * v[:, 0] * 0.02, rtol=1e-6, atol=1e-9 * RADIUS)
    assert gap[-1] > 1e-3 * RADIUS
    assert (programs == 1).all()


def test_frictionless_laws_are_identical(pile):
    """mu = mu_r = 0: the correction is zero, the two laws solve the same program: equal steps
    (bit for bit: the same solver calls), one cone program a step."""
    from helpers import DT
    ends = {}
    for name in FRICTION_LAWS:
        settings = StepSettings(dt=DT, walls=Walls(floor=True, cylinder_radius=None), friction=FrictionLaw(name))
        results = list(run(pile.settled, settings, 5, ClarabelSolver()))
        assert all(r.diagnostics.friction_iterations == 1 for r in results)
        ends[name] = results[-1].state
    np.testing.assert_array_equal(ends["associated"].position, ends["coulomb"].position)
    np.testing.assert_array_equal(ends["associated"].angular_velocity, ends["coulomb"].angular_velocity)


def test_coulomb_keeps_loaded_contacts_closed_in_a_collapsing_pile(pile):
    """Five steps (dt = 0.002, a tenth of the pile's) of the session pile released under the
    collapse's friction, both laws, Clarabel. (At the pile's own dt the fixed point does not
    converge on the first step: docs/method.md, "Friction law".)

    Every force lies in its cone (1e-7 of the largest normal force: Clarabel at 1e-8).

    Under coulomb every contact that carries load (at least 1e-4 of the largest normal force) ends
    the step closed to within the fixed point's guarantee: a loaded contact's cone constraint is
    active, so its end-of-step gap g + du_n is its entry of the last residual (dilation minus
    correction), whose root mean square over the step's m contacts the stopping rule holds at tol d;
    hence each entry is at most sqrt(m) tol d, plus the solver's accuracy, taken as 1e-6 d. (An
    interior point leaves a slack of about its complementarity tolerance over the force: on contacts
    at 1e-6 of the largest force, gaps of up to 2.9e-5 d were measured, so such contacts count as
    unloaded; at 1e-4 that slack is a hundred times smaller.) The bound is worked out for each step's
    own m: the pile is chaotic and its contacts differ by processor.
    Under the associated law the sliding contacts open by mu |du_t| + mu_r |dphi|, more than that
    bound allows coulomb (measured 1.3e-4 d over these first steps against a bound of 2.5e-5 d;
    coulomb's largest 4.8e-6 d)."""
    from colsim.engine.program import assemble, cone_violation
    from helpers import COLLAPSE_LAW
    dt, tol = 0.002, 1e-6
    d_mean = 2 * float(pile.settled.radius.mean())
    opening, bound = {}, 0.0
    for name in FRICTION_LAWS:
        settings = StepSettings(dt=dt, walls=Walls(floor=True, cylinder_radius=None), law=COLLAPSE_LAW,
                                friction=FrictionLaw(name, tolerance=tol))
        state, largest = pile.settled, 0.0
        for result in run(state, settings, 5, ClarabelSolver()):
            program = assemble(state, result.contacts, dt, settings.gravity)
            lam = result.solution.forces
            assert cone_violation(program, result.solution.increments, lam)["dual"] <= 1e-7 * lam[:, 0].max()
            gaps = program.end_of_step_gaps(result.solution.increments)[:, 0]
            loaded = lam[:, 0] > 1e-4 * lam[:, 0].max()
            step_bound = np.sqrt(program.m) * tol + 1e-6
            if name == "coulomb":
                assert gaps[loaded].max() / d_mean <= step_bound, (result.diagnostics.step, program.m)
                bound = max(bound, step_bound)
            largest = max(largest, float(gaps[loaded].max()))
            state = result.state
        opening[name] = largest / d_mean
    assert opening["associated"] > bound


def test_coulomb_fixed_point_that_does_not_converge_is_an_error():
    """A cap of 2 cone programs at tolerance 1e-12 d: a SolverError naming the step, no result."""
    from colsim.solvers import SolverError
    with pytest.raises(SolverError, match="Coulomb fixed point did not converge at step 1 within 2"):
        incline_run(math.atan(1.5 * MU), MU, 10.0, 0.02, 0.04, FrictionLaw("coulomb", tolerance=1e-12, max_iter=2))
