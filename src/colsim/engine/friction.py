"""The friction law of a step: associated (the paper's) or Coulomb (non-associated), on the same cone program.

associated: one cone program (:mod:`colsim.engine.program`), g + du_n >= mu ||du_t|| + mu_r ||dphi||.
    Its flow rule is normal to the cone: a sliding contact opens by mu ||du_t|| (and a rolling one
    by mu_r ||dphi||) every step, so a sliding grain hovers.

coulomb: De Saxce's bipotential, solved as in Acary and Cadoux (2013) and Krabbenhoft et al.
    (2012): the gap of each contact is corrected by the dilation of the current iterate,

        g + s + du_n >= mu ||du_t|| + mu_r ||dphi||,   s = mu ||du_t'|| + mu_r ||dphi'||,

    with du' the previous iterate's local displacement, and the program is solved again until s
    stops changing (a fixed point of whole solves, each warm-started from the last forces, with a
    per-contact secant step, halved, :class:`_Secant`). At the fixed point a sliding contact does
    not open: g + du_n = 0, while its force stays on the cone (||q|| = mu p) and opposes the slip.
    With mu = mu_r = 0 the correction is zero and the two laws are the same program.

Stopping rule: the root mean square over the contacts of the change of the correction s between
two iterates (the spurious opening the fixed point leaves, on average over the contacts) is at most
`tolerance` times the mean particle diameter; then no contact is off by more than sqrt(m) times
that. A fixed point not reached in `max_iter` solves is a :class:`SolverError` naming the step.

Why the mean and not the largest change: in the fast flow of a column the largest change wanders
on a few contacts, different ones each time, and a rule on it stopped whole collapses, while the
mean settles well below the associated law's dilation a step. Why the secant steps are halved
(:class:`_Secant`): undamped, the fixed-point map itself (not the solver) cycled on one step of
one column. Why whole solves and not a correction folded into the APGD iteration, and why s starts
from 0 and not from the previous step's correction: both converged worse. The measurements behind
each: docs/validation/friction-law.md.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from .program import ConeProgram

from .solver_contract import ConeSolution, Solver, SolverError, at_step
from .state import FRICTION_LAWS, FrictionLaw

__all__ = ["FRICTION_LAWS", "FrictionLaw", "dilation", "solve_step"]


def dilation(program: ConeProgram, increments: np.ndarray) -> np.ndarray:
    """(m,) mu ||du_t|| + mu_r ||dphi|| of each contact for increments u (6n,) (length)."""
    local = program.local_displacement(increments)
    return (program.mu * np.linalg.norm(local[:, 1:3], axis=1)
            + program.mu_r * np.linalg.norm(local[:, 3:5], axis=1))


def solve_step(program: ConeProgram, solver: Solver, law: FrictionLaw, mean_diameter: float,
               warm_start: np.ndarray | None = None, step: int | None = None) -> ConeSolution:
    """The step's contact forces and increments under `law`, solved by `solver`.

    For coulomb the solution's `iterations` and times add up over the fixed point's solves, and
    its info holds 'friction_iterations' (cone programs solved) and 'correction_change' (the last
    root-mean-square change of s over the mean diameter)."""
    solution = solver.solve(program, warm_start=warm_start, step=step)
    if law.name == "associated" or program.m == 0 or not (np.any(program.mu) or np.any(program.mu_r)):
        solution.info["friction_iterations"] = 1
        return solution
    correction = np.zeros(program.m)
    accelerate = _Secant()
    iterations, setup_time, solve_time = solution.iterations, solution.setup_time, solution.solve_time
    for solves in range(1, law.max_iter + 1):
        residual = dilation(program, solution.increments) - correction
        change = float(np.sqrt(np.mean(residual**2))) / mean_diameter
        if change <= law.tolerance:
            solution.iterations, solution.setup_time, solution.solve_time = iterations, setup_time, solve_time
            solution.info.update(friction_iterations=solves, correction_change=change)
            return solution
        if solves == law.max_iter:
            break
        correction = accelerate(correction, residual)
        solution = solver.solve(replace(program, gap_shift=correction),
                                warm_start=solution.resident_forces(), step=step)
        iterations += solution.iterations
        setup_time += solution.setup_time
        solve_time += solution.solve_time
    raise SolverError(
        f"the Coulomb fixed point did not converge{at_step(step)} within {law.max_iter} cone programs "
        f"(last root-mean-square change of the dilation correction {change:.2e} mean diameters, tolerance "
        f"{law.tolerance:.1e}, {program.m} contacts)", status="FixedPointMaxIterations", step=step)


class _Secant:
    """Per-contact secant steps on f(s) = dilation(s) - s, the fixed point's residual, damped.

    Each contact's correction moves `relaxation` (0.5) of the way to where the line through its
    last two (s, f) crosses f = 0, where that line falls (slope below -0.1, as it does where the
    plain iteration s <- s + f overshoots); elsewhere it moves `relaxation` of the plain step.
    Clipped to s >= 0 (a dilation).

    Why a secant step: the plain iteration and Anderson acceleration both stalled in two-cycles (a
    contact carrying load one iterate and not the next) where the secant went through
    (docs/validation/friction-law.md). The damping: see the module docstring.
    """

    relaxation = 0.5

    def __init__(self):
        self.s_prev = self.f_prev = None

    def __call__(self, s: np.ndarray, f: np.ndarray) -> np.ndarray:
        step = f.copy()
        if self.f_prev is not None:
            ds = s - self.s_prev
            with np.errstate(divide="ignore", invalid="ignore"):
                slope = np.where(ds != 0, (f - self.f_prev) / ds, -1.0)
            falling = slope < -0.1
            step[falling] = -f[falling] / slope[falling]
        self.s_prev, self.f_prev = s.copy(), f.copy()
        return np.maximum(s + self.relaxation * step, 0.0)
