"""An operator-splitting back-end: ADMM on the displacement (primal) form, as OSQP does for QPs.

The step's program (:mod:`colsim.engine.program`) in its displacement form is

    minimise   1/2 u' Mbar u - fbar' u   subject to   y = B u + g e_n in C,
    C = {y: y_n >= mu ||y_t|| + mu_r ||y_r||} per contact,

whose dual cone is the force cone K = {(p, q, r): ||q|| <= mu p, ||r|| <= mu_r p}.

Scaling: each contact's normal, sliding and rolling rows are scaled, y^ = D y with
D = diag(s_n, s_t, s_t, s_r, s_r) per contact and s = diag(B Mbar^-1 B')^-1/2 (the scaling of
:func:`colsim.engine.cones.row_scaling`). The scaled cone is the same kind of cone with mu^ = mu s_n/s_t and
mu_r^ = mu_r s_n/s_r, so the Euclidean projection onto it stays exact, and a scalar penalty rho in
the scaled space is the per-row penalty R = rho D^2 in the original one.

Iteration (scaled ADMM; w is the scaled dual variable, alpha the over-relaxation):

    u  <- (Mbar + rho B' D^2 B)^-1 (fbar + rho B' D (z - w - D g e_n))   [one factorisation, reused]
    x  <- alpha D (B u + g e_n) + (1 - alpha) z
    z  <- Proj_C^(x + w) = (x + w) + Proj_K^(-(x + w))                   [Moreau; exact projection]
    w  <- w + x - z

so -w stays in K^ and z in C^ with z . w = 0 exactly; the contact forces are lam = -rho D w (in K
by construction) and u solves Mbar u = fbar + B' lam at convergence (ClarabelSolver's convention).

Stopping (every `check_every` iterations), both as lengths relative to the free-flight length L
(:func:`colsim.engine.cones.length_scale`): primal max |B u + g e_n - z| / L, and dual
max |u - u(lam)| / L with u(lam) = Mbar^-1 (fbar + B' lam). APGD's force-form residuals of the
result are recorded in the solution's info as force_form_*. Not converging within `max_iter`
iterations raises :class:`SolverError`.

Changing rho: every `adapt_every` iterations rho is multiplied by `rho_growth` (default: 10 once,
after 300 iterations), refactorising at most `max_refactor` times per step. With rho_growth = 0
the factor is OSQP's rule, sqrt(primal residual / dual residual), applied when it changes rho by
more than `adapt_factor`; here that rule lowered rho and slowed convergence.

Not faster than Clarabel at any size measured: its iteration count shrinks neither with a warm start
nor with size, and most of an iteration is the two triangular solves; the forces, which a
hyperstatic packing leaves nearly indeterminate, converge last (docs/performance.md has the measurements).

Warm start: forces (m, 5) (the stepper passes the previous step's forces matched by contact pair,
:class:`colsim.solvers.WarmStart`): w = -D^-1 lam / rho and z = Proj_C^(D (B u(lam) + g e_n) + w).
"""
from __future__ import annotations

import logging
import time

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from . import defaults
from ..engine.cones import (force_floor, length_scale, project_coupled_cone, project_gap_cone,
                    relative_residuals, row_scaling, scaled_coefficients)
from ..engine.program import ROWS_PER_CONTACT, ConeProgram
from ..engine.solver_contract import ConeSolution, Solver, SolverError, at_step

log = logging.getLogger(__name__)


class _Factor:
    """A sparse LU factorisation (scipy splu, symmetric mode) of the SPD matrix Mbar + rho B' D^2 B."""

    def __init__(self, matrix: sp.spmatrix, ordering: str):
        lu = spla.splu(sp.csc_matrix(matrix), permc_spec=ordering,
                       options={"SymmetricMode": True}, diag_pivot_thresh=0.0)
        self.solve = lu.solve


class AdmmSolver(Solver):
    """Scaled ADMM on the displacement form (see the module docstring).

    tolerance: on the relative primal infeasibility and complementarity (as APGD's).
    rho: the penalty relative to diag(B Mbar^-1 B')^-1 (dimensionless). alpha: over-relaxation.
    adaptive: change rho during the solve (see 'Changing rho' in the module docstring).
    factorization: the scipy splu column ordering ('MMD_AT_PLUS_A', 'COLAMD', 'MMD_ATA', 'NATURAL').
    """

    name = "admm"
    uses_warm_start = True

    def __init__(self, tolerance: float = defaults.ADMM_TOLERANCE, max_iter: int = defaults.ADMM_MAX_ITER, rho: float = 30.0,
                 alpha: float = 1.6, adaptive: bool = True, adapt_every: int = 300,
                 adapt_factor: float = 5.0, max_refactor: int = 1, check_every: int = 10,
                 factorization: str = "MMD_AT_PLUS_A", rho_growth: float = 10.0,
                 verbose: bool = False):
        if not tolerance > 0:
            raise ValueError(f"ADMM tolerance must be positive, got {tolerance}")
        if not rho > 0:
            raise ValueError(f"ADMM rho must be positive, got {rho}")
        if not 0 < alpha < 2:
            raise ValueError(f"ADMM alpha must be in (0, 2), got {alpha}")
        if max_iter < 1 or check_every < 1 or adapt_every < 1:
            raise ValueError("max_iter, check_every and adapt_every must be >= 1")
        self.tolerance = float(tolerance)
        self.max_iter = int(max_iter)
        self.rho = float(rho)
        self.alpha = float(alpha)
        self.adaptive = adaptive
        self.adapt_every = int(adapt_every)
        self.adapt_factor = float(adapt_factor)
        self.max_refactor = int(max_refactor)
        self.check_every = int(check_every)
        self.factorization = factorization
        self.rho_growth = float(rho_growth)
        self.verbose = verbose

    def solve(self, program: ConeProgram, warm_start: np.ndarray | None = None,
              step: int | None = None) -> ConeSolution:
        if program.m == 0:
            return self.no_contacts(program)
        start = time.perf_counter()
        m = program.m
        B = program.jacobian.tocsr()
        mass = program.mass
        inv_mass = 1.0 / mass
        fbar = program.fbar
        s = row_scaling(B, inv_mass)            # (m, 5): D
        d = s.ravel()
        a, b = scaled_coefficients(program, s)  # the scaled cone's coefficients
        A = (sp.diags(d) @ B).tocsr()           # D B
        AT = A.T.tocsr()
        AtA = (AT @ A).tocsc()
        h = np.zeros(5 * m)                     # D g e_n
        h[::ROWS_PER_CONTACT] = d[::ROWS_PER_CONTACT] * program.gap
        scale = length_scale(program)
        floor = force_floor(program, scale)
        rho = self.rho
        t0 = time.perf_counter()
        factor = _Factor(sp.diags(mass) + rho * AtA, self.factorization)
        factor_time = time.perf_counter() - t0
        refactors = 0

        def forces_of(w, rho):
            return (-rho * d * w).reshape(m, ROWS_PER_CONTACT)

        if warm_start is not None and np.shape(warm_start) == (m, ROWS_PER_CONTACT):
            lam = project_coupled_cone(np.asarray(warm_start, dtype=float), program.mu, program.mu_r)
            w = -lam.ravel() / (rho * d)
            started = "warm"
        else:
            lam = np.zeros((m, ROWS_PER_CONTACT))
            w = np.zeros(5 * m)
            started = "cold"
        u = program.increments(lam)
        z = project_gap_cone((A @ u + h + w).reshape(m, 5), a, b).ravel()
        setup_time = time.perf_counter() - start

        res = {"primal": np.inf, "dual": np.inf}
        converged = False
        k = 0
        solve_s = 0.0
        while k < self.max_iter:
            k += 1
            t0 = time.perf_counter()
            u = factor.solve(fbar + rho * (AT @ (z - w - h)))
            solve_s += time.perf_counter() - t0
            Au = A @ u
            ax = Au + h
            x = self.alpha * ax + (1.0 - self.alpha) * z
            z_prev = z
            v = x + w
            z = project_gap_cone(v.reshape(m, 5), a, b).ravel()
            w = v - z
            if k % self.check_every == 0 or k == self.max_iter:
                lam = forces_of(w, rho)
                u_lam = program.increments(lam)
                res = {"primal": float(np.max(np.abs((ax - z) / d))) / scale,
                       "dual": float(np.max(np.abs(u - u_lam))) / scale}
                if self.verbose:
                    log.info("admm %d: rho %.3g primal %.2e dual %.2e", k, rho, res["primal"],
                             res["dual"])
                if res["primal"] <= self.tolerance and res["dual"] <= self.tolerance:
                    converged = True
                    break
            if self.adaptive and k % self.adapt_every == 0 and refactors < self.max_refactor:
                # OSQP: relative primal and dual residuals of the scaled problem
                r_prim = np.max(np.abs(ax - z)) / max(np.max(np.abs(ax)), np.max(np.abs(z)), 1e-300)
                Atw = rho * (AT @ w)
                r_dual = (np.max(np.abs(rho * (AT @ (z - z_prev)))) /
                          max(np.max(np.abs(mass * u)), np.max(np.abs(Atw)), np.max(np.abs(fbar)),
                              1e-300))
                factor_rho = np.sqrt(r_prim / max(r_dual, 1e-300))
                if self.rho_growth:
                    factor_rho = self.rho_growth
                if factor_rho > self.adapt_factor or factor_rho < 1.0 / self.adapt_factor:
                    new_rho = rho * factor_rho
                    w *= rho / new_rho          # keep the forces lam = -rho D w
                    rho = new_rho
                    t0 = time.perf_counter()
                    factor = _Factor(sp.diags(mass) + rho * AtA, self.factorization)
                    factor_time += time.perf_counter() - t0
                    refactors += 1
        solve_time = time.perf_counter() - start - setup_time
        lam = forces_of(w, rho)
        info = dict(res, start=started, rho=rho, refactors=refactors, factor_time=factor_time,
                    linear_solve_time=solve_s, length_scale=scale, factorization=self.factorization)
        if not converged:
            raise SolverError(
                f"ADMM did not converge{at_step(step)} within {self.max_iter} iterations "
                f"(relative primal residual {res['primal']:.2e}, dual residual "
                f"{res['dual']:.2e}, tolerance {self.tolerance:.1e}, {m} contacts)",
                status="MaxIterations", step=step, residuals=res)
        y = program.end_of_step_gaps(u)
        info.update({"force_form_" + key: value for key, value in
                     relative_residuals(y, lam, program.mu, program.mu_r, scale, floor).items()})
        return ConeSolution(u, lam, "Solved", k, setup_time, solve_time, info)
