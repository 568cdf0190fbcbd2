"""The cone toolkit shared by the iterative back-ends: projections, row scalings and residuals.

Every contact k has the force cone K_k = {(p, q, r): ||q|| <= mu_k p, ||r|| <= mu_r,k p} (the
multipliers lam_k = (p, q1, q2, r1, r2) of :mod:`colsim.engine.program`) and its dual, the cone of
admissible end-of-step gaps C_k = {y: y_n >= mu_k ||y_t|| + mu_r,k ||y_r||}. This module projects
onto both exactly, scales a contact's rows so that the two cones keep their form, and measures how
far forces and gaps are from a solution in dimensionless terms. It knows nothing of any solver.

Residuals (relative, the stopping rule of :mod:`colsim.solvers.apgd` and :mod:`colsim.solvers.admm`):
  - primal: max_k (mu ||y_t|| + mu_r ||y_r|| - y_n)_+ / L;
  - dual: max_k max(||q|| - mu p, ||r|| - mu_r p, -p)_+ / F;
  - complementarity: sum_k |lam_k . y_k| / ((sum_k p_k + m F0) L);
with L the length of :func:`length_scale`, F0 = :func:`force_floor` (about the weight of a mean
particle at rest) and F = max(mean p, F0), so that a step whose contacts all open still converges.
"""
from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp

from .compiled import numba, prange
from .program import ROWS_PER_CONTACT, ConeProgram
from .threads import threads


# --------------------------------------------------------------------------------------------
# The exact projection onto the coupled force cone
# --------------------------------------------------------------------------------------------

def project_coupled_cone(lam: np.ndarray, mu: np.ndarray, mu_r: np.ndarray) -> np.ndarray:
    """Euclidean projection of points lam (m, 5) = (p, q1, q2, r1, r2) onto
    {||q|| <= mu p, ||r|| <= mu_r p} (mu, mu_r (m,) >= 0; 0 forces q or r to zero).

    For a fixed p the nearest q and r are radial clips of q0, r0 to radii mu p and mu_r p, so the
    squared distance is phi(p) = (p - p0)^2 + (||q0|| - mu p)_+^2 + (||r0|| - mu_r p)_+^2, a convex
    piecewise quadratic on p >= 0 with breakpoints ||q0||/mu and ||r0||/mu_r. The piece holding the
    minimiser is chosen by the sign of the monotone derivative phi' at the breakpoints (exact: no
    comparison of nearly equal phi values), and the minimiser of that piece is clipped to it.
    """
    lam = np.asarray(lam, dtype=float)
    p0 = lam[:, 0]
    nq = np.sqrt(lam[:, 1] ** 2 + lam[:, 2] ** 2)
    nr = np.sqrt(lam[:, 3] ** 2 + lam[:, 4] ** 2)
    mu_k = np.broadcast_to(np.asarray(mu, dtype=float), p0.shape)
    mu_r_k = np.broadcast_to(np.asarray(mu_r, dtype=float), p0.shape)
    with np.errstate(divide="ignore", invalid="ignore"):
        bq = np.where(mu_k > 0, nq / np.where(mu_k > 0, mu_k, 1.0), np.inf)  # q clipped iff p < bq
        br = np.where(mu_r_k > 0, nr / np.where(mu_r_k > 0, mu_r_k, 1.0), np.inf)
    q_first = bq <= br
    t1 = np.where(q_first, bq, br)
    t2 = np.where(q_first, br, bq)
    c2 = np.where(q_first, mu_r_k, mu_k)          # the term whose breakpoint is t2: coefficient, norm
    n2 = np.where(q_first, nr, nq)
    finite1, finite2 = np.isfinite(t1), np.isfinite(t2)
    t1f, t2f = np.where(finite1, t1, 0.0), np.where(finite2, t2, 0.0)
    # phi'/2 at t1 (only the t2 term active) and at t2 (none active)
    slope1 = t1f - p0 - c2 * np.maximum(n2 - c2 * t1f, 0.0)
    slope2 = t2f - p0
    p_both = np.clip((p0 + mu_k * nq + mu_r_k * nr) / (1.0 + mu_k * mu_k + mu_r_k * mu_r_k), 0.0, t1)
    p_mid = np.clip((p0 + c2 * n2) / (1.0 + c2 * c2), t1f, t2)
    p = np.where(~finite1 | (slope1 >= 0), p_both,
                 np.where(~finite2 | (slope2 >= 0), p_mid, np.maximum(p0, t2f)))
    p = np.maximum(p, 0.0)
    out = np.empty_like(lam)
    out[:, 0] = p
    with np.errstate(divide="ignore", invalid="ignore"):
        fq = np.where(nq > mu_k * p, mu_k * p / np.where(nq > 0, nq, 1.0), 1.0)
        fr = np.where(nr > mu_r_k * p, mu_r_k * p / np.where(nr > 0, nr, 1.0), 1.0)
    out[:, 1:3] = lam[:, 1:3] * fq[:, None]
    out[:, 3:5] = lam[:, 3:5] * fr[:, None]
    return out


def project_point(p0, q1, q2, r1, r2, mu, mu_r):
    """:func:`project_coupled_cone` of one point onto {||q|| <= mu p, ||r|| <= mu_r p} (scalar code:
    compiled by numba, and for the GPU by numba.cuda)."""
    nq = math.sqrt(q1 * q1 + q2 * q2)
    nr = math.sqrt(r1 * r1 + r2 * r2)
    if p0 >= 0.0 and nq <= mu * p0 and nr <= mu_r * p0:  # inside (0 <= 0 * p0 holds for p0 < 0 too)
        return p0, q1, q2, r1, r2
    bq = nq / mu if mu > 0 else math.inf
    br = nr / mu_r if mu_r > 0 else math.inf
    if bq <= br:
        t1, t2, c2, n2 = bq, br, mu_r, nr
    else:
        t1, t2, c2, n2 = br, bq, mu, nq
    if t1 < math.inf and t1 - p0 - c2 * max(n2 - c2 * t1, 0.0) < 0.0:
        if t2 < math.inf and t2 - p0 < 0.0:
            p = max(p0, t2)                                   # no term active
        else:
            p = min(max((p0 + c2 * n2) / (1.0 + c2 * c2), t1), t2)  # only the t2 term active
    else:
        p = min(max((p0 + mu * nq + mu_r * nr) / (1.0 + mu * mu + mu_r * mu_r), 0.0), t1)  # both active
    p = max(p, 0.0)
    fq = mu * p / nq if nq > mu * p else 1.0
    fr = mu_r * p / nr if nr > mu_r * p else 1.0
    return p, q1 * fq, q2 * fq, r1 * fr, r2 * fr


def _project_rows(lam, a, b):
    out = np.empty_like(lam)
    for k in range(lam.shape[0]):
        p, q1, q2, r1, r2 = project_point(lam[k, 0], lam[k, 1], lam[k, 2], lam[k, 3], lam[k, 4],
                                          a[k], b[k])
        out[k, 0], out[k, 1], out[k, 2], out[k, 3], out[k, 4] = p, q1, q2, r1, r2
    return out


project_point = numba.njit(cache=True, inline="always")(project_point)
_project_rows = numba.njit(cache=True)(_project_rows)


def project_compiled(lam: np.ndarray, mu: np.ndarray, mu_r: np.ndarray) -> np.ndarray:
    """:func:`project_coupled_cone` by the scalar kernel, compiled."""
    return _project_rows(np.ascontiguousarray(lam, dtype=float), np.ascontiguousarray(mu, dtype=float),
                         np.ascontiguousarray(mu_r, dtype=float))


def project_gap_cone(y: np.ndarray, mu: np.ndarray, mu_r: np.ndarray) -> np.ndarray:
    """Euclidean projection of y (m, 5) onto C = {y_n >= mu ||y_t|| + mu_r ||y_r||}, the dual cone
    of the force cone: by Moreau's decomposition Proj_C(y) = y + Proj_K(-y), K = C*."""
    return y + project_compiled(-y, mu, mu_r)


# --------------------------------------------------------------------------------------------
# Scaling and residuals
# --------------------------------------------------------------------------------------------

def row_scaling(B: sp.csr_matrix, inv_mass: np.ndarray) -> np.ndarray:
    """(m, 5) per-row scales s = diag(B Mbar^-1 B')^-1/2, shared by the two rows of a tangent pair.

    With lam = S z the scaled cone is again a coupled cone, with mu' = mu s_n/s_t and
    mu_r' = mu_r s_n/s_r (:func:`scaled_coefficients`), so its projection stays exact."""
    return scales_of_diagonal((B.multiply(B) @ inv_mass).reshape(-1, ROWS_PER_CONTACT))


def scales_of_diagonal(diag: np.ndarray) -> np.ndarray:
    """(m, 5) the row scales of :func:`row_scaling` from diag(B Mbar^-1 B') (m, 5) (the matrix-free
    path: :meth:`colsim.engine.operator.ContactOperator.diagonal`)."""
    s = np.empty_like(diag)
    s[:, 0] = diag[:, 0]
    s[:, 1:3] = 0.5 * (diag[:, 1] + diag[:, 2])[:, None]
    s[:, 3:5] = 0.5 * (diag[:, 3] + diag[:, 4])[:, None]
    return 1.0 / np.sqrt(np.where(s > 0, s, 1.0))   # a row B never moves (0): scale 1


def scaled_coefficients(program: ConeProgram, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(m,), (m,): the cone's mu and mu_r after the row scaling s (m, 5)."""
    return program.mu * s[:, 0] / s[:, 1], program.mu_r * s[:, 0] / s[:, 3]


def length_scale(program: ConeProgram, diameter: float | None = None) -> float:
    """L (length): the root-mean-square free-flight displacement (v dt + g dt^2) of the step, but at
    least 1e-6 of the mean radius; the length that makes the residuals dimensionless. diameter: the
    program's :func:`mean_diameter`, where the caller has it (None: made here)."""
    # the gravity part of the free flight cannot be told apart from v in fbar
    return max(program.free_flight_rms(), 0.5e-6 * (mean_diameter(program) if diameter is None else diameter))


def mean_diameter(program: ConeProgram) -> float:
    """The mean sphere diameter (length), from Mbar's masses and moments of inertia (I = 2/5 m R^2);
    1 for a program without spheres."""
    return program.mean_diameter()


def force_floor(program: ConeProgram, scale: float) -> float:
    """F0 = mean particle mass L / dt^2 (force): about the weight of a mean particle at rest."""
    return program.mean_mass() * scale if program.n_unknowns else 1.0


def relative_residuals(y: np.ndarray, lam: np.ndarray, mu, mu_r, scale: float,
                       floor: float) -> dict[str, float]:
    """Relative primal, dual and complementarity residuals (module docstring) of end-of-step gaps
    y (m, 5) and forces lam (m, 5), with L = scale (length) and F0 = floor (force)."""
    nyt = np.sqrt(y[:, 1] ** 2 + y[:, 2] ** 2)
    nyr = np.sqrt(y[:, 3] ** 2 + y[:, 4] ** 2)
    primal = float(np.max(np.maximum(mu * nyt + mu_r * nyr - y[:, 0], 0.0), initial=0.0))
    p = lam[:, 0]
    nq = np.sqrt(lam[:, 1] ** 2 + lam[:, 2] ** 2)
    nr = np.sqrt(lam[:, 3] ** 2 + lam[:, 4] ** 2)
    dual = float(np.max(np.maximum.reduce([nq - mu * p, nr - mu_r * p, -p]), initial=0.0))
    total = float(np.sum(np.maximum(p, 0.0)))
    comp = float(np.sum(np.abs(np.einsum("ij,ij->i", lam, y))))
    return combine_residuals(primal, dual, total, comp, len(p), scale, floor)


def combine_residuals(primal: float, dual: float, total: float, comp: float, m: int, scale: float,
                      floor: float) -> dict[str, float]:
    """The relative residuals from their absolute parts: primal, the largest cone violation of the
    gaps (length); dual, of the forces (force); total, the sum of the positive normal forces;
    comp, sum_k |lam_k . y_k| (force length); m contacts, L = scale, F0 = floor."""
    force_scale = max(total / max(m, 1), floor)
    return {"primal": primal / scale, "dual": max(dual, 0.0) / force_scale,
            "complementarity": comp / ((total + m * floor) * scale)}


def contact_residuals(k, g0, g1, g2, g3, g4, x, s, mu, mu_r):
    """Contact k's parts of :func:`combine_residuals` from its scaled gaps g0..g4 and the scaled
    forces x, s their scaling ((5m,) each): its cone violation of the gaps y = g / s, of the forces
    lam = s x, its positive normal force and |lam_k . y_k| (scalar code: compiled by numba, and for
    the GPU by numba.cuda, :mod:`colsim.engine.cuda_apgd`)."""
    o = 5 * k
    y0, y1, y2 = g0 / s[o], g1 / s[o + 1], g2 / s[o + 2]
    y3, y4 = g3 / s[o + 3], g4 / s[o + 4]
    p, q1, q2 = s[o] * x[o], s[o + 1] * x[o + 1], s[o + 2] * x[o + 2]
    r1, r2 = s[o + 3] * x[o + 3], s[o + 4] * x[o + 4]
    primal = mu[k] * math.sqrt(y1 * y1 + y2 * y2) + mu_r[k] * math.sqrt(y3 * y3 + y4 * y4) - y0
    dual = max(math.sqrt(q1 * q1 + q2 * q2) - mu[k] * p, math.sqrt(r1 * r1 + r2 * r2) - mu_r[k] * p, -p)
    return primal, dual, max(p, 0.0), abs(p * y0 + q1 * y1 + q2 * y2 + r1 * y3 + r2 * y4)


def _residual_parts(g, x, s, mu, mu_r, blocks):
    """(primal, dual, total, comp) of :func:`combine_residuals` for the end-of-step gaps y = g / s
    and the forces lam = s x ((5m,) each), in one sweep over the contacts split into `blocks` fixed
    ranges (on the kernels' threads; their sums added in block order, so one block is the serial
    sum and a block count always gives the same bits): :func:`relative_residuals` compiled."""
    m = len(mu)
    parts = np.zeros((blocks, 4))
    for block in prange(blocks):
        primal = dual = -np.inf
        total = comp = 0.0
        for k in range(block * m // blocks, (block + 1) * m // blocks):
            o = 5 * k
            primal_k, dual_k, pushing, product = contact_residuals(k, g[o], g[o + 1], g[o + 2], g[o + 3], g[o + 4],
                                                                   x, s, mu, mu_r)
            primal = max(primal, primal_k)
            dual = max(dual, dual_k)
            total += pushing
            comp += product
        parts[block, 0], parts[block, 1], parts[block, 2], parts[block, 3] = primal, dual, total, comp
    primal = dual = total = comp = 0.0
    for block in range(blocks):
        primal = max(primal, parts[block, 0])
        dual = max(dual, parts[block, 1])
        total += parts[block, 2]
        comp += parts[block, 3]
    return primal, dual, total, comp


contact_residuals = numba.njit(cache=True, inline="always")(contact_residuals)
_residual_parts = numba.njit(cache=True, parallel=True)(_residual_parts)


def scaled_residuals(g: np.ndarray, x: np.ndarray, s: np.ndarray, mu, mu_r, scale: float,
                     floor: float) -> dict[str, float]:
    """:func:`relative_residuals` of the gaps y = g / s and forces lam = s x given scaled and flat
    ((5m,) each, as the iterative back-ends hold them): one compiled sweep."""
    return combine_residuals(*_residual_parts(g, x, s, np.ascontiguousarray(mu, dtype=float),
                                              np.ascontiguousarray(mu_r, dtype=float), threads()),
                             len(g) // ROWS_PER_CONTACT, scale, floor)
