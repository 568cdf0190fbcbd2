"""Cone programs shared by the tests of the iterative back-ends (APGD, ADMM) against Clarabel."""
from __future__ import annotations

import numpy as np

from colsim.stages.pack import starting_cloud
from colsim.engine.program import assemble
from colsim.solvers import ClarabelSolver
from colsim.engine.state import ContactLaw, ParticleState, StepSettings, Walls
from colsim.engine.backend import HOST, Backend, predicted_displacement
from colsim.engine.stepper import run, step

COLLAPSE = StepSettings(dt=0.02, law=ContactLaw.uniform(0.577, 0.12))


def small_pile() -> ParticleState:
    """About 90 spheres (d in [0.25, 0.5]) poured into a cylinder of radius 1.2 (mu = mu_r = 0), 100 steps."""
    state = starting_cloud(90, 1.2, seed=7)
    for result in run(state, StepSettings(dt=0.02, walls=Walls(cylinder_radius=1.2)), 100, ClarabelSolver()):
        state = result.state
    state.velocity[:] = 0.0
    state.angular_velocity[:] = 0.0
    return state


def collapse_program(state: ParticleState, settings: StepSettings = COLLAPSE, backend: Backend = HOST):
    """(program, contacts) of one collapse step from `state`, detected as the stepper does (by `backend`;
    the program assembled on the host)."""
    margin = settings.detection_margin_fraction * 2 * state.radius.min()
    found = backend.detect(state, settings.walls, settings.law, predicted_displacement(state, settings),
                           margin, settings.detection_slack)
    return assemble(state, found, settings.dt, settings.gravity), found


def collapse_settings(law: ContactLaw | None = None) -> StepSettings:
    """COLLAPSE, or the same step under another contact law."""
    return COLLAPSE if law is None else StepSettings(dt=COLLAPSE.dt, law=law)


def mid_collapse(state: ParticleState, steps: int = 6, law: ContactLaw | None = None) -> ParticleState:
    """The state after `steps` collapse steps with Clarabel (under `law`: COLLAPSE's by default)."""
    for k in range(steps):
        state = step(state, collapse_settings(law), ClarabelSolver(), k).state
    return state


def against_clarabel(solver, state: ParticleState, law: ContactLaw | None = None):
    """Solve one collapse step from `state` with `solver` and with Clarabel at 1e-10.

    Returns (program, solution, relative difference of the increments, relative difference of the
    net contact force on the particles B' lam, which is unique even where the forces are not)."""
    program, _ = collapse_program(state, collapse_settings(law))
    assert program.m > 100 and np.all(program.mu > 0) and np.any(program.mu_r > 0)
    ref = ClarabelSolver(tolerance=1e-10).solve(program)
    sol = solver.solve(program)
    du = np.linalg.norm(sol.increments - ref.increments) / np.linalg.norm(ref.increments)
    net = program.jacobian.T @ sol.forces.ravel()
    net_ref = program.jacobian.T @ ref.forces.ravel()
    return program, sol, du, np.linalg.norm(net - net_ref) / np.linalg.norm(net_ref)
