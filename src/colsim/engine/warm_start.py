"""Contact forces carried from one step (or stage) to the next, by contact pair.

A warm start stores each contact's force and rolling force in the global frame, with the pair that
carries it: particle i, and particle j, a wall (j = -1 with the wall's family) or a fixed sphere
(j = -2 - k, :class:`colsim.engine.state.FixedSpheres`). The next step's
contacts are matched by pair and get the stored forces re-expressed in their own frames, projected
onto their cones (zeros for new pairs). The pairs survive a change of the particle set: pouring
more spheres keeps the indices, and trimming renumbers them (:meth:`WarmStart.subset`). So a packing's
final forces can start the first step of its column's collapse. A pour in layers steps only its
moving spheres, on fixed ones: :meth:`WarmStart.for_moving` and :meth:`WarmStart.in_whole` carry the
forces between the whole packing's numbering and that step's.

A plain record: the compiled kernels (numba) are loaded by :meth:`WarmStart.match` and
:meth:`WarmStart.from_step` alone, so that reading a file's forces (:mod:`colsim.io`) loads no numerics.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .state import fixed_code, pair_keys


@dataclass
class WarmStart:
    """Forces of m contact pairs, in the global frame.

    i: (m,) int particle; j: (m,) int particle, -1 for a wall, -2 - k for fixed sphere k; family: (m,) int (state.PARTICLE,
    FLOOR or CYLINDER). force: (m, 3) p n + q1 t1 + q2 t2; rolling: (m, 3) r1 t1 + r2 t2 (force units).
    """

    i: np.ndarray
    j: np.ndarray
    family: np.ndarray
    force: np.ndarray
    rolling: np.ndarray

    @property
    def m(self) -> int:
        return len(self.i)

    @classmethod
    def from_step(cls, contacts, forces: np.ndarray) -> "WarmStart":
        """The forces (m, 5) = (p, q1, q2, r1, r2) of a step's `contacts`, in the global frame
        (:func:`colsim.engine.operator.global_forces`)."""
        from .operator import global_forces

        m = len(forces)
        f, r = np.empty((m, 3)), np.empty((m, 3))
        global_forces(*(np.ascontiguousarray(a, dtype=float) for a in (
            forces, contacts.normal, contacts.tangent1, contacts.tangent2)), f, r)
        return cls(contacts.i.copy(), contacts.j.copy(), contacts.family.copy(), f, r)

    def carries_load(self) -> bool:
        """Whether any stored pair pushes (a start worth warming from)."""
        return bool(np.any(np.einsum("ij,ij->i", self.force, self.force) > 0.0))

    def match(self, contacts):
        """(m, 5) the stored forces of the pairs in `contacts`, in their frames, projected onto their
        cones; zeros for new pairs."""
        from .cones import project_coupled_cone
        from .program import ROWS_PER_CONTACT

        out = np.zeros((contacts.m, ROWS_PER_CONTACT))
        if self.m == 0 or contacts.m == 0:
            return out
        stored = pair_keys(self.i, self.j, self.family)
        order = np.argsort(stored, kind="stable")
        stored = stored[order]
        keys = contacts.keys
        pos = np.clip(np.searchsorted(stored, keys), 0, len(stored) - 1)
        found = stored[pos] == keys
        f, r = self.force[order[pos[found]]], self.rolling[order[pos[found]]]
        n, t1, t2 = contacts.normal[found], contacts.tangent1[found], contacts.tangent2[found]
        out[found, 0] = np.einsum("ij,ij->i", f, n)
        out[found, 1] = np.einsum("ij,ij->i", f, t1)
        out[found, 2] = np.einsum("ij,ij->i", f, t2)
        out[found, 3] = np.einsum("ij,ij->i", r, t1)
        out[found, 4] = np.einsum("ij,ij->i", r, t2)
        return project_coupled_cone(out, contacts.mu, contacts.mu_r)

    def subset(self, keep: np.ndarray) -> "WarmStart":
        """The pairs whose particles are all in `keep` ((n,) bool mask of the old particles),
        renumbered as :meth:`colsim.engine.state.ParticleState.subset` renumbers the particles."""
        keep = np.asarray(keep, dtype=bool)
        new_index = np.full(len(keep), -1, dtype=np.int64)
        new_index[keep] = np.arange(np.count_nonzero(keep))
        stays = keep[self.i] & ((self.j < 0) | keep[np.maximum(self.j, 0)])
        j = np.where(self.j < 0, self.j, new_index[np.maximum(self.j, 0)])
        return WarmStart(new_index[self.i[stays]], j[stays], self.family[stays].copy(),
                         self.force[stays].copy(), self.rolling[stays].copy())

    def for_moving(self, moving: np.ndarray, supports: np.ndarray, n: int) -> "WarmStart":
        """The pairs (numbered as n particles) between a `moving` particle and a moving one, a wall
        or one of the `supports`, numbered as a step of the moving particles alone numbers them:
        moving ones in order, supports as fixed spheres (j = -2 - k). moving, supports: int indices."""
        as_moving = np.full(n, -1, dtype=np.int64)
        as_moving[moving] = np.arange(len(moving))
        as_support = np.full(n, -1, dtype=np.int64)
        as_support[supports] = np.arange(len(supports))
        i = as_moving[self.i]
        other = np.maximum(self.j, 0)
        j = np.where(self.j < 0, self.j,
                     np.where(as_moving[other] >= 0, as_moving[other], fixed_code(as_support[other])))
        keep = (i >= 0) & ((self.j < 0) | (as_moving[other] >= 0) | (as_support[other] >= 0))
        return WarmStart(i[keep], j[keep], self.family[keep], self.force[keep], self.rolling[keep])

    def in_whole(self, moving: np.ndarray, supports: np.ndarray) -> "WarmStart":
        """The inverse of :meth:`for_moving`: a step's forces in the numbering of the whole packing."""
        j = self.j.copy()                       # walls keep -1
        particle, fixed = self.j >= 0, self.j <= -2
        j[particle] = moving[self.j[particle]]
        j[fixed] = supports[fixed_code(self.j[fixed])]
        return WarmStart(moving[self.i], j, self.family.copy(), self.force.copy(), self.rolling.copy())

    def among(self, fixed: np.ndarray) -> "WarmStart":
        """The pairs whose bodies are all `fixed` ((n,) bool) or walls."""
        keep = fixed[self.i] & ((self.j == -1) | fixed[np.maximum(self.j, 0)])
        return WarmStart(self.i[keep], self.j[keep], self.family[keep], self.force[keep], self.rolling[keep])

    def joined(self, other: "WarmStart") -> "WarmStart":
        """The pairs of both (no pair may be in both)."""
        return WarmStart(*(np.concatenate([getattr(self, name), getattr(other, name)])
                           for name in ("i", "j", "family", "force", "rolling")))

