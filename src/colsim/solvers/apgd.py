"""A first-order back-end: accelerated projected gradient (APGD) on the contact forces.

It solves the force form of the step's cone program (:mod:`colsim.engine.program`),

    minimise   1/2 lam' W lam + c' lam      subject to lam_k in K_k,
    K_k = {(p, q, r): ||q|| <= mu_k p, ||r|| <= mu_r,k p},

the same convex program as Clarabel (same cones, same associated law), by Nesterov's accelerated
projected gradient with adaptive (gradient) restart and backtracking on the step length, as in
Chrono's APGD (Mazhar et al. 2015). W is never formed: the gradient is

    W lam + c = B u(lam) + g e_n,   u(lam) = Mbar^-1 (fbar + B' lam),

i.e. each contact's gap at the end of the step, so one iteration costs one product with B' and one
with B (work linear in the number of contacts) plus the exact Euclidean projection onto K_k
(:func:`colsim.engine.cones.project_point`). The compiled kernel fuses them and applies B and B' from the
contacts' frames and radii (12 numbers a contact) instead of the matrix (42 non-zeros a contact),
which costs less an iteration (docs/performance.md, "Cost of one APGD iteration").

Preconditioning: each contact's normal, sliding and rolling rows are scaled separately, lam = S z
with S = diag(s_n, s_t, s_t, s_r, s_r) per contact and s = diag(W)^-1/2 (averaged over the two rows
of a pair). The scaled cone is again a coupled cone with mu' = mu s_n/s_t, mu_r' = mu_r s_n/s_r
(mu_s and mu_r_s in the code), so the projection stays exact.

Stopping (checked every `check_every` iterations, at the current iterate lam, in one compiled
sweep): the relative primal infeasibility and complementarity of
:func:`colsim.engine.cones.relative_residuals` must both fall below `tolerance`; dual feasibility
(lam_k in K_k) is exact by construction (the iterate is a projection). Their length L is the
step's root-mean-square free flight, or `length_floor` mean diameters where that is larger: at rest
the free flight is g dt^2 (4e-4 d at r0 = 2 and dt/sqrt(h0/g) = 0.004), and without a floor the
tolerance 1e-5 asks each contact's gap to 4e-9 d, which took most of a resting step's iterations
(at step 900 of an r0 = 2, a = 5 collapse: 1,280 iterations, 310 with the floor 0.1). The
primal residual, a maximum over the contacts, also counts as met once the largest violation is at
most `overlap_tolerance` mean diameters: with the floor, it is what holds most steps after
complementarity has converged (`auto` uses 1e-4 d; 4.3x fewer iterations at r0 = 4).
Not reaching it within `max_iter` iterations raises :class:`SolverError`.

Warm start: the solver accepts forces (m, 5) aligned with the program's contacts (zeros for new
contacts). :class:`colsim.engine.warm_start.WarmStart` carries a step's forces by contact pair, in the
global frame, and re-expresses them in the next step's contact frames.
"""
from __future__ import annotations

import logging
import math
import time

import numpy as np
import scipy.sparse as sp

from . import defaults
from ..engine.cones import (HAVE_NUMBA, force_floor, length_scale, mean_diameter, project_compiled,
                            project_coupled_cone, project_point, row_scaling, scaled_coefficients,
                            scaled_residuals, scales_of_diagonal)
from ..engine.operator import ContactOperator, gradient_of, transpose_of
from ..engine.program import ROWS_PER_CONTACT, ConeProgram
from ..engine.solver_contract import ConeSolution, Solver, SolverError, at_step
from ..engine.compiled import prange
from ..engine.threads import threads

if HAVE_NUMBA:
    import numba

log = logging.getLogger(__name__)


# --------------------------------------------------------------------------------------------
# The iterations: fused numba kernels, or the same steps in numpy
# --------------------------------------------------------------------------------------------

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
            y0 = x[o] + beta * (x[o] - x_prev[o])
            y1 = x[o + 1] + beta * (x[o + 1] - x_prev[o + 1])
            y2 = x[o + 2] + beta * (x[o + 2] - x_prev[o + 2])
            y3 = x[o + 3] + beta * (x[o + 3] - x_prev[o + 3])
            y4 = x[o + 4] + beta * (x[o + 4] - x_prev[o + 4])
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


# APGD's decisions, written once: Nesterov's momentum, the gradient restart, the backtracking on the
# step length (decide). The CPU's loop (apgd_iterations, compiled with the CPU's kernels below) and
# the GPU's (colsim.solvers.apgd_cuda: a kernel a trial step runs decide on the device) both make
# them with it. The numpy loop in _Iteration._iterate_numpy is the tests' oracle.

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


if HAVE_NUMBA:
    decide = numba.njit(cache=True)(decide)


def apgd_iterations(trial_step, extrapolate, gradient):
    """The function iterate(n_iter, x, x_prev, beta, hx, hy, g, x_new, h_new, theta, lip, geometry, c,
    mu_s, mu_r_s, inv_mass, lip_decay, reduction) that runs n_iter APGD iterations with the kernel set
    and returns (x, x_prev, x_new, hx, h_new, theta, beta, lip, backtracks, restarts): the arrays
    trade places (no copies), hy and g are updated in place.

    x, hx = T x: the iterate; the extrapolated point is y = x + beta (x - x_prev), never stored,
    hy = T y, and g = G hy + c the gradient at y; T = B' S and G = S B Mbar^-1 come from the contact
    `geometry` (:class:`colsim.engine.operator.ContactGeometry`). Each trial step's outcome is
    :func:`decide`'s; an accepted one moves the iterate on.

    The kernel set: trial_step(x, x_prev, beta, g, x_new, step, h_new, hy, geometry, mu_s, mu_r_s,
    inv_mass, reduction) sets x_new = Proj_K(y - step g) and h_new = T x_new and returns
    (||x_new - y||^2, g . (x_new - x), ||h_new - hy||^2_{Mbar^-1}); extrapolate(hy, h_new, hx, beta)
    sets hy = h_new + beta (h_new - hx); gradient(hy, inv_mass, geometry, c, g) sets g = G hy + c.
    `reduction` is how the kernels sum (the CPU's: a count of fixed blocks)."""

    def iterate(n_iter, x, x_prev, beta, hx, hy, g, x_new, h_new, theta, lip, geometry, c, mu_s, mu_r_s,
                inv_mass, lip_decay, reduction):
        backtracks = 0
        restarts = 0
        for _ in range(n_iter):
            while True:
                dd, uphill, change = trial_step(x, x_prev, beta, g, x_new, 1.0 / lip, h_new, hy, geometry,
                                                mu_s, mu_r_s, inv_mass, reduction)
                accepted, lip, theta, beta, restarted = decide(dd, uphill, change, lip, theta, beta, lip_decay)
                if accepted:
                    break
                backtracks += 1
            if restarted:
                restarts += 1
            x_prev, x, x_new = x, x_new, x_prev
            extrapolate(hy, h_new, hx, beta)
            hx, h_new = h_new, hx
            gradient(hy, inv_mass, geometry, c, g)
        return x, x_prev, x_new, hx, h_new, theta, beta, lip, backtracks, restarts

    return iterate


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


if HAVE_NUMBA:
    _parallel = numba.njit(cache=True, parallel=True)
    _project_step = _parallel(_project_step)
    _weighted_change = _parallel(_weighted_change)
    _extrapolate = _parallel(_extrapolate)
    _trial_step = numba.njit(cache=True)(_trial_step)
    _gradient = numba.njit(cache=True)(_gradient)
    _iterate_compiled = numba.njit(cache=True)(apgd_iterations(_trial_step, _extrapolate, _gradient))


class _Iteration:
    """The APGD state between residual checks, in scaled forces z (lam = S z); iterate(n) runs n
    iterations: compiled and matrix-free when given the program's operator (B from the contacts'
    frames, :class:`colsim.engine.operator.ContactOperator`), else numpy with G and T."""

    def __init__(self, G, T, c, mu_s, mu_r_s, inv_mass, x, scaling, lip_decay=1.0, operator: ContactOperator | None = None):
        self.G, self.T, self.c, self.mu_s, self.mu_r_s, self.inv_mass = G, T, c, mu_s, mu_r_s, inv_mass
        self.scaling = scaling  # (m, 5) S: lam = S z
        self.geometry = None if operator is None else operator.geometry(scaling.ravel())
        hx = self.apply_T(x)
        self.x, self.hx = x.copy(), hx
        self.x_prev, self.beta, self.hy = x.copy(), 0.0, hx.copy()   # y = x + beta (x - x_prev) = x
        self.g = self.apply_G(self.hy, c)
        self.x_new, self.h_new = np.empty_like(x), np.empty_like(hx)
        self.theta, self.lip = 1.0, self.lipschitz_estimate()
        self.backtracks = self.restarts = 0
        self.lip_decay = float(lip_decay)

    def apply_T(self, z: np.ndarray) -> np.ndarray:
        """(6n,) T z = B' S z: the forces and moments of scaled contact forces z (5m,) on the bodies."""
        if self.geometry is None:
            return self.T @ z
        out = np.empty(len(self.inv_mass))
        transpose_of(self.geometry, z, out)
        return out

    def apply_G(self, h: np.ndarray, c: np.ndarray) -> np.ndarray:
        """(5m,) G h + c = S B Mbar^-1 h + c."""
        if self.geometry is None:
            return self.G @ h + c
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
        if self.geometry is not None:
            (self.x, self.x_prev, self.x_new, self.hx, self.h_new, theta, self.beta, lip, bt,
             rs) = _iterate_compiled(n, self.x, self.x_prev, self.beta, self.hx, self.hy, self.g, self.x_new,
                                     self.h_new, self.theta, self.lip, self.geometry, self.c, self.mu_s, self.mu_r_s,
                                     self.inv_mass, self.lip_decay, threads())
        else:
            theta, lip, bt, rs = self._iterate_numpy(n)
        self.theta, self.lip = theta, lip
        self.backtracks += bt
        self.restarts += rs

    def _iterate_numpy(self, n):
        m = len(self.mu_s)
        theta, lip, bt, rs = self.theta, self.lip, 0, 0
        x, hx, hy, g = self.x, self.hx, self.hy, self.g
        x_prev, beta = self.x_prev, self.beta
        y = x + beta * (x - x_prev)
        for _ in range(n):
            while True:
                x_new = project_coupled_cone((y - g / lip).reshape(m, 5), self.mu_s, self.mu_r_s).ravel()
                h_new = self.T @ x_new
                d = x_new - y
                dh = h_new - hy
                dd = _dot(d, d)
                if dd == 0.0 or _dot(dh * self.inv_mass, dh) <= lip * dd * (1.0 + 1e-12):
                    break
                lip *= 2.0
                bt += 1
            theta_new = 0.5 * (-theta * theta + theta * np.sqrt(theta * theta + 4.0))
            beta = theta * (1.0 - theta) / (theta * theta + theta_new)
            if _dot(g, x_new - x) > 0.0:
                theta_new, beta = 1.0, 0.0
                rs += 1
            theta = theta_new
            lip *= self.lip_decay
            y = x_new + beta * (x_new - x)
            hy = h_new + beta * (h_new - hx)
            x_prev, x, hx = x, x_new, h_new
            g = self.G @ hy + self.c
        self.x, self.x_prev, self.beta, self.hx, self.hy, self.g = x, x_prev, beta, hx, hy, g
        return theta, lip, bt, rs


#: the power iteration's start, the longest made so far (numpy's generator fills in sequence, so
#: the first k numbers of a longer draw are those of a draw of k: tests/solvers/test_apgd.py checks it)
_power_start = np.zeros(0)


def power_start(size: int) -> np.ndarray:
    """(size,) the power iteration's fixed random start (reproducible): standard normals from seed 0,
    drawn once for the longest size asked and kept (a step's draw took about 5-9 ms at r0 = 4)."""
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


class ApgdSolver(Solver):
    """Accelerated projected gradient on the contact forces (see the module docstring).

    tolerance: on the relative primal infeasibility and complementarity (dimensionless).
    max_iter: iterations before :class:`SolverError`. check_every: iterations between residual
    checks. precondition: scale each contact's normal, sliding and rolling rows separately.
    kernel: 'numba' (fused compiled iterations, the default when numba is installed), 'cuda' (the
    same iterations on one GPU, or on numba's simulator: :mod:`colsim.solvers.apgd_cuda`) or 'numpy'.
    length_floor: the residuals' length is at least this many mean diameters (module docstring;
    0: the step's free flight alone).
    overlap_tolerance: the primal residual also counts as met once the largest cone violation of
    the end-of-step gaps (a contact's overlap, for a sticking one) is at most this many mean
    diameters (0: the relative tolerance alone). Complementarity keeps `tolerance` either way.
    lipschitz_decay: the Lipschitz estimate L shrinks by this factor after every iteration and
    doubles when the descent test fails (as in Chrono's APGD): longer steps where W is flatter
    (docs/solvers.md, "The Lipschitz estimate's decay").
    storage: how the GPU's iteration stores its arrays (kernel 'cuda'; defaults.GPU_STORAGES):
    'float64', or 'float32' (:data:`colsim.solvers.apgd_cuda.NARROW_GEOMETRY`: fewer bytes an
    iteration, the stopping test and the step's forces still in float64); a float32 solve that reaches
    the cap is made again in float64 before the solver gives up.
    """

    name = "apgd"
    uses_warm_start = True

    def __init__(self, tolerance: float = defaults.APGD_TOLERANCE, max_iter: int = defaults.APGD_MAX_ITER, check_every: int = 10,
                 precondition: bool = True, kernel: str | None = None, lipschitz_decay: float = defaults.APGD_LIPSCHITZ_DECAY,
                 length_floor: float = 0.0, overlap_tolerance: float = 0.0, storage: str = defaults.DEFAULT_GPU_STORAGE,
                 verbose: bool = False):
        if not tolerance > 0:
            raise ValueError(f"APGD tolerance must be positive, got {tolerance}")
        if max_iter < 1 or check_every < 1:
            raise ValueError("max_iter and check_every must be >= 1")
        if kernel is None:
            kernel = "numba" if HAVE_NUMBA else "numpy"
        if kernel not in ("numba", "numpy", "cuda"):
            raise ValueError(f"APGD kernel must be 'numba', 'cuda' or 'numpy', got {kernel!r}")
        if kernel in ("numba", "cuda") and not HAVE_NUMBA:
            raise ValueError(f"APGD kernel {kernel!r} needs numba installed")
        if kernel == "cuda":
            from numba import cuda

            if not cuda.is_available():
                raise ValueError("APGD kernel 'cuda' needs a CUDA GPU (none is visible here) or numba's "
                                 "simulator (NUMBA_ENABLE_CUDASIM=1)")
        if storage not in defaults.GPU_STORAGES:
            raise ValueError(f"APGD's storage must be one of {', '.join(defaults.GPU_STORAGES)}, got {storage!r}")
        if storage != defaults.DEFAULT_GPU_STORAGE and kernel != "cuda":
            raise ValueError(f"APGD's {storage} storage is the GPU's (kernel 'cuda'); the {kernel} kernel stores "
                             f"{defaults.DEFAULT_GPU_STORAGE}")
        self.storage = storage
        self.tolerance = float(tolerance)
        self.max_iter = int(max_iter)
        self.check_every = int(check_every)
        self.precondition = precondition
        if not 0 < lipschitz_decay <= 1:
            raise ValueError(f"lipschitz_decay must be in (0, 1], got {lipschitz_decay}")
        self.kernel = kernel
        self.lipschitz_decay = float(lipschitz_decay)
        if not length_floor >= 0:
            raise ValueError(f"length_floor must be >= 0 mean diameters, got {length_floor}")
        self.length_floor = float(length_floor)
        if not overlap_tolerance >= 0:
            raise ValueError(f"overlap_tolerance must be >= 0 mean diameters, got {overlap_tolerance}")
        self.overlap_tolerance = float(overlap_tolerance)
        self.verbose = verbose

    @property
    def device(self) -> str:
        return "cuda" if self.kernel == "cuda" else "cpu"

    def describe(self) -> dict:
        """The settings; the overlap tolerance only when it is on and the storage only when it is not
        float64, so that runs made before they existed (and the packings, which do not use the first)
        compare equal to those made after."""
        settings = super().describe()
        if not self.overlap_tolerance:
            del settings["overlap_tolerance"]
        if self.storage == defaults.DEFAULT_GPU_STORAGE:   # likewise the storage, where it is the default
            del settings["storage"]
        return settings

    # -- the iteration ---------------------------------------------------------------------
    def prepare(self, program: ConeProgram, warm_start: np.ndarray | None = None,
                storage: str | None = None) -> "_Iteration":
        """The scaled problem of `program` (m > 0 contacts) and its first iterate, ready to iterate
        (storage: the GPU's, default the solver's)."""
        m = program.m
        if self.kernel == "cuda":   # the scaling, the start and the iterations, all on the device
            from .apgd_cuda import CudaIteration

            return CudaIteration.of_program(program, warm_start, self.precondition, self.lipschitz_decay,
                                            storage or self.storage)
        inv_mass = 1.0 / program.mass
        # the compiled kernels apply B and B' from the contacts' frames and never form B
        operator = program.operator if self.kernel == "numba" else None
        B = None if operator is not None else program.jacobian.tocsr()
        if not self.precondition:
            s = np.ones((m, 5))
        elif operator is not None:
            s = scales_of_diagonal(operator.diagonal(inv_mass))
        else:
            s = row_scaling(B, inv_mass)
        mu_s, mu_r_s = scaled_coefficients(program, s)
        # In z (lam = S z): gradient G h + c with h = T z = B' S z, G = S B Mbar^-1, and
        # c = S (B u_free + g e_n); the descent test needs only h (f is quadratic). The compiled
        # kernels apply T and G from the contacts' frames; the numpy path forms them.
        c = (program.local_displacement(program.fbar * inv_mass)).ravel()
        c[::ROWS_PER_CONTACT] += program.gap
        c *= s.ravel()
        if warm_start is not None and np.shape(warm_start) == (m, ROWS_PER_CONTACT):
            project = project_compiled if operator is not None else project_coupled_cone
            x = project(np.asarray(warm_start, dtype=float) / s, mu_s, mu_r_s).ravel()
        else:
            x = np.zeros(5 * m)
        if operator is not None:
            return _Iteration(None, None, c, mu_s, mu_r_s, inv_mass, x, s, self.lipschitz_decay, operator=operator)
        SB = sp.diags(s.ravel()) @ B
        G = (SB @ sp.diags(inv_mass)).tocsr()
        return _Iteration(G, SB.T.tocsr(), c, mu_s, mu_r_s, inv_mass, x, s, self.lipschitz_decay)

    def stopping_scales(self, program: ConeProgram) -> tuple[float, float, float]:
        """The stopping rule's scales for `program`: the residuals' length L (the free flight or
        `length_floor` mean diameters d, whichever is larger), the force floor F0 (from the free
        flight alone) and the primal tolerance (relative to L: `tolerance`, or the overlap
        tolerance's `overlap_tolerance` d / L where that is larger)."""
        diameter = mean_diameter(program)
        free_flight = length_scale(program, diameter)
        scale = max(free_flight, self.length_floor * diameter)
        return (scale, force_floor(program, free_flight),
                max(self.tolerance, self.overlap_tolerance * diameter / scale))

    def solve(self, program: ConeProgram, warm_start: np.ndarray | None = None,
              step: int | None = None, max_iter: int | None = None) -> ConeSolution:
        """Solve `program` from `warm_start` ((m, 5) forces or None); max_iter: this call's cap
        (default: the solver's). Under float32 storage a solve that reaches the cap is made again from
        the same start in float64 (its info's `storage` says which solved, and its `backend` is
        defaults.FLOAT64_FALLBACK, which a collapse records as the step's `step_solver_backend`)."""
        if program.m == 0:
            return self.no_contacts(program)
        try:
            return self._solve(program, warm_start, step, max_iter, self.storage)
        except SolverError as error:
            if self.storage == defaults.DEFAULT_GPU_STORAGE:
                raise
            log.info("%s with %s storage; solving this step again with %s", error, self.storage,
                     defaults.DEFAULT_GPU_STORAGE)
            solution = self._solve(program, warm_start, step, max_iter, defaults.DEFAULT_GPU_STORAGE)
            solution.backend = defaults.FLOAT64_FALLBACK
            return solution

    def _solve(self, program: ConeProgram, warm_start, step, max_iter, storage: str) -> ConeSolution:
        """:meth:`solve` with the GPU's `storage`."""
        start = time.perf_counter()
        m = program.m
        max_iter = self.max_iter if max_iter is None else int(max_iter)
        run = self.prepare(program, warm_start, storage)
        started = "warm" if run.is_warm() else "cold"
        scale, floor, primal_tolerance = self.stopping_scales(program)
        setup_time = time.perf_counter() - start

        res = {"primal": np.inf, "dual": 0.0, "complementarity": np.inf}
        k = 0
        converged = False
        while k < max_iter:
            n = min(self.check_every, max_iter - k)
            res = run.iterate_and_check(n, program, scale, floor)
            k += n
            if self.verbose:
                log.info("apgd %d: primal %.2e compl %.2e L %.3g", k, res["primal"],
                         res["complementarity"], run.lip)
            if res["primal"] <= primal_tolerance and res["complementarity"] <= self.tolerance:
                converged = True
                break
        solve_time = time.perf_counter() - start - setup_time
        info = dict(res, start=started, backtracks=run.backtracks, restarts=run.restarts,
                    lipschitz=run.lip, length_scale=scale, kernel=self.kernel)
        if self.kernel == "cuda":
            info["storage"] = storage
        if not converged:
            raise SolverError(
                f"APGD did not converge{at_step(step)} within {max_iter} iterations "
                f"(relative primal infeasibility {res['primal']:.2e}, complementarity "
                f"{res['complementarity']:.2e}, tolerance {self.tolerance:.1e}, {m} contacts)",
                status="MaxIterations", step=step, residuals=res)
        return run.solution(program, k, setup_time, solve_time, info)
