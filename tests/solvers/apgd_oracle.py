"""APGD's iteration in plain numpy: the tests' oracle for the compiled kernels.

The same iteration as :class:`colsim.engine.apgd_iteration.CpuIteration`, written from the
matrices: B built (:attr:`colsim.engine.program.ConeProgram.jacobian`), the rows' scaling taken from
it (:func:`colsim.engine.cones.row_scaling`), G = S B Mbar^-1 and T = B' S formed, the projection
numpy's (:func:`colsim.engine.cones.project_coupled_cone`) and the decisions spelled out in the loop.
:class:`NumpyBackend` hands it to :class:`colsim.solvers.apgd.ApgdSolver`: a solver on it runs APGD's
one control flow on this iteration.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from colsim.engine.apgd_iteration import CpuIteration, _dot, scaled_gaps
from colsim.engine.backend import CpuBackend
from colsim.engine.cones import project_coupled_cone, row_scaling, scaled_coefficients
from colsim.engine.program import ROWS_PER_CONTACT


class NumpyIteration(CpuIteration):
    """:class:`CpuIteration` with G and T as sparse matrices and the loop in numpy."""

    def __init__(self, program, warm_start, precondition: bool, lip_decay: float):
        m = program.m
        inv_mass = 1.0 / program.mass
        B = program.jacobian.tocsr()
        s = row_scaling(B, inv_mass) if precondition else np.ones((m, 5))
        mu_s, mu_r_s = scaled_coefficients(program, s)
        if warm_start is not None and np.shape(warm_start) == (m, ROWS_PER_CONTACT):
            x = project_coupled_cone(np.asarray(warm_start, dtype=float) / s, mu_s, mu_r_s).ravel()
        else:
            x = np.zeros(5 * m)
        SB = sp.diags(s.ravel()) @ B
        self.G, self.T = (SB @ sp.diags(inv_mass)).tocsr(), SB.T.tocsr()
        super().__init__(None, scaled_gaps(program, inv_mass, s), mu_s, mu_r_s, inv_mass, x, s, lip_decay)

    def apply_T(self, z):
        return self.T @ z

    def apply_G(self, h, c):
        return self.G @ h + c

    def iterate(self, n: int):
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
        self.theta, self.lip = theta, lip
        self.backtracks += bt
        self.restarts += rs


class NumpyBackend(CpuBackend):
    """The host's back-end with APGD's iteration in numpy (:class:`NumpyIteration`)."""

    apgd_kernel = "numpy"

    def apgd_iteration(self, program, warm_start, precondition, lip_decay, storage):
        return NumpyIteration(program, warm_start, precondition, lip_decay)
