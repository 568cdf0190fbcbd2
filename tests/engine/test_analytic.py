"""Analytic cases of SPEC section 7 on one sphere: free fall, the sliding and the rolling threshold.

Incline: the floor z = 0 stays horizontal and gravity is tilted by theta towards +x,
g = 9.81 (sin theta, 0, -cos theta), so "down the slope" is +x.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from colsim.solvers import ClarabelSolver
from colsim.engine.state import ContactLaw, ParticleState, StepSettings, Walls
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




