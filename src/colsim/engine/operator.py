"""The contact Jacobian B applied without the matrix: B u and B' lam from each contact's frame and
radii (12 numbers a contact instead of B's 42 non-zeros), as compiled kernels whose loops over
contacts and bodies run on numba's threads (:mod:`colsim.engine.threads`). APGD's iteration runs on
them (:mod:`colsim.solvers.apgd`); the step's program uses them for u = Mbar^-1 (fbar + B' lam) and
B u, so that a step solved by APGD never forms B (:class:`colsim.engine.program.ConeProgram`).

Each body sums its contacts' forces and moments in contact order, so a product is the same on any
number of threads.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .compiled import numba, prange


def body_contacts(first: np.ndarray, second: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Each body's contacts, for applying B' body by body: body b's are entry[start[b]:start[b + 1]],
    in increasing contact order, each 2 k for contact k's first body and 2 k + 1 for its second
    (second < 0: a wall, no second body). Returns (start (n + 1,), entry) as int64."""
    bodies = np.column_stack([first, second]).ravel().astype(np.int64)   # entry e's body is bodies[e]
    entry = np.flatnonzero(bodies >= 0)
    bodies = bodies[entry]
    start = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(bodies, minlength=n), out=start[1:])
    return start, _by_body(entry, bodies, start)


def _by_body(entry, bodies, start):
    """entry reordered body by body (body b's from start[b]), in their order within each body: a
    counting sort (the stable sort by body, in one pass)."""
    out = np.empty_like(entry)
    filled = start[:-1].copy()
    for e in range(len(entry)):
        b = bodies[e]
        out[filled[b]] = entry[e]
        filled[b] += 1
    return out


def _contact_wrenches(z, s, nrm, t1, t2, ri, rj, lever, work):
    """work (m, 9): each contact's wrench (:func:`contact_wrench`) from scaled forces z (5m,)."""
    for k in prange(len(ri)):
        o = 5 * k
        contact_wrench(k, s[o] * z[o], s[o + 1] * z[o + 1], s[o + 2] * z[o + 2], s[o + 3] * z[o + 3],
                       s[o + 4] * z[o + 4], nrm, t1, t2, ri, rj, lever, work)


def contact_wrench(k, p, q1, q2, r1, r2, nrm, t1, t2, ri, rj, lever, work):
    """work[k] (9,): contact k's force on its second body (minus that on its first), its moment on
    the first body and on the second, from its force p (normal), q1, q2 (sliding), r1, r2 (rolling)
    (scalar code: compiled by numba, and for the GPU by numba.cuda, :mod:`colsim.engine.cuda_operator`)."""
    for d in range(3):
        sliding = q2 * t1[k, d] - q1 * t2[k, d]
        rolling = lever[k] * (r1 * t1[k, d] + r2 * t2[k, d])
        work[k, d] = p * nrm[k, d] + q1 * t1[k, d] + q2 * t2[k, d]
        work[k, 3 + d] = ri[k] * sliding - rolling
        work[k, 6 + d] = rj[k] * sliding + rolling


def global_force_row(k, forces, nrm, t1, t2, force, rolling):
    """Contact k's row of :func:`global_forces` (scalar code: compiled by numba, and for the GPU by
    numba.cuda, :mod:`colsim.engine.cuda_warm_start`)."""
    for d in range(3):
        force[k, d] = forces[k, 0] * nrm[k, d] + forces[k, 1] * t1[k, d] + forces[k, 2] * t2[k, d]
        rolling[k, d] = forces[k, 3] * t1[k, d] + forces[k, 4] * t2[k, d]


def global_forces(forces, nrm, t1, t2, force, rolling):
    """force (m, 3) = p n + q1 t1 + q2 t2 and rolling (m, 3) = r1 t1 + r2 t2: the contacts' forces
    (m, 5) = (p, q1, q2, r1, r2) in the global frame, one pass (numpy's broadcast form made eight
    (m, 3) temporaries); summed in the same order, so the same bits."""
    for k in prange(len(force)):
        global_force_row(k, forces, nrm, t1, t2, force, rolling)


def apply_transpose(z, s, nrm, t1, t2, ri, rj, lever, start, entry, work, out):
    """out (6n,) = B' S z without forming B: each body sums its contacts' forces and moments
    (:func:`_contact_wrenches`) in contact order, so the sums are the same on any number of
    threads; work: (m, 9) scratch."""
    _contact_wrenches(z, s, nrm, t1, t2, ri, rj, lever, work)
    for body in prange(len(start) - 1):
        body_sums(body, work, start, entry, out)


def body_sums(body, work, start, entry, out):
    """out's entries of `body` (force 3 body + d, moment 3 n + 3 body + d) = the sums of its contacts'
    wrenches (work (m, 9)) in contact order (scalar code: compiled by numba, and for the GPU by
    numba.cuda, :mod:`colsim.engine.cuda_operator`)."""
    n = start.shape[0] - 1
    for d in range(3):
        force = 0.0
        moment = 0.0
        for e in range(start[body], start[body + 1]):
            k = entry[e] // 2
            if entry[e] % 2 == 1:
                force += work[k, d]
                moment += work[k, 6 + d]
            else:
                force -= work[k, d]
                moment += work[k, 3 + d]
        out[3 * body + d] = force
        out[3 * n + 3 * body + d] = moment


def apply_gradient(h, inv_mass, s, ci, cj, nrm, t1, t2, ri, rj, lever, c, out):
    """out (5m,) = S B Mbar^-1 h + c without forming B: each contact's relative motion
    (:func:`gradient_values`, a contact a thread)."""
    for k in prange(len(ci)):
        o = 5 * k
        out[o], out[o + 1], out[o + 2], out[o + 3], out[o + 4] = gradient_values(
            k, h, h, 0.0, False, inv_mass, s, ci, cj, nrm, t1, t2, ri, rj, lever, c)


def gradient_values(k, h, h_prev, beta, extrapolate, inv_mass, s, ci, cj, nrm, t1, t2, ri, rj, lever, c):
    """Contact k's five rows of S B Mbar^-1 h + c, returned; where `extrapolate`, of h + beta (h - h_prev)
    instead (T y of y = x + beta (x - x_prev) from h = T x and h_prev = T x_prev, as APGD extrapolates).
    Scalar code: compiled by numba, and for the GPU by numba.cuda (:mod:`colsim.engine.cuda_operator`),
    whose trial step keeps the rows in registers."""
    rot = h.shape[0] // 2
    first, second = ci[k], cj[k]
    un = ut1 = ut2 = ur1 = ur2 = 0.0
    for d in range(3):
        a, b = 3 * first + d, rot + 3 * first + d
        dx = -(h[a] + beta * (h[a] - h_prev[a]) if extrapolate else h[a]) * inv_mass[a]
        w = (h[b] + beta * (h[b] - h_prev[b]) if extrapolate else h[b]) * inv_mass[b]
        un += nrm[k, d] * dx
        ut1 += t1[k, d] * dx - ri[k] * t2[k, d] * w
        ut2 += t2[k, d] * dx + ri[k] * t1[k, d] * w
        ur1 -= lever[k] * t1[k, d] * w
        ur2 -= lever[k] * t2[k, d] * w
        if second >= 0:
            a, b = 3 * second + d, rot + 3 * second + d
            dx = (h[a] + beta * (h[a] - h_prev[a]) if extrapolate else h[a]) * inv_mass[a]
            w = (h[b] + beta * (h[b] - h_prev[b]) if extrapolate else h[b]) * inv_mass[b]
            un += nrm[k, d] * dx
            ut1 += t1[k, d] * dx - rj[k] * t2[k, d] * w
            ut2 += t2[k, d] * dx + rj[k] * t1[k, d] * w
            ur1 += lever[k] * t1[k, d] * w
            ur2 += lever[k] * t2[k, d] * w
    o = 5 * k
    return (s[o] * un + c[o], s[o + 1] * ut1 + c[o + 1], s[o + 2] * ut2 + c[o + 2], s[o + 3] * ur1 + c[o + 3],
            s[o + 4] * ur2 + c[o + 4])


def diagonal_row(k, inv_mass, ci, cj, nrm, t1, t2, ri, rj, lever, out):
    """out[k] (5,) = contact k's rows of the diagonal of B Mbar^-1 B': each row's squared entries
    weighted by the inverse masses and inertias of the body they act on (scalar code: compiled by
    numba, and for the GPU by numba.cuda, :mod:`colsim.engine.cuda_operator`)."""
    rot = inv_mass.shape[0] // 2
    for row in range(5):
        out[k, row] = 0.0
    for side in range(2):
        body = ci[k] if side == 0 else cj[k]
        if body < 0:
            continue
        radius = ri[k] if side == 0 else rj[k]
        for d in range(3):
            lin = inv_mass[3 * body + d]
            ang = inv_mass[rot + 3 * body + d]
            out[k, 0] += nrm[k, d] ** 2 * lin
            out[k, 1] += t1[k, d] ** 2 * lin + (radius * t2[k, d]) ** 2 * ang
            out[k, 2] += t2[k, d] ** 2 * lin + (radius * t1[k, d]) ** 2 * ang
            out[k, 3] += (lever[k] * t1[k, d]) ** 2 * ang
            out[k, 4] += (lever[k] * t2[k, d]) ** 2 * ang


def jacobian_diagonal(inv_mass, ci, cj, nrm, t1, t2, ri, rj, lever, out):
    """out (m, 5) = the diagonal of B Mbar^-1 B' (:func:`diagonal_row`, a contact a thread)."""
    for k in prange(len(ci)):
        diagonal_row(k, inv_mass, ci, cj, nrm, t1, t2, ri, rj, lever, out)


_by_body = numba.njit(cache=True)(_by_body)
diagonal_row = numba.njit(cache=True, inline="always")(diagonal_row)
body_sums = numba.njit(cache=True, inline="always")(body_sums)
contact_wrench = numba.njit(cache=True, inline="always")(contact_wrench)
gradient_values = numba.njit(cache=True, inline="always")(gradient_values)
_parallel = numba.njit(cache=True, parallel=True)
_contact_wrenches = _parallel(_contact_wrenches)
apply_transpose = _parallel(apply_transpose)
apply_gradient = _parallel(apply_gradient)
jacobian_diagonal = _parallel(jacobian_diagonal)
global_force_row = numba.njit(cache=True, inline="always")(global_force_row)
global_forces = _parallel(global_forces)


class ContactGeometry(NamedTuple):
    """The contacts of one program as the kernels take them, by name (numpy arrays for the CPU's,
    device arrays for the GPU's): s (5m,) the rows' scaling S; i, j (m,) the bodies (j < 0: a wall
    or a fixed sphere); normal, tangent1, tangent2 (m, 3) the frames; radius_i, radius_j (m,) the
    contact points' distances from the centres; lever (m,) the rolling lever; start (n + 1,) and
    entry (2m,) each body's contacts (:func:`body_contacts`); work (m, 9) room for the wrenches."""

    s: np.ndarray
    i: np.ndarray
    j: np.ndarray
    normal: np.ndarray
    tangent1: np.ndarray
    tangent2: np.ndarray
    radius_i: np.ndarray
    radius_j: np.ndarray
    lever: np.ndarray
    start: np.ndarray
    entry: np.ndarray
    work: np.ndarray


def transpose_of(geometry: ContactGeometry, z: np.ndarray, out: np.ndarray) -> None:
    """out (6n,) = B' S z (:func:`apply_transpose` by the geometry's names)."""
    g = geometry
    apply_transpose(z, g.s, g.normal, g.tangent1, g.tangent2, g.radius_i, g.radius_j, g.lever, g.start, g.entry,
                    g.work, out)


def gradient_of(geometry: ContactGeometry, h: np.ndarray, inv_mass: np.ndarray, c: np.ndarray,
                out: np.ndarray) -> None:
    """out (5m,) = S B Mbar^-1 h + c (:func:`apply_gradient` by the geometry's names)."""
    g = geometry
    apply_gradient(h, inv_mass, g.s, g.i, g.j, g.normal, g.tangent1, g.tangent2, g.radius_i, g.radius_j, g.lever,
                   c, out)


transpose_of = numba.njit(cache=True)(transpose_of)
gradient_of = numba.njit(cache=True)(gradient_of)


class ContactOperator:
    """B of m contacts among n bodies, applied without the matrix (:func:`apply_gradient`,
    :func:`apply_transpose`). Walls and fixed spheres (j < 0) do not move: no second body."""

    def __init__(self, contacts, n_bodies: int):
        self.n = n_bodies
        self.i = contacts.i.astype(np.int64)
        self.j = contacts.j.astype(np.int64)
        self.normal, self.tangent1, self.tangent2, self.radius_i, self.radius_j, self.lever = (
            np.ascontiguousarray(v, dtype=float) for v in (
                contacts.normal, contacts.tangent1, contacts.tangent2, contacts.radius_i,
                contacts.radius_j, contacts.lever))
        self.start, self.entry = body_contacts(self.i, self.j, n_bodies)
        self.work = np.empty((len(self.i), 9))

    @property
    def m(self) -> int:
        return len(self.i)

    def geometry(self, scaling: np.ndarray) -> ContactGeometry:
        """The contacts by name with the rows' scaling S (5m,), for the kernels."""
        return ContactGeometry(np.ascontiguousarray(scaling, dtype=float), self.i, self.j, self.normal,
                               self.tangent1, self.tangent2, self.radius_i, self.radius_j, self.lever,
                               self.start, self.entry, self.work)

    def frames(self) -> tuple:
        """(i, j, normal, tangent1, tangent2, R_i, R_j, lever): the kernels' contact arguments."""
        return (self.i, self.j, self.normal, self.tangent1, self.tangent2, self.radius_i, self.radius_j,
                self.lever)

    def transpose(self, z: np.ndarray, scaling: np.ndarray | None = None) -> np.ndarray:
        """(6n,) B' S z for z (5m,) (S = diag(scaling), identity if None)."""
        s = np.ones(5 * self.m) if scaling is None else scaling
        out = np.empty(6 * self.n)
        apply_transpose(np.ascontiguousarray(z, dtype=float), s, self.normal, self.tangent1, self.tangent2,
                        self.radius_i, self.radius_j, self.lever, self.start, self.entry, self.work, out)
        return out

    def apply(self, u: np.ndarray) -> np.ndarray:
        """(5m,) B u for u (6n,)."""
        out = np.empty(5 * self.m)
        apply_gradient(np.ascontiguousarray(u, dtype=float), np.ones(6 * self.n), np.ones(5 * self.m),
                       *self.frames(), np.zeros(5 * self.m), out)
        return out

    def diagonal(self, inv_mass: np.ndarray) -> np.ndarray:
        """(m, 5) the diagonal of B Mbar^-1 B' (inv_mass: (6n,) the diagonal of Mbar^-1)."""
        out = np.empty((self.m, 5))
        jacobian_diagonal(np.ascontiguousarray(inv_mass, dtype=float), *self.frames(), out)
        return out
