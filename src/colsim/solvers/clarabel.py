"""The reference back-end: Clarabel's interior-point method on the step's cone program.

Clarabel solves the program of :mod:`colsim.engine.program` to high accuracy in 20-60 KKT factorisations
whatever the step size; its cost per factorisation grows about N^1.65-1.8 (3D fill). It is the
reference every other back-end is tested against.
"""
from __future__ import annotations

import logging
import time

import clarabel
import numpy as np
import scipy.sparse as sp

from ..engine.program import ROWS_PER_CONTACT, ConeProgram
from . import defaults

from ..engine.solver_contract import ConeSolution, Solver, SolverError, at_step

log = logging.getLogger(__name__)


def _rows(matrix: sp.csr_matrix, index: np.ndarray) -> sp.coo_matrix:
    return matrix[index].tocoo()


class ClarabelSolver(Solver):
    """Clarabel's interior-point method on the displacement form (default) or the force form.

    direct_solve_method: 'qdldl' or 'faer' (Clarabel's KKT factorisation); threads: faer threads (0 = all).
    Defaults faer with 1 thread, by measurement (benchmarks/step.py, docs/performance.md): faer takes
    less CPU time than qdldl at the same accuracy, and a study runs several simulations at once anyway.
    equilibrate: Clarabel's Ruiz equilibration. Off by default: on resting, hyperstatic packings with
    rolling resistance it ended NumericalError on 2 of 3 test collapses, off it solved every step.
    retry: on NumericalError or InsufficientProgress, try again with equilibration and extra static
    regularisation, then with the other form; a retry is logged and recorded in the solution's info.
    accept_almost_solved: take AlmostSolved as a result (it is recorded in the status).
    """

    name = "clarabel"
    RETRY_STATUSES = ("NumericalError", "InsufficientProgress")

    def __init__(self, form: str = "displacement", direct_solve_method: str = "faer",
                 threads: int = 1, tolerance: float = defaults.CLARABEL_TOLERANCE, max_iter: int = defaults.CLARABEL_MAX_ITER,
                 equilibrate: bool = False, retry: bool = True,
                 accept_almost_solved: bool = True, verbose: bool = False):
        if form not in ("displacement", "force"):
            raise ValueError(f"Clarabel form must be 'displacement' or 'force', got {form!r}")
        if direct_solve_method not in ("qdldl", "faer", "auto"):
            raise ValueError(f"direct_solve_method must be qdldl, faer or auto, got {direct_solve_method!r}")
        if not tolerance > 0:
            raise ValueError(f"solver tolerance must be positive, got {tolerance}")
        self.form = form
        self.direct_solve_method = direct_solve_method
        self.threads = threads
        self.tolerance = tolerance
        self.max_iter = max_iter
        self.equilibrate = equilibrate
        self.retry = retry
        self.accept_almost_solved = accept_almost_solved
        self.verbose = verbose

    def _settings(self, **overrides):
        settings = clarabel.DefaultSettings()
        settings.verbose = self.verbose
        settings.direct_solve_method = self.direct_solve_method
        settings.max_threads = self.threads
        settings.tol_gap_abs = settings.tol_gap_rel = settings.tol_feas = self.tolerance
        settings.max_iter = self.max_iter
        settings.equilibrate_enable = self.equilibrate
        for key, value in overrides.items():
            setattr(settings, key, value)
        return settings

    def _attempts(self):
        """(form, settings overrides) to try in turn."""
        other = "force" if self.form == "displacement" else "displacement"
        attempts = [(self.form, {})]
        if self.retry:
            attempts += [(self.form, {"equilibrate_enable": not self.equilibrate,
                                      "static_regularization_constant": 1e-7}), (other, {})]
        return attempts

    def solve(self, program, warm_start=None, step=None):
        if program.m == 0:
            return self.no_contacts(program)
        start = time.perf_counter()
        setup_time, failures = 0.0, []
        for form, overrides in self._attempts():
            t0 = time.perf_counter()
            build = self._displacement_form if form == "displacement" else self._force_form
            P, q, A, b, cones, unpack = build(program)
            solver = clarabel.DefaultSolver(P, q, A, b, cones, self._settings(**overrides))
            setup_time += time.perf_counter() - t0
            result = solver.solve()
            status = str(result.status)
            if status not in self.RETRY_STATUSES:
                break
            failures.append(f"{form} {overrides or 'defaults'}: {status}")
            log.info("Clarabel ended %s at step %s (%s form); retrying", status, step, form)
        solve_time = time.perf_counter() - start - setup_time
        residuals = {"primal": result.r_prim, "dual": result.r_dual}
        ok = status == "Solved" or (status == "AlmostSolved" and self.accept_almost_solved)
        if not ok:
            raise SolverError(
                f"Clarabel ended {status}{at_step(step)} after {result.iterations} iterations "
                f"(primal residual {result.r_prim:.2e}, dual residual {result.r_dual:.2e}, "
                f"{program.m} contacts; attempts: {'; '.join(failures) or 'one'})",
                status=status, step=step, residuals=residuals)
        if status != "Solved":
            log.info("Clarabel ended %s at step %s (primal residual %.2e, dual %.2e)",
                     status, step, result.r_prim, result.r_dual)
        u, forces = unpack(np.asarray(result.x), np.asarray(result.z))
        info = {**residuals, "retries": failures}
        return ConeSolution(u, forces, status, result.iterations, setup_time, solve_time, info)

    @staticmethod
    def _displacement_form(program: ConeProgram):
        """Variables [u (6n); b (mr)], one auxiliary per rolling contact. Per contact k, by type:

        mu > 0:            (g + du_n - b_k, mu du_t) in SOC3      (b_k only if mu_r > 0)
        mu_r > 0:          (b_k, mu_r dphi) in SOC3
        mu = 0:            g + du_n - b_k >= 0                    (a non-negative row)

        i.e. g + du_n >= mu ||du_t|| + mu_r ||dphi||. The gap rides in the sliding cone, which saves
        one variable and one row per contact against a separate non-negative row (KKT size 6n + 7m
        rather than 6n + 9m). The duals are the forces: p is the first entry of the sliding cone
        (or the non-negative row), q = mu times its tail, r = mu_r times the rolling cone's tail.
        """
        nu, m = program.n_unknowns, program.m
        B = program.jacobian
        plain = np.flatnonzero(program.mu == 0)
        sliding = np.flatnonzero(program.mu > 0)
        rolling = np.flatnonzero(program.mu_r > 0)
        mp, ms, mr = len(plain), len(sliding), len(rolling)
        aux = np.full(m, -1)
        aux[rolling] = nu + np.arange(mr)
        # the row of each contact's normal constraint: first the plain rows, then the sliding cones
        normal_row = np.empty(m, dtype=np.int64)
        normal_row[plain] = np.arange(mp)
        normal_row[sliding] = mp + 3 * np.arange(ms)
        normal = _rows(B, ROWS_PER_CONTACT * np.arange(m))
        has_aux = aux >= 0
        rows = [normal_row[normal.row], normal_row[has_aux]]
        cols = [normal.col, aux[has_aux]]
        vals = [-normal.data, np.ones(int(has_aux.sum()))]
        row0 = mp + 3 * ms
        for members, coefficient, first, base in ((sliding, program.mu, 1, mp),
                                                  (rolling, program.mu_r, 3, row0)):
            picked = np.stack([ROWS_PER_CONTACT * members + first,
                               ROWS_PER_CONTACT * members + first + 1], axis=1).ravel()
            tangential = _rows(B, picked)
            cone = tangential.row // 2
            rows.append(base + 3 * cone + 1 + tangential.row % 2)
            cols.append(tangential.col)
            vals.append(-coefficient[members][cone] * tangential.data)
        rows.append(row0 + 3 * np.arange(mr))     # rolling cones' first entry: b_k
        cols.append(aux[rolling])
        vals.append(-np.ones(mr))
        n_rows = row0 + 3 * mr
        A = sp.csc_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                          shape=(n_rows, nu + mr))
        P = sp.diags(np.concatenate([program.mass, np.zeros(mr)]), format="csc")
        q = np.concatenate([-program.fbar, np.zeros(mr)])
        b = np.zeros(n_rows)
        b[normal_row] = program.gap
        cones = ([clarabel.NonnegativeConeT(mp)] if mp else []) + [clarabel.SecondOrderConeT(3)] * (ms + mr)

        def unpack(x, z):
            forces = np.zeros((m, ROWS_PER_CONTACT))
            forces[:, 0] = z[normal_row]
            slide = z[mp:row0].reshape(ms, 3)
            roll = z[row0:].reshape(mr, 3)
            forces[sliding, 1:3] = program.mu[sliding, None] * slide[:, 1:]
            forces[rolling, 3:5] = program.mu_r[rolling, None] * roll[:, 1:]
            return x[:nu], forces

        return P, q, A, b, cones, unpack

    @staticmethod
    def _force_form(program: ConeProgram):
        """Variables lam (5m); p >= 0, (mu p, q) and (mu_r p, r) in second-order cones (zero cones if mu = 0)."""
        m = program.m
        B = program.jacobian
        scaled = sp.diags(1.0 / program.mass) @ B.T
        P = sp.triu(B @ scaled, format="csc")
        c = B @ (program.fbar / program.mass)
        c[::ROWS_PER_CONTACT] += program.gap
        k = np.arange(m)
        col = ROWS_PER_CONTACT * k
        rows, cols, vals, cones = [k], [col], [-np.ones(m)], [clarabel.NonnegativeConeT(m)]
        row0 = m
        for coefficient, first in ((program.mu, 1), (program.mu_r, 3)):
            zero = np.flatnonzero(coefficient == 0)
            rows.append(row0 + np.arange(2 * len(zero)))
            cols.append((col[zero][:, None] + first + np.arange(2)).ravel())
            vals.append(np.ones(2 * len(zero)))
            if len(zero):
                cones.append(clarabel.ZeroConeT(2 * len(zero)))
            row0 += 2 * len(zero)
        for coefficient, first in ((program.mu, 1), (program.mu_r, 3)):
            members = np.flatnonzero(coefficient > 0)
            base = row0 + 3 * np.arange(len(members))
            rows += [base, base + 1, base + 2]
            cols += [col[members], col[members] + first, col[members] + first + 1]
            vals += [-coefficient[members], -np.ones(len(members)), -np.ones(len(members))]
            cones += [clarabel.SecondOrderConeT(3)] * len(members)
            row0 += 3 * len(members)
        A = sp.csc_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                          shape=(row0, ROWS_PER_CONTACT * m))
        b = np.zeros(row0)

        def unpack(x, z):
            forces = x.reshape(m, ROWS_PER_CONTACT)
            return program.increments(forces), forces

        return P, c, A, b, cones, unpack
