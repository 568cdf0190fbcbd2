"""The cone program of one time step (SPEC section 2; the paper's Eq. 6).

Unknowns: u = [dx (3n, particle-major); dth (3n)], the displacement and rotation increments.
Displacement (primal) form:

    minimise   1/2 u' Mbar u - fbar' u
    subject to g_k + du_n,k >= mu_k ||du_t,k|| + mu_r,k ||dphi_k||     for every contact k

with Mbar = diag(M, J)/dt^2 and fbar = [f_ext + M v/dt; J w/dt]. The local relative displacement of
contact k is B_k u = (du_n, du_t1, du_t2, dphi_1, dphi_2), B is the (5m, 6n) contact Jacobian.
Its Lagrange dual (force form) is

    minimise   1/2 lam' W lam + c' lam,   W = B Mbar^-1 B',   c = B Mbar^-1 fbar + g e_n
    subject to lam_k = (p, q1, q2, r1, r2) with ||q|| <= mu p, ||r|| <= mu_r p

and u = Mbar^-1 (fbar + B' lam). The multipliers are the contact forces: normal p, sliding q and
rolling r; the rolling moment is L r, L the contact's lever (:func:`colsim.engine.state.rolling_lever`:
the paper's particle radius, or R_eff). This is the associated friction law of the paper: a
sliding contact opens by mu ||du_t|| per step.

A back-end solves a program behind one contract (:mod:`colsim.engine.solver_contract`): it returns
a ConeSolution or raises SolverError, never an unconverged result. The back-ends
are :mod:`colsim.solvers.clarabel`, :mod:`colsim.solvers.apgd` and :mod:`colsim.solvers.admm`; :mod:`colsim.solvers` picks
them by name.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import scipy.sparse as sp

from .compiled import numba, prange
from .contacts import Contacts
from .operator import ContactOperator
from .state import ParticleState

ROWS_PER_CONTACT = 5  # normal, two sliding, two rolling


@dataclass
class ConeProgram:
    """One step's program in the notation of the module docstring.

    mass: (6n,) diagonal of Mbar = diag(m, m, m, ..., I, I, I, ...)/dt^2, mass/time^2
    fbar: (6n,) fbar, force (and moment) units
    contacts: the contacts: B is built from them (their frames and radii also give B without the
    matrix: :attr:`operator`), and the gaps and coefficients are theirs (:attr:`gap`, :attr:`mu`,
    :attr:`mu_r`: not copied, so that a GPU detection's stay on the device)
    gap_shift: (m,) length added to the contacts' gaps (a Coulomb fixed point's correction), or None
    matrix: (5m, 6n) CSR matrix B, dimensionless and length (rotation columns), or None: built from
    the contacts when first asked for (:attr:`jacobian`). A step solved by APGD never asks: its
    products with B and B' run on :attr:`operator`.
    """

    mass: np.ndarray
    fbar: np.ndarray
    contacts: Contacts
    gap_shift: np.ndarray | None = None
    matrix: sp.csr_matrix | None = field(default=None, repr=False)
    _operator: ContactOperator | None = field(default=None, init=False, repr=False, compare=False)

    @property
    def n_unknowns(self) -> int:
        return len(self.mass)

    @property
    def m(self) -> int:
        return self.contacts.m

    @cached_property
    def gap(self) -> np.ndarray:
        """(m,) length: the contacts' gaps, shifted by gap_shift where given."""
        return self.contacts.gap if self.gap_shift is None else self.contacts.gap + self.gap_shift

    mu = property(lambda self: self.contacts.mu, doc="(m,) the contacts' sliding coefficients.")
    mu_r = property(lambda self: self.contacts.mu_r, doc="(m,) the contacts' rolling coefficients.")

    @property
    def jacobian(self) -> sp.csr_matrix:
        """(5m, 6n) B, built from the contacts on first use."""
        if self.matrix is None:
            self.matrix = contact_jacobian(self.contacts, self.n_unknowns // 6)
        return self.matrix

    @property
    def operator(self) -> ContactOperator | None:
        """B applied from the contacts' frames, made when first asked for."""
        if self._operator is None:
            self._operator = ContactOperator(self.contacts, self.n_unknowns // 6)
        return self._operator

    def free_flight_rms(self) -> float:
        """The root-mean-square free-flight displacement v dt + g dt^2 of the particles (length): the
        translational entries of Mbar^-1 fbar (0 without particles)."""
        n = self.n_unknowns // 6
        trans = (self.fbar[:3 * n] / self.mass[:3 * n]).reshape(n, 3)
        return float(np.sqrt(np.mean(np.einsum("ij,ij->i", trans, trans)))) if n else 0.0

    def mean_diameter(self) -> float:
        """The mean sphere diameter (length), from Mbar's masses and moments of inertia (I = 2/5 m
        R^2); 1 for a program without spheres."""
        n = self.n_unknowns // 6
        if n == 0:
            return 1.0
        return 2.0 * float(np.mean(np.sqrt(self.mass[3 * n::3] / (0.4 * self.mass[:3 * n:3]))))

    def mean_mass(self) -> float:
        """The mean of Mbar's translational entries, the particles' mean mass over dt^2 (mass/time^2;
        1 without particles)."""
        n = self.n_unknowns // 6
        return float(np.mean(self.mass[:3 * n])) if n else 1.0

    def free_motion(self) -> np.ndarray:
        """(6n,) the increments without any contact force: Mbar^-1 fbar."""
        return self.fbar / self.mass

    def increments(self, forces: np.ndarray) -> np.ndarray:
        """(6n,) u = Mbar^-1 (fbar + B' lam) for contact forces lam (m, 5)."""
        if self.matrix is None and self.operator is not None:
            return (self.fbar + self.operator.transpose(forces.reshape(-1))) / self.mass
        return (self.fbar + self.jacobian.T @ forces.reshape(-1)) / self.mass

    def local_displacement(self, u: np.ndarray) -> np.ndarray:
        """(m, 5) B u: (du_n, du_t1, du_t2, dphi_1, dphi_2) of every contact."""
        if self.matrix is None and self.operator is not None:
            return self.operator.apply(u).reshape(-1, ROWS_PER_CONTACT)
        return (self.jacobian @ u).reshape(-1, ROWS_PER_CONTACT)

    def end_of_step_gaps(self, u: np.ndarray) -> np.ndarray:
        """(m, 5) B u + g e_n: the local displacement with the gap added to the normal entry.

        The constraint is that every row lies in {y_n >= mu ||y_t|| + mu_r ||y_r||}.
        """
        y = self.local_displacement(u)
        y[:, 0] += self.gap
        return y


def contact_jacobian(contacts: Contacts, n_particles: int) -> sp.csr_matrix:
    """The (5m, 6n) matrix B mapping u = [dx; dth] to each contact's local relative displacement."""
    m, n = contacts.m, n_particles
    n_, t1, t2 = contacts.normal, contacts.tangent1, contacts.tangent2
    ri = contacts.radius_i[:, None]
    rj = contacts.radius_j[:, None]
    lever = contacts.lever[:, None]
    k = np.arange(m)

    rows, cols, vals = [], [], []

    def block(local_row, column_start, values, bodies):
        """Add values (m, 3) at rows 5k + local_row, columns column_start + 3 body + (0, 1, 2)."""
        on = bodies >= 0
        rows.append(np.repeat(ROWS_PER_CONTACT * k[on] + local_row, 3))
        cols.append((column_start + 3 * bodies[on][:, None] + np.arange(3)).ravel())
        vals.append(values[on].ravel())

    i, j = contacts.i, contacts.j
    dx, dth = 0, 3 * n
    # particle i: du = ... - (dx_i + R_i dth_i x n)
    block(0, dx, -n_, i)
    block(1, dx, -t1, i)
    block(1, dth, -ri * t2, i)
    block(2, dx, -t2, i)
    block(2, dth, ri * t1, i)
    block(3, dth, -lever * t1, i)
    block(4, dth, -lever * t2, i)
    # body j (particles only; walls do not move): du = (dx_j - R_j dth_j x n) - ...
    block(0, dx, n_, j)
    block(1, dx, t1, j)
    block(1, dth, -rj * t2, j)
    block(2, dx, t2, j)
    block(2, dth, rj * t1, j)
    block(3, dth, lever * t1, j)
    block(4, dth, lever * t2, j)

    return sp.csr_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
        shape=(ROWS_PER_CONTACT * m, 6 * n),
    )


def _fill_program(m_i, inertia, velocity, angular_velocity, dt, dt2, gravity, mass, fbar):
    """mass (6n,) = [m; I] / dt2 and fbar (6n,) = [m v / dt + m g; I w / dt], each body's six entries
    (particle-major) in one pass over the bodies (compiled; dt2 = dt**2 as Python makes it): the
    arithmetic of numpy's column-at-a-time fill, so the same bits, in one pass instead of several."""
    n = m_i.shape[0]
    for b in prange(n):
        mass_b = m_i[b] / dt2
        inertia_b = inertia[b] / dt2
        for d in range(3):
            mass[3 * b + d] = mass_b
            mass[3 * n + 3 * b + d] = inertia_b
            force = m_i[b] * velocity[b, d]
            force /= dt
            fbar[3 * b + d] = force + m_i[b] * gravity[d]   # f_ext + m v / dt
            moment = inertia[b] * angular_velocity[b, d]
            fbar[3 * n + 3 * b + d] = moment / dt


_fill_program = numba.njit(cache=True, parallel=True)(_fill_program)


def assemble(state: ParticleState, contacts: Contacts, dt: float, gravity) -> ConeProgram:
    """The cone program of one step of length dt (time) from `state` with `contacts` (B is built
    when a back-end first asks for it: :attr:`ConeProgram.jacobian`)."""
    n = state.n
    m_i, inertia = state.mass_and_inertia()
    mass, fbar = np.empty(6 * n), np.empty(6 * n)
    gravity = np.asarray(gravity, dtype=float)
    _fill_program(m_i, inertia, state.velocity, state.angular_velocity, float(dt), float(dt)**2, gravity, mass, fbar)
    return ConeProgram(mass=mass, fbar=fbar, contacts=contacts)


def cone_violation(program: ConeProgram, u: np.ndarray, forces: np.ndarray) -> dict[str, float]:
    """How far a solution is from the cones, in length (primal) and force (dual) units.

    primal: largest mu||du_t|| + mu_r||dphi|| - (g + du_n) over contacts (<= 0 when feasible)
    dual: largest ||q|| - mu p, ||r|| - mu_r p and -p over contacts (<= 0 when feasible)
    complementarity: largest |p (g + du_n - mu||du_t|| - mu_r||dphi||)| ... per contact, force length
    """
    if program.m == 0:
        return {"primal": 0.0, "dual": 0.0, "complementarity": 0.0}
    local = program.end_of_step_gaps(u)
    slack = (local[:, 0] - program.mu * np.linalg.norm(local[:, 1:3], axis=1)
             - program.mu_r * np.linalg.norm(local[:, 3:5], axis=1))
    p = forces[:, 0]
    dual = np.maximum.reduce([
        np.linalg.norm(forces[:, 1:3], axis=1) - program.mu * p,
        np.linalg.norm(forces[:, 3:5], axis=1) - program.mu_r * p,
        -p,
    ])
    return {
        "primal": float(np.max(-slack)),
        "dual": float(np.max(dual)),
        "complementarity": float(np.max(np.abs(p * slack))),
    }
