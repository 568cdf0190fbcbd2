"""APGD's iteration: the state between residual checks and the compiled kernels that move it.

The solver (:mod:`colsim.solvers.apgd`) states APGD once: the stopping rule, the caps, the fallback.
It drives an :class:`ApgdIteration`, which a back-end makes (:meth:`colsim.engine.backend.Backend.apgd_iteration`):
:class:`CpuIteration` here, with numba's kernels on the host's threads, or the GPU's
(:class:`colsim.engine.cuda_apgd.CudaIteration`). Both make APGD's decisions with :func:`decide`.

The iterate is in scaled forces z (lam = S z, S the rows' scaling): the gradient is G h + c with
h = T z = B' S z and G = S B Mbar^-1, and c = S (B u_free + g e_n); the descent test needs only h
(the objective is quadratic). The kernels apply T and G from the contacts' frames
(:class:`colsim.engine.operator.ContactGeometry`) and never form B.
"""
from __future__ import annotations

import math
from typing import Protocol

import numba
import numpy as np

from .cones import project_compiled, project_point, scaled_coefficients, scaled_residuals, scales_of_diagonal
from .operator import gradient_of, transpose_of
from .program import ROWS_PER_CONTACT, ConeProgram
from .solver_contract import ConeSolution
from .threads import threads

prange = numba.prange


class ApgdIteration(Protocol):
    """What APGD's solver asks of an iteration state (:class:`CpuIteration`, the GPU's
    :class:`colsim.engine.cuda_apgd.CudaIteration`, the tests' numpy oracle)."""

    #: the Lipschitz estimate L (the trial step is 1/L), the iterations made (accepted trial steps)
    #: and the counts of backtracks and restarts
    lip: float
    iterations: int
    backtracks: int
    restarts: int

    def trial_round(self, trials: int, check: bool) -> None:
        """Make `trials` trial steps, each with its decision (:func:`decide`), and update `iterations`:
        the back-end's operator that :func:`run_iterations` drives. check: a back-end that computes
        the residual check with the round (the GPU's, read in the same copy) does so."""

    def iterate(self, n: int) -> None:
        """Run n iterations (:func:`run_iterations`)."""

    def iterate_and_check(self, n: int, program: ConeProgram, scale: float, floor: float) -> dict[str, float]:
        """Run n iterations, then return the residuals at the iterate
        (:func:`colsim.engine.cones.relative_residuals`: primal, dual, complementarity)."""

    def is_warm(self) -> bool:
        """Does the first iterate hold a force (a warm start)? Asked before iterating."""

    def host_x(self) -> np.ndarray:
        """(5m,) the scaled iterate z, on the host."""

    def forces(self):
        """(m, 5) the contact forces S z of the iterate."""

    def solution(self, program: ConeProgram, iterations: int, setup_time: float, solve_time: float,
                 info: dict) -> ConeSolution:
        """The solved program's solution at the iterate (times in seconds)."""


def cpu_iteration(program: ConeProgram, warm_start, precondition: bool, lip_decay: float) -> "CpuIteration":
    """The scaled problem of `program` (m > 0 contacts) and its first iterate, ready to iterate on
    the host: the rows' scaling (or none), the scaled coefficients, c, and the warm start (m, 5)
    projected onto the scaled cones (zeros where None or of another shape)."""
    m = program.m
    inv_mass = 1.0 / program.mass
    operator = program.operator
    s = scales_of_diagonal(operator.diagonal(inv_mass)) if precondition else np.ones((m, 5))
    mu_s, mu_r_s = scaled_coefficients(program, s)
    c = scaled_gaps(program, inv_mass, s)
    if warm_start is not None and np.shape(warm_start) == (m, ROWS_PER_CONTACT):
        x = project_compiled(np.asarray(warm_start, dtype=float) / s, mu_s, mu_r_s).ravel()
    else:
        x = np.zeros(5 * m)
    return CpuIteration(operator.geometry(s.ravel()), c, mu_s, mu_r_s, inv_mass, x, s, lip_decay)


def scaled_gaps(program: ConeProgram, inv_mass: np.ndarray, s: np.ndarray) -> np.ndarray:
    """(5m,) c = S (B u_free + g e_n): the scaled end-of-step gaps of free motion."""
    c = (program.local_displacement(program.fbar * inv_mass)).ravel()
    c[::ROWS_PER_CONTACT] += program.gap
    c *= s.ravel()
    return c


# --------------------------------------------------------------------------------------------
# The compiled kernels of an iteration on the host
# --------------------------------------------------------------------------------------------

def extrapolated(x, x_prev, o, beta):
    """The five rows from o of the extrapolated point y = x + beta (x - x_prev) (scalar code: compiled
    by numba, and for the GPU by numba.cuda, :mod:`colsim.engine.cuda_apgd`)."""
    return (x[o] + beta * (x[o] - x_prev[o]), x[o + 1] + beta * (x[o + 1] - x_prev[o + 1]),
            x[o + 2] + beta * (x[o + 2] - x_prev[o + 2]), x[o + 3] + beta * (x[o + 3] - x_prev[o + 3]),
            x[o + 4] + beta * (x[o + 4] - x_prev[o + 4]))


def _project_step(x, x_prev, beta, g, x_new, step, mu_s, mu_r_s, blocks):
    """x_new = Proj_K(y - step g) at the extrapolated point y = x + beta (x - x_prev), formed here
    rather than stored (one pass less over the contacts' arrays an iteration); returns
    (||x_new - y||^2, g . (x_new - x)), each summed over `blocks` fixed ranges of contacts (one
    thread each) and then in order: one block gives the plain sum, and the result depends on the
    block count, never on the threads' timing."""
    m = len(mu_s)
    dd_part = np.zeros(blocks)
    uphill_part = np.zeros(blocks)
    for block in prange(blocks):
        dd = 0.0
        uphill = 0.0
        for k in range(block * m // blocks, (block + 1) * m // blocks):
            o = 5 * k
            y0, y1, y2, y3, y4 = extrapolated(x, x_prev, o, beta)
            pp, q1, q2, r1, r2 = project_point(
                y0 - step * g[o], y1 - step * g[o + 1], y2 - step * g[o + 2],
                y3 - step * g[o + 3], y4 - step * g[o + 4], mu_s[k], mu_r_s[k])
            x_new[o] = pp
            x_new[o + 1] = q1
            x_new[o + 2] = q2
            x_new[o + 3] = r1
            x_new[o + 4] = r2
            for c, yc in enumerate((y0, y1, y2, y3, y4)):   # summed as when y was stored: the same bits
                d = x_new[o + c] - yc
                dd += d * d
                uphill += g[o + c] * (x_new[o + c] - x[o + c])
        dd_part[block] = dd
        uphill_part[block] = uphill
    dd = 0.0
    uphill = 0.0
    for block in range(blocks):
        dd += dd_part[block]
        uphill += uphill_part[block]
    return dd, uphill


def _weighted_change(h_new, hy, inv_mass, blocks):
    """||h_new - hy||^2 weighted by inv_mass, summed as :func:`_project_step` sums."""
    nb = len(h_new)
    part = np.zeros(blocks)
    for block in prange(blocks):
        total = 0.0
        for i in range(block * nb // blocks, (block + 1) * nb // blocks):
            dh = h_new[i] - hy[i]
            total += dh * dh * inv_mass[i]
        part[block] = total
    total = 0.0
    for block in range(blocks):
        total += part[block]
    return total


# APGD's loop and decisions, written once. run_iterations drives rounds of trial steps, each step
# with its decision (decide: Nesterov's momentum, the gradient restart, the backtracking on the step
# length): the CPU's round is apgd_trials compiled with the CPU's kernels below, the GPU's is its
# launches (colsim.engine.cuda_apgd: a kernel runs decide on the device). The tests keep a numpy loop
# as their oracle (tests/solvers/apgd_oracle.py).

def run_iterations(iteration: ApgdIteration, n: int, check: bool = False) -> None:
    """n more APGD iterations (accepted trial steps) of `iteration`, the one loop of every back-end:
    rounds of as many trial steps as iterations are left (:meth:`ApgdIteration.trial_round`), until
    they are made; a rejected trial step (a backtrack) leaves its iteration to the next round. A GPU
    waits for the host once a round, not once a trial step. check: each round also computes the
    residual check where the back-end does so with its round."""
    target = iteration.iterations + n
    while iteration.iterations < target:
        iteration.trial_round(target - iteration.iterations, check)


def decide(dd, uphill, change, lip, theta, beta, lip_decay):
    """What a trial step from y with step 1/lip decides, from its sums dd = ||x_new - y||^2,
    uphill = g . (x_new - x) and change = ||T (x_new - y)||^2_{Mbar^-1}: returns (accepted, lip,
    theta, beta, restarted). The step is accepted when change <= lip dd (the exact descent test of a
    quadratic), or when dd = 0 (nothing moved; the test would compare two roundings of zero, and lip
    would double forever); then Nesterov's theta and beta move on, or restart (theta = 1, beta = 0)
    when uphill > 0, and lip *= lip_decay. Else lip doubles and the rest stays."""
    if not (dd == 0.0 or change <= lip * dd * (1.0 + 1e-12)):
        return False, 2.0 * lip, theta, beta, False
    theta_new = 0.5 * (-theta * theta + theta * math.sqrt(theta * theta + 4.0))
    beta = theta * (1.0 - theta) / (theta * theta + theta_new)
    restarted = uphill > 0.0
    if restarted:
        theta_new = 1.0
        beta = 0.0
    return True, lip * lip_decay, theta_new, beta, restarted


decide = numba.njit(cache=True)(decide)


def apgd_trials(trial_step, extrapolate, gradient):
    """The function trials(n_trials, x, x_prev, beta, hx, hy, g, x_new, h_new, theta, lip, geometry, c,
    mu_s, mu_r_s, inv_mass, lip_decay, reduction) that makes n_trials APGD trial steps with the kernel
    set (a round of :func:`run_iterations`) and returns (x, x_prev, x_new, hx, h_new, theta, beta, lip,
    accepted, backtracks, restarts): the arrays trade places (no copies), hy and g are updated in place.

    x, hx = T x: the iterate; the extrapolated point is y = x + beta (x - x_prev), never stored,
    hy = T y, and g = G hy + c the gradient at y; T = B' S and G = S B Mbar^-1 come from the contact
    `geometry` (:class:`colsim.engine.operator.ContactGeometry`). Each trial step's outcome is
    :func:`decide`'s; an accepted one moves the iterate on.

    The kernel set: trial_step(x, x_prev, beta, g, x_new, step, h_new, hy, geometry, mu_s, mu_r_s,
    inv_mass, reduction) sets x_new = Proj_K(y - step g) and h_new = T x_new and returns
    (||x_new - y||^2, g . (x_new - x), ||h_new - hy||^2_{Mbar^-1}); extrapolate(hy, h_new, hx, beta)
    sets hy = h_new + beta (h_new - hx); gradient(hy, inv_mass, geometry, c, g) sets g = G hy + c.
    `reduction` is how the kernels sum (the CPU's: a count of fixed blocks)."""

    def trials(n_trials, x, x_prev, beta, hx, hy, g, x_new, h_new, theta, lip, geometry, c, mu_s, mu_r_s,
               inv_mass, lip_decay, reduction):
        accepted_steps = 0
        backtracks = 0
        restarts = 0
        for _ in range(n_trials):
            dd, uphill, change = trial_step(x, x_prev, beta, g, x_new, 1.0 / lip, h_new, hy, geometry,
                                            mu_s, mu_r_s, inv_mass, reduction)
            accepted, lip, theta, beta, restarted = decide(dd, uphill, change, lip, theta, beta, lip_decay)
            if not accepted:
                backtracks += 1
                continue
            accepted_steps += 1
            if restarted:
                restarts += 1
            x_prev, x, x_new = x, x_new, x_prev
            extrapolate(hy, h_new, hx, beta)
            hx, h_new = h_new, hx
            gradient(hy, inv_mass, geometry, c, g)
        return x, x_prev, x_new, hx, h_new, theta, beta, lip, accepted_steps, backtracks, restarts

    return trials


def _trial_step(x, x_prev, beta, g, x_new, step, h_new, hy, geometry, mu_s, mu_r_s, inv_mass, blocks):
    """The CPU's trial step (:func:`apgd_iterations`): sums over `blocks` fixed blocks."""
    dd, uphill = _project_step(x, x_prev, beta, g, x_new, step, mu_s, mu_r_s, blocks)
    transpose_of(geometry, x_new, h_new)
    return dd, uphill, _weighted_change(h_new, hy, inv_mass, blocks)


def _extrapolate(hy, h_new, hx, beta):
    for i in prange(len(hy)):
        hy[i] = h_new[i] + beta * (h_new[i] - hx[i])


def _gradient(hy, inv_mass, geometry, c, g):
    gradient_of(geometry, hy, inv_mass, c, g)


extrapolated = numba.njit(cache=True, inline="always")(extrapolated)
_parallel = numba.njit(cache=True, parallel=True)
_project_step = _parallel(_project_step)
_weighted_change = _parallel(_weighted_change)
_extrapolate = _parallel(_extrapolate)
_trial_step = numba.njit(cache=True)(_trial_step)
_gradient = numba.njit(cache=True)(_gradient)
_trials_compiled = numba.njit(cache=True)(apgd_trials(_trial_step, _extrapolate, _gradient))



class CpuIteration:
    """The APGD state between residual checks, in scaled forces z (lam = S z), on the host;
    iterate(n) runs n iterations with the compiled kernels on the contacts' `geometry`
    (:meth:`colsim.engine.operator.ContactOperator.geometry`, or None where a subclass applies T and
    G itself: the tests' numpy oracle)."""

    def __init__(self, geometry, c, mu_s, mu_r_s, inv_mass, x, scaling, lip_decay=1.0):
        self.c, self.mu_s, self.mu_r_s, self.inv_mass = c, mu_s, mu_r_s, inv_mass
        self.scaling = scaling  # (m, 5) S: lam = S z
        self.geometry = geometry
        hx = self.apply_T(x)
        self.x, self.hx = x.copy(), hx
        self.x_prev, self.beta, self.hy = x.copy(), 0.0, hx.copy()   # y = x + beta (x - x_prev) = x
        self.g = self.apply_G(self.hy, c)
        self.x_new, self.h_new = np.empty_like(x), np.empty_like(hx)
        self.theta, self.lip = 1.0, self.lipschitz_estimate()
        self.iterations = self.backtracks = self.restarts = 0
        self.lip_decay = float(lip_decay)

    def apply_T(self, z: np.ndarray) -> np.ndarray:
        """(6n,) T z = B' S z: the forces and moments of scaled contact forces z (5m,) on the bodies."""
        out = np.empty(len(self.inv_mass))
        transpose_of(self.geometry, z, out)
        return out

    def apply_G(self, h: np.ndarray, c: np.ndarray) -> np.ndarray:
        """(5m,) G h + c = S B Mbar^-1 h + c."""
        out = np.empty_like(c)
        gradient_of(self.geometry, h, self.inv_mass, c, out)
        return out

    def lipschitz_estimate(self) -> float:
        """:func:`lipschitz_estimate` with this iteration's G and T."""
        zero = np.zeros_like(self.c)
        return lipschitz_estimate(power_start(len(self.c)), lambda v: self.apply_G(self.apply_T(v), zero), _dot,
                                  lambda v: np.divide(v, math.sqrt(_dot(v, v)), out=v))

    def gradient_at_x(self) -> np.ndarray:
        """G hx + c: the scaled end-of-step gaps S (B u + g e_n) at the iterate."""
        return self.apply_G(self.hx, self.c)

    def residuals(self, mu, mu_r, scale: float, floor: float) -> dict[str, float]:
        """:func:`colsim.engine.cones.relative_residuals` at the iterate (mu, mu_r (m,): the program's own)."""
        return scaled_residuals(self.gradient_at_x(), self.x, self.scaling.ravel(), mu, mu_r, scale, floor)

    def iterate_and_check(self, n: int, program: ConeProgram, scale: float, floor: float) -> dict[str, float]:
        """:meth:`iterate` n, then :meth:`residuals` there (the GPU's twin reads both in one copy)."""
        self.iterate(n)
        return self.residuals(program.mu, program.mu_r, scale, floor)

    def host_x(self) -> np.ndarray:
        """(5m,) the scaled iterate z."""
        return self.x

    def is_warm(self) -> bool:
        """Does the first iterate hold a force (a warm start)? Asked before iterating."""
        return bool(np.any(self.x))

    def forces(self) -> np.ndarray:
        """(m, 5) the contact forces S z of the iterate."""
        return (self.scaling.ravel() * self.x).reshape(-1, 5)

    def increments(self, program: ConeProgram, forces: np.ndarray) -> np.ndarray:
        """(6n,) u = Mbar^-1 (fbar + B' lam) at the iterate's forces lam (m, 5) (:meth:`forces`)."""
        return program.increments(forces)

    def solution(self, program: ConeProgram, iterations: int, setup_time: float, solve_time: float,
                 info: dict) -> ConeSolution:
        """The solved program's solution at the iterate (times in seconds)."""
        forces = self.forces()
        return ConeSolution(self.increments(program, forces), forces, "Solved", iterations, setup_time, solve_time,
                            info)

    def iterate(self, n: int):
        """n iterations (:func:`run_iterations`)."""
        run_iterations(self, n)

    def trial_round(self, trials: int, check: bool = False):
        """`trials` trial steps, compiled (:func:`apgd_trials` with the host's kernels). check: no
        part of the round (the host computes the residuals when asked, :meth:`residuals`)."""
        (self.x, self.x_prev, self.x_new, self.hx, self.h_new, theta, self.beta, lip, accepted, bt,
         rs) = _trials_compiled(trials, self.x, self.x_prev, self.beta, self.hx, self.hy, self.g, self.x_new,
                                self.h_new, self.theta, self.lip, self.geometry, self.c, self.mu_s, self.mu_r_s,
                                self.inv_mass, self.lip_decay, threads())
        self.theta, self.lip = theta, lip
        self.iterations += accepted
        self.backtracks += bt
        self.restarts += rs


#: the power iteration's start, the longest made so far (numpy's generator fills in sequence, so
#: the first k numbers of a longer draw are those of a draw of k: tests/solvers/test_apgd.py checks it)
_power_start = np.zeros(0)


def power_start(size: int) -> np.ndarray:
    """(size,) the power iteration's fixed random start (reproducible): standard normals from seed 0,
    drawn once for the longest size asked and kept (a draw a step cost more than a small step's iterations)."""
    return power_start_drawn(size)[:size].copy()


def power_start_drawn(size: int) -> np.ndarray:
    """(at least size,) read-only: every number of the power iteration's start drawn so far, drawn
    further first where fewer than `size` (power_start(k) is its first k)."""
    global _power_start
    if size > len(_power_start):
        _power_start = np.random.default_rng(0).standard_normal(max(size, 2 * len(_power_start)))
        _power_start.flags.writeable = False
    return _power_start


def lipschitz_estimate(v, apply_GT, dot, normalise, iterations: int = 12) -> float:
    """The largest eigenvalue of S W S = G T, from below, by power iteration from v (overwritten),
    with a kernel set's operations (the CPU's or the GPU's): apply_GT(v) returns G T v, dot(u, v) the
    scalar product (only the last iteration's, v . G T v, is taken), normalise(v) divides v by its
    norm in place (on a GPU without a copy to the host). The backtracking in the iteration keeps the
    step safe."""
    for _ in range(iterations):
        normalise(v)
        wv = apply_GT(v)
        v, last = wv, v
    return max(dot(last, wv), 1e-12)


def _dot(u: np.ndarray, v: np.ndarray) -> float:
    """u . v without BLAS (a threaded BLAS dot oversubscribes a busy machine badly)."""
    return float(np.einsum("i,i->", u, v))

