"""The swept particle pairs of contact detection on one GPU: the pairs of
:func:`colsim.engine.contacts.swept_pairs` from a uniform grid instead of a k-d tree, in numba.cuda
kernels.

Each particle's swept segment is binned by its midpoint x + u/2 into cubic cells at least as wide
as the k-d tree's reach, so that every candidate pair lies in neighbouring cells:

1. one thread a particle finds its cell; the cells' counts (an atomic add each) become their
   starts (a prefix sum) and the particles are listed cell by cell (a counting sort);
2. one thread a particle scans the 27 cells around its own, and keeps each partner j > i whose
   midpoint lies within the reach (the k-d tree's test) and whose relative segment comes within
   margin + slack |u_j - u_i| of contact (the CPU's :func:`colsim.engine.contacts.swept_close`,
   compiled for the GPU): a first pass counts them, a prefix sum gives each particle its place, a
   second pass writes them there and sorts them by j.

So the pairs come out sorted by (i, j) as the CPU's do, and the same every run: no order depends on
the atomic adds. For detect, :func:`swept_contacts` then makes every contact's arrays there (3. one
thread a particle over its partners: the normal, tangents and gap; then one thread a contact: the
lever and the pair key), and they stay there (:class:`DeviceContacts`): what comes back is the
pairs' count and each block's largest overlap. The prefix sums run on the device. Without a GPU
the kernels run on numba's CUDA simulator (NUMBA_ENABLE_CUDASIM=1), where the tests compare the
contacts with the CPU's.
"""
from __future__ import annotations

import functools
import math

import numpy as np

from .contacts import WALL, Contacts, lever_of, pair_overlaps, plane_gap, relaxation_of, swept_close
from .state import CYLINDER, FLOOR, PARTICLE, PLANE, pair_key
from .cuda_launch import launch
from .cuda_state import (DeviceParticleArray, axis_distance, midpoints_on_device, particle_array_on_device,
                         state_array_on_device)
from .cuda_operator import (THREADS, block_reduce, blocks_for, cuda, full_on_device,
                            keep_device_copy, prefix_sums_on_device, sort_range_on_device)

#: the CPU's swept test (colsim.engine.contacts.swept_close), compiled for the GPU
_swept_close = cuda.jit(device=True)(getattr(swept_close, "py_func", swept_close))

#: the grid has at most this many cells a particle: a sparse cloud gets wider cells (any width at
#: least the reach finds the same pairs), not an array of empty ones
CELLS_PER_PARTICLE = 4


def swept_pairs_on_device(state, predicted: np.ndarray, margin: float, slack: float):
    """(i, j) int64 (m,): the pairs of :func:`colsim.engine.contacts.swept_pairs`, sorted by (i, j),
    found on the GPU. state: a ParticleState (n particles); predicted: (n, 3) length."""
    if state.n < 2:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty
    found = _SweptPairs(state, predicted, margin, slack)
    counts = np.diff(found.offsets.copy_to_host())
    return np.repeat(np.arange(state.n, dtype=np.int64), counts), found.partners.copy_to_host()[:found.m]


class DeviceContacts(Contacts):
    """The contacts of a GPU detection (:func:`swept_contacts`, :func:`join_given_pairs`), whose arrays
    stay on the device: `rows` (a :class:`ContactRows`) holds them, and `device` each of them by name
    (:data:`colsim.engine.contacts.DEVICE_ARRAYS`). A host array is copied from there when first read
    (a file, a solver on the CPU), and that copy keeps the device's as its own
    (:func:`colsim.engine.cuda_operator.keep_device_copy`); a step on the GPU reads none: the warm start
    and the solver take the device's (:func:`contact_arrays_on_device`). m: the contacts; pair_count:
    the first pair_count are the particle pairs, the walls' and fixed spheres' rows follow;
    particles: (positions (n, 3), radii (n,)) on the device, of the state detected, kept with the
    largest pair overlap measured (a first attempt's; None: neither)."""

    def __init__(self, rows: "ContactRows", pair_count: int, largest_pair_overlap: float | None, particles=None):
        self.rows, self.device, self._pair_count = rows, rows.named(), pair_count
        self.largest_pair_overlap, self.particles = largest_pair_overlap, particles

    m = property(lambda self: self.rows.count)
    pair_count = property(lambda self: self._pair_count)
    keys = property(lambda self: self._on_host("keys"), doc="(m,) int64 pair keys (copied from the device).")

    def __getattr__(self, name):   # only for an attribute not set: a host array not yet copied
        if name in self.__dict__.get("device", ()):
            return self._on_host(name)
        raise AttributeError(name)

    def _on_host(self, name: str) -> np.ndarray:
        host = self.__dict__.get(name)
        if host is None:
            host = self.__dict__[name] = self.device[name].copy_to_host()
            keep_device_copy(host, self.device[name])
        return host

    def overlapping_pairs(self, state, tolerance: float) -> tuple:
        """:meth:`colsim.engine.contacts.Contacts.overlapping_pairs`, the pairs that overlap by more than
        `tolerance` listed on the device (one thread a pair: the flags, their prefix sums, the flagged
        pairs' bodies), at the particles the detection had there (`particles`: their positions and
        radii; `state` must be the one detected). What comes back is their count and their bodies;
        their normals are made on the host, as there. Contacts without their largest overlap
        measured, nor the particles kept (a redo's): the host's way."""
        pairs = self.pair_count
        if self.largest_pair_overlap is None or not pairs:
            return super().overlapping_pairs(state, tolerance)
        position, radius = self.particles
        flag = cuda.device_array(pairs, dtype=np.int64)
        launch(_overlap_flags_kernel, blocks_for(pairs), THREADS, position, radius, self.rows.bodies,
               float(tolerance), flag)
        start = prefix_sums_on_device(flag)
        count = int(start[pairs:].copy_to_host()[0])
        listed = np.zeros((2, 0), dtype=np.int64)
        if count:
            on_device = cuda.device_array((2, count), dtype=np.int64)
            launch(_flagged_pairs_kernel, blocks_for(pairs), THREADS, self.rows.bodies, start, on_device)
            listed = on_device.copy_to_host()
        pi, pj = listed
        _, overlapping = pair_overlaps(state, pi, pj, state.position[pj] - state.position[pi], tolerance)
        return self.largest_pair_overlap, overlapping


#: the rows of the device's per-contact numbers and bodies (:class:`ContactRows`), by the contacts' names
_NUMBERS = ("gap", "radius_i", "radius_j", "lever", "mu", "mu_r")
GAP, RADIUS_I, RADIUS_J, LEVER, MU, MU_R = range(len(_NUMBERS))
_BODIES = ("i", "j", "family")
BODY_I, BODY_J, FAMILY = range(len(_BODIES))
_FRAMES = ("normal", "tangent1", "tangent2")


class ContactRows:
    """`count` contacts' arrays on the device, in four blocks: frames (3, count, 3) float64 (normal,
    tangent1, tangent2), numbers (6, count) float64 (:data:`_NUMBERS`), bodies (3, count) int64
    (:data:`_BODIES`) and keys (count,) int64, the pair keys."""

    def __init__(self, count: int):
        self.count = count
        self.frames = cuda.device_array((len(_FRAMES), count, 3), dtype=np.float64)
        self.numbers = cuda.device_array((len(_NUMBERS), count), dtype=np.float64)
        self.bodies = cuda.device_array((len(_BODIES), count), dtype=np.int64)
        self.keys = cuda.device_array(count, dtype=np.int64)

    def named(self) -> dict:
        """Each contact array, a view of its block, by its name in :class:`colsim.engine.contacts.Contacts`."""
        return {"keys": self.keys, **{name: self.bodies[k] for k, name in enumerate(_BODIES)},
                **{name: self.frames[f] for f, name in enumerate(_FRAMES)},
                **{name: self.numbers[k] for k, name in enumerate(_NUMBERS)}}

    def upload(self, rows: dict, first: int) -> None:
        """Host contacts' arrays by name (all but the lever and keys, which :meth:`levers_and_keys`
        makes) into rows first, first + 1, ...: in one copy (a small copy from the host costs nearly what
        a large one does), the bodies' integers carried as the float64 words of the same
        bits, and read back as integers on the device (a copy moves bytes, never rounds them)."""
        w = len(rows["i"])
        if not w:
            return
        end = first + w
        uploaded = [row for row in range(len(_NUMBERS)) if row != LEVER]
        bodies = np.stack([rows[name] for name in _BODIES]).astype(np.int64).reshape(-1)
        words = cuda.to_device(np.concatenate([np.stack([rows[name] for name in _FRAMES]).reshape(-1)] + [
            np.asarray(rows[_NUMBERS[row]], dtype=float) for row in uploaded] + [bodies.view(np.float64)]))
        for f in range(len(_FRAMES)):
            self.frames[f, first:end].copy_to_device(words[3 * w * f:3 * w * (f + 1)].reshape(w, 3))
        for k, row in enumerate(uploaded):
            self.numbers[row, first:end].copy_to_device(words[(9 + k) * w:(10 + k) * w])
        integers = words[(9 + len(uploaded)) * w:].view(np.int64)
        for b in range(len(_BODIES)):
            self.bodies[b, first:end].copy_to_device(integers[b * w:(b + 1) * w])

    def levers_and_keys(self, rolling_lever: str, first: int = 0, end: int | None = None) -> None:
        """Rows first to end's (None: the last) rolling levers and pair keys, from their radii and bodies."""
        end = self.count if end is None else end
        if end > first:
            launch(_lever_and_key_kernel, blocks_for(end - first), THREADS, self.numbers, self.bodies,
                   2.0 if rolling_lever == "paper" else 1.0, self.keys, first, end)


def swept_contacts(state, predicted: np.ndarray, margin: float, slack: float, most_recovered: float,
                   others: dict, law, walls=None, kept: float = 0.0) -> DeviceContacts | None:
    """The contacts of :func:`colsim.engine.contacts.detect`'s first attempt, made on the GPU
    (:class:`DeviceContacts`), or None for fewer than two particles or no contacts (detect then makes
    them on the host).

    The particle pairs are :func:`swept_pairs_on_device`'s. Each gets the unit normal from i to j,
    the tangents of :func:`colsim.engine.contacts.tangent_basis` and the gap along the normal, relaxed
    by :func:`colsim.engine.contacts.recovery_relaxation` with most_recovered (length; inf: none) and
    kept (length), in
    the CPU's arithmetic (to rounding: a GPU fuses some multiply-adds), and its bodies, family,
    radii and coefficients (from `law`, a ContactLaw).

    walls: a Walls whose floor and cylinder contacts are made on the device (:class:`_WallContacts`, the
    arithmetic of :func:`colsim.engine.contacts._wall_contacts`, no cylinder margin), following the
    pairs'; None: none there. others: the other contacts' arrays by name (detect's fixed spheres, and
    its walls where `walls` is None, made on the host); their rows go to the device in one copy
    (:meth:`ContactRows.upload`) and follow the pairs' and the walls'. Every
    contact's lever (the CPU's arithmetic) and pair key (:func:`colsim.engine.state.pair_key`) are made
    there. The pairs' largest overlap R_i + R_j - |x_j - x_i| (length; -inf: no pair) is
    :func:`colsim.engine.contacts.overlaps`' of these pairs, in its arithmetic, so that the stepper's
    check need not measure them on the host: each block's largest comes back, the one copy from the
    device besides the pairs' count and the walls' count."""
    if state.n < 2:
        return None
    found = _SweptPairs(state, predicted, margin, slack)
    on_walls = _WallContacts(found, margin, slack, most_recovered, walls, kept) if walls is not None else None
    m, made = found.m, on_walls.count if on_walls is not None else 0
    total = m + made + len(others["i"])
    if total == 0:   # no zero-length arrays on the device
        return None
    rows = ContactRows(total)
    if made:
        on_walls.fill(rows, m, law)
    rows.upload(others, m + made)
    blocks = blocks_for(state.n)
    largest = cuda.device_array(blocks, dtype=np.float64)   # each block's largest pair overlap
    launch(_frames_kernel, blocks, THREADS, found.position, found.radius, found.offsets, found.partners,
           float(most_recovered), float(kept), rows.frames[0], rows.numbers[GAP], rows.frames[1], rows.frames[2],
           largest)
    mu, mu_r = (float(np.asarray(values)[PARTICLE]) for values in (law.mu, law.mu_r))
    launch(_pair_rows_kernel, blocks, THREADS, found.offsets, found.partners, found.radius, mu, mu_r, rows.bodies,
           rows.numbers)
    rows.levers_and_keys(law.rolling_lever)
    return DeviceContacts(rows, m, float(largest.copy_to_host().max()), (found.position, found.radius))


def join_given_pairs(found: DeviceContacts, given: dict, n: int, rolling_lever: str) -> DeviceContacts:
    """:func:`colsim.engine.contacts.detect`'s redo on the GPU: the contacts of `found` (a first
    attempt's, :func:`swept_contacts`) with the particle pairs `given` (their arrays by name, made on
    the host with the normals the stepper gives, as :func:`colsim.engine.contacts.pair_rows` makes
    them; each pair once) in place of found's same pairs, in the CPU's order: found's other pairs,
    then the given ones, then found's walls and fixed spheres. n: the particles (a pair's key is
    i n + j); rolling_lever: the ContactLaw's.

    The rows move on the device: one thread a pair looks its key up among the given ones (sorted, a
    binary search), the kept pairs' places are their prefix sums, and one thread a contact copies its
    row there. What goes to the device is the given pairs (their sorted keys, their rows in one
    copy); what comes back is the kept pairs' count. Its pairs' largest overlap is not measured
    (None), as on the host."""
    wanted = np.sort(np.asarray(given["i"], dtype=np.int64) * n + np.asarray(given["j"], dtype=np.int64))
    pairs = found.pair_count
    keep = cuda.device_array(max(pairs, 1), dtype=np.int64)[:pairs]
    if pairs:
        launch(_kept_pairs_kernel, blocks_for(pairs), THREADS, found.rows.bodies, n, cuda.to_device(wanted), keep)
    start = prefix_sums_on_device(keep)
    kept = int(start[pairs:].copy_to_host()[0])
    rows = ContactRows(found.m - pairs + kept + len(wanted))
    old = found.rows
    launch(_move_rows_kernel, blocks_for(old.count), THREADS, old.frames, old.numbers, old.bodies, old.keys, pairs,
           start, len(wanted), rows.frames, rows.numbers, rows.bodies, rows.keys)
    rows.upload(given, kept)
    rows.levers_and_keys(rolling_lever, kept, kept + len(wanted))
    return DeviceContacts(rows, kept + len(wanted), None)


#: the CPU's lever (colsim.engine.contacts.lever_of) and pair key (colsim.engine.state.pair_key), for the GPU
_lever_of = cuda.jit(device=True)(getattr(lever_of, "py_func", lever_of))
_relaxation_of = cuda.jit(device=True)(getattr(relaxation_of, "py_func", relaxation_of))
_plane_gap = cuda.jit(device=True)(getattr(plane_gap, "py_func", plane_gap))
_pair_key = cuda.jit(device=True)(pair_key)


@cuda.jit
def _pair_rows_kernel(offsets, partners, radius, mu, mu_r, bodies, numbers):
    """Each pair (i, j) of particle i (one thread a particle): its bodies and family, its radii R_i and
    R_j and the particles' coefficients, into the rows of bodies (:data:`_BODIES`) and numbers
    (:data:`_NUMBERS`)."""
    i = cuda.grid(1)
    if i >= offsets.shape[0] - 1:
        return
    for k in range(offsets[i], offsets[i + 1]):
        j = partners[k]
        bodies[BODY_I, k], bodies[BODY_J, k], bodies[FAMILY, k] = i, j, PARTICLE
        numbers[RADIUS_I, k], numbers[RADIUS_J, k] = radius[i], radius[j]
        numbers[MU, k], numbers[MU_R, k] = mu, mu_r


@cuda.jit
def _lever_and_key_kernel(numbers, bodies, scale, keys, first, end):
    """Contacts first to end - 1 (one thread each): the rolling lever from the radii and the pair key from
    the bodies, by the CPU's code (:func:`colsim.engine.contacts.lever_of`,
    :func:`colsim.engine.state.pair_key`)."""
    k = first + cuda.grid(1)
    if k < end:
        numbers[LEVER, k] = _lever_of(numbers[RADIUS_I, k], numbers[RADIUS_J, k], scale)
        keys[k] = _pair_key(bodies[BODY_I, k], bodies[BODY_J, k], bodies[FAMILY, k])


@cuda.jit
def _kept_pairs_kernel(bodies, n, wanted, keep):
    """keep[k] = 0 where pair k's key i n + j is among `wanted` (sorted; a binary search), else 1."""
    k = cuda.grid(1)
    if k >= keep.shape[0]:
        return
    key = bodies[BODY_I, k] * n + bodies[BODY_J, k]
    low, high = 0, wanted.shape[0]
    while low < high:
        middle = (low + high) // 2
        if wanted[middle] < key:
            low = middle + 1
        else:
            high = middle
    keep[k] = 0 if low < wanted.shape[0] and wanted[low] == key else 1


@cuda.jit
def _overlap_flags_kernel(position, radius, bodies, tolerance, flag):
    """flag[k] = 1 where pair k's overlap R_i + R_j - |x_j - x_i| exceeds `tolerance`, else 0 (one thread
    a pair, the arithmetic of colsim.engine.contacts.overlaps)."""
    k = cuda.grid(1)
    if k >= flag.shape[0]:
        return
    i, j = bodies[BODY_I, k], bodies[BODY_J, k]
    d0 = position[j, 0] - position[i, 0]
    d1 = position[j, 1] - position[i, 1]
    d2 = position[j, 2] - position[i, 2]
    flag[k] = 1 if radius[i] + radius[j] - math.sqrt(d0 * d0 + d1 * d1 + d2 * d2) > tolerance else 0


@cuda.jit
def _flagged_pairs_kernel(bodies, start, listed):
    """The flagged pairs' bodies (start: the flags' prefix sums) into listed[0] (i) and listed[1] (j),
    in the pairs' order."""
    k = cuda.grid(1)
    if k < start.shape[0] - 1 and start[k + 1] > start[k]:
        listed[0, start[k]], listed[1, start[k]] = bodies[BODY_I, k], bodies[BODY_J, k]


@cuda.jit
def _move_rows_kernel(frames, numbers, bodies, keys, pairs, start, given, to_frames, to_numbers, to_bodies,
                      to_keys):
    """Contact k's row (one thread each) to its place in the joined blocks: a pair (k < pairs) to
    start[k] when kept (start: the kept flags' prefix sums), nowhere when not; another contact after
    the kept pairs and the `given` ones."""
    k = cuda.grid(1)
    if k >= keys.shape[0]:
        return
    if k < pairs:
        if start[k + 1] == start[k]:
            return
        row = start[k]
    else:
        row = start[pairs] + given + k - pairs
    for f in range(frames.shape[0]):
        for d in range(3):
            to_frames[f, row, d] = frames[f, k, d]
    for r in range(numbers.shape[0]):
        to_numbers[r, row] = numbers[r, k]
    for b in range(bodies.shape[0]):
        to_bodies[b, row] = bodies[b, k]
    to_keys[row] = keys[k]


class _SweptPairs:
    """The swept pairs of n >= 2 particles on the device: particle i's partners are
    partners[offsets[i]:offsets[i + 1]] (sorted), m pairs in all (the one number copied to the host);
    position, predicted, radius: the particles' on the device."""

    def __init__(self, state, predicted, margin: float, slack: float):
        n = state.n
        # a step's own, made on the device from the last step's (cuda_state), else copied once
        self.position = state_array_on_device(state, "position")
        if not isinstance(predicted, DeviceParticleArray):   # a host array: its copy (kept) or one made now
            predicted = np.ascontiguousarray(predicted, dtype=float)
        self.predicted = particle_array_on_device(predicted)
        self.radius = particle_array_on_device(state.radius)   # the particles' radii never change: one copy a run
        d_midpoint = midpoints_on_device(self.position, self.predicted)
        lower, upper, reach = _bounds(d_midpoint, self.predicted, self.radius, margin, slack)
        lower, dims, width = _grid(lower, upper, reach, n)
        cells = int(np.prod(dims))
        lower, dims = tuple(float(x) for x in lower), tuple(int(c) for c in dims)   # by value: no copies
        start, listed = _cell_lists(d_midpoint, lower, dims, width, cells)
        args = (self.position, self.predicted, self.radius, d_midpoint, start, listed, lower, dims, width,
                reach * reach, float(margin), float(slack))
        counts = full_on_device(n, 0, np.int64)
        launch(_pairs_kernel, blocks_for(n), THREADS, *args, counts, counts, counts, False)
        self.offsets = prefix_sums_on_device(counts)
        self.m = int(self.offsets[n:].copy_to_host()[0])
        self.partners = full_on_device(max(self.m, 1), 0, np.int64)
        launch(_pairs_kernel, blocks_for(n), THREADS, *args, counts, self.offsets, self.partners, True)


@cuda.jit
def _frames_kernel(position, radius, offsets, partners, most_recovered, kept, normal, gap, tangent1, tangent2,
                   largest):
    """Each pair (i, j) of particle i (one thread a particle): the unit normal from i to j, the gap
    along it relaxed as :func:`_relaxation_of` relaxes |d| - R_i - R_j, and the tangents of
    colsim.engine.contacts.tangent_basis (helper x unless |n_x| >= 0.9, then y; t1 = helper x n,
    normalised; t2 = n x t1), in the CPU's arithmetic; and largest[b] the largest overlap
    R_i + R_j - |d| of block b's particles' pairs (-inf: none)."""
    cache = cuda.shared.array(THREADS, dtype=np.float64)
    i = cuda.grid(1)
    t = cuda.threadIdx.x
    cache[t] = -math.inf
    if i < offsets.shape[0] - 1:
        cache[t] = _pair_frames(i, position, radius, offsets, partners, most_recovered, kept, normal, gap,
                                tangent1, tangent2)
    block_reduce(cache, t, True)
    if t == 0:
        largest[cuda.blockIdx.x] = cache[0]


@cuda.jit(device=True)
def _pair_frames(i, position, radius, offsets, partners, most_recovered, kept, normal, gap, tangent1, tangent2):
    """:func:`_frames_kernel`'s work for particle i's pairs; returns their largest overlap."""
    largest = -math.inf
    for k in range(offsets[i], offsets[i + 1]):
        j = partners[k]
        d0 = position[j, 0] - position[i, 0]
        d1 = position[j, 1] - position[i, 1]
        d2 = position[j, 2] - position[i, 2]
        distance = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        largest = max(largest, radius[i] + radius[j] - distance)
        n0, n1, n2 = d0 / distance, d1 / distance, d2 / distance
        g = n0 * d0 + n1 * d1 + n2 * d2 - radius[i] - radius[j]
        gap[k] = g + _relaxation_of(distance - radius[i] - radius[j], most_recovered, kept)
        normal[k, 0], normal[k, 1], normal[k, 2] = n0, n1, n2
        _put_tangents(k, n0, n1, n2, tangent1, tangent2)
    return largest


@cuda.jit(device=True)
def _put_tangents(k, n0, n1, n2, tangent1, tangent2):
    """Row k of tangent1 and tangent2 (m, 3): :func:`colsim.engine.contacts.tangent_basis` of the unit
    normal (n0, n1, n2), in its arithmetic (helper x unless |n_x| >= 0.9, then y; t1 = helper x n,
    normalised; t2 = n x t1)."""
    h0, h1 = (1.0, 0.0) if abs(n0) < 0.9 else (0.0, 1.0)   # the helper (h0, h1, 0)
    a0, a1, a2 = h1 * n2 - 0.0 * n1, 0.0 * n0 - h0 * n2, h0 * n1 - h1 * n0   # helper x n, as np.cross
    length = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
    a0, a1, a2 = a0 / length, a1 / length, a2 / length
    tangent1[k, 0], tangent1[k, 1], tangent1[k, 2] = a0, a1, a2
    tangent2[k, 0] = n1 * a2 - n2 * a1
    tangent2[k, 1] = n2 * a0 - n0 * a2
    tangent2[k, 2] = n0 * a1 - n1 * a0


@functools.lru_cache(maxsize=16)
def _planes_on_device(planes: bytes):
    """The plane walls (p, 4) of a run's walls on the device, copied there once, not every step (a
    (1, 4) array of zeros stands for none: no empty array on a device)."""
    array = np.frombuffer(planes, dtype=np.float64).reshape(-1, 4)
    return cuda.to_device(array if len(array) else np.zeros((1, 4)))


class _WallContacts:
    """The floor's, the cylinder's and the plane walls' contacts of the particles of `found` (a
    :class:`_SweptPairs`), made on the device as :func:`colsim.engine.contacts._wall_contacts` makes
    them with no cylinder margin: particle i touches the floor where z_i - R_i is below its reach
    margin + (1 + slack) |u_i| (u: the predicted motion), the cylinder where its gap R - rho_i - R_i,
    relaxed by :func:`colsim.engine.contacts.recovery_relaxation`, is, and plane p where its gap
    n_p . x_i - offset_p - R_i, relaxed alike, is; the floor's contacts first, then the cylinder's,
    then each plane's, each in the particles' order. `count` (the one number copied to the host) of them."""

    def __init__(self, found: "_SweptPairs", margin: float, slack: float, most_recovered: float, walls,
                 kept: float = 0.0):
        n = found.radius.shape[0]
        self.found, self.most_recovered, self.kept = found, float(most_recovered), float(kept)
        self.cylinder_radius = math.nan if walls.cylinder_radius is None else float(walls.cylinder_radius)
        planes = walls.plane_array()
        self.n_planes = len(planes)
        self.planes = _planes_on_device(planes.tobytes())
        flags = cuda.device_array((2 + self.n_planes) * n, dtype=np.int64)
        launch(_wall_flags_kernel, blocks_for(n), THREADS, found.position, found.radius, found.predicted,
               bool(walls.floor), self.cylinder_radius, self.planes, self.n_planes, float(margin), float(slack),
               self.most_recovered, self.kept, flags)
        self.start = prefix_sums_on_device(flags)
        self.count = int(self.start[flags.shape[0]:].copy_to_host()[0])

    def fill(self, rows: "ContactRows", first: int, law) -> None:
        """Their rows of `rows`, from row `first` on (all but the levers and keys)."""
        mu, mu_r = np.asarray(law.mu, dtype=float), np.asarray(law.mu_r, dtype=float)
        found = self.found
        launch(_wall_rows_kernel, blocks_for(found.radius.shape[0]), THREADS, found.position, found.radius,
               self.start, self.cylinder_radius, self.planes, self.n_planes, self.most_recovered, self.kept, first,
               float(mu[FLOOR]), float(mu_r[FLOOR]), float(mu[CYLINDER]), float(mu_r[CYLINDER]), rows.frames[0],
               rows.frames[1], rows.frames[2], rows.numbers, rows.bodies)


@cuda.jit(device=True)
def _motion_length(predicted, i):
    """|u_i| of particle i's predicted motion, the squares summed in order as
    :func:`colsim.engine.contacts.row_lengths` sums them."""
    square = predicted[i, 0] * predicted[i, 0]
    square += predicted[i, 1] * predicted[i, 1]
    square += predicted[i, 2] * predicted[i, 2]
    return math.sqrt(square)


@cuda.jit(device=True)
def _cylinder_gap(i, position, radius, cylinder_radius, most_recovered, kept):
    """(particle i's gap to the cylinder, relaxed as :func:`colsim.engine.contacts.recovery_relaxation`
    relaxes it; its distance rho from the axis, :func:`colsim.engine.cuda_state.axis_distance`)."""
    rho = axis_distance(position, i)
    true_gap = cylinder_radius - rho - radius[i]
    return true_gap + _relaxation_of(true_gap, most_recovered, kept), rho


@cuda.jit(device=True)
def _relaxed_plane_gap(i, position, radius, planes, p, most_recovered, kept):
    """Particle i's gap to plane wall p of `planes` (p, 4) (:func:`colsim.engine.contacts.plane_gap`),
    relaxed as :func:`colsim.engine.contacts.recovery_relaxation` relaxes it."""
    true_gap = _plane_gap(position, radius, i, planes[p, 0], planes[p, 1], planes[p, 2], planes[p, 3])
    return true_gap + _relaxation_of(true_gap, most_recovered, kept)


@cuda.jit
def _wall_flags_kernel(position, radius, predicted, floor, cylinder_radius, planes, n_planes, margin, slack,
                       most_recovered, kept, flags):
    """flags ((2 + p) n,): 1 where particle i touches the floor (entry i), the cylinder (entry n + i,
    none for a cylinder_radius of nan) or plane wall q < p = n_planes of `planes` (entry (2 + q) n + i), else 0
    (:class:`_WallContacts`); one thread a particle."""
    i = cuda.grid(1)
    n = position.shape[0]
    if i >= n:
        return
    reach = margin + (1.0 + slack) * _motion_length(predicted, i)
    flags[i] = 1 if floor and position[i, 2] - radius[i] < reach else 0
    flags[n + i] = 0
    if not math.isnan(cylinder_radius):
        gap, _ = _cylinder_gap(i, position, radius, cylinder_radius, most_recovered, kept)
        flags[n + i] = 1 if gap < reach else 0
    for q in range(n_planes):
        flags[(2 + q) * n + i] = 1 if _relaxed_plane_gap(i, position, radius, planes, q, most_recovered, kept) < reach else 0


@cuda.jit
def _wall_rows_kernel(position, radius, start, cylinder_radius, planes, n_planes, most_recovered, kept, first,
                      mu_floor, mu_r_floor, mu_cylinder, mu_r_cylinder, normal, tangent1, tangent2, numbers, bodies):
    """Particle i's floor, cylinder and plane rows (one thread a particle), at first + start[i], first +
    start[n + i] and first + start[(2 + q) n + i] where flagged (start: the flags' prefix sums): the
    normal out of the particle, the tangents, the gap relaxed as on the host, the bodies (i, WALL), the
    family (PLANE + q for plane q), the radii (R_i, 0) and the wall's coefficients (the cylinder's for
    the planes: colsim.engine.state.law_family)."""
    i = cuda.grid(1)
    n = position.shape[0]
    if i >= n:
        return
    if start[i + 1] > start[i]:
        k = first + start[i]
        gap = position[i, 2] - radius[i]
        _put_wall_row(k, i, FLOOR, 0.0, 0.0, -1.0, gap + _relaxation_of(gap, most_recovered, kept), radius[i], mu_floor,
                      mu_r_floor, normal, tangent1, tangent2, numbers, bodies)
    if start[n + i + 1] > start[n + i]:
        k = first + start[n + i]
        gap, rho = _cylinder_gap(i, position, radius, cylinder_radius, most_recovered, kept)
        n0, n1 = (1.0, 0.0) if rho < 1e-12 else (position[i, 0] / rho, position[i, 1] / rho)
        _put_wall_row(k, i, CYLINDER, n0, n1, 0.0, gap, radius[i], mu_cylinder, mu_r_cylinder, normal, tangent1,
                      tangent2, numbers, bodies)
    for q in range(n_planes):
        at = (2 + q) * n + i
        if start[at + 1] > start[at]:
            gap = _relaxed_plane_gap(i, position, radius, planes, q, most_recovered, kept)
            _put_wall_row(first + start[at], i, PLANE + q, -planes[q, 0], -planes[q, 1], -planes[q, 2], gap,
                          radius[i], mu_cylinder, mu_r_cylinder, normal, tangent1, tangent2, numbers, bodies)


@cuda.jit(device=True)
def _put_wall_row(k, i, family, n0, n1, n2, gap, radius_i, mu, mu_r, normal, tangent1, tangent2, numbers, bodies):
    """Row k: particle i's contact with a wall of `family`, unit normal (n0, n1, n2), `gap`."""
    normal[k, 0], normal[k, 1], normal[k, 2] = n0, n1, n2
    _put_tangents(k, n0, n1, n2, tangent1, tangent2)
    numbers[GAP, k], numbers[RADIUS_I, k], numbers[RADIUS_J, k] = gap, radius_i, 0.0
    numbers[MU, k], numbers[MU_R, k] = mu, mu_r
    bodies[BODY_I, k], bodies[BODY_J, k], bodies[FAMILY, k] = i, WALL, family


def _bounds(midpoint, predicted, radius, margin: float, slack: float) -> tuple:
    """(the midpoints' lower corner (3,), their upper corner (3,), reach) of
    :func:`colsim.engine.contacts.swept_midpoints`, measured on the device (midpoint, predicted (n, 3),
    radius (n,) there): each block's smallest and largest coordinates and largest R_i + (1 + slack)
    |u_i| / 2, one copy to the host. The corners are the host's; the reach is 2 max(...) + margin, to
    a few units in the last place of the host's (a card fuses multiply-adds in R_i + (1 + slack) |u_i| / 2)."""
    n = midpoint.shape[0]
    parts = cuda.device_array((7, blocks_for(n)), dtype=np.float64)
    launch(_bounds_kernel, blocks_for(n), THREADS, midpoint, predicted, radius, float(slack), parts)
    parts = parts.copy_to_host()
    return parts[:3].min(axis=1), parts[3:6].max(axis=1), 2.0 * float(parts[6].max()) + margin


@cuda.jit
def _bounds_kernel(midpoint, predicted, radius, slack, parts):
    """parts (7, blocks): each block's smallest midpoint coordinates (rows 0-2, as their negatives'
    largest, exact), largest (rows 3-5) and largest R_i + (1 + slack) |u_i| / 2 (row 6); one thread a
    particle."""
    cache = cuda.shared.array((7, THREADS), dtype=np.float64)
    i = cuda.grid(1)
    t = cuda.threadIdx.x
    for row in range(7):
        cache[row, t] = -math.inf
    if i < midpoint.shape[0]:
        for d in range(3):
            cache[d, t] = -midpoint[i, d]
            cache[3 + d, t] = midpoint[i, d]
        cache[6, t] = radius[i] + 0.5 * _motion_length(predicted, i) * (1.0 + slack)
    for row in range(7):
        block_reduce(cache[row], t, True)
    if t == 0:
        for row in range(7):
            parts[row, cuda.blockIdx.x] = -cache[row, 0] if row < 3 else cache[row, 0]


def _grid(lower: np.ndarray, upper: np.ndarray, reach: float, n: int):
    """(lower corner (3,), cells along x, y, z (3,) int64, cell width): cubes at least `reach` wide
    over the midpoints' box from `lower` to `upper` (3,), at most CELLS_PER_PARTICLE of them for each
    of the n particles."""
    extent = upper - lower
    width = max(reach, 1e-300)
    while True:
        dims = np.floor(extent / width).astype(np.int64) + 1
        if np.prod(dims.astype(float)) <= CELLS_PER_PARTICLE * n:
            return lower, dims, width
        width *= 2.0


def _cell_lists(midpoint, lower, dims, width, cells: int):
    """(start (cells + 1,), listed (n,)) on the device: the particles of cell c are
    listed[start[c]:start[c + 1]]; lower (3,), dims (3,): the grid's corner and cells along each axis,
    tuples (`cells` their product)."""
    n = midpoint.shape[0]
    cell = cuda.device_array(n, dtype=np.int64)
    count = full_on_device(cells, 0, np.int64)
    launch(_cell_kernel, blocks_for(n), THREADS, midpoint, lower, dims, width, cell, count)
    d_start = prefix_sums_on_device(count)   # on the device: no round trip of the counts
    filled = full_on_device(cells, 0, np.int64)
    listed = cuda.device_array(n, dtype=np.int64)
    launch(_list_kernel, blocks_for(n), THREADS, cell, d_start, filled, listed)
    return d_start, listed


@cuda.jit(device=True)
def _cell_coordinate(x, lower, width, count):
    """The cell index of coordinate x along one axis of `count` cells."""
    c = int(math.floor((x - lower) / width))
    return min(max(c, 0), count - 1)


@cuda.jit(device=True)
def _cell_of(midpoint, i, lower, width, dims):
    """(x, y, z) cell indices of particle i's midpoint."""
    return (_cell_coordinate(midpoint[i, 0], lower[0], width, dims[0]),
            _cell_coordinate(midpoint[i, 1], lower[1], width, dims[1]),
            _cell_coordinate(midpoint[i, 2], lower[2], width, dims[2]))


@cuda.jit
def _cell_kernel(midpoint, lower, dims, width, cell, count):
    """cell[i] = particle i's cell (x fastest); count[c] += 1 (atomic)."""
    i = cuda.grid(1)
    if i >= midpoint.shape[0]:
        return
    cx, cy, cz = _cell_of(midpoint, i, lower, width, dims)
    c = cx + dims[0] * (cy + dims[1] * cz)
    cell[i] = c
    cuda.atomic.add(count, c, 1)


@cuda.jit
def _list_kernel(cell, start, filled, listed):
    """listed[start[c] + slot] = i for particle i of cell c (slot: an atomic count; the order within
    a cell is any)."""
    i = cuda.grid(1)
    if i >= cell.shape[0]:
        return
    c = cell[i]
    listed[start[c] + cuda.atomic.add(filled, c, 1)] = i


@cuda.jit
def _pairs_kernel(position, predicted, radius, midpoint, start, listed, lower, dims, width, reach2, margin,
                  slack, counts, offsets, partners, write):
    """Particle i's partners j > i: midpoints within the reach (reach2 its square) and the swept test.
    write False: counts[i] = how many; True: partners[offsets[i]:offsets[i + 1]] = them, sorted."""
    i = cuda.grid(1)
    if i >= midpoint.shape[0]:
        return
    cx, cy, cz = _cell_of(midpoint, i, lower, width, dims)
    found = 0
    for z in range(max(cz - 1, 0), min(cz + 2, dims[2])):
        for y in range(max(cy - 1, 0), min(cy + 2, dims[1])):
            for x in range(max(cx - 1, 0), min(cx + 2, dims[0])):
                c = x + dims[0] * (y + dims[1] * z)
                for slot in range(start[c], start[c + 1]):
                    j = listed[slot]
                    if j <= i:
                        continue
                    r2 = 0.0
                    for d in range(3):
                        e = midpoint[j, d] - midpoint[i, d]
                        r2 += e * e
                    if r2 <= reach2 and _swept_close(position, predicted, radius, i, j, margin, slack):
                        if write:
                            partners[offsets[i] + found] = j
                        found += 1
    if not write:
        counts[i] = found
        return
    sort_range_on_device(partners, offsets[i], offsets[i] + found)   # a particle has a dozen partners or so
