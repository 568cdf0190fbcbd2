"""Contact detection: potential contacts between spheres, the floor, the cylinder, plane walls and fixed spheres.

A potential contact k joins particle i to body j (another particle, a wall, j = -1, or fixed
sphere k, j = -2 - k: :class:`colsim.engine.state.FixedSpheres`). Its unit
normal points from i to j, its gap is the surface distance along that normal at the start of the
step (negative when overlapping), and (t1, t2, n) is a right-handed orthonormal frame. A pair is
listed when its predicted relative motion within the step brings it within a margin of contact
(:func:`swept_pairs`); the stepper checks afterwards with :func:`overlaps` that nothing was missed.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy.spatial import cKDTree

from .compiled import numba, prange
from .state import (CYLINDER, FLOOR, PARTICLE, PLANE, ContactLaw, FixedSpheres, ParticleState, Walls, fixed_code,
                    law_family, pair_keys, rolling_lever)

WALL = -1  # index of the other body for a particle-wall contact


@dataclass
class Contacts:
    """Potential contacts, m of them.

    i, j: (m,) int, particle indices (j = -1 for a wall, -2 - k for fixed sphere k)
    family: (m,) int, PARTICLE, FLOOR, CYLINDER or PLANE + p (plane wall p)
    normal, tangent1, tangent2: (m, 3) float, unit vectors, normal from i to j
    gap: (m,) float, length, surface distance at the start of the step
    radius_i, radius_j: (m,) float, length (radius_j = 0 for walls, the fixed sphere's radius)
    lever: (m,) float, length, the lever L of the rolling moment L r (law.rolling_lever:
        the paper's 2 R_i R_j/(R_i + R_j) or R_eff = R_i R_j/(R_i + R_j)), R_i for a wall
    mu, mu_r: (m,) float, sliding and rolling coefficients
    largest_pair_overlap: the largest overlap R_i + R_j - |x_j - x_i| (length) of the swept particle
        pairs, where detection measured it (the GPU's first attempts: -inf without pairs), else None
    """

    i: np.ndarray
    j: np.ndarray
    family: np.ndarray
    normal: np.ndarray
    tangent1: np.ndarray
    tangent2: np.ndarray
    gap: np.ndarray
    radius_i: np.ndarray
    radius_j: np.ndarray
    lever: np.ndarray
    mu: np.ndarray
    mu_r: np.ndarray
    largest_pair_overlap: float | None = None

    @property
    def m(self) -> int:
        return len(self.i)

    @cached_property
    def keys(self) -> np.ndarray:
        """(m,) int64: each contact's pair of bodies as one number (:func:`colsim.engine.state.pair_keys`),
        made once (a step's matching and the next step's both take them: the contacts never change)."""
        return pair_keys(self.i, self.j, self.family)

    @property
    def pair_count(self) -> int:
        """How many contacts join two moving particles (j >= 0)."""
        return int(np.count_nonzero(self.j >= 0))

    def particle_pairs(self) -> tuple[np.ndarray, np.ndarray]:
        """(i, j): the contacts between two moving particles (not a wall, not a fixed sphere)."""
        between = (self.family == PARTICLE) & (self.j >= 0)
        return self.i[between], self.j[between]

    def overlapping_pairs(self, state: ParticleState, tolerance: float) -> tuple:
        """(largest overlap, (i, j, normal (k, 3))): the largest overlap R_i + R_j - |x_j - x_i| of
        these contacts' particle pairs at `state` (length; -inf: none), and the pairs that overlap by
        more than `tolerance` with their unit normals from i to j (:func:`overlaps`)."""
        pi, pj = self.particle_pairs()
        return pair_overlaps(state, pi, pj, state.position[pj] - state.position[pi], tolerance)


def row_lengths(vectors: np.ndarray) -> np.ndarray:
    """(m,) the length of each row of `vectors` (m, 3): numpy's norm along axis 1, the same bits (the
    squares summed in order), a column at a time: several times faster."""
    x, y, z = vectors[:, 0], vectors[:, 1], vectors[:, 2]
    square = x * x
    square += y * y
    square += z * z
    return np.sqrt(square, out=square)


def tangent_basis(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit tangents (m, 3) with (t1, t2, n) right-handed, for unit normals (m, 3)."""
    helper = np.zeros_like(normal)
    use_x = np.abs(normal[:, 0]) < 0.9
    helper[use_x, 0] = 1.0
    helper[~use_x, 1] = 1.0
    t1 = np.cross(helper, normal)
    t1 /= row_lengths(t1)[:, None]
    t2 = np.cross(normal, t1)
    return t1, t2


def particle_pairs(state: ParticleState, distance: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pairs (i < j) with surface gap below `distance` now: (i, j, centre-to-centre vector (m, 3))."""
    if state.n < 2:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty, np.zeros((0, 3))
    reach = 2.0 * state.radius.max() + max(distance, 0.0)
    pairs = cKDTree(state.position).query_pairs(reach, output_type="ndarray")
    i, j = pairs[:, 0], pairs[:, 1]
    d = state.position[j] - state.position[i]
    gap = row_lengths(d) - state.radius[i] - state.radius[j]
    close = gap < distance
    return i[close], j[close], d[close]


def swept_pairs(state: ParticleState, predicted: np.ndarray, margin: float, slack: float):
    """Pairs (i < j) that may touch within a step in which particle i is predicted to move predicted[i].

    Each particle sweeps a segment from x to x + u; a pair is kept when the relative segment comes
    within margin + slack |u_j - u_i| of contact (length). Candidates come from a k-d tree on the
    segments' midpoints with the swept spheres' radii R + |u|/2. The pairs come sorted by (i, j):
    the solver's kernels then find a contact's bodies near those of the contacts before it in
    memory (the tree's own order made an APGD iteration slower).
    """
    if state.n < 2:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty
    midpoint, reach = swept_midpoints(state, predicted, margin, slack)
    pairs = cKDTree(midpoint).query_pairs(reach, output_type="ndarray")
    i, j = pairs[:, 0].astype(np.int64), pairs[:, 1].astype(np.int64)
    keep = np.empty(len(i), dtype=np.bool_)
    _swept_keep(i, j, np.ascontiguousarray(state.position, dtype=float),
                np.ascontiguousarray(predicted, dtype=float), np.ascontiguousarray(state.radius, dtype=float),
                float(margin), float(slack), keep)
    i, j = i[keep], j[keep]
    order = np.lexsort((j, i))
    return i[order], j[order]


def swept_midpoints(state: ParticleState, predicted: np.ndarray, margin: float, slack: float):
    """(midpoints x + u/2 (n, 3), reach): the swept segments' midpoints and the distance (length)
    within which two of them must lie for the pair to be a candidate of :func:`swept_pairs`."""
    half = 0.5 * row_lengths(predicted)
    reach = 2.0 * float(np.max(state.radius + half * (1.0 + slack))) + margin
    return state.position + 0.5 * predicted, reach


def swept_close(position, predicted, radius, a, b, margin, slack):
    """Whether the pair (a, b) comes within margin + slack |u_b - u_a| of contact (length) as its
    relative segment d0 + tau (u_b - u_a), tau in [0, 1], is swept (scalar code: compiled by numba,
    and for the GPU by numba.cuda, :mod:`colsim.engine.cuda_contacts`)."""
    d0u = du2 = 0.0
    for d in range(3):
        du = predicted[b, d] - predicted[a, d]
        d0u += (position[b, d] - position[a, d]) * du
        du2 += du * du
    tau = min(max(-d0u / max(du2, 1e-300), 0.0), 1.0)
    c2 = 0.0
    for d in range(3):
        c = position[b, d] - position[a, d] + tau * (predicted[b, d] - predicted[a, d])
        c2 += c * c
    return math.sqrt(c2) - radius[a] - radius[b] < margin + slack * math.sqrt(du2)


def _swept_keep(i, j, position, predicted, radius, margin, slack, keep):
    """keep[k] (bool (m,), out) = :func:`swept_close` of candidate pair (i[k], j[k]). A loop over the
    candidates (a million a step in a pour's impacts, and in numpy the detection's largest cost), on
    numba's threads."""
    for k in prange(len(i)):
        keep[k] = swept_close(position, predicted, radius, i[k], j[k], margin, slack)


def lever_of(radius_i, radius_j, scale):
    """One contact's rolling lever (length): scale R_i R_j / (R_i + R_j), or R_i for a wall (R_j = 0)
    (scalar code: compiled by numba, and for the GPU by numba.cuda, :mod:`colsim.engine.cuda_contacts`)."""
    if radius_j > 0:
        return scale * (radius_i * radius_j / (radius_i + radius_j))
    return radius_i


def _levers(radius_i, radius_j, scale, out):
    """out (m,) = :func:`colsim.engine.state.rolling_lever` in one pass, the same arithmetic (scale 2
    for 'paper', 1 for 'effective'): numpy's form made eight temporaries."""
    for k in prange(len(out)):
        out[k] = lever_of(radius_i[k], radius_j[k], scale)


def contact_levers(radius_i: np.ndarray, radius_j: np.ndarray, lever: str) -> np.ndarray:
    """(m,) the rolling lever of each contact (:func:`colsim.engine.state.rolling_lever`, its
    definition and the tests' oracle), compiled for the step's arrays."""
    rolling_lever(radius_i[:1], radius_j[:1], lever)   # the same check of `lever`
    out = np.empty(len(radius_i))
    _levers(np.ascontiguousarray(radius_i, dtype=float), np.ascontiguousarray(radius_j, dtype=float),
            2.0 if lever == "paper" else 1.0, out)
    return out


swept_close = numba.njit(cache=True, inline="always")(swept_close)
_swept_keep = numba.njit(cache=True, parallel=True)(_swept_keep)
lever_of = numba.njit(cache=True, inline="always")(lever_of)
_levers = numba.njit(cache=True, parallel=True)(_levers)


def recovery_relaxation(true_gap: np.ndarray, most_recovered: float, kept: float = 0.0) -> np.ndarray:
    """(m,) length added to each constraint's gap so that a step removes at most `most_recovered`
    (length) of an overlap that is already there: max(0, -true_gap - most_recovered), and with
    `kept` (length) > 0 none of an overlap up to `kept`: max(that, min(-true_gap, kept)).

    An overlap g < 0 at the start of a step is otherwise removed within the step, as a velocity
    -g/dt: a kinetic energy that grows like 1/dt^2 as the step shrinks. With the relaxation the
    constraint asks for g_eff + du_n >= ..., g_eff = max(g, -most_recovered): an overlap never grows
    and shrinks by at least most_recovered a step, at a speed that does not depend on dt.

    kept: an overlap up to it is kept as it is (it never grows) and not asked back; a larger one
    shrinks towards it by at most most_recovered a step. Between rigid walls a chain of grains from
    wall to wall may have no motion but dilating ones under the associated law's friction, so that
    asking an overlap back leaves the step no solution (a one-grain slot's first step did)."""
    true_gap = np.ascontiguousarray(true_gap, dtype=float)
    out = np.empty_like(true_gap)
    _relaxations(true_gap.reshape(-1), float(most_recovered), float(kept), out.reshape(-1))
    return out


def relaxation_of(true_gap, most_recovered, kept):
    """:func:`recovery_relaxation` of one gap: max(0, -g - most_recovered, min(-g, kept)) (kept 0 adds
    nothing: min(-g, 0) <= max(0, ...)) (scalar code: compiled by numba, and for the GPU by
    numba.cuda, :mod:`colsim.engine.cuda_contacts`)."""
    return max(0.0, -true_gap - most_recovered, min(-true_gap, kept))


def _relaxations(true_gap, most_recovered, kept, out):
    """out (m,) = :func:`relaxation_of` of each gap of `true_gap` (m,)."""
    for k in prange(len(out)):
        out[k] = relaxation_of(true_gap[k], most_recovered, kept)


relaxation_of = numba.njit(cache=True, inline="always")(relaxation_of)
_relaxations = numba.njit(cache=True, parallel=True)(_relaxations)


def _wall_contacts(state: ParticleState, walls: Walls, reach: np.ndarray, cylinder_margin=0.0,
                   most_recovered: float = np.inf, kept: float = 0.0):
    """(i, family, normal (m,3), gap) for particle-wall contacts with gap below reach (n,) (length).

    cylinder_margin: (n,) or scalar length subtracted from the cylinder gaps (see :func:`detect`).
    most_recovered, kept: the most of an existing overlap that a step removes, and the overlap it
    keeps (:func:`recovery_relaxation`).
    """
    parts = []
    if walls.floor:
        gap = state.position[:, 2] - state.radius
        idx = np.flatnonzero(gap < reach)
        normal = np.tile([0.0, 0.0, -1.0], (len(idx), 1))
        gap = gap + recovery_relaxation(gap, most_recovered, kept)
        parts.append((idx, np.full(len(idx), FLOOR), normal, gap[idx]))
    if walls.cylinder_radius is not None:
        rho = np.hypot(state.position[:, 0], state.position[:, 1])
        true_gap = walls.cylinder_radius - rho - state.radius
        gap = true_gap + recovery_relaxation(true_gap, most_recovered, kept) - cylinder_margin
        idx = np.flatnonzero(gap < reach)
        normal = np.zeros((len(idx), 3))
        on_axis = rho[idx] < 1e-12
        safe_rho = np.where(on_axis, 1.0, rho[idx])
        normal[:, 0] = np.where(on_axis, 1.0, state.position[idx, 0] / safe_rho)
        normal[:, 1] = np.where(on_axis, 0.0, state.position[idx, 1] / safe_rho)
        parts.append((idx, np.full(len(idx), CYLINDER), normal, gap[idx]))
    for p, plane in enumerate(walls.plane_array()):
        true_gap = plane_gaps(state, plane)
        gap = true_gap + recovery_relaxation(true_gap, most_recovered, kept)
        idx = np.flatnonzero(gap < reach)
        parts.append((idx, np.full(len(idx), PLANE + p), np.tile(-plane[:3], (len(idx), 1)), gap[idx]))
    if not parts:
        return np.zeros(0, int), np.zeros(0, int), np.zeros((0, 3)), np.zeros(0)
    return tuple(np.concatenate(arrays) for arrays in zip(*parts))


def plane_gap(position, radius, i, normal_x, normal_y, normal_z, offset):
    """Particle i's gap n . x_i - offset - R_i (length) to the plane wall (n_x, n_y, n_z, offset)
    (:class:`colsim.engine.state.Walls`), the products summed in the order x, y, z (scalar code:
    compiled by numba, and for the GPU by numba.cuda, :mod:`colsim.engine.cuda_contacts`)."""
    distance = position[i, 0] * normal_x
    distance += position[i, 1] * normal_y
    distance += position[i, 2] * normal_z
    return (distance - offset) - radius[i]


def _plane_gaps(position, radius, plane, out):
    """out (n,) = :func:`plane_gap` of each particle to `plane` (4,)."""
    for i in prange(len(out)):
        out[i] = plane_gap(position, radius, i, plane[0], plane[1], plane[2], plane[3])


plane_gap = numba.njit(cache=True, inline="always")(plane_gap)
_plane_gaps = numba.njit(cache=True, parallel=True)(_plane_gaps)


def plane_gaps(state: ParticleState, plane: np.ndarray) -> np.ndarray:
    """(n,) each particle's gap to the plane wall `plane` (n_x, n_y, n_z, offset) (length)."""
    out = np.empty(state.n)
    _plane_gaps(np.ascontiguousarray(state.position, dtype=float), np.ascontiguousarray(state.radius, dtype=float),
                np.ascontiguousarray(plane, dtype=float), out)
    return out


def fixed_pairs(state: ParticleState, fixed: FixedSpheres | None, reach: np.ndarray):
    """Particle-fixed sphere pairs with a gap below reach[i] (length): (i, k, normal from i to k
    (m, 3), gap (m,))."""
    if fixed is None or fixed.n == 0 or state.n == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0)
    far = float(state.radius.max() + fixed.radius.max() + max(float(np.max(reach)), 0.0))
    found = cKDTree(state.position).sparse_distance_matrix(cKDTree(fixed.position), far, output_type="ndarray")
    i, k, dist = found["i"].astype(np.int64), found["j"].astype(np.int64), found["v"]
    gap = dist - state.radius[i] - fixed.radius[k]
    close = gap < reach[i]
    i, k, dist, gap = i[close], k[close], dist[close], gap[close]
    normal = (fixed.position[k] - state.position[i]) / np.maximum(dist, 1e-300)[:, None]
    return i, k, normal, gap


def pair_frames(state: ParticleState, i: np.ndarray, j: np.ndarray, normal: np.ndarray | None = None,
                most_recovered: float = np.inf, kept: float = 0.0):
    """(normal, tangent1, tangent2 (m, 3), gap (m,)) of particle pairs (i, j): the unit normal from
    i to j (or the `normal` given), the tangents of :func:`tangent_basis` and the gap along the
    normal (length), relaxed by :func:`recovery_relaxation` of the centre-distance gap."""
    d = state.position[j] - state.position[i]
    distance = row_lengths(d)
    if normal is None:
        normal = d / distance[:, None]
    gap = np.einsum("ij,ij->i", normal, d) - state.radius[i] - state.radius[j]
    true_gap = distance - state.radius[i] - state.radius[j]
    gap += recovery_relaxation(true_gap, most_recovered, kept)
    t1, t2 = tangent_basis(np.reshape(normal, (-1, 3)))
    return normal, t1, t2, gap


def detect(state: ParticleState, walls: Walls, law: ContactLaw, predicted: np.ndarray,
           margin: float, slack: float = 0.5, cylinder_margin=0.0, renormal=None,
           most_recovered: float = np.inf, kept: float = 0.0) -> Contacts:
    """Potential contacts of a step in which the particles are predicted to move predicted (n, 3).

    margin (length): gap allowed beyond the predicted motion; slack: fraction of each pair's (or
    particle's, for walls) predicted displacement added to it, for the velocity changes of the step.
    The cylinder is concave: a particle sliding a distance s along it moves out by about s^2/(2 r0),
    which the linearised constraint does not see; `cylinder_margin` ((n,) or scalar, length)
    tightens those gaps and the stepper sets it from the overlap of a first attempt.
    renormal: optional (i, j, normal (k, 3)) particle pairs to include with a given normal. Any unit
    normal n gives a conservative linear constraint n.(x_j - x_i) - R_i - R_j + n.du >= 0, since
    |d| >= n.d; the stepper passes the end-of-attempt normals of pairs that a first attempt missed.
    most_recovered (length): the most of an overlap present at the start that the step removes; the
    gaps are relaxed by :func:`recovery_relaxation` of the true (centre-distance) gaps, so the
    linearisation and the cylinder margin keep their effect. inf: the whole overlap (no cap).
    kept (length): an overlap up to it is kept and not asked back (:func:`recovery_relaxation`).
    The swept pairs come from a k-d tree (:func:`swept_pairs`) and their frames from
    :func:`pair_frames`; a back-end may find them elsewhere (:mod:`colsim.engine.backend`).
    """
    others = other_rows(state, walls, law, predicted, margin, slack, cylinder_margin, most_recovered, kept)
    given = given_rows(state, law, renormal, most_recovered, kept)
    predicted = np.asarray(predicted)   # a predicted motion made elsewhere: its host copy
    pi, pj = swept_pairs(state, predicted, margin, slack)
    pairs = pair_rows(state, law, pi, pj, pair_frames(state, pi, pj, None, most_recovered, kept))
    parts = [pairs, others]
    if given is not None:   # these pairs, with the normals given, replace those found and go last
        keep = ~np.isin(pi.astype(np.int64) * state.n + pj, given["i"].astype(np.int64) * state.n + given["j"])
        parts = [{name: values[keep] for name, values in pairs.items()}, given, others]
    arrays = {name: np.concatenate([part[name] for part in parts]) for name in pairs}
    for name in ("i", "j", "family"):
        arrays[name] = arrays[name].astype(np.int64)
    arrays["lever"] = contact_levers(arrays["radius_i"], arrays["radius_j"], law.rolling_lever)
    return Contacts(**arrays)


def other_rows(state: ParticleState, walls: Walls, law: ContactLaw, predicted, margin: float, slack: float,
               cylinder_margin, most_recovered: float, kept: float = 0.0) -> dict:
    """The contacts of :func:`detect` with `walls`' walls and fixed spheres, by name (:func:`_other_contacts`)."""
    fixed = walls.fixed is not None and walls.fixed.n > 0
    if walls.floor or walls.cylinder_radius is not None or walls.planes or fixed:
        reach = margin + (1.0 + slack) * row_lengths(np.asarray(predicted))
    else:
        reach = np.zeros(state.n)   # no wall: none asked
    return _other_contacts(state, walls, law, reach, cylinder_margin, most_recovered, kept)


def given_rows(state: ParticleState, law: ContactLaw, renormal, most_recovered: float,
               kept: float = 0.0) -> dict | None:
    """The rows of :func:`detect`'s pairs with given normals (`renormal`: (i, j, normal), or None)."""
    if renormal is None:
        return None
    return pair_rows(state, law, renormal[0], renormal[1],
                     pair_frames(state, renormal[0], renormal[1], renormal[2], most_recovered, kept))


def pair_rows(state: ParticleState, law: ContactLaw, i: np.ndarray, j: np.ndarray, frames) -> dict:
    """The arrays of particle pairs (i, j) ((k,) each) by their names in :class:`Contacts` (all but the
    lever): bodies, family, frames (normal, tangent1, tangent2, gap: :func:`pair_frames`), radii and
    the particles' coefficients."""
    normal, tangent1, tangent2, gap = frames
    k = len(i)
    return {"i": i, "j": j, "family": np.full(k, PARTICLE), "gap": gap, "radius_i": state.radius[i],
            "radius_j": state.radius[j], "mu": np.full(k, float(np.asarray(law.mu)[PARTICLE])),
            "mu_r": np.full(k, float(np.asarray(law.mu_r)[PARTICLE])), "normal": normal.reshape(-1, 3),
            "tangent1": tangent1.reshape(-1, 3), "tangent2": tangent2.reshape(-1, 3)}


#: the arrays of every contact, by name, that a back-end's detection may hold elsewhere than the host
DEVICE_ARRAYS = ("i", "j", "family", "normal", "tangent1", "tangent2", "gap", "radius_i", "radius_j", "lever", "mu",
                 "mu_r", "keys")


def _other_contacts(state: ParticleState, walls: Walls, law: ContactLaw, reach: np.ndarray, cylinder_margin,
                    most_recovered: float, kept: float = 0.0) -> dict:
    """The contacts with the floor, the cylinder, the planes and the fixed spheres (see :func:`detect`), by name:
    i, j, family, normal, tangent1, tangent2, gap, radius_i, radius_j, mu, mu_r (the lever is made
    with the pairs' one)."""
    wi, wfamily, wnormal, wgap = _wall_contacts(state, walls, reach, cylinder_margin, most_recovered, kept)
    fi, fk, fnormal, fgap = fixed_pairs(state, walls.fixed, reach)
    normal = np.concatenate([wnormal, fnormal]).reshape(-1, 3)
    tangent1, tangent2 = tangent_basis(normal)
    family = np.concatenate([wfamily, np.full(len(fi), PARTICLE)]).astype(np.int64)
    i = np.concatenate([wi, fi]).astype(np.int64)
    return {"i": i, "j": np.concatenate([np.full(len(wi), WALL), fixed_code(fk)]).astype(np.int64),
            "family": family, "normal": normal, "tangent1": tangent1, "tangent2": tangent2,
            "gap": np.concatenate([wgap, fgap + recovery_relaxation(fgap, most_recovered, kept)]),
            "radius_i": state.radius[i],
            "radius_j": np.concatenate([np.zeros(len(wi)), walls.fixed.radius[fk] if len(fk) else np.zeros(0)]),
            "mu": np.asarray(law.mu)[law_family(family)], "mu_r": np.asarray(law.mu_r)[law_family(family)]}


@dataclass
class Overlaps:
    """Overlaps (length, >= 0) after a step.

    pairs: (i, j, normal (k, 3)) particle pairs that overlap by more than `tolerance`
    largest_pair, largest_floor, largest_fixed, largest_plane: largest particle-particle,
    particle-floor, particle-fixed sphere and particle-plane wall overlap
    cylinder: (n,) overlap of each particle with the cylinder, or None where only the largest was
    measured (`largest_cylinder`: a state on the device whose overlaps are all within the tolerance)
    """

    pairs: tuple
    largest_pair: float
    largest_floor: float
    cylinder: np.ndarray | None
    largest_fixed: float = 0.0
    largest_cylinder: float | None = None
    largest_plane: float = 0.0

    @property
    def largest(self) -> float:
        cylinder = float(self.cylinder.max(initial=0.0)) if self.cylinder is not None else self.largest_cylinder
        return max(self.largest_pair, self.largest_floor, self.largest_fixed, cylinder, self.largest_plane)


def overlaps(state: ParticleState, walls: Walls, tolerance: float = 0.0,
             detected: Contacts | None = None) -> Overlaps:
    """Measure every overlap of `state` (see :class:`Overlaps`). detected: a detection at `state`,
    whose swept pairs hold every pair that overlaps there (the stepper's check): its particle pairs
    are measured instead of searching (:func:`detected_overlaps`)."""
    if detected is not None:
        largest_pair, pairs = detected_overlaps(detected, state, tolerance)
    else:
        largest_pair, pairs = pair_overlaps(state, *particle_pairs(state, 0.0), tolerance)
    return wall_overlaps(state, walls, largest_pair, pairs)


def detected_overlaps(detected: Contacts, state: ParticleState, tolerance: float) -> tuple:
    """(largest overlap, (i, j, normal)) of the particle pairs of `detected`, a detection at `state`
    (:meth:`Contacts.overlapping_pairs`), or none at all to report when the detection measured
    their largest overlap and that is within the tolerance (:attr:`Contacts.largest_pair_overlap`)."""
    measured = detected.largest_pair_overlap
    if measured is not None and measured <= tolerance:
        return measured, (np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros((0, 3)))
    return detected.overlapping_pairs(state, tolerance)


def wall_overlaps(state: ParticleState, walls: Walls, largest_pair: float, pairs: tuple) -> Overlaps:
    """The :class:`Overlaps` of `state` with its particle pairs' (largest_pair, pairs) given: the
    floor's, each particle's with the cylinder, the planes' and the fixed spheres' measured here."""
    largest_floor = 0.0
    if walls.floor and state.n:
        largest_floor = max(0.0, float(-(state.position[:, 2] - state.radius).min()))
    cylinder = np.zeros(state.n)
    if walls.cylinder_radius is not None and state.n:
        rho = np.hypot(state.position[:, 0], state.position[:, 1])
        cylinder = np.maximum(rho + state.radius - walls.cylinder_radius, 0.0)
    _, _, _, fixed_gap = fixed_pairs(state, walls.fixed, np.zeros(state.n))
    return Overlaps(pairs, max(0.0, largest_pair), largest_floor, cylinder, max(0.0, float(-fixed_gap.min(initial=0.0))),
                    largest_plane=largest_plane_overlap(state, walls))


def largest_plane_overlap(state: ParticleState, walls: Walls) -> float:
    """The largest overlap R_i - (n . x_i - offset) (length, >= 0) of `state` with `walls`' planes."""
    largest = 0.0
    for plane in walls.plane_array():
        if state.n:
            largest = max(largest, float(np.max(-plane_gaps(state, plane))))
    return largest


def pair_overlaps(state: ParticleState, pi: np.ndarray, pj: np.ndarray, d: np.ndarray, tolerance: float) -> tuple:
    """(largest overlap (-inf: no pair), (i, j, normal)) of the pairs (pi, pj) with centre-to-centre
    vectors d (k, 3): :meth:`Contacts.overlapping_pairs`."""
    dist = row_lengths(d)
    overlap = state.radius[pi] + state.radius[pj] - dist
    bad = overlap > tolerance
    pairs = (pi[bad], pj[bad], d[bad] / np.maximum(dist[bad, None], 1e-300))   # two centres on one spot: a zero normal
    return float(overlap.max(initial=-np.inf)), pairs


def touching_pairs(state: ParticleState, tolerance: float) -> tuple[np.ndarray, np.ndarray]:
    """Particle pairs (i, j) whose gap is below tolerance (length): the contact graph's edges."""
    pi, pj, _ = particle_pairs(state, tolerance)
    return pi, pj
